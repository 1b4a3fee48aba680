"""The tick's label and events (runtime/tick.py, after the stages): the supervisor's
``record`` — the one home of the rule that a control verdict of the label noted last notes
nothing — gives every tick its label, notes a mode event only where that rule does not hold,
and its events are taken whenever it holds any; over flights whose supervisor changes mode
(a mocap dropout, a diverging solver), with the runner's cells and dict rows."""

from __future__ import annotations

from pathlib import Path

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.log_columns import MODE_CELL
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action, Supervisor

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
FLIGHTS = [
    ("step_x.yaml", ["duration_s=4", "sim.settle_s=1", "faults.mocap_dropout.start_s=1",
                     "faults.mocap_dropout.duration_s=0.3"]),
    ("square.yaml", ["duration_s=4", "sim.settle_s=1", "faults.solver_diverge.start_s=1",
                     "faults.solver_diverge.duration_s=1"]),
    ("square.yaml", ["duration_s=3", "sim.settle_s=1", "controller.kind=p"]),
]


@pytest.mark.parametrize("config, overrides", FLIGHTS)
def test_every_tick_is_recorded_and_only_a_change_of_mode_noted(monkeypatch, config, overrides):
    cfg = load_config(CONFIGS / config, overrides)
    record, step = Supervisor.record, Tick.step
    given = []  # record's answers
    ticks = []  # (label before, label given, mode asked, action, records, pending, events)

    def spied_record(self, decision, nominal):
        given.append(record(self, decision, nominal))
        return given[-1]

    def spied_step(self, inputs, **kwargs):
        before, n_calls, pending = self.supervisor.label, len(given), list(self.supervisor.events)
        out = step(self, inputs, **kwargs)
        label = out.cells[MODE_CELL] if out.cells is not None else out.row["mode"]
        assert given[n_calls:] == [label]  # one record a tick: its label
        ticks.append((before, label, kwargs.get("mode", "track"), out.action, pending,
                      out.events))
        assert self.supervisor.events == []  # taken, every tick
        return out

    monkeypatch.setattr(Supervisor, "record", spied_record)
    monkeypatch.setattr(Tick, "step", spied_step)
    # per tick: Tick.step sees every tick (a diverging solver's usual ticks fly in blocks,
    # whose rows and labels tests/integration/test_tick_blocks.py holds to these)
    monkeypatch.setattr(lockstep, "BLOCK_TICKS", 0)
    lockstep.run_lockstep(cfg, recorder=MemoryRecorder())
    usual = [t for t in ticks if t[3] is Action.CONTROL and t[1] == t[2] == t[0]]
    assert usual and len(usual) < len(ticks)  # both kinds of tick flown
    for before, label, mode, action, pending, events in usual:
        assert events[:len(pending)] == pending  # what the supervisor held, handed on
        assert not [e for e in events[len(pending):] if e.get("kind") == "mode"]  # no note
    changed = [t for t in ticks if t[1] != t[0]]
    assert changed  # the flights change mode (their events: tests/unit/test_safety.py)
