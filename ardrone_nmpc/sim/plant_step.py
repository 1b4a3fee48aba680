"""A flying plant's whole :meth:`~ardrone_nmpc.sim.plant.AirframePlant.advance` in one
compiled call: the substeps (:func:`~ardrone_nmpc.sim.airframe.flying_steps`), the heading
wrapped, and the navdata biases advanced (the yaw offset's drift and walk, the velocity
biases' Gauss–Markov step) — the plant's Python arithmetic in its order, so the same bits,
without the interpreter between the steps (the simulator's largest cost per tick)."""

from __future__ import annotations

import math

from numba import njit

from ardrone_nmpc.core.angle_kernels import wrap_half_turn
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.sim.airframe import flying_steps

__all__ = ["advance_biases", "flying_advance"]


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


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
