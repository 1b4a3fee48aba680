"""Control-oriented quadrotor model of thesis eq. 3.13, its derivatives and discretisation.

All functions are pure and numba-compatible (they are compiled by the solver kernels
with ``numba.njit``); here they stay plain Python so importing this module is cheap.

State ``x`` (7,) = [x, ẋ, y, ẏ, z, ż, ψ] in m, m/s, rad; input ``u`` (4,) = [z̈, φ, θ, ψ̇]
in m/s², rad, rad, rad/s.  World frame: x forward, y left, z up; ψ counter-clockwise.
"""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.core.types import GRAVITY_MPS2


def dynamics(x, u, out):
    """Write ``f(x, u)`` of eq. 3.13 into ``out`` (7,).

    ``ẍ = (sin ψ tan φ / cos θ + cos ψ tan θ)(z̈ + g)`` and
    ``ÿ = (−cos ψ tan φ / cos θ + sin ψ tan θ)(z̈ + g)``.
    """
    spsi = math.sin(x[6])
    cpsi = math.cos(x[6])
    tphi = math.tan(u[1])
    tth = math.tan(u[2])
    cth = math.cos(u[2])
    thrust = u[0] + GRAVITY_MPS2
    out[0] = x[1]
    out[1] = (spsi * tphi / cth + cpsi * tth) * thrust
    out[2] = x[3]
    out[3] = (-cpsi * tphi / cth + spsi * tth) * thrust
    out[4] = x[5]
    out[5] = u[0]
    out[6] = u[3]


def f(x, u):
    """Return ``f(x, u)`` (7,) of eq. 3.13 as a new array (convenience for non-kernel code)."""
    out = np.empty(7)
    dynamics(np.asarray(x, dtype=float), np.asarray(u, dtype=float), out)
    return out


def jacobian_x(x, u):
    """∂f/∂x (7, 7) of eq. 3.13; only the kinematic rows and the ψ column are non-zero."""
    spsi, cpsi = math.sin(x[6]), math.cos(x[6])
    tphi, tth, cth = math.tan(u[1]), math.tan(u[2]), math.cos(u[2])
    thrust = u[0] + GRAVITY_MPS2
    jac = np.zeros((7, 7))
    jac[0, 1] = 1.0
    jac[2, 3] = 1.0
    jac[4, 5] = 1.0
    jac[1, 6] = (cpsi * tphi / cth - spsi * tth) * thrust
    jac[3, 6] = (spsi * tphi / cth + cpsi * tth) * thrust
    return jac


def jacobian_u(x, u):
    """∂f/∂u (7, 4) of eq. 3.13."""
    spsi, cpsi = math.sin(x[6]), math.cos(x[6])
    tphi, tth, cth = math.tan(u[1]), math.tan(u[2]), math.cos(u[2])
    sec2_phi = 1.0 + tphi * tphi
    sec2_th = 1.0 + tth * tth
    thrust = u[0] + GRAVITY_MPS2
    jac = np.zeros((7, 4))
    # row ẍ
    jac[1, 0] = spsi * tphi / cth + cpsi * tth
    jac[1, 1] = spsi * sec2_phi / cth * thrust
    jac[1, 2] = (spsi * tphi * tth / cth + cpsi * sec2_th) * thrust
    # row ÿ
    jac[3, 0] = -cpsi * tphi / cth + spsi * tth
    jac[3, 1] = -cpsi * sec2_phi / cth * thrust
    jac[3, 2] = (-cpsi * tphi * tth / cth + spsi * sec2_th) * thrust
    jac[5, 0] = 1.0
    jac[6, 3] = 1.0
    return jac


def euler_step(x, u, dt_s):
    """Forward-Euler step of eq. 3.16: ``x + f(x, u) Δτ``."""
    return np.asarray(x, dtype=float) + f(x, u) * dt_s


def rk4_step(x, u, dt_s):
    """One classical Runge–Kutta step with ``u`` held (used as a reference integrator)."""
    x = np.asarray(x, dtype=float)
    k1 = f(x, u)
    k2 = f(x + 0.5 * dt_s * k1, u)
    k3 = f(x + 0.5 * dt_s * k2, u)
    k4 = f(x + dt_s * k3, u)
    return x + dt_s / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
