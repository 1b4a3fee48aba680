"""The motion-capture link: the latest fresh pose of one object from the UDP pose stream.

docs/mocap-stream.md, receiver rules. A receiver thread reads datagrams (buffer ≥ 2048 bytes),
stamps each on receipt with the link's clock, decodes it with
:func:`~ardrone_nmpc.protocol.mocap.decode_mocap` (malformed → counted, never raised) and hands
the frame to :meth:`MocapSource.accept_frame
<ardrone_nmpc.links.mocap_source.MocapSource.accept_frame>`, which keeps the newest *fresh* pose
of the configured object as a :class:`~ardrone_nmpc.core.types.MocapPose` (metres, radians, ψ
wrapped to (−π, π], ``t_s`` = receipt time) by the rules every mocap source shares (missing,
zero and repeated poses). Here, on top: a frame number not newer than the last accepted one
(duplicate or reordered datagram, ``stats.out_of_order``) is dropped, unless it is far below it
(a restarted tracker, ``stats.restarts``).

:attr:`MocapLink.stats` counts every datagram with a valid number (so ``rate_hz`` and frame
``lost`` describe the stream itself, whether or not the object was visible) and the malformed
ones. Closing the link stops the thread and closes the socket.
"""

from __future__ import annotations

import socket
import threading
import time

from ardrone_nmpc.links.mocap_source import MocapSource, mocap_pose_of
from ardrone_nmpc.links.udp import RECV_BUFFER_BYTES, Clock, open_udp
from ardrone_nmpc.protocol.mocap import MOCAP_DEFAULT_PORT, MocapError, decode_mocap

__all__ = ["MocapLink", "mocap_pose_of"]

_RX_POLL_S = 0.05


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
    restart_backjump : a frame number this far below the last is a tracker restart.

    Context manager: ``with MocapLink(...) as mocap:`` starts the thread, exit stops it.
    """

    kind = "vicon_udp"

    def __init__(self, bind_host: str = "0.0.0.0", port: int = MOCAP_DEFAULT_PORT, *,
                 object_name: str = "ardrone", clock: Clock = time.monotonic,
                 repeat_limit: int = 3, restart_backjump: int = 1000,
                 other_objects: tuple[str, ...] = ()) -> None:
        super().__init__(object_name=object_name, other_objects=other_objects, clock=clock,
                         repeat_limit=repeat_limit, restart_backjump=restart_backjump)
        self.bind_host = bind_host
        self._requested_port = int(port)
        self._sock: socket.socket | None = None
        self._bound_port: int | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

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

    # ----------------------------------------------------------------------------- receiver

    def _rx_loop(self) -> None:
        sock = self._sock
        assert sock is not None
        while not self._stop.is_set():
            try:
                data = sock.recv(RECV_BUFFER_BYTES)
            except socket.timeout:
                continue
            except OSError:
                if self._stop.is_set():
                    return
                self._stop.wait(_RX_POLL_S)
                continue
            self._handle(data, self._clock())

    def feed(self, data: bytes, t_s: float) -> None:
        """Handle one datagram received at ``t_s`` (link clock) as the receiver thread would:
        the lockstep simulator delivers its datagrams this way, without a socket."""
        self._handle(data, t_s)

    def _handle(self, data: bytes, t_s: float) -> None:
        stats = self.stats
        stats.record_datagram()
        try:
            frame = decode_mocap(data)
        except MocapError as exc:
            stats.record_malformed()
            self._last_error = f"mocap: {exc}"
            return
        if not stats.accept_sequence(frame.frame_number):
            return
        stats.record_packet(t_s)
        self.accept_frame(frame.poses, t_s)
