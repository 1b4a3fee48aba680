"""The airframe's compiled right-hand side and RK4 steps: the simulator's hot path.

:mod:`ardrone_nmpc.sim.plant` defines the model (its module docstring) and calls these:
:func:`airframe_rk4` is one fixed RK4 step of the motors-on plant, :func:`flying_steps`
many in one call with the command delay and the battery (a flying plant's substeps without
Python in between);
:func:`rk4_step` is the plain-Python RK4 of any right-hand side (the falling drone's, and the
reference the compiled steps are tested against).

The attitude loops are a first-order lag on a 10-element state; with the second-order form
(``sim.plant.attitude_model: second_order``) the state carries two more elements, the hidden
states η_φ, η_θ of each loop's observable canonical form (:func:`airframe_rk4_array`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.types import GRAVITY_MPS2

__all__ = ["N_AUX_STATE", "N_STATE", "airframe_rk4", "airframe_rk4_array",
           "flying_steps", "freefall_derivative", "rk4_step"]

N_STATE = 10      # x, y, z, vx, vy, vz, φ, θ, ψ, r
_NO_WIND = (0.0, 0.0, 0.0)
N_AUX_STATE = 12  # + η_φ, η_θ of the second-order attitude form


@njit(cache=True, **INNER_KERNEL)
def _rhs(q, second, roll, pitch, gaz, yaw, hold, k, w):
    """The motors-on right-hand side (the one definition) at the state's dynamic part ``q`` =
    (vx, vy, vz, φ, θ, ψ, r, η_φ, η_θ) — x[3:12]; η unused unless ``second`` (the
    second-order attitude form) — as a 12-tuple (its last two 0.0 unless ``second``). ``k`` is
    ``PlantParams.rhs_coefficients``. On values, not arrays: :func:`_rk4_into` holds its
    stages in tuples — an array passed between kernels costs an atomic reference count at
    every call (with seven per RK4 step, a third of the legs kernel's time). Not
    ``inline="always"``: numba would type and lower it once per call site (13 of them, ~2 s
    more of a cold start); LLVM inlines it where it pays.

    The tilt: first order (ref − φ)/τ_a; second order with a zero, observable canonical form
    of (b1·s + b0)/(s² + a1·s + a0): φ' = −a1·φ + η + b1·ref, η' = −a0·φ + b0·ref."""
    e_roll, vz_gain, inv_tau_vz, yaw_gain, inv_tau_yaw = k[0], k[1], k[2], k[3], k[4]
    kd, hold_damping, e_pitch = k[6], k[7], k[8]
    vx, vy, vz, phi, theta, psi, r = q[0], q[1], q[2], q[3], q[4], q[5], q[6]
    forward = GRAVITY_MPS2 * math.tan(theta)
    right = GRAVITY_MPS2 * math.tan(phi)
    c = math.cos(psi)
    s = math.sin(psi)
    ax = c * forward + s * right - kd * (vx - w[0])
    ay = s * forward - c * right - kd * (vy - w[1])
    if hold:
        ax -= hold_damping * vx
        ay -= hold_damping * vy
        ref_phi = ref_theta = 0.0
    else:
        ref_phi, ref_theta = roll * e_roll, -pitch * e_pitch
    if second:
        a1, a0, b1, b0 = k[9], k[10], k[11], k[12]
        d_phi = -a1 * phi + q[7] + b1 * ref_phi
        d_theta = -a1 * theta + q[8] + b1 * ref_theta
        d_eta_phi = -a0 * phi + b0 * ref_phi
        d_eta_theta = -a0 * theta + b0 * ref_theta
    else:
        inv_tau_tilt = k[5]
        d_phi = (ref_phi - phi) * inv_tau_tilt
        d_theta = (ref_theta - theta) * inv_tau_tilt
        d_eta_phi = d_eta_theta = 0.0
    return (vx, vy, vz, ax, ay, gaz * vz_gain - vz * inv_tau_vz + kd * w[2], d_phi, d_theta, r,
            -yaw * yaw_gain - r * inv_tau_yaw, d_eta_phi, d_eta_theta)


@njit(cache=True, inline="always", **INNER_KERNEL)
def _dynamic_part(x, second):
    """x[3:12] as :func:`_rhs`' ``q`` (η 0.0 for a 10-state)."""
    return (x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[10] if second else 0.0,
            x[11] if second else 0.0)


@njit(cache=True, inline="always", **INNER_KERNEL)
def _stage(x, f, d):
    """An RK4 stage's ``q``: x[3:12] + f·d[3:12] element by element (``x`` a ``q``)."""
    return (x[0] + f * d[3], x[1] + f * d[4], x[2] + f * d[5], x[3] + f * d[6],
            x[4] + f * d[7], x[5] + f * d[8], x[6] + f * d[9], x[7] + f * d[10],
            x[8] + f * d[11])


@njit(cache=True, **OUTER_KERNEL)
def _airframe_rhs(x, roll, pitch, gaz, yaw, hold, k, w, out):
    """:func:`_rhs` of the state array ``x`` (10 or 12) into ``out`` (its first x.size):
    :func:`airframe_derivative`'s."""
    second = x.shape[0] > N_STATE
    d = _rhs(_dynamic_part(x, second), second, roll, pitch, gaz, yaw, hold, k, w)
    for i in range(x.shape[0]):
        out[i] = d[i]


@njit(cache=True, inline="always", **INNER_KERNEL)
def _rk4_into(x, roll, pitch, gaz, yaw, hold, k, w, h, out):
    """One classical RK4 step of :func:`_rhs` from the array ``x`` into ``out`` (``out`` may
    be ``x``). The stages need only x[3:] (the RHS reads no position): the same arithmetic,
    element by element, as stepping whole stage arrays."""
    second = x.shape[0] > N_STATE
    hh = 0.5 * h
    q = _dynamic_part(x, second)
    a = _rhs(q, second, roll, pitch, gaz, yaw, hold, k, w)
    b = _rhs(_stage(q, hh, a), second, roll, pitch, gaz, yaw, hold, k, w)
    c = _rhs(_stage(q, hh, b), second, roll, pitch, gaz, yaw, hold, k, w)
    d = _rhs(_stage(q, h, c), second, roll, pitch, gaz, yaw, hold, k, w)
    h6 = h / 6.0
    for i in range(x.shape[0]):
        out[i] = x[i] + h6 * (a[i] + 2.0 * (b[i] + c[i]) + d[i])


@njit(cache=True, **INNER_KERNEL)
def _rk4_array(x, roll, pitch, gaz, yaw, hold, k, w, h):
    """One classical RK4 step of :func:`_rhs` from the array ``x``; a new array."""
    out = np.empty(x.shape[0])
    _rk4_into(x, roll, pitch, gaz, yaw, hold, k, w, h, out)
    return out


@njit(cache=True, **OUTER_KERNEL)
def airframe_rk4(state, roll, pitch, gaz, yaw, hold, k, w, h):
    """:func:`rk4_step` of :func:`airframe_derivative`, compiled: the simulator's hot path
    (13 substeps per control tick) for the first-order attitude form. ``k`` is
    ``PlantParams.rhs_coefficients``; returns the new 10-tuple state."""
    x = np.empty(N_STATE)
    for i in range(N_STATE):
        x[i] = state[i]
    x = _rk4_array(x, roll, pitch, gaz, yaw, hold, k, w, h)
    return (x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9])


@njit(cache=True, **OUTER_KERNEL)
def airframe_rk4_array(x, roll, pitch, gaz, yaw, hold, k, w, h):
    """:func:`airframe_rk4` on a state array of 10 or, with the second-order attitude form,
    12 elements; returns a new array."""
    return _rk4_array(x, roll, pitch, gaz, yaw, hold, k, w, h)


@njit(cache=True, inline="always", **INNER_KERNEL)
def shift_ring(ring, head, roll, pitch, gaz, yaw, hold):
    """Queue the command ``roll`` … ``hold`` in the delay ring ``ring`` (m, 5; oldest at
    ``head``) and return the oldest with the new head — the command itself when the ring is
    empty (no delay); :meth:`~ardrone_nmpc.sim.command_fifo.CommandFifo.shift` compiled, for
    both plants' flying steps."""
    m = ring.shape[0]
    if m == 0:
        return roll, pitch, gaz, yaw, hold, head
    r, p, g, y, hd = (ring[head, 0], ring[head, 1], ring[head, 2], ring[head, 3],
                      ring[head, 4] != 0.0)
    ring[head, 0], ring[head, 1], ring[head, 2], ring[head, 3] = roll, pitch, gaz, yaw
    ring[head, 4] = 1.0 if hold else 0.0
    return r, p, g, y, hd, head + 1 if head + 1 < m else 0


@njit(cache=True, inline="always", **INNER_KERNEL)
def sagged_vz_gain(vz_gain, sag, battery):
    """:meth:`~ardrone_nmpc.sim.plant.PlantParams.vertical_gain` at the battery level
    ``battery`` (%), Python's ``min`` and ``max`` spelled out — for both plants' flying
    steps."""
    level = battery if not 0.0 > battery else 0.0
    level = level if not 100.0 < level else 100.0
    return vz_gain * (1.0 - sag * (1.0 - level / 100.0))


@njit(cache=True, inline="always", **INNER_KERNEL)
def floor_and_drain(x, battery, drain):
    """The end of a flying step, :meth:`~ardrone_nmpc.sim.plant.AirframePlant._substep`'s:
    the floor on the state array ``x`` (z ≤ 0 stops at 0 with no downward speed; a NaN z is
    kept, as Python's ``max``), then the drain; returns the battery left (≥ 0)."""
    if not x[2] > 0.0:
        x[2] = 0.0
        if 0.0 > x[5]:
            x[5] = 0.0
    left = battery - drain
    return left if left > 0.0 else 0.0


@njit(cache=True, **INNER_KERNEL)
def flying_steps(x, ring, head, roll, pitch, gaz, yaw, hold, k, w, h, n, battery, drain, vz_gain,
                 sag):
    """Up to ``n`` steps of a FLYING plant in one call: each queues the current command
    (``roll`` … ``hold``) in the delay ring ``ring`` (m, 5; oldest at ``head``; shifted in
    place) and flies the oldest (the current one with no delay), one RK4 step from the state
    array ``x`` (10 or 12), then the floor (z ≤ 0 stops at 0 with no downward speed) and the
    battery drain — :meth:`~ardrone_nmpc.sim.plant.AirframePlant._substep`'s arithmetic in
    its order. Stops before a step whose drain would empty the battery (a mode change, the
    plant's). With a battery sag ``sag`` > 0 each step's vertical gain is
    :meth:`~ardrone_nmpc.sim.plant.PlantParams.coefficients_at`'s at the battery level before
    it (``vz_gain``: the unsagged one). Returns (steps done, head, battery, state array)."""
    x = x.copy()
    done, head, battery = flying_steps_into(x, ring, head, roll, pitch, gaz, yaw, hold, k, w,
                                            h, n, battery, drain, vz_gain, sag)
    return done, head, battery, x


@njit(cache=True, **INNER_KERNEL)
def flying_steps_into(x, ring, head, roll, pitch, gaz, yaw, hold, k, w, h, n, battery, drain,
                      vz_gain, sag):
    """:func:`flying_steps` on ``x`` in place (the lockstep tick's legs). Returns (steps
    done, head, battery)."""
    for i in range(n):
        if not battery - drain > 0.0:
            return i, head, battery
        r, p, g, y, hd, head = shift_ring(ring, head, roll, pitch, gaz, yaw, hold)
        kk = k
        if sag != 0.0:
            gain = sagged_vz_gain(vz_gain, sag, battery)
            kk = (k[0], k[1] * gain / vz_gain, k[2], k[3], k[4], k[5], k[6], k[7], k[8], k[9],
                  k[10], k[11], k[12])
        _rk4_into(x, r, p, g, y, hd, kk, w, h, x)
        battery = floor_and_drain(x, battery, drain)
    return n, head, battery


def rk4_step(deriv, state: tuple, h: float, command: tuple, params,
             wind_mps: tuple = _NO_WIND) -> tuple:
    """One classical RK4 step of ``deriv(state, command, params, wind_mps)`` over ``h``.

    Unrolled over the 10 states: list comprehensions over ``zip`` cost 3× more here.
    """
    x0, x1, x2, x3, x4, x5, x6, x7, x8, x9 = state
    hh = 0.5 * h
    a0, a1, a2, a3, a4, a5, a6, a7, a8, a9 = deriv(state, command, params, wind_mps)
    b0, b1, b2, b3, b4, b5, b6, b7, b8, b9 = deriv(
        (x0 + hh * a0, x1 + hh * a1, x2 + hh * a2, x3 + hh * a3, x4 + hh * a4,
         x5 + hh * a5, x6 + hh * a6, x7 + hh * a7, x8 + hh * a8, x9 + hh * a9),
        command, params, wind_mps)
    c0, c1, c2, c3, c4, c5, c6, c7, c8, c9 = deriv(
        (x0 + hh * b0, x1 + hh * b1, x2 + hh * b2, x3 + hh * b3, x4 + hh * b4,
         x5 + hh * b5, x6 + hh * b6, x7 + hh * b7, x8 + hh * b8, x9 + hh * b9),
        command, params, wind_mps)
    d0, d1, d2, d3, d4, d5, d6, d7, d8, d9 = deriv(
        (x0 + h * c0, x1 + h * c1, x2 + h * c2, x3 + h * c3, x4 + h * c4,
         x5 + h * c5, x6 + h * c6, x7 + h * c7, x8 + h * c8, x9 + h * c9),
        command, params, wind_mps)
    h6 = h / 6.0
    return (x0 + h6 * (a0 + 2.0 * (b0 + c0) + d0), x1 + h6 * (a1 + 2.0 * (b1 + c1) + d1),
            x2 + h6 * (a2 + 2.0 * (b2 + c2) + d2), x3 + h6 * (a3 + 2.0 * (b3 + c3) + d3),
            x4 + h6 * (a4 + 2.0 * (b4 + c4) + d4), x5 + h6 * (a5 + 2.0 * (b5 + c5) + d5),
            x6 + h6 * (a6 + 2.0 * (b6 + c6) + d6), x7 + h6 * (a7 + 2.0 * (b7 + c7) + d7),
            x8 + h6 * (a8 + 2.0 * (b8 + c8) + d8), x9 + h6 * (a9 + 2.0 * (b9 + c9) + d9))


def freefall_derivative(state: tuple, command: tuple, params,
                        wind_mps: tuple = _NO_WIND) -> tuple:
    """Right-hand side with the motors cut (EMERGENCY): gravity, horizontal drag; φ, θ and the
    yaw rate r stay as they were (ψ keeps turning at r).

    Same signature as :func:`~ardrone_nmpc.sim.plant.airframe_derivative` (``params`` a
    :class:`~ardrone_nmpc.sim.plant.PlantParams`); ``command`` is ignored.
    """
    vx, vy, vz = state[3:6]
    kd = params.drag_per_s
    return (vx, vy, vz, -kd * (vx - wind_mps[0]), -kd * (vy - wind_mps[1]), -GRAVITY_MPS2,
            0.0, 0.0, state[9], 0.0)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
