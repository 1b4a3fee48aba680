"""The simulated drone's usual tick in compiled code, for a block of ticks run in one call.

:class:`~ardrone_nmpc.sim.lockstep_legs.CompiledLegs` makes a tick of the drone one compiled
call (:func:`~ardrone_nmpc.sim.sensor_step.lockstep_run`) with Python around it: the
firmware's tests before the run (its PCMD applied, no watchdog due), the samples made
objects after it, and the tick's PCMD (:meth:`CompiledLegs.command`). Here the same
tick of a quiet firmware is numbers only — :func:`drone_legs` and :func:`drone_command` —,
so that a caller compiled itself (``runtime/lockstep_block``) can fly ticks without
Python; what they leave is in ``d`` (indices ``D_*``), written back to the firmware, the
plant and the sampler by ``CompiledLegs.after_block``.

Each answers "not mine" (the ``LEGS_*`` codes, False) whenever the Python path's tick would
do anything else — a watchdog due, a leg the kernel leaves to Python, a capped climb or a
fraction the plant clips — and then changes nothing the Python path does not redo itself.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL
from ardrone_nmpc.sim import sensor_step as ks

__all__ = ["D_SIZE", "LEGS_DONE", "LEGS_NOT_QUIET", "LEGS_PARTIAL", "LEGS_SHORT",
           "drone_command", "drone_legs"]

# d: the plant's held command (roll, pitch, gaz, yaw, position hold 0/1); the firmware's
# applied command (its four fractions, and 1 while it is a progressive one of them); the
# last PCMD's fractions (its gaz: the cap's test); the time of its last accepted command;
# the com-watchdog bit (0/1) and whether any command clears it (0/1); its watchdog times,
# the cap's lead and height; the wind; the mocap latency; what the links hold — the newest
# pose (its event and receipt times, time, position, heading) and navdata sample (its
# time, battery, roll, pitch, forward and right speeds), 1 once a run of the block took
# one —; the PCMDs applied
(D_ROLL, D_PITCH, D_GAZ, D_YAW, D_HOLD, D_APP_ROLL, D_APP_PITCH, D_APP_GAZ, D_APP_YAW,
 D_APPLIED, D_CMD_ROLL, D_CMD_PITCH, D_CMD_GAZ, D_CMD_YAW, D_LAST_CMD_T, D_LATCHED,
 D_CLEAR_ANY, D_COMWDG_S, D_HOVER_AFTER_S, D_LINK_LOSS_S, D_LEAD_S, D_ALT_MAX, D_W0, D_W1,
 D_W2, D_LATENCY, D_T_POSE, D_POSE_RX, D_POSE_T, D_PX, D_PY, D_PZ, D_PSI, D_TOOK_POSE,
 D_T_NAV, D_NAV_T, D_BATTERY, D_NAV_ROLL, D_NAV_PITCH, D_NAV_VX, D_NAV_VY, D_TOOK_NAV,
 D_COMMANDS) = range(43)
D_SIZE = 43

#: :func:`drone_legs`' answers: the tick's legs all run; the firmware would do more than
#: the kernel (nothing run); a block of normals ran short (nothing run); the run left legs
#: or a mode change to the Python path (run: ``CompiledLegs``' own after-run code goes on)
LEGS_DONE, LEGS_NOT_QUIET, LEGS_SHORT, LEGS_PARTIAL = 0, 1, 2, 3


@njit(cache=True, **INNER_KERNEL)
def drone_legs(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s):
    """``CompiledLegs.run`` of a FLYING plant under a quiet firmware to plant time ``t_s``:
    its tests, the kernel's run, the com-watchdog bit after it (``LEGS_*``)."""
    silence = t_s - d[D_LAST_CMD_T]
    if silence > d[D_HOVER_AFTER_S] or silence > d[D_LINK_LOSS_S]:
        return LEGS_NOT_QUIET  # a watchdog acts on the way: the Python path's
    sv, iv = buf[ks.B_SV:ks.B_P], buf[ks.B_IV:ks.B_SV].view(np.int64)
    out = buf[ks.B_OUT:ks.B_IV]
    climbing = d[D_CMD_GAZ] > 0.0  # the firmware watches the cap
    sv[ks.S_ROLL], sv[ks.S_PITCH], sv[ks.S_GAZ] = d[D_ROLL], d[D_PITCH], d[D_GAZ]
    sv[ks.S_YAW], sv[ks.S_HOLD] = d[D_YAW], d[D_HOLD]
    sv[ks.S_CLIMBING] = 1.0 if climbing else 0.0
    sv[ks.S_LEAD] = d[D_LEAD_S] if climbing else 0.0
    sv[ks.S_ALT_MAX] = d[D_ALT_MAX] if climbing else 0.0
    sv[ks.S_W0], sv[ks.S_W1], sv[ks.S_W2] = d[D_W0], d[D_W1], d[D_W2]
    sv[ks.S_MODE], sv[ks.S_T], sv[ks.S_ENDS] = ks.MODE_FLYING, t_s, 0.0
    ks.lockstep_run(x, ring, buf, bias_n, gust_n, mocap_n, nav_n)
    done, n_events = iv[ks.I_DONE], iv[ks.I_EVENTS]
    if done < 0:
        return LEGS_SHORT
    taken = n_events if done > n_events else done
    for i in range(taken):  # what the links hold now (the samples' own arrays: out's)
        t_event = out[ks.O_EV_T0 + i]
        if iv[ks.I_KIND0 + i] == ks.MOCAP:
            d[D_T_POSE], d[D_POSE_RX] = t_event, t_event + d[D_LATENCY]
            d[D_POSE_T], d[D_PX] = out[ks.O_POSE], out[ks.O_POSE + 1]
            d[D_PY], d[D_PZ] = out[ks.O_POSE + 2], out[ks.O_POSE + 3]
            d[D_PSI], d[D_TOOK_POSE] = out[ks.O_POSE + 7], 1.0
        else:
            d[D_T_NAV], d[D_NAV_T] = t_event, out[ks.O_NAV]
            d[D_BATTERY], d[D_NAV_ROLL] = out[ks.O_NAV + 1], out[ks.O_NAV + 2]
            d[D_NAV_PITCH], d[D_NAV_VX] = out[ks.O_NAV + 3], out[ks.O_NAV + 6]
            d[D_NAV_VY], d[D_TOOK_NAV] = out[ks.O_NAV + 7], 1.0
    now = out[ks.O_LAST_NOW]
    if now == now and now - d[D_LAST_CMD_T] > d[D_COMWDG_S]:
        d[D_LATCHED] = 1.0
    if done <= n_events or iv[ks.I_CHANGED] >= 0:
        return LEGS_PARTIAL
    return LEGS_DONE


@njit(cache=True, **INNER_KERNEL)
def drone_command(d, out, roll, pitch, gaz, yaw):
    """``CompiledLegs.command`` of the tick's progressive PCMD after a run that did all its
    legs (``out``: its truth) — False, nothing changed, when the firmware caps the climb or
    the plant would clip a fraction (the Python path's)."""
    if not (-1.0 <= roll <= 1.0 and -1.0 <= pitch <= 1.0 and -1.0 <= gaz <= 1.0
            and -1.0 <= yaw <= 1.0):
        return False
    if gaz > 0.0:  # DroneFirmware._z_stop_m of the plant now
        vz = out[ks.O_STATE + 5]
        if out[ks.O_STATE + 2] + (vz if vz > 0.0 else 0.0) * d[D_LEAD_S] >= d[D_ALT_MAX]:
            return False
    d[D_LAST_CMD_T] = out[ks.O_T]
    if d[D_CLEAR_ANY] != 0.0:
        d[D_LATCHED] = 0.0
    d[D_CMD_ROLL], d[D_CMD_PITCH], d[D_CMD_GAZ], d[D_CMD_YAW] = roll, pitch, gaz, yaw
    if not (d[D_APPLIED] != 0.0 and roll == d[D_APP_ROLL] and pitch == d[D_APP_PITCH]
            and gaz == d[D_APP_GAZ] and yaw == d[D_APP_YAW]):
        d[D_ROLL], d[D_PITCH], d[D_GAZ], d[D_YAW], d[D_HOLD] = roll, pitch, gaz, yaw, 0.0
        d[D_APP_ROLL], d[D_APP_PITCH], d[D_APP_GAZ], d[D_APP_YAW] = roll, pitch, gaz, yaw
        d[D_APPLIED] = 1.0
    d[D_COMMANDS] += 1.0
    return True


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
