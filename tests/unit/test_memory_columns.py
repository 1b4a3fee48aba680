"""``MemoryRecorder.columns`` (rows transposed per run of one key sequence) against the
column-by-column way it replaced: the same names, dtypes and bits, for lockstep-like rows,
fuzzed rows of changing key sets and odd values, extra keys and no rows."""

from __future__ import annotations

import random

import numpy as np
import pytest

from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS, cells_row
from ardrone_nmpc.runs.memory import MemoryRecorder, _numbers, _text

from tests.unit.test_recorder_plain_line import _row


def _columns_by_name(rows) -> dict:
    """The implementation before the transposition (commit fb5eae3), verbatim."""
    extra = set().union(*rows) - set(LOG_COLUMNS) if rows else set()
    names = [*LOG_COLUMNS, *sorted(extra)]
    n = len(rows)
    out = {}
    for name in names:
        cells = [row.get(name) for row in rows]
        if name in STRING_COLUMNS:
            arr = np.empty(n, dtype=object)
            arr[:] = [c if c.__class__ is str else _text(c) for c in cells]
        else:
            arr = _numbers(cells, n)
        out[name] = arr
    return out


def _assert_same(got: dict, want: dict) -> None:
    assert list(got) == list(want)
    for name in want:
        a, b = got[name], want[name]
        assert a.dtype == b.dtype and a.shape == b.shape, name
        if a.dtype == object:
            assert [type(v) for v in a] == [type(v) for v in b] and list(a) == list(b), name
        else:
            assert np.array_equal(a.view(np.uint64), b.view(np.uint64)), name


def _recorder(rows) -> MemoryRecorder:
    rec = MemoryRecorder()
    for row in rows:
        rec.write_row(row)
    return rec


@pytest.mark.parametrize("odd", [0.0, 0.05])
@pytest.mark.parametrize("sequences", [1, 3, 50])
def test_columns_are_the_column_by_column_ones(odd, sequences):
    rng = random.Random(sequences * 10 + int(odd * 100))
    shapes = [_row(rng, odd) for _ in range(sequences)]  # key sequences, with extra keys
    for shape in shapes[::2]:
        shape[f"extra_{rng.randint(0, 3)}"] = rng.choice([1.5, "text", None])
    rows = []
    for _ in range(300):
        shape = rng.choice(shapes)
        fresh = _row(rng, odd)
        rows.append({k: fresh.get(k, v) for k, v in shape.items()})
    _assert_same(_recorder(rows).columns(), _columns_by_name(rows))


def test_runs_of_key_sequences_and_no_rows():
    rows = [{"t_s": 0.0, "x_m": 1.0}, {"t_s": 0.1, "x_m": 2.0}, {"x_m": 3.0, "t_s": 0.2},
            {"t_s": 0.3, "mode": "track"}, {"t_s": 0.4, "x_m": None, "odd": "a"}]
    _assert_same(_recorder(rows).columns(), _columns_by_name(rows))
    _assert_same(_recorder([]).columns(), _columns_by_name([]))


def test_a_flown_square():
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    rec = MemoryRecorder()
    run_lockstep(load_config("configs/square.yaml", ["duration_s=5"]), recorder=rec)
    # the runner's usual rows come as cells (write_cells) and, a block of ticks' rows,
    # as blocks (write_block: runs/block_rows) — a clean square has both
    kinds = {r.__class__.__name__ for r in rec._rows}
    assert {"list", "BlockRows"} <= kinds
    _assert_same(rec.columns(), _columns_by_name(rec.rows))
    cells = [c for r in rec._rows  # a run of cells alone, and mixed
             for c in (r.cells() if r.__class__.__name__ == "BlockRows" else (r,))
             if c.__class__ is list]
    _assert_same(_recorder_cells(cells).columns(), _columns_by_name(list(map(cells_row, cells))))
    mixed = [{"t_s": -1.0, "mode": "settle", "odd": 2.0}, *cells[:50], {"x_m": 3.0},
             *cells[50:]]
    rec = MemoryRecorder()
    for r in mixed:
        (rec.write_cells if r.__class__ is list else rec.write_row)(r)
    _assert_same(rec.columns(), _columns_by_name([cells_row(r) if r.__class__ is list else r
                                                  for r in mixed]))


def _recorder_cells(rows) -> MemoryRecorder:
    rec = MemoryRecorder()
    for cells in rows:
        rec.write_cells(cells)
    return rec
