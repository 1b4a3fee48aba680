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


def _fit_reference(state, K, L):
    """fit_grid's former scalar loop in Python floats: (out, any_ok)."""
    from ardrone_nmpc.estimation import response_kernels as rk
    kl2, n = K * L * 2, float(state[rk.S_N])
    sx, sxx, sxy = (state[rk.HEAD + i * kl2:rk.HEAD + (i + 1) * kl2] for i in range(3))
    out = np.zeros(rk.fit_size(K, L))
    syy = [float(state[rk.S_SYY + a]) - float(state[rk.S_SY + a]) ** 2 / n for a in range(2)]
    out[3 * kl2 + K * L:] = syy
    any_ok = False
    for i in range(K * L):
        for a in range(2):
            e = 2 * i + a
            v = float(sx[e])
            c = float(sxx[e]) - v * v / n
            cy = float(sxy[e]) - v * float(state[rk.S_SY + a]) / n
            out[e] = c
            if c > 1e-12:
                any_ok = True
                g = cy / c
                out[kl2 + e], out[2 * kl2 + e] = g, syy[a] - g * cy
            else:
                out[kl2 + e], out[2 * kl2 + e] = 0.0, syy[a]
        out[3 * kl2 + i] = (0.0 + out[2 * kl2 + 2 * i]) + out[2 * kl2 + 2 * i + 1]
    return out, any_ok


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_grid_matches_the_scalar_loop_bit_for_bit(seed):
    from ardrone_nmpc.estimation import response_kernels as rk
    rng = np.random.default_rng(seed)
    K, L = 7, 3
    kl2 = K * L * 2
    state = rk.new_state(np.arange(K) * 0.01, np.array([0.03, 0.1, 0.3]), 8, 0.2, 30.0, 15)
    state[rk.S_N] = 37.25
    sx = rng.normal(size=kl2)
    state[rk.HEAD:rk.HEAD + kl2] = sx
    state[rk.HEAD + kl2:rk.HEAD + 2 * kl2] = sx * sx / 37.25 + rng.uniform(0, 2, kl2) ** 3
    state[rk.HEAD + kl2 + 3] = sx[3] * sx[3] / 37.25  # c ≈ 0: the gain not made
    state[rk.HEAD + kl2 + 8] = math.nan  # c NaN: not made either
    state[rk.HEAD + 2 * kl2:rk.HEAD + 3 * kl2] = rng.normal(size=kl2)
    state[rk.S_SY:rk.S_SY + 2] = rng.normal(size=2)
    state[rk.S_SYY:rk.S_SYY + 2] = rng.uniform(1, 3, size=2)
    want, want_ok = _fit_reference(state, K, L)
    out = np.full(rk.fit_size(K, L), -7.0)
    best = rk.fit_grid(state.copy(), out)
    assert out.tobytes() == want.tobytes()
    assert (best >= 0) == want_ok


def test_fit_grid_answers_none_when_nothing_moved():
    from ardrone_nmpc.estimation import response_kernels as rk
    state = rk.new_state(np.arange(3) * 0.01, np.array([0.1]), 8, 0.2, 30.0, 15)
    state[rk.S_N], state[rk.S_SYY] = 25.0, 1.0  # every Σx² centred 0: no gain made
    out = np.zeros(rk.fit_size(3, 1))
    assert rk.fit_grid(state, out) == -1
    assert not out[6:12].any()  # the gains: 0
