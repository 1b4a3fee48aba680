"""One lockstep tick of the simulated drone in one compiled call: the plant run from sensor
event to sensor event and the samples drawn on the way.

:meth:`LockstepSensors.advance_to <ardrone_nmpc.sim.sensors.LockstepSensors.advance_to>` runs the
drone to the newest mocap frame time, draws a pose, to the newest navdata time, draws a
sample, then to the tick's time — each leg a firmware advance (plant advance, watchdogs, the
held command) and each sample a few lines of arithmetic. :func:`lockstep_run` does the same
legs and samples for an airborne airframe plant — FLYING, or in its automatic take-off or
landing (:func:`~ardrone_nmpc.sim.plant_step.auto_steps`), or a thesis_kit plant's
(:mod:`~ardrone_nmpc.sim.plant_kit`, a state array of ``X_KIT``) — while nothing but
physics happens between them (the caller checks that nothing the firmware does could change on the way; here
each leg is checked for what only its start shows — a climb within reach of the altitude
cap, a battery that could empty — and the run stops before such a leg, untouched, for the
Python path to go on from there; a take-off's or landing's leg that ends it — the climb
settled, the touch-down — is flown on as the Python path flies it, FLYING or at rest, when
the caller allows it (``sv[S_ENDS]``: nothing but the plant's mode changes with it), else
found to change the mode and undone, for the Python path too). The arithmetic is the Python's, in its order: the event grid of ``advance_to``'s
direct path, :meth:`AirframePlant.advance <ardrone_nmpc.sim.plant.AirframePlant.advance>`
(whole steps, the remainder carried; :func:`~ardrone_nmpc.sim.plant_step.flying_advance`, the
turbulence's Gauss–Markov step), :meth:`~ardrone_nmpc.sim.plant.AirframePlant.mocap_pose`
and :meth:`~ardrone_nmpc.sim.plant.AirframePlant.navdata`. The normals come from blocks drawn
ahead (:class:`~ardrone_nmpc.sim.normal_blocks.NormalBlocks`), consumed in the order the
Python draws them.

The arrays (indices below): ``iv`` int64 counters, ``sv`` the plant's float state beside its
state vector, ``p`` the parameters of a flight, ``out`` what the run produced — the four
side by side in one array ``buf`` (``B_*``), one argument of the call.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.angle_kernels import wrap_half_turn
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.sim.airframe import N_STATE, flying_steps_into, shift_ring
from ardrone_nmpc.sim.plant_kit import N_KIT, kit_auto_steps, kit_flying_steps
from ardrone_nmpc.sim.plant_step import (AUTO_FLYING, AUTO_LANDED, AUTO_SAME, advance_biases,
                                         auto_steps)

__all__ = ["lockstep_run"]

# iv: int64 counters (in and out)
I_STEPS, I_HEAD, I_NEXT_MOCAP, I_NEXT_NAV = 0, 1, 2, 3
I_POS_BIAS, I_POS_GUST, I_POS_MOCAP, I_POS_NAV = 4, 5, 6, 7
I_DONE, I_EVENTS, I_KIND0, I_KIND1, I_CHANGED = 8, 9, 10, 11, 12
IV_SIZE = 13
# sv: the plant's float state (in and out), the plant's current command (roll, pitch, gaz,
# yaw, position hold 0/1), the firmware's cap (climbing 0/1, its lead, the cap), the wind,
# the plant's mode (MODE_*), the tick's time, whether the run may fly the take-off's or the
# landing's end (1/0; in: the last fourteen side by side, from the command on, which the
# caller writes in one pack every run)
(S_PENDING, S_BATTERY, S_YAW_BIAS, S_VB0, S_VB1, S_GUST0, S_GUST1, S_ROLL, S_PITCH, S_GAZ,
 S_YAW, S_HOLD, S_CLIMBING, S_LEAD, S_ALT_MAX, S_W0, S_W1, S_W2, S_MODE, S_T,
 S_ENDS) = range(21)
SV_SIZE = 21
#: the kernel's modes (LANDED: only after a touch-down the run flew)
MODE_FLYING, MODE_TAKING_OFF, MODE_LANDING, MODE_LANDED = 0.0, 1.0, 2.0, 3.0
# p: a flight's parameters (the automatic climb's and descent's gaz, τ_z, the take-off
# height among them), then the 13 coefficients of the airframe's RHS, then the thesis_kit
# plant's 27 (KitModel.coefficients; read only for a kit plant's state array: X_KIT)
(P_H, P_DRAIN, P_YAW_DRIFT, P_YAW_WALK, P_VB_STD, P_VB_TAU, P_TURB_STD, P_TURB_TAU,
 P_MOCAP_PERIOD, P_MOCAP_LATENCY, P_NAV_PERIOD, P_SP, P_SA, P_ATT_STD, P_YAW_STD, P_ALT_STD,
 P_VEL_STD, P_TRIM0, P_TRIM1, P_BIAS0, P_BIAS1, P_VMAX, P_VZ_GAIN, P_SAG, P_GAZ_UP, P_GAZ_DOWN,
 P_TAU_VZ, P_TAKEOFF_ALT, P_K) = range(29)
N_K = 13
P_KIT_K, N_KIT_K = P_K + N_K, 27
P_SIZE = P_KIT_K + N_KIT_K
#: the state array of a thesis_kit plant (sim/plant_kit.KitPlant): its 10-state, then its
#: channels' 12 (the kernel flies the kit's dynamics for an array of this length; the
#: airframe's is 10, or 12 with the second-order attitude form)
X_KIT = N_STATE + N_KIT
# the normals a run may take: three legs of bias and gust draws, one pose, one navdata sample
NEED_BIAS, NEED_GUST, NEED_MOCAP, NEED_NAV = 9, 6, 6, 7
# out: the pose (t, position, XYZ angles, ψ), the navdata sample (t, battery, roll, pitch,
# yaw, altitude, forward, right, down), the event times, the last firmware time — and, after
# a run that did all its legs, the plant's time, battery and 10-state then (its truth)
O_POSE, O_NAV, O_EV_T0, O_EV_T1, O_LAST_NOW = 0, 8, 17, 18, 19
O_T, O_BATTERY, O_STATE = 20, 21, 22
OUT_SIZE = O_STATE + 10
#: buf: the four side by side in one float64 array (iv's int64 viewed in place) — the kernel's
#: one argument for them (every array argument costs the call ~30 ns to unbox); out first,
#: then iv: the caller reads what a run left (out, iv[I_DONE …]) in one unpack of buf's bytes
B_OUT, B_IV, B_SV, B_P = 0, OUT_SIZE, OUT_SIZE + IV_SIZE, OUT_SIZE + IV_SIZE + SV_SIZE
BUF_SIZE = B_P + P_SIZE
MOCAP, NAV = 0, 1
_TIME_TOL_S = 1e-9  # the plant's (sim/plant.py)


@njit(cache=True, **INNER_KERNEL)
def _mocap_pose(x, sp, sa, n, out):
    """:meth:`AirframePlant.mocap_pose`'s arithmetic (with
    :func:`~ardrone_nmpc.sim.geometry.mocap_rotation_xyz_rad` and
    :func:`~ardrone_nmpc.protocol.mocap.rotation_heading_rad`) into ``out[1:8]``."""
    phi, theta, psi = x[6], x[7], x[8]
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    sps, cps = math.sin(psi), math.cos(psi)
    r00 = cps * ct
    r01 = cps * st * sf - sps * cf
    r02 = cps * st * cf + sps * sf
    r12 = sps * st * cf - cps * sf
    r22 = ct * cf
    c = r02 if r02 < 1.0 else 1.0  # min(1.0, r02) as Python's min: a NaN gives 1.0
    c = c if c > -1.0 else -1.0
    ry = math.asin(c)
    rx, rz = math.atan2(-r12, r22), math.atan2(-r01, r00)
    rx, ry = wrap_half_turn(rx + sa * n[3], math.pi), ry + sa * n[4]
    rz = wrap_half_turn(rz + sa * n[5], math.pi)
    out[1], out[2], out[3] = x[0] + sp * n[0], x[1] + sp * n[1], x[2] + sp * n[2]
    out[4], out[5], out[6] = rx, ry, rz
    if not (math.isfinite(rx) and math.isfinite(ry) and math.isfinite(rz)):
        out[7] = math.nan
        return
    r10 = math.cos(rx) * math.sin(rz) + math.sin(rx) * math.sin(ry) * math.cos(rz)
    r00 = math.cos(ry) * math.cos(rz)
    heading = math.atan2(r10, r00)
    out[7] = math.pi if heading <= -math.pi else heading


@njit(cache=True, **INNER_KERNEL)
def _navdata(x, sv, p, n, out):
    """:meth:`AirframePlant.navdata`'s arithmetic for an airborne plant into ``out[2:9]``."""
    vx, vy, vz, phi, theta, psi = x[3], x[4], x[5], x[6], x[7], x[8]
    out[2] = math.degrees(phi + p[P_TRIM0] + p[P_ATT_STD] * n[0])
    out[3] = math.degrees(-theta + p[P_TRIM1] + p[P_ATT_STD] * n[1])
    out[4] = wrap_half_turn(math.degrees(-psi + p[P_YAW_STD] * n[2]) + sv[S_YAW_BIAS], 180.0)
    c, s = math.cos(psi), math.sin(psi)
    sv_ = p[P_VEL_STD]
    altitude = x[2] + p[P_ALT_STD] * n[3]
    out[5] = altitude if altitude > 0.0 else 0.0  # max(0.0, …) as Python's max
    out[6] = c * vx + s * vy + sv[S_VB0] + p[P_BIAS0] + sv_ * n[4]
    out[7] = s * vx - c * vy + sv[S_VB1] + p[P_BIAS1] + sv_ * n[5]
    out[8] = -vz + sv_ * n[6]


@njit(cache=True, **INNER_KERNEL)
def _gust_step(iv, sv, p, n, h, gust_n):
    """The turbulence's step at the end of an advance of ``n`` steps (none without)."""
    if p[P_TURB_STD] > 0.0:  # plant.gauss_markov_step over the call's n·h
        a = math.exp(-(n * h) / p[P_TURB_TAU])
        q = p[P_TURB_STD] * math.sqrt(1.0 - a * a)
        g = iv[I_POS_GUST]
        iv[I_POS_GUST] = g + 2
        sv[S_GUST0] = a * sv[S_GUST0] + q * gust_n[g]
        sv[S_GUST1] = a * sv[S_GUST1] + q * gust_n[g + 1]


@njit(cache=True, **INNER_KERNEL)
def _flying_steps(x, ring, head, roll, pitch, gaz, yaw, hold, k, p, w, h, n, battery):
    """:func:`flying_steps_into` on the state array ``x`` (the airframe's RHS coefficients
    ``k``) — or, for a thesis_kit plant's (``X_KIT``), :func:`kit_flying_steps` on its
    10-state and its channels (the kit's coefficients in ``p``). Returns (steps done, head,
    battery)."""
    if x.shape[0] == X_KIT:
        return kit_flying_steps(x, x[N_STATE:], ring, head, roll, pitch, gaz, yaw, hold,
                                _kit_coefficients(p), w, h, n, battery, p[P_DRAIN],
                                p[P_VZ_GAIN], p[P_SAG])
    return flying_steps_into(x, ring, head, roll, pitch, gaz, yaw, hold, k, w, h, n, battery,
                             p[P_DRAIN], p[P_VZ_GAIN], p[P_SAG])


@njit(cache=True, **INNER_KERNEL)
def _auto_steps(x, ring, head, roll, pitch, gaz, yaw, hold, landing, k, p, w, h, n, battery):
    """:func:`auto_steps` of the state array ``x`` (as :func:`_flying_steps` chooses: the
    airframe's, or a thesis_kit plant's :func:`kit_auto_steps` on a copy). Returns (steps
    done, head, battery, the new state array, the mode then: ``AUTO_*``)."""
    gaz_auto = p[P_GAZ_DOWN] if landing else p[P_GAZ_UP]
    if x.shape[0] == X_KIT:
        xn = x.copy()
        done, head, battery, mode = kit_auto_steps(
            xn, xn[N_STATE:], ring, head, roll, pitch, gaz, yaw, hold, landing, gaz_auto,
            _kit_coefficients(p), w, h, n, battery, p[P_DRAIN], p[P_VZ_GAIN], p[P_SAG],
            p[P_TAU_VZ], p[P_TAKEOFF_ALT])
        return done, head, battery, xn, mode
    return auto_steps(x, ring, head, roll, pitch, gaz, yaw, hold, landing, gaz_auto, k, w, h,
                      n, battery, p[P_DRAIN], p[P_VZ_GAIN], p[P_SAG], p[P_TAU_VZ],
                      p[P_TAKEOFF_ALT])


@njit(cache=True, **INNER_KERNEL)
def _kit_coefficients(p):
    """The thesis_kit plant's coefficients in ``p`` (``P_KIT_K``): the tuple of
    ``KitModel.coefficients``."""
    q = P_KIT_K
    return (p[q], p[q + 1], p[q + 2], p[q + 3], p[q + 4], p[q + 5], p[q + 6], p[q + 7],
            p[q + 8], p[q + 9], p[q + 10], p[q + 11], p[q + 12], p[q + 13], p[q + 14],
            p[q + 15], p[q + 16], p[q + 17], p[q + 18], p[q + 19], p[q + 20], p[q + 21],
            p[q + 22], p[q + 23], p[q + 24], p[q + 25], p[q + 26])


@njit(cache=True, **INNER_KERNEL)
def _wrap_and_biases(x, iv, sv, p, dt, bias_n):
    """The end of a take-off's, landing's or landed advance over ``dt``: the heading
    wrapped, the navdata biases advanced (:func:`advance_biases`, the next three normals)."""
    x[8] = wrap_half_turn(x[8], math.pi)
    pos = iv[I_POS_BIAS]
    iv[I_POS_BIAS] = pos + 3
    sv[S_YAW_BIAS], sv[S_VB0], sv[S_VB1] = advance_biases(
        dt, bias_n[pos:pos + 3], sv[S_YAW_BIAS], sv[S_VB0], sv[S_VB1], p[P_YAW_DRIFT],
        p[P_YAW_WALK], p[P_VB_STD], p[P_VB_TAU])


@njit(cache=True, **INNER_KERNEL)
def _auto_leg(x, ring, iv, sv, p, k, w, h, n, bias_n, leg):
    """The automatic take-off's or landing's ``n`` steps (:meth:`AirframePlant.advance
    <ardrone_nmpc.sim.plant.AirframePlant.advance>`: :func:`auto_steps`, the heading's wrap,
    the biases). Steps that change the mode: with ``sv[S_ENDS]`` set, a take-off whose climb
    settles flies on (the steps left as :func:`flying_steps_into`'s, unless the battery
    would empty) and a landing that touches down rests (the steps left shift the delay ring
    only) — the mode then in ``sv[S_MODE]``, this ``leg`` in ``iv[I_CHANGED]``; otherwise
    False, with the state and the ring as they were."""
    m = ring.shape[0]
    saved = np.empty((m, 5))  # auto_steps shifts the ring in place
    for i in range(m):
        for j in range(5):
            saved[i, j] = ring[i, j]
    done, head, battery, xn, mode = _auto_steps(
        x, ring, iv[I_HEAD], sv[S_ROLL], sv[S_PITCH], sv[S_GAZ], sv[S_YAW], sv[S_HOLD] != 0.0,
        sv[S_MODE] == MODE_LANDING, k, p, w, h, n, sv[S_BATTERY])
    if mode != AUTO_SAME or done < n:  # the mode changes on the way
        ends = sv[S_ENDS] != 0.0
        roll, pitch, gaz, yaw, hold = (sv[S_ROLL], sv[S_PITCH], sv[S_GAZ], sv[S_YAW],
                                       sv[S_HOLD] != 0.0)
        if ends and mode == AUTO_FLYING:  # _substep's FLYING steps for the rest
            flown, head, battery = _flying_steps(xn, ring, head, roll, pitch, gaz, yaw, hold,
                                                 k, p, w, h, n - done, battery)
            ends = flown == n - done  # (else the battery empties: a mode change again)
        elif ends and mode == AUTO_LANDED:  # _substep's LANDED steps: the ring shifted
            for i in range(n - done):
                head = shift_ring(ring, head, roll, pitch, gaz, yaw, hold)[5]
        else:
            ends = False
        if not ends:  # the Python path's
            for i in range(m):
                for j in range(5):
                    ring[i, j] = saved[i, j]
            return False
        sv[S_MODE] = MODE_FLYING if mode == AUTO_FLYING else MODE_LANDED
        iv[I_CHANGED] = leg
        done = n
    _wrap_and_biases(xn, iv, sv, p, n * h, bias_n)
    iv[I_HEAD] = head
    iv[I_STEPS] += done
    sv[S_BATTERY] = battery
    for i in range(x.shape[0]):
        x[i] = xn[i]
    return True


@njit(cache=True, **INNER_KERNEL)
def _landed_leg(x, ring, iv, sv, p, n, h, bias_n):
    """``n`` steps of a plant that touched down earlier in the run (:meth:`AirframePlant.
    advance <ardrone_nmpc.sim.plant.AirframePlant.advance>` of a LANDED plant: each
    ``_substep`` shifts the delay ring only; the heading's wrap, the biases)."""
    head, hold = iv[I_HEAD], sv[S_HOLD] != 0.0
    for i in range(n):
        head = shift_ring(ring, head, sv[S_ROLL], sv[S_PITCH], sv[S_GAZ], sv[S_YAW], hold)[5]
    _wrap_and_biases(x, iv, sv, p, n * h, bias_n)
    iv[I_HEAD] = head
    iv[I_STEPS] += n


@njit(cache=True, **INNER_KERNEL)
def _leg(x, ring, iv, sv, p, k, bias_n, gust_n, t_event, leg):
    """The firmware's advance to ``t_event`` (plant time), the run's ``leg``-th — False, with
    nothing changed, if the Python path must take it (a climb within reach of the cap, a
    battery that could empty on the way, a take-off or landing that ends on the way unless
    the run may fly its end: :func:`_auto_leg`)."""
    h = p[P_H]
    t_plant = iv[I_STEPS] * h
    if not t_event > t_plant:
        return True
    dt = t_event - t_plant
    if sv[S_CLIMBING] != 0.0 and x[2] + p[P_VMAX] * (dt + sv[S_LEAD]) >= sv[S_ALT_MAX]:
        return False  # the firmware checks the cap after every step
    pending = sv[S_PENDING] + dt
    n = int(math.floor((pending + _TIME_TOL_S) / h))
    drain = p[P_DRAIN]
    if n > 0 and not sv[S_BATTERY] - drain * (n + 1) > drain:
        return False  # it might empty on the way: a mode change, the plant's own path
    rest = pending - n * h
    rest = rest if rest > 0.0 else 0.0
    if n == 0:
        sv[S_PENDING] = rest
        return True
    w0, w1, w2 = sv[S_W0], sv[S_W1], sv[S_W2]
    turbulent = p[P_TURB_STD] > 0.0
    if turbulent:
        w0, w1 = w0 + sv[S_GUST0], w1 + sv[S_GUST1]
    if sv[S_MODE] == MODE_LANDED:
        _landed_leg(x, ring, iv, sv, p, n, h, bias_n)
        sv[S_PENDING] = rest
        _gust_step(iv, sv, p, n, h, gust_n)
        return True
    if sv[S_MODE] != MODE_FLYING:
        if not _auto_leg(x, ring, iv, sv, p, k, (w0, w1, w2), h, n, bias_n, leg):
            return False
        sv[S_PENDING] = rest
        _gust_step(iv, sv, p, n, h, gust_n)
        return True
    sv[S_PENDING] = rest
    pos = iv[I_POS_BIAS]
    iv[I_POS_BIAS] = pos + 3
    # flying_advance in place (all n steps fly: the battery was checked above)
    done, head, battery = _flying_steps(
        x, ring, iv[I_HEAD], sv[S_ROLL], sv[S_PITCH], sv[S_GAZ], sv[S_YAW], sv[S_HOLD] != 0.0,
        k, p, (w0, w1, w2), h, n, sv[S_BATTERY])
    x[8] = wrap_half_turn(x[8], math.pi)
    sv[S_YAW_BIAS], sv[S_VB0], sv[S_VB1] = advance_biases(
        n * h, bias_n[pos:pos + 3], sv[S_YAW_BIAS], sv[S_VB0], sv[S_VB1], p[P_YAW_DRIFT],
        p[P_YAW_WALK], p[P_VB_STD], p[P_VB_TAU])
    iv[I_HEAD] = head
    iv[I_STEPS] += done
    sv[S_BATTERY] = battery
    _gust_step(iv, sv, p, n, h, gust_n)
    return True


@njit(cache=True, **INNER_KERNEL)
def leg_coefficients(p):
    """The 13 coefficients of ``p[P_K:]`` as the tuple :func:`_leg` takes (read once a run:
    ``lockstep_run``'s and ``wire_step.wire_run``'s)."""
    return (p[P_K], p[P_K + 1], p[P_K + 2], p[P_K + 3], p[P_K + 4], p[P_K + 5], p[P_K + 6],
            p[P_K + 7], p[P_K + 8], p[P_K + 9], p[P_K + 10], p[P_K + 11], p[P_K + 12])


@njit(cache=True, **INNER_KERNEL)
def truth_out(x, out, iv, sv, h):
    """All legs done: the plant's truth now (AirframePlant.t_s, its battery and state) into
    ``out[O_T:]`` — a run's last write (``lockstep_run``'s and ``wire_step.wire_run``'s)."""
    out[O_T] = iv[I_STEPS] * h
    out[O_BATTERY] = sv[S_BATTERY]
    for i in range(10):
        out[O_STATE + i] = x[i]


@njit(cache=True, **OUTER_KERNEL)
def lockstep_run(x, ring, buf, bias_n, gust_n, mocap_n, nav_n):
    """The direct sensor path's advance to ``sv[S_T]`` (module docstring): the due mocap and
    navdata events (at most one of each, in time order, mocap first on a tie) into
    ``iv[I_KIND*]``/``out[O_EV_T*]``, then the legs to each and to the tick's time, each
    event's sample into ``out``. ``iv[I_DONE]``: the legs done (events, then the last); the
    rest is the Python path's — or −1, nothing done, if a block of normals has fewer left
    than a run may take (``NEED_*``: draw new blocks and call again). ``x`` (the state
    array), ``ring`` and the counters are updated in place; after all the legs, the truth
    then into ``out[O_T:]`` (the caller's truth reads). ``iv``, ``sv``, ``p``, ``out``: the
    parts of ``buf``."""
    out, iv = buf[B_OUT:B_IV], buf[B_IV:B_SV].view(np.int64)
    sv, p = buf[B_SV:B_P], buf[B_P:BUF_SIZE]
    if (iv[I_POS_BIAS] + NEED_BIAS > bias_n.shape[0] or iv[I_POS_MOCAP] + NEED_MOCAP
            > mocap_n.shape[0] or iv[I_POS_NAV] + NEED_NAV > nav_n.shape[0]
            or (p[P_TURB_STD] > 0.0 and iv[I_POS_GUST] + NEED_GUST > gust_n.shape[0])):
        iv[I_DONE] = -1
        return
    k = leg_coefficients(p)
    t_s = sv[S_T]
    mocap_period, nav_period = p[P_MOCAP_PERIOD], p[P_NAV_PERIOD]
    k_mocap = math.floor((t_s - p[P_MOCAP_LATENCY]) / mocap_period + 1e-9)
    k_nav = math.floor(t_s / nav_period + 1e-9)
    n_events = 0
    t_mocap = t_nav = 0.0
    has_mocap = k_mocap >= iv[I_NEXT_MOCAP]
    if has_mocap:
        t_mocap = k_mocap * mocap_period
        iv[I_NEXT_MOCAP] = k_mocap + 1
    has_nav = k_nav >= iv[I_NEXT_NAV]
    if has_nav:
        t_nav = k_nav * nav_period
        iv[I_NEXT_NAV] = k_nav + 1
    if has_mocap and has_nav:  # sorted((t, kind)): the mocap frame first on a tie
        if t_nav < t_mocap:
            iv[I_KIND0], out[O_EV_T0], iv[I_KIND1], out[O_EV_T1] = NAV, t_nav, MOCAP, t_mocap
        else:
            iv[I_KIND0], out[O_EV_T0], iv[I_KIND1], out[O_EV_T1] = MOCAP, t_mocap, NAV, t_nav
        n_events = 2
    elif has_mocap:
        iv[I_KIND0], out[O_EV_T0] = MOCAP, t_mocap
        n_events = 1
    elif has_nav:
        iv[I_KIND0], out[O_EV_T0] = NAV, t_nav
        n_events = 1
    iv[I_EVENTS] = n_events
    iv[I_DONE] = 0
    iv[I_CHANGED] = -1
    out[O_LAST_NOW] = math.nan
    h = p[P_H]
    for i in range(n_events + 1):
        if i < n_events:
            kind = iv[I_KIND0 + i]
            t_event = out[O_EV_T0 + i]
        else:
            kind = -1
            t_event = t_s
        ran = t_event > iv[I_STEPS] * h
        if not _leg(x, ring, iv, sv, p, k, bias_n, gust_n, t_event, i):
            return
        if ran:
            out[O_LAST_NOW] = t_event
        if kind == MOCAP:
            pos = iv[I_POS_MOCAP]
            iv[I_POS_MOCAP] = pos + 6
            out[O_POSE] = iv[I_STEPS] * h
            _mocap_pose(x, p[P_SP], p[P_SA], mocap_n[pos:pos + 6], out[O_POSE:O_NAV])
        elif kind == NAV:
            pos = iv[I_POS_NAV]
            iv[I_POS_NAV] = pos + 7
            out[O_NAV] = iv[I_STEPS] * h
            out[O_NAV + 1] = sv[S_BATTERY]
            _navdata(x, sv, p, nav_n[pos:pos + 7], out[O_NAV:O_EV_T0])
            if sv[S_MODE] == MODE_LANDED:  # motors off: no altitude, no speeds
                for j in range(5, 9):
                    out[O_NAV + j] = 0.0
        iv[I_DONE] = i + 1
    truth_out(x, out, iv, sv, h)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
