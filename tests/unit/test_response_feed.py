"""The attitude-response fit's compiled step (``response_kernels.feed``) against the numpy
code it replaced, bit for bit: the sums, the tracked residual and every estimate (the grid's
fit, ``response_kernels.fit_grid``, too)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.estimation.attitude_response import (
    DELAY_RIVAL_SEPARATION_S, DELAY_STEP_S, NO_ESTIMATE, REFRESH_SAMPLES, AttitudeEstimate,
    AttitudeResponseEstimator, _microseconds,
)
from ardrone_nmpc.estimation import response_kernels as rk
from ardrone_nmpc.estimation.response_kernels import CMD_RESTART, CMD_SEND

E = 0.21


class _NumpyFeed(AttitudeResponseEstimator):
    """The feeding methods and the fit as they were before they were compiled (numpy)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        cap = self._capacity
        self._t = np.zeros(cap)
        self._u = np.zeros((cap, 2))
        self._y = np.zeros((cap, len(self.lags_s), 2))
        self._count = 0
        self._decay = np.zeros((len(self.delays_s), len(self.lags_s)))
        self._x = np.zeros_like(self._sx)
        self._last_r = None
        self._last_t = math.nan
        self._since_best = 0

    def _fit(self):
        n = self._n
        if n < 20:
            return NO_ESTIMATE
        sxx = self._sxx - self._sx ** 2 / n
        sxy = self._sxy - self._sx * self._sy / n
        syy = self._syy - self._sy ** 2 / n
        ok = sxx > 1e-12
        if not ok.any() or syy.sum() <= 0.0:
            return NO_ESTIMATE
        gain = np.where(ok, sxy / np.where(ok, sxx, 1.0), 0.0)
        rss_axis = np.where(ok, syy - gain * sxy, syy)
        rss = rss_axis.sum(axis=2)
        k, l = np.unravel_index(int(np.argmin(rss)), rss.shape)
        g = gain[k, l]
        offset = (self._sy - g * self._sx[k, l]) / n
        st = self._state
        st[7], st[8], st[9] = 1.0, k, l
        st[10:12], st[12:14] = g, offset
        sigma2 = float(rss[k, l]) / max(2.0 * n - 5.0, 1.0)
        inflate = self._inflation()
        delay, delay_var = self._refine(rss[:, l], k, sigma2)
        gains, gain_std = [], []
        for a in range(2):
            if ok[k, l, a]:
                gains.append(float(g[a]))
                gain_std.append(inflate * math.sqrt(max(float(rss_axis[k, l, a]), 0.0)
                                                    / max(n - 2.0, 1.0) / float(sxx[k, l, a])))
            else:
                gains.append(math.nan)
                gain_std.append(math.inf)
        return AttitudeEstimate(float(delay), inflate * math.sqrt(delay_var),
                                (gains[0], gains[1]), (gain_std[0], gain_std[1]),
                                float(self.lags_s[l]),
                                1.0 - float(rss[k, l]) / float(syy.sum()), float(n),
                                self._contrast(rss[:, l], k, sigma2 * inflate ** 2))

    def _contrast(self, curve, k, sigma2):
        away = np.abs(self.delays_s - self.delays_s[k]) >= DELAY_RIVAL_SEPARATION_S - 1e-9
        if not away.any() or not sigma2 > 0.0:
            return math.inf
        return float(curve[away].min() - curve[k]) / sigma2

    def _refine(self, curve, k, sigma2):
        i = min(max(k, 1), len(curve) - 2)
        lo, mid, hi = curve[i - 1], curve[i], curve[i + 1]
        if not np.all(np.isfinite((lo, mid, hi))):
            return float(self.delays_s[k]), math.inf
        second = lo - 2.0 * mid + hi
        if not second > 0.0:
            return float(self.delays_s[k]), math.inf
        delay = float(self.delays_s[i]) + 0.5 * DELAY_STEP_S * (lo - hi) / second
        delay = min(max(delay, float(self.delays_s[0])), float(self.delays_s[-1]))
        return delay, max(2.0 * sigma2 * DELAY_STEP_S ** 2 / second, DELAY_STEP_S ** 2 / 12.0)

    def _inflation(self):
        rr, rr1, w = self._res
        if w < 10.0 or rr <= 0.0:
            return 1.0
        rho = min(max(rr1 / rr, 0.0), 0.95)
        return math.sqrt((1.0 + rho) / (1.0 - rho))

    def command(self, t_s, roll_frac, pitch_frac):
        t_s = _microseconds(t_s)
        u = np.array([roll_frac, pitch_frac], dtype=float) * self.euler_angle_max_rad
        n = self._count
        if n:
            t0 = self._t[n - 1]
            if t_s <= t0:
                return
            u0, y0 = self._u[n - 1], self._y[n - 1]
            decay = np.array([math.exp(a) for a in -(t_s - t0) / self.lags_s])
            y = u0 + (y0 - u0) * decay[:, None]
        else:
            y = np.tile(u, (len(self.lags_s), 1))
        if n == len(self._t):
            keep = n // 2
            for a in (self._t, self._u, self._y):
                a[:keep] = a[n - keep:n]
            n = keep
        self._t[n], self._u[n], self._y[n] = t_s, u, y
        self._count = n + 1

    def restart(self):
        self._count = 0
        self._last_r = None

    def navdata(self, t_s, roll_deg, pitch_deg):
        n = self._count
        t_s = _microseconds(t_s)
        y = np.radians([roll_deg, pitch_deg])
        if (n < 2 or not np.all(np.isfinite(y)) or t_s <= self._last_t
                or self._t[0] > t_s - self.delays_s[-1]):
            return False
        at = t_s - self.delays_s
        j = np.searchsorted(self._t[:n], at, side="right") - 1
        arg = -(at - self._t[j])[:, None] / self.lags_s
        decay = np.array([[math.exp(a) for a in row] for row in arg])
        forget = (math.exp(-(t_s - self._last_t) / self.window_s)
                  if math.isfinite(self._last_t) else 1.0)
        self._last_t = t_s
        uj = self._u[j][:, None, :]
        x = uj + (self._y[j] - uj) * decay[:, :, None]
        if forget != 1.0:
            for s in (self._sx, self._sxx, self._sxy):
                s *= forget
        self._sx += x
        self._sxx += x * x
        self._sxy += x * y
        st = self._state
        if st[7] != 0.0:  # a best model (S_HAS_BEST), set by _fit
            k, l = int(st[8]), int(st[9])
            r = y - (st[10:12] * x[k, l] + st[12:14])
            self._res *= forget
            if self._last_r is not None:
                r0, r1 = float(r[0]), float(r[1])
                p0, p1 = float(self._last_r[0]), float(self._last_r[1])
                self._res += (r0 * r0 + r1 * r1, r0 * p0 + r1 * p1, 1.0)
            self._last_r = r
        st[0] = st[0] * forget + 1.0
        self._sy[:] = self._sy * forget + y
        self._syy[:] = self._syy * forget + y * y
        self._estimate = None
        self._since_best += 1
        if self._since_best >= REFRESH_SAMPLES:
            self._since_best = 0
            self._estimate = self._fit()
        return True


def _stream(seed: int):
    """Commands every 65 ms (some repeated or late), navdata every ~5 ms with a delayed,
    lagged, noisy response; hovers (restarts), NaN samples and samples seen twice."""
    rng = np.random.default_rng(seed)
    t, cmd, state = 0.0, np.zeros(2), np.zeros(2)
    events = []
    for k in range(1500):
        t += 0.065 + rng.normal(0.0, 0.002)
        if k % 200 == 150:
            events.append(("restart", t))
        elif k % 97 == 5:
            events.append(("cmd", t - 0.1, 0.1, 0.1))  # before the last: ignored
        else:
            cmd = np.clip(cmd + rng.normal(0.0, 0.2, 2), -1, 1)
            events.append(("cmd", t, *cmd))
        for m in range(13):
            tn = t + m * 0.005 + rng.uniform(0, 0.001)
            state += 0.1 * (cmd * E * 1.3 - state)
            roll, pitch = np.degrees(state + rng.normal(0, 0.003, 2))
            if rng.random() < 0.01:
                roll = math.nan
            events.append(("nav", tn, roll, pitch))
            if rng.random() < 0.01:
                events.append(("nav", tn, roll, pitch))  # seen again
    return events


def _same(a: AttitudeResponseEstimator, b: AttitudeResponseEstimator) -> None:
    for name in ("_sx", "_sxx", "_sxy", "_sy", "_syy", "_res"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    assert a._n == b._n


def _feed_both(ref, got, ev) -> None:
    """One event of a stream to both estimators; their navdata answers agree."""
    if ev[0] == "cmd":
        ref.command(*ev[1:])
        got.command(*ev[1:])
    elif ev[0] == "restart":
        ref.restart()
        got.restart()
    else:
        assert ref.navdata(*ev[1:]) == got.navdata(*ev[1:])


def test_feed_is_the_numpy_step_bit_for_bit():
    for seed, window_s in ((0, 30.0), (1, math.inf), (2, 5.0)):
        ref = _NumpyFeed(E, window_s=window_s)
        got = AttitudeResponseEstimator(E, window_s=window_s)
        fits = 0
        for i, ev in enumerate(_stream(seed)):
            _feed_both(ref, got, ev)
            if i % 50 == 0:
                _same(ref, got)
                assert ref.estimate == got.estimate or (
                    repr(ref.estimate) == repr(got.estimate))  # NaN fields compare unequal
                fits += math.isfinite(got.estimate.delay_s)
        _same(ref, got)
        assert fits > 10


def test_one_call_per_tick_is_the_sample_then_the_command():
    """``feed`` (what the tick calls) is ``navdata`` then ``command`` or ``restart``."""
    one, two = AttitudeResponseEstimator(E), AttitudeResponseEstimator(E)
    events = _stream(4)
    cmds = [e for e in events if e[0] != "nav"]
    navs = [e for e in events if e[0] == "nav"]
    for i, c in enumerate(cmds[:800]):
        nav = navs[i * 13]
        if c[0] == "restart":
            r1 = one.feed(nav[1], nav[2], nav[3], CMD_RESTART)
            r2 = two.navdata(*nav[1:])
            two.restart()
        else:
            r1 = one.feed(nav[1], nav[2], nav[3], CMD_SEND, *c[1:])
            r2 = two.navdata(*nav[1:])
            two.command(*c[1:])
        assert r1 == r2
        assert repr(one.estimate) == repr(two.estimate)
    _same(one, two)


def _odd_sums(rng, ref, trial: int) -> np.ndarray:
    """A state of random sums for ``ref``'s grid (its parameters and grid kept): every fourth
    with an axis no command moved, NaN in a sum, or only 0, −0 and 1; the tracked residual's
    sums (the inflation) random too, with at least ten pairs every other trial."""
    st = rng.normal(size=ref._state.size) ** 2
    st[0] = 30.0 + trial  # the samples' effective number
    # the fit's parameters and grid as built (response_kernels.new_state)
    grid = len(ref.delays_s) + len(ref.lags_s)
    st[rk.S_CAPACITY:rk.HEAD] = ref._state[rk.S_CAPACITY:rk.HEAD]
    st[-grid:] = ref._state[-grid:]
    kl2 = ref._sx.size
    head = rk.HEAD
    if trial % 4 == 1:  # an axis no command moved
        st[head + kl2 + 1:head + 2 * kl2:2] = 0.0
        st[head + 1:head + kl2:2] = 0.0
    if trial % 4 == 2:
        st[head + rng.integers(3 * kl2)] = math.nan
    if trial % 4 == 3:
        st[head:head + 3 * kl2] = rng.choice([0.0, -0.0, 1.0], size=3 * kl2)
    st[rk.S_RES:rk.S_RES + 2] = rng.choice([rng.normal(), 0.0, -1.0, math.nan], size=2)
    st[rk.S_RES + 2] = 10.0 + trial if trial % 2 else 9.0
    return st


def _both_fit(ref, got, st) -> AttitudeEstimate:
    """The numpy fit and the compiled one of the state ``st``: the same estimate (every field,
    its mean gain too) and the same best model tracked."""
    ref._state[:], got._state[:] = st, st
    want, have = ref._fit(), got._fit()
    assert repr(want) == repr(have)
    assert repr((want.gain_mean, want.gain_mean_std)) == repr((have.gain_mean,
                                                               have.gain_mean_std))
    assert ref._state.tobytes() == got._state.tobytes()  # the best model tracked
    return have


def test_the_compiled_fit_on_odd_sums():
    """Axes never moved, NaN and ±0 in the sums, an odd residual: the grid's fit and the
    estimate (``response_kernels.fit_estimate``) are what numpy made, on the full grid and on
    short ones — no delay far enough for a rival (0–0.05 s), a few (0–0.07 s), two delays (a
    neighbour at Python's index −1)."""
    rng = np.random.default_rng(7)
    for max_delay_s in (0.6, 0.05, 0.07, 0.01):
        fits = 0
        for trial in range(40):
            ref = _NumpyFeed(E, max_delay_s=max_delay_s)
            got = AttitudeResponseEstimator(E, max_delay_s=max_delay_s)
            fits += math.isfinite(_both_fit(ref, got, _odd_sums(rng, ref, trial)).delay_s)
        assert fits > 20


def test_the_compiled_estimate_of_a_stream_on_short_grids():
    """A stream's estimates on grids with no rival delay (0–0.05 s), some (0–0.07 s) and two
    delays: numpy's, every field; a contrast only where a rival exists."""
    for max_delay_s, rivals in ((0.05, False), (0.07, True), (0.01, False)):
        ref = _NumpyFeed(E, max_delay_s=max_delay_s)
        got = AttitudeResponseEstimator(E, max_delay_s=max_delay_s)
        contrasts = []
        for i, ev in enumerate(_stream(9)[:6000]):
            _feed_both(ref, got, ev)
            if i % 50 == 0:
                assert repr(ref.estimate) == repr(got.estimate)
                if math.isfinite(got.estimate.delay_s):
                    contrasts.append(got.estimate.delay_contrast)
        assert len(contrasts) > 50
        assert any(map(math.isfinite, contrasts)) == rivals


def test_the_compiled_estimate_without_one_and_on_ties():
    """Fewer than 20 samples (or no sample), nothing moved: no estimate, the state untouched
    with too few; sums alike at every grid point (a tie: the first) or at every rival; a
    grid of one delay fails as Python's neighbour did."""
    rng = np.random.default_rng(3)
    ref, got = _NumpyFeed(E), AttitudeResponseEstimator(E)
    st = _odd_sums(rng, ref, 0)
    for n in (0.0, 19.999):
        st[rk.S_N] = n
        got._state[:] = st
        assert got._fit() is NO_ESTIMATE and ref._fit() is NO_ESTIMATE
        assert got._state.tobytes() == st.tobytes()
    st[rk.S_N] = math.nan  # not fewer than 20: fitted, NaN everywhere, as numpy did
    _both_fit(ref, got, st)
    kl2 = ref._sx.size
    flat = st.copy()
    flat[rk.S_N] = 40.0
    sx = flat[rk.HEAD:rk.HEAD + kl2]
    flat[rk.HEAD + kl2:rk.HEAD + 2 * kl2] = sx * sx / 40.0  # Σx² = (Σx)²/n: nothing moved
    _both_fit(ref, got, flat)
    assert got._fit() is NO_ESTIMATE
    L = len(ref.lags_s)
    for trial in range(20):
        tie = _odd_sums(rng, ref, trial)
        sums = tie[rk.HEAD:rk.HEAD + 3 * kl2].reshape(3, -1, L, 2)
        if trial % 2:
            sums[:] = sums[:, :1]  # every delay alike: a tie along the whole curve
        else:
            sums[:, 20:] = sums[:, 20:21]  # the rivals of the best alike
        _both_fit(ref, got, tie)
    one_ref = _NumpyFeed(E, max_delay_s=0.0)
    one_got = AttitudeResponseEstimator(E, max_delay_s=0.0)
    st = _odd_sums(rng, one_ref, 0)
    for est in (one_ref, one_got):
        est._state[:] = st
        with pytest.raises(IndexError):
            est._fit()


def test_the_compiled_estimate_through_its_entry_point_and_a_copy(monkeypatch):
    """The estimate's first call goes through numba's dispatcher, the next through the
    compiled entry point; a copy (no entry point pickled) binds it again: the same fits."""
    import copy

    from ardrone_nmpc.core import entry_points
    from ardrone_nmpc.estimation import attitude_response as ar

    rng = np.random.default_rng(11)
    ref = _NumpyFeed(E)
    monkeypatch.setattr(entry_points, "entry_point", lambda *args: None)  # as if not compiled
    got = AttitudeResponseEstimator(E)
    monkeypatch.undo()
    first = got._fit_step  # the dispatcher's first call
    for trial in range(6):
        _both_fit(ref, got, _odd_sums(rng, ref, trial))
        entry = ar._FIT.entry_for(got._state, got._fit_out)
        assert entry is not None and got._fit_step is entry and entry is not first
        got = copy.deepcopy(got)


def test_times_the_kernel_leaves_to_pythons_round():
    """Times below 1 µs (a flight's first command at 0) or beyond 2⁴⁰ µs, NaN: the compiled
    step answers −1 and the times are rounded by ``round`` and fed again — the numpy step's
    bits, whichever of the two rounded them."""
    early = [("cmd", 0.0, 0.1, 0.2), ("nav", 2e-7, 1.0, 1.0), ("cmd", 6e-7, -0.1, 0.3),
             ("nav", 8e-7, 0.5, 0.2), ("cmd", 1.4e-6, 0.2, 0.2), ("nav", 1.6e-6, 0.4, 0.1),
             ("cmd", math.nan, 0.1, 0.1), ("nav", math.nan, 0.3, 0.3)]
    late = [(kind, t + 2.0 ** 41 / 1e6, *rest) for kind, t, *rest in _stream(6)[:400]]
    for events in (early + _stream(5), late):
        ref, got = _NumpyFeed(E), AttitudeResponseEstimator(E)
        for ev in events:
            _feed_both(ref, got, ev)
        _same(ref, got)
        assert repr(ref.estimate) == repr(got.estimate)


def test_the_compiled_entry_point_takes_numbers_as_float_makes_them():
    """Once compiled, the step is called through its entry point (no look-up of the
    arguments' types): it makes ints, numpy scalars and bools floats as ``float`` does (what
    the dispatcher's one signature is called with) — the same bits."""
    from ardrone_nmpc.estimation import attitude_response as ar

    ref, got = AttitudeResponseEstimator(E), AttitudeResponseEstimator(E)
    kinds = (int, np.float32, np.float64, np.int64, lambda v: bool(v > 0.0), float)
    for i, ev in enumerate(_stream(8)[:4000]):
        kind = kinds[i % len(kinds)]
        values = [kind(v) if math.isfinite(v) else v for v in ev[2:]]  # (no NaN int)
        if ev[0] == "cmd":
            ref.command(np.float64(ev[1]), *(float(v) for v in values))
            got.command(np.float64(ev[1]), *values)
        elif ev[0] == "restart":
            ref.restart()
            got.restart()
        else:
            assert ref.navdata(ev[1], *(float(v) for v in values)) == got.navdata(ev[1],
                                                                                  *values)
        assert ref._state.tobytes() == got._state.tobytes()
    entry = ar._FEED.entry_for(got._state)
    assert entry is not None and got._step is entry and ref._step is entry


def test_the_compiled_mean_gain_is_pythons_to_the_bit():
    """``fit_estimate``'s mean gain and its σ (``response_kernels._gain_means``) against
    ``AttitudeEstimate.gain_mean`` and ``gain_mean_std`` on odd gains and σ (NaN, ±inf, ±0,
    the 1e-9 floor, squares ``pow`` rounds unlike x · x): the same bits; where a weight's
    square overflows it makes none, and the estimate raises when read, as Python's ``**``."""
    import random

    from ardrone_nmpc.core.numerics import callable_from_python

    means = callable_from_python(rk._gain_means)
    rng = random.Random(5)
    odd = [0.0, -0.0, math.nan, math.inf, -math.inf, 1e-12, 1e-9, 5e-10, 1e-300, 1e155]
    answer = np.zeros(rk.ESTIMATE_ANSWER)
    made = 0
    for _ in range(20_000):
        gain, std = ([rng.choice(odd) if rng.random() < 0.3
                      else rng.uniform(-2.0, 2.0) * 10.0 ** rng.randint(-12, 3)
                      for _ in range(2)] for _ in range(2))
        answer[2:6] = gain + std
        answer[10:12] = -7.0
        ours = AttitudeEstimate(0.1, 0.01, tuple(gain), tuple(std), 0.1, 0.5, 50.0)
        if means(answer, 2.0):
            made += 1
            assert repr(answer[10:12].tolist()) == repr([ours.gain_mean, ours.gain_mean_std])
            fitted = AttitudeEstimate._fitted(0.1, 0.01, tuple(gain), tuple(std), 0.1, 0.5,
                                              50.0, math.inf, *answer[10:12].tolist(), 1.0)
            assert fitted.__dict__ == {**ours.__dict__, "delay_contrast": math.inf} or (
                repr(fitted) == repr(AttitudeEstimate(0.1, 0.01, tuple(gain), tuple(std), 0.1,
                                                      0.5, 50.0, math.inf)))
        else:  # left to the properties: each raises where Python's did (σ's at least)
            assert answer[10:12].tolist() == [-7.0, -7.0]  # nothing written
            fitted = AttitudeEstimate._fitted(0.1, 0.01, tuple(gain), tuple(std), 0.1, 0.5,
                                              50.0, 0.0, 0.0, 0.0, 0.0)
            assert "gain_mean" not in fitted.__dict__
            assert _read(fitted, "gain_mean") == _read(ours, "gain_mean")
            assert _read(fitted, "gain_mean_std") == _read(ours, "gain_mean_std") == "raised"
    assert 15_000 < made < 20_000


def _read(est: AttitudeEstimate, name: str) -> str:
    """An estimate's property, its repr or "raised" (an OverflowError)."""
    try:
        return repr(getattr(est, name))
    except OverflowError:
        return "raised"


def test_an_estimate_the_kernel_made_is_one_init_makes():
    """``AttitudeEstimate._fitted`` (the kernel's answer, without the frozen ``__init__``):
    equal, the same repr and hash, frozen, its mean gain kept as the first read keeps it."""
    import dataclasses

    fields = (0.2, 0.01, (0.9, 1.1), (0.02, math.inf), 0.06, 0.7, 300.0, 12.0)
    made = AttitudeEstimate(*fields)
    fitted = AttitudeEstimate._fitted(*fields, made.gain_mean, made.gain_mean_std, 1.0)
    assert fitted == made and repr(fitted) == repr(made) and hash(fitted) == hash(made)
    assert fitted.__dict__ == made.__dict__
    with pytest.raises(dataclasses.FrozenInstanceError):
        fitted.delay_s = 0.3


def test_the_state_heads_slots_are_apart():
    """Every slot of the state's head its own (a two-wide scratch once covered the flag of an
    unordered command time: every fold set it, and each sample took the binary search), and a
    stream's folds leave the flag down while its times ascend."""
    wide = {rk.S_R: 2, rk.S_G: 2, rk.S_B: 2, rk.S_RES: 3, rk.S_SY: 2, rk.S_SYY: 2, rk.S_Y: 2,
            rk.S_X: 2}
    starts = [getattr(rk, name) for name in rk.__all__ if name.startswith("S_")]
    cells = [s + i for s in starts for i in range(wide.get(s, 1))]
    assert len(cells) == len(set(cells)) and max(cells) < rk.HEAD
    est = AttitudeResponseEstimator(E)
    for ev in _stream(2)[:3000]:
        if ev[0] == "cmd":
            est.command(*ev[1:])
        elif ev[0] == "nav":
            est.navdata(*ev[1:])
    assert est._state[rk.S_HAS_BEST] == 1.0 and est._state[rk.S_UNORDERED] == 0.0
