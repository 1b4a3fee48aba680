"""A scripted second object for the simulated mocap stream: a scale car driving a loop.

Pure functions of time (s since the simulation started), so the lockstep runner and the
loopback mocap server stream the same object.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL
from ardrone_nmpc.core.types import MocapPose

__all__ = ["target_numbers", "target_pose", "target_state"]


def target_state(cfg, t_s: float) -> tuple[np.ndarray, float, np.ndarray]:
    """``(position_m (3,), psi_rad, velocity_mps (3,))`` of the scripted object at ``t_s``.

    ``circle``: counter-clockwise around ``center_m`` at ``radius_m``, starting at +x;
    ``figure8``: the lemniscate of Gerono x = r·sin(2φ)/2 … traced at roughly ``speed_mps``
    (its phase advances at speed/radius). Heading is the direction of travel.
    """
    r, v = cfg.radius_m, cfg.speed_mps
    cx, cy, cz = cfg.center_m
    w = v / r  # phase rate (rad/s)
    a = w * t_s
    if cfg.path == "circle":
        pos = np.array([cx + r * math.cos(a), cy + r * math.sin(a), cz])
        vel = np.array([-r * w * math.sin(a), r * w * math.cos(a), 0.0])
    else:  # figure 8: x = r sin a, y = (r/2) sin 2a
        pos = np.array([cx + r * math.sin(a), cy + 0.5 * r * math.sin(2 * a), cz])
        vel = np.array([r * w * math.cos(a), r * w * math.cos(2 * a), 0.0])
    psi = math.atan2(vel[1], vel[0]) if v > 0 else 0.0
    return pos, psi, vel


def target_pose(cfg, t_s: float, rng: np.random.Generator | None = None,
                position_std_m: float = 0.0) -> MocapPose:
    """The object's mocap pose at ``t_s`` (optionally with N(0, σ) position noise)."""
    pos, psi, _ = target_state(cfg, t_s)
    if rng is not None and position_std_m > 0:
        pos = pos + position_std_m * rng.standard_normal(3)
    pos.setflags(write=False)
    rot = np.array([0.0, 0.0, psi])
    rot.setflags(write=False)
    return MocapPose(t_s=t_s, position_m=pos, rotation_xyz_rad=rot, psi_rad=psi)


@njit(cache=True, **INNER_KERNEL)
def target_numbers(circle, r, v, cx, cy, cz, t_s):
    """:func:`target_state`'s position and heading as numbers, for compiled code (a block of
    lockstep ticks: ``runtime/second_object``): ``circle`` True for ``path: circle``, else
    the figure 8 — the same expressions in the same order (cos, sin and atan2: the C
    library's, as Python's math), so the same bits."""
    w = v / r
    a = w * t_s
    if circle:
        px, py = cx + r * math.cos(a), cy + r * math.sin(a)
        vx, vy = -r * w * math.sin(a), r * w * math.cos(a)
    else:
        px, py = cx + r * math.sin(a), cy + 0.5 * r * math.sin(2 * a)
        vx, vy = r * w * math.cos(a), r * w * math.cos(2 * a)
    psi = math.atan2(vy, vx) if v > 0 else 0.0
    return px, py, cz, psi


flush_stale_caches(__name__)
