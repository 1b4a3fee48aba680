"""Fault injection datagram by datagram: a :class:`~ardrone_nmpc.sim.faults.FaultSchedule` asked
by the simulated drone (:class:`~ardrone_nmpc.sim.drone.SimulatedDrone`) on its clock.

One :class:`ServerFaults` per simulated drone, shared by whatever serves it: the drone server
and the mocap streamer of a :class:`~ardrone_nmpc.sim.loopback.Loopback` (``fly --sim``), or the
lockstep link and its sensors (``simulate``). Experiment time is ``now − t0`` (s): the servers
pass their clock (``time.monotonic`` unless injected) and ``t0`` is set by
:meth:`ServerFaults.set_clock` when the runner starts the experiment; the lockstep drone passes
experiment time itself (``t0`` = 0). Until then experiment time is −inf: no window fault acts,
only the constant wind blows.

The decisions: a mocap frame is dropped, occluded (object missing or an all-zero pose) or
delayed by its sampling time; a navdata packet is lost or corrupted by its send time; either
stream's datagrams are duplicated or held back behind the next one; an AT datagram is lost by
its arrival time, and in a blackout so is a wake-up on the navdata port. Plant faults (battery floor, emergency, command-delay jump, wind, landing by
itself) go through :class:`~ardrone_nmpc.sim.faults.PlantFaults`; the drone's firmware options
(ctrl_state codes, config session, control port) are read from the same schedule by
:meth:`SimulatedDrone.from_config`.

Thread safety: the random draws and the held-back datagrams are guarded by an internal lock
(the schedule's generator is shared by the AT, navdata and mocap threads);
:meth:`ServerFaults.update_plant` must be called under the plant's lock, as every plant call.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, replace

from ardrone_nmpc.sim.faults import Disorder, FaultSchedule, PlantFaults, corrupt_navdata

__all__ = ["ServerFaults", "FaultCounters", "MocapFrameFault"]


@dataclass(frozen=True)
class MocapFrameFault:
    """What happens to one mocap frame.

    Attributes
    ----------
    dropped : the frame is not sent at all (dropout burst).
    occlusion : ``"missing"`` (no pose item), ``"zero"`` (an all-zero pose) or None.
    extra_latency_s : latency added to the frame's send time (s).
    """

    dropped: bool = False
    occlusion: str | None = None
    extra_latency_s: float = 0.0


NO_MOCAP_FAULT = MocapFrameFault()


@dataclass
class FaultCounters:
    """How often each injected fault acted (a snapshot copy when read)."""

    mocap_dropped: int = 0        # frames not sent (dropout burst)
    mocap_occluded: int = 0       # frames sent without the object or with a zero pose
    mocap_delayed: int = 0        # frames sent with extra latency
    navdata_lost: int = 0         # navdata packets not sent
    navdata_corrupted: int = 0    # navdata packets sent corrupted
    duplicated: int = 0           # datagrams sent twice (either stream)
    reordered: int = 0            # datagrams held back behind the next one (either stream)
    at_lost: int = 0              # AT datagrams discarded on arrival


class ServerFaults:
    """The fault decisions of the loopback servers (see the module docstring).

    Parameters
    ----------
    schedule : the run's :class:`~ardrone_nmpc.sim.faults.FaultSchedule`.
    plant : the simulated drone the plant faults act on (None: no plant faults).
    """

    def __init__(self, schedule: FaultSchedule, plant=None) -> None:
        self.schedule = schedule
        self.t0_s = math.inf
        self._plant_faults = PlantFaults(schedule, plant) if plant is not None else None
        self._lock = threading.Lock()
        self._disorder = {"mocap": Disorder(), "navdata": Disorder()}
        self._counters = FaultCounters()
        self._events: list[tuple[float, dict]] = []
        self._taken = 0
        self._spans = schedule.window_spans()  # (quiet_until_s; and without a repeated
        self._spans_bursts_asked = schedule.window_spans(repeated=False)  # dropout's)

    # ------------------------------------------------------------------ the clock

    def set_clock(self, t0_s: float) -> None:
        """Experiment time 0 is ``t0_s`` on the servers' clock (s)."""
        self.t0_s = float(t0_s)

    def t_exp(self, now_s: float) -> float:
        """Experiment time of ``now_s`` (s); −inf before :meth:`set_clock`."""
        return now_s - self.t0_s

    @property
    def counters(self) -> FaultCounters:
        with self._lock:
            return replace(self._counters)

    @property
    def events(self) -> list[tuple[float, dict]]:
        """``(experiment time s, event)`` of every plant fault that started, in order."""
        with self._lock:
            return list(self._events)

    def take_events(self) -> list[tuple[float, dict]]:
        """:attr:`events` not taken before, in order."""
        with self._lock:
            taken, self._taken = self._events[self._taken:], len(self._events)
        return taken

    # ------------------------------------------------------------------ the drone

    def update_plant(self, now_s: float) -> list[dict]:
        """Apply the plant faults due at ``now_s`` (call under the plant's lock); returns the
        events of the faults that started."""
        if self._plant_faults is None:
            return []
        t = self.t_exp(now_s)
        events = self._plant_faults.update(t)
        if events:
            with self._lock:
                self._events.extend((t, ev) for ev in events)
        return events

    def quiet_until_s(self, now_s: float, bursts_asked: bool = False) -> float:
        """The time (servers' clock) from ``now_s`` on before which no fault acts: no plant
        fault is due (one-shot, a gust's start, blowing or end) and no fault's window is
        open (AT loss, blackout, the sensors', the solver's). Every decision asked at a time
        in ``[now_s, answer)`` is then a fault-free drone's, and draws nothing; an answer at
        or before ``now_s``: one may act at ``now_s``. (The constant wind and the firmware's
        options act for the whole flight: they are the drone's, not a decision.)
        ``bursts_asked``: the caller asks ``schedule.mocap_dropped`` of every mocap frame
        itself — a repeated dropout's bursts (a window that never ends) are left out."""
        t = self.t_exp(now_s)
        bound = math.inf if self._plant_faults is None else self._plant_faults.next_due_s()
        for start, end in self._spans_bursts_asked if bursts_asked else self._spans:
            if end > t and start < bound:
                bound = start
        return bound + self.t0_s

    def holds_datagrams(self) -> bool:
        """A stream's disorder holds a datagram back (the next one of its stream sends it)."""
        with self._lock:
            return any(d.holding for d in self._disorder.values())

    def wakeup_lost(self, now_s: float) -> bool:
        """A datagram on the navdata port at ``now_s`` never reaches the drone (a blackout)."""
        return self.schedule.blackout(self.t_exp(now_s))

    def at_lost(self, now_s: float) -> bool:
        """The AT datagram arriving at ``now_s`` never reaches the drone."""
        with self._lock:
            lost = self.schedule.at_lost(self.t_exp(now_s))
            self._counters.at_lost += lost
        return lost

    def at_loss_acts(self, now_s: float) -> bool:
        """:meth:`at_lost` at ``now_s`` decides (else it answers False, draws and counts
        nothing)."""
        return self.schedule.at_loss_acts(self.t_exp(now_s))

    def navdata_lost(self, now_s: float) -> bool:
        """The navdata packet due at ``now_s`` is lost (it need not be built)."""
        with self._lock:
            lost = self.schedule.navdata_lost(self.t_exp(now_s))
            self._counters.navdata_lost += lost
        return lost

    def navdata_datagrams(self, now_s: float, packet: bytes) -> list[bytes]:
        """The datagrams to send, in order, for the navdata ``packet`` due at ``now_s`` (not
        :meth:`navdata_lost`): the packet corrupted, duplicated or held back."""
        t = self.t_exp(now_s)
        sched = self.schedule
        with self._lock:
            kind = sched.navdata_corruption(t)
            if kind is not None:
                packet = corrupt_navdata(packet, kind)
                self._counters.navdata_corrupted += 1
            return self._disordered("navdata", t, packet)

    # ------------------------------------------------------------------ mocap

    def mocap_frame(self, t_frame_s: float) -> MocapFrameFault:
        """The faults of the mocap frame sampled at ``t_frame_s`` (servers' clock, s)."""
        t = self.t_exp(t_frame_s)
        sched = self.schedule
        with self._lock:
            if sched.mocap_dropped(t):
                self._counters.mocap_dropped += 1
                return MocapFrameFault(dropped=True)
            occlusion = sched.mocap_occlusion(t)
            extra = sched.mocap_extra_latency_s(t)
            self._counters.mocap_occluded += occlusion is not None
            self._counters.mocap_delayed += extra > 0
        if occlusion is None and extra == 0.0:
            return NO_MOCAP_FAULT
        return MocapFrameFault(occlusion=occlusion, extra_latency_s=extra)

    def mocap_datagrams(self, t_frame_s: float, data: bytes) -> list[bytes]:
        """The datagrams to queue, in order, for the mocap frame sampled at ``t_frame_s``."""
        with self._lock:
            return self._disordered("mocap", self.t_exp(t_frame_s), data)

    # ------------------------------------------------------------------ both streams

    def _disordered(self, stream: str, t: float, data: bytes) -> list[bytes]:
        duplicate, hold = self.schedule.disorder(stream, t)
        disorder = self._disorder[stream]
        out = disorder(data, duplicate, hold)
        self._counters.duplicated += duplicate
        self._counters.reordered += disorder.holding  # only a fresh hold leaves one held
        return out
