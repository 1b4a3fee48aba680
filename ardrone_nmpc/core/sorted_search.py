"""``numpy.searchsorted(a[:n], v, side="right")`` for compiled kernels: one home for the binary
search the per-tick lookups use (the waypoint reference, the attitude-response fit)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL

__all__ = ["count_at_or_below"]


@njit(cache=True, **INNER_KERNEL)
def count_at_or_below(a: np.ndarray, n: int, v: float) -> int:
    """How many of the ascending ``a[:n]`` are ≤ ``v``; ``n`` for NaN (numpy sorts it last)."""
    if v != v:
        return n
    lo, hi = 0, n  # the count lies in [lo, hi]
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] <= v:
            lo = mid + 1
        else:
            hi = mid
    return lo


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
