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

A followed object (reference kind ``follow``) is observed every tick (:func:`followed`:
``LiveTarget.observe``'s filter and freshness) and its reference written into the control
stage's table at the tick's horizon times (``LiveTarget.state_at``'s arithmetic, where the
per-tick path's ``fill_reference_table`` calls it): the compiled control tick reads it there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control.obstacles import OBS_COLS, OBS_X
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL
from ardrone_nmpc.core.types import (IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z, STATE_DIM,
                                     MocapPose)
from ardrone_nmpc.reference.live import MAX_EXTRAPOLATION_S, LiveTarget
from ardrone_nmpc.runtime.stages import MovingObstacles
from ardrone_nmpc.runtime.tick_kernels import W_HEAD, W_TIMES
from ardrone_nmpc.sim.normal_blocks import NormalBlocks
from ardrone_nmpc.sim.target import target_numbers

__all__ = ["O_FOLLOW", "O_ON", "SecondObject", "followed", "take_frame"]

# o: an object at all (1.0) or none (0.0); its path (1.0: circle), radius, speed, centre,
# the noise's σ; the normals consumed (from the block's first); its newest pose — the
# frame's time, receipt time, position, heading — and 1.0 once the kernel took one; then a
# moving obstacle's (1.0: one), the prediction time, the filter's τ, the tracked object
# (seen 1.0, time, the pose's stamp, position, heading, velocity); a followed one's (1.0:
# one; LiveTarget's settings — the pose's age limit, its prediction 1.0, the object's
# heading 1.0, the fixed heading, the offset and its frame (1.0: the object's), the start —
# and whether the pose is fresh 1.0); the obstacle table's rows that move (their count, then
# the rows: O_ROWS …)
(O_ON, O_CIRCLE, O_R, O_V, O_CX, O_CY, O_CZ, O_STD, O_USED, O_T, O_RX, O_X, O_Y, O_Z, O_PSI,
 O_TOOK, O_MOVING, O_AHEAD_S, O_TAU_S, O_SEEN, O_TRK_T, O_STAMP, O_TRK_X, O_TRK_Y, O_TRK_Z,
 O_TRK_PSI, O_VX, O_VY, O_VZ, O_FOLLOW, O_MAX_AGE_MS, O_PREDICT, O_HEADING, O_FIXED_PSI,
 O_OX, O_OY, O_OZ, O_OBJECT_FRAME, O_START_X, O_START_Y, O_START_Z, O_FRESH, O_N_ROWS,
 O_ROWS) = range(44)
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
        _tracked(o, t_event, t_event, px, py, pz, psi)
        ahead = o[O_AHEAD_S]
        cx = o[O_TRK_X] + o[O_VX] * ahead
        cy = o[O_TRK_Y] + o[O_VY] * ahead
        cz = o[O_TRK_Z] + o[O_VZ] * ahead
        for k in range(int(o[O_N_ROWS])):
            row = int(o[O_ROWS + k])
            obstacles[row, OBS_X], obstacles[row, OBS_X + 1] = cx, cy
            obstacles[row, OBS_X + 2] = cz


@njit(cache=True, **INNER_KERNEL)
def followed(o, t_s, t_exp_s, lead_s, work, rows):
    """``LiveTarget.observe`` of the object's newest pose at the tick of plant time ``t_s``
    (experiment time ``t_exp_s``), then the reference table's first tick
    (``tick_kernels.fill_reference_table``'s, its horizon times [t, (t + lead) + offsets[1:]])
    filled by ``LiveTarget.state_at``'s arithmetic, time by time."""
    age_s = t_s - o[O_RX]
    age_ms = age_s * 1e3
    o[O_FRESH] = 1.0 if age_ms <= o[O_MAX_AGE_MS] else 0.0
    _tracked(o, t_exp_s - age_s, o[O_T], o[O_X], o[O_Y], o[O_Z], o[O_PSI])
    n = int(work[W_TIMES])
    base = t_exp_s + lead_s
    for i in range(n):
        t = t_exp_s if i == 0 else base + work[W_HEAD + i]
        rows[i, 0] = t
        _state_at(o, t, rows[i, 1:])


@njit(cache=True, **INNER_KERNEL)
def _state_at(o, t, out):
    """``LiveTarget.state_at`` of one time ``t`` into ``out`` (7): its expressions
    element by element (``np.clip``'s bounds: −0.0 and NaN kept)."""
    for c in range(STATE_DIM):
        out[c] = 0.0
    out[IX_PSI] = o[O_TRK_PSI] if o[O_HEADING] != 0.0 else o[O_FIXED_PSI]
    if o[O_SEEN] == 0.0:
        out[IX_X], out[IX_Y], out[IX_Z] = o[O_START_X], o[O_START_Y], o[O_START_Z]
        return
    vx = vy = vz = 0.0
    if o[O_PREDICT] != 0.0 and o[O_FRESH] != 0.0:
        vx, vy, vz = o[O_VX], o[O_VY], o[O_VZ]
    ahead = t - o[O_TRK_T]
    if ahead < 0.0:
        ahead = 0.0
    elif ahead > MAX_EXTRAPOLATION_S:
        ahead = MAX_EXTRAPOLATION_S
    ox, oy, oz = o[O_OX], o[O_OY], o[O_OZ]
    if o[O_OBJECT_FRAME] != 0.0:  # (LiveTarget._offset_world)
        c, s = math.cos(o[O_TRK_PSI]), math.sin(o[O_TRK_PSI])
        ox, oy = c * ox - s * oy, s * ox + c * oy
    out[IX_X] = (o[O_TRK_X] + ox) + ahead * vx
    out[IX_Y] = (o[O_TRK_Y] + oy) + ahead * vy
    out[IX_Z] = (o[O_TRK_Z] + oz) + ahead * vz
    out[IX_VX], out[IX_VY], out[IX_VZ] = vx, vy, vz


@njit(cache=True, **INNER_KERNEL)
def _tracked(o, t_s, stamp, px, py, pz, psi):
    """``TrackedObject.update`` of the pose stamped ``stamp`` seen at ``t_s``:
    ``v ← (1 − a)·v + a·Δp/Δt`` element by element, in its order."""
    if stamp == o[O_STAMP]:
        return
    if o[O_SEEN] != 0.0 and t_s > o[O_TRK_T]:
        dt = t_s - o[O_TRK_T]
        a = dt / (dt + o[O_TAU_S])
        o[O_VX] = (1.0 - a) * o[O_VX] + a * (px - o[O_TRK_X]) / dt
        o[O_VY] = (1.0 - a) * o[O_VY] + a * (py - o[O_TRK_Y]) / dt
        o[O_VZ] = (1.0 - a) * o[O_VZ] + a * (pz - o[O_TRK_Z]) / dt
    o[O_TRK_X], o[O_TRK_Y], o[O_TRK_Z], o[O_TRK_PSI] = px, py, pz, psi
    o[O_TRK_T], o[O_STAMP], o[O_SEEN] = t_s, stamp, 1.0


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
        #: the solver's obstacle table (the moving rows' centres written there; none
        #: without an NMPC: an empty table of the same kind)
        nmpc = tick.control.nmpc
        self.obstacles = nmpc.obstacles if nmpc is not None else np.zeros((0, OBS_COLS))
        self._draws = None
        self.normals = np.zeros(0)
        if cfg is not None:
            self.o[O_ON] = 1.0
            self._draws = NormalBlocks(sensors._target_rng, _DRAWN)

    @staticmethod
    def takes(tick, sensors) -> bool:
        """Whether the kernel does this flight's object: none, or ``sim.target``'s (a path
        it knows) feeding nothing, moving obstacles (the stage's own class) or the
        ``follow`` reference of an NMPC (``LiveTarget``'s own class, read from the control
        stage's table: :func:`followed`) — not both."""
        cfg, follow, moving = sensors.target_cfg, tick.follow, tick.obstacles
        if cfg is None:
            return follow is None and moving is None
        return (cfg.path in ("circle", "figure8")
                and (moving is None or type(moving) is MovingObstacles)
                and (follow is None or (type(follow) is LiveTarget and moving is None
                                        and tick.control.nmpc is not None)))

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
        moving, follow = self.tick.obstacles, self.tick.follow
        if moving is not None:
            o[O_MOVING], o[O_AHEAD_S] = 1.0, moving.ahead_s
            _track_entered(o, moving.track)
        elif follow is not None:
            f = follow.cfg
            _track_entered(o, follow._object)
            o[O_FOLLOW:O_N_ROWS] = (
                1.0, f.max_age_ms, 1.0 if f.predict else 0.0,
                1.0 if f.heading == "object" else 0.0, follow.fixed_psi_rad,
                *follow._offset.tolist(), 1.0 if f.offset_frame != "world" else 0.0,
                *follow.start_m.tolist(), 1.0 if follow._fresh else 0.0)
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
        (``target_pose``'s: read-only arrays); the tracked object's filter — a followed
        one's, and its pose's freshness, whether a frame was taken or not (``observe``:
        every tick)."""
        draws, o = self._draws, self.o
        if draws is None:
            return
        draws.sync()
        follow = self.tick.follow
        if follow is not None:
            v = o.tolist()
            follow._fresh = v[O_FRESH] != 0.0
            if v[O_SEEN] != 0.0:
                _track_written(follow._object, v, np.array(v[O_TRK_X:O_TRK_PSI]))
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
            _track_written(moving.track, v, pos)


def _track_entered(o: np.ndarray, track) -> None:
    """``o``'s tracked object from ``track`` (a ``TrackedObject``)."""
    seen = track.position_m is not None
    stamp = track._stamp
    o[O_TAU_S:O_FOLLOW] = (
        track.time_constant_s, 1.0 if seen else 0.0, track.t_s,
        math.nan if stamp is None else stamp,
        *(track.position_m.tolist() if seen else (0.0, 0.0, 0.0)), track.psi_rad,
        *track.velocity_mps.tolist())


def _track_written(track, v: list, position_m: np.ndarray) -> None:
    """``track`` (a ``TrackedObject``) from ``o``'s numbers ``v`` (its position: the pose's
    array, as ``update`` keeps it)."""
    track.position_m, track.psi_rad = position_m, v[O_TRK_PSI]
    track.velocity_mps = np.array(v[O_VX:O_VZ + 1])
    track.t_s, track._stamp = v[O_TRK_T], v[O_STAMP]
