"""Compiled steps of the attitude-response fit (:mod:`~ardrone_nmpc.estimation.attitude_response`).

Each navdata sample adds its model value at every grid point (delays × lags × axes) to the
running sums: two dozen numpy operations on arrays of a few hundred elements, the largest
cost of a tick with something ``auto`` (issue 26). These loops compute the same expressions
in the same order — sums, products and quotients round alike in numpy and in a compiled loop
on the pinned target, which fuses nothing — so the fit is the same bits. The exponentials
are the C library's ``exp`` (``math.exp`` in Python, the same function): numpy's vectorised
``exp`` is chosen by the CPU at run time and differs in the last bit on AVX-512 machines
from the one on AVX2 machines (4.6 % of arguments), which made the fit, and the flights it
steers, depend on the CPU (docs/solver-notes.md §9).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import OUTER_KERNEL
from ardrone_nmpc.core.sorted_search import count_at_or_below

__all__ = ["fold_sample", "lag_decays"]


@njit(cache=True, **OUTER_KERNEL)
def lag_decays(times: np.ndarray, n: int, t_s: float, delays_s: np.ndarray,
               lags_s: np.ndarray, j_out: np.ndarray, decay_out: np.ndarray) -> None:
    """Per delay d: ``j_out`` the last of the ``n`` command times at or before ``t_s − d``
    (``searchsorted(times[:n], t_s − d, side="right") − 1``; NaN sorts last) and ``decay_out``
    (K, L) each lag τ's decay ``exp(−(t_s − d − times[j]) / τ)`` (the C library's ``exp``)."""
    for k in range(delays_s.size):
        at = t_s - delays_s[k]
        j = count_at_or_below(times, n, at) - 1
        j_out[k] = j
        d = at - times[j]
        for m in range(lags_s.size):
            decay_out[k, m] = math.exp(-d / lags_s[m])


@njit(cache=True, **OUTER_KERNEL)
def fold_sample(u: np.ndarray, ylag: np.ndarray, j: np.ndarray, decay: np.ndarray,
                y: np.ndarray, forget: float, x: np.ndarray, sx: np.ndarray, sxx: np.ndarray,
                sxy: np.ndarray) -> None:
    """The model value ``x`` (K, L, 2) of a sample at every grid point — the lag's output
    ``u + (y_lag − u)·decay`` from the command ``j[k]`` — and its sums, first faded by
    ``forget`` (unless it is 1): Σx, Σx², Σx·y."""
    scale = forget != 1.0
    for k in range(decay.shape[0]):
        jk = j[k]
        for m in range(decay.shape[1]):
            for a in range(2):
                uu = u[jk, a]
                v = uu + (ylag[jk, m, a] - uu) * decay[k, m]
                x[k, m, a] = v
                if scale:
                    sx[k, m, a] *= forget
                    sxx[k, m, a] *= forget
                    sxy[k, m, a] *= forget
                sx[k, m, a] += v
                sxx[k, m, a] += v * v
                sxy[k, m, a] += v * y[a]


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
