"""``tick_row``'s one-literal path for the usual NMPC tick against the general path, row for
row over real flights: the same keys in the same order and the same bits in every cell."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs import log_columns
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime import tick as tick_module

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


class _DictRows(MemoryRecorder):
    """A MemoryRecorder the runner hands dict rows (its tick_cells rows skip tick_row)."""

    write_cells = None


def _bits(value):
    if isinstance(value, str) or value is None:
        return value
    return struct.pack("<d", float(value)) if not isinstance(value, int) else value


@pytest.mark.parametrize("config, overrides", [
    ("square.yaml", ["duration_s=4", "sim.settle_s=1"]),
    ("square.yaml", ["duration_s=3", "sim.settle_s=1", "controller.kind=p"]),
])
def test_fast_row_is_the_general_row(monkeypatch, config, overrides):
    seen = {"fast": 0, "all": 0}

    def checked(**kw):
        row = log_columns.tick_row(**kw)
        general = log_columns._general_row(**kw)
        assert list(row) == list(general)
        assert [_bits(v) for v in row.values()] == [_bits(v) for v in general.values()]
        seen["all"] += 1
        seen["fast"] += kw["solution"] is not None and kw["solution"].result is not None
        return row

    monkeypatch.setattr(tick_module, "tick_row", checked)
    cfg = load_config(CONFIGS / config, overrides)
    lockstep.run_lockstep(cfg, recorder=_DictRows())  # tick_row's rows (no write_cells)
    assert seen["all"] > 20
    if cfg.controller.kind == "nmpc":
        assert seen["fast"] > 20
