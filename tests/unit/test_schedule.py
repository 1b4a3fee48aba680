"""ardrone_nmpc.runtime.schedule: tick counts against exact rational arithmetic, the phase
label, refused times, event stamping; and the lockstep run flying exactly that schedule."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.schema import config_from_dict

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.record import record_lockstep
from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.runtime import schedule as sched
from ardrone_nmpc.runtime.schedule import Schedule, ScheduleError, phase
from ardrone_nmpc.runtime.session import FlightSession
from tests.conftest import ManualClock

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
PERIODS = ("0.065", "0.05", "0.1", "0.03", "0.02", "0.001")


@pytest.mark.parametrize("period", PERIODS)
def test_settle_ticks_are_the_exact_ceiling_of_settle_over_period(period):
    """Decimal settle times that are whole ticks must not gain a tick from float round-off
    (0.3 / 0.1 = 3.0000000000000004); the others round up."""
    p = Fraction(period)
    for k in range(0, 400):
        settle = f"{k * 0.005:.3f}"
        expected = math.ceil(Fraction(settle) / p)
        got = Schedule.of(settle_s=float(settle), duration_s=1.0, period_s=float(period))
        assert got.n_settle == expected, (settle, period)


@pytest.mark.parametrize("period", PERIODS)
def test_the_experiment_is_duration_over_period_rounded_plus_its_last_tick(period):
    p = Fraction(period)
    for k in range(1, 300):
        duration = f"{k * 0.0137:.4f}"
        ratio = Fraction(duration) / p
        if abs(ratio - math.floor(ratio) - Fraction(1, 2)) < Fraction(1, 10**6):
            continue  # a tie: float round-off decides, nothing exact to compare with
        expected = round(ratio)
        got = Schedule.of(settle_s=0.0, duration_s=float(duration), period_s=float(period))
        assert got.n_ticks == expected + 1, (duration, period)


def test_tick_times_put_experiment_time_zero_on_tick_n_settle():
    s = Schedule.of(settle_s=0.5, duration_s=3.5, period_s=0.065)
    assert (s.n_settle, s.n_ticks) == (8, 8 + 54 + 1)
    assert s.t_exp_s(s.n_settle) == 0.0
    assert s.t_exp_s(0) == -s.settle_span_s == -8 * 0.065
    assert s.t_exp_s(s.n_ticks - 1) == pytest.approx(54 * 0.065)
    assert s.fraction_done(s.n_ticks - 1) == 1.0
    assert s.fraction_done(0) == pytest.approx(1 / 63)


@pytest.mark.parametrize("settle, duration, period", [
    (0.5, 3.5, 0.065), (0.0, 1.0, 0.0625), (0.3, 0.0, 0.1), (1.0, 2.0, 1 / 3), (2.0, 0.5, 0.7)])
def test_the_settle_ticks_are_the_first_n_settle_and_the_last_tick_is_at_the_duration(
        settle, duration, period):
    """The runner's loop asks ``phase(t_exp_s(k))`` for every k (blocks jump in k): the
    first ``n_settle`` ticks settle, the others track, the last at ``duration_s`` (whole
    ticks)."""
    s = Schedule.of(settle_s=settle, duration_s=duration, period_s=period)
    phases = [phase(s.t_exp_s(k)) for k in range(s.n_ticks)]
    assert phases == ["settle"] * s.n_settle + ["track"] * (s.n_ticks - s.n_settle)
    assert s.t_exp_s(s.n_settle) == 0.0
    assert s.t_exp_s(s.n_ticks - 1) == pytest.approx(round(duration / period) * period)


def test_phase_is_settle_before_zero_and_track_from_zero():
    assert [phase(t) for t in (-1.0, -1e-300, -0.0, 0.0, 1e-300, 5.0)] == [
        "settle", "settle", "track", "track", "track", "track"]


def test_from_config_reads_settle_duration_and_period():
    cfg = load_config(CONFIGS / "step_x.yaml", ["duration_s=2", "sim.settle_s=0.3",
                                                 "loop.period_s=0.05"])
    assert Schedule.from_config(cfg) == Schedule.of(settle_s=0.3, duration_s=2.0, period_s=0.05)
    assert Schedule.from_config(cfg) == Schedule(0.05, 6, 6 + 40 + 1)


@pytest.mark.parametrize("settle, duration, period, field", [
    (1e308, 10.0, 0.065, "sim.settle_s"),
    (1.0, 1e308, 0.065, "duration_s"),
    (math.inf, 10.0, 0.065, "sim.settle_s"),
    (1.0, math.nan, 0.065, "duration_s"),
    (-0.5, 10.0, 0.065, "sim.settle_s"),
    (1.0, 10.0, 0.0, "loop.period_s"),
    (1.0, 10.0, math.nan, "loop.period_s"),
    (1.0, 10.0, 5e-324, "sim.settle_s"),  # a subnormal period: 1 / 5e-324 overflows
    (1.0, 2.0 ** 52, 0.5, "duration_s"),  # finite, but more ticks than doubles count
    (2.0 ** 51, 2.0 ** 51, 0.5, "sim.settle_s + duration_s"),
])
def test_times_without_a_tick_count_are_refused_naming_the_field(settle, duration, period,
                                                                  field):
    with pytest.raises(ScheduleError) as err:
        Schedule.of(settle_s=settle, duration_s=duration, period_s=period)
    assert isinstance(err.value, ValueError)
    assert str(err.value).startswith(field + " = ")
    assert "\n" not in str(err.value)


def test_the_largest_tick_count_is_still_taken():
    s = Schedule.of(settle_s=0.0, duration_s=2.0 ** 53 - 2.0, period_s=1.0)
    assert s.n_ticks == 2 ** 53 - 1 == sched.MAX_TICKS - 1
    s = Schedule.of(settle_s=0.0, duration_s=2.0 ** 53 - 1.0, period_s=1.0)
    assert s.n_ticks == sched.MAX_TICKS            # "at most MAX_TICKS": the bound itself
    with pytest.raises(ScheduleError):
        Schedule.of(settle_s=1.0, duration_s=2.0 ** 53 - 1.0, period_s=1.0)


def test_too_many_ticks_together_names_the_sum_of_the_times():
    with pytest.raises(ScheduleError) as err:
        Schedule.of(settle_s=2.0 ** 51, duration_s=2.0 ** 51, period_s=0.5)
    assert str(err.value).startswith(f"sim.settle_s + duration_s = {2.0 ** 52:g} s: ")


def test_timeouts_are_defined_once():
    assert FlightSession.TAKEOFF_TIMEOUT_S is sched.TAKEOFF_TIMEOUT_S
    # a real landing has no timeout (it goes on until navdata confirms it): only the
    # simulated one, whose plant cannot fail to land, gives up
    assert not hasattr(FlightSession, "LANDING_TIMEOUT_S")
    import ardrone_nmpc.runtime.lockstep as lockstep

    assert lockstep.LANDING_TIMEOUT_S is sched.LANDING_TIMEOUT_S


def test_events_are_stamped_with_experiment_time_on_every_clock():
    manual_clock = ManualClock()
    written = []
    events = [{"kind": "mode", "mode": "hover-stale-mocap", "previous": "track"}]
    sched.write_events(lambda t, kind, **f: written.append((t, kind, f)), -0.13, events)
    assert written == [(-0.13, "mode", {"mode": "hover-stale-mocap", "previous": "track"})]
    assert events[0]["kind"] == "mode"  # the tick's own dicts are left alone
    # the real-time run's clock: held until experiment time 0 is known, then stamped on it
    wall = []
    manual_clock.t = 100.0
    clock = sched.EventClock(lambda t, kind, **f: wall.append((t, kind, f)), manual_clock)
    manual_clock.t = 101.0
    clock.event("takeoff")
    assert wall == []                                       # no experiment time yet
    manual_clock.t = 104.0
    clock.start(104.5)                                      # t = 0 half a second from now
    sched.write_events(clock.at, 2.6, events)
    manual_clock.t = 110.0
    clock.event("landing", reason="end")
    assert wall == [(101.0 - 104.5, "takeoff", {"wall_s": 1.0}),
                    (2.6, "mode", {"wall_s": 4.0, "mode": "hover-stale-mocap",
                                   "previous": "track"}),
                    (5.5, "landing", {"wall_s": 10.0, "reason": "end"})]
    refused = []
    clock = sched.EventClock(lambda t, kind, **f: refused.append((t, kind, f)), manual_clock)
    clock.event("preflight_failed", check="battery", value=9.1)
    clock.close()                                           # the experiment never started
    assert len(refused) == 1 and math.isnan(refused[0][0])
    assert refused[0][1:] == ("preflight_failed", {"wall_s": 0.0, "check": "battery",
                                                   "value": 9.1})
    held = []   # a held event keeps its fields when experiment time 0 stamps it
    clock = sched.EventClock(lambda t, kind, **f: held.append((t, kind, f)), manual_clock)
    clock.event("connected", host="127.0.0.1", port=5556)
    clock.start(manual_clock.t + 1.0)
    assert held == [(-1.0, "connected", {"wall_s": 0.0, "host": "127.0.0.1", "port": 5556})]


def test_a_lockstep_run_flies_the_schedule_tick_for_tick(tmp_path):
    """Every logged tick of a completed run, at its schedule time, with its phase."""
    cfg = config_from_dict({"name": "sched", "duration_s": 1.3, "sim": {"settle_s": 0.3},
                            "reference": {"kind": "step", "target_m": [-0.3, 0.0, 1.0]}})
    s = Schedule.from_config(cfg)
    recording = record_lockstep(cfg, tmp_path)
    assert recording.result.ending == "completed" and recording.result.ticks == s.n_ticks
    run = read_run(recording.path)
    t = run.columns["t_s"]
    assert run.n_rows == s.n_ticks
    assert np.array_equal(t, [s.t_exp_s(k) for k in range(s.n_ticks)])
    assert list(run.columns["mode"]) == [phase(v) for v in t]
    assert sum(v < 0 for v in t) == s.n_settle == math.ceil(Fraction("0.3") / Fraction("0.065"))
