"""The simulated drone's usual tick in compiled code, for a block of ticks run in one call.

:class:`~ardrone_nmpc.sim.lockstep_legs.CompiledLegs` makes a tick of the drone one compiled
call (:func:`~ardrone_nmpc.sim.sensor_step.lockstep_run`) with Python around it: the
firmware's tests before the run (its PCMD applied, no watchdog due), the samples made
objects after it, and the tick's PCMD (:meth:`CompiledLegs.command`). Here the same
tick of a quiet firmware is numbers only — :func:`drone_legs` and :func:`drone_command` —,
so that a caller compiled itself (``runtime/lockstep_block``) can fly ticks without
Python; what they start from and leave is in ``d`` (indices ``D_*``): :func:`block_entry`
fills it from the firmware, the plant and the sampler, :func:`after_block` writes it back.

Each answers "not mine" (the ``LEGS_*`` codes, False) whenever the Python path's tick would
do anything else — a watchdog due, a leg the kernel leaves to Python, a capped climb or a
fraction the plant clips — and then changes nothing the Python path does not redo itself.
"""

from __future__ import annotations

import math
import struct

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim.drone_firmware import _HOVER_CMD, _PROGRESSIVE
from ardrone_nmpc.sim.lockstep_legs import _HOVER_APPLIED, _HOVER_PCMD

__all__ = ["D_SIZE", "LEGS_DONE", "LEGS_NOT_QUIET", "LEGS_PARTIAL", "LEGS_SHORT",
           "after_ascent", "after_block", "after_descent", "ascent_entry", "block_entry",
           "descent_entry", "drone_ascent", "drone_command", "drone_descent", "drone_legs",
           "set_run_inputs", "watchdog_due"]

# d: the plant's held command (roll, pitch, gaz, yaw, position hold 0/1); the firmware's
# applied command (its four fractions, and 1 while it is a progressive one of them); the
# last PCMD's fractions (its gaz: the cap's test); the time of its last accepted command;
# the com-watchdog bit (0/1) and whether any command clears it (0/1); its watchdog times,
# the cap's lead and height; the wind; the mocap latency; what the links hold — the newest
# pose (its event and receipt times, time, position, heading) and navdata sample (its
# time, battery, roll, pitch, forward and right speeds), 1 once a run of the block took
# one —; the PCMDs applied; the hover watchdog's flag (1: it dropped the held PCMD); the
# navdata sample's state word (NaN: none, the direct path's; sim/wire_block's)
(D_ROLL, D_PITCH, D_GAZ, D_YAW, D_HOLD, D_APP_ROLL, D_APP_PITCH, D_APP_GAZ, D_APP_YAW,
 D_APPLIED, D_CMD_ROLL, D_CMD_PITCH, D_CMD_GAZ, D_CMD_YAW, D_LAST_CMD_T, D_LATCHED,
 D_CLEAR_ANY, D_COMWDG_S, D_HOVER_AFTER_S, D_LINK_LOSS_S, D_LEAD_S, D_ALT_MAX, D_W0, D_W1,
 D_W2, D_LATENCY, D_T_POSE, D_POSE_RX, D_POSE_T, D_PX, D_PY, D_PZ, D_PSI, D_TOOK_POSE,
 D_T_NAV, D_NAV_T, D_BATTERY, D_NAV_ROLL, D_NAV_PITCH, D_NAV_VX, D_NAV_VY, D_TOOK_NAV,
 D_COMMANDS, D_LOST_COM_HOVER, D_NAV_STATE) = range(45)
D_SIZE = 45
_PUT_D = struct.Struct(f"{D_SIZE}d").pack_into  # d filled in one pack
_FLYING, _LANDING = FlightMode.FLYING, FlightMode.LANDING
_TAKING_OFF = FlightMode.TAKING_OFF
_NP_F64 = np.float64

#: :func:`drone_legs`' answers: the tick's legs all run; the firmware would do more than
#: the kernel (nothing run); a block of normals ran short (nothing run); the run left legs
#: or a mode change to the Python path (run: ``CompiledLegs``' own after-run code goes on)
LEGS_DONE, LEGS_NOT_QUIET, LEGS_SHORT, LEGS_PARTIAL = 0, 1, 2, 3


@njit(cache=True, **INNER_KERNEL)
def drone_legs(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s, mode, ends):
    """``CompiledLegs.run`` of a plant in the kernel's ``mode`` (FLYING, or LANDING: its
    touch-down flown if ``ends`` is 1, ``sv[S_ENDS]``) under a quiet firmware to plant time
    ``t_s``: its tests, the kernel's run, the com-watchdog bit after it (``LEGS_*``; a run
    that changed the mode is ``LEGS_PARTIAL``: the legs' after-run code shows it)."""
    if watchdog_due(d, t_s):
        return LEGS_NOT_QUIET  # a watchdog acts on the way: the Python path's
    return _run(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s, mode, ends)


@njit(cache=True, **INNER_KERNEL)
def watchdog_due(d, t_s):
    """The hover or the link-loss watchdog fires by plant time ``t_s`` (the silence since
    the last accepted command past its time)."""
    silence = t_s - d[D_LAST_CMD_T]
    return silence > d[D_HOVER_AFTER_S] or silence > d[D_LINK_LOSS_S]


@njit(cache=True, **INNER_KERNEL)
def _run(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s, mode, ends):
    """:func:`drone_legs` past its watchdog tests: the kernel's run, what the links hold
    after it, the com-watchdog bit (``LEGS_*``)."""
    iv = buf[ks.B_IV:ks.B_SV].view(np.int64)
    out = buf[ks.B_OUT:ks.B_IV]
    set_run_inputs(d, buf[ks.B_SV:ks.B_P], t_s, mode, ends)
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
def set_run_inputs(d, sv, t_s, mode, ends):
    """The run's inputs in ``sv`` (``CompiledLegs.pack``'s): the plant's held command, the
    cap's test while the last PCMD climbs, the wind, the mode, the time, ``ends``."""
    climbing = d[D_CMD_GAZ] > 0.0  # the firmware watches the cap
    sv[ks.S_ROLL], sv[ks.S_PITCH], sv[ks.S_GAZ] = d[D_ROLL], d[D_PITCH], d[D_GAZ]
    sv[ks.S_YAW], sv[ks.S_HOLD] = d[D_YAW], d[D_HOLD]
    sv[ks.S_CLIMBING] = 1.0 if climbing else 0.0
    sv[ks.S_LEAD] = d[D_LEAD_S] if climbing else 0.0
    sv[ks.S_ALT_MAX] = d[D_ALT_MAX] if climbing else 0.0
    sv[ks.S_W0], sv[ks.S_W1], sv[ks.S_W2] = d[D_W0], d[D_W1], d[D_W2]
    sv[ks.S_MODE], sv[ks.S_T], sv[ks.S_ENDS] = mode, t_s, ends


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


@njit(cache=True, **OUTER_KERNEL)
def drone_descent(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_first_s, period_s, k0,
                  n_max, deadline_s, ends):
    """Ticks ``k0`` … of a landing the runner waits out (plant time ``t_first_s +
    k·period_s``): each the legs' run of the LANDING plant, then the REF land and hover PCMD
    the link holds, accepted (``CompiledLegs.land_again``: traffic for the watchdogs, the
    com-watchdog bit cleared), until the plant's time reaches ``deadline_s`` (the tick that
    reaches it counted) — ``(ticks, LEGS_*)``: a tick not done whole is the Python path's
    (its legs ran, or not: the answer says which, as :func:`drone_legs`'; the touch-down's,
    flown if ``ends`` is 1, is such a tick)."""
    out = buf[ks.B_OUT:ks.B_IV]
    for i in range(n_max):
        status = drone_legs(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n,
                            t_first_s + (k0 + i) * period_s, ks.MODE_LANDING, ends)
        if status != LEGS_DONE:
            return i, status
        now = out[ks.O_T]
        d[D_LAST_CMD_T] = now
        if d[D_CLEAR_ANY] != 0.0:
            d[D_LATCHED] = 0.0
        d[D_COMMANDS] += 1.0
        if not now < deadline_s:
            return i + 1, LEGS_DONE
    return n_max, LEGS_DONE


@njit(cache=True, **OUTER_KERNEL)
def drone_ascent(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s, period_s, n_max,
                 timeout_s, ends):
    """Ticks of a take-off the runner waits out, each a run to the plant's time now (``t_s``
    at first) plus ``period_s`` (``CompiledLegs.run`` of the TAKING_OFF plant under the REF
    take-off and the hover it holds, no command sent): the hover watchdog's flags set as the
    run leaves them (the held PCMD a hover already: ``sim/drone_block.ascent_entry``), the
    climb's end flown if ``ends`` is 1 (not on a tick the hover watchdog is due), until the
    plant's time reaches ``timeout_s`` (the tick that reaches it counted) — ``(ticks,
    LEGS_*, its time, hover due, ends)``: a tick not done whole is the Python path's (its
    legs ran to that time, or not), the last two its run's."""
    out = buf[ks.B_OUT:ks.B_IV]
    for i in range(n_max):
        t_s += period_s
        silence = t_s - d[D_LAST_CMD_T]
        if silence > d[D_LINK_LOSS_S]:  # the link-loss watchdog: the Python path's
            return i, LEGS_NOT_QUIET, t_s, False, 0.0
        hover_due = silence > d[D_HOVER_AFTER_S] and d[D_LOST_COM_HOVER] == 0.0
        run_ends = 0.0 if hover_due else ends
        status = _run(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s,
                      ks.MODE_TAKING_OFF, run_ends)
        if status != LEGS_DONE:
            return i, status, t_s, hover_due, run_ends
        now = out[ks.O_LAST_NOW]
        if hover_due and now == now and now - d[D_LAST_CMD_T] > d[D_HOVER_AFTER_S]:
            d[D_LOST_COM_HOVER] = 1.0
        t_s = out[ks.O_T]
        if not t_s < timeout_s:
            return i + 1, LEGS_DONE, t_s, False, 0.0
    return n_max, LEGS_DONE, t_s, False, 0.0


flush_stale_caches(__name__)


# ---------------------------------------------------------------------- the Python side
def block_entry(legs, d: np.ndarray, seq: int, second_object: bool = False) -> bool:
    """``d`` filled from the compiled legs ``legs`` (``CompiledLegs``: their plant,
    firmware and sampler) for a block of ticks whose first PCMD is number ``seq`` — or
    False, nothing written, unless the next tick is one the block flies: ``legs.run``'s
    tick of a FLYING plant the navdata shows FLYING (:func:`_quiet`), a held PCMD that is a
    progressive one, no second object (unless the caller draws its frames:
    ``second_object``) — and samples of the kinds the kernel makes."""
    plant, fw, sensors = legs.plant, legs.firmware, legs.sensors
    if not (plant._mode is _FLYING and sensors._nav_mode is _FLYING
            and (second_object or sensors.target_cfg is None) and fw.pcmd[0] & _PROGRESSIVE
            and _quiet(legs, seq)):
        return False
    pose, nav = sensors.pose, sensors.nav
    if not (pose is not None and nav is not None and nav.mode is _FLYING
            and nav.state_bits is None and pose.t_s.__class__ is float
            and pose.psi_rad.__class__ is float and nav.t_s.__class__ is float
            and nav.battery_pct.__class__ is float and nav.roll_deg.__class__ is float
            and nav.pitch_deg.__class__ is float and nav.vx_body_mps.__class__ is _NP_F64
            and nav.vy_body_mps.__class__ is _NP_F64):
        return False  # (the kinds of cells the rows of a block's samples hold)
    px, py, pz = pose.position_m.tolist()
    _fill(legs, d, (sensors.pose_rx_t_s, pose.t_s, px, py, pz, pose.psi_rad, 0.0,
                    sensors.nav_rx_t_s, nav.t_s, nav.battery_pct, nav.roll_deg,
                    nav.pitch_deg, nav.vx_body_mps, nav.vy_body_mps))
    return True


def descent_entry(legs, d: np.ndarray, seq: int) -> bool:
    """``d`` filled for :func:`drone_descent` from ticks whose REF land is number ``seq``
    — or False, nothing written, unless the next tick is one it flies: ``legs.run``'s tick
    of a LANDING plant the navdata shows LANDING (:func:`_quiet`), the REF land and hover
    PCMD ``legs.land_again`` holds (the hover applied; REF land's flags, which it writes
    again)."""
    plant, fw, sensors = legs.plant, legs.firmware, legs.sensors
    if not (legs.lands_in and plant._mode is _LANDING and sensors._nav_mode is _LANDING
            and sensors.target_cfg is None and fw.applied == _HOVER_APPLIED
            and fw.pcmd is _HOVER_PCMD and not (fw.ref_start or fw.ref_emergency)
            and seq > fw.last_seq and _quiet(legs, seq)):
        return False
    _fill(legs, d, (math.nan,) * 14)  # (the samples: the sampler's)
    return True


def _quiet(legs, seq: int) -> bool:
    """:func:`_held`, no hover noted, and command number ``seq`` accepted."""
    fw = legs.firmware
    return not fw.lost_com_hover and (seq == 1 or seq > fw.last_seq) and _held(legs)


def _held(legs) -> bool:
    """The arrays hold the plant's state and its flight's parameters; a quiet firmware: its
    held PCMD applied, not capped, traffic seen, no link loss — the PCMDs
    ``legs.command``'s (a drone it stands in for: the ticks' faults are the caller's)."""
    plant, fw, sensors = legs.plant, legs.firmware, legs.sensors
    old = legs._p_key
    return (legs.stands_in and legs.live_out is not None
            and len(plant.__dict__) == legs._plant_len
            and len(sensors.__dict__) == legs._sensors_len
            and fw.pcmd is fw._applied_pcmd and not fw.alt_capped
            and fw.last_cmd_t is not None and not fw.link_lost
            and old and old[0] is plant.params and old[1] is plant.noise
            and old[2] is plant._trim_bias_rad and old[3] == plant._yaw_drift_sign)


def ascent_entry(legs, d: np.ndarray) -> bool:
    """``d`` filled for :func:`drone_ascent` — or False, nothing written, unless the next
    tick is one it flies: ``legs.run``'s tick of a TAKING_OFF plant the navdata shows
    TAKING_OFF (:func:`_held`), the held PCMD a hover applied (the REF take-off's: no
    climb the firmware caps, a hover watchdog that drops nothing)."""
    plant, fw, sensors = legs.plant, legs.firmware, legs.sensors
    if not (plant._mode is _TAKING_OFF and sensors._nav_mode is _TAKING_OFF
            and sensors.target_cfg is None and fw.applied == _HOVER_APPLIED
            and not fw.pcmd[0] & _PROGRESSIVE and _held(legs)):
        return False
    _fill(legs, d, (math.nan,) * 14)  # (the samples: the sampler's)
    return True


def _fill(legs, d: np.ndarray, links: tuple) -> None:
    """``d`` from the firmware's and the plant's state, ``links`` its samples' numbers (from
    ``D_POSE_RX`` to ``D_NAV_VY``), nothing taken or applied yet."""
    plant, fw = legs.plant, legs.firmware
    roll, pitch, gaz, yaw, hold = legs._saved["_current"]
    applied = fw.applied
    progressive = applied[4] is True
    w0, w1, w2 = plant.wind_mps.tolist()
    _PUT_D(d, 0, roll, pitch, gaz, yaw, 1.0 if hold else 0.0,
           *(applied[:4] if progressive else (0.0, 0.0, 0.0, 0.0)),
           1.0 if progressive else 0.0, *fw.pcmd[1:], fw.last_cmd_t,
           1.0 if fw.comwdg_latched else 0.0, 1.0 if fw.comwdg_clear == "any" else 0.0,
           fw.comwdg_s, fw.hover_after_s, fw.link_loss_s, fw._lead_s(),
           fw.config.altitude_max_m, w0, w1, w2, legs.sensors.mocap_latency_s, math.nan,
           *links[:6], 0.0, *links[7:], 0.0, 0.0, 1.0 if fw.lost_com_hover else 0.0,
           math.nan)


def after_block(legs, d: np.ndarray, seq: int, ran: bool) -> None:
    """What a block of ticks left in ``d`` and ``legs``' arrays, written back as the Python
    path's ticks would have left it: the firmware's state and counters after the PCMDs
    it applied (the last one numbered ``seq``), the plant's held command, the newest
    samples (``ran``: a run of the block did its legs or part of them)."""
    v = d.tolist()
    if _written_back(legs, v, 1, seq, _FLYING if ran else None):
        fw = legs.firmware
        fw.pcmd = fw._applied_pcmd = (_PROGRESSIVE, *v[D_CMD_ROLL:D_CMD_YAW + 1])
        fw.applied = (*v[D_APP_ROLL:D_APP_YAW + 1], True)
        legs._saved["_current"] = (*v[D_ROLL:D_YAW + 1], v[D_HOLD] != 0.0)


def after_descent(legs, d: np.ndarray, seq: int, ran: bool) -> None:
    """What :func:`drone_descent` left, written back as ``legs.land_again`` and the legs'
    runs would have: each tick's datagram (REF land, hover PCMD) counted and accepted, the
    last one's PCMD numbered ``seq``; the newest samples (``ran``: a run did legs)."""
    _written_back(legs, d.tolist(), 2, seq, _LANDING if ran else None)


def after_ascent(legs, d: np.ndarray, ran: bool) -> None:
    """What :func:`drone_ascent` left, written back as the legs' runs would have: the
    watchdogs' flags (the hover's: its held PCMD dropped for a hover), the newest samples
    (``ran``: a run did legs)."""
    v = d.tolist()
    _written_back(legs, v, 0, 0, _TAKING_OFF if ran else None)
    fw = legs.firmware
    if v[D_LOST_COM_HOVER] != 0.0 and not fw.lost_com_hover:
        fw.lost_com_hover = True
        fw.pcmd = fw._applied_pcmd = _HOVER_CMD


def _written_back(legs, v: list, per_datagram: int, seq: int, mode) -> bool:
    """What :func:`after_block` and :func:`after_descent` share (``v``: ``d``'s numbers):
    the com-watchdog bit; the datagrams of ``per_datagram`` commands accepted (counted,
    the last numbered ``seq``, the time of the last); the newest samples of a plant in
    ``mode`` (None: no run did legs). Whether any datagram was."""
    fw = legs.firmware
    fw.comwdg_latched = v[D_LATCHED] != 0.0
    n = int(v[D_COMMANDS])
    if n:
        c = legs.counters
        c.at_datagrams_in += n
        c.at_commands_in += per_datagram * n
        c.at_commands_applied += per_datagram * n
        fw.last_seq = seq
        fw.last_cmd_t = v[D_LAST_CMD_T]
    if mode is not None:
        legs.ran_block(v[D_T_POSE] if v[D_TOOK_POSE] else None,
                       v[D_T_NAV] if v[D_TOOK_NAV] else None, mode)
    return n > 0
