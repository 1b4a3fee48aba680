"""A block of rows (``runs/block_rows.BlockRows``) gives the cells and columns of the rows a
block's numbers stand for, and the recorders that take blocks keep what they keep of cells.

The reference is ``runs/log_columns.block_cells`` row by row (itself compared with the
per-tick path's cells in tests/integration/test_tick_blocks.py): the columns made column by
column must equal the cells transposed — values, bits and Python types.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from ardrone_nmpc.experiments.tick_bench import _Clocks
from ardrone_nmpc.runs.block_row import (BLOCK_ROW, BR_GMRES, BR_NEWTON, BR_SATURATED, BR_T,
                                         BR_TARGET_X, BR_TRUE_PSI)
from ardrone_nmpc.runs.block_rows import BlockRows
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, block_cells
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runs.verdict import VerdictTally

SATURATED = ("", "roll", "pitch", "roll+pitch")


def _numbers(rng, n: int) -> np.ndarray:
    """Rows of numbers as a block writes them: integers where the kernel writes counts and
    bits, angles beyond ±π for the truth's ψ (wrapped in the cells), NaN, ±inf, −0.0."""
    rows = rng.normal(scale=3.0, size=(n, BLOCK_ROW))
    rows[:, BR_SATURATED] = rng.integers(0, len(SATURATED), n)
    rows[:, BR_GMRES] = rng.integers(0, 30, n)
    rows[:, BR_NEWTON] = rng.integers(0, 3, n)
    rows[:, BR_TRUE_PSI] = rng.uniform(-10.0, 10.0, n)
    if n > 3:
        rows[0, BR_TRUE_PSI], rows[1, BR_TRUE_PSI] = math.pi, -math.pi
        rows[2, 1], rows[3, 2], rows[3, 3] = math.nan, math.inf, -0.0
    return rows


def _bits(value):
    """A cell as (type, bits): NaN equal to NaN, −0.0 apart from 0.0."""
    if isinstance(value, float):
        return type(value).__name__, struct.pack("<d", value)
    return type(value).__name__, value


def _block(rows, mode="track") -> BlockRows:
    return BlockRows(rows, mode, SATURATED, "ok", "flying")


@pytest.mark.parametrize("target", [False, True], ids=["alone", "second_object"])
@pytest.mark.parametrize("n", [1, 2, 7, 32])
def test_cells_are_block_cells_row_by_row_and_columns_the_cells_transposed(n, target):
    rows = _numbers(np.random.default_rng(n), n)
    block = BlockRows(rows, "track", SATURATED, "ok", "flying", target)
    cells = block.cells()
    expected = [block_cells(v, vx, vy, SATURATED, "ok", "track", "flying", target)
                for v, vx, vy in zip(rows.tolist(), rows[:, 31], rows[:, 32])]
    at = LOG_COLUMNS.index("target_x_m")
    # the object's six cells: its numbers (BR_TARGET_X …), or none
    assert [row[at:at + 6] for row in expected] == (
        rows[:, BR_TARGET_X:BR_TARGET_X + 6].tolist() if target else [[""] * 6] * n)
    assert [[_bits(c) for c in row] for row in cells] == [
        [_bits(c) for c in row] for row in expected]
    assert all(len(row) == len(LOG_COLUMNS) for row in cells)
    columns = block.columns()
    assert len(columns) == len(LOG_COLUMNS)
    assert [[_bits(c) for c in col] for col in columns] == [
        [_bits(c) for c in col] for col in zip(*cells)]
    assert len(block) == n and block.times_s() == rows[:, BR_T].tolist()


def _mixed(rng) -> tuple[MemoryRecorder, MemoryRecorder]:
    """The same rows given to two recorders: one takes blocks of rows, the other each block
    row's cells — with rows of cells and dict rows between them."""
    by_block, by_cells = MemoryRecorder(), MemoryRecorder()
    for step in range(6):
        block = _block(_numbers(rng, int(rng.integers(1, 9))), mode=f"m{step % 2}")
        by_block.write_block(block)
        for cells in block.cells():
            by_cells.write_cells(cells)
        extra = _block(_numbers(rng, 2)).cells()  # a per-tick row of cells
        for rec in (by_block, by_cells):
            rec.write_cells(list(extra[0]))
        if step == 3:  # a dict row (a P controller's, a landing's)
            for rec in (by_block, by_cells):
                rec.write_row({"t_s": 9.0, "mode": "land", "x_m": 1.0})
    return by_block, by_cells


def test_a_memory_recorder_keeps_blocks_as_the_cells_of_their_rows():
    by_block, by_cells = _mixed(np.random.default_rng(7))
    assert by_block.rows_written == by_cells.rows_written > 20
    rows_a, rows_b = by_block.rows, by_cells.rows
    assert [list(r) for r in rows_a] == [list(r) for r in rows_b]
    assert [[_bits(v) for v in r.values()] for r in rows_a] == [
        [_bits(v) for v in r.values()] for r in rows_b]
    cols_a, cols_b = by_block.columns(), by_cells.columns()
    assert list(cols_a) == list(cols_b)
    for name in cols_a:
        a, b = cols_a[name], cols_b[name]
        assert a.dtype == b.dtype, name
        if a.dtype == object:
            assert a.tolist() == b.tolist(), name
        else:
            assert a.tobytes() == b.tobytes(), name


def test_a_memory_recorder_of_blocks_only_gives_every_column():
    by_block, by_cells = MemoryRecorder(), MemoryRecorder()
    block = _block(_numbers(np.random.default_rng(3), 5))
    by_block.write_block(block)
    for cells in block.cells():
        by_cells.write_cells(cells)
    a, b = by_block.columns(), by_cells.columns()
    assert list(a) == list(b) == list(LOG_COLUMNS)
    assert all(a[k].tobytes() == b[k].tobytes() for k in a if a[k].dtype != object)
    assert all(a[k].tolist() == b[k].tolist() for k in a if a[k].dtype == object)


def test_the_bench_clocks_of_a_block_are_its_rows_cells_clocks():
    block = _block(_numbers(np.random.default_rng(5), 9))
    by_block, by_cells = _Clocks(), _Clocks()
    by_block.write_block(block)
    for cells in block.cells():
        by_cells.write_cells(cells)
    a, b = by_block.clocks(), by_cells.clocks()
    assert [struct.pack("<9d", *x) for x in a] == [struct.pack("<9d", *x) for x in b]


@pytest.mark.parametrize("seed", range(5))
def test_a_tally_of_a_block_of_ticks_is_its_ticks_one_by_one(seed):
    rng = np.random.default_rng(seed)
    one, block = VerdictTally(follow=False), VerdictTally(follow=False)
    for _ in range(12):
        mode = str(rng.choice(["track", "settle", "fallback-hold", "land"]))
        times = rng.normal(size=int(rng.integers(0, 6))).tolist()
        for t in times:
            one.add_tick(t, mode)
        block.add_ticks(times, mode)
        assert block.tracking_ticks == one.tracking_ticks
    assert one.tracking_ticks > 0


def test_a_recorder_that_watches_cells_below_write_block_is_given_cells():
    """A subclass overriding ``write_cells`` but not ``write_block`` would miss a block's
    rows: the runner gives it none (``lockstep._block_sink``); its own ``write_block`` or
    its base's alone is taken."""
    from ardrone_nmpc.runtime.lockstep import _block_sink

    class Watching(MemoryRecorder):
        def write_cells(self, cells):
            super().write_cells(cells)

    class WatchingBoth(Watching):
        def write_block(self, rows):
            super().write_block(rows)

    assert _block_sink(Watching()) is None
    assert _block_sink(WatchingBoth()).__func__ is WatchingBoth.write_block
    assert _block_sink(MemoryRecorder()).__func__ is MemoryRecorder.write_block
    assert _block_sink(_Clocks()).__func__ is _Clocks.write_block
