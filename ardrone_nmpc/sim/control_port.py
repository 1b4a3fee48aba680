"""The simulated drone's TCP control port (the drone's 5559): clients connect and keep the
connection open; after ``AT*CTRL=seq,4,0`` the drone writes its configuration text there,
ended by a NUL byte (docs/protocol.md, control port).

One thread accepts loopback connections and drops those the client closed; :meth:`dump` is
called by the firmware (under the drone's lock) and writes to every open connection. A port
that does not answer (a fault) either accepts and never writes (``mode="silent"``) or keeps its
port bound without listening, so connections are refused (``"refused"``).
"""

from __future__ import annotations

import select
import socket
import threading
from typing import Literal

from ardrone_nmpc.sim.addresses import is_loopback_peer

__all__ = ["ControlPort"]

_POLL_S = 0.05              # accept timeout: shutdown latency of the thread
_SEND_TIMEOUT_S = 0.5


class ControlPort:
    """A listening TCP socket on ``(bind_host, port)`` (0 = a free port).

    ``lock`` is the drone's lock; ``counters`` its counters (``control_connections``,
    ``config_dumps`` are counted here, under the lock); ``mode`` "serve", "silent" or
    "refused" (module docstring).
    """

    def __init__(self, bind_host: str, port: int, *, lock, counters,
                 mode: Literal["serve", "silent", "refused"] = "serve") -> None:
        if mode not in ("serve", "silent", "refused"):
            raise ValueError(f"control port mode must be serve, silent or refused, got {mode!r}")
        self.mode = mode
        self.lock = lock
        self.counters = counters
        self.clients: list[socket.socket] = []
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((bind_host, int(port)))
            if mode != "refused":   # bound, not listening: the port is kept, connects refused
                s.listen(4)
            s.settimeout(_POLL_S)
        except BaseException:
            s.close()
            raise
        self._sock = s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return self._sock.getsockname()[1]

    def start(self) -> None:
        if self.mode == "refused":
            return
        self._thread = threading.Thread(target=self._accept_loop, name="drone-server-control",
                                        daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread and close every socket (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
        for s in (self._sock, *self.clients):
            try:
                s.close()
            except OSError:  # pragma: no cover
                pass
        self.clients.clear()

    def dump(self, text: str) -> None:
        """Write ``text`` + NUL to every connected client (call under the lock)."""
        if not self.clients or self.mode != "serve":
            return
        data = text.encode("ascii", errors="replace") + b"\0"
        for s in list(self.clients):
            try:
                s.settimeout(_SEND_TIMEOUT_S)
                s.sendall(data)
            except OSError:
                self.clients.remove(s)
                s.close()
        self.counters.config_dumps += 1

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, addr = self._sock.accept()
            except socket.timeout:
                self._reap()
                continue
            except OSError:
                if self._stop.is_set():
                    break
                continue
            if not is_loopback_peer(addr):   # pragma: no cover - the socket is loopback-bound
                conn.close()
                continue
            with self.lock:
                self.clients.append(conn)
                self.counters.control_connections += 1

    def _reap(self) -> None:
        """Drop connections the client has closed (and discard anything it sent)."""
        with self.lock:
            clients = list(self.clients)
        if not clients:
            return
        readable, _, _ = select.select(clients, [], [], 0)
        for s in readable:
            try:
                s.setblocking(False)
                data = s.recv(4096)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                data = b""
            if not data:
                with self.lock:
                    if s in self.clients:
                        self.clients.remove(s)
                s.close()
