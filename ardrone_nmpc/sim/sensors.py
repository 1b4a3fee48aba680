"""The lockstep sensor sampler: which mocap pose and navdata sample the links hold at time t.

One sampler for every lockstep run. Mocap frames are sampled every ``1 / sim.mocap_rate_hz``
and arrive ``noise.mocap_latency_ms`` later; navdata samples every ``1 / sim.navdata_rate_hz``
(the firmware's packets, body-frame velocities). It runs the simulated drone
(:class:`~ardrone_nmpc.sim.drone.SimulatedDrone`: physics, the firmware's watchdogs and
altitude cap) forward between those events. Two ways to hand the samples over:

* **direct** (no fault touches the sensors): only the newest sample of each stream before t is
  what a link would hand the tick, so only that one is drawn — intermediate mocap frames are
  skipped with their noise draws; the stream stays deterministic for a seed;
* **through the wire** (a fault touches the bytes, :data:`~ardrone_nmpc.sim.faults.SENSOR_FAULTS`):
  every frame and packet is encoded, faulted by the drone's fault injection (dropped, occluded,
  delayed, duplicated, reordered, corrupted) and handed to the real receiving logic —
  :class:`~ardrone_nmpc.links.mocap_link.MocapLink` and the navdata decoder — at its arrival
  time; a frame's receipt time is its pose time, as on the real link. Every frame costs a
  little speed and draws the noise in another order, so clean runs keep the direct path (and
  their golden trace). A mocap frame travels decoded (a :class:`~ardrone_nmpc.protocol.mocap.
  MocapFrame`, through the faults' disorder and the queue, to ``MocapLink.feed_frame``): its
  datagram holds the poses as float64 and the names as ASCII, so ``decode_mocap`` would give
  back the same frame — the bytes' encoding and decoding were half of a frame's cost (the
  first frame is still encoded once, for ``encode_mocap``'s checks of the names). Navdata
  packets stay bytes (corruption acts on bytes) but a quiet tick's: its packets travel as
  what their receipt reads of them (:class:`QuietPacket`: the sequence, the state word, the
  major and the sample, worked out compiled through the wire's float32 — what
  ``decode_navdata`` would give back of their bytes), or, where those numbers cannot stand in
  (sim/quiet_wire.py), as the :class:`~ardrone_nmpc.protocol.navdata.Navdata` they are built
  as, whose demo floats are stored as the wire's float32.
  A quiet tick's frames (the object alone, as they are) travel as their numbers
  (:class:`ObjectFrame`; those that arrive within the tick off the queue, their places in it
  noted) and the ones that arrive by a tick are received together — a quiet navdata packet
  between them touches nothing of the mocap link's —
  (:meth:`MocapLink.feed_object_frames
  <ardrone_nmpc.links.mocap_link.MocapLink.feed_object_frames>`: the link's state left as
  by ``feed_frame`` of each in turn; only the newest fresh pose made a record) — the tick
  reads only what the newest leaves.

On the direct path a tick in which nothing but physics happens (an airframe flying, taking
off or landing, a quiet firmware) is one compiled call
(:class:`~ardrone_nmpc.sim.lockstep_legs.CompiledLegs`): the
same legs, samples and bits.

Each navdata sample received is also shown to ``on_navdata(state, ctrl_major)`` — the state
bits and ctrl_state major the drone reported — which the link's take-off guard watches (on
the direct path only when the flight mode changes: between changes the guard would see the
same flight bits and a flying major again). A bootstrap packet received through the wire (the
drone lost its client: a blackout) is shown to ``on_bootstrap()``, which answers it as the
link does.
"""

from __future__ import annotations

import heapq
import math
from typing import Callable

import numpy as np

from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.links.udp import LinkStats
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap
from ardrone_nmpc.protocol.navdata import DroneState, Navdata, NavdataError, decode_navdata
from ardrone_nmpc.sim.faults import SENSOR_FAULTS
from ardrone_nmpc.sim.held_state import holds_in_arrays, overrides_none
from ardrone_nmpc.sim.target import target_pose

__all__ = ["LockstepSensors", "ObjectFrame", "QuietPacket"]

_MOCAP, _NAV = 0, 1
_BOOTSTRAP_BIT = int(DroneState.NAVDATA_BOOTSTRAP)
_navdata_sample_of = None  # links.drone_link's, imported by the wire's first packet


def _import_navdata_sample_of():
    """``links.drone_link.navdata_sample_of``, imported once (the wire's only: a direct run's
    process does without the link's module)."""
    global _navdata_sample_of
    from ardrone_nmpc.links.drone_link import navdata_sample_of

    _navdata_sample_of = navdata_sample_of
    return navdata_sample_of


#: what the wire path's quiet ticks (sim/quiet_wire.py) do in the sampler's place
_WIRE_REPLACED = ("_advance_through_wire", "deliver", "_mocap_frame", "_send_frame", "_push",
                  "_receive", "_receive_quiet", "push_object_frame", "push_quiet_packet",
                  "receives_quiet_packets")


class ObjectFrame:
    """A quiet tick's mocap frame on its way (sim/quiet_wire.py): the frame
    ``MocapFrame.of(number, [MocapObjectPose.from_si(object_name, position_m,
    rotation_xyz_rad)])`` as its numbers — received in bulk
    (:meth:`MocapLink.feed_object_frames
    <ardrone_nmpc.links.mocap_link.MocapLink.feed_object_frames>`), never built."""

    __slots__ = ("number", "position_m", "rotation_xyz_rad")

    def __init__(self, number: int, position_m, rotation_xyz_rad) -> None:
        self.number = number
        self.position_m, self.rotation_xyz_rad = position_m, rotation_xyz_rad

    def frame(self, object_name: str) -> MocapFrame:
        """The frame it stands for."""
        return MocapFrame.of(self.number, [MocapObjectPose.from_si(
            object_name, self.position_m, self.rotation_xyz_rad)])


class QuietPacket:
    """A quiet tick's navdata packet on its way (sim/quiet_wire.py) as what its receipt
    reads of the decoded packet: its ``sequence``, its ``state`` (a DroneState, as the
    take-off guard is shown it), its ctrl_state major and the sample
    ``navdata_sample_of`` makes of it at its arrival — never built as a packet."""

    __slots__ = ("sequence", "state", "ctrl_major", "sample")

    def __init__(self, sequence: int, state: DroneState, ctrl_major: int, sample) -> None:
        self.sequence, self.state, self.ctrl_major, self.sample = (sequence, state,
                                                                   ctrl_major, sample)


#: what a quiet tick queues: received without flushing the frames received together before
_QUIET_DATA = (ObjectFrame, Navdata, QuietPacket)


# the sensor grids' next indices: held by the compiled legs between their runs
@holds_in_arrays("_next_mocap_k", "_next_nav_k")
class LockstepSensors:
    """The sensor side of a lockstep run (module docstring).

    :attr:`frames_as_bytes` (class attribute, False): the wire's mocap frames encoded and
    decoded as bytes — the reference the decoded hand-over is tested against.
    :attr:`frames_in_bulk` (True): a quiet tick's frames received in one
    ``feed_object_frames`` call — not for a link whose class overrides ``feed_frame`` alone
    (each frame then goes through its override).

    Parameters
    ----------
    cfg : ExperimentConfig.
    drone : the simulated drone (advanced by :meth:`advance_to`).
    on_navdata : ``(state bits, ctrl_state major)`` of each navdata sample received.
    on_bootstrap : called for each bootstrap packet received (through the wire).
    defers_mode : ``defers_mode(mode)``: whether ``on_navdata`` of a sample showing the new
        flight mode ``mode`` may come after the compiled legs' run of the tick, not at the
        sample's time (it sends nothing then; :meth:`took_mode`). None: never.
    watching : ``watching()``: whether ``on_navdata`` looks at the direct path's samples now
        (the drone's state is not worked out for a callback that ignores it). None: always.
    t_zero_s : plant time of experiment time 0 (the faults' clock); settable later.
    """

    frames_as_bytes = False
    frames_in_bulk = True

    def __init__(self, cfg, drone, on_navdata: Callable | None = None,
                 t_zero_s: float = math.inf, on_bootstrap: Callable | None = None,
                 defers_mode: Callable | None = None, watching: Callable | None = None):
        self._held_by = None  # the compiled legs holding the grids' indices
        self.drone = drone
        self.plant = drone.plant
        self.firmware = drone.firmware
        faults = drone.faults
        self.wire = faults is not None and bool(faults.schedule.active & SENSOR_FAULTS)
        self.on_navdata = on_navdata or (lambda state, major: None)
        self.on_bootstrap = on_bootstrap or (lambda: None)
        self.defers_mode = defers_mode or (lambda mode: False)
        self.watching = watching or (lambda: True)
        self.t_zero_s = t_zero_s
        self.object_name = cfg.mocap.object_name
        self.mocap_period_s = 1.0 / cfg.sim.mocap_rate_hz
        self.mocap_latency_s = cfg.sim.noise.mocap_latency_ms * 1e-3
        self.nav_period_s = 1.0 / cfg.sim.navdata_rate_hz
        self.target_cfg = cfg.sim.target
        self.nav = None
        self.nav_rx_t_s = -math.inf
        self._nav_mode = None
        self._next_mocap_k = 0
        self._next_nav_k = 0
        # direct: the newest samples
        self.pose = None
        self.pose_rx_t_s = -math.inf
        self.target = None
        self.target_rx_t_s = -math.inf
        self._target_rng = np.random.default_rng([cfg.sim.seed, 0x7A26])
        self._target_std_m = cfg.sim.noise.mocap_position_std_m
        # through the wire: the receiving links and the datagrams on their way (the UDP
        # links' and servers' modules imported for it alone, here, in _mocap_frame and in
        # _receive: a direct run's process, a sweep's worker, does without ~9 ms of imports)
        self.mocap = None
        if self.wire:
            from ardrone_nmpc.links.mocap_link import MocapLink

            others = (self.target_cfg.object_name,) if self.target_cfg is not None else ()
            self.mocap = MocapLink("127.0.0.1", 0, object_name=self.object_name,  # never
                                   other_objects=others)                          # opened
        self.nav_stats = LinkStats(window_s=1.0)
        self.nav_malformed = 0
        self._queue: list = []  # (arrival_s, order, stream, bytes or a MocapFrame)
        self._order = 0
        # a quiet tick's frames that arrive within it, kept off the queue (their place in
        # it: (arrival_s, order, number, position_m, rotation_xyz_rad)): push_object_frame
        self._arrived: list = []
        self._names_checked = False  # (_mocap_frame: the first frame's names encoded)
        # the direct path's compiled tick (sim/lockstep_legs.py), for the plants it can fly
        self._legs = None
        # … and the wire path's quiet ticks on the same arrays (sim/quiet_wire.py)
        self._quiet = None
        from ardrone_nmpc.sim.lockstep_legs import SAMPLER_REPLACED, CompiledLegs
        kind = type(self)  # (a sampler overriding its legs keeps them)
        replaced = SAMPLER_REPLACED + (_WIRE_REPLACED if self.wire else ())
        if CompiledLegs.eligible(self.plant, self.firmware) and all(
                getattr(kind, name) is getattr(LockstepSensors, name)
                for name in replaced + LockstepSensors.HELD_IN_ARRAYS):
            if not self.wire:
                self._legs = CompiledLegs(self)
            else:
                from ardrone_nmpc.sim.quiet_wire import QuietWire
                if QuietWire.eligible(drone):
                    self._quiet = QuietWire(self, CompiledLegs(self))

    # ------------------------------------------------------------------ the clock
    def _run_to(self, t_s: float) -> None:
        """The drone's time passes to plant time ``t_s`` (physics, watchdogs, altitude cap)."""
        plant = self.plant
        if t_s > plant.t_s:
            self.firmware.advance(t_s - plant.t_s, t_s)

    def advance_to(self, t_s: float) -> None:
        """Run the drone to plant time ``t_s``, sampling the sensors on their own grids on the
        way (module docstring: only the newest, or every one through the wire)."""
        if self.wire:
            self._advance_through_wire(t_s)
            return
        legs = self._legs  # one compiled call (sim/lockstep_legs.py), if it can fly the tick
        left = legs.run(t_s) if legs is not None else None
        if left is None or left[0] or left[1]:
            self.go_on(t_s, left)

    def go_on(self, t_s: float, left: tuple | None) -> None:
        """The direct path's Python legs to ``t_s``: all of the tick's (``left`` None), or
        what :meth:`CompiledLegs.run <ardrone_nmpc.sim.lockstep_legs.CompiledLegs.run>` left
        (``(events, last_leg)``: the ``(time, kind)`` events in order, each sample drawn at
        its time, then, if ``last_leg``, the leg to ``t_s``)."""
        events, last_leg = (self._direct_events(t_s), True) if left is None else left
        for t_event, kind in events:
            self._run_to(t_event)
            if kind == _MOCAP:
                self.took_pose(t_event, self.plant.mocap_pose())
            else:
                self.took_navdata(t_event, self.plant.navdata())
        if last_leg:
            self._run_to(t_s)

    def inputs(self, t_s: float) -> TickInputs:
        """What the links hold at ``t_s``: the tick's input."""
        if not self.wire:
            return TickInputs.make(t_s, self.pose, self.pose_rx_t_s, self.nav, self.nav_rx_t_s,
                                   self.target, self.target_rx_t_s)
        pose, pose_rx = self.mocap.latest()
        target, target_rx = (self.mocap.latest_of(self.target_cfg.object_name)
                             if self.target_cfg is not None else (None, -math.inf))
        return TickInputs.make(t_s, pose, pose_rx, self.nav, self.nav_rx_t_s, target, target_rx)

    # ------------------------------------------------------------------ direct
    def _direct_events(self, t_s: float) -> list[tuple[float, int]]:
        """The newest mocap frame and navdata sample due by ``t_s`` not taken yet, in time
        order: ``(time, kind)``."""
        k_mocap = math.floor((t_s - self.mocap_latency_s) / self.mocap_period_s + 1e-9)
        k_nav = math.floor(t_s / self.nav_period_s + 1e-9)
        events = []
        if k_mocap >= self._next_mocap_k:
            events.append((k_mocap * self.mocap_period_s, _MOCAP))
            self._next_mocap_k = k_mocap + 1
        if k_nav >= self._next_nav_k:
            events.append((k_nav * self.nav_period_s, _NAV))
            self._next_nav_k = k_nav + 1
        return sorted(events)

    def took_pose(self, t_event: float, pose) -> None:
        """The mocap frame of ``t_event`` (its pose drawn): what the link holds."""
        self.pose = pose
        self.pose_rx_t_s = t_event + self.mocap_latency_s
        if self.target_cfg is not None:  # the scripted second object, same frame
            self.target = target_pose(self.target_cfg, t_event, self._target_rng,
                                      self._target_std_m)
            self.target_rx_t_s = self.pose_rx_t_s

    def took_navdata(self, t_event: float, nav) -> None:
        """The navdata sample of ``t_event``: what the link holds (and the guard sees)."""
        self.nav = nav
        self.nav_rx_t_s = t_event
        if nav.mode is not self._nav_mode:  # what the guard sees changes with it
            self.took_mode(t_event, nav.mode)

    def took_mode(self, t_event: float, mode) -> None:
        """The navdata sample of ``t_event`` shows a new flight mode ``mode``: the drone's
        state bits and ctrl_state major then, to ``on_navdata``."""
        self._nav_mode = mode
        if not self.watching():
            return
        status = self.firmware.status(t_event)
        self.on_navdata(status.state_bits(), status.ctrl_state(self.firmware.ctrl_codes) >> 16)

    # ------------------------------------------------------------------ through the wire
    def _advance_through_wire(self, t_s: float) -> None:
        """Send every frame due by ``t_s`` and deliver every datagram arrived by then, in
        arrival order (a quiet tick's legs and samples compiled: sim/quiet_wire.py)."""
        quiet = self._quiet
        if quiet is None or not quiet.run(t_s):  # (or the rest of what it ran)
            self._send_through_wire(t_s)
        self.deliver(t_s)

    def deliver(self, t_s: float) -> None:
        """Hand the links every datagram arrived by ``t_s``, in arrival order (a quiet
        tick's frames arrived in a row in one bulk receipt)."""
        queue, quiet_frames, arrived = self._queue, [], self._arrived
        if arrived and not all(item[3].__class__ in _QUIET_DATA for item in queue):
            self._queue_arrived()  # (a datagram of the Python path's on its way)
        while queue and queue[0][0] <= t_s + 1e-12:
            arrival, _, stream, data = heapq.heappop(queue)
            if data.__class__ is ObjectFrame:  # received together, in order
                quiet_frames.append((data.number, arrival, data.position_m,
                                     data.rotation_xyz_rad))
                continue
            if data.__class__ is QuietPacket:  # (touches nothing of the mocap link's)
                self._receive_quiet(arrival, data)
                continue
            # (a quiet tick's navdata packet between them — its sample, the guard's look —
            # touches nothing of the mocap link's: the frames go on together, one bulk call
            # a tick; anything else is received after those before it)
            if quiet_frames and data.__class__ is not Navdata:
                self.mocap.feed_object_frames(quiet_frames)
                quiet_frames = []
            self._receive(arrival, stream, data)
        if arrived:  # after the queue's frames, all sampled earlier: their arrival order
            quiet_frames += [(number, arrival, position_m, rotation)
                             for arrival, _, number, position_m, rotation in arrived]
            arrived.clear()
        if quiet_frames:
            self.mocap.feed_object_frames(quiet_frames)

    def _queue_arrived(self) -> None:
        """The quiet tick's frames kept off the queue (:meth:`push_object_frame`) put in
        their places in it: received in its order, among datagrams of the Python path's."""
        queue = self._queue
        for arrival, order, number, position_m, rotation in self._arrived:
            heapq.heappush(queue, (arrival, order, _MOCAP,
                                   ObjectFrame(number, position_m, rotation)))
        self._arrived.clear()

    def _send_through_wire(self, t_s: float) -> None:
        """Run the drone to ``t_s``, sending every frame and packet due on the way."""
        k_mocap = math.floor(t_s / self.mocap_period_s + 1e-9)
        k_nav = math.floor(t_s / self.nav_period_s + 1e-9)
        events = [(k * self.mocap_period_s, _MOCAP, k)
                  for k in range(self._next_mocap_k, k_mocap + 1)]
        events += [(k * self.nav_period_s, _NAV, k) for k in range(self._next_nav_k, k_nav + 1)]
        self._next_mocap_k = max(self._next_mocap_k, k_mocap + 1)
        self._next_nav_k = max(self._next_nav_k, k_nav + 1)
        for t_event, kind, k in sorted(events):
            self._run_to(t_event)
            if kind == _MOCAP:
                self._mocap_frame(k, t_event)
            else:
                t_exp = t_event - self.t_zero_s
                for data in self.drone.navdata_datagrams(t_event, t_exp):
                    self._push(t_event, _NAV, data)
        self._run_to(t_s)

    def _push(self, arrival_s: float, stream: int, data: bytes) -> None:
        # equal arrival times leave in push order: a held-back datagram arrives just after
        # the one that overtook it
        heapq.heappush(self._queue, (arrival_s, self._order, stream, data))
        self._order += 1

    def push_object_frame(self, arrival_s: float, k: int, position_m, rotation_xyz_rad,
                          t_s: float = -math.inf) -> None:
        """Queue the mocap frame ``k`` of the object alone at ``position_m``,
        ``rotation_xyz_rad``, as it is, to arrive at ``arrival_s`` — as numbers
        (:class:`ObjectFrame`: a quiet tick's, sim/quiet_wire.py). One that arrives by the
        tick's time ``t_s`` is kept off the queue (:attr:`_arrived`, its place in the queue
        noted): the tick's receipt takes it after the queue's frames, or puts it in its
        place when a datagram of the Python path's is on its way."""
        if arrival_s <= t_s + 1e-12:  # (the receipt's test)
            self._arrived.append((arrival_s, self._order, k & 0xFFFFFFFF, position_m,
                                  rotation_xyz_rad))
            self._order += 1
            return
        self._push(arrival_s, _MOCAP, ObjectFrame(k & 0xFFFFFFFF, position_m, rotation_xyz_rad))

    def push_quiet_packet(self, arrival_s: float, sequence: int, state: DroneState,
                          ctrl_major: int, sample) -> None:
        """Queue a quiet tick's navdata packet as its numbers (:class:`QuietPacket`) to
        arrive at ``arrival_s`` (sim/quiet_wire.py: where
        :meth:`receives_quiet_packets`)."""
        self._push(arrival_s, _NAV, QuietPacket(sequence, state, ctrl_major, sample))

    def receives_quiet_packets(self) -> bool:
        """Whether :meth:`_receive`'s navdata receipt is the one :meth:`_receive_quiet`
        stands in for: not patched, the stats a :class:`LinkStats`."""
        return type(self)._receive is _RECEIVE and self.nav_stats.__class__ is LinkStats

    def _mocap_frame(self, k: int, t_s: float) -> None:
        faults = self.drone.faults
        t_exp = t_s - self.t_zero_s
        fault = faults.mocap_frame(t_exp)
        if fault.dropped:
            return
        self._send_frame(k, t_s, self.plant.mocap_pose(), fault, t_exp)

    def _send_frame(self, k: int, t_s: float, pose, fault, t_exp: float | None) -> None:
        """Queue the mocap frame ``k`` sampled at ``t_s`` (``pose``: its drawn pose; ``fault``:
        the faults' decision of it; ``t_exp``: its experiment time for the faults' disorder,
        None where no fault acts — the frame goes out as it is)."""
        from ardrone_nmpc.sim.mocap_server import frame_items  # (the wire's only: __init__)

        items = frame_items(self.object_name, pose, fault.occlusion, self.target_cfg, t_s)
        frame = MocapFrame.of(k & 0xFFFFFFFF, items)
        if not self._names_checked:
            # the first frame encoded: encode_mocap's checks of the names (its ValueError)
            encoded = encode_mocap(frame)
            self._names_checked = True
            # a link of another kind (a swapped mocap source: a subclass's), or a MocapLink
            # whose class overrides the bytes' receipt (skipped by the decoded hand-overs),
            # takes bytes — decided once, at the first frame
            from ardrone_nmpc.links.mocap_link import MocapLink  # (the wire's only)

            if not overrides_none(self.mocap, MocapLink, ("feed", "_handle", "_handle_frame")):
                self.frames_as_bytes = True
            elif not overrides_none(self.mocap, MocapLink, ("feed_frame",)) and \
                    overrides_none(self.mocap, MocapLink, ("feed_object_frames",)):
                self.frames_in_bulk = False  # (the bulk receipt would skip its feed_frame)
            data = encoded if self.frames_as_bytes else frame
        elif self.frames_as_bytes:
            data = encode_mocap(frame)
        else:
            data = frame  # (what decode_mocap makes of encode_mocap's bytes: module docstring)
        arrival = t_s + (self.mocap_latency_s + fault.extra_latency_s)
        if t_exp is None:
            self._push(arrival, _MOCAP, data)
            return
        for datagram in self.drone.faults.mocap_datagrams(t_exp, data):
            self._push(arrival, _MOCAP, datagram)

    def _receive_quiet(self, arrival_s: float, packet: QuietPacket) -> None:
        """:meth:`_receive` of a quiet tick's navdata packet as its numbers: the stats'
        three calls under one lock, the sample and the guard's look as the decoded packet
        gives them (no bootstrap bit: sim/quiet_wire.py sends those as packets)."""
        if self.nav_stats.record_numbered(((packet.sequence, arrival_s, False),))[0]:
            self.nav, self.nav_rx_t_s = packet.sample, arrival_s
            self.on_navdata(packet.state, packet.ctrl_major)

    def _receive(self, arrival_s: float, stream: int, data: bytes) -> None:
        if stream == _MOCAP:
            if data.__class__ is MocapFrame:
                self.mocap.feed_frame(data, arrival_s)
            else:
                self.mocap.feed(data, arrival_s)
            return
        stats = self.nav_stats
        stats.record_datagram()
        if data.__class__ is Navdata:  # a quiet tick's packet, as decoded (sim/quiet_wire)
            packet = data
        else:
            try:
                packet = decode_navdata(data)
            except NavdataError:
                stats.record_malformed()
                self.nav_malformed += 1
                return
        if not stats.accept_sequence(packet.sequence):
            return
        if packet.state & _BOOTSTRAP_BIT:  # (DroneState.NAVDATA_BOOTSTRAP in the flags)
            self.on_bootstrap()
        sample_of = _navdata_sample_of or _import_navdata_sample_of()
        sample = sample_of(packet, arrival_s)
        if sample is not None:
            stats.record_packet(arrival_s)
            self.nav, self.nav_rx_t_s = sample, arrival_s
            self.on_navdata(packet.state, packet.demo.ctrl_major)


_RECEIVE = LockstepSensors._receive  # (as defined: one patched keeps the packets built)
