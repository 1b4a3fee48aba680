"""The compiled per-tick lookups give the bits of the numpy expressions they replace (issue 26):
the waypoint reference (``reference/kernels``; a hover and a step through it too) and the
attitude-response fit's fold (``estimation/response_kernels``), each against the vectorised
numpy formula written from its documented definition (``searchsorted``, broadcasting; a
step's closed form), at ordinary times, on the knots, next to them, and at NaN and ±inf."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.core.numerics import callable_from_python
from ardrone_nmpc.core.sorted_search import count_at_or_below
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z
from ardrone_nmpc.estimation import response_kernels
from ardrone_nmpc.reference.experiment import HoldStartThen, lookup_args
from ardrone_nmpc.reference.kernels import waypoint_states
from ardrone_nmpc.reference.trajectories import Hover, Square, Step, Waypoints

# the attitude fit's inner kernels, callable from Python (the same source and options)
held_count = callable_from_python(response_kernels.held_count)
searched = callable_from_python(count_at_or_below)
memo_decays = callable_from_python(response_kernels.memo_decays)
microseconds = callable_from_python(response_kernels.microseconds)
fold_sample = callable_from_python(response_kernels.fold_sample)


def _numpy_waypoints(t_knots, p, psi, t):
    """Linear interpolation between timed waypoints, the first held before, the last after."""
    dt = np.diff(t_knots)
    vel = np.diff(p, axis=0) / dt[:, None]
    k = np.clip(np.searchsorted(t_knots, t, side="right") - 1, 0, dt.size - 1)
    inside = (t >= t_knots[0]) & (t < t_knots[-1])
    after = t >= t_knots[-1]
    frac = np.where(after, 1.0, np.where(inside, (t - t_knots[k]) / dt[k], 0.0))
    pos = np.where(after[:, None], p[k + 1], p[k] + frac[:, None] * (p[k + 1] - p[k]))
    out = np.zeros((t.size, 7))
    out[:, [IX_X, IX_Y, IX_Z]] = pos
    out[:, [IX_VX, IX_VY, IX_VZ]] = np.where(inside[:, None], vel[k], 0.0)
    out[:, IX_PSI] = np.where(after, psi[k + 1], psi[k] + frac * (psi[k + 1] - psi[k]))
    return out


def _trajectories():
    rng = np.random.default_rng(7)
    return [Square([0.0, 0.0, 1.0]), Square([-0.3, 0.7, 1.2], 1.3, 4.1, 2.0),
            Waypoints([0.0, 0.3, 1.1, 2.0, 7.0], rng.normal(size=(5, 3)), rng.normal(size=5)),
            Waypoints([-1.0, 2.0], np.array([[-0.0, 0.0, -0.0], [0.0, -0.0, 0.0]]), [0.0, -0.0])]


@pytest.mark.parametrize("traj", _trajectories())
def test_waypoint_lookup_is_the_numpy_interpolation_bit_for_bit(traj):
    rng = np.random.default_rng(1)
    knots = traj.t_s
    for t in (rng.uniform(-3.0, 25.0, 3000), knots.copy(), np.nextafter(knots, np.inf),
              np.nextafter(knots, -np.inf), np.array([np.nan, np.inf, -np.inf, -0.0, 0.0])):
        expected = _numpy_waypoints(knots, traj.positions_m, traj.psi_rad, t)
        assert traj.state_at(t).tobytes() == expected.tobytes()


def test_waypoint_lookup_takes_a_scalar_and_any_layout():
    traj = Square([0.0, 0.0, 1.0])
    assert traj.state_at(7.5).shape == (1, 7)
    t = np.linspace(0.0, 20.0, 40)
    assert traj.state_at(t[::2]).tobytes() == traj.state_at(t[::2].copy()).tobytes()
    np.testing.assert_array_equal(traj.state_at(7.5)[0, [IX_X, IX_Y]], [1.0, 0.5])


def test_the_fold_is_the_numpy_broadcast_bit_for_bit():
    """``fold_sample``: each delay's command (``searchsorted``), its decays (``math.exp``) and
    the sums they make, as numpy's broadcast makes them — walking down the times or, for
    times out of order, searching them; the tracked model's value alone kept."""
    rng = np.random.default_rng(3)
    n, cap = 40, 64
    times = np.zeros(cap)
    times[:n] = np.cumsum(rng.uniform(0.02, 0.1, n))
    u, ylag = rng.normal(size=(cap, 2)), rng.normal(size=(cap, 6, 2))
    delays, lags = np.arange(0.0, 0.605, 0.01), np.array([0.03, 0.06, 0.1, 0.15, 0.2, 0.3])
    sums = rng.normal(size=(3, delays.size, lags.size, 2))
    # the decays' cache, cold for the first time and warm (every d seen) for its repeat
    memo = np.full(2 * response_kernels.MEMO_SETS * (1 + lags.size), math.nan)
    bits = np.zeros(1)
    for t_s, forget, ordered, best in ((float(times[n - 1]) + 0.013, 0.97, True, (5, 2)),
                                       (float(times[n - 1]), 1.0, False, None),
                                       (float(times[n - 1]) + 0.013, 0.97, True, (60, 5)),
                                       (float(times[n - 1]) + 0.2, 0.9, False, (0, 0))):
        y = rng.normal(size=2)
        x_best = np.full(2, 7.0)
        expected = sums.copy()
        flat = -1 if best is None else 2 * (best[0] * lags.size + best[1])
        fold_sample(times, n, ordered, t_s, delays, lags, memo, bits, bits.view(np.int64),
                    u.reshape(-1), ylag.reshape(-1), y, forget, sums.reshape(-1), flat, x_best)
        at = t_s - delays
        j = np.searchsorted(times[:n], at, side="right") - 1
        arg = -(at - times[j])[:, None] / lags
        decay = np.array([[math.exp(a) for a in row] for row in arg])
        uj = u[j][:, None, :]
        x_np = uj + (ylag[j] - uj) * decay[:, :, None]
        if forget != 1.0:
            expected *= forget
        expected[0] += x_np
        expected[1] += x_np * x_np
        expected[2] += x_np * y
        assert sums.tobytes() == expected.tobytes()
        want = np.full(2, 7.0) if best is None else x_np[best]
        assert x_best.tobytes() == want.tobytes()


def test_the_walk_down_the_times_is_the_binary_search():
    """``held_count`` from the last count, for ``at`` descending (a sample's delays), is
    ``count_at_or_below`` on ascending times (±inf, a NaN last, a NaN ``at`` included); out
    of order (a NaN held among them) it is the binary search itself."""
    rng = np.random.default_rng(9)
    for trial in range(300):
        n = int(rng.integers(1, 30))
        times = np.cumsum(rng.uniform(0.0, 0.1, n)).round(2)  # ties with the ``at`` too
        times = np.unique(times)
        n = times.size
        if trial % 5 == 1:
            times[-1] = math.inf
        if trial % 5 == 2:
            times[0] = -math.inf
        if trial % 5 == 3:
            times[-1] = math.nan
        t_s = float(rng.uniform(-0.1, times[np.isfinite(times)].max(initial=0.0) + 0.3))
        ats = t_s - np.arange(0.0, 0.605, 0.01)
        if trial % 7 == 0:
            ats[:] = math.nan
        c = n
        for at in ats:
            c = held_count(times, n, c, at, True)
            assert c == np.searchsorted(times[:n], at, side="right"), (times, at)
        if n > 2:  # a NaN held in the middle: the times after it are unsorted
            times[n // 2] = math.nan
            times[n // 2 + 1:] = rng.permutation(times[n // 2 + 1:])
            c = n
            for at in ats:
                c = held_count(times, n, c, at, False)
                assert c == searched(times, n, at)


def test_the_decays_cache_holds_the_exponentials_of_its_keys_bit_for_bit():
    """``memo_decays``: whatever it finds or evicts, the row it answers holds ``exp(−d/τ)``
    of exactly the d asked (the C library's, as ``math.exp``); a set's two slots, the newest
    first; NaN matches nothing, ±0 both give 1."""
    rng = np.random.default_rng(11)
    lags = np.array([0.03, 0.06, 0.1, 0.15, 0.2, 0.3])
    memo = np.full((2 * response_kernels.MEMO_SETS, 1 + lags.size), math.nan)
    flat = memo.reshape(-1)
    bits = np.zeros(1)
    ints = bits.view(np.int64)
    # µs-rounded differences and their last-bit neighbours (the flight's keys), repeated, in
    # a table far too small for them all: hits, misses and evictions
    base = np.round(rng.uniform(0.0, 0.07, 300), 6)
    keys = np.concatenate([base, np.nextafter(base, 1.0), np.nextafter(base, -1.0)])
    keys = np.concatenate([keys, [0.0, -0.0, math.nan, math.inf, -1.5, 1e300]])
    width = 1 + lags.size
    for d in rng.choice(keys, 20_000):
        at = memo_decays(d, lags, flat, bits, ints)
        row = at // width
        assert at % width == 1
        want = np.array([math.exp(-d / tau) for tau in lags])
        assert memo[row, 1:].tobytes() == want.tobytes(), d
        assert row % 2 == 0 or memo[row, 0] == d
    assert np.isnan(memo[memo_decays(math.nan, lags, flat, bits, ints) // width, 1:]).all()


def test_the_kernels_microseconds_is_round_to_six_decimals_bit_for_bit():
    """``response_kernels.microseconds`` is ``round(t, 6)`` wherever it answers — random
    times, a navdata period's thirds of a ms, exact ties (q/128: t·10⁶ ends in ·5), the halves
    of a microsecond and their neighbours — and refuses (−1) exactly outside 1 µs … 2⁴⁰ µs."""
    import random

    rng = random.Random(5)
    times = [rng.uniform(0.0, 1e4) for _ in range(50_000)]
    times += [0.065 * rng.randrange(10**6) for _ in range(10_000)]
    times += [rng.randrange(1, 10**10) / 3e6 for _ in range(10_000)]
    times += [q / 128 for q in range(1, 40_000, 2)]
    for _ in range(10_000):
        k = rng.randrange(10**10)
        for t in ((k + 0.5) / 1e6, (k + 0.25) / 1e6, k / 1e6):
            times += [t, math.nextafter(t, -math.inf), math.nextafter(t, math.inf)]
    times += [rng.uniform(-10.0, 10.0) for _ in range(5_000)]
    times += [0.0, -0.0, 1e-7, 5e-7, 1e-6, 1.5e-6, 2.0 ** 40 / 1e6,
              math.nextafter(2.0 ** 40 / 1e6, 0.0), 1e12, math.inf, -math.inf, math.nan]
    for t in times:
        got = microseconds(t)
        answers = 1.0 <= t * 1e6 < 2.0 ** 40
        assert (got != -1.0) == answers, t
        if answers:
            want = round(t, 6)
            assert got == want and math.copysign(1.0, got) == math.copysign(1.0, want), t


# ----------------------------------------------------------------------------- set points
def _lookup(traj, t: np.ndarray) -> np.ndarray:
    out = np.full((t.size, 7), np.nan)
    waypoint_states(*lookup_args(traj), t, out)
    return out


def _set_point_rows(before_m, before_psi, after_m, after_psi, step_time_s, t) -> np.ndarray:
    """The closed form of a step: ``before`` at t < step time (and at NaN), ``after`` from it
    on; velocities +0.0."""
    out = np.zeros((t.size, 7))
    later = t >= step_time_s
    for row, point, psi in ((~later, before_m, before_psi), (later, after_m, after_psi)):
        out[np.ix_(row, [IX_X, IX_Y, IX_Z])] = point
        out[row, IX_PSI] = psi
    return out


_SET_POINTS = [  # (start, ψ, target, ψ, step time)
    ([0.0, 0.0, 1.0], 0.0, [-1.5, 0.0, 1.0], 0.0, 1.0),  # the thesis' x step
    ([0.0, 0.0, 1.0], 0.0, [0.0, 0.0, 1.0], 1.0, 1.0),  # a heading step: one point
    ([0.3, -0.7, 1.2], -2.5, [-0.1, 0.9, 0.4], 7.0, 0.3),
    ([-0.0, 0.0, 1.0], -0.0, [-1.0, -0.0, 1.0], -3.0, 2.0),  # −0.0 + −0.0·… stays −0.0
    ([1e300, 0.0, 1.0], 0.0, [-1e300, 0.0, 1.0], 0.0, -0.4),
    ([0.1, 0.2, 1.0], 0.0, [0.4, 0.2, 1.0], 0.0, math.inf),
    ([0.1, 0.2, 1.0], 0.0, [0.4, 0.2, 1.0], 0.0, -math.inf),
    ([0.1, 0.2, 1.0], 0.0, [0.4, 0.2, 1.0], 0.0, math.nan),
]


def _times_around(step_time_s: float) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    grid = (np.arange(-2.0, 30.0, 0.065)[:, None] + 0.1 * np.arange(16)).ravel()
    near = np.array([step_time_s, np.nextafter(step_time_s, np.inf),
                     np.nextafter(step_time_s, -np.inf)])
    return [np.linspace(-5.0, 35.0, 400_001), grid, rng.uniform(-3.0, 25.0, 3000),
            near[np.isfinite(near)], np.array([np.nan, np.inf, -np.inf, -0.0, 0.0])]


@pytest.mark.parametrize("case", _SET_POINTS)
def test_set_point_lookup_is_the_step_bit_for_bit(case):
    """A step and a hover through the waypoint lookup (``lookup_args``): the closed form's
    bits, and :meth:`Step.state_at`'s / :meth:`Hover.state_at`'s, on a dense grid, the tick's
    horizon times, the step time and its neighbours, NaN and ±inf."""
    start, start_psi, target, target_psi, step_time_s = case
    step = Step(start, start_psi, target, target_psi, step_time_s)
    hover = Hover(start, start_psi)
    for t in _times_around(step_time_s):
        expected = _set_point_rows(start, start_psi, target, target_psi, step_time_s, t)
        assert _lookup(step, t).tobytes() == expected.tobytes()
        assert step.state_at(t).tobytes() == expected.tobytes()
        held = _set_point_rows(start, start_psi, start, start_psi, -math.inf, t)
        if lookup_args(hover) is not None:  # (a −0.0 hover: the next test)
            assert _lookup(hover, t).tobytes() == held.tobytes()
        assert hover.state_at(t).tobytes() == held.tobytes()


@pytest.mark.parametrize("traj", [
    Hover([-0.0, 0.0, 1.0]), Hover([0.0, 0.0, 1.0], -0.0),
    Step([-0.0, 0.0, 1.0], 0.0, [1.0, 0.0, 1.0], 0.0),  # −0.0 + 0.0 is +0.0
    Step([0.0, 0.0, 1.0], 1e308, [0.0, 0.0, 1.0], -1e308),  # an overflowing difference
])
def test_a_set_point_the_lookup_cannot_give_exactly_keeps_numpy(traj):
    assert lookup_args(traj) is None
    assert HoldStartThen(traj).waypoint_args is None


def test_a_subclass_that_overrides_state_at_keeps_its_own():
    class Shifted(Hover):
        def state_at(self, t_s):
            return super().state_at(t_s) + 1.0

    assert lookup_args(Shifted([0.0, 0.0, 1.0])) is None
    assert lookup_args(Hover([0.0, 0.0, 1.0])) is not None
