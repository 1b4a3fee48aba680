"""The wire sensor path's quiet tick of the simulated drone in one compiled call: the plant run
to every mocap frame's and navdata packet's time, each one's sample drawn on the way.

:meth:`LockstepSensors._advance_through_wire
<ardrone_nmpc.sim.sensors.LockstepSensors._advance_through_wire>` (a flight with a sensor
fault) sends every frame and packet: it runs the drone to each sampling time in turn —
mocap frames at ``k·T_mocap``, navdata packets at ``k·T_nav``, in time order, the frame first
on a tie — draws its pose or navdata sample there, and runs on to the tick's time. Where no
fault can act (:class:`~ardrone_nmpc.sim.quiet_wire.QuietWire` checks it) nothing but those
legs and draws decides what is sent, and :func:`wire_run` does them: the legs and the
samples are :func:`~ardrone_nmpc.sim.sensor_step.lockstep_run`'s (the same ``_leg``,
``_mocap_pose``, ``_navdata`` and arrays ``buf``), only the events differ — every one due,
not the newest of each stream. Each event's sample goes into a row of ``ev``; what a frame
or packet becomes on the wire (its bytes, its arrival, the links) stays the Python's.

The run stops before a leg the direct path's kernel would not fly (``iv[I_DONE]``: the events
whose legs and samples it did; their grid indices passed, the rest the Python path's); it
does nothing (``iv[I_DONE]`` −1) when ``ev`` or a block of normals is too short for the tick's
events (their counts in ``iv[I_EVENTS]`` and ``iv[I_KIND0]``: mocap frames, navdata packets).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import OUTER_KERNEL
from ardrone_nmpc.protocol.navdata import DroneState
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim.sensor_step import (_leg, _mocap_pose, _navdata, leg_coefficients,
                                          truth_out)

__all__ = ["wire_run", "navdata_packets", "EV_KIND", "EV_T", "EV_K", "EV_SAMPLE", "EV_OK",
           "EV_STATE", "EV_DEMO", "EV_WIDTH", "normals_needed"]

# a row of ev: the event's kind (ks.MOCAP, ks.NAV), its sampling time, its grid index, then
# its sample: the plant's time, and the pose (position, XYZ angles, ψ) or the navdata
# sample (battery, roll, pitch, yaw, altitude, forward, right, down) — out's layouts; then a
# navdata row's packet as its receiver reads it (navdata_packets): 1 if the numbers hold it,
# its state word, and its demo option's sample (battery as a whole %, roll, pitch, yaw
# unwrapped, altitude, forward, right, down: through the float32 / mm wire values)
EV_KIND, EV_T, EV_K, EV_SAMPLE = 0, 1, 2, 3
EV_OK = EV_SAMPLE + (ks.O_EV_T0 - ks.O_NAV)
EV_STATE, EV_DEMO = EV_OK + 1, EV_OK + 2
EV_WIDTH = EV_DEMO + 8
_COM_WATCHDOG, _VBAT_LOW = int(DroneState.COM_WATCHDOG), int(DroneState.VBAT_LOW)
_I32_MIN, _I32_MAX = -2.0 ** 31, 2.0 ** 31 - 1.0


@njit(cache=True)
def normals_needed(n_mocap, n_nav):
    """The normals a run of ``n_mocap`` frames and ``n_nav`` packets may take from each block
    (biases, gusts, poses, navdata): three and two a leg — one to each event and the last —,
    six a pose, seven a navdata sample."""
    legs = n_mocap + n_nav + 1
    return 3 * legs, 2 * legs, 6 * n_mocap, 7 * n_nav


@njit(cache=True, **OUTER_KERNEL)
def wire_run(x, ring, buf, bias_n, gust_n, mocap_n, nav_n, ev):
    """The wire path's advance to ``sv[S_T]`` (module docstring): every mocap frame and
    navdata packet due, a leg to each and its sample into ``ev``, then the leg to the tick's
    time. ``iv[I_DONE]``: the events done, one more if the last leg ran too (then the truth
    in ``out[O_T:]``, as ``lockstep_run`` leaves it) — or −1 (module docstring)."""
    out, iv = buf[ks.B_OUT:ks.B_IV], buf[ks.B_IV:ks.B_SV].view(np.int64)
    sv, p = buf[ks.B_SV:ks.B_P], buf[ks.B_P:ks.BUF_SIZE]
    t_s = sv[ks.S_T]
    mocap_period, nav_period = p[ks.P_MOCAP_PERIOD], p[ks.P_NAV_PERIOD]
    last_mocap = math.floor(t_s / mocap_period + 1e-9)  # the wire's grids (no latency:
    last_nav = math.floor(t_s / nav_period + 1e-9)      # a frame is sent when sampled)
    k_mocap, k_nav = iv[ks.I_NEXT_MOCAP], iv[ks.I_NEXT_NAV]
    n_mocap = last_mocap - k_mocap + 1 if last_mocap >= k_mocap else 0
    n_nav = last_nav - k_nav + 1 if last_nav >= k_nav else 0
    need_bias, need_gust, need_mocap, need_nav = normals_needed(n_mocap, n_nav)
    if (n_mocap + n_nav > ev.shape[0] or iv[ks.I_POS_BIAS] + need_bias > bias_n.shape[0]
            or iv[ks.I_POS_MOCAP] + need_mocap > mocap_n.shape[0]
            or iv[ks.I_POS_NAV] + need_nav > nav_n.shape[0]
            or (p[ks.P_TURB_STD] > 0.0 and iv[ks.I_POS_GUST] + need_gust > gust_n.shape[0])):
        iv[ks.I_DONE] = -1
        iv[ks.I_EVENTS], iv[ks.I_KIND0] = n_mocap, n_nav
        return
    k = leg_coefficients(p)
    n_events = n_mocap + n_nav
    iv[ks.I_EVENTS] = n_events
    iv[ks.I_DONE] = 0
    iv[ks.I_CHANGED] = -1
    out[ks.O_LAST_NOW] = math.nan
    h = p[ks.P_H]
    for i in range(n_events + 1):
        kind = -1
        t_event = t_s
        if i < n_events:  # sorted((t, kind, k)): the earlier, the frame first on a tie
            t_mocap = k_mocap * mocap_period
            t_nav = k_nav * nav_period
            if k_mocap <= last_mocap and (k_nav > last_nav or t_mocap <= t_nav):
                kind, t_event = ks.MOCAP, t_mocap
            else:
                kind, t_event = ks.NAV, t_nav
        ran = t_event > iv[ks.I_STEPS] * h
        if not _leg(x, ring, iv, sv, p, k, bias_n, gust_n, t_event, i):
            return
        if ran:
            out[ks.O_LAST_NOW] = t_event
        if kind >= 0:
            row = ev[i]
            row[EV_KIND], row[EV_T] = kind, t_event
            sample = row[EV_SAMPLE:]
            sample[0] = iv[ks.I_STEPS] * h
            if kind == ks.MOCAP:
                row[EV_K] = k_mocap
                k_mocap += 1
                iv[ks.I_NEXT_MOCAP] = k_mocap
                pos = iv[ks.I_POS_MOCAP]
                iv[ks.I_POS_MOCAP] = pos + 6
                _mocap_pose(x, p[ks.P_SP], p[ks.P_SA], mocap_n[pos:pos + 6], sample)
            else:
                row[EV_K] = k_nav
                k_nav += 1
                iv[ks.I_NEXT_NAV] = k_nav
                pos = iv[ks.I_POS_NAV]
                iv[ks.I_POS_NAV] = pos + 7
                sample[1] = sv[ks.S_BATTERY]
                _navdata(x, sv, p, nav_n[pos:pos + 7], sample)
        iv[ks.I_DONE] = i + 1
    truth_out(x, out, iv, sv, h)  # all legs done: the plant's truth now


@njit(cache=True, **OUTER_KERNEL)
def navdata_packets(ev, n, state, watchdog_from_t, comwdg_s, vbat_low_pct):
    """The packet of each navdata row of ``ev[:n]`` as a receiver decodes it (``EV_OK:``,
    ``DroneFirmware.packet_of``'s and ``decode_navdata``'s numbers): its state word — the
    tick's ``state`` with the com-watchdog bit once ``t − watchdog_from_t > comwdg_s`` (the
    bit a command clears, by each packet's time; +inf: the tick's alone) and the low-battery
    bit below ``vbat_low_pct`` — and the demo option's sample: the battery a whole percent
    in 0–100, the angles and speeds ×1000 through float32 and back, the altitude through
    whole mm (rounded half to even, as Python's ``round``). ``EV_OK`` 0: a value the wire's
    checks would refuse or carry as no finite number (its packet the Python's)."""
    for i in range(n):
        row = ev[i]
        if row[EV_KIND] != ks.NAV:
            continue
        sample, demo = row[EV_SAMPLE:], row[EV_DEMO:]
        battery = sample[1]
        word = state
        if row[EV_T] - watchdog_from_t > comwdg_s:
            word |= _COM_WATCHDOG
        if battery < vbat_low_pct:
            word |= _VBAT_LOW
        row[EV_STATE] = word
        whole = battery if battery > 0.0 else 0.0  # (max(0, ·), then min(100, ·): a NaN 0)
        demo[0] = np.rint(whole if whole < 100.0 else 100.0)
        ok = True
        for j in (1, 2, 3, 5, 6, 7):  # roll, pitch, yaw, forward, right, down
            wire = sample[j + 1] * 1000.0
            single = np.float32(wire)
            ok = ok and math.isfinite(wire) and math.isfinite(single)
            demo[j] = np.float64(single) / 1000.0
        mm = np.rint(sample[5] * 1000.0) + 0.0  # (Python's round: an int, no −0)
        ok = ok and math.isfinite(mm) and _I32_MIN <= mm <= _I32_MAX
        demo[4] = mm / 1000.0
        row[EV_OK] = 1.0 if ok else 0.0


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
