"""Compiled steps of the attitude-response fit (:mod:`~ardrone_nmpc.estimation.attitude_response`).

Each navdata sample adds its model value at every grid point (delays × lags × axes) to the
running sums: two dozen numpy operations on arrays of a few hundred elements, the largest
cost of a tick with something ``auto`` (issue 26). These loops compute the same expressions
in the same order — sums, products and quotients round alike in numpy and in a compiled loop
on the pinned target, which fuses nothing — so the fit is the same bits; the exponentials
stay numpy's (its vectorised ``exp`` and the C library's may differ in the last bit).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ardrone_nmpc.core.numerics import OUTER_KERNEL
from ardrone_nmpc.core.sorted_search import count_at_or_below

__all__ = ["fold_sample", "lag_exponents"]


@njit(cache=True, **OUTER_KERNEL)
def lag_exponents(times: np.ndarray, n: int, t_s: float, delays_s: np.ndarray,
                  lags_s: np.ndarray, j_out: np.ndarray, arg_out: np.ndarray) -> None:
    """Per delay d: ``j_out`` the last of the ``n`` command times at or before ``t_s − d``
    (``searchsorted(times[:n], t_s − d, side="right") − 1``; NaN sorts last) and ``arg_out``
    (K, L) the exponent ``−(t_s − d − times[j]) / τ`` of each lag τ."""
    for k in range(delays_s.size):
        at = t_s - delays_s[k]
        j = count_at_or_below(times, n, at) - 1
        j_out[k] = j
        d = at - times[j]
        for m in range(lags_s.size):
            arg_out[k, m] = -d / lags_s[m]


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
