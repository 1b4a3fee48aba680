"""A second mocap object (``sim.target``: a scripted car or cart) in a block of lockstep ticks.

Per mocap frame the sampler takes, the per-tick path draws the object's pose
(``sim/target.target_pose``: its scripted motion, plus N(0, σ) noise from the sampler's own
``Generator``) and, for a moving obstacle, ``runtime/stages.MovingObstacles.update`` filters
its velocity and moves the obstacle's centre in the solver's table before the controller's
call. :func:`take_frame` does the same in a block's kernel (``runtime/lockstep_block``):
the scripted pose by ``sim/target.target_numbers`` (the same expressions), the noise from
normals drawn ahead from the same generator (``sim/normal_blocks.NormalBlocks``: the same
values in the same order; ``pos + σ·z`` element by element, as numpy adds the arrays), the
filter and the centres in ``TrackedObject.update``'s and ``MovingObstacles.update``'s order.
:class:`SecondObject` is the Python side: what a block starts from (``o``, indices
``O_*``), and what it leaves written back — the sampler's newest pose of the object, the
generator, the tracked object's filter.

The ``follow`` reference (``reference/live.LiveTarget``) is not here: its ticks are the
per-tick path's (no compiled control tick takes that reference).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control.obstacles import OBS_X
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL
from ardrone_nmpc.core.types import MocapPose
from ardrone_nmpc.runtime.stages import MovingObstacles
from ardrone_nmpc.sim.normal_blocks import NormalBlocks
from ardrone_nmpc.sim.target import target_numbers

__all__ = ["SecondObject", "take_frame"]

# o: an object at all (1.0) or none (0.0); its path (1.0: circle), radius, speed, centre,
# the noise's σ; the normals consumed (from the block's first); its newest pose — the
# frame's time, receipt time, position, heading — and 1.0 once the kernel took one; then a
# moving obstacle's (1.0: one), the prediction time, the filter's τ, the tracked object
# (seen 1.0, time, the pose's stamp, position, heading, velocity), and the table's rows
# that move (their count, then the rows: O_ROWS …)
(O_ON, O_CIRCLE, O_R, O_V, O_CX, O_CY, O_CZ, O_STD, O_USED, O_T, O_RX, O_X, O_Y, O_Z, O_PSI,
 O_TOOK, O_MOVING, O_AHEAD_S, O_TAU_S, O_SEEN, O_TRK_T, O_STAMP, O_TRK_X, O_TRK_Y, O_TRK_Z,
 O_TRK_PSI, O_VX, O_VY, O_VZ, O_N_ROWS, O_ROWS) = range(31)
#: normals drawn ahead at a time: several blocks' frames (three a frame, one frame a tick)
_DRAWN = 1024


@njit(cache=True, **INNER_KERNEL)
def take_frame(o, normals, t_event, rx_s, obstacles):
    """The object's pose of the mocap frame at ``t_event`` (received at ``rx_s``) into
    ``o`` (``target_pose``'s, its noise from ``normals[o[O_USED]:]``), and a moving
    obstacle's filter and centres after it (``MovingObstacles.update``)."""
    px, py, pz, psi = target_numbers(o[O_CIRCLE] != 0.0, o[O_R], o[O_V], o[O_CX], o[O_CY],
                                     o[O_CZ], t_event)
    std = o[O_STD]
    if std > 0:
        j = int(o[O_USED])
        px, py, pz = px + std * normals[j], py + std * normals[j + 1], pz + std * normals[j + 2]
        o[O_USED] = j + 3
    o[O_T], o[O_RX], o[O_X], o[O_Y], o[O_Z], o[O_PSI] = t_event, rx_s, px, py, pz, psi
    o[O_TOOK] = 1.0
    if o[O_MOVING] != 0.0:
        _tracked(o, t_event, px, py, pz, psi)
        ahead = o[O_AHEAD_S]
        cx = o[O_TRK_X] + o[O_VX] * ahead
        cy = o[O_TRK_Y] + o[O_VY] * ahead
        cz = o[O_TRK_Z] + o[O_VZ] * ahead
        for k in range(int(o[O_N_ROWS])):
            row = int(o[O_ROWS + k])
            obstacles[row, OBS_X], obstacles[row, OBS_X + 1] = cx, cy
            obstacles[row, OBS_X + 2] = cz


@njit(cache=True, **INNER_KERNEL)
def _tracked(o, t_s, px, py, pz, psi):
    """``TrackedObject.update`` of the pose stamped ``t_s`` seen at ``t_s``:
    ``v ← (1 − a)·v + a·Δp/Δt`` element by element, in its order."""
    if t_s == o[O_STAMP]:
        return
    if o[O_SEEN] != 0.0 and t_s > o[O_TRK_T]:
        dt = t_s - o[O_TRK_T]
        a = dt / (dt + o[O_TAU_S])
        o[O_VX] = (1.0 - a) * o[O_VX] + a * (px - o[O_TRK_X]) / dt
        o[O_VY] = (1.0 - a) * o[O_VY] + a * (py - o[O_TRK_Y]) / dt
        o[O_VZ] = (1.0 - a) * o[O_VZ] + a * (pz - o[O_TRK_Z]) / dt
    o[O_TRK_X], o[O_TRK_Y], o[O_TRK_Z], o[O_TRK_PSI] = px, py, pz, psi
    o[O_TRK_T], o[O_STAMP], o[O_SEEN] = t_s, t_s, 1.0


flush_stale_caches(__name__)


class SecondObject:
    """The Python side of :func:`take_frame` for one flight's sampler and tick (``sensors``:
    ``LockstepSensors``; ``tick``: the ``Tick``). :attr:`o`, :attr:`normals` and
    :attr:`obstacles` are the block kernel's arguments; a flight without a second object
    passes them too (``o[O_ON]`` 0: never read)."""

    def __init__(self, tick, sensors) -> None:
        self.sensors, self.tick = sensors, tick
        cfg = sensors.target_cfg
        moving = tick.obstacles
        rows = moving.indices if moving is not None else []
        self.o = np.zeros(O_ROWS + len(rows))
        self.o[O_N_ROWS] = len(rows)
        self.o[O_ROWS:] = rows
        #: the solver's obstacle table (the moving rows' centres written there)
        self.obstacles = tick.control.nmpc.obstacles
        self._draws = None
        self.normals = np.zeros(0)
        if cfg is not None:
            self.o[O_ON] = 1.0
            self._draws = NormalBlocks(sensors._target_rng, _DRAWN)

    @staticmethod
    def takes(tick, sensors) -> bool:
        """Whether the kernel does this flight's object: none, or ``sim.target``'s (a path
        it knows, numbers it reads as float64s) feeding nothing or moving obstacles (the
        stage's own class); the ``follow`` reference is the per-tick path's."""
        cfg = sensors.target_cfg
        return tick.follow is None and (tick.obstacles is None or (
            type(tick.obstacles) is MovingObstacles and cfg is not None)) and (
            cfg is None or cfg.path in ("circle", "figure8"))

    def entered(self) -> bool:
        """``o`` filled from the sampler's newest pose of the object and the moving
        obstacles' filter — or False (no block): an object not seen yet."""
        sensors, o = self.sensors, self.o
        if self._draws is None:
            return True
        pose = sensors.target
        if pose is None or pose.t_s.__class__ is not float:
            return False
        cfg = sensors.target_cfg
        x, y, z = pose.position_m.tolist()
        o[O_CIRCLE:O_TOOK + 1] = (1.0 if cfg.path == "circle" else 0.0, cfg.radius_m,
                                  cfg.speed_mps, *cfg.center_m, sensors._target_std_m, 0.0,
                                  pose.t_s, sensors.target_rx_t_s, x, y, z, pose.psi_rad, 0.0)
        moving = self.tick.obstacles
        if moving is not None:
            track = moving.track
            seen = track.position_m is not None
            stamp = track._stamp
            o[O_MOVING:O_N_ROWS] = (
                1.0, moving.ahead_s, track.time_constant_s, 1.0 if seen else 0.0, track.t_s,
                math.nan if stamp is None else stamp,
                *(track.position_m.tolist() if seen else (0.0, 0.0, 0.0)), track.psi_rad,
                *track.velocity_mps.tolist())
        return True

    def drawn(self, n_ticks: int) -> None:
        """Normals for ``n_ticks`` frames ahead (:attr:`normals` from the first not
        consumed: ``o[O_USED]`` counts from there)."""
        draws = self._draws
        if draws is None or not self.o[O_STD] > 0:
            return
        draws.ensure(3 * n_ticks)
        self.normals = draws.values[draws.pos:]
        self.o[O_USED] = 0.0

    def consumed(self) -> None:
        """The normals a call of the kernel consumed, counted as taken."""
        if self._draws is not None:
            self._draws.pos += int(self.o[O_USED])
            self.o[O_USED] = 0.0

    def written(self) -> None:
        """What the blocks left, written back as the per-tick path leaves it: the
        generator where the frames' draws left it; the sampler's newest pose of the object
        (``target_pose``'s: read-only arrays); the tracked object's filter."""
        draws, o = self._draws, self.o
        if draws is None:
            return
        draws.sync()
        if o[O_TOOK] == 0.0:
            return
        o[O_TOOK] = 0.0
        v = o.tolist()
        pos = np.array(v[O_X:O_PSI])
        pos.setflags(write=False)
        rot = np.array([0.0, 0.0, v[O_PSI]])
        rot.setflags(write=False)
        sensors = self.sensors
        sensors.target = MocapPose(t_s=v[O_T], position_m=pos, rotation_xyz_rad=rot,
                                   psi_rad=v[O_PSI])
        sensors.target_rx_t_s = v[O_RX]
        moving = self.tick.obstacles
        if moving is not None:
            track = moving.track
            track.position_m, track.psi_rad = pos, v[O_TRK_PSI]
            track.velocity_mps = np.array(v[O_VX:O_VZ + 1])
            track.t_s, track._stamp = v[O_TRK_T], v[O_STAMP]
