"""The reference of an experiment as the runners hand it to the tick: settle, then track.

Every runner (lockstep, real time, ``replay --rerun``) holds the configured trajectory's
start point through the settle phase (experiment time t < 0) and flies the trajectory from
t = 0; a followed object (reference kind ``follow``) is live from the first tick.
"""

from __future__ import annotations

import numpy as np

from ardrone_nmpc.reference.trajectories import Trajectory, make_trajectory


class HoldStartThen:
    """``trajectory`` for t ≥ 0, its t = 0 point at rest for t < 0 (the settle phase)."""

    def __init__(self, trajectory: Trajectory):
        self.inner = trajectory
        start = trajectory.state_at(0.0)[0].copy()
        start[[1, 3, 5]] = 0.0  # at rest: ẋ, ẏ, ż = 0
        self._start = start
        self.duration_s = trajectory.duration_s

    def state_at(self, t_s):
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        out = self.inner.state_at(np.maximum(t, 0.0))
        out[t < 0.0] = self._start
        return out

    def polyline_m(self):
        return self.inner.polyline_m()


def experiment_trajectory(cfg):
    """The reference a runner hands the tick: the configured trajectory held at its start
    through the settle phase, or — kind ``follow`` — the live object (it follows from the
    first tick)."""
    if cfg.reference.kind == "follow":
        return make_trajectory(cfg.reference)
    return HoldStartThen(make_trajectory(cfg.reference, duration_s=cfg.duration_s))
