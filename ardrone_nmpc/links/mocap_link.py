"""The motion-capture link: the latest fresh pose of one object from the UDP pose stream.

docs/mocap-stream.md, receiver rules. A receiver thread reads datagrams (buffer ≥ 2048 bytes),
stamps each on receipt with the link's clock, decodes it with
:func:`~ardrone_nmpc.protocol.mocap.decode_mocap` (malformed → counted, never raised) and hands
the frame to :meth:`MocapSource.accept_frame
<ardrone_nmpc.links.mocap_source.MocapSource.accept_frame>`, which keeps the newest *fresh* pose
of the configured object as a :class:`~ardrone_nmpc.core.types.MocapPose` (metres, radians, ψ
wrapped to (−π, π], ``t_s`` = receipt time) by the rules every mocap source shares (missing,
zero and repeated poses). Here, on top: a frame number not newer than the last accepted one
(duplicate or reordered datagram, ``stats.out_of_order``) is dropped — unless the stream had
been silent for ``restart_silence_s`` (0.5 s): a restarted tracker numbers from 1 again
(``stats.restarts``).

**One sender per stream.** Frames are read with their source (address, port). The link locks
onto the first sender whose frame carries the configured object; datagrams from any other
sender — a stale ``replay --broadcast``, a second tracker — are counted per sender
(:attr:`MocapLink.foreign_senders`, ``stats.foreign``), reported once each as an event
(:meth:`MocapLink.take_events`: ``mocap_foreign_sender``, naming it) and never move the pose.
Only after the locked sender has been silent for ``relock_silence_s`` (2 s: by then the
supervisor has long landed the drone for lack of mocap) may another sender take over
(``mocap_sender_changed``) — a restarted tracker that came back from a new port.

:attr:`MocapLink.stats` counts every datagram with a valid number (so ``rate_hz`` and frame
``lost`` describe the stream itself, whether or not the object was visible) and the malformed
ones. Closing the link stops the thread and closes the socket.
"""

from __future__ import annotations

import math
import socket
import threading
import time

from ardrone_nmpc.links.mocap_source import MocapSource, mocap_pose_of
from ardrone_nmpc.links.udp import RECV_BUFFER_BYTES, Clock, open_udp
from ardrone_nmpc.protocol.mocap import (
    _MM_PER_M,  # (MocapObjectPose.from_si's scale: feed_object_frames)
    MOCAP_DEFAULT_PORT,
    MocapError,
    MocapFrame,
    MocapObjectPose,
    decode_mocap,
)

__all__ = ["MocapLink", "mocap_pose_of"]

_RX_POLL_S = 0.05


def _name(sender) -> str:
    return f"{sender[0]}:{sender[1]}"


class MocapLink(MocapSource):
    """Receive the pose stream and keep the latest fresh pose of ``object_name``.

    Parameters
    ----------
    bind_host : local address to listen on (``"0.0.0.0"``: all interfaces, as a Vicon PC sends
        from the lab network; ``"127.0.0.1"`` for the loopback streamer).
    port : UDP port (51001); 0 picks a free one, see :attr:`port`.
    object_name : the tracked object's name in the stream.
    clock : receipt stamps (seconds, monotonic).
    repeat_limit : consecutive bit-identical frames from which a pose stops being fresh (≥ 2).
    restart_silence_s : silence of the locked sender after which its frame numbering may
        restart (any number is accepted next).
    relock_silence_s : silence of the locked sender after which another sender may replace it.

    Context manager: ``with MocapLink(...) as mocap:`` starts the thread, exit stops it.
    """

    kind = "vicon_udp"

    def __init__(self, bind_host: str = "0.0.0.0", port: int = MOCAP_DEFAULT_PORT, *,
                 object_name: str = "ardrone", clock: Clock = time.monotonic,
                 repeat_limit: int = 3, restart_silence_s: float = 0.5,
                 relock_silence_s: float = 2.0,
                 other_objects: tuple[str, ...] = ()) -> None:
        super().__init__(object_name=object_name, other_objects=other_objects, clock=clock,
                         repeat_limit=repeat_limit,
                         # a frame number going back is a restart only after a silence
                         restart_backjump=1 << 40)
        self.bind_host = bind_host
        self._requested_port = int(port)
        self._sock: socket.socket | None = None
        self._bound_port: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.restart_silence_s = float(restart_silence_s)
        self.relock_silence_s = float(relock_silence_s)
        self._sender = None                  # (address, port) locked onto; None before
        self._sender_t_s = -math.inf         # its last datagram (link clock)
        self._frames: dict = {}              # sender → [datagrams, last frame number]
        self._carriers: set = set()          # senders whose frames carried the object
        self._events: list[dict] = []

    # ----------------------------------------------------------------------------- lifecycle

    def start(self) -> None:
        """Bind the socket and start the receiver thread (once)."""
        if self._sock is not None or self._stop.is_set():
            raise RuntimeError("MocapLink already started (or closed)")
        self._sock = open_udp(self.bind_host, self._requested_port, timeout_s=_RX_POLL_S)
        self._bound_port = self._sock.getsockname()[1]
        self._thread = threading.Thread(target=self._rx_loop, name="mocap-rx", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the thread and close the socket (idempotent)."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        if self._sock is not None:
            self._sock.close()

    @property
    def port(self) -> int:
        """The bound UDP port (the actual one when 0 was requested); the requested port before
        :meth:`start`."""
        return self._bound_port if self._bound_port is not None else self._requested_port

    @property
    def where(self) -> str:
        return f"udp {self.bind_host}:{self.port}"

    @property
    def sender(self) -> str | None:
        """The locked sender as ``address:port`` (None before the first frame of the object)."""
        s = self._sender
        return None if s is None else _name(s)

    @property
    def foreign_senders(self) -> dict[str, int]:
        """Datagrams received from each sender that is not the locked one (``address:port``)."""
        with self._lock:
            return {_name(k): v[0] for k, v in self._frames.items() if k != self._sender}

    def frames_from(self, sender: str) -> int:
        """Datagrams received from ``sender`` (``address:port``), locked or not."""
        with self._lock:
            return next((v[0] for k, v in self._frames.items() if _name(k) == sender), 0)

    @property
    def contenders(self) -> list[str]:
        """Foreign senders whose frames carried the controlled object (``address:port``)."""
        with self._lock:
            return sorted(_name(k) for k in self._carriers if k != self._sender)

    def take_events(self) -> list[dict]:
        """Sender events since the last call (``kind`` ``mocap_sender``,
        ``mocap_foreign_sender`` or ``mocap_sender_changed``, with ``sender``), and forget
        them."""
        with self._lock:
            events, self._events = self._events, []
        return events

    # ----------------------------------------------------------------------------- receiver

    def _rx_loop(self) -> None:
        sock = self._sock
        assert sock is not None
        while not self._stop.is_set():
            try:
                data, addr = sock.recvfrom(RECV_BUFFER_BYTES)
            except socket.timeout:
                continue
            except OSError:
                if self._stop.is_set():
                    return
                self._stop.wait(_RX_POLL_S)
                continue
            self._handle(data, self._clock(), (addr[0], addr[1]))

    def feed(self, data: bytes, t_s: float, sender=("lockstep", 0)) -> None:
        """Handle one datagram received at ``t_s`` (link clock) from ``sender`` as the receiver
        thread would: the lockstep simulator delivers its datagrams this way, without a socket."""
        self._handle(data, t_s, sender)

    def feed_frame(self, frame: MocapFrame, t_s: float, sender=("lockstep", 0)) -> None:
        """:meth:`feed` of a datagram already decoded: ``frame`` is what
        :func:`~ardrone_nmpc.protocol.mocap.decode_mocap` makes of its bytes (the lockstep
        simulator's frames: their encoding is exact, float64 poses — no bytes needed)."""
        self.stats.record_datagram()
        self._handle_frame(frame, t_s, sender)

    def feed_object_frames(self, frames, sender=("lockstep", 0)) -> None:
        """:meth:`feed_frame` of each frame of ``frames`` in turn, of frames carrying the
        object ``object_name`` alone: ``(frame_number, t_s, position_m, rotation_xyz_rad)``
        each — the frame ``MocapFrame.of(frame_number, [MocapObjectPose.from_si(object_name,
        position_m, rotation_xyz_rad)])`` received at ``t_s``. The link's state left is the
        calls' one by one (its sender's counts and silence, the stream's statistics, the
        freshness rules'); the frames are not built (the lockstep simulator's quiet ticks)."""
        name = self.object_name
        frames = list(frames)
        while frames and (self._sender != sender or name in self.other_objects):
            number, t_s, position_m, rotation = frames.pop(0)  # (sender lock, events)
            self.feed_frame(MocapFrame.of(number, [MocapObjectPose.from_si(
                name, position_m, rotation)]), t_s, sender)
        if not frames:
            return
        restart_s = self.restart_silence_s
        numbered = []
        with self._lock:  # (_from_locked_sender's, the sender locked and carrying the object)
            count = self._frames[sender]
            last_t = self._sender_t_s
            for number, t_s, _, _ in frames:
                numbered.append((number, t_s, t_s - last_t >= restart_s))
                last_t = t_s
            count[0] += len(frames)
            count[1] = frames[-1][0]
            self._sender_t_s = last_t
        accepted = self.stats.record_numbered(numbered)
        object_frames = []  # (MocapObjectPose.from_si's floats)
        for (_, t_s, (x, y, z), (rx, ry, rz)), ok in zip(frames, accepted):
            if ok:
                object_frames.append((t_s, (float(x) * _MM_PER_M, float(y) * _MM_PER_M,
                                            float(z) * _MM_PER_M),
                                      (float(rx), float(ry), float(rz))))
        self.accept_object_frames(object_frames)

    def _handle(self, data: bytes, t_s: float, sender) -> None:
        stats = self.stats
        stats.record_datagram()
        try:
            frame = decode_mocap(data)
        except MocapError as exc:
            stats.record_malformed()
            self._last_error = f"mocap: {exc}"
            return
        self._handle_frame(frame, t_s, sender)

    def _handle_frame(self, frame: MocapFrame, t_s: float, sender) -> None:
        """A decoded datagram (counted) from ``sender``: its sender locked, its sequence
        checked, its poses accepted."""
        stats = self.stats
        locked, after_silence = self._from_locked_sender(frame, t_s, sender)
        if not locked:
            stats.record_foreign()
            return
        if not stats.accept_sequence(frame.frame_number, restart_ok=after_silence):
            return
        stats.record_packet(t_s)
        self.accept_frame(frame.poses, t_s)

    def _from_locked_sender(self, frame, t_s: float, sender) -> tuple[bool, bool]:
        """Count the frame for its sender; lock onto the first sender of the object, or (after
        ``relock_silence_s``) a new one. Returns (the frame is the locked sender's, it ends a
        silence of ``restart_silence_s`` — its numbering may have restarted)."""
        carries = self.object_name in frame.poses
        with self._lock:
            count = self._frames.setdefault(sender, [0, None])
            if carries:
                self._carriers.add(sender)
            count[0] += 1
            count[1] = frame.frame_number
            locked = self._sender
            silence_s = t_s - self._sender_t_s
            if sender != locked:
                if not carries or (locked is not None and not silence_s >= self.relock_silence_s):
                    if count[0] == 1:  # report each foreign sender once
                        self._events.append({"kind": "mocap_foreign_sender",
                                             "sender": _name(sender), "frame": frame.frame_number,
                                             "carries_object": carries,
                                             "locked_sender": None if locked is None
                                             else _name(locked)})
                    return False, False
                kind = "mocap_sender" if locked is None else "mocap_sender_changed"
                self._events.append({"kind": kind, "sender": _name(sender),
                                     "frame": frame.frame_number})
                self._sender = sender
                silence_s = math.inf   # a new stream: its numbering starts afresh
            self._sender_t_s = t_s
        return True, silence_s >= self.restart_silence_s
