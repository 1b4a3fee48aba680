"""The recorder's one-call row printer (``row_text._plain_line``) against the per-cell way it
stands in for (``RunRecorder._line``: the cells into orjson one by one, or the careful path):
the same bytes for every row it takes, and every row it does not take is left to the other."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS
from ardrone_nmpc.runs.rundir import _EMPTY_CELLS, RunRecorder, _plain_line

NUMERIC = [c for c in LOG_COLUMNS if c not in STRING_COLUMNS]
STRINGS = sorted(STRING_COLUMNS)
TEXTS = ["", "ok", "track", "hold-stale-mocap", "flying", "0101", "null", "xtrue", "[a",
         "{b", "a,b", 'q"', "back\\slash", "tab\tx", "line\nx", "é", "nan", "false"]


def _float(rng: random.Random) -> float:
    pick = rng.random()
    if pick < 0.1:
        return rng.choice([math.nan, math.inf, -math.inf, -0.0, 0.0, 5e-324, 1e-7, 5.0, 1e16,
                           1.7976931348623157e308])
    if pick < 0.3:
        return float(rng.randint(-1000, 1000))
    return np.frombuffer(rng.randbytes(8), dtype=np.float64)[0].item() if pick < 0.5 \
        else rng.gauss(0.0, 10.0) ** rng.choice([1, 3])


def _number(rng: random.Random, odd: float):
    """A numeric cell: mostly float / np.float64 / int / None, sometimes an odd type."""
    pick = rng.random()
    if pick < odd:
        return rng.choice([np.float32(rng.gauss(0.0, 10.0)), np.int64(rng.randint(-9, 9)), True, False,
                           np.bool_(True), rng.choice(TEXTS), 2 ** 70, [1.0], np.float16(0.5),
                           np.longdouble(0.1)])
    if pick < 0.4:
        return np.float64(_float(rng))
    if pick < 0.5:
        return rng.randint(-2 ** 40, 2 ** 40)
    if pick < 0.53:
        return None
    return _float(rng)


def _row(rng: random.Random, odd: float) -> dict:
    row = {}
    for name in LOG_COLUMNS:
        if rng.random() < 0.15:
            continue  # a missing key: an empty cell
        if name in STRING_COLUMNS:
            row[name] = (rng.choice(TEXTS[:6]) if rng.random() > odd
                         else rng.choice([*TEXTS, math.nan, None, 1.0]))
        else:
            row[name] = _number(rng, odd)
    keys = list(row)
    if rng.random() < 0.3:
        rng.shuffle(keys)  # callers may build rows in any key order
    return {k: row[k] for k in keys}


def _per_cell(rec: RunRecorder, row: dict) -> bytes | Exception:
    try:
        return rec._line(row, rec._plan(tuple(row)))
    except ValueError as err:
        return err


@pytest.mark.parametrize("odd", [0.0, 0.02, 0.2])
def test_plain_line_prints_what_the_per_cell_way_prints(odd):
    rec = RunRecorder.__new__(RunRecorder)
    rec._plans = {}
    rng = random.Random(int(odd * 1000) + 7)
    taken = 0
    for _ in range(4000):
        row = _row(rng, odd)
        plan = rec._plan(tuple(row))
        line = _plain_line(list(map(row.get, LOG_COLUMNS, _EMPTY_CELLS)), plan[4])
        expected = _per_cell(rec, row)
        if line is not None:
            taken += 1
            assert line == expected, row
    assert taken > {0.0: 3000, 0.02: 50, 0.2: -1}[odd]  # plain rows take the one-call way


def test_write_row_writes_the_per_cell_bytes(tmp_path):
    """Through the file: rows of a lockstep flight's shapes, NaN cells included."""
    from ardrone_nmpc.config.io import load_config

    cfg = load_config(overrides=["name=plain", "duration_s=1"])
    rng = random.Random(3)
    rows = [_row(rng, 0.05) for _ in range(500)]
    expected = b""
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for row in rows:
            line = _per_cell(rec, row)
            if isinstance(line, bytes):
                rec.write_row(row)
                expected += line
            else:
                with pytest.raises(ValueError):
                    rec.write_row(row)
    text = (rec.path / "log.csv").read_bytes()
    assert text.split(b"\n", 1)[1] == expected
