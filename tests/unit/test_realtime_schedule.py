"""The real-time loop flies the schedule tick for tick (runtime/realtime.py ``_control_loop``).

The loop runs on a manual clock (its Rate, its ``time.monotonic`` and its event clock on one
the test advances), against stand-ins of the tick and the opened drone that only record what
the loop asks of them: the number of ticks, their experiment times and phases, skipped
deadlines, and the instant the drone (whose injected faults run on it) and the event clock are
told experiment time 0 starts.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.mapping import PcmdCommand
from ardrone_nmpc.links.backend import OpenedDrone
from ardrone_nmpc.core.clock import Rate
from ardrone_nmpc.runtime import realtime
from ardrone_nmpc.runtime.schedule import EventClock, Schedule, phase
from ardrone_nmpc.runtime.tick import TickOutput
from ardrone_nmpc.safety import Action
from tests.conftest import ManualClock

PERIOD_S = 0.05


class _Tick:
    """Records each step; ``busy_s[k]`` is how long step k keeps the clock."""

    def __init__(self, clock: ManualClock, busy_s: dict | None = None):
        self.clock, self.busy_s, self.steps = clock, busy_s or {}, []

    def step(self, inputs, *, t_exp_s: float, mode: str) -> TickOutput:
        self.steps.append((inputs.t_s, t_exp_s, mode))
        self.clock.sleep(self.busy_s.get(len(self.steps) - 1, 0.0))
        return TickOutput(PcmdCommand(0.0, 0.0, 0.0, 0.0, (False,) * 4), True,
                          {"t_s": t_exp_s, "mode": mode}, Action.CONTROL, [])


def _drone(t0: list) -> OpenedDrone:
    link = SimpleNamespace(set_command=lambda *a: None, hover=lambda: None, navdata=None,
                           navdata_rx_t_s=-math.inf, self_landing=None,
                           stats=SimpleNamespace(rate_hz=0.0))
    mocap = SimpleNamespace(latest=lambda: (None, -math.inf), take_events=lambda: [],
                            latest_of=lambda name: (None, -math.inf))
    return OpenedDrone(link, mocap, "stand-in", start_experiment=lambda t: t0.append(t) or [])


def _fly(monkeypatch, schedule: Schedule, busy_s: dict | None = None):
    clock = ManualClock()
    monkeypatch.setattr(realtime, "Rate",
                        lambda period_s: Rate(period_s, clock=clock, sleep_fn=clock.sleep))
    monkeypatch.setattr(realtime, "time", SimpleNamespace(monotonic=clock))
    cfg = load_config(None, [f"loop.period_s={schedule.period_s}"])
    tick, rows, events, t0 = _Tick(clock, busy_s), [], [], []
    recorder = SimpleNamespace(write_row=rows.append)
    stamps = EventClock(lambda t_s, kind, **f: events.append((kind, {"t_s": t_s, **f})), clock)
    realtime._control_loop(cfg, schedule, tick, _drone(t0), recorder, stamps, None)
    return tick.steps, rows, events, t0


def test_every_tick_of_the_schedule_and_no_more(monkeypatch):
    s = Schedule.of(settle_s=0.2, duration_s=0.5, period_s=PERIOD_S)
    assert (s.n_settle, s.n_ticks) == (4, 15)
    steps, rows, events, _ = _fly(monkeypatch, s)
    assert len(rows) == len(steps) == s.n_ticks
    assert [r["t_s"] for r in rows] == [s.t_exp_s(k) for k in range(s.n_ticks)]
    assert [r["mode"] for r in rows] == [phase(s.t_exp_s(k)) for k in range(s.n_ticks)]
    timing = [f for kind, f in events if kind == "loop_timing"]
    assert len(timing) == 1 and timing[0]["overruns"] == 0


def test_experiment_time_zero_is_fixed_settle_span_after_the_first_tick(monkeypatch):
    """``start_experiment(t0)``, the drone's (and its injected faults') clock: the monotonic
    time of experiment time 0 — the instant tick n_settle runs, settle_span_s after the first
    tick (not the first tick itself); the events are stamped on the same origin."""
    s = Schedule.of(settle_s=0.2, duration_s=0.3, period_s=PERIOD_S)
    steps, _, events, t0 = _fly(monkeypatch, s)
    assert len(t0) == 1
    first_s, zero_s = steps[0][0], steps[s.n_settle][0]
    assert steps[s.n_settle][1] == 0.0
    assert t0[0] == pytest.approx(first_s + s.settle_span_s, abs=1e-12)
    assert t0[0] == pytest.approx(zero_s, abs=1e-9)
    (timing,) = [f for kind, f in events if kind == "loop_timing"]
    end_s = first_s + (s.n_ticks - 1) * PERIOD_S  # the loop_timing event: after the last tick
    assert timing["t_s"] == pytest.approx(end_s + PERIOD_S - t0[0], abs=1e-9)


def test_an_overrun_skips_its_deadline_and_counts_it(monkeypatch):
    """Tick 5 runs 1.5 periods: deadline 6 is skipped (no burst of catch-up ticks), the
    experiment times stay wall time, and the skipped deadline is counted in loop_timing."""
    s = Schedule.of(settle_s=0.1, duration_s=0.4, period_s=PERIOD_S)
    steps, rows, events, _ = _fly(monkeypatch, s, busy_s={5: 1.5 * PERIOD_S})
    ks = [k for k in range(s.n_ticks) if k != 6]
    assert [r["t_s"] for r in rows] == [s.t_exp_s(k) for k in ks]
    overruns = [f["overruns"] for kind, f in events if kind == "loop_timing"]
    assert overruns == [1] and len(rows) + 1 == s.n_ticks


def test_deadlines_skipped_after_the_last_tick_are_not_counted(monkeypatch):
    s = Schedule.of(settle_s=0.0, duration_s=0.2, period_s=PERIOD_S)
    _, rows, events, _ = _fly(monkeypatch, s, busy_s={s.n_ticks - 1: 3.5 * PERIOD_S})
    assert [r["t_s"] for r in rows] == [s.t_exp_s(k) for k in range(s.n_ticks)]
    assert [f["overruns"] for kind, f in events if kind == "loop_timing"] == [0]
