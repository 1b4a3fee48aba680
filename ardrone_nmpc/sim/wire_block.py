"""The wire sensor path's quiet ticks in a block of ticks: a sensor-fault flight's usual tick
as numbers, for ``runtime/lockstep_block``'s blocks.

A flight with a fault on the sensors' bytes sends every mocap frame and navdata packet
through the wire (``sim/sensors.py``); outside the faults' windows a tick's legs and draws
are one compiled call (``sim/wire_step.wire_run``, ``sim/quiet_wire.QuietWire``) and its
frames and packets are received by the links in Python. Here those ticks fly in blocks:
:func:`drone_legs` is :func:`~ardrone_nmpc.sim.drone_block.drone_legs` for the wire — the
tick's run by ``wire_run``, each packet's state word and demo sample as its receiver
decodes it (``wire_step.navdata_packets``), and what the links hold after the tick worked
out from the block's events: the newest frame arrived (its pose through the wire's mm and
back, the heading of its angles) and the newest packet. ``tick_block``'s twin with this
module in ``drone_block``'s place (``runtime/lockstep_block.tick_block_wire``) flies them.

The links themselves stay Python's: every event of the block is kept in ``d``'s rows
(``W_*``) and, after the block, :func:`sent` sends each frame and packet as
the quiet tick does and the sampler receives them (``LockstepSensors.deliver``) — the
same calls in the same order, a block's frames in one bulk receipt —, so the links' state
is theirs. Whenever the numbers could differ from what the links would hold — a packet
the numbers do not stand for, alarm bits that change, a frame the freshness rules would
judge (zero, not finite, a repeat) — the tick ends the block after its legs and the
Python tick goes on from the links' own state.
"""

from __future__ import annotations

import math
import struct

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.protocol.mocap import rotation_heading_rad
from ardrone_nmpc.protocol.navdata import DroneState
from ardrone_nmpc.sim import drone_block as db
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim import wire_step as ws
from ardrone_nmpc.sim.drone_block import (  # noqa: F401 (what tick_block reads of its db)
    D_BATTERY, D_CMD_GAZ, D_CMD_PITCH, D_CMD_ROLL, D_CMD_YAW, D_COMWDG_S, D_LAST_CMD_T,
    D_LATCHED, D_LATENCY, D_NAV_PITCH, D_NAV_ROLL, D_NAV_STATE, D_NAV_T, D_NAV_VX, D_NAV_VY,
    D_POSE_RX, D_POSE_T, D_PSI, D_PX, D_PY, D_PZ, D_SIZE, D_T_NAV, D_T_POSE, LEGS_DONE,
    LEGS_NOT_QUIET, LEGS_PARTIAL, LEGS_SHORT, drone_command, set_run_inputs, watchdog_due)
from ardrone_nmpc.sim.drone_firmware import _PROGRESSIVE
from ardrone_nmpc.sim.faults import FaultSchedule
from ardrone_nmpc.sim.sensors import ObjectFrame

__all__ = ["W_ROWS", "drone_legs", "normals_short", "quiet_until_s", "row_capacity", "sent",
           "wire_block_entry", "wire_d"]

# d's wire part, after drone_block's numbers: the state word of the firmware's status at
# the block's entry (no silence, no low battery, no com-watchdog bit: sim/quiet_wire's
# _status) and its ctrl_state; the alarm bits the controller's call was entered with (a
# packet showing others ends the block) and their mask (safety's); the low-battery
# threshold (%); the rows used, the first row of a frame not yet received, the rows kept
# from the entry (frames in transit: their arrival in EV_T), the rows' capacity; the last
# run's time, whether its tick began latched (0/1) and whether it did all its legs (0/1);
# the last frame's six wire values (mm, rad: a repeat's test; NaN: none)
(W_STATE, W_CTRL, W_BITS, W_ALARM, W_VBAT_LOW, W_N, W_RX, W_N0, W_CAP, W_T_RUN, W_LATCHED0,
 W_WHOLE, W_LAST) = range(D_SIZE, D_SIZE + 13)
W_ROWS = W_LAST + 6  # then the rows (wire_step's ev rows, EV_WIDTH numbers each)
_EV = ws.EV_WIDTH
_MM_PER_M = 1000.0
_POSE_BITS = struct.Struct("<6d")  # (links/mocap_source's: a pose's values as its bytes)
_BOOTSTRAP_BIT = int(DroneState.NAVDATA_BOOTSTRAP)
_COM_WATCHDOG = int(DroneState.COM_WATCHDOG)
_TICKS_OF_NORMALS = 16  # (refilled for as many ticks as the short one: fewer refills)
_MARGIN_S = 1e-6  # (a tick's experiment time and the faults' clock: rounded apart)
_SCAN_FRAMES = 512  # frames a dropout is asked of ahead (~5 s at 100 Hz)


def row_capacity(sensors, n_max: int, period_s: float) -> int:
    """Rows for the frames and packets of ``n_max`` of the wire's ticks of ``period_s`` and
    the frames on their way at the first."""
    per_tick = (math.ceil(period_s / sensors.mocap_period_s)
                + math.ceil(period_s / sensors.nav_period_s) + 2)
    in_transit = 2 * (math.ceil(sensors.mocap_latency_s / sensors.mocap_period_s) + 2)
    return n_max * per_tick + in_transit


def wire_d(cap: int) -> np.ndarray:
    """A ``d`` for blocks of the wire's ticks with room for ``cap`` events."""
    d = np.zeros(W_ROWS + cap * _EV)
    d[W_CAP], d[W_WHOLE] = cap, 1.0
    return d


@njit(cache=True, **INNER_KERNEL)
def drone_legs(d, x, ring, buf, bias_n, gust_n, mocap_n, nav_n, t_s, mode, ends):
    """``drone_block.drone_legs`` of the wire (module docstring): its watchdog tests, the
    tick's run by ``wire_run`` with every event into ``d``'s rows, what the links hold after
    it — ``LEGS_*`` (``LEGS_PARTIAL`` too when the links' numbers are Python's to work
    out); nothing run when the rows have no room for the tick's events (LEGS_NOT_QUIET)."""
    if watchdog_due(d, t_s):
        return LEGS_NOT_QUIET  # a watchdog acts on the way: the Python path's
    if (d[D_CMD_ROLL] == 0.0 and d[D_CMD_PITCH] == 0.0 and d[D_CMD_GAZ] == 0.0
            and d[D_CMD_YAW] == 0.0):
        return LEGS_NOT_QUIET  # a PCMD of zeros: the status reports hovering
    sv, iv = buf[ks.B_SV:ks.B_P], buf[ks.B_IV:ks.B_SV].view(np.int64)
    out = buf[ks.B_OUT:ks.B_IV]
    n, cap = int(d[W_N]), int(d[W_CAP])
    rows = d[W_ROWS:W_ROWS + cap * _EV].reshape((cap, _EV))
    latched0 = d[D_LATCHED]
    set_run_inputs(d, sv, t_s, mode, ends)
    ws.wire_run(x, ring, buf, bias_n, gust_n, mocap_n, nav_n, rows[n:])
    done, n_events = iv[ks.I_DONE], iv[ks.I_EVENTS]
    if done < 0:
        return LEGS_NOT_QUIET if n + n_events + iv[ks.I_KIND0] > cap else LEGS_SHORT
    taken = n_events if done > n_events else done
    # each packet as its receiver decodes it: the status's word, the com-watchdog bit as
    # the tick began (latched) or by the packet's time (a command clears it), the battery's
    word = int(d[W_STATE]) | (_COM_WATCHDOG if latched0 != 0.0 else 0)
    from_t = d[D_LAST_CMD_T] if latched0 == 0.0 else math.inf
    ws.navdata_packets(rows[n:], taken, word, from_t, d[D_COMWDG_S], d[W_VBAT_LOW])
    d[W_N], d[W_T_RUN], d[W_LATCHED0] = n + taken, t_s, latched0
    usual = _links_hold(d, rows, n, n + taken, t_s)
    now = out[ks.O_LAST_NOW]
    if now == now and now - d[D_LAST_CMD_T] > d[D_COMWDG_S]:
        d[D_LATCHED] = 1.0
    d[W_WHOLE] = 1.0 if done > n_events else 0.0
    if done <= n_events or iv[ks.I_CHANGED] >= 0 or not usual:
        return LEGS_PARTIAL
    return LEGS_DONE


@njit(cache=True, **INNER_KERNEL)
def _links_hold(d, rows, lo, hi, t_s):
    """What the links hold at ``t_s`` after the tick's events ``rows[lo:hi]`` (into ``d``'s
    samples): the newest packet of the tick, the newest frame arrived — False where the
    Python receipt may judge otherwise (module docstring)."""
    usual = True
    bits, alarm = int(d[W_BITS]), int(d[W_ALARM])
    for i in range(lo, hi):  # the tick's packets (they arrive when sent: by t_s)
        row = rows[i]
        if row[ws.EV_KIND] != ks.NAV:
            continue
        if row[ws.EV_OK] == 0.0 or (int(row[ws.EV_STATE]) & alarm) != bits:
            usual = False
        demo = row[ws.EV_DEMO:]
        d[D_T_NAV], d[D_NAV_T], d[D_BATTERY] = row[ws.EV_T], row[ws.EV_T], demo[0]
        d[D_NAV_ROLL], d[D_NAV_PITCH] = demo[1], demo[2]
        d[D_NAV_VX], d[D_NAV_VY], d[D_NAV_STATE] = demo[5], demo[6], row[ws.EV_STATE]
    j, n0, latency = int(d[W_RX]), int(d[W_N0]), d[D_LATENCY]
    last = d[W_LAST:W_LAST + 6]
    while j < hi:  # the frames arrived by t_s, in their order
        row = rows[j]
        if row[ws.EV_KIND] != ks.MOCAP:
            j += 1
            continue
        arrival = row[ws.EV_T] if j < n0 else row[ws.EV_T] + latency
        if not arrival <= t_s + 1e-12:  # (the receipt's test)
            break
        s = row[ws.EV_SAMPLE:]
        mx, my, mz = s[1] * _MM_PER_M, s[2] * _MM_PER_M, s[3] * _MM_PER_M
        fresh = ((mx != 0.0 or my != 0.0 or mz != 0.0 or s[4] != 0.0 or s[5] != 0.0
                  or s[6] != 0.0) and math.isfinite(mx) and math.isfinite(my)
                 and math.isfinite(mz) and math.isfinite(s[4]) and math.isfinite(s[5])
                 and math.isfinite(s[6]))
        if not fresh or (mx == last[0] and my == last[1] and mz == last[2]
                         and s[4] == last[3] and s[5] == last[4] and s[6] == last[5]):
            usual = False  # (the freshness rules': the receipt's to judge)
        last[0], last[1], last[2], last[3], last[4], last[5] = mx, my, mz, s[4], s[5], s[6]
        d[D_T_POSE], d[D_POSE_RX], d[D_POSE_T] = row[ws.EV_T], arrival, arrival
        d[D_PX], d[D_PY], d[D_PZ] = mx / _MM_PER_M, my / _MM_PER_M, mz / _MM_PER_M
        d[D_PSI] = s[7]  # (rotation_heading_rad of its angles: _mocap_pose's)
        j += 1
    d[W_RX] = j
    return usual


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py


# ---------------------------------------------------------------------- the Python side
_FLYING = FlightMode.FLYING
_DROPPED = FaultSchedule.mocap_dropped  # (a schedule's own: asked of each frame)
_SENDER = ("lockstep", 0)  # (the lockstep receiver's sender: MocapLink.feed_frame's)
_SEQ_ROOM = 1 << 20  # sequence numbers a chain of blocks may take before a wrap is near


def wire_block_entry(legs, d: np.ndarray, seq: int) -> bool:
    """``d`` filled for a block of the wire's ticks from the next (``drone_block.
    block_entry``'s numbers, then ``W_*``: the frames in transit as the rows kept) — or
    False, nothing written, unless the next tick is one it flies: the quiet tick's
    (``sim/quiet_wire.QuietWire``) of a FLYING plant, its frames sent as numbers and its
    packets as :class:`~ardrone_nmpc.sim.sensors.QuietPacket`, nothing but such frames on
    their way, the mocap link locked on the sampler, numbers that accept every frame's and
    packet's sequence, the held samples of the kinds the rows hold."""
    sensors, fw = legs.sensors, legs.firmware
    quiet, mocap = sensors._quiet, sensors.mocap
    if not (quiet is not None and quiet.enabled and legs.plant._mode is _FLYING
            and quiet.frames_as_numbers() and not sensors._arrived
            and sensors.receives_quiet_packets()
            and fw.comwdg_clear == "any" and not fw.config.bootstrap
            and fw.pcmd[0] & _PROGRESSIVE and fw.moving and mocap._sender == _SENDER
            and mocap.object_name not in mocap.other_objects
            and mocap.__class__ is _mocap_link_class() and not quiet.faults.holds_datagrams()
            and db._quiet(legs, seq)):
        return False
    in_transit = _queued_frames(sensors)
    if in_transit is None:
        return False  # (a datagram of the Python path's on its way)
    state, ctrl_state, demo_sent = quiet._status(fw)
    if state & _BOOTSTRAP_BIT or not demo_sent:
        return False
    pose, pose_rx = mocap.latest()
    nav = sensors.nav
    if not (pose is not None and nav is not None and nav.mode is _FLYING
            and nav.state_bits is not None and _floats(pose.t_s, pose.psi_rad, pose_rx,
                                                       sensors.nav_rx_t_s, nav.t_s,
                                                       nav.battery_pct, nav.roll_deg,
                                                       nav.pitch_deg, nav.vx_body_mps,
                                                       nav.vy_body_mps)):
        return False
    first = (in_transit[0][1] if in_transit
             else int(legs.iv[ks.I_NEXT_MOCAP]) & 0xFFFFFFFF)
    last_frame, last_packet = mocap.stats._last_seq, sensors.nav_stats._last_seq
    if not (first < 0xFFFFFFFF - _SEQ_ROOM and fw.nav_seq < 0xFFFFFFFF - _SEQ_ROOM
            and (last_frame is None or last_frame < first)
            and (last_packet is None or last_packet <= fw.nav_seq)
            and len(in_transit) < int(d[W_CAP]) // 2):
        return False
    from ardrone_nmpc.safety import ALARM_BITS  # (the controller's mask)

    px, py, pz = pose.position_m.tolist()
    db._fill(legs, d, (pose_rx, pose.t_s, px, py, pz, pose.psi_rad, 0.0, sensors.nav_rx_t_s,
                       nav.t_s, nav.battery_pct, nav.roll_deg, nav.pitch_deg,
                       nav.vx_body_mps, nav.vy_body_mps))
    # (the com-watchdog bit: the kernel's, as each tick begins and by each packet's time —
    # a latch the block's first command clears is not the word's)
    d[D_NAV_STATE], d[W_STATE], d[W_CTRL] = nav.state_bits, state & ~_COM_WATCHDOG, ctrl_state
    d[W_BITS], d[W_ALARM] = nav.state_bits & ALARM_BITS, ALARM_BITS
    d[W_VBAT_LOW] = fw.vbat_low_pct
    d[W_LAST:W_LAST + 6] = (math.nan if mocap._last_values is None
                            else _POSE_BITS.unpack(mocap._last_values))
    _kept(d, in_transit)
    return True


def _kept(d: np.ndarray, frames: list) -> None:
    """``d``'s rows: ``frames`` (in transit, queued already: ``(arrival, number, position_m,
    rotation_xyz_rad)`` in arrival order) as the rows kept, nothing received of them."""
    rows = d[W_ROWS:].reshape((int(d[W_CAP]), _EV))
    for i, (arrival, number, position_m, rotation) in enumerate(frames):
        row = rows[i]
        row[ws.EV_KIND], row[ws.EV_T], row[ws.EV_K] = ks.MOCAP, arrival, number
        s = row[ws.EV_SAMPLE:]
        s[1:4], s[4:7] = position_m, rotation
        s[7] = rotation_heading_rad(*(float(a) for a in rotation))
    d[W_N] = d[W_N0] = len(frames)
    d[W_RX] = 0


def sent(legs, d: np.ndarray) -> bool:
    """The frames and packets of the runs since the rows were kept (:func:`_kept`) sent as
    the quiet tick sends them and received by the sampler to the last run's time — but
    for a run that stopped before a leg (the tick's rest is the Python path's: the
    caller's, then the receipt); the frames still on their way kept as the rows. Whether
    the receipt waits for the tick's rest."""
    rest = d[W_WHOLE] == 0.0
    d[W_WHOLE] = 1.0  # (the run's rest handed over)
    n0, n = int(d[W_N0]), int(d[W_N])
    if n > n0:
        sensors, fw = legs.sensors, legs.firmware
        rows = d[W_ROWS + n0 * _EV:W_ROWS + n * _EV].reshape((n - n0, _EV)).tolist()
        ctrl_state = int(d[W_CTRL])
        latched = fw.comwdg_latched  # (a built packet's status: as the last run's tick began)
        fw.comwdg_latched = d[W_LATCHED0] != 0.0
        try:
            sensors._quiet.send(rows, _FLYING, d[W_T_RUN], (ctrl_state, ctrl_state >> 16))
        finally:
            fw.comwdg_latched = latched
    if rest:  # (a run stopped before a leg, its events or none: the caller's to go on)
        _kept(d, [])
        return True
    if n > n0:
        legs.sensors.deliver(d[W_T_RUN])
        _kept(d, _queued_frames(legs.sensors))
    return False


def normals_short(legs) -> tuple:
    """The normals of each block a run of the wire found short needs (``wire_run``'s
    counts of its tick's frames and packets, left in ``iv``)."""
    iv = legs.iv
    need = ws.normals_needed(int(iv[ks.I_EVENTS]), int(iv[ks.I_KIND0]))
    return tuple(_TICKS_OF_NORMALS * n for n in need)


def _queued_frames(sensors) -> list | None:
    """The sampler's datagrams on their way as frames ``(arrival, number, position_m,
    rotation_xyz_rad)`` in arrival order — None if one is not a quiet tick's frame."""
    queue = sensors._queue
    if not all(item[3].__class__ is ObjectFrame for item in queue):
        return None
    return [(arrival, item.number, item.position_m, item.rotation_xyz_rad)
            for arrival, _, _, item in sorted(queue)]


def _floats(*values) -> bool:
    """Every value a Python float (the kinds of numbers the per-tick path's rows hold)."""
    return all(v.__class__ is float for v in values)


def _mocap_link_class():
    from ardrone_nmpc.links.mocap_link import MocapLink  # (the wire's only)

    return MocapLink


def quiet_until_s(sensors, legs) -> float:
    """The experiment time before which the wire's ticks from the plant's time now are
    quiet (``sim/quiet_wire.QuietWire.quiet``'s tests: the faults' quiet time from now,
    a repeated dropout's bursts left out, then a dropout asked of each frame ahead —
    as far as :data:`_SCAN_FRAMES` of them), less a margin for the two clocks' rounding."""
    faults = sensors.drone.faults
    t_zero = sensors.t_zero_s
    bound = faults.quiet_until_s(legs.t_s() - t_zero, bursts_asked=True)
    schedule = faults.schedule
    if schedule.cfg.mocap_dropout is not None or type(schedule).mocap_dropped is not \
            _DROPPED:
        period = sensors.mocap_period_s
        k = int(legs.iv[ks.I_NEXT_MOCAP]) if legs.held() else sensors._next_mocap_k
        last = math.ceil((bound + t_zero) / period) if bound < math.inf else math.inf
        j = _first_dropped(sensors._quiet, schedule.mocap_dropped, k,
                           min(k + _SCAN_FRAMES, last), period, t_zero)
        bound = min(bound, j * period - t_zero)
    return bound - _MARGIN_S


def _first_dropped(quiet, dropped, k: int, end: int, period: float, t_zero: float) -> int:
    """The first frame from ``k`` before ``end`` that ``dropped`` drops, else ``end`` —
    each frame asked once (``quiet.dropout_scan``: the frames asked last, ``(first, next,
    dropped, t_zero)``: those from ``first`` before ``next`` not dropped, ``next`` dropped or
    not asked yet, on the faults' clock of ``t_zero``)."""
    first, j, hit, asked_t_zero = quiet.dropout_scan
    if not (first <= k <= j and asked_t_zero == t_zero):
        first, j, hit = k, k, False
    while not hit and j < end:
        if dropped(j * period - t_zero):
            hit = True
        else:
            j += 1
    quiet.dropout_scan = (first, j, hit, t_zero)
    return j
