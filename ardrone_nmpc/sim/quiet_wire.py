"""The wire sensor path's ticks at which no fault can act, flown by one compiled call.

A flight with a sensor fault sends every mocap frame and navdata packet through the wire
(:class:`~ardrone_nmpc.sim.sensors.LockstepSensors`: the drone run to each one's sampling
time in Python, its sample drawn, the faults asked, the datagram queued and handed to the
receiving links). Outside the faults' windows the faults decide nothing: they draw nothing,
count nothing and hand the datagram on as it is (``ServerFaults.quiet_until_s``). There
:class:`QuietWire` flies the tick's legs and draws its samples in one compiled call
(:func:`~ardrone_nmpc.sim.wire_step.wire_run`, on the arrays of the direct path's
:class:`~ardrone_nmpc.sim.lockstep_legs.CompiledLegs`), then sends each frame and packet as
the Python path would — the frame built from the pose drawn, the packet as the numbers
its receipt reads of the decoded packet (:func:`~ardrone_nmpc.sim.wire_step.navdata_packets`:
the state word, the demo sample through the float32 / mm codec; ``QuietPacket``, received
by ``LockstepSensors._receive_quiet``), or built by the firmware from the sample drawn
where those cannot stand in (:meth:`DroneFirmware.packet_of
<ardrone_nmpc.sim.drone_firmware.DroneFirmware.packet_of>`: the packet as its bytes decode,
handed over without them as the frames are) — into the same queue, in the same order; the
receiving links are the Python path's, but a frame goes as its numbers (``LockstepSensors.
push_object_frame``: nothing reads the frame object) and is received with the other such
frames arrived in a row in one bulk call (``MocapLink.feed_object_frames``).

A tick is flown so when the Python path's would do nothing but those legs and draws:

* no fault acts at any of its events (the faults' quiet time lies past the tick; a
  dropout's own test at each of its frames: the spans bound its window by a rounded end,
  and a repeated one's bursts by none), and neither stream's disorder holds a datagram back;
* the plant airborne — FLYING, or taking off or landing, its end left to the Python path
  (the kernel stops before the leg that ends it) — on a dynamics the kernel flies
  (``CompiledLegs.eligible``), the navdata out of bootstrap;
* a firmware that changes nothing by the tick's time but its com-watchdog bit: its PCMD
  applied and not capped, neither the hover nor the link-loss watchdog firing — so the state
  bits it reports are the tick's first at every packet but for the battery's, which each
  packet's own sample gives (:meth:`DroneFirmware.packet_of
  <ardrone_nmpc.sim.drone_firmware.DroneFirmware.packet_of>`), and the com watchdog's: a
  firmware whose bit any command clears (``comwdg_clear`` "any") reports it set once the
  silence is past ``comwdg_s``, latched or not, so each packet's time gives it too (the bit
  latched after the run, as ``CompiledLegs`` latches it; another firmware flies a tick that
  latches it on the Python path). With a command every 65 ms and a 50 ms watchdog, most
  ticks latch it.

The kernel stops before a leg it does not fly (a climb near the altitude cap, an emptying
battery): the events it did are sent, the Python path goes on with the rest.
"""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_deg
from ardrone_nmpc.core.types import FlightMode, NavdataSample
from ardrone_nmpc.protocol.navdata import DroneState, OptionTag
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim import wire_step as ws
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim.drone_firmware import DroneFirmware
from ardrone_nmpc.sim.fault_injection import NO_MOCAP_FAULT, ServerFaults
from ardrone_nmpc.sim.faults import FaultSchedule
from ardrone_nmpc.sim.held_state import overrides_none

__all__ = ["QuietWire"]

_FLYING, _TAKING_OFF, _LANDING = FlightMode.FLYING, FlightMode.TAKING_OFF, FlightMode.LANDING
_MOCAP = ks.MOCAP
_T, _K, _S = ws.EV_T, ws.EV_K, ws.EV_SAMPLE
_N_EVENTS = 16  # ev's rows to start with (grown to a tick's events)
_OK, _STATE, _DEMO = ws.EV_OK, ws.EV_STATE, ws.EV_DEMO
_BOOTSTRAP_BIT, _DEMO_OPTION = int(DroneState.NAVDATA_BOOTSTRAP), 1 << OptionTag.DEMO
#: (state word, ctrl_state) → (the DroneState, the flight mode navdata_sample_of reads)
_DECODED: dict = {}
_DROPPED = FaultSchedule.mocap_dropped  # (a schedule's own: asked of each frame)
#: What a quiet tick does in the drone's, firmware's and faults' place (besides the legs':
#: CompiledLegs.eligible): a class overriding one of these keeps the Python wire path
_REPLACED = ((SimulatedDrone, ("navdata_datagrams",)),
             (DroneFirmware, ("packet", "packet_of", "status", "status_inputs", "moving",
                              "battery_low")),
             (ServerFaults, ("mocap_frame", "mocap_datagrams", "navdata_lost",
                             "navdata_datagrams", "quiet_until_s", "holds_datagrams")))


class _Pose:
    """What :func:`~ardrone_nmpc.sim.mocap_server.frame_items` reads of a pose drawn."""

    __slots__ = ("position_m", "rotation_xyz_rad")

    def __init__(self, position_m, rotation_xyz_rad) -> None:
        self.position_m, self.rotation_xyz_rad = position_m, rotation_xyz_rad


class QuietWire:
    """The quiet ticks of a wire sampler ``sensors`` (module docstring), on ``legs``: a
    :class:`~ardrone_nmpc.sim.lockstep_legs.CompiledLegs` of its plant and firmware."""

    enabled = True  # (False: every tick the Python path's — the tests' reference)

    def __init__(self, sensors, legs) -> None:
        self.sensors, self.legs = sensors, legs
        self.faults = sensors.drone.faults
        self.schedule = self.faults.schedule
        self.ev = np.zeros((_N_EVENTS, ws.EV_WIDTH))
        self._status_key, self._status_of = None, None  # (_status's)
        self.dropout_scan = (0, 0, False, math.nan)  # (sim/wire_block's: the frames asked)

    @staticmethod
    def eligible(drone) -> bool:
        """A drone (its firmware, its faults) whose classes override none of what a quiet
        tick does in their place."""
        for base, names in _REPLACED:
            obj = (drone if base is SimulatedDrone else
                   drone.firmware if base is DroneFirmware else drone.faults)
            if not overrides_none(obj, base, names):
                return False
        return True

    def quiet(self, t_s: float) -> bool:
        """No fault can act on the sensors' datagrams from the plant's time to ``t_s``."""
        sensors, faults, legs = self.sensors, self.faults, self.legs
        t_zero = sensors.t_zero_s
        t_from = legs.t_s() - t_zero
        if (not faults.quiet_until_s(t_from, bursts_asked=True) > t_s - t_zero
                or faults.holds_datagrams()):
            return False
        # a dropout asked of each frame (its window ends at start + duration as its phase
        # says, not at the span's rounded sum; a repeated one's bursts come for ever); the
        # grid's next index held by the legs: read without releasing them
        schedule = self.schedule
        if schedule.cfg.mocap_dropout is None and type(schedule).mocap_dropped is _DROPPED:
            return True  # (no dropout: no frame of the tick's is dropped)
        period, dropped = sensors.mocap_period_s, schedule.mocap_dropped
        k = int(legs.iv[ks.I_NEXT_MOCAP]) if legs.held() else sensors._next_mocap_k
        for k in range(k, math.floor(t_s / period + 1e-9) + 1):
            if dropped(k * period - t_zero):
                return False
        return True

    def run(self, t_s: float) -> bool:
        """The tick to ``t_s`` flown (module docstring), as far as the kernel went: True if
        it ran all the legs, False if the Python path is to fly the tick (or its rest)."""
        legs, fw, plant = self.legs, self.legs.firmware, self.legs.plant
        mode = plant._mode
        if (not self.enabled or not (mode is _FLYING or mode is _TAKING_OFF or mode is _LANDING)
                or fw.config.bootstrap):
            return False
        pcmd, last_cmd_t = fw.pcmd, fw.last_cmd_t
        if pcmd is not fw._applied_pcmd or fw.alt_capped or last_cmd_t is None:
            return False
        silence = t_s - last_cmd_t  # (it only grows within the tick: none fires earlier)
        if ((silence > fw.comwdg_s and not fw.comwdg_latched and fw.comwdg_clear != "any")
                or (silence > fw.hover_after_s and not fw.lost_com_hover)
                or (silence > fw.link_loss_s and not fw.link_lost)):
            return False
        if not self.quiet(t_s):
            return False
        legs.pack(t_s, pcmd, mode, 0.0)  # (a take-off's or landing's end: the Python's)
        while True:
            ws.wire_run(*legs._args, self.ev)
            iv = legs.iv
            if iv[ks.I_DONE] >= 0:
                break
            n_mocap, n_nav = int(iv[ks.I_EVENTS]), int(iv[ks.I_KIND0])
            if n_mocap + n_nav > self.ev.shape[0]:
                self.ev = np.zeros((2 * (n_mocap + n_nav), ws.EV_WIDTH))
            legs.refill(ws.normals_needed(n_mocap, n_nav))
        done, n_events = int(iv[ks.I_DONE]), int(iv[ks.I_EVENTS])
        self.send(self.ev[:min(done, n_events)].tolist(), mode, t_s)  # (the bit: the start's)
        fw.latch_after_run(legs.out[ks.O_LAST_NOW])  # (as the legs left it)
        legs.ran_block(None, None, mode)  # what a tick reads of the run (no sample taken)
        if done <= n_events:  # legs left: the Python path's
            legs.release()
        return done > n_events

    def send(self, rows: list, mode, t_s: float, receipt: tuple | None = None) -> None:
        """The frames and packets of the events the run did (``ev``'s rows, as lists; the
        plant in ``mode`` all along) in the tick to ``t_s``, as the Python path sends them;
        ``receipt``: :meth:`_receipt`'s answer, the rows' packets worked out already (a
        block's: ``sim/wire_block``) — None: worked out here, in ``ev``, at the first."""
        sensors = self.sensors
        firmware, push, frame = sensors.firmware, sensors._push, sensors._send_frame
        numbers = self.frames_as_numbers()
        push_numbers = sensors.push_object_frame
        latency_s = sensors.mocap_latency_s + NO_MOCAP_FAULT.extra_latency_s
        for i, row in enumerate(rows):
            t_event, sample = row[_T], row[_S:]
            if row[0] == _MOCAP:
                if numbers:
                    push_numbers(t_event + latency_s, int(row[_K]), sample[1:4], sample[4:7],
                                 t_s)
                    continue
                frame(int(row[_K]), t_event, _Pose(sample[1:4], sample[4:7]), NO_MOCAP_FAULT,
                      None)
                continue
            # AirframePlant.navdata's sample (airborne), the packet of it: as the numbers
            # its receipt reads (wire_step.navdata_packets), or built
            if receipt is None:
                receipt = self._receipt(len(rows))
                if receipt:  # (the rows' packets worked out in ev)
                    rows[i:] = self.ev[i:len(rows)].tolist()
                    row = rows[i]
            if receipt and row[_OK]:
                self._packet(receipt, t_event, row)
                continue
            t, battery, roll, pitch, yaw, altitude, forward, right, down = sample[:9]
            nav = NavdataSample.make(t, mode, battery, roll, pitch, yaw, altitude,
                                     forward, right, down)
            push(t_event, ks.NAV, firmware.packet_of(t_event, nav))

    def frames_as_numbers(self) -> bool:
        """Whether the frames go as their numbers (received in bulk: ``sensors.
        ObjectFrame``): where ``_send_frame`` would queue a ``MocapFrame`` of the object
        alone, as it is, to a link that takes frames decoded and in bulk."""
        sensors = self.sensors
        return (sensors._names_checked and not sensors.frames_as_bytes
                and sensors.frames_in_bulk and sensors.target_cfg is None)

    def _receipt(self, n_rows: int) -> tuple | bool:
        """The tick's packets as numbers (``ev[:n_rows]``'s navdata rows worked out by
        ``wire_step.navdata_packets``): ``(the firmware's ctrl_state, its major)`` — or False
        where they go built: the sampler's receipt patched or its stats of another kind
        (``LockstepSensors.receives_quiet_packets``), a state
        word with the bootstrap bit (the receipt answers it) or packets without the demo
        option (no sample: the receipt reads none). The state word the firmware's
        (``DroneFirmware.status``) but for the bits a packet's own time and battery give."""
        sensors, fw = self.sensors, self.sensors.firmware
        if not sensors.receives_quiet_packets():
            return False
        state, ctrl_state, demo_sent = self._status(fw)
        if state & _BOOTSTRAP_BIT or not demo_sent:
            return False
        by_command = not fw.comwdg_latched and fw.comwdg_clear == "any"
        ws.navdata_packets(self.ev, n_rows, state,
                           float(fw.last_cmd_t) if by_command else math.inf,
                           float(fw.comwdg_s), float(fw.vbat_low_pct))
        return ctrl_state, ctrl_state >> 16

    def _status(self, fw) -> tuple:
        """``(state word, ctrl_state, demo option sent)`` of ``DroneFirmware.status`` at no
        silence and no low battery (the bits a packet's own time and battery add: _receipt),
        worked out again only when what it reads of the firmware changes (a tick's packets,
        most ticks', share it; a command heard: ``run`` flies no tick before the first)."""
        config = fw.config
        key = (fw.status_inputs(), config.navdata_options)
        if key != self._status_key:
            status = fw.status(-math.inf, math.inf)
            self._status_key = key
            self._status_of = (int(status.state_bits()), status.ctrl_state(fw.ctrl_codes),
                               bool(not status.demo or config.navdata_options & _DEMO_OPTION))
        return self._status_of

    def _packet(self, receipt: tuple, t_event: float, row: list) -> None:
        """The packet of the navdata row ``row`` (``ev``'s, worked out) sent at ``t_event``,
        as the numbers its receipt reads (its sequence number taken, as ``packet_of``)."""
        ctrl_state, major = receipt
        word = int(row[_STATE])
        decoded = _DECODED.get((word, ctrl_state))
        if decoded is None:
            decoded = _decoded(word, ctrl_state)
        battery, roll, pitch, yaw, altitude, forward, right, down = row[_DEMO:_DEMO + 8]
        sample = NavdataSample.make(t_event, decoded[1], battery, roll, pitch,
                                    wrap_angle_deg(yaw), altitude, forward, right, down,
                                    ctrl_state, word)
        sensors = self.sensors
        sensors.push_quiet_packet(t_event, sensors.firmware._next_sequence(), decoded[0],
                                  major, sample)


def _decoded(word: int, ctrl_state: int) -> tuple:
    """``_DECODED``'s entry of a state word and ctrl_state (a few a flight: kept)."""
    from ardrone_nmpc.links.drone_link import flight_mode_of  # (the wire's only)

    if len(_DECODED) > 256:
        _DECODED.clear()
    state = DroneState(word)
    _DECODED[word, ctrl_state] = decoded = (state, flight_mode_of(state, ctrl_state >> 16))
    return decoded
