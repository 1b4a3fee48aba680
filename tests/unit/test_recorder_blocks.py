"""Rows handed to the OS in blocks (``RunRecorder.create(rows_per_write=…)``, the lockstep
recordings; ``row_text.BlockCheck`` / ``block_text``) against one row a write: the same
``log.csv`` bytes, the same kept columns, the same refusals at the same rows, and nothing
held once the recorder is flushed or closed."""

from __future__ import annotations

import math
import random
import time

import numpy as np
import pytest

from ardrone_nmpc.config.schema import config_from_dict
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import LOG_FILE, RunRecorder

from tests.unit.test_recorder_plain_line import _row

CFG = config_from_dict({"name": "blocks"})


def _write(tmp_path, rows, rows_per_write: int, sub: str):
    """Write ``rows`` (a refused row is noted, as a caller catching it would); returns the
    log bytes, the kept columns and the refusals (row index, message)."""
    rec = RunRecorder.create(tmp_path / sub, CFG, seed=0, rows_per_write=rows_per_write)
    refused = []
    with rec:
        for i, row in enumerate(rows):
            try:
                rec.write_row(row)
            except ValueError as err:
                refused.append((i, str(err)))
        kept = rec.kept_columns()
    return (rec.path / LOG_FILE).read_bytes(), kept, refused, rec.rows_written


def _same_columns(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return a.keys() == b.keys() and all(
        a[k].dtype == b[k].dtype and (np.array_equal(a[k], b[k]) if a[k].dtype == object
                                      else np.array_equal(a[k], b[k], equal_nan=True))
        for k in a)


@pytest.mark.parametrize("odd", [0.0, 0.01, 0.2])
@pytest.mark.parametrize("rows_per_write", [2, 7, 64])
def test_blocks_write_what_one_row_a_write_writes(tmp_path, odd, rows_per_write):
    rng = random.Random(int(odd * 1000) + rows_per_write)
    rows = [_row(rng, odd) for _ in range(600)]
    one = _write(tmp_path, rows, 1, "one")
    block = _write(tmp_path, rows, rows_per_write, "block")
    assert block[0] == one[0]
    assert block[2] == one[2]  # refused alike, at once
    assert block[3] == one[3]
    assert _same_columns(block[1], one[1])


def _tick_like(rng: random.Random, k: int) -> dict:
    """A lockstep-like row: the same keys every tick, floats and np.float64, one NaN cell,
    a few strings; now and then an infinite age or a None."""
    row = {name: rng.gauss(0.0, 3.0) for name in LOG_COLUMNS[:40] if name not in STRING_COLUMNS}
    row["t_s"] = k * 0.0625
    row["x_m"] = np.float64(rng.random())
    row["nav_state_bits"] = math.nan
    row["mode"], row["solver_status"], row["cmd_saturated"] = "track", "ok", "0000"
    if k % 97 == 5:
        row["mocap_age_ms"] = math.inf
    if k % 89 == 3:
        row["battery_pct"] = None
    if k % 131 == 7:
        row["vx_mps"] = -np.float64(math.inf)
    return row


def test_lockstep_like_rows_in_blocks(tmp_path):
    rng = random.Random(3)
    rows = [_tick_like(rng, k) for k in range(1500)]
    one = _write(tmp_path, rows, 1, "one")
    block = _write(tmp_path, rows, 64, "block")
    assert block[0] == one[0] and not one[2]
    assert _same_columns(block[1], one[1])


def test_held_rows_reach_the_file_on_flush_close_and_in_time(tmp_path, monkeypatch):
    rng = random.Random(4)
    rec = RunRecorder.create(tmp_path, CFG, seed=0, rows_per_write=64)
    log = rec.path / LOG_FILE
    header = log.read_bytes()
    for k in range(10):
        rec.write_row(_tick_like(rng, k))
    assert log.read_bytes() == header and rec.rows_written == 10  # held
    rec.flush()
    after_flush = log.read_bytes()
    assert after_flush.count(b"\n") == 11
    # a row held longer than HOLD_S goes out with the next one
    monkeypatch.setattr(RunRecorder, "HOLD_S", 0.0)
    rec.write_row(_tick_like(rng, 10))
    time.sleep(0.001)
    rec.write_row(_tick_like(rng, 11))
    assert log.read_bytes().count(b"\n") == 13
    monkeypatch.undo()
    rec.write_row(_tick_like(rng, 12))
    rec.close()
    assert log.read_bytes().count(b"\n") == 14
    rec.close()  # idempotent


@pytest.mark.parametrize("odd", [0.0, 0.01])
def test_blocks_of_rows_without_infinities_take_the_block_path(tmp_path, monkeypatch, odd):
    """The fuzzed rows of test_recorder_plain_line with every ±inf made NaN: the blocks are
    printed by block_text (counted), and the bytes are one row a write's."""
    from ardrone_nmpc.runs import rundir

    printed = []
    real = rundir.block_text
    monkeypatch.setattr(rundir, "block_text",
                        lambda rows: printed.append(real(rows) is not None) or real(rows))
    rng = random.Random(11 + int(odd * 100))

    def finite(v):
        return math.nan if isinstance(v, float) and math.isinf(v) else v

    rows = [{k: finite(v) for k, v in _row(rng, odd).items()} for _ in range(800)]
    one = _write(tmp_path, rows, 1, "one")
    block = _write(tmp_path, rows, 16, "block")
    assert block[0] == one[0] and block[2] == one[2]
    assert _same_columns(block[1], one[1])
    assert sum(printed) >= len(printed) // 2 > 5


def test_a_simulations_run_directory_is_not_fsynced_and_the_same(tmp_path, monkeypatch):
    """durable=False (record_lockstep): no fsync, the same config.yaml and summary.csv."""
    import datetime as dt
    import os

    from ardrone_nmpc.runs.rundir import CONFIG_FILE, SUMMARY_FILE, SummaryRow

    now = dt.datetime(2026, 1, 2, 3, 4, 5, tzinfo=dt.timezone.utc)
    rows = [SummaryRow("x", "rmse", 0.1, "m"), SummaryRow("run", "ticks", 5.0, "count")]
    texts = {}
    for durable in (True, False):
        synced = []
        real = os.fsync
        monkeypatch.setattr(os, "fsync", lambda fd: synced.append(fd) or real(fd))
        with RunRecorder.create(tmp_path / str(durable), CFG, seed=1, now=now,
                                durable=durable) as rec:
            rec.write_summary(rows)
        monkeypatch.undo()
        assert bool(synced) is durable
        texts[durable] = [(rec.path / name).read_bytes() for name in (CONFIG_FILE, SUMMARY_FILE)]
    assert texts[True] == texts[False]


@pytest.mark.parametrize("written", [False, True])
def test_an_interrupt_at_the_blocks_write_neither_loses_nor_repeats_rows(tmp_path, monkeypatch,
                                                                         written):
    """A KeyboardInterrupt (a signal) raised in the block's write: before the bytes reached
    the file the rows stay held and close writes them; after, they are not written again."""
    from ardrone_nmpc.runs import rundir

    rng = random.Random(6)
    rows = [_tick_like(rng, k) for k in range(70)]
    expected = _write(tmp_path, rows, 1, "one")[0]
    rec = RunRecorder.create(tmp_path / "block", CFG, seed=0, rows_per_write=64)
    real = rundir._write_all

    def interrupted(raw, data):
        if written:
            real(raw, data)
        raise KeyboardInterrupt

    monkeypatch.setattr(rundir, "_write_all", interrupted)
    with pytest.raises(KeyboardInterrupt):
        for row in rows:
            rec.write_row(row)
    monkeypatch.undo()
    rec.close()
    text = (rec.path / LOG_FILE).read_bytes()
    assert text == expected[:len(text)] and text.count(b"\n") == 65  # header + 64 rows


def test_the_events_encoder_writes_what_json_dumps_wrote():
    """RunRecorder.event's encoder, made once, against json.dumps with its arguments."""
    import enum
    import json
    from pathlib import Path

    from ardrone_nmpc.runs import rundir

    class Kind(enum.Enum):
        A = "a"

    rng = random.Random(8)
    values = [1.5, math.nan, math.inf, -0.0, 1e-7, "é", 'q"', np.float64(2.5), np.int64(3),
              np.arange(3), Kind.A, {2, 1}, Path("/x"), None, True, [1, {"a": 2.5}]]
    for _ in range(500):
        record = {"t_s": rng.random(), "kind": "k",
                  **{f"f{i}": rng.choice(values) for i in range(rng.randint(0, 5))}}
        assert rundir._EVENT_JSON.encode(record) == json.dumps(
            record, default=rundir._json_default, separators=(",", ":"))


@pytest.mark.parametrize("bad", [{"mode": "tr\udcffack"},  # a lone surrogate: not UTF-8
                                 {"gmres_iterations": 10 ** 400}])  # float() overflows
def test_a_row_that_cannot_be_written_is_refused_at_once_not_held(tmp_path, bad):
    """Held, such a row failed the whole block at its write (the error at a later row or at
    close, every row of the block lost): it is refused at write_row, as one row a write."""
    rows = [{"t_s": k * 0.0625, "mode": "track", "gmres_iterations": 3} for k in range(10)]
    rows[5] = {**rows[5], **bad}
    outcome = []
    for rows_per_write in (1, 64):
        rec = RunRecorder.create(tmp_path / str(rows_per_write), CFG, seed=0,
                                 rows_per_write=rows_per_write)
        refused = []
        with rec:
            for i, row in enumerate(rows):
                try:
                    rec.write_row(row)
                except (ValueError, OverflowError) as err:
                    refused.append((i, type(err).__name__, str(err)))
        outcome.append(((rec.path / LOG_FILE).read_bytes(), refused))
    assert outcome[1] == outcome[0]
    assert [i for i, *_ in outcome[0][1]] == [5]
    assert outcome[0][0].count(b"\n") == 1 + 9  # the header and the nine good rows


@pytest.mark.parametrize("go_on", [False, True])
def test_an_interrupt_in_the_bookkeeping_after_the_blocks_write_repeats_no_row(tmp_path,
                                                                               go_on):
    """A KeyboardInterrupt landing after the block reached the file but before the recorder
    noted it (here: as the write's ``finally`` asks the file's position) — close, or the
    next block, must not write those rows again; rows held since are still written."""
    rng = random.Random(8)
    rows = [_tick_like(rng, k) for k in range(150)]
    expected = _write(tmp_path, rows, 1, "one")[0]
    rec = RunRecorder.create(tmp_path / "block", CFG, seed=0, rows_per_write=64)
    log = rec._log
    interrupt = {"armed": False, "blocks": 0}

    class Log:  # the real file, its tell() interrupted once after the first block's write
        closed = property(lambda self: log.closed)

        def write(self, data):
            n = log.write(data)
            interrupt["blocks"] += 1
            interrupt["armed"] = interrupt["blocks"] == 1
            return n

        def tell(self):
            if interrupt["armed"]:
                interrupt["armed"] = False
                raise KeyboardInterrupt
            return log.tell()

        def close(self):
            log.close()

    rec._log = Log()
    n = 0
    with pytest.raises(KeyboardInterrupt):
        for n, row in enumerate(rows, 1):
            rec.write_row(row)
    assert n == 64
    if go_on:  # a caller that goes on writing (the next block settles the interrupted one)
        for row in rows[n:]:
            rec.write_row(row)
    rec.close()
    text = (rec.path / LOG_FILE).read_bytes()
    assert text == (expected if go_on else expected[:len(text)])
    assert text.count(b"\n") == 1 + (len(rows) if go_on else 64)
