"""Loopback motion-capture streamer: the plant's pose as Vicon-style UDP datagrams.

docs/mocap-stream.md, "Rules for the loopback streamer". One thread samples
:meth:`AirframePlant.mocap_pose` (noise from the plant's ``noise`` settings) at ``rate_hz`` on
absolute deadlines, encodes it with :func:`~ardrone_nmpc.protocol.mocap.encode_mocap` (one pose
item, zero-padded to 256 bytes) and sends it ``latency_ms`` after the sampling deadline to a
127.x target. Frame numbers are tied to the deadlines: frame ``first_frame + k`` is the pose of
deadline ``k``, so they go up by one per frame; a dropped frame (``drop_probability``, seeded)
leaves a gap, as a lost datagram of a real system would. When the thread wakes more than
``max_catchup_s`` late (a stalled process) it skips the missed frames (a gap, counted in
``skipped``) instead of bursting them; shorter delays are caught up frame by frame.

Injected faults (``faults``, a :class:`~ardrone_nmpc.sim.fault_injection.ServerFaults`) act per
frame at its sampling deadline: a dropout burst sends nothing (a frame-number gap), an
occlusion sends the frame without the object or with an all-zero pose, a latency spike adds to
the due time, and disorder duplicates a datagram or holds it back behind the next one. The send
queue is kept sorted by due time, so frames delayed by a spike are overtaken by later ones, as
on a real network.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
import random
import socket
import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional

from ardrone_nmpc.protocol.mocap import MOCAP_DEFAULT_PORT, MocapFrame, MocapObjectPose, encode_mocap
from ardrone_nmpc.sim.drone_server import require_loopback_host
from ardrone_nmpc.sim.fault_injection import NO_MOCAP_FAULT, ServerFaults
from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.sim.target import target_pose

__all__ = ["frame_items", "MocapServer", "MocapServerCounters"]


@dataclass
class MocapServerCounters:
    """Counters of a :class:`MocapServer` (a snapshot copy when read)."""

    frames: int = 0            # deadlines sampled (sent, dropped, or withheld by a fault)
    sent: int = 0
    dropped: int = 0           # by drop_probability
    skipped: int = 0           # deadlines skipped after a stall longer than max_catchup_s
    send_errors: int = 0
    last_frame_number: int = -1


class _NullLock:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def frame_items(object_name: str, pose, occlusion: Optional[str], second_object,
                t_plant_s: float) -> list[MocapObjectPose]:
    """The wire poses of one simulated mocap frame: the drone's ``pose`` (left out when
    ``occlusion`` is ``"missing"``, all zero when ``"zero"``, a tracker's "not seen") and, if a
    ``sim.target`` config is given, the scripted second object at plant time ``t_plant_s``.
    Shared by this streamer and the lockstep wire sensors."""
    if occlusion == "missing":
        items = []
    elif occlusion == "zero":
        items = [MocapObjectPose(object_name, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))]
    else:
        items = [MocapObjectPose.from_si(object_name, pose.position_m, pose.rotation_xyz_rad)]
    if second_object is not None:
        other = target_pose(second_object, t_plant_s)
        items.append(MocapObjectPose.from_si(second_object.object_name, other.position_m,
                                             (0.0, 0.0, other.psi_rad)))
    return items


class MocapServer:
    """Streams the plant's pose to ``target`` (context manager: enter starts, exit stops).

    Parameters
    ----------
    plant : the simulated drone (``mocap_pose()`` is called under ``lock``).
    target : (host, port); the host must be a 127.x address (ValueError otherwise).
    rate_hz : frame rate (Hz), 100 as the thesis' Vicon system.
    object_name : the object name in each pose item (1–24 ASCII characters).
    latency_ms : delay from the sampling deadline to the send (ms), ≥ 0.
    lock : lock shared with the thread advancing the plant (None: no locking).
    drop_probability : probability a frame is not sent (frame number still advances).
    seed : seed of the drop decisions.
    first_frame : frame number of the first frame.
    max_catchup_s : lateness beyond which missed frames are skipped rather than sent.
    clock : the time source (s), ``time.monotonic`` by default.
    faults : injected faults (None: none); their experiment time runs on ``clock``.
    """

    def __init__(self, plant: AirframePlant, *,
                 target: tuple[str, int] = ("127.0.0.1", MOCAP_DEFAULT_PORT),
                 rate_hz: float = 100.0, object_name: str = "ardrone", latency_ms: float = 2.0,
                 lock=None, drop_probability: float = 0.0, seed: int = 0, first_frame: int = 1,
                 max_catchup_s: float = 0.25,
                 clock: Callable[[], float] = time.monotonic,
                 faults: Optional[ServerFaults] = None, second_object=None) -> None:
        host, port = target
        host = require_loopback_host(host, "mocap target")
        port = int(port)
        if not 1 <= port <= 65535:
            raise ValueError(f"mocap target port must be in 1..65535, got {port}")
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be finite and > 0, got {rate_hz!r}")
        if not (math.isfinite(latency_ms) and latency_ms >= 0):
            raise ValueError(f"latency_ms must be finite and >= 0, got {latency_ms!r}")
        if not 0.0 <= drop_probability <= 1.0:
            raise ValueError(f"drop_probability must be in [0, 1], got {drop_probability!r}")
        if not 0 <= first_frame <= 0xFFFFFFFF:
            raise ValueError(f"first_frame must be a u32, got {first_frame!r}")
        # validates the name (ASCII, 1..24 characters) once, up front
        encode_mocap(MocapFrame.of(0, [MocapObjectPose(object_name, (1.0, 0, 0), (0, 0, 0))]))
        self.plant = plant
        self.second_object = second_object  # a sim.target config: a scripted second object
        self.target = (host, port)
        self.rate_hz = float(rate_hz)
        self.object_name = object_name
        self.latency_s = float(latency_ms) / 1000.0
        self.drop_probability = float(drop_probability)
        self.first_frame = int(first_frame)
        self.max_catchup_s = float(max_catchup_s)
        self._lock = lock if lock is not None else _NullLock()
        self._rng = random.Random(seed)
        self._clock = clock
        self._faults = faults
        self._order = 0                 # queue tie-break: equal due times go out FIFO
        self._counters = MocapServerCounters()
        self._counters_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._closed = False
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind(("127.0.0.1", 0))
        except BaseException:
            self._sock.close()
            raise

    @property
    def counters(self) -> MocapServerCounters:
        with self._counters_lock:
            return dataclasses.replace(self._counters)

    @property
    def source_port(self) -> int:
        """The local UDP port the datagrams come from."""
        return self._sock.getsockname()[1]

    # ------------------------------------------------------------------ life cycle

    def start(self) -> MocapServer:
        if self._closed:
            raise RuntimeError("MocapServer is closed")
        if self._thread is not None:
            raise RuntimeError("MocapServer already started")
        self._thread = threading.Thread(target=self._run, name="mocap-server", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop and join the thread, close the socket (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
        self._sock.close()
        self._closed = True

    close = stop

    def __enter__(self) -> MocapServer:
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        return (f"MocapServer({self.object_name!r} → {self.target[0]}:{self.target[1]}, "
                f"{self.rate_hz:g} Hz)")

    # ------------------------------------------------------------------ streaming

    def _frame_bytes(self, frame_number: int, occlusion: Optional[str] = None) -> bytes:
        """The datagram of ``frame_number``; ``occlusion`` ``"missing"`` leaves the object out,
        ``"zero"`` sends it at an all-zero pose (a tracker's "not seen" convention)."""
        with self._lock:
            pose = self.plant.mocap_pose()
            t_plant_s = self.plant.t_s
        items = frame_items(self.object_name, pose, occlusion, self.second_object, t_plant_s)
        return encode_mocap(MocapFrame.of(frame_number & 0xFFFFFFFF, items))

    def _run(self) -> None:
        clock, period = self._clock, 1.0 / self.rate_hz
        queue: list = []   # heap of (due time, order, bytes): sent in due order, FIFO on ties
        t0 = clock()
        k = 0
        while not self._stop.is_set():
            now = clock()
            self._send_due(queue, now)
            deadline = t0 + k * period
            if now >= deadline:
                if now - deadline > self.max_catchup_s:
                    k_now = int((now - t0) / period)
                    with self._counters_lock:
                        self._counters.skipped += k_now - k
                    k = k_now
                    deadline = t0 + k * period
                self._sample(self.first_frame + k, deadline, queue)
                k += 1
                continue
            wake = deadline if not queue else min(deadline, queue[0][0])
            self._stop.wait(max(0.0, wake - now))

    def _send_due(self, queue: list, now: float) -> None:
        """Send every queued datagram due by ``now`` (s), earliest first."""
        while queue and queue[0][0] <= now:
            _, _, data = heapq.heappop(queue)
            try:
                self._sock.sendto(data, self.target)
                sent_ok = True
            except OSError:
                sent_ok = False
            with self._counters_lock:
                if sent_ok:
                    self._counters.sent += 1
                else:
                    self._counters.send_errors += 1

    def _sample(self, frame_number: int, deadline: float, queue: list) -> None:
        """Sample the frame of ``deadline`` (s) and queue its datagrams (or none)."""
        fault = NO_MOCAP_FAULT if self._faults is None else self._faults.mocap_frame(deadline)
        data = None if fault.dropped else self._frame_bytes(frame_number, fault.occlusion)
        dropped = self.drop_probability > 0 and self._rng.random() < self.drop_probability
        with self._counters_lock:
            c = self._counters
            c.frames += 1
            c.last_frame_number = frame_number & 0xFFFFFFFF
            if dropped and data is not None:
                c.dropped += 1
        if dropped or data is None:
            return
        due = deadline + self.latency_s + fault.extra_latency_s
        datagrams = [data] if self._faults is None else self._faults.mocap_datagrams(deadline, data)
        for d in datagrams:
            heapq.heappush(queue, (due, self._order, d))
            self._order += 1
