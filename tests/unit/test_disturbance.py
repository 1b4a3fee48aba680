"""Offset-free tracking: the reference-shift integrator (estimation/disturbance.py) and its stage.

Checked against closed forms: with a loop that settles at once (p = ref + Δ + s) the shift obeys
s_k = −Δ(1 − (1 − ki·T)^k) exactly; with a first-order loop τ·ė = −e + Δ + s the PI shift is
compared with scipy's ODE solution of the same continuous system. Anti-windup: nothing is
learnt before ``hold_s`` at rest, while frozen, outside the error band, or while the reference
(or its preview) moves; the shift stays within ``max_shift``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ardrone_nmpc.config.schema import OffsetFreeConfig
from ardrone_nmpc.control.mapping import DroneLimits, map_to_pcmd
from ardrone_nmpc.core.types import (IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z,
                                     AttitudeCommand)
from ardrone_nmpc.estimation.disturbance import ReferenceIntegrator, frozen_axes
from ardrone_nmpc.runtime.stages import OffsetFree, Sent, Solution
from ardrone_nmpc.safety import Action, Decision

T = 0.065
REF = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0])  # hover at (0, 0, 1), ψ = 0


def integrator(ki=(0.5, 0.5, 0.4, 0.15), kp=(0.0,) * 4, hold_s=(0.0,) * 4, period_s=T,
               band=(0.5, 0.5, 0.5, 0.3), speed=(0.15, 0.15, 0.05, 0.3), max_shift=(0.5,) * 4,
               steady=(math.inf,) * 4, release=(math.inf,) * 4):
    return ReferenceIntegrator(ki, band, speed, max_shift, hold_s, period_s, kp, release, steady)


def state(x=0.0, y=0.0, z=1.0, psi=0.0, vx=0.0, vz=0.0, vy=0.0) -> np.ndarray:
    s = np.zeros(7)
    s[IX_X], s[IX_Y], s[IX_Z], s[IX_PSI], s[IX_VX], s[IX_VZ] = x, y, z, psi, vx, vz
    s[IX_VY] = vy
    return s


def test_instant_loop_shift_follows_the_geometric_closed_form():
    """p = ref + Δ + s (a loop that settles within a tick): s_k = −Δ(1 − (1 − ki·T)^k)."""
    delta = np.array([0.07, -0.06, 0.19, 0.05])
    ki = np.array([0.5, 0.5, 0.4, 0.15])
    integ = integrator(ki=ki)
    for k in range(1, 400):
        s = integ.shift
        integ.update(state(*(delta[:3] + s[:3] + [0, 0, 1]), psi=delta[3] + s[3]), REF)
        expected = -delta * (1.0 - (1.0 - ki * T) ** k)
        np.testing.assert_allclose(integ.shift, expected, rtol=0, atol=1e-12)
    # "a constant disturbance is estimated to within 1 % in ln(100)/ki seconds"
    n = math.ceil(math.log(100.0) / (0.4 * T))
    integ = integrator(ki=(0.4,) * 4)
    for _ in range(n):
        s = integ.shift
        integ.update(state(*(delta[:3] + s[:3] + [0, 0, 1]), psi=delta[3] + s[3]), REF)
    assert np.all(np.abs(integ.shift + delta) <= 0.01 * np.abs(delta))


@pytest.mark.parametrize("kp", [0.0, 1.0])
def test_first_order_loop_matches_scipy(kp):
    """τ·ė = −e + Δ + s with s = I − kp·e, İ = −ki·e: the discrete integrator at a small
    period against scipy's solution of the continuous system (e from the loop, not from us)."""
    tau, ki, delta, h = 2.4, 0.4, 0.27, 0.001
    integ = integrator(ki=(0.0, 0.0, ki, 0.0), kp=(0.0, 0.0, kp, 0.0), period_s=h,
                       speed=(1.0,) * 4)
    e = delta  # at rest with the full offset when learning starts
    t_end = 20.0
    for _ in range(int(round(t_end / h))):
        s = integ.update(state(z=1.0 + e), REF)[2]
        e += h * (-e + delta + s) / tau  # explicit Euler of the loop

    def rhs(_t, y):
        e_, i_ = y
        return [(-e_ + delta + i_ - kp * e_) / tau, -ki * e_]

    sol = solve_ivp(rhs, (0.0, t_end), [delta, 0.0], rtol=1e-10, atol=1e-12)
    e_ref, i_ref = sol.y[:, -1]
    assert e == pytest.approx(e_ref, abs=2e-3 * delta)
    assert integ.shift[2] == pytest.approx(i_ref - kp * e_ref, abs=2e-3 * delta)
    assert abs(e) < 0.03 * delta  # and the offset is gone within 20 s


def test_nothing_is_learnt_before_hold_s_at_rest_then_it_learns():
    integ = integrator(hold_s=(1.0,) * 4)
    n_hold = math.floor(1.0 / T)  # learning starts once the time at rest exceeds hold_s
    for _ in range(n_hold):
        integ.update(state(x=0.1), REF)
        assert integ.shift[0] == 0.0 and not integ.learning[0]
    integ.update(state(x=0.1), REF)
    assert integ.learning[0] and integ.shift[0] == pytest.approx(-0.5 * 0.1 * T)


def test_a_converging_tail_does_not_start_learning_a_steady_offset_does():
    """e = 5 cm · e^(−t/τ), τ = 0.85 s (the y step's tail): it loses more than a fifth of
    itself in every 1.5 s hold, so it latches only once within the 2 mm steady band, and
    learns next to nothing; a steady 5 cm ± 2 mm latches after the hold."""
    tau_s = 0.85
    integ = integrator(hold_s=(1.5,) * 4, steady=(0.002,) * 4)
    for k in range(150):
        e = 0.05 * math.exp(-k * T / tau_s)
        integ.update(state(x=e, vx=-e / tau_s), REF)
        if e > 0.005:
            assert not integ.learning[0] and integ.shift[0] == 0.0
    assert abs(integ.shift[0]) < 2e-4
    integ = integrator(hold_s=(1.5,) * 4, steady=(0.002,) * 4)
    rng = np.random.default_rng(1)
    learnt = []
    for _ in range(100):
        integ.update(state(x=0.05 + rng.uniform(-0.002, 0.002)), REF)
        learnt.append(bool(integ.learning[0]))
    assert not any(learnt[:23]) and all(learnt[24:])  # after 1.5 s = 23 ticks at rest


def test_a_fast_motion_releases_a_learning_axis():
    integ = integrator(release=(0.3,) * 4)
    for _ in range(5):
        integ.update(state(x=0.1), REF)
    assert integ.learning[0]
    s = integ.shift[0]
    integ.update(state(x=0.2, vx=0.6), REF)  # a gust
    assert not integ.learning[0] and integ.shift[0] == s


def test_moving_too_fast_does_not_start_learning():
    integ = integrator()
    for _ in range(50):
        integ.update(state(x=0.1, vx=0.3), REF)  # beyond the 0.15 m/s speed band
    assert integ.shift[0] == 0.0 and not integ.learning[0]


def test_frozen_axes_keep_their_shift_and_resume_where_they_were():
    integ = integrator()
    for _ in range(10):
        integ.update(state(x=0.1, z=1.1), REF)
    before = integ.shift.copy()
    for _ in range(30):  # saturated tilt: x and y frozen, z goes on
        integ.update(state(x=0.1, z=1.1), REF, frozen=(True, True, False, False))
    assert integ.shift[0] == before[0] and integ.shift[1] == before[1]
    assert integ.shift[2] < before[2]
    integ.update(state(x=0.1, z=1.1), REF)
    assert integ.shift[0] == pytest.approx(before[0] - 0.5 * 0.1 * T)


def test_the_tick_step_freezes_one_period_only():
    """``step`` hands a frozen axis to the kernel in a row the kernel clears, and the usual
    tick's nothing-frozen tuple is not written: after a frozen period the next unfrozen one
    integrates again, as ``update`` (every flag passed) does."""
    tick, twin = integrator(), integrator()
    free = frozen_axes((0.0, 0.0, 0.0, 0.0), "0000")  # the usual tick's
    x = state(x=0.1, z=1.1)
    for frozen in [free] * 5 + [(True, True, False, False)] * 3 + [free] * 2 + [
            (False, False, True, True), free, (True,) * 4, free, free]:
        tick.step(x, REF, frozen, None)
        twin.update(x, REF, frozen=tuple(bool(f) for f in frozen))
        assert tick.shift.tobytes() == twin.shift.tobytes()
        assert list(tick.learning) == [not f for f in frozen]
        assert not tick._flags[2].any()  # cleared for the next period


def test_a_moving_reference_or_preview_stops_learning_and_needs_a_new_hold():
    integ = integrator(hold_s=(0.5,) * 4)
    for _ in range(20):
        integ.update(state(x=0.1), REF)
    assert integ.learning[0]
    preview = np.tile(REF, (16, 1))
    preview[-1, IX_X] = 1.0  # a step ahead in the NMPC's horizon
    s = integ.shift[0]
    integ.update(state(x=0.1), REF, preview=preview)
    assert not integ.learning[0] and integ.shift[0] == s
    assert integ.learning[1] and integ.learning[2]  # the other axes did not move
    moved = REF.copy()
    moved[IX_X] = 1.0
    for _ in range(math.floor(0.5 / T)):
        integ.update(state(x=1.05), moved)
        assert not integ.learning[0] and integ.shift[0] == s


def test_large_errors_are_not_integrated_and_the_shift_is_clipped():
    integ = integrator(max_shift=(0.05,) * 4)
    for _ in range(10):
        integ.update(state(x=0.6), REF)  # outside the 0.5 m band: a transient
    assert integ.shift[0] == 0.0
    for _ in range(1000):
        integ.update(state(x=0.4, z=0.6), REF)
    assert integ.shift[0] == -0.05 and integ.shift[2] == 0.05


def test_psi_error_wraps_the_short_way():
    integ = integrator()
    ref = REF.copy()
    ref[IX_PSI] = math.pi - 0.01
    integ.update(state(psi=-math.pi + 0.01), ref)  # 0.02 rad ahead, not 2π − 0.02
    assert integ.errors(state(psi=-math.pi + 0.01), ref)[3] == pytest.approx(0.02)
    assert integ.shift[3] == pytest.approx(-0.15 * 0.02 * T)


def test_shifted_moves_only_the_position_and_heading_columns():
    integ = integrator()
    integ.shift[:] = [0.1, -0.2, 0.3, 0.05]
    ref = np.tile(REF, (3, 1))
    out = integ.shifted(ref)
    assert out is not ref and np.all(ref == np.tile(REF, (3, 1)))
    cols = [IX_X, IX_Y, IX_Z, IX_PSI]
    np.testing.assert_array_equal(out[:, cols], ref[:, cols] + [0.1, -0.2, 0.3, 0.05])
    others = [i for i in range(7) if i not in (IX_X, IX_Y, IX_Z, IX_PSI)]
    np.testing.assert_array_equal(out[:, others], ref[:, others])


@pytest.mark.parametrize("fracs, flags, frozen", [
    ((0.2, -0.3, 0.1, 0.0), "0000", (False, False, False, False)),
    ((1.0, 0.0, 0.0, 0.0), "1000", (True, True, False, False)),
    ((0.0, -0.9995, 0.0, 0.0), "0000", (True, True, False, False)),  # on the limit, unflagged
    ((0.0, 0.0, 1.0, 0.0), "0000", (False, False, True, False)),      # ż clipped before mapping
    ((0.0, 0.0, 0.0, 0.3), "0001", (False, False, False, True)),
])
def test_frozen_axes_of_a_command(fracs, flags, frozen):
    assert frozen_axes(fracs, flags) == frozen


LIMITS = DroneLimits()


def _sent(action: Action, cmd=AttitudeCommand(0.0, 0.0, 0.0, 0.0)) -> Sent:
    pcmd = map_to_pcmd(cmd, LIMITS)
    return Sent(pcmd, np.zeros(4), True, Decision(action), cmd,
                "".join("1" if f else "0" for f in pcmd.saturated))


@pytest.mark.parametrize("action", [Action.HOLD, Action.HOVER, Action.LAND, Action.FALLBACK,
                                    Action.STOP])
def test_stage_is_frozen_unless_the_nmpc_flew(action):
    stage = OffsetFree(OffsetFreeConfig(hold_s=(0.0,) * 4), T)
    sol = Solution(REF, state())
    for _ in range(20):
        stage.update(state(x=0.1), sol, _sent(action))
    assert np.all(stage.integrator.shift == 0.0) and not stage.integrator.learning.any()
    stage.update(state(x=0.1), sol, _sent(Action.CONTROL))
    assert stage.integrator.shift[0] < 0.0


def test_stage_freezes_x_and_y_on_a_saturated_tilt():
    stage = OffsetFree(OffsetFreeConfig(hold_s=(0.0,) * 4), T)
    sol = Solution(REF, state())
    for _ in range(20):
        stage.update(state(x=0.1, z=1.1), sol,
                     _sent(Action.CONTROL, AttitudeCommand(0.0, 0.0, 0.5, 0.0)))  # > 0.21 rad
    assert stage.integrator.shift[0] == 0.0 and stage.integrator.shift[2] < 0.0


@pytest.mark.parametrize("override, enabled", [
    ("controller.offset_free=false", False), ("controller.offset_free=true", True),
    ("controller.offset_free.enabled=false", False)])
def test_offset_free_switch_and_its_bool_shorthand(override, enabled):
    from ardrone_nmpc.config.io import load_config

    cfg = load_config(None, [override])
    assert cfg.controller.offset_free.enabled is enabled
    assert cfg.controller.offset_free.ki_per_s == OffsetFreeConfig().ki_per_s


# --- the bugs a developer writes: windup, one-sided checks, crossed axes, units, edges -----

def test_after_windup_a_reversed_error_moves_the_shift_off_its_limit_at_once():
    """The integral itself is clipped, not only the shift: once the error reverses, the shift
    leaves −max_shift on the next tick by ki·|e|·T a tick (a wound-up integral would hold it
    on the limit for as long as it had been pushed beyond)."""
    ki, lim, e = 0.5, 0.05, 0.1
    integ = integrator(ki=(ki,) * 4, max_shift=(lim,) * 4)
    for _ in range(2000):  # 130 s pushing against the limit
        integ.update(state(x=0.4), REF)
    assert integ.shift[0] == -lim
    for k in range(1, 31):
        integ.update(state(x=-e), REF)
        assert integ.learning[0]
        assert integ.shift[0] == pytest.approx(-lim + k * ki * e * T, abs=1e-12)


@pytest.mark.parametrize("axis, kwargs", [
    (0, {"vx": 0.6}), (0, {"vx": -0.6}), (1, {"vy": 0.6}), (1, {"vy": -0.6}),
    (2, {"vz": 0.6}), (2, {"vz": -0.6})])
def test_a_gust_either_way_releases_its_axis_only(axis, kwargs):
    integ = integrator(release=(0.3,) * 4)
    for _ in range(5):
        integ.update(state(x=0.1, y=0.1, z=1.1), REF)
    assert integ.learning[:3].all()
    before = integ.shift.copy()
    integ.update(state(x=0.1, y=0.1, z=1.1, **kwargs), REF)
    assert not integ.learning[axis] and integ.shift[axis] == before[axis]
    others = [k for k in range(3) if k != axis]
    assert integ.learning[others].all()


@pytest.mark.parametrize("axis, kwargs", [(0, {"vx": 0.3}), (1, {"vy": 0.3}),
                                          (1, {"vy": -0.3}), (2, {"vz": 0.3})])
def test_each_axis_is_at_rest_on_its_own_rate(axis, kwargs):
    """ė per axis: x from ẋ, y from ẏ, z from ż — a moving axis does not start learning,
    the still ones do."""
    integ = integrator(hold_s=(0.2,) * 4, speed=(0.15, 0.15, 0.15, 0.3))
    for _ in range(10):
        integ.update(state(x=0.1, y=0.1, z=1.1, **kwargs), REF)
    assert not integ.learning[axis] and integ.shift[axis] == 0.0
    others = [k for k in range(3) if k != axis]
    assert integ.learning[others].all()


def _psi_ramp(rate_radps: float, ticks: int, **kw) -> ReferenceIntegrator:
    """ψ error ramping at ``rate_radps`` (inside the band) from 0.05 rad."""
    integ = integrator(**kw)
    for k in range(ticks):
        integ.update(state(x=0.1, psi=0.05 + rate_radps * k * T), REF)
    return integ


def test_the_heading_rate_is_per_second():
    """ψ's ė is the change of its error over one period divided by the period: a drift of
    0.2 rad/s (0.013 rad a tick) is beyond a 0.1 rad/s speed band, 0.05 rad/s is inside."""
    kw = {"hold_s": (0.3,) * 4, "speed": (0.15, 0.15, 0.05, 0.1)}
    fast = _psi_ramp(0.2, 20, **kw)
    assert not fast.learning[3] and fast.shift[3] == 0.0
    assert fast.learning[0]  # x was at rest all along
    slow = _psi_ramp(0.05, 20, **kw)
    assert slow.learning[3] and slow.shift[3] < 0.0


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_fast_heading_change_either_way_releases_psi(sign):
    integ = integrator(release=(0.3, 0.3, 0.3, 0.5))
    for _ in range(5):
        integ.update(state(psi=0.1), REF)
    assert integ.learning[3]
    s = integ.shift[3]
    integ.update(state(psi=0.1 + sign * 0.05), REF)  # 0.77 rad/s
    assert not integ.learning[3] and integ.shift[3] == s
    integ = integrator(release=(0.3, 0.3, 0.3, 0.5))
    for _ in range(5):
        integ.update(state(psi=0.1), REF)
    integ.update(state(psi=0.1 + sign * 0.02), REF)  # 0.31 rad/s: still learning
    assert integ.learning[3]


def test_a_reference_that_moves_stops_learning_on_that_tick():
    integ = integrator()
    for _ in range(5):
        integ.update(state(x=0.1), REF)
    assert integ.learning[0]
    s = integ.shift[0]
    moved = REF.copy()
    moved[IX_X] = 0.01
    integ.update(state(x=0.11), moved)
    assert not integ.learning[0] and integ.shift[0] == s
    assert integ.learning[1:].all()


def test_the_edges_of_the_bands_are_outside_them():
    """|e| < error_band, |ė| < speed_band to be at rest; a release needs |ė| > release_speed;
    a reference (or its preview) moves when it changes by more than 1e-9."""
    integ = integrator()
    integ.update(state(x=0.5), REF)  # exactly on the 0.5 m band
    assert not integ.learning[0]
    integ = integrator(hold_s=(0.1,) * 4)
    for _ in range(10):
        integ.update(state(x=0.1, vx=0.15), REF)  # exactly the 0.15 m/s speed band
    assert not integ.learning[0]
    integ = integrator(release=(0.3,) * 4)
    for _ in range(3):
        integ.update(state(x=0.1), REF)
    integ.update(state(x=0.1, vx=0.3), REF)  # exactly the release speed: no release
    assert integ.learning[0]
    integ = integrator()
    still = REF.copy()
    for k in range(4):  # steps of exactly 1e-9 in x: not a move
        still[IX_X] = 1e-9 * (k % 2)
        preview = np.tile(still, (3, 1))
        preview[-1, IX_Y] = still[IX_Y] + 1e-9
        integ.update(state(x=0.1), still, preview=preview)
    assert integ.learning[0] and integ.learning[1]


def test_a_range_exactly_the_steady_band_wide_is_steady():
    integ = integrator(hold_s=(0.5,) * 4, band=(1.0,) * 4, steady=(0.125,) * 4)
    for k in range(10):
        integ.update(state(x=0.25 if k % 2 else 0.375), REF)  # range exactly 0.125
    assert integ.learning[0]


def _ticks_to_learn(integ, errors) -> int:
    """The first tick (1-based) on which x learns while its error goes through ``errors``."""
    for k, e in enumerate(errors, start=1):
        integ.update(state(x=e), REF)
        if integ.learning[0]:
            return k
    return 0


def test_a_rest_that_restarts_learns_hold_s_after_the_restart():
    """Learning starts on the first tick at which the time at rest exceeds hold_s — counted
    from the last restart (a range beyond the steady band), the range then measured from the
    restart's error."""
    kw = {"hold_s": (1.0,) * 4, "steady": (0.002,) * 4}
    # 3 ticks at 5 cm, then 3 cm for good: the drop restarts the rest on tick 4
    assert _ticks_to_learn(integrator(**kw), [0.05] * 3 + [0.03] * 30) == 3 + 16
    # a new rest after a fast tick forgets the last rest's range: 4.5 cm then 4.1 cm is
    # steady (0.004 ≤ 0.2·4.1 cm), whereas 5 cm … 4.1 cm would not be
    integ = integrator(**kw)
    for _ in range(5):
        integ.update(state(x=0.05), REF)
    integ.update(state(x=0.05, vx=0.3), REF)
    assert _ticks_to_learn(integ, [0.045] + [0.041] * 30) == 16


def test_from_config_takes_every_field_to_its_axis():
    cfg = OffsetFreeConfig(ki_per_s=(0.1, 0.2, 0.3, 0.4), kp=(0.5, 0.6, 0.7, 0.8),
                           error_band=(0.11, 0.12, 0.13, 0.14), hold_s=(1.1, 1.2, 1.3, 1.4),
                           steady_band=(0.021, 0.022, 0.023, 0.024),
                           speed_band=(0.31, 0.32, 0.33, 0.34),
                           release_speed=(0.41, 0.42, 0.43, 0.44),
                           max_shift=(0.51, 0.52, 0.53, 0.54))
    integ = ReferenceIntegrator.from_config(cfg, 0.05)
    assert integ.period_s == 0.05
    for name in ("ki_per_s", "kp", "error_band", "hold_s", "steady_band", "speed_band",
                 "release_speed", "max_shift"):
        np.testing.assert_array_equal(getattr(integ, name), getattr(cfg, name), err_msg=name)


def test_shifted_integer_states_come_back_as_floats():
    integ = integrator()
    integ.shift[:] = [0.25, -0.5, 0.75, 0.125]
    out = integ.shifted(np.zeros((2, 7), dtype=int))
    assert out.dtype == float
    np.testing.assert_array_equal(out[:, [IX_X, IX_Y, IX_Z, IX_PSI]],
                                  [[0.25, -0.5, 0.75, 0.125]] * 2)


def test_a_fraction_exactly_on_the_saturation_threshold_freezes():
    assert frozen_axes((0.0, 0.0, 0.999, -0.999), None) == (False, False, True, True)


def test_per_axis_vectors_are_four_floats():
    integ = integrator(ki=(1, 1, 0, 0), hold_s=(0, 0, 0, 0))
    assert integ.ki_per_s.dtype == float and integ.hold_s.dtype == float
    with pytest.raises(ValueError, match="one value per axis"):
        integrator(ki=(0.5, 0.5, 0.4))
    with pytest.raises(ValueError, match="one value per axis"):
        integrator(max_shift=(0.5,) * 5)


def test_frozen_axes_is_its_rule_everywhere():
    """The shortcut for the usual tick (all inside, nothing flagged) against the rule written
    out: every combination of values at, inside and beyond the limit, NaN, and flags."""
    import itertools

    from ardrone_nmpc.estimation.disturbance import SATURATION_FRAC

    def rule(fracs, flags):
        s = [abs(v) >= SATURATION_FRAC for v in fracs]
        if flags and flags != "0000":
            s = [a or c == "1" for a, c in zip(s, flags)]
        return (s[0] or s[1], s[0] or s[1], s[2], s[3])

    values = (0.0, -0.0, 0.5, -0.5, SATURATION_FRAC, -SATURATION_FRAC,
              math.nextafter(SATURATION_FRAC, 0.0), -math.nextafter(SATURATION_FRAC, 0.0),
              1.0, -1.0, math.nan, math.inf)
    for flags in (None, "", "0000", "1000", "0100", "0010", "0001", "1111"):
        for fracs in itertools.product(values, repeat=4):
            assert frozen_axes(fracs, flags) == rule(fracs, flags), (fracs, flags)


@pytest.mark.parametrize("how", ["deepcopy", "pickle", "copy"])
def test_a_copy_of_the_integrator_integrates_into_its_own_public_arrays(how):
    """shift, latched, learning (and the carry, the law, the period) are views of the kernel's
    buffers: a copy's must be views of the copy's buffers, else the copy's kernel writes
    where its ``shift`` (what ``update`` returns, what ``shifted`` adds) never sees it."""
    import copy
    import pickle

    integ = ReferenceIntegrator((0.5,) * 4, (1.0,) * 4, (1.0,) * 4, (1.0,) * 4, (0.0,) * 4,
                                0.1)
    twin = ReferenceIntegrator((0.5,) * 4, (1.0,) * 4, (1.0,) * 4, (1.0,) * 4, (0.0,) * 4,
                               0.1)
    x, ref = np.zeros(7), np.zeros(7)
    x[IX_X] = 0.2
    for _ in range(3):
        integ.update(x, ref)
        twin.update(x, ref)
    other = {"deepcopy": copy.deepcopy, "pickle": lambda o: pickle.loads(pickle.dumps(o)),
             "copy": copy.copy}[how](integ)
    if how == "copy":  # a shallow copy shares the buffers (as it shared the arrays before)
        assert other._work is integ._work
        return
    other.period_s = 0.1
    for _ in range(3):
        shift = other.update(x, ref)
        twin.update(x, ref)
    assert shift is other.shift and other.shift.tolist() == twin.shift.tolist()
    assert other.latched.tolist() == twin.latched.tolist()
    assert other.learning.tolist() == twin.learning.tolist()
    assert np.shares_memory(other.shift, other._work)
    assert np.shares_memory(other._carry, other._work)
    assert np.shares_memory(other.latched, other._flags)
    assert integ.shift.tolist() != other.shift.tolist()  # the original untouched by the copy
