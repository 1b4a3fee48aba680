"""Reference kind ``follow``: the desired state taken live from a second mocap object.

Each tick the runner hands :meth:`LiveTarget.observe` the object's newest pose with its age;
:meth:`LiveTarget.state_at` then answers the controller's horizon like any
:class:`~ardrone_nmpc.reference.trajectories.Trajectory`: the object's position plus the configured offset,
extrapolated at its estimated velocity (``follow.predict``), so the NMPC plans to where the
object will be, not where it was. The velocity comes from differences of successive poses
through a first-order filter (time constant ``follow.velocity_filter_s``). Before the object is
seen the reference holds ``reference.start_m``; once its pose is older than
``follow.max_age_ms`` the reference stops extrapolating and holds the last position.
"""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z, STATE_DIM

__all__ = ["MAX_EXTRAPOLATION_S", "TABLE_ARGS", "LiveTarget", "TrackedObject"]

MAX_EXTRAPOLATION_S = 3.0  # never plan further ahead on a guessed velocity than this
#: The lookup's arrays of a reference the compiled tick reads from a table of its states
#: (``runtime/tick_kernels.fill_reference_table``): no knots.
TABLE_ARGS = (np.zeros(0), np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros((0, 3)))


class TrackedObject:
    """The newest pose of a tracked mocap object and its estimated velocity.

    The velocity is the backward difference of successive poses through a first-order
    filter, ``v ← (1 − a)·v + a·Δp/Δt`` with ``a = Δt/(Δt + τ)``. Used by the ``follow``
    reference and by moving obstacles.

    Parameters
    ----------
    time_constant_s : τ (s).
    """

    def __init__(self, time_constant_s: float) -> None:
        self.time_constant_s = float(time_constant_s)
        self.position_m: np.ndarray | None = None  # newest position (m), None before the first
        self.psi_rad = 0.0
        self.velocity_mps = np.zeros(3)
        self.t_s = -math.inf  # time of the newest pose on the caller's clock (s)
        self._stamp = None    # the pose's own stamp: a new pose or the same one again

    def update(self, pose, t_s: float) -> bool:
        """Take ``pose`` (a MocapPose) seen at ``t_s`` (s); False if it is the one already
        taken."""
        if pose.t_s == self._stamp:
            return False
        p = np.asarray(pose.position_m, dtype=np.float64)
        if self.position_m is not None and t_s > self.t_s:
            dt = t_s - self.t_s
            a = dt / (dt + self.time_constant_s)
            self.velocity_mps = (1.0 - a) * self.velocity_mps + a * (p - self.position_m) / dt
        self.position_m, self.psi_rad, self.t_s = p, float(pose.psi_rad), t_s
        self._stamp = pose.t_s
        return True


class LiveTarget:
    """A :class:`~ardrone_nmpc.reference.trajectories.Trajectory` that follows a tracked object.

    Parameters
    ----------
    ref_cfg : :class:`~ardrone_nmpc.config.schema.ReferenceConfig` with ``kind: follow``.
    """

    duration_s = math.inf
    #: the compiled tick reads its states from a table :meth:`state_at` fills, a tick at a
    #: time (``reference/experiment.tabulated``: every expression of it elementwise, the
    #: same bits whatever other times it is asked with)
    tabulated = True

    def __init__(self, ref_cfg) -> None:
        f = ref_cfg.follow
        self.cfg = f
        self.start_m = np.asarray(ref_cfg.start_m, dtype=np.float64)
        self.fixed_psi_rad = float(ref_cfg.start_psi_rad)
        self._offset = np.asarray(f.offset_m, dtype=np.float64)
        self._object = TrackedObject(f.velocity_filter_s)  # on the experiment clock
        self._fresh = False
        #: the compiled tick's lookup arrays (``HoldStartThen.waypoint_args``'): a table's
        self.waypoint_args = TABLE_ARGS + (self.state_at(0.0)[0],)

    # ------------------------------------------------------------------ measurements
    def observe(self, pose, *, t_pose_s: float, age_ms: float) -> None:
        """The object's newest ``pose`` (MocapPose or None), seen at experiment time
        ``t_pose_s`` (s), ``age_ms`` old now."""
        self._fresh = pose is not None and age_ms <= self.cfg.max_age_ms
        if pose is not None:
            self._object.update(pose, t_pose_s)

    @property
    def seen(self) -> bool:
        return self._object.position_m is not None

    # ------------------------------------------------------------------ the reference
    def _offset_world(self) -> np.ndarray:
        if self.cfg.offset_frame == "world":
            return self._offset
        c, s = math.cos(self._object.psi_rad), math.sin(self._object.psi_rad)
        ox, oy, oz = self._offset
        return np.array([c * ox - s * oy, s * ox + c * oy, oz])

    def state_at(self, t_s) -> np.ndarray:
        """Desired states ``(len(t), 7)`` at experiment times ``t_s`` (s)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).ravel()
        out = np.zeros((t.size, STATE_DIM))
        obj = self._object
        psi = obj.psi_rad if self.cfg.heading == "object" else self.fixed_psi_rad
        out[:, IX_PSI] = psi
        if obj.position_m is None:
            out[:, [IX_X, IX_Y, IX_Z]] = self.start_m
            return out
        moving = self.cfg.predict and self._fresh
        vel = obj.velocity_mps if moving else np.zeros(3)
        ahead = np.clip(t - obj.t_s, 0.0, MAX_EXTRAPOLATION_S)
        base = obj.position_m + self._offset_world()
        out[:, [IX_X, IX_Y, IX_Z]] = base + ahead[:, None] * vel
        out[:, [IX_VX, IX_VY, IX_VZ]] = vel
        return out

    def polyline_m(self) -> np.ndarray:
        """Where the reference is now, (1, 3) (the path is not known in advance)."""
        return self.state_at(self._object.t_s if self.seen else 0.0)[:, [IX_X, IX_Y, IX_Z]]
