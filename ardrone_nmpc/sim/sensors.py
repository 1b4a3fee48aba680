"""Lockstep sensors through the wire: every mocap frame and navdata packet is encoded to bytes,
faulted (dropped, occluded, delayed, duplicated, reordered, corrupted), and handed to the real
receiving logic — :class:`~ardrone_nmpc.links.mocap_link.MocapLink` and the navdata decoder —
at its arrival time on the manual clock.

The lockstep runner uses this instead of its direct sampling when a sensor fault is configured
(:data:`~ardrone_nmpc.sim.faults.SENSOR_FAULTS`): sampling every frame costs a little speed and
draws the sensor noise in another order than the direct path, so clean runs keep the direct
path (and their golden trace). Mocap latency here may be anything (the direct path is limited
to 50 ms); a frame's receipt time is its pose time, as on the real link.
"""

from __future__ import annotations

import heapq
import math

from ardrone_nmpc.sim.faults import Disorder, FaultSchedule, corrupt_navdata
from ardrone_nmpc.links.drone_link import navdata_sample_of
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.links.udp import LinkStats
from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.protocol.mocap import MocapFrame, encode_mocap
from ardrone_nmpc.protocol.navdata import (
    CtrlCodes,
    DroneStatus,
    NavdataError,
    decode_navdata,
    encode_drone_navdata,
)
from ardrone_nmpc.sim.mocap_server import frame_items


def drone_status(plant) -> DroneStatus:
    """What the lockstep drone reports about itself now.

    This drone has no AT link (the runner commands the plant directly), so the bits that
    echo the client's commands — REF start, ACK, com watchdog, link lost — stay clear; its
    VBAT_LOW and injected fault bits are the plant's.
    """
    return DroneStatus(plant.mode.value, moving=plant.moving, battery_low=plant.vbat_low,
                       faults=plant.fault_bits)


def navdata_packet(plant, sequence: int, codes: CtrlCodes = CtrlCodes.SDK) -> bytes:
    """The demo navdata packet the lockstep drone sends now, through the one drone encoder
    (its status: :func:`drone_status`)."""
    return encode_drone_navdata(drone_status(plant), sequence, plant.navdata(), codes=codes,
                                t_s=plant.t_s)


class WireSensors:
    """The sensor side of a lockstep run, datagram by datagram.

    Parameters
    ----------
    cfg : ExperimentConfig.
    plant : the simulated drone (advanced by :meth:`advance_to`).
    schedule : the run's :class:`~ardrone_nmpc.sim.faults.FaultSchedule`.
    t_zero_s : plant time of experiment time 0 (the faults' clock); settable later.
    """

    def __init__(self, cfg, plant, schedule: FaultSchedule, t_zero_s: float = math.inf):
        self.plant = plant
        self.schedule = schedule
        self.ctrl_codes = schedule.ctrl_codes()
        self.t_zero_s = t_zero_s
        self.object_name = cfg.mocap.object_name
        self.mocap_period_s = 1.0 / cfg.sim.mocap_rate_hz
        self.mocap_latency_s = cfg.sim.noise.mocap_latency_ms * 1e-3
        self.nav_period_s = 1.0 / cfg.sim.navdata_rate_hz
        self.target_cfg = cfg.sim.target
        others = (self.target_cfg.object_name,) if self.target_cfg is not None else ()
        self.mocap = MocapLink("127.0.0.1", 0, object_name=self.object_name,  # never opened
                               other_objects=others)
        self.nav_stats = LinkStats(window_s=1.0)
        self.nav = None
        self.nav_rx_t_s = -math.inf
        self.nav_malformed = 0
        self._queue: list = []  # (arrival_s, order, stream, bytes)
        self._order = 0
        self._next_mocap_k = 0
        self._next_nav_k = 0
        self._disorder = {"mocap": Disorder(), "navdata": Disorder()}

    # ------------------------------------------------------------------ sending side
    def _send(self, stream: str, sent_s: float, arrival_s: float, data: bytes) -> None:
        duplicate, hold = self.schedule.disorder(stream, sent_s - self.t_zero_s)
        # equal arrival times leave in push order: a held-back datagram arrives just after
        # the one that overtook it
        for datagram in self._disorder[stream](data, duplicate, hold):
            self._push(arrival_s, stream, datagram)

    def _push(self, arrival_s: float, stream: str, data: bytes) -> None:
        heapq.heappush(self._queue, (arrival_s, self._order, stream, data))
        self._order += 1

    def _mocap_frame(self, k: int, t_s: float) -> None:
        t_exp = t_s - self.t_zero_s
        sched = self.schedule
        if sched.mocap_dropped(t_exp):
            return
        pose = self.plant.mocap_pose()
        items = frame_items(self.object_name, pose, sched.mocap_occlusion(t_exp),
                            self.target_cfg, t_s)
        data = encode_mocap(MocapFrame.of(k & 0xFFFFFFFF, items))
        latency = self.mocap_latency_s + sched.mocap_extra_latency_s(t_exp)
        self._send("mocap", t_s, t_s + latency, data)

    def _navdata_packet(self, k: int, t_s: float) -> None:
        t_exp = t_s - self.t_zero_s
        if self.schedule.navdata_lost(t_exp):
            return
        data = navdata_packet(self.plant, (k + 1) & 0xFFFFFFFF or 1, self.ctrl_codes)
        kind = self.schedule.navdata_corruption(t_exp)
        if kind is not None:
            data = corrupt_navdata(data, kind)
        self._send("navdata", t_s, t_s, data)

    # ------------------------------------------------------------------ receiving side
    def _receive(self, arrival_s: float, stream: str, data: bytes) -> None:
        if stream == "mocap":
            self.mocap.feed(data, arrival_s)
            return
        stats = self.nav_stats
        stats.record_datagram()
        try:
            packet = decode_navdata(data)
        except NavdataError:
            stats.record_malformed()
            self.nav_malformed += 1
            return
        if not stats.accept_sequence(packet.sequence):
            return
        sample = navdata_sample_of(packet, arrival_s)
        if sample is not None:
            stats.record_packet(arrival_s)
            self.nav, self.nav_rx_t_s = sample, arrival_s

    # ------------------------------------------------------------------ the clock
    def advance_to(self, t_s: float) -> None:
        """Run the plant to ``t_s``, sending every frame due on the way and delivering every
        datagram that has arrived by ``t_s``, in arrival order."""
        plant = self.plant
        k_mocap = math.floor(t_s / self.mocap_period_s + 1e-9)
        k_nav = math.floor(t_s / self.nav_period_s + 1e-9)
        events = [(k * self.mocap_period_s, 0, k) for k in range(self._next_mocap_k, k_mocap + 1)]
        events += [(k * self.nav_period_s, 1, k) for k in range(self._next_nav_k, k_nav + 1)]
        self._next_mocap_k = max(self._next_mocap_k, k_mocap + 1)
        self._next_nav_k = max(self._next_nav_k, k_nav + 1)
        for t_event, kind, k in sorted(events):
            if t_event > plant.t_s:
                plant.advance(t_event - plant.t_s)
            if kind == 0:
                self._mocap_frame(k, t_event)
            else:
                self._navdata_packet(k, t_event)
        if t_s > plant.t_s:
            plant.advance(t_s - plant.t_s)
        queue = self._queue
        while queue and queue[0][0] <= t_s + 1e-12:
            arrival, _, stream, data = heapq.heappop(queue)
            self._receive(arrival, stream, data)

    def inputs(self, t_s: float) -> TickInputs:
        pose, pose_rx = self.mocap.latest()
        target, target_rx = (self.mocap.latest_of(self.target_cfg.object_name)
                             if self.target_cfg is not None else (None, -math.inf))
        return TickInputs(t_s, pose, pose_rx, self.nav, self.nav_rx_t_s, target, target_rx)
