"""A flying plant's whole :meth:`~ardrone_nmpc.sim.plant.AirframePlant.advance` in one
compiled call: the substeps (:func:`~ardrone_nmpc.sim.airframe.flying_steps`), the heading
wrapped, and the navdata biases advanced (the yaw offset's drift and walk, the velocity
biases' Gauss–Markov step) — the plant's Python arithmetic in its order, so the same bits,
without the interpreter between the steps (the simulator's largest cost per tick).
:func:`auto_steps` does the same for the steps of the automatic take-off and landing, up to
the mode change that ends them."""

from __future__ import annotations

import math

from numba import njit

from ardrone_nmpc.core.angle_kernels import wrap_half_turn
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL

from ardrone_nmpc.sim.airframe import _rk4_into, flying_steps, sagged_vz_gain, shift_ring

__all__ = ["AUTO_FLYING", "AUTO_LANDED", "AUTO_LANDING", "advance_biases", "auto_step_end",
           "auto_steps", "flying_advance"]

#: :func:`auto_steps`' mode after its last step: unchanged, or the one it changed to
AUTO_SAME, AUTO_FLYING, AUTO_LANDING, AUTO_LANDED = 0, 1, 2, 3


@njit(cache=True, **INNER_KERNEL)
def advance_biases(dt, normals, yaw_bias_deg, vel_bias_0, vel_bias_1, yaw_drift_radps,
                   yaw_walk, vel_bias_std, vel_bias_tau_s):
    """:meth:`~ardrone_nmpc.sim.plant.AirframePlant._advance_biases` over ``dt``: the yaw
    offset by ``yaw_drift_radps``·dt (signed) and ``yaw_walk``·√dt·normals[0], the velocity
    biases as :func:`~ardrone_nmpc.sim.plant.gauss_markov_step`. Returns (yaw offset °,
    velocity bias 0, velocity bias 1)."""
    drift = yaw_drift_radps * dt
    walk = yaw_walk * math.sqrt(dt) * normals[0]
    yaw_bias_deg = wrap_half_turn(yaw_bias_deg + math.degrees(drift + walk), 180.0)
    a = math.exp(-dt / vel_bias_tau_s)
    q = vel_bias_std * math.sqrt(1.0 - a * a)
    return yaw_bias_deg, a * vel_bias_0 + q * normals[1], a * vel_bias_1 + q * normals[2]


@njit(cache=True, **OUTER_KERNEL)
def flying_advance(x, ring, head, roll, pitch, gaz, yaw, hold, k, w, h, n, battery, drain,
                   vz_gain, sag, normals, yaw_bias_deg, vel_bias_0, vel_bias_1,
                   yaw_drift_radps, yaw_walk, vel_bias_std, vel_bias_tau_s):
    """``n`` steps of :func:`flying_steps` (arguments as there), then — only if all ``n``
    were flown — the heading wrapped and the biases advanced over ``n·h`` with the standard
    normals ``normals`` (3) (:func:`advance_biases`). Returns (steps done, head, battery,
    state, yaw offset °, velocity bias 0, velocity bias 1)."""
    done, head, battery, x = flying_steps(x, ring, head, roll, pitch, gaz, yaw, hold, k, w, h,
                                          n, battery, drain, vz_gain, sag)
    if done < n:  # the battery empties: the plant's step-by-step path goes on
        return done, head, battery, x, yaw_bias_deg, vel_bias_0, vel_bias_1
    x[8] = wrap_half_turn(x[8], math.pi)
    yaw_bias_deg, vel_bias_0, vel_bias_1 = advance_biases(
        n * h, normals, yaw_bias_deg, vel_bias_0, vel_bias_1, yaw_drift_radps, yaw_walk,
        vel_bias_std, vel_bias_tau_s)
    return done, head, battery, x, yaw_bias_deg, vel_bias_0, vel_bias_1


@njit(cache=True, **OUTER_KERNEL)
def auto_steps(x, ring, head, roll, pitch, gaz, yaw, hold, landing, gaz_auto, k, w, h, n,
               battery, drain, vz_gain, sag, tau_vz_s, takeoff_altitude_m):
    """Up to ``n`` steps of the automatic take-off (``landing`` False) or landing —
    :meth:`~ardrone_nmpc.sim.plant.AirframePlant._substep`'s arithmetic in its order: the
    current command (``roll`` … ``hold``) queued in the delay ring and ignored, one RK4 step of
    the automatic climb or descent (gaz ``gaz_auto``, position hold; the vertical gain sagged
    as :func:`flying_steps` sags it), the floor — a landing touches down at rest, its hidden
    attitude states kept — the drain, the mode's transitions (a take-off whose climb will
    settle at ``takeoff_altitude_m`` flies, an empty battery lands). Stops after the step that
    changes the mode. Returns (steps done, head, battery, state array, the mode then:
    ``AUTO_*``)."""
    x = x.copy()
    # position hold: True, typed ``bool`` — a literal ``True`` is typed ``Literal[bool](True)``
    # and would type the inlined _rk4_into and _rhs a second time (flying_steps passes a
    # ``bool``): ~0.5 s of a cold start. The same arithmetic either way.
    auto_hold = landing or not landing
    for i in range(n):
        head = shift_ring(ring, head, roll, pitch, gaz, yaw, hold)[5]
        kk = k
        if sag != 0.0:
            gain = sagged_vz_gain(vz_gain, sag, battery)
            kk = (k[0], k[1] * gain / vz_gain, k[2], k[3], k[4], k[5], k[6], k[7], k[8], k[9],
                  k[10], k[11], k[12])
        _rk4_into(x, 0.0, 0.0, gaz_auto, 0.0, auto_hold, kk, w, h, x)
        battery, mode = auto_step_end(x, battery, drain, landing, tau_vz_s,
                                      takeoff_altitude_m)
        if mode != AUTO_SAME:
            return i + 1, head, battery, x, mode
    return n, head, battery, x, AUTO_SAME


@njit(cache=True, inline="always", **INNER_KERNEL)
def auto_step_end(x, battery, drain, landing, tau_vz_s, takeoff_altitude_m):
    """The end of a step of the automatic take-off (``landing`` False) or landing on the
    state array ``x`` (:meth:`~ardrone_nmpc.sim.plant.AirframePlant._substep`'s, after the
    motors-on step; :func:`auto_steps`' and the kit's ``kit_auto_steps``): the floor — a
    landing touches down at rest, the hidden attitude states kept —, the drain, the mode's
    transitions (a take-off whose climb will settle at ``takeoff_altitude_m`` flies, an
    empty battery lands). Returns (battery, the mode then: ``AUTO_*``)."""
    mode = AUTO_SAME
    if not x[2] > 0.0:  # _ground_contact
        if landing:  # touch-down: at rest (_at_rest keeps x, y, ψ)
            for j in (2, 3, 4, 5, 6, 7, 9):
                x[j] = 0.0
            mode = AUTO_LANDED
        else:  # the floor
            x[2] = 0.0
            if 0.0 > x[5]:
                x[5] = 0.0
    left = battery - drain
    battery = left if left > 0.0 else 0.0
    if mode == AUTO_LANDED:  # _check_transitions of a LANDED plant: none
        return battery, mode
    if not landing and x[2] + x[5] * tau_vz_s >= takeoff_altitude_m:
        mode = AUTO_FLYING
    if battery <= 0.0 and not landing:  # taking off (or flying since this step)
        mode = AUTO_LANDING
    return battery, mode


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
