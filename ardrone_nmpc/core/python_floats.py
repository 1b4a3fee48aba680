"""Python's float built-ins as compiled code gives them: ``max``, ``min`` and ``x ** 2``.

A compiled twin of a Python stage (``runtime/before_solve``, ``runtime/after_solve``, the
attitude fit in ``estimation/response_kernels``) must give the Python stage's bits. Python's
``max(a, b)`` and ``min(a, b)`` keep their first argument unless the second is strictly beyond
it (a NaN first stays, a NaN second does not), which numba's ``max``/``min`` do not promise;
Python's ``x ** 2`` calls the C library's ``pow``, which differs from ``x * x`` in the last bit
for ~0.1 % of x, and a constant exponent lets the compiler make it ``x * x``.
"""

from __future__ import annotations

import math

from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL

__all__ = ["py_max", "py_min", "py_square"]


@njit(cache=True, **INNER_KERNEL)
def py_max(a: float, b: float) -> float:
    """Python's ``max(a, b)``: ``b`` only if it is greater (a NaN first stays; a NaN second
    does not)."""
    return b if b > a else a


@njit(cache=True, **INNER_KERNEL)
def py_min(a: float, b: float) -> float:
    """Python's ``min(a, b)``: ``b`` only if it is less."""
    return b if b < a else a


@njit(cache=True, **INNER_KERNEL)
def py_square(x: float, two: float) -> float:
    """Python's ``x ** 2`` of a finite or NaN ``x``: the C library's ``pow(x, 2.0)`` — not x · x
    — with ``two`` (2.0) read at run time (a constant 2 would let the compiler make it x · x);
    NaN itself. An infinite answer is where Python raises OverflowError: the caller checks."""
    if x != x:
        return x
    return math.pow(x, two)


flush_stale_caches(__name__)  # (core/kernel_cache.py)
