"""The lockstep runner's rows as cells in column order (``tick_cells``, ``write_cells``)
against the dict rows they replace, over real flights: the same dict (keys in order, bits),
the same ``log.csv`` bytes from RunRecorder, the same MemoryRecorder columns, and a bad cell
refused with write_row's error."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs import log_columns
from ardrone_nmpc.runs.log_columns import (LOG_COLUMNS, MODE_CELL, TICK_CELL_KEYS, cells_row,
                                           put_truth_cells)
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runs.row_text import BlockCheck, row_plan
from ardrone_nmpc.runs.rundir import RunRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime import tick as tick_module

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
CLOCKS = ("solve_us", "compute_us")
FLIGHTS = [
    ("square.yaml", ["duration_s=4", "sim.settle_s=1"]),
    ("square.yaml", ["duration_s=3", "sim.settle_s=1", "controller.kind=p"]),
    ("step_x.yaml", ["duration_s=4", "sim.settle_s=1", "faults.mocap_dropout.start_s=1",
                     "faults.mocap_dropout.duration_s=0.5"]),
]


def _bits(value):
    if isinstance(value, str) or value is None:
        return value
    return struct.pack("<d", float(value)) if not isinstance(value, int) else value


class _DictRows(MemoryRecorder):
    """A MemoryRecorder the runner hands dict rows (no write_cells)."""

    write_cells = None


def _cfg(config, overrides):
    return load_config(CONFIGS / config, overrides)


def _masked(columns: dict) -> dict:
    out = {}
    for name, arr in columns.items():
        if name in CLOCKS:
            continue
        out[name] = (list(arr) if arr.dtype == object else arr.tobytes())
    return out


def test_tick_cells_is_the_fast_row(monkeypatch):
    """Every tick of a flight that tick_cells takes: truth put, the dict of tick_row +
    put_truth, keys in order and bits (the others: None, tick_row's general path)."""
    seen = {"cells": 0, "all": 0}

    def checked(**kw):
        row = log_columns.tick_row(**kw)
        cells = log_columns.tick_cells(**kw)
        seen["all"] += 1
        if cells is not None:
            assert len(cells) == len(LOG_COLUMNS)
            truth = (1.5, -2.0, 0.25, math.pi, -0.0)
            put_truth_cells(cells, truth)
            log_columns.put_truth(row, truth)
            again = cells_row(cells)
            assert list(again) == list(row)
            assert [_bits(v) for v in again.values()] == [_bits(v) for v in row.values()]
            assert all(cells[i] == "" for i, c in enumerate(LOG_COLUMNS) if c not in row)
            seen["cells"] += 1
        return row

    monkeypatch.setattr(tick_module, "tick_row", checked)
    lockstep.run_lockstep(_cfg(*FLIGHTS[0]), recorder=_DictRows())
    assert seen["all"] > 40 and seen["cells"] > 20


@pytest.mark.parametrize("config, overrides", FLIGHTS)
def test_memory_columns_from_cells_are_those_of_dicts(config, overrides):
    cfg = _cfg(config, overrides)
    cells, dicts = MemoryRecorder(), _DictRows()
    lockstep.run_lockstep(cfg, recorder=cells)
    lockstep.run_lockstep(cfg, recorder=dicts)
    assert any(r.__class__ is list for r in cells._rows) or cfg.controller.kind == "p"
    assert all(r.__class__ is dict for r in dicts.rows)
    assert _masked(cells.columns()) == _masked(dicts.columns())
    # .rows gives dicts, as before: those of tick_row + put_truth
    assert [list(r) for r in cells.rows] == [list(r) for r in dicts.rows]
    assert ([[_bits(v) for k, v in r.items() if k not in CLOCKS] for r in cells.rows]
            == [[_bits(v) for k, v in r.items() if k not in CLOCKS] for r in dicts.rows])
    assert cells.events == dicts.events


class _DictRunRecorder(RunRecorder):
    write_cells = None


def _masked_log(path: Path) -> list[list[str]]:
    lines = (path / "log.csv").read_text().splitlines()
    header = lines[0].split(",")
    clocks = [header.index(c) for c in CLOCKS]
    out = []
    for line in lines:
        cells = line.split(",")
        for i in clocks:
            cells[i] = "-"
        out.append(cells)
    return out


@pytest.mark.parametrize("config, overrides", FLIGHTS)
def test_run_directory_from_cells_is_that_of_dicts(tmp_path, config, overrides):
    cfg = _cfg(config, overrides)
    logs = {}
    for name, cls in (("cells", RunRecorder), ("dicts", _DictRunRecorder)):
        rec = cls.create(tmp_path / name, cfg, seed=0, rows_per_write=64, durable=False)
        with rec:
            lockstep.run_lockstep(cfg, recorder=rec, seed=0)
            kept = rec.kept_columns()
        logs[name] = (_masked_log(rec.path), _masked(kept),
                      [line.split(',"wall_s"')[0]
                       for line in (rec.path / "events.jsonl").read_text().splitlines()])
    assert logs["cells"] == logs["dicts"]


def _a_cells_row():
    cfg = _cfg(*FLIGHTS[0])
    rec = MemoryRecorder()
    lockstep.run_lockstep(cfg, recorder=rec)
    return next(r for r in rec._rows if r.__class__ is list)


@pytest.mark.parametrize("slot, value", [
    (LOG_COLUMNS.index("x_m"), "1.0"),
    (LOG_COLUMNS.index("x_m"), [1.0]),
    (MODE_CELL, "hold,x"),
    (MODE_CELL, 3.0),
    (LOG_COLUMNS.index("solver_status"), 'o"k'),
])
def test_a_bad_cell_is_refused_as_write_row_refuses(tmp_path, slot, value):
    cfg = _cfg(*FLIGHTS[0])
    cells = list(_a_cells_row())
    cells[slot] = value
    errors = []
    for name, write in (("cells", "write_cells"), ("dict", "write_row")):
        rec = RunRecorder.create(tmp_path / name, cfg, seed=0, rows_per_write=64,
                                 durable=False)
        with rec, pytest.raises(ValueError) as err:
            getattr(rec, write)(list(cells) if write == "write_cells" else cells_row(cells))
        errors.append(str(err.value))
        assert rec.rows_written == 0
    assert errors[0] == errors[1]


def test_the_cells_check_passes_only_what_block_check_passes():
    cells = _a_cells_row()
    check = BlockCheck()
    n_str = row_plan(TICK_CELL_KEYS)[5]
    variants = [list(cells)]
    for slot, value in [(0, np.float32(1.0)), (1, True), (1, "x"), (MODE_CELL, "a]b"),
                        (MODE_CELL, "null"), (MODE_CELL, None), (2, None), (3, math.inf),
                        (4, 7), (LOG_COLUMNS.index("nav_mode"), 1.0)]:
        v = list(cells)
        v[slot] = value
        variants.append(v)
    assert check.tick_cells(variants[0])
    for v in variants:
        if check.tick_cells(v):
            assert check(v, n_str)
    # the last row's types are remembered: each row judged alike after any other
    judged = [check.tick_cells(v) for v in variants]
    assert judged == [check.tick_cells(v) for v in reversed(variants)][::-1]
    assert judged == [BlockCheck().tick_cells(v) for v in variants]


@pytest.mark.parametrize("state_bits", [math.nan, None, np.float64(math.nan), 5, ""])
def test_block_text_counts_nav_state_bits_nulls_and_still_refuses_infinities(state_bits):
    """block_text's shortcut (the nulls are nav_state_bits' NaN) never hides a ±inf or
    another NaN cell: the text is _plain_line's, row for row, or None for a ±inf."""
    from ardrone_nmpc.runs.row_text import _plain_line, block_text

    cells = list(_a_cells_row())
    cells[LOG_COLUMNS.index("nav_state_bits")] = state_bits
    quotes = row_plan(TICK_CELL_KEYS)[4] + 2 * (state_bits == "")  # an empty cell: ""
    slots = [LOG_COLUMNS.index(c) for c in ("x_m", "battery_pct", "vz_true_mps")]
    for slot in slots:
        for value in (math.inf, -math.inf, np.float64(math.inf), math.nan, None):
            rows = [list(cells) for _ in range(5)]
            rows[3][slot] = value
            text = block_text(rows)
            if isinstance(value, float) and math.isinf(value):
                assert text is None
            else:
                assert text == b"".join(_plain_line(list(r), quotes) for r in rows)
    rows = [list(cells) for _ in range(4)]
    assert block_text(rows) == b"".join(_plain_line(list(r), quotes) for r in rows)


def test_a_wrapper_forwarding_attributes_gets_dict_rows():
    """A recorder wrapper whose __getattr__ forwards to a RunRecorder-like one (the live
    view's tee) sees every row through its own write_row, as dicts."""

    class _Forwarding:
        def __init__(self, inner):
            self._inner = inner
            self.seen = []

        def write_row(self, row):
            self.seen.append(row)
            self._inner.write_row(row)

        def __getattr__(self, name):
            return getattr(self._inner, name)

    inner = MemoryRecorder()
    tee = _Forwarding(inner)
    lockstep.run_lockstep(_cfg(*FLIGHTS[0]), recorder=tee)
    assert tee.seen and len(tee.seen) == len(inner.rows)
    assert all(r.__class__ is dict for r in inner._rows)


@pytest.mark.parametrize("slot, value", [
    (LOG_COLUMNS.index("gmres_iterations"), 10 ** 400),  # float() overflows: OverflowError
    (MODE_CELL, "tr\udcffack"),  # a lone surrogate: not UTF-8 (UnicodeEncodeError)
])
def test_a_cell_that_cannot_be_printed_is_refused_at_once_not_held(tmp_path, slot, value):
    """Held, such a row failed its whole block at the block's write (the error at a later
    row or at close): write_cells refuses it at once, as write_row one row a write does."""
    cfg = _cfg(*FLIGHTS[0])
    cells = list(_a_cells_row())
    cells[slot] = value
    errors = []
    for name, write, rows_per_write in (("cells", "write_cells", 64), ("dict", "write_row", 1)):
        rec = RunRecorder.create(tmp_path / name, cfg, seed=0, rows_per_write=rows_per_write,
                                 durable=False)
        with rec, pytest.raises((ValueError, OverflowError)) as err:
            getattr(rec, write)(list(cells) if write == "write_cells" else cells_row(cells))
        errors.append((type(err.value), str(err.value)))
        assert rec.rows_written == 0
    assert errors[0] == errors[1]


@pytest.mark.parametrize("n_rows", [1, 2, 64])
def test_block_text_leaves_its_rows_as_they_were(n_rows):
    """block_text hands nav_state_bits' NaN/None to orjson as "nan" and puts the very objects
    back (the recorder keeps the rows); the text is _plain_line's row for row, also with a
    'u' in a string cell (a null then looked for), another NaN cell (the nulls' path) and
    ±inf (None)."""
    from ardrone_nmpc.runs.row_text import _plain_line, block_text

    cells = list(_a_cells_row())
    quotes = row_plan(TICK_CELL_KEYS)[4]
    bits = LOG_COLUMNS.index("nav_state_bits")
    for mode, other in (("track", None), ("fallback-unsure", None), ("track", math.nan),
                        ("track", np.float64(math.nan)), ("track", -math.inf)):
        rows = [list(cells) for _ in range(n_rows)]
        for i, r in enumerate(rows):
            r[MODE_CELL] = mode
            r[bits] = (math.nan, None, np.float64(math.nan), 5)[i % 4]
        if other is not None:
            rows[-1][LOG_COLUMNS.index("y_ref_m")] = other
        before = [list(r) for r in rows]
        text = block_text(rows)
        assert all(a is b for r, s in zip(rows, before) for a, b in zip(r, s))
        if isinstance(other, float) and math.isinf(other):
            assert text is None
        else:
            assert text == b"".join(_plain_line(list(r), quotes) for r in rows)


@pytest.mark.parametrize("column", ["tick_late_ms", "nav_ctrl_state", "target_x_m",
                                    "target_age_ms"])
@pytest.mark.parametrize("value", ["abc", "x[y", "a]b", 'q"', 1.5, None])
def test_a_cell_tick_cells_leaves_empty_is_written_in_blocks_as_one_row_a_write(
        tmp_path, column, value):
    """Something else than the "" tick_cells leaves in a column it lacks: the row is not held
    for a block (its text would carry the cell, or lose a bracket of it) but written as one
    row a write writes it — write_row of its dict, which drops the cell."""
    cfg = _cfg(*FLIGHTS[0])
    rows = [list(_a_cells_row()) for _ in range(5)]
    rows[2][LOG_COLUMNS.index(column)] = value
    written = []
    for name, rows_per_write in (("one", 1), ("block", 64)):
        rec = RunRecorder.create(tmp_path / name, cfg, seed=0, rows_per_write=rows_per_write,
                                 durable=False)
        with rec:
            for cells in rows:
                rec.write_cells(list(cells))
        written.append((rec.path / "log.csv").read_bytes())
    assert written[0] == written[1]
    assert written[0].count(b"\n") == 6
    assert b"abc" not in written[1] and b"x[y" not in written[1] and b"xy" not in written[1]
    assert not BlockCheck().tick_cells(rows[2]) and BlockCheck().tick_cells(rows[1])
