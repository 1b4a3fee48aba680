"""The airframe's compiled right-hand side and RK4 steps: the simulator's hot path.

:mod:`ardrone_nmpc.sim.plant` defines the model (its module docstring) and calls these:
:func:`airframe_rk4` is one fixed RK4 step of the motors-on plant, :func:`airframe_rk4_many`
many in one call (a whole control tick's substeps without Python in between).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.types import GRAVITY_MPS2

__all__ = ["airframe_rk4", "airframe_rk4_many"]


@njit(cache=True)
def _airframe_rhs(x, roll, pitch, gaz, yaw, hold, k, w, out):
    """The motors-on right-hand side on arrays (the one definition: :func:`airframe_derivative`
    and :func:`airframe_rk4` both call it)."""
    e, vz_gain, inv_tau_vz, yaw_gain, inv_tau_yaw, inv_tau_tilt, kd, hold_damping = k
    vx, vy, vz, phi, theta, psi, r = x[3], x[4], x[5], x[6], x[7], x[8], x[9]
    forward = GRAVITY_MPS2 * math.tan(theta)
    right = GRAVITY_MPS2 * math.tan(phi)
    c = math.cos(psi)
    s = math.sin(psi)
    ax = c * forward + s * right - kd * (vx - w[0])
    ay = s * forward - c * right - kd * (vy - w[1])
    if hold:
        ax -= hold_damping * vx
        ay -= hold_damping * vy
        phi_dot = -phi * inv_tau_tilt
        theta_dot = -theta * inv_tau_tilt
    else:
        phi_dot = (roll * e - phi) * inv_tau_tilt
        theta_dot = (-pitch * e - theta) * inv_tau_tilt
    out[0], out[1], out[2], out[3], out[4] = vx, vy, vz, ax, ay
    out[5] = gaz * vz_gain - vz * inv_tau_vz + kd * w[2]
    out[6], out[7], out[8], out[9] = phi_dot, theta_dot, r, -yaw * yaw_gain - r * inv_tau_yaw


@njit(cache=True)
def airframe_rk4(state, roll, pitch, gaz, yaw, hold, k, w, h):
    """:func:`rk4_step` of :func:`airframe_derivative`, compiled: the simulator's hot path
    (13 substeps per control tick). ``k`` is ``PlantParams.rhs_coefficients``; returns the
    new 10-tuple state."""
    x = np.empty(10)
    for i in range(10):
        x[i] = state[i]
    a = np.empty(10)
    b = np.empty(10)
    c = np.empty(10)
    d = np.empty(10)
    t = np.empty(10)
    hh = 0.5 * h
    _airframe_rhs(x, roll, pitch, gaz, yaw, hold, k, w, a)
    for i in range(10):
        t[i] = x[i] + hh * a[i]
    _airframe_rhs(t, roll, pitch, gaz, yaw, hold, k, w, b)
    for i in range(10):
        t[i] = x[i] + hh * b[i]
    _airframe_rhs(t, roll, pitch, gaz, yaw, hold, k, w, c)
    for i in range(10):
        t[i] = x[i] + h * c[i]
    _airframe_rhs(t, roll, pitch, gaz, yaw, hold, k, w, d)
    h6 = h / 6.0
    for i in range(10):
        x[i] = x[i] + h6 * (a[i] + 2.0 * (b[i] + c[i]) + d[i])
    return (x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9])


@njit(cache=True)
def airframe_rk4_many(state, commands, k, w, h):
    """:func:`airframe_rk4` once per row of ``commands`` (n, 5: roll, pitch, gaz, yaw, hold
    as 0/1), each step from the last; stops after a step that ends at z ≤ 0 (ground
    contact is the caller's). Returns (steps done, state)."""
    x = state
    for i in range(commands.shape[0]):
        c = commands[i]
        x = airframe_rk4(x, c[0], c[1], c[2], c[3], c[4] != 0.0, k, w, h)
        if x[2] <= 0.0:
            return i + 1, x
    return commands.shape[0], x
