"""The P controller's flights fly blocks of ticks (``runtime/control_tick_p``,
``lockstep_block.tick_block_p``), and their rows are the per-tick path's.

The oracle is the per-tick path as it was before P's compiled tick (``lockstep.BLOCK_TICKS
= 0`` and no ``PControlTick``: ``Tick.step``'s Python stages and ``p_tick``): each flight is
flown both ways and every row must be the same keys in the same order with the same values'
bits and Python types (the clock cell ``compute_us``: its type only) — so ``log.csv``'s
bytes are the same too —, the same events and ending. Flights: a wind, a command delay and
a delay jump (the response fit's events between blocks), the drone's and P's own gains not 1
(commands beyond the tilt cap: ticks whose law's answer Python sends), a supervisor's
landing with its logged descent, an emergency stop mid-flight, a moving obstacle (a second
object: rows with its cells, ``p_cells_row(…, target=True)``). The compiled tick one tick at
a time leaves the Python stages' state after every tick, too.
"""

from __future__ import annotations

import math
import pickle
import struct
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime import lockstep_block as lb
from ardrone_nmpc.runtime.after_solve import after_solve
from ardrone_nmpc.runtime.control_tick_p import PControlTick
from ardrone_nmpc.runtime import tick as tick_module
from ardrone_nmpc.runtime.tick import Tick
from tests.tick_flights import carried, fly

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
SHORT = ["duration_s=6", "sim.settle_s=1", "controller.kind=p"]
CASES = [
    ("wind", "hover", [*SHORT, "faults.wind.velocity_mps=[0.6,0.2,0]"], 1),
    ("delay", "step_x", [*SHORT, "sim.plant.command_delay_s=0.4",
                         "faults.delay_jump.start_s=2", "controller.adaptation.refit_s=0.2"], 2),
    # the drone tilts 0.6 of the nominal; P's gains high: commands beyond the tilt cap
    ("gains", "square", [*SHORT, "sim.plant.attitude_gain=0.6",
                         "controller.p_gains.k2_rad_per_mps=0.9",
                         "controller.p_gains.k3_rad_per_mps=0.9",
                         "controller.p_gains.k1_per_s=1.3"], 3),
    # the battery reaches the floor: the supervisor lands, the descent's ticks logged
    ("landing", "square", ["duration_s=10", "sim.settle_s=1", "controller.kind=p",
                           "sim.plant.battery_start_pct=23",
                           "sim.plant.battery_drain_pct_per_min=30"], 0),
    ("emergency", "square", [*SHORT, "faults.emergency.start_s=3"], 0),
    # a second object in the mocap frames: rows with its cells (blocks.target and blocks.p)
    ("moving_obstacle", "moving_obstacle", SHORT, 1),
]


def _bits(value):
    """A cell as (type, bits): NaN equal to NaN, −0.0 apart from 0.0."""
    if isinstance(value, (float, np.floating)):
        return type(value).__name__, struct.pack("<d", float(value))
    return type(value).__name__, value


def _counted(monkeypatch) -> list:
    """``[ticks blocks flew]``, counted from now on (``TickBlocks.fly`` wrapped)."""
    flown = [0]
    fly = lb.TickBlocks.fly

    def counted(self, *args):
        answer = fly(self, *args)
        flown[0] += answer[0]
        return answer

    monkeypatch.setattr(lb.TickBlocks, "fly", counted)
    return flown


def _python_p_ticks(monkeypatch) -> None:
    """P's ticks the Python stages' and ``p_tick``'s, as before its compiled tick: no
    :class:`PControlTick` built (so no block either)."""
    monkeypatch.setattr(tick_module, "_p_tick_ready", lambda tick, compile_now: False)


def _fly(cfg, seed: int, block_ticks: int, monkeypatch) -> tuple:
    """The flight's rows (keys and cells' bits, the clock's type only), events and ending,
    and how many of its ticks blocks flew (``block_ticks`` 0: the Python stages' ticks)."""
    monkeypatch.setattr(lockstep, "BLOCK_TICKS", block_ticks)
    if block_ticks == 0:
        _python_p_ticks(monkeypatch)
    flown = _counted(monkeypatch)
    recorder = MemoryRecorder()
    result = lockstep.run_lockstep(cfg, recorder=recorder, seed=seed)
    rows = [[(k, type(v).__name__ if k == "compute_us" else _bits(v)) for k, v in row.items()]
            for row in recorder.rows]
    events = [{k: v for k, v in e.items() if k != "wall_s"} for e in recorder.events]
    return rows, pickle.dumps(events), (result.ticks, result.ending), flown[0]


@pytest.fixture(scope="module", autouse=True)
def _warm():
    lockstep.warm_up_blocks()  # (tick_block_p: loaded, or compiled once)


@pytest.mark.parametrize("name, config, overrides, seed", CASES, ids=[c[0] for c in CASES])
def test_p_block_rows_are_the_per_tick_path_s(name, config, overrides, seed, monkeypatch):
    cfg = load_config(CONFIGS / f"{config}.yaml", overrides)
    rows_b, events_b, end_b, in_blocks = _fly(cfg, seed, lockstep.BLOCK_TICKS, monkeypatch)
    rows_p, events_p, end_p, none = _fly(cfg, seed, 0, monkeypatch)
    assert none == 0
    assert in_blocks > len(rows_b) // 2  # (blocks flew most of the ticks)
    assert len(rows_b) == len(rows_p)
    for i, (a, b) in enumerate(zip(rows_b, rows_p)):
        assert a == b, f"row {i}"
    assert events_b == events_p
    assert end_b == end_p
    if name == "landing":
        assert end_b[1] == "land-battery" and ("mode", ("str", "landing")) in rows_b[-1]
    if name == "emergency":
        assert end_b[1] == "stop-emergency"
    if name == "moving_obstacle":  # (the object's cells in every row)
        assert all(dict(row)["target_x_m"][0] == "float64" for row in rows_b[5:])


@pytest.mark.parametrize("overrides", [
    [*SHORT, "sim.plant.command_delay_s=0.4", "controller.adaptation.refit_s=0.2"],
    [*SHORT, "faults.battery_floor.start_s=3"],
    CASES[2][2],  # (commands beyond the tilt cap: clipped, in the ring as sent)
], ids=["refits", "battery_floor", "gains"])
def test_p_s_compiled_tick_leaves_the_python_stages_state(overrides, monkeypatch):
    """Tick by tick (no blocks), P's compiled tick leaves every stage as the Python stages
    and ``p_tick`` do (``tick_flights.carried``: the delay ring, the supervisor, the
    estimate, the response fit, …) — but ``Control._x_solve`` and ``_states``, the compiled
    tick's scratch (the Python P path writes neither: ``np.empty``'s bits)."""
    cfg = load_config(CONFIGS / "square.yaml", overrides)
    built = []

    def use(tick) -> None:
        built.append(isinstance(tick.control_tick, PControlTick))
        state = carried(tick)  # (the scratch's place in it)
        assert state[scratch] == [tick.control._x_solve.tobytes(), tick.control._states.tobytes()]

    scratch = slice(16, 18)  # (carried's c._x_solve, c._states)
    rows_c, events_c, states_c = fly(cfg, monkeypatch, use=use)
    with monkeypatch.context() as m:
        _python_p_ticks(m)
        rows_p, events_p, states_p = fly(cfg, monkeypatch, use=lambda tick: None)
    assert built == [True]
    assert len(states_c) == len(states_p) > 50
    for k, (a, b) in enumerate(zip(states_c, states_p)):
        del a[scratch], b[scratch]
        assert a == b, f"tick {k}"
    assert [[_bits(v) for k, v in r.items() if k != "compute_us"] for r in rows_c] == \
        [[_bits(v) for k, v in r.items() if k != "compute_us"] for r in rows_p]
    unclocked = [[{k: v for k, v in e.items() if k != "wall_s"} for e in events]
                 for events in (events_c, events_p)]
    assert pickle.dumps(unclocked[0]) == pickle.dumps(unclocked[1])


def test_a_p_flight_s_rows_have_no_solver_cells(monkeypatch):
    """The P rows a block writes: no solver's figures, no z̈, an empty status — and the
    flight's ticks but its first few are blocks'."""
    cfg = load_config(CONFIGS / "square.yaml", SHORT)
    recorder = MemoryRecorder()
    flown = _counted(monkeypatch)
    result = lockstep.run_lockstep(cfg, recorder=recorder)
    assert flown[0] >= result.ticks - 3
    for row in recorder.rows:
        assert not {"solve_us", "residual_norm", "gmres_iterations",
                    "newton_iterations"} & set(row)
        assert row["solver_status"] == "" and math.isnan(row["u_zacc_mps2"])


@pytest.mark.parametrize("config, overrides, taken", [
    ("square", ["controller.kind=p"], True),
    *(("square", ["controller.kind=p", f"estimator.kind={kind}"], True)
      for kind in ("luenberger", "difference", "none")),  # (every ż estimator: compiled)
    ("ellipse", ["controller.kind=p"], False),  # (a curve's table: not p_tick's)
])
def test_the_p_controller_s_tick_is_compiled_against_waypoints(config, overrides, taken):
    cfg = load_config(CONFIGS / f"{config}.yaml", overrides)
    from ardrone_nmpc.reference.experiment import experiment_trajectory

    tick = Tick(cfg, experiment_trajectory(cfg))
    assert isinstance(tick.control_tick, PControlTick) is taken
    if taken:
        assert lb.BLOCK_KERNELS[tick.control_tick.kernel] is lb.tick_block_p


@pytest.mark.parametrize("vz", [0.0, -0.0, 1e-300, -2.5, 7.0, 1e300])
def test_the_law_s_vz_passes_the_stages_after_it_to_the_bit(vz):
    """``control_tick_p`` hands P's ż to ``after_solve`` as the base with z̈ 0 and a lead
    of −0, no limit: it comes back the same bits (a −0 too), as the Python stages send it."""
    ring = np.zeros((2, 4))
    x = np.zeros(7)
    answer = after_solve(0.0, 0.01, -0.02, 0.1, vz, -0.0, math.inf, 0.3, 1.0, 0.2, 1.0, 1.7,
                         ring, 0, np.zeros(0), 1, 1.0, 0.0, 0.0, 1.0, x, x, np.zeros((0, 7)),
                         np.zeros(0), np.zeros((3, 0), np.bool_))
    assert answer[0] == 0
    assert struct.pack("<d", answer[1]) == struct.pack("<d", vz)
    assert ring[0].tolist() == [0.0, 0.01, -0.02, 0.1]  # (the z̈ sent: 0)


@pytest.mark.parametrize("compile_now, cached, taken", [
    (False, False, False),  # a cold cache: p_tick's call a tick, the compile the background's
    (False, True, True), (True, False, True),  # (compile_now: compiled by its warm-up)
])
def test_p_s_compiled_tick_waits_for_the_background_compile(compile_now, cached, taken,
                                                              monkeypatch):
    from ardrone_nmpc.reference.experiment import experiment_trajectory
    from ardrone_nmpc.runtime import tick as tick_module

    monkeypatch.setattr(tick_module, "load_cached", lambda kernel: cached)
    cfg = load_config(CONFIGS / "square.yaml", ["controller.kind=p"])
    tick = Tick(cfg, experiment_trajectory(cfg), compile_now=compile_now)
    assert isinstance(tick.control_tick, PControlTick) is taken
