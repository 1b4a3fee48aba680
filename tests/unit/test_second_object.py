"""A second mocap object's frames in a block's kernel (``runtime/second_object.take_frame``)
are the per-tick path's: the pose ``sim/target.target_pose`` draws (its scripted motion,
its noise from the sampler's generator), the moving obstacle's filter and centres
``runtime/stages.MovingObstacles.update`` leaves — bit for bit, against those Python
functions themselves fed the same frames. (Whole flights, blocks against the per-tick path:
tests/integration/test_tick_blocks.py.)"""

from __future__ import annotations

import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from ardrone_nmpc.control.obstacles import OBS_COLS, OBS_X
from ardrone_nmpc.core.numerics import callable_from_python
from ardrone_nmpc.runs.log_columns import (LOG_COLUMNS, TARGET_CELL_KEYS, TICK_CELL_KEYS,
                                           target_cells_row)
from ardrone_nmpc.runtime import second_object as so
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.reference.live import LiveTarget
from ardrone_nmpc.runtime.stages import MovingObstacles
from ardrone_nmpc.runtime.tick_kernels import TABLE_TICKS, W_HEAD, W_TIMES
from ardrone_nmpc.sim.normal_blocks import NormalBlocks
from ardrone_nmpc.sim import target as target_module
from ardrone_nmpc.sim.target import target_pose, target_state

# the kernels' twins Python can call (the same source and options: the same machine code)
target_numbers = callable_from_python(target_module.target_numbers)
take_frame = callable_from_python(so.take_frame)
followed = callable_from_python(so.followed)


def _bits(x: float) -> bytes:
    return struct.pack("<d", float(x))


def _cfg(path: str, speed: float = 0.3):
    return SimpleNamespace(path=path, center_m=(1.0, -0.5, 0.25), radius_m=1.3,
                           speed_mps=speed)


@pytest.mark.parametrize("path", ["circle", "figure8"])
@pytest.mark.parametrize("speed", [0.3, 0.0])
def test_target_numbers_are_target_states_bits(path, speed):
    cfg = _cfg(path, speed)
    for t in np.linspace(-3.0, 250.0, 997).tolist() + [0.0, 1e-300, 12345.678]:
        pos, psi, _ = target_state(cfg, t)
        got = target_numbers(path == "circle", cfg.radius_m, cfg.speed_mps, *cfg.center_m, t)
        assert [_bits(v) for v in got] == [_bits(v) for v in (*pos, psi)], t


class _Solver:
    """A stand-in for the NMPC's obstacle table and its move (solver_base's)."""

    def __init__(self, n: int) -> None:
        self.obstacles = np.arange(n * OBS_COLS, dtype=np.float64).reshape(n, OBS_COLS)

    def move_obstacles(self, centres: np.ndarray) -> None:
        self.obstacles[:, OBS_X:OBS_X + 3] = centres


def _object(cfg, std: float, rows: list[int], ahead_s: float) -> np.ndarray:
    o = np.zeros(so.O_ROWS + len(rows))
    o[so.O_ON], o[so.O_CIRCLE] = 1.0, 1.0 if cfg.path == "circle" else 0.0
    o[so.O_R], o[so.O_V], o[so.O_CX:so.O_CZ + 1] = cfg.radius_m, cfg.speed_mps, cfg.center_m
    o[so.O_STD], o[so.O_STAMP] = std, math.nan
    o[so.O_MOVING], o[so.O_AHEAD_S], o[so.O_TAU_S] = 1.0, ahead_s, 0.2
    o[so.O_N_ROWS], o[so.O_ROWS:] = len(rows), rows
    return o


@pytest.mark.parametrize("std", [0.0005, 0.0])
@pytest.mark.parametrize("path", ["circle", "figure8"])
def test_frames_are_target_poses_and_the_moving_obstacles_update(std, path):
    """Frames at uneven times (one seen twice: the filter takes it once): the kernel's
    pose, filter and table equal target_pose's (its generator) and MovingObstacles'."""
    cfg, rows, ahead = _cfg(path), [0, 2], 0.37
    rng_py, rng_k = np.random.default_rng(11), np.random.default_rng(11)
    python = MovingObstacles(_Solver(3), rows, ahead)
    table = _Solver(3).obstacles
    o = _object(cfg, std, rows, ahead)
    draws = NormalBlocks(rng_k, 16)
    times = [0.01, 0.02, 0.035, 0.035, 0.1, 0.101, 0.3, 0.31]
    pose = None
    for i, t in enumerate(times):
        if i and t == times[i - 1]:  # the same pose again (a tick without a new frame):
            python.update(pose)      # the kernel is given each frame once
            continue
        pose = target_pose(cfg, t, rng_py, std)
        python.update(pose)
        draws.ensure(3)
        o[so.O_USED] = 0.0
        take_frame(o, draws.values[draws.pos:], t, t + 0.008, table)
        draws.pos += int(o[so.O_USED])
        got = o[[so.O_X, so.O_Y, so.O_Z, so.O_PSI, so.O_T]].tolist()
        assert [_bits(v) for v in got] == [_bits(v) for v in (*pose.position_m, pose.psi_rad,
                                                              pose.t_s)]
        track = python.track
        assert [_bits(v) for v in o[so.O_VX:so.O_VZ + 1]] == [
            _bits(v) for v in track.velocity_mps]
        assert table.tobytes() == python.nmpc.obstacles.tobytes()
    assert o[so.O_TOOK] == 1.0 and o[so.O_RX] == times[-1] + 0.008
    assert np.any(python.track.velocity_mps != 0.0)  # (the filter moved)


def test_a_target_row_has_the_general_rows_keys_in_order():
    """tick_row's row of a tick with a second object: the usual keys with the object's six
    after the navdata's (log_columns' general path: measurements, then the object)."""
    assert len(TARGET_CELL_KEYS) == len(TICK_CELL_KEYS) + 6
    at = TARGET_CELL_KEYS.index("target_x_m")
    assert TARGET_CELL_KEYS[at - 1] == "nav_state_bits" and TARGET_CELL_KEYS[at + 6] == "x_m"
    cells = [float(i) for i in range(len(LOG_COLUMNS))]
    row = target_cells_row(cells)
    assert list(row) == list(TARGET_CELL_KEYS)
    assert all(row[k] == LOG_COLUMNS.index(k) for k in row)
    assert type(row["target_x_m"]) is np.float64 and type(row["target_t_s"]) is float


@pytest.mark.parametrize("overrides", [
    [], ["reference.follow.offset_frame=object", "reference.follow.heading=object"],
    ["reference.follow.predict=false"]], ids=["world", "object", "no_predict"])
def test_a_followed_object_is_observed_and_its_table_filled_as_live_targets(overrides):
    """Ticks with and without a new frame, the pose fresh and stale (a 10 ms limit): the
    kernel's table rows equal ``LiveTarget.observe`` then ``state_at`` at the horizon times
    ``fill_reference_table`` makes (its time column too), the freshness and the filter."""
    ref = load_config(None, ["reference.kind=follow", "reference.start_m=[1,2,1]",
                             "reference.start_psi_rad=0.3", "reference.follow.max_age_ms=10",
                             "reference.follow.offset_m=[0.4,-0.2,1.0]", *overrides]).reference
    live = LiveTarget(ref)
    cfg, n, lead = _cfg("circle"), 6, 0.26
    work = np.zeros(W_HEAD + n)
    work[W_TIMES], work[W_HEAD:] = n, np.arange(n) * 0.1
    rows = np.full((TABLE_TICKS * n, 8), np.nan)
    o = _object(cfg, 0.0005, [], 0.0)
    o[so.O_MOVING], o[so.O_TAU_S] = 0.0, live._object.time_constant_s
    o[so.O_FOLLOW], o[so.O_MAX_AGE_MS] = 1.0, ref.follow.max_age_ms
    o[so.O_PREDICT] = 1.0 if ref.follow.predict else 0.0
    o[so.O_HEADING] = 1.0 if ref.follow.heading == "object" else 0.0
    o[so.O_FIXED_PSI], o[so.O_OX:so.O_OZ + 1] = live.fixed_psi_rad, ref.follow.offset_m
    o[so.O_OBJECT_FRAME] = 1.0 if ref.follow.offset_frame == "object" else 0.0
    o[so.O_START_X:so.O_START_Z + 1] = ref.start_m
    rng, draws = np.random.default_rng(4), NormalBlocks(np.random.default_rng(4), 64)
    t_zero, pose, fresh = 2.0, None, set()
    no_obstacles = np.zeros((0, OBS_COLS))
    for k in range(12):
        t_s = t_zero + 0.065 * k
        if k % 3 != 2:  # a new frame, 3 or 8 ms before the tick; else the last again
            t_frame = t_s - (0.003 if k % 2 else 0.008)
            pose = target_pose(cfg, t_frame, rng, 0.0005)
            draws.ensure(3)
            o[so.O_USED] = 0.0
            take_frame(o, draws.values[draws.pos:], t_frame, t_frame, no_obstacles)
            draws.pos += int(o[so.O_USED])
        t_exp = t_s - t_zero - 0.5
        age_s = t_s - o[so.O_RX]
        live.observe(pose, t_pose_s=t_exp - age_s, age_ms=age_s * 1e3)
        times = np.add(t_exp + lead, work[W_HEAD:])
        times[0] = t_exp
        expected = live.state_at(times)
        followed(o, t_s, t_exp, lead, work, rows)
        assert rows[:n, 0].tobytes() == times.tobytes(), k
        assert rows[:n, 1:].tobytes() == expected.tobytes(), k
        assert (o[so.O_FRESH] != 0.0) is live._fresh
        fresh.add(live._fresh)
        assert o[so.O_VX:so.O_VZ + 1].tobytes() == live._object.velocity_mps.tobytes()
    assert np.isnan(rows[n:]).all() and fresh == {True, False}
