"""The recorder's kept rows (``RunRecorder.kept_columns``) against ``read_run`` parsing the
``log.csv`` it wrote: the same columns, types and bits — what lets a recording summarise its
run without parsing the file again."""

from __future__ import annotations

import random

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import RunRecorder, format_number, read_run
from tests.unit.test_recorder_plain_line import _row


def _same(kept: dict, read: dict) -> None:
    assert list(kept) == list(LOG_COLUMNS)
    for name in LOG_COLUMNS:
        a, b = kept[name], read[name]
        assert a.dtype == b.dtype and a.shape == b.shape, name
        if name in STRING_COLUMNS:
            assert [type(x) for x in a] == [type(x) for x in b] and list(a) == list(b), name
        else:
            assert np.array_equal(a.view(np.uint64), b.view(np.uint64)), name  # bit for bit


@pytest.fixture
def cfg():
    return load_config(overrides=["name=kept", "duration_s=1"])


@pytest.mark.parametrize("odd", [0.0, 0.05, 0.3])
def test_kept_columns_are_the_columns_read_back(tmp_path, cfg, odd):
    rng = random.Random(11 + int(odd * 100))
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for _ in range(400):
            try:
                rec.write_row(_row(rng, odd))
            except ValueError:
                pass  # refused: neither written nor kept
        rec.write_row({"t_s": -0.0, "x_m": float("-nan"), "nav_state_bits": 2 ** 60 + 1})
    _same(rec.kept_columns(), read_run(rec.path).columns)


def test_no_row_and_too_many_rows(tmp_path, cfg, monkeypatch):
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        pass
    _same(rec.kept_columns(), read_run(rec.path).columns)
    monkeypatch.setattr(RunRecorder, "KEEP_ROWS", 3)
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k in range(3):
            rec.write_row({"t_s": float(k)})
        _same(rec.kept_columns(), read_run(rec.path).columns)
        rec.write_row({"t_s": 3.0})
    assert rec.kept_columns() is None  # a long run is read back from its file


@pytest.mark.parametrize("config, overrides", [
    ("square", ["duration_s=6"]),
    ("hover", ["duration_s=6", "sim.settle_s=1", "faults.battery_floor.start_s=3"]),
    ("hover", ["duration_s=6", "sim.settle_s=1", "faults.emergency.start_s=3"]),
    ("follow_car", ["duration_s=3"]),
    ("step_x", ["duration_s=3", "controller.kind=p"]),
])
def test_a_recorded_flight_is_summarised_from_what_its_file_holds(tmp_path, config,
                                                                  overrides):
    from pathlib import Path

    from ardrone_nmpc.experiments.record import record_lockstep
    from ardrone_nmpc.runs.summary import summarise

    root = Path(__file__).resolve().parents[2]
    rec = record_lockstep(load_config(root / "configs" / f"{config}.yaml", overrides),
                          tmp_path, catch=True)
    assert rec.error == ""
    again = read_run(rec.path)
    _same(rec.run.columns, again.columns)
    text = lambda rows: [(r.axis, r.metric, format_number(r.value), r.unit) for r in rows]  # noqa: E731
    assert text(summarise(again)) == text(rec.summary)  # NaN included
