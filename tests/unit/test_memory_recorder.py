"""The in-memory recorder gives the RunData a run directory read back gives."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.runs.summary import summarise
from ardrone_nmpc.runtime.lockstep import run_lockstep

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
WALL_TIME = {"solve_us", "compute_us"}  # measured, differ between two flights


def test_a_flight_in_memory_equals_the_same_flight_read_back(tmp_path):
    cfg = load_config(CONFIGS / "step_z.yaml", ["duration_s=2", "sim.settle_s=0.5"])
    memory = MemoryRecorder()
    result = run_lockstep(cfg, recorder=memory)
    assert result.run_dir is None
    with RunRecorder.create(tmp_path, cfg, seed=0) as recorder:
        run_lockstep(cfg, recorder=recorder)
    on_disk = read_run(recorder.path)
    in_memory = memory.run_data(cfg, seed=0)
    assert list(in_memory.columns) == list(on_disk.columns) == list(LOG_COLUMNS)
    for name in LOG_COLUMNS:
        a, b = on_disk.columns[name], in_memory.columns[name]
        assert a.dtype == b.dtype == (object if name in STRING_COLUMNS else np.float64), name
        if name in STRING_COLUMNS:
            assert a.tolist() == b.tolist(), name
        elif name not in WALL_TIME:
            assert np.array_equal(a, b, equal_nan=True), name
    assert [e["kind"] for e in in_memory.events] == [e["kind"] for e in on_disk.events]
    rows_disk, rows_mem = summarise(on_disk), summarise(in_memory)
    assert [(r.axis, r.metric) for r in rows_disk] == [(r.axis, r.metric) for r in rows_mem]
    for a, b in zip(rows_disk, rows_mem):
        if a.axis not in ("solver", "loop") or a.metric in ("non_ok", "fallbacks"):
            assert a.value == b.value or (math.isnan(a.value) and math.isnan(b.value)), a


def test_missing_cells_none_and_extra_columns_read_as_a_run_directory_would():
    rec = MemoryRecorder()
    rec.write_row({"t_s": 0.0, "x_m": None, "mode": "track", "note": "a"})
    rec.write_row({"t_s": 0.1, "x_m": 2, "cmd_saturated": None, "note": "b"})
    rec.event(0.5, "land", reason="done")
    cols = rec.columns()
    assert cols["t_s"].tolist() == [0.0, 0.1]
    assert math.isnan(cols["x_m"][0]) and cols["x_m"][1] == 2.0
    assert np.isnan(cols["y_m"]).all()
    assert cols["mode"].tolist() == ["track", ""]
    assert cols["cmd_saturated"].tolist() == ["", ""]
    assert cols["note"].dtype == object and cols["note"].tolist() == ["a", "b"]
    assert rec.events == [{"t_s": 0.5, "kind": "land", "reason": "done"}]
    assert rec.rows_written == 2
