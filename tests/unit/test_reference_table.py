"""A curve's reference read from a table (issue 26): ``runtime/tick_kernels``'
``fill_reference_table`` fills it with the reference's own ``state_at`` — one call for a
block of ticks' horizon times —, ``nmpc_inputs`` copies a tick's rows from it and
``table_tick`` finds them by their times. The states the compiled tick reads are then
``HoldStartThen.state_at``'s at each tick's times, asked alone, as the Python stages ask
them (``Control.solve``'s general path): bit for bit, at ticks of the settle phase, at t = 0,
along the curve and past a Lorenz path's end. That a state is the same bits whatever other
times it is asked with (``reference/experiment.tabulated``) is checked on dense grids too."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.numerics import callable_from_python
from ardrone_nmpc.core.types import STATE_DIM
from ardrone_nmpc.reference.experiment import HoldStartThen, tabulated
from ardrone_nmpc.reference.trajectories import Ellipse, Lorenz, Waypoints, make_trajectory
from ardrone_nmpc.runtime.tick_kernels import (TABLE_TICKS, fill_reference_table, nmpc_inputs,
                                               nmpc_work, nmpc_work_views, table_tick)

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
PERIOD_S = 0.065
N_TIMES = 13  # a horizon of 11 stages: the reference now and 12 times
table_tick_py = callable_from_python(table_tick)


def _curves() -> list[HoldStartThen]:
    def of(name: str, duration_s: float | None = None) -> HoldStartThen:
        cfg = load_config(str(ROOT / "configs" / name))
        return HoldStartThen(make_trajectory(cfg.reference, duration_s=duration_s))

    return [of("ellipse.yaml"), of("identify.yaml"), of("lorenz.yaml", 12.0),
            HoldStartThen(Ellipse((0.3, -0.2), (0.7, 1.3), 1.1, 7.3, -0.4))]


def _work(traj: HoldStartThen, dtau_s: float) -> tuple[np.ndarray, np.ndarray]:
    work, rows = nmpc_work(PERIOD_S, N_TIMES, traj.waypoint_args)
    offsets = nmpc_work_views(work)[0]
    np.multiply(dtau_s, np.arange(N_TIMES - 1, dtype=np.float64), out=offsets[1:])
    return work, rows


def _python_states(traj: HoldStartThen, t_s: float, lead_s: float,
                   offsets: np.ndarray) -> np.ndarray:
    """``Control.solve``'s general path: one tick's times, asked alone."""
    times = np.add(t_s + lead_s, offsets)
    times[0] = t_s
    return traj.state_at(times)


@pytest.mark.parametrize("lead_s, dtau_s", [(0.26, 0.1), (0.0, 0.08), (0.455, 0.065)])
def test_a_block_of_ticks_reads_each_ticks_states_bit_for_bit(lead_s, dtau_s):
    """Blocks of :data:`TABLE_TICKS` ticks from the settle phase (t < 0) over t = 0, along
    the curve and past a Lorenz path's end: each tick's states (and shifted horizon) through
    ``nmpc_inputs`` are the Python path's."""
    shift = np.array([0.02, -0.01, 0.005, 0.03])
    for traj in _curves():
        assert traj.tabulated and traj.waypoint_args[0].size == 0
        work, rows = _work(traj, dtau_s)
        offsets, _, _, horizon = nmpc_work_views(work)
        for k0 in (-40, -3, 0, 150, 170, 180, 400):
            ks = np.arange(k0, k0 + TABLE_TICKS)
            fill_reference_table(traj, ks * PERIOD_S, lead_s, work, rows)
            for k in ks:
                t_s = float(k) * PERIOD_S
                want = _python_states(traj, t_s, lead_s, offsets)
                states = np.full((N_TIMES, STATE_DIM), np.nan)
                x = np.zeros(STATE_DIM)
                nmpc_inputs(x, np.zeros((2, 4)), 0, 0, x, t_s, lead_s, shift, states, work,
                            rows)
                assert states.tobytes() == want.tobytes(), (type(traj.inner), t_s)
                shifted = want[1:].copy()
                shifted[:, [0, 2, 4, 6]] += shift
                assert horizon.tobytes() == shifted.tobytes()


def test_a_tick_not_in_the_table_is_found_nowhere():
    """``table_tick`` answers −1 for times the table does not hold — another tick, another
    lead, a NaN time, +0.0 for −0.0 (a state may differ there: an ellipse's ẋ, −aω·sin) —
    and ``nmpc_inputs`` then reads NaN states (``before_solve`` asks first: not nominal)."""
    traj = _curves()[0]
    work, rows = _work(traj, 0.1)
    assert table_tick_py(0.0, 0.26, work, rows) == -1  # (a new table: no tick's)
    fill_reference_table(traj, np.array([-0.0, 0.065, 0.13]), 0.26, work, rows)
    assert [table_tick_py(t, 0.26, work, rows) for t in (0.065, 0.13, -0.0)] == [1, 2, 0]
    for t_s, lead_s in ((0.0, 0.26), (0.195, 0.26), (0.065, 0.25), (math.nan, 0.26)):
        assert table_tick_py(t_s, lead_s, work, rows) == -1, (t_s, lead_s)
    states = np.zeros((N_TIMES, STATE_DIM))
    x = np.zeros(STATE_DIM)
    nmpc_inputs(x, np.zeros((2, 4)), 0, 0, x, 0.195, 0.26, np.zeros(0), states, work, rows)
    assert np.isnan(states).all()


@pytest.mark.parametrize("index", range(4))
def test_a_curves_state_is_the_same_whatever_else_is_asked(index):
    """The premise of the table (``tabulated``): a state at a time is the same bits asked
    among 200 000 times, in a horizon's 13, or alone."""
    traj = _curves()[index]
    rng = np.random.default_rng(index)
    t = np.concatenate([rng.uniform(-2.0, 80.0, 200_000), np.arange(-1.0, 20.0, 0.005),
                        [0.0, -0.0, 12.0, np.nextafter(12.0, 13.0)]])
    together = traj.state_at(t)
    for i in rng.choice(t.size, 300, replace=False):
        assert traj.state_at(t[i:i + 1]).tobytes() == together[i:i + 1].tobytes()
    for j in range(0, 2000, 13):
        assert traj.state_at(t[j:j + 13]).tobytes() == together[j:j + 13].tobytes()


def test_only_the_curves_own_classes_are_tabulated():
    class Shifted(Ellipse):
        def state_at(self, t_s):
            return super().state_at(t_s) + 1.0

    assert tabulated(Ellipse()) and tabulated(Lorenz(duration_s=5.0))
    assert not tabulated(Shifted())
    assert not tabulated(Waypoints([0.0, 1.0], [[0, 0, 1], [1, 0, 1]], [0.0, 0.0]))
    held = HoldStartThen(Shifted())
    assert not held.tabulated and held.waypoint_args is None
