"""``response_lanes.fold_lags``: the two-lane fold gives the scalar expressions' bits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from ardrone_nmpc.estimation.response_lanes import fold_lags


@njit
def _fold(sums, ylag, memo, e0, g0, r0, lags, kl2, u0, u1, y0, y1, forget, scale):
    fold_lags(sums, ylag, memo, e0, g0, r0, lags, kl2, u0, u1, y0, y1, forget, scale)


def _reference(sums, ylag, memo, e0, g0, r0, lags, kl2, u, y, forget, scale):
    """fold_sample's scalar loop in Python floats (IEEE doubles, the same operations)."""
    for m in range(lags):
        dk = float(memo[r0 + m])
        for a in range(2):
            v = u[a] + (float(ylag[g0 + 2 * m + a]) - u[a]) * dk
            e = e0 + 2 * m + a
            for idx, add in ((e, v), (e + kl2, v * v), (e + 2 * kl2, v * y[a])):
                s = float(sums[idx])
                sums[idx] = (s * forget + add) if scale else (s + add)


@pytest.mark.parametrize("scale", [True, False])
def test_fold_lags_matches_the_scalar_fold_bit_for_bit(scale):
    rng = np.random.default_rng(7)
    lags, kl2 = 6, 2 * 6 * 5
    sums = rng.normal(size=3 * kl2 + 3) * 10.0 ** rng.integers(-8, 8, size=3 * kl2 + 3)
    sums[5], sums[kl2 + 7] = math.nan, math.inf  # propagated as the scalar code does
    ylag = rng.normal(size=40 * lags * 2)
    memo = rng.uniform(0.0, 1.0, size=3 * (1 + lags))
    args = (13, 2 * 3 * lags + 2, 1 + lags + 1, lags, kl2)  # an odd e0: any alignment
    u, y, forget = (0.1 * rng.normal(), -0.2 * rng.normal()), (0.3, -1e-3), 0.99781
    want, got = sums.copy(), sums.copy()
    _reference(want, ylag, memo, *args, u, y, forget, scale)
    _fold(got, ylag, memo, *args, u[0], u[1], y[0], y[1], forget, scale)
    assert got.tobytes() == want.tobytes()
    assert not np.array_equal(np.nan_to_num(got), np.nan_to_num(sums))  # it did fold


def test_fold_lags_touches_only_its_elements():
    lags, kl2 = 2, 8
    sums = np.zeros(3 * kl2)
    _fold(sums, np.ones(8), np.full(4, 0.5), 2, 2, 1, lags, kl2, 0.0, 0.0, 2.0, 2.0, 1.0,
          False)
    touched = np.flatnonzero(sums)
    assert touched.tolist() == [2, 3, 4, 5, 10, 11, 12, 13, 18, 19, 20, 21]
    assert sums[2] == 0.5 and sums[10] == 0.25 and sums[18] == 1.0
