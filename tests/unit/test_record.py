"""ardrone_nmpc.experiments.record: a flight recorded into a run directory and summarised."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.config.schema import config_from_dict
from ardrone_nmpc.experiments.record import (FAILED_EVENT, SIMULATED_EVENT, one_line, record,
                                             record_lockstep)
from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.runs.summary import read_summary, summarise
from ardrone_nmpc.runtime.schedule import Schedule, ScheduleError

FILES = {"config.yaml", "log.csv", "events.jsonl", "summary.csv"}


def _same_rows(a, b) -> None:
    """Summary rows equal, NaN values included (summary.csv round-trips every double)."""
    assert [(r.axis, r.metric, r.unit) for r in a] == [(r.axis, r.metric, r.unit) for r in b]
    np.testing.assert_array_equal([r.value for r in a], [r.value for r in b])


def _cfg(**top):
    data = {"name": "rec", "duration_s": 1.0, "sim": {"settle_s": 0.2},
            "reference": {"kind": "step", "target_m": [-0.3, 0.0, 1.0]}}
    data.update(top)
    return config_from_dict(data)


def test_a_lockstep_recording_is_a_complete_summarised_run_directory(tmp_path):
    cfg = _cfg()
    recording = record_lockstep(cfg, tmp_path, seed=7)
    assert {p.name for p in recording.path.iterdir()} == FILES
    assert recording.path.parent == tmp_path and recording.error == ""
    run = read_run(recording.path)
    # the summary is the one this version computes from the files, nothing else
    _same_rows(read_summary(recording.path), summarise(run))
    _same_rows(recording.summary, summarise(run))
    assert recording.run.n_rows == run.n_rows == recording.result.ticks
    assert recording.result.ticks == Schedule.from_config(cfg).n_ticks
    # the seed flown is the one the run directory names, in its header and its config
    assert run.seed == 7 and run.config.sim.seed == 7
    assert recording.wall_s > 0


def test_the_simulated_event_ends_the_events_in_time_order(tmp_path):
    recording = record_lockstep(_cfg(), tmp_path)
    events = read_run(recording.path).events
    last = events[-1]
    assert last["kind"] == SIMULATED_EVENT
    assert (last["ticks"], last["ending"], last["final_mode"]) == (
        recording.result.ticks, "completed", "landed")
    times = [e["t_s"] for e in events]
    assert times == sorted(times)
    landed = next(e for e in events if e["kind"] == "landed")
    assert last["t_s"] == landed["t_s"] == recording.result.end_t_s
    assert last["t_s"] > 1.0  # after the experiment: the landing took time


def test_a_seed_equal_to_the_config_leaves_the_config_untouched(tmp_path):
    cfg = _cfg(sim={"settle_s": 0.2, "seed": 3})
    recording = record_lockstep(cfg, tmp_path)
    assert read_run(recording.path).config == cfg


def test_times_without_a_tick_count_create_no_run_directory(tmp_path):
    # validation bounds duration_s (config/limits.py); a config built around it (model_copy
    # skips validation) still meets the schedule's own guard before any directory exists
    cfg = _cfg().model_copy(update={"duration_s": 1e308})
    with pytest.raises(ScheduleError, match="^duration_s = "):
        record_lockstep(cfg, tmp_path / "logs")
    assert not (tmp_path / "logs").exists()


def _explode(cfg, **kwargs):
    raise RuntimeError("plant exploded\non two lines")


def test_a_flight_that_raises_keeps_its_directory_without_a_summary(tmp_path, monkeypatch):
    import ardrone_nmpc.runtime.lockstep as lockstep

    monkeypatch.setattr(lockstep, "run_lockstep", _explode)
    with pytest.raises(RuntimeError, match="plant exploded"):
        record_lockstep(_cfg(), tmp_path)
    (run_dir,) = tmp_path.iterdir()
    assert {p.name for p in run_dir.iterdir()} == FILES - {"summary.csv"}
    (event,) = read_run(run_dir).events
    assert event["kind"] == FAILED_EVENT and math.isnan(event["t_s"])
    assert event["error"] == "RuntimeError: plant exploded on two lines"


def test_catch_returns_the_failure_instead(tmp_path, monkeypatch):
    import ardrone_nmpc.runtime.lockstep as lockstep

    monkeypatch.setattr(lockstep, "run_lockstep", _explode)
    recording = record_lockstep(_cfg(), tmp_path, catch=True)
    assert recording.result is None and recording.run is None and recording.summary == []
    assert recording.error == "RuntimeError: plant exploded on two lines"
    assert not (recording.path / "summary.csv").exists()


def test_record_runs_any_flight_into_the_directory_then_summarises(tmp_path):
    """The rerun's use: a flight of its own rows, summarised from what it wrote."""
    cfg = _cfg()

    def fly(recorder):
        for k in range(5):
            recorder.write_row({"t_s": k * 0.065, "x_m": 0.1 * k, "mode": "track"})
        recorder.event(0.0, "replay", source="elsewhere")
        return "flown"

    recording = record(cfg, tmp_path, seed=None, fly=fly)
    assert recording.result == "flown" and recording.run.n_rows == 5
    _same_rows(read_summary(recording.path), summarise(read_run(recording.path)))
    assert [e["kind"] for e in recording.run.events] == ["replay"]


def test_one_line_collapses_whitespace_and_names_the_type():
    assert one_line(ValueError("a\n  b\tc ")) == "ValueError: a b c"
    assert one_line(KeyError()) == "KeyError"


def test_record_lockstep_hands_the_flight_the_reference_it_checked(tmp_path, monkeypatch):
    """One experiment_trajectory a flight: made for the geofence check, flown by
    run_lockstep — but never a follow's live object (the flight makes its own)."""
    from pathlib import Path

    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.experiments.record import record_lockstep
    from ardrone_nmpc.reference.experiment import HoldStartThen
    from ardrone_nmpc.runtime import lockstep

    handed = []
    fly = lockstep.run_lockstep

    def spy(cfg, **kwargs):
        handed.append(kwargs.get("trajectory"))
        return fly(cfg, **kwargs)

    monkeypatch.setattr(lockstep, "run_lockstep", spy)
    root = Path(__file__).resolve().parents[2] / "configs"
    for name in ("hover", "follow_car"):
        record_lockstep(load_config(root / f"{name}.yaml", ["duration_s=1", "sim.settle_s=0.5"]),
                        tmp_path / name, seed=3)
    assert isinstance(handed[0], HoldStartThen) and handed[1] is None
