"""Static obstacles in the NMPC: an exterior penalty for ‖p − c‖² ≥ d² (numba-compatible).

Formulation (docs/solver-notes.md §7). Each obstacle ``k`` adds to every stage cost
``L_i`` (``i = 0 … N``, the terminal state included, each weighted by Δτ like a stage)::

    P_k(p) = ½ w_k · max(0, d_k² − ‖p − c_k‖²)²

with ``p`` the predicted position, ``c_k`` the centre, ``d_k = radius + margin`` the
constraint distance and ``e = d_k² − ‖p − c_k‖²`` the intrusion (m²). A cylinder (vertical,
unbounded in height) measures the horizontal distance only. The penalty is C¹: zero and flat
outside ``d_k``, growing without bound inside. Its gradient ``−2 w_k max(0, e) (p − c_k)``
keeps the optimality residual the gradient of a cost; it enters the costates as ``∂L/∂x``
(λ̇ = −H_x). (A Huber variant, linear beyond a knee, bounded the residuals of plans through
an obstacle but also the push out of it: a strong pull of the reference then overpowered it.
Measured in docs/solver-notes.md §7.)

Why a penalty and not a dummy-input constraint: the input bounds' condensed dummy inputs are
a barrier, which needs a strictly feasible iterate; a state constraint is met or not by the
rollout of *all* earlier inputs, and the delay-compensated state can start inside the margin
(noise, disturbances), where a barrier is undefined. The exterior penalty is defined
everywhere and inactive (exactly zero, bit for bit) away from the obstacle.

Tie-break. A head-on approach is symmetric: the path through the centre is a stationary point
of the cost, and any smooth penalty keeps one nearby. Each tick (:func:`aim_obstacles`) the
penalty's centre moves ``s`` to the left of the line of sight from the drone to the obstacle
and ``d`` grows by ``s``, so the penalised region still covers the true one (on the right it
touches it): the stationary path moves ``s`` to the left, and a drone within ``s`` of the
line of sight passes the obstacle on its right. One already further out keeps its side.

The table travels to the kernels as a runtime array (one row per obstacle, columns
``OBS_*``), so a moving obstacle can rewrite its centre every tick; the kernels write the
effective columns ``OBS_E*`` from it. Like :mod:`ardrone_nmpc.model`, the functions here are
plain Python (cheap to import: the summary uses :func:`clearance_m`) and numba-compatible;
:mod:`~ardrone_nmpc.control.kernels` compiles them. They call no other function of theirs, so
that each compiles on its own.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "KINDS", "KIND_CYLINDER", "KIND_SPHERE", "OBS_COLS", "OBS_DIST", "OBS_EDIST", "OBS_EX",
    "OBS_EY", "OBS_EZ", "OBS_KIND", "OBS_SHIFT", "OBS_WEIGHT", "OBS_X", "OBS_Y", "OBS_Z",
    "aim_obstacles", "clearance_m", "obstacle_table", "penalty", "penalty_gradient",
]

# Columns of the obstacle table. The obstacle (from the config; a moving obstacle rewrites
# X, Y, Z): kind, centre (m), constraint distance d (m), weight, tie-break shift s (m) …
OBS_KIND, OBS_X, OBS_Y, OBS_Z, OBS_DIST, OBS_WEIGHT, OBS_SHIFT = range(7)
# … and what the penalty uses, written by aim_obstacles each tick: centre (m), d (m).
OBS_EX, OBS_EY, OBS_EZ, OBS_EDIST = range(7, 11)
OBS_COLS = 11
KIND_SPHERE = 0.0
KIND_CYLINDER = 1.0
KINDS = {"sphere": KIND_SPHERE, "cylinder": KIND_CYLINDER}


def obstacle_table(obstacles, weight: float, tie_break_m: float = 0.0) -> np.ndarray:
    """The kernels' (n, ``OBS_COLS``) table from config obstacles (``ObstacleConfig``).

    Parameters
    ----------
    obstacles : sequence with ``kind``, ``center_m`` (3,), ``radius_m``, ``margin_m``.
    weight : penalty weight ``w`` (1/m⁴ per unit of stage cost), the same for all.
    tie_break_m : the tie-break shift ``s`` (m).

    The effective columns start unshifted (:func:`aim_obstacles` sets them each tick).
    """
    table = np.zeros((len(obstacles), OBS_COLS))
    for k, obs in enumerate(obstacles):
        table[k, OBS_KIND] = KINDS[obs.kind]
        table[k, OBS_X:OBS_Z + 1] = obs.center_m
        table[k, OBS_DIST] = obs.radius_m + obs.margin_m
        table[k, OBS_WEIGHT] = weight
        table[k, OBS_SHIFT] = tie_break_m
    aim_obstacles(table, np.array([np.nan] * 7))  # no line of sight: unshifted
    return table


def aim_obstacles(obs, x):
    """Write the effective columns of every obstacle for a drone at state ``x`` (7,).

    The centre moves by the obstacle's shift ``s`` along the horizontal line of sight from
    ``(x, y)`` to it, turned 90° counter-clockwise (to its left), and ``d`` grows by ``s``;
    without a line of sight (right above or below the centre, or a non-finite ``x``) nothing
    moves.
    """
    for k in range(obs.shape[0]):
        sx = obs[k, OBS_X] - x[0]
        sy = obs[k, OBS_Y] - x[2]
        norm = (sx * sx + sy * sy) ** 0.5
        shift = obs[k, OBS_SHIFT] if norm > 1e-9 else 0.0  # NaN > 1e-9 is False too
        left_x = -sy / norm if shift > 0.0 else 0.0
        left_y = sx / norm if shift > 0.0 else 0.0
        obs[k, OBS_EX] = obs[k, OBS_X] + shift * left_x
        obs[k, OBS_EY] = obs[k, OBS_Y] + shift * left_y
        obs[k, OBS_EZ] = obs[k, OBS_Z]
        obs[k, OBS_EDIST] = obs[k, OBS_DIST] + shift


def penalty(obs, px, py, pz):
    """``Σ_k ½ w_k max(0, d_k² − ‖p − c_k‖²)²`` at the position ``(px, py, pz)`` (m), with the
    effective centres and distances."""
    total = 0.0
    for k in range(obs.shape[0]):
        dx = px - obs[k, OBS_EX]
        dy = py - obs[k, OBS_EY]
        dz = pz - obs[k, OBS_EZ] if obs[k, OBS_KIND] == KIND_SPHERE else 0.0
        d = obs[k, OBS_EDIST]
        intrusion = d * d - (dx * dx + dy * dy + dz * dz)
        if intrusion > 0.0:
            total += 0.5 * obs[k, OBS_WEIGHT] * intrusion * intrusion
    return total


def penalty_gradient(obs, px, py, pz, fx, fy, fz):
    """``∂/∂p`` of :func:`penalty` at ``p``, ``(g_x, g_y, g_z)``, with the direction of each
    term taken at ``f``: ``Σ_k −2 w_k e_k(p) (f − c_k)`` over the obstacles whose intrusion
    ``e_k(p) = d_k² − ‖p − c_k‖²`` is positive.

    ``f = p`` is the exact gradient. A fixed ``f`` (the base point of a Jacobian–vector
    product) makes the product's derivative the Gauss–Newton curvature
    ``4 w_k (f − c_k)(f − c_k)ᵀ``: it drops ``−2 w_k e_k I``, the negative curvature that makes
    the path through an obstacle's centre a stationary point that Newton steps are drawn to.
    Exactly zero outside every ``d_k``.
    """
    gx = 0.0
    gy = 0.0
    gz = 0.0
    for k in range(obs.shape[0]):
        cylinder = obs[k, OBS_KIND] != KIND_SPHERE
        dx = px - obs[k, OBS_EX]
        dy = py - obs[k, OBS_EY]
        dz = 0.0 if cylinder else pz - obs[k, OBS_EZ]
        d = obs[k, OBS_EDIST]
        intrusion = d * d - (dx * dx + dy * dy + dz * dz)
        if intrusion > 0.0:
            c = -2.0 * obs[k, OBS_WEIGHT] * intrusion
            gx += c * (fx - obs[k, OBS_EX])
            gy += c * (fy - obs[k, OBS_EY])
            gz += 0.0 if cylinder else c * (fz - obs[k, OBS_EZ])
    return gx, gy, gz


def clearance_m(positions_m: np.ndarray, obstacle) -> np.ndarray:
    """Distance (m) from each position (K, 3) to the surface of a config obstacle
    (``ObstacleConfig``): ``‖p − c‖ − radius``, horizontal for a cylinder, negative inside."""
    p = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
    offset = p - np.asarray(obstacle.center_m, dtype=np.float64)
    if obstacle.kind == "cylinder":
        offset[:, 2] = 0.0
    return np.sqrt(np.einsum("ij,ij->i", offset, offset)) - obstacle.radius_m
