"""LazyColumns: the read-only mapping of a run's columns, each converted once, on first read
(the values themselves: tests/unit/test_recorder_kept_rows.py, test_memory_columns.py)."""

from __future__ import annotations

import pickle

import numpy as np

from ardrone_nmpc.runs.lazy_columns import LazyColumns
from ardrone_nmpc.runs.memory import MemoryRecorder


def _double(name, cells):
    _double.calls.append(name)
    return np.array(cells, dtype=float) * 2.0


def test_each_column_is_converted_once_on_first_read():
    _double.calls = []
    cols = LazyColumns({"b": (1.0, 2.0), "a": (3.0,)}, _double)
    assert _double.calls == []
    assert list(cols) == ["b", "a"] and len(cols) == 2  # column order
    assert "a" in cols and "c" not in cols and cols.get("c") is None
    assert cols["a"].tolist() == [6.0] and cols["a"] is cols["a"]
    assert _double.calls == ["a"]
    assert {k: v.tolist() for k, v in cols.items()} == {"b": [2.0, 4.0], "a": [6.0]}
    assert _double.calls == ["a", "b"]
    assert dict(cols).keys() == {"a", "b"}


def test_the_columns_are_a_snapshot_and_pickle():
    rec = MemoryRecorder()
    rec.write_row({"t_s": 0.0, "mode": "track"})
    cols = rec.columns()
    rec.write_row({"t_s": 1.0, "mode": "track"})
    assert cols["t_s"].tolist() == [0.0] and list(cols["mode"]) == ["track"]
    again = pickle.loads(pickle.dumps(cols))
    assert list(again) == list(cols) and again["t_s"].tolist() == [0.0]
