"""Blocks of ticks (``lockstep.BLOCK_TICKS``) against the per-tick path on combinations of
what issue 26's strands put in blocks, each checked alone in ``test_tick_blocks`` (whose
machinery this reuses): the thesis_kit plant, curves read from a table, ẋ, ẏ from the
navdata's speeds, injected faults (windows over the settle phase and the landing, faults in
a logged and in an unlogged landing), fits every 0.2 s, other periods — the same rows,
events, result and states; and ``MemoryRecorder``'s rows and columns of a flight's blocks,
cells and dicts read back as those of a recorder given every row as cells.
"""

from __future__ import annotations

import pytest

from ardrone_nmpc.runs.block_rows import BlockRows
from ardrone_nmpc.runs.log_columns import cells_row
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.sim.fault_injection import ServerFaults
from tests.integration.test_tick_blocks import (CLOCK_CELLS, KIT, SETTLE, _config,
                                                assert_same_flights, bits, fly, fly_both)

SHORT = ["duration_s=6", *SETTLE]
WIND = "faults.wind.velocity_mps=[0.3,-0.2,0]"
GUST = ["faults.wind_gust.start_s=2", "faults.wind_gust.duration_s=0.5"]
AT_LOSS = ["faults.at_loss.start_s=3", "faults.at_loss.duration_s=0.3",
           "faults.at_loss.probability=0.5"]
NAV = "estimator.horizontal_velocity=navdata"
FIT = "controller.adaptation.refit_s=0.2"
LOW_BATTERY = ["sim.plant.battery_start_pct=23", "sim.plant.battery_drain_pct_per_min=30"]
EXCITATION = ["reference.excitation.axis_s=2.4", "reference.excitation.rest_s=0.5",
              "reference.excitation.sweep_m=0.1"]

# (name, config, overrides, seed)
CASES = [
    ("kit_wind_navdata", "square", [*SHORT, KIT, WIND, NAV], 3),
    ("kit_ellipse_fit", "ellipse", [*SHORT, KIT, FIT], 4),
    ("kit_lorenz_gust", "lorenz", [*SHORT, KIT, *GUST], 5),
    ("ellipse_gust_at_loss", "ellipse", [*SHORT, *GUST, *AT_LOSS], 6),
    ("lorenz_delay_jump_fit", "lorenz",
     [*SHORT, FIT, "faults.delay_jump.start_s=2", "faults.delay_jump.delay_s=0.2"], 7),
    ("identify_battery_floor", "identify",
     [*SHORT, *EXCITATION, "faults.battery_floor.start_s=3"], 8),
    ("ellipse_emergency", "ellipse", [*SHORT, "faults.emergency.start_s=3"], 9),
    ("lorenz_self_land", "lorenz", [*SHORT, "faults.self_land.start_s=3"], 10),
    ("square_fit_faults", "square",
     [*SHORT, FIT, *GUST, "faults.delay_jump.start_s=3", "faults.delay_jump.delay_s=0.15",
      "faults.at_loss.start_s=4", "faults.at_loss.duration_s=0.2"], 11),
    # windows over the settle phase (start < 0) and past the end (the unlogged landing's
    # descent: blocks up to the first tick one may act at)
    ("windows_over_settle_and_landing", "square",
     ["duration_s=5", *SETTLE, "faults.wind_gust.start_s=-0.4",
      "faults.wind_gust.duration_s=0.8", "faults.at_loss.start_s=4.8",
      "faults.at_loss.duration_s=2", "faults.at_loss.probability=0.5"], 12),
    ("kit_faults_in_unlogged_landing", "square",
     ["duration_s=4", *SETTLE, KIT, "faults.wind_gust.start_s=4.2",
      "faults.wind_gust.duration_s=0.3", "faults.emergency.start_s=4.6"], 15),
    ("period_0.05_kit_faults", "square",
     ["duration_s=5", *SETTLE, "loop.period_s=0.05", KIT, *GUST,
      "faults.delay_jump.start_s=3"], 13),
    ("period_1/30_ellipse_navdata_wind", "ellipse",
     ["duration_s=5", *SETTLE, "loop.period_s=0.03333333333333333", NAV, WIND], 14),
    ("period_0.04_identify_kit_fit", "identify",
     ["duration_s=5", *SETTLE, "loop.period_s=0.04", KIT, FIT, *EXCITATION, *AT_LOSS], 16),
    # the supervisor lands (low battery): faults start in the logged landing
    ("low_battery_faults_in_landing", "square",
     ["duration_s=10", *SETTLE, *LOW_BATTERY, "faults.wind_gust.start_s=3.6",
      "faults.wind_gust.duration_s=3", "faults.at_loss.start_s=3.8",
      "faults.at_loss.duration_s=2", "faults.at_loss.probability=0.3",
      "faults.delay_jump.start_s=4"], 0),
    ("kit_low_battery_faults", "square",
     ["duration_s=10", *SETTLE, KIT, *LOW_BATTERY, "faults.delay_jump.start_s=5",
      "faults.wind_gust.start_s=6.5", "faults.wind_gust.duration_s=2"], 0),
]


def _case(name: str) -> tuple:
    return next(c for c in CASES if c[0] == name)


@pytest.mark.parametrize("name, config, overrides, seed", CASES, ids=[c[0] for c in CASES])
def test_combinations_change_nothing(name, config, overrides, seed, monkeypatch):
    """Each combination with the module's blocks and without: the same bits."""
    assert_same_flights(*fly_both(_config(config, overrides), seed, monkeypatch))


@pytest.mark.parametrize("name, block_ticks, close_every", [
    ("kit_lorenz_gust", 7, 3), ("ellipse_gust_at_loss", None, 1),
    ("period_0.04_identify_kit_fit", 1, 0), ("square_fit_faults", 1000, 0)])
def test_combinations_in_other_blocks(name, block_ticks, close_every, monkeypatch):
    """Other block lengths, and chains written back mid-flight: the same bits."""
    _, config, overrides, seed = _case(name)
    assert_same_flights(*fly_both(_config(config, overrides), seed, monkeypatch, block_ticks,
                                  close_every=close_every))


@pytest.mark.parametrize("name", ["period_0.05_kit_faults", "kit_low_battery_faults"])
def test_kit_fault_flights_fly_blocks_as_the_drones_own_chain(name, monkeypatch):
    """A kit flight with faults in blocks, and without blocks every PCMD and REF land through
    the drone's own chain (its AT-loss decision asked every tick): the same bits."""
    _, config, overrides, seed = _case(name)
    cfg = _config(config, overrides)
    block = fly(cfg, seed, monkeypatch, block_ticks=None, wanted=set())
    monkeypatch.setattr(ServerFaults, "at_loss_acts", lambda self, now_s: True)
    plain = fly(cfg, seed, monkeypatch, block_ticks=0, wanted=set())
    assert block.steps * 2 < plain.steps
    assert_same_flights(block, plain)


# ---------------------------------------------------------------- MemoryRecorder
def _columns_bits(recorder: MemoryRecorder) -> dict:
    """The recorder's ``columns()`` as bits (the clock columns: their dtype only)."""
    return {name: (arr.dtype.str, arr.shape) if name in CLOCK_CELLS else bits(arr)
            for name, arr in recorder.columns().items()}


def _rows_bits(recorder: MemoryRecorder) -> list:
    return [tuple((k, type(v).__name__ if k in CLOCK_CELLS else bits(v)) for k, v in r.items())
            for r in recorder.rows]


def _as_cells(recorder: MemoryRecorder) -> MemoryRecorder:
    """A recorder given the same rows, a block's one by one as cells (a dict as a dict)."""
    other = MemoryRecorder()
    for row in recorder._rows:
        if row.__class__ is BlockRows:
            for cells in row.cells():
                other.write_cells(cells)
        elif row.__class__ is list:
            other.write_cells(row)
        else:
            other.write_row(row)
    return other


def assert_same_memory(got: MemoryRecorder, want: MemoryRecorder) -> None:
    """``got`` (with blocks of rows) reads back as ``want`` and as a recorder given each of
    its rows as cells: ``rows_written``, ``rows`` (dicts) and ``columns()``."""
    kinds = {row.__class__.__name__ for row in got._rows}
    assert "BlockRows" in kinds, kinds
    cells = _as_cells(got)
    assert got.rows_written == want.rows_written == cells.rows_written
    columns = _columns_bits(want)
    for name, other in (("blocks", _columns_bits(got)), ("as cells", _columns_bits(cells))):
        apart = [c for c in columns if other.get(c) != columns[c]]
        assert not apart and other.keys() == columns.keys(), (name, apart[:8])
    assert _rows_bits(got) == _rows_bits(want) == _rows_bits(cells)


@pytest.mark.parametrize("name", ["ellipse_emergency", "lorenz_self_land",
                                  "low_battery_faults_in_landing", "kit_wind_navdata"])
def test_memory_recorder_reads_blocks_as_cells(name, monkeypatch):
    """A block flight's recorder (blocks, cells and — a landing's, a stop's — dicts) reads
    back as the per-tick flight's."""
    _, config, overrides, seed = _case(name)
    block, plain = fly_both(_config(config, overrides), seed, monkeypatch)
    assert_same_memory(block.recorder, plain.recorder)


def test_memory_recorder_mixes_blocks_cells_and_dicts(monkeypatch):
    """A recorder given a flight's rows as blocks, cells and dicts in turn (dicts between
    blocks, blocks after dicts) reads back as one given every row as cells."""
    _, config, overrides, seed = _case("low_battery_faults_in_landing")
    flight = fly(_config(config, overrides), seed, monkeypatch, block_ticks=7, wanted=set())
    mixed, i = MemoryRecorder(), 0
    for row in flight.recorder._rows:
        if row.__class__ is BlockRows:  # half a block, then its rows as dicts and cells
            half = len(row) // 2
            first, rest = (BlockRows(numbers, row.mode, row.saturated, row.status,
                                     row.nav_mode)
                           for numbers in (row.numbers[:half], row.numbers[half:]))
            mixed.write_block(first)
            for j, cells in enumerate(rest.cells()):
                mixed.write_cells(cells) if j % 2 else mixed.write_row(cells_row(cells))
        elif row.__class__ is list:
            i += 1
            mixed.write_cells(row) if i % 2 else mixed.write_row(cells_row(row))
        else:
            mixed.write_row(row)
    kinds = {row.__class__.__name__ for row in mixed._rows}
    assert kinds == {"BlockRows", "list", "dict"}, kinds
    assert_same_memory(mixed, _as_cells(flight.recorder))
