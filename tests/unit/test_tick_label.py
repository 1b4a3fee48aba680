"""The tick's label and events (runtime/tick.py, after the stages): the supervisor's
``record`` is skipped only on a tick where it would note nothing — a control verdict of the
label it noted last — and its events are taken whenever it holds any; over flights whose
supervisor changes mode (a mocap dropout, a diverging solver), with the runner's cells and
dict rows."""

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
def test_record_is_skipped_only_where_it_would_note_nothing(monkeypatch, config, overrides):
    cfg = load_config(CONFIGS / config, overrides)
    record, step = Supervisor.record, Tick.step
    calls = []
    ticks = []  # (label before, label given, mode asked, action, recorded, events)

    def spied_record(self, decision, nominal):
        calls.append((decision, nominal))
        return record(self, decision, nominal)

    def spied_step(self, inputs, **kwargs):
        before, n_calls, pending = self.supervisor.label, len(calls), list(self.supervisor.events)
        out = step(self, inputs, **kwargs)
        label = out.cells[MODE_CELL] if out.cells is not None else out.row["mode"]
        ticks.append((before, label, kwargs.get("mode", "track"), out.action,
                      len(calls) > n_calls, pending, out.events))
        assert self.supervisor.events == []  # taken, every tick
        return out

    monkeypatch.setattr(Supervisor, "record", spied_record)
    monkeypatch.setattr(Tick, "step", spied_step)
    lockstep.run_lockstep(cfg, recorder=MemoryRecorder())
    skipped = [t for t in ticks if not t[4]]
    assert skipped and len(skipped) < len(ticks)  # both ways taken
    for before, label, mode, action, _, pending, events in skipped:
        assert action is Action.CONTROL and label == mode == before
        assert events[:len(pending)] == pending  # what the supervisor held, handed on
    changed = [t for t in ticks if t[1] != t[0]]
    assert changed and all(t[4] for t in changed)  # every change of label was recorded
