"""The reference of an experiment as the runners hand it to the tick: settle, then track.

Every runner (lockstep, real time, ``replay --rerun``) holds the configured trajectory's
start point through the settle phase (experiment time t < 0) and flies the trajectory from
t = 0; a followed object (reference kind ``follow``) is live from the first tick. A reference
that leaves the geofence anywhere over the experiment is refused before anything flies
(:func:`check_inside_geofence`; ``check`` runs it too): the supervisor would land the drone
there, after flying it towards the fence.
"""

from __future__ import annotations

import numpy as np

from ardrone_nmpc.core.types import IX_X, IX_Y, IX_Z
from ardrone_nmpc.reference.excitation import Excitation
from ardrone_nmpc.reference.live import TABLE_ARGS
from ardrone_nmpc.reference.trajectories import (Ellipse, Hover, Lorenz, ReferenceError, Step,
                                                  Trajectory, Waypoints, is_times,
                                                  make_trajectory)

#: ``ndarray.min`` of a 1-D array is this reduction (numpy/_core/_methods.py: ``_amin``).
_min = np.minimum.reduce

#: Sampling step of :func:`check_inside_geofence` (s).
FENCE_CHECK_STEP_S = 0.01

#: The references found inside their geofence, by what decides it (:func:`_fence_key`): a
#: sweep or a benchmark flies one reference many times, and the check samples it at
#: ~100 Hz over the whole experiment (~0.2 ms a flight). Only passes are kept; bounded.
_INSIDE: set = set()
_INSIDE_MAX = 256
#: … and the waypoint references made, by the same key: a pure function of it, read and
#: never written by a flight (their arrays are the compiled tick's), so each flight of a
#: sweep takes the one made first (~0.2 ms a flight); bounded as :data:`_INSIDE`.
_MADE: dict = {}


def lookup_args(trajectory: Trajectory) -> tuple | None:
    """The arrays of the compiled waypoint lookup (``reference/kernels.waypoint_states``) whose
    states are ``trajectory.state_at``'s bit for bit: a waypoint path's (``Waypoints``: the
    square, a path file) or a set point's (``Hover``, ``Step``) — None for any other kind, a
    subclass that overrides ``state_at`` (its own is called) or a set point the lookup cannot
    give exactly (``trajectories._set_point_args``)."""
    for cls in (Waypoints, Hover, Step):
        if isinstance(trajectory, cls):
            return trajectory._kernel_args if type(trajectory).state_at is cls.state_at else None
    return None




def tabulated(trajectory: Trajectory) -> bool:
    """Whether the compiled tick may read ``trajectory``'s states from a table its own
    ``state_at`` fills, one call for many ticks' horizon times: a curve whose state at a time
    is the same bits whatever other times it is asked with — every expression of its
    ``state_at`` elementwise: :class:`Ellipse` (the C library's cos and sin, numpy's loop
    calls them per element), :class:`Lorenz` (the dense output's polynomial, per element of
    its segment), :class:`Excitation` (masks, sums and products). Its own class only: a
    subclass' ``state_at`` may not be."""
    return type(trajectory) in (Ellipse, Lorenz, Excitation)


class HoldStartThen:
    """``trajectory`` for t ≥ 0, its t = 0 point at rest for t < 0 (the settle phase)."""

    def __init__(self, trajectory: Trajectory):
        self.inner = trajectory
        start = trajectory.state_at(0.0)[0].copy()
        start[[1, 3, 5]] = 0.0  # at rest: ẋ, ẏ, ż = 0
        self._start = start
        self.duration_s = trajectory.duration_s
        # the arrays of the tick's one-call horizon lookup (runtime/tick_kernels.nmpc_inputs)
        # of a waypoint trajectory or a set point (hover, step), or none for a curve whose
        # states it reads from a table this object fills (``tabulated``); None else
        args = lookup_args(trajectory)
        #: the states are a table's, filled by :meth:`state_at` (``tabulated``)
        self.tabulated = args is None and tabulated(trajectory)
        if self.tabulated:
            args = TABLE_ARGS
        self.waypoint_args = None if args is None else args + (start,)

    def state_at(self, t_s):
        if is_times(t_s):  # the horizon's times: no conversions; the same reduction as .min()
            if t_s.size and _min(t_s) > 0.0:
                return self.inner.state_at(t_s)
            t = t_s
        else:
            t = np.atleast_1d(np.asarray(t_s, dtype=float))
        if t.size and t.min() > 0.0:  # all inside the experiment (NaN is not): nothing held
            return self.inner.state_at(t)
        out = self.inner.state_at(np.maximum(t, 0.0))
        out[t < 0.0] = self._start
        return out

    def polyline_m(self):
        return self.inner.polyline_m()


def check_inside_geofence(cfg, trajectory: Trajectory) -> None:
    """Raise :class:`ReferenceError` if ``trajectory`` leaves ``cfg.safety``'s geofence at any
    time of the experiment (sampled every :data:`FENCE_CHECK_STEP_S` over [0, duration_s])."""
    n = int(np.ceil(cfg.duration_s / FENCE_CHECK_STEP_S)) + 1
    t = np.minimum(np.arange(n) * FENCE_CHECK_STEP_S, cfg.duration_s)
    pos = trajectory.state_at(t)[:, [IX_X, IX_Y, IX_Z]]
    lo = np.asarray(cfg.safety.geofence_min_m, dtype=float)
    hi = np.asarray(cfg.safety.geofence_max_m, dtype=float)
    outside = np.any(~((pos >= lo) & (pos <= hi)), axis=1)  # NaN is outside too
    if outside.any():
        i = int(np.argmax(outside))
        x, y, z = (float(v) for v in pos[i])
        box = " × ".join(f"[{a:g}, {b:g}]" for a, b in zip(lo, hi))
        raise ReferenceError(
            f"reference: the {cfg.reference.kind} reference leaves the geofence at t = "
            f"{t[i]:.2f} s, at ({x:.2f}, {y:.2f}, {z:.2f}) m outside {box} m "
            "(safety.geofence_min_m / geofence_max_m) — bring the reference inside the fence")


def _fence_key(cfg) -> tuple | None:
    """What decides :func:`check_inside_geofence` of ``cfg``'s experiment trajectory: its
    reference section (every field, as JSON), the experiment's duration and the fence —
    None for a reference read from a file (the file may change between flights)."""
    ref = cfg.reference
    if ref.path_file is not None:
        return None
    return (ref.model_dump_json(), cfg.duration_s, tuple(cfg.safety.geofence_min_m),
            tuple(cfg.safety.geofence_max_m))


def experiment_trajectory(cfg):
    """The reference a runner hands the tick: the configured trajectory held at its start
    through the settle phase, or — kind ``follow`` — the live object (it follows from the
    first tick; it cannot be checked against the geofence before it flies). Raises
    :class:`ReferenceError` for a reference that leaves the geofence (checked once per
    reference, duration and fence a process flies: :data:`_INSIDE`; a waypoint reference is
    made once too, :data:`_MADE`)."""
    if cfg.reference.kind == "follow":
        return make_trajectory(cfg.reference)
    key = _fence_key(cfg)
    made = _MADE.get(key) if key is not None else None
    if made is not None:
        return made
    trajectory = make_trajectory(cfg.reference, duration_s=cfg.duration_s)
    if key is None or key not in _INSIDE:
        check_inside_geofence(cfg, trajectory)
        if key is not None:
            if len(_INSIDE) >= _INSIDE_MAX:
                _INSIDE.clear()
            _INSIDE.add(key)
    held = HoldStartThen(trajectory)
    if key is not None and held.waypoint_args is not None and not held.tabulated:
        if len(_MADE) >= _INSIDE_MAX:
            _MADE.clear()
        _MADE[key] = held
    return held
