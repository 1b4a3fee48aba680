"""The operator's link: act first, ask later (``land``, ``emergency``; docs/first-flight.md §8).

:class:`~ardrone_nmpc.links.drone_link.DroneLink` connects before it commands anything: wake
navdata, leave bootstrap with the ACK handshake, wait for demo packets. An operator who must
bring a drone down cannot wait for that — a drone left in another multiconfig session never
acknowledges a plain CONFIG, and a dead navdata stream answers nothing. :class:`OperatorLink`
turns the order round (docs/protocol.md §2.2, §2.4):

* :meth:`OperatorLink.start` sends the command — REF land, or the emergency: REF land then REF
  emergency, a 0 → 1 edge of bit 8 — in the very first datagram, from the caller's thread,
  before a navdata socket has seen anything; a thread repeats REF land every ``interval_s``
  (30 ms) until :meth:`close`.
* Every datagram is self-contained and numbered from 1: seq 1 restarts the drone's counter, so
  whatever client spoke before — a ``fly`` at seq 40 000, a crashed FreeFlight — the drone
  takes each of them whole (REF, then ``AT*PCMD`` hover).
* Bit 8 acts on each 0 → 1 edge: a second edge toggles the emergency (on the ground it clears
  it). So after its edge the link holds bit 8 low again, as the repeats of REF land: no datagram
  of its own, interleaved with another client's, can make a second edge; and a drone that
  missed the edge (a lost datagram) lands on them instead. Another edge is made only when asked
  (:meth:`emergency`: the caller saw a fresh packet without the cut).
* Navdata only confirms, and only once asked (:meth:`wake_navdata`: a ``fly`` holding the drone
  keeps its stream until it lets go). Any packet counts — the state word is in every one,
  bootstrap packets included (:attr:`state`, :attr:`packet_mode`). A bootstrap packet is
  answered as the SDK does (``ardrone_general_navdata.c``): ``AT*CONFIG general:navdata_demo``
  (after ``AT*CONFIG_IDS`` with ``config_ids``) at most every :data:`BOOTSTRAP_ANSWER_EVERY_S`,
  never waited for; a raised ACK bit is cleared with ``AT*CTRL 5``.

It offers what :meth:`~ardrone_nmpc.runtime.session.FlightSession.land` reads of a link
(``land``, ``emergency``, ``connected`` and the
:class:`~ardrone_nmpc.links.readings.PacketReadings`), so the operator's landing is the
session's landing. Closing never sends anything more. Nothing it imports loads the numerical
stack: the first datagram goes out as soon as the command line is parsed.
"""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from collections.abc import Sequence

from ardrone_nmpc.links.drone_config import LinkError, check_config_id
from ardrone_nmpc.links.readings import PacketReadings
from ardrone_nmpc.links.udp import RECV_BUFFER_BYTES, Clock, check_host, check_port
from ardrone_nmpc.protocol.at import (
    AT_PORT,
    CTRL_MODE_ACK,
    AtBody,
    AtSequencer,
    Config,
    ConfigIds,
    Ctrl,
    Pcmd,
    Ref,
)
from ardrone_nmpc.protocol.navdata import (
    NAVDATA_PORT,
    NAVDATA_WAKEUP,
    DroneState,
    NavdataError,
    decode_navdata,
)

__all__ = ["BOOTSTRAP_ANSWER_EVERY_S", "OperatorLink", "WAKE_EVERY_S"]

WAKE_EVERY_S = 0.2                  # wake-up re-sent after this much navdata silence
BOOTSTRAP_ANSWER_EVERY_S = 0.5      # navdata_demo re-sent at most this often in bootstrap
_COMMANDS = ("land", "emergency")


class OperatorLink(PacketReadings):
    """REF land / emergency first, navdata after (module doc).

    Parameters
    ----------
    host, at_port, navdata_port : the drone (192.168.1.1, 5556, 5554).
    config_ids : ``(session, profile, application)`` ids for the bootstrap answer, or None.
    bind_host : local address of both sockets.
    at_local_port : local port of the AT socket (5556 as the guide asks; 0 or busy →
        ephemeral).
    interval_s : repeat period of the command (≤ 30 ms, docs/protocol.md §2.6).
    clock : receipt stamps (:attr:`state_rx_t_s`).
    """

    def __init__(self, host: str, *, at_port: int = AT_PORT, navdata_port: int = NAVDATA_PORT,
                 config_ids: Sequence[str] | None = None, bind_host: str = "0.0.0.0",
                 at_local_port: int = AT_PORT, interval_s: float = 0.03,
                 clock: Clock = time.monotonic) -> None:
        self.host = check_host("drone address", host)
        self.at_port = check_port("AT port", at_port)
        self.navdata_port = check_port("navdata port", navdata_port)
        if config_ids is not None:
            config_ids = tuple(check_config_id(v) for v in config_ids)
            if len(config_ids) != 3:
                raise ValueError("config_ids must be (session, profile, application)")
        self.config_ids = config_ids
        self.bind_host = bind_host
        self.at_local_port = at_local_port
        if not (math.isfinite(interval_s) and 0.0 < interval_s <= 0.03):
            raise ValueError(f"interval_s must be in (0, 0.03], got {interval_s!r}")
        self.interval_s = float(interval_s)
        self._clock = clock
        self._lock = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._at: socket.socket | None = None
        self._nav: socket.socket | None = None
        self._host_ip: str | None = None
        self._prime = False            # the next datagram carries the emergency's 0 → 1 edge
        self._waking = False
        self._last_wake = -math.inf
        self._last_rx = -math.inf      # monotonic time of the last packet (wake-up timing)
        self._last_answer = -math.inf
        self._init_readings()
        self.sent_datagrams = 0
        """AT datagrams sent."""
        self.packets = 0
        """Navdata packets decoded (any kind)."""
        self.malformed = 0
        """Datagrams from the drone's address that did not decode."""
        self.bootstrap_answers = 0
        """Datagrams that carried the bootstrap answer."""
        self.edges = 0
        """Emergency edges sent (REF bit 8 low, then high, in one datagram)."""
        self.last_edge_t = -math.inf
        """Monotonic time of the last edge."""
        self.last_error: str | None = None
        """The last send error (diagnostics)."""

    # ----------------------------------------------------------------------------- lifecycle

    def start(self, command: str, *, edge_sent: bool = False) -> None:
        """Open the sockets, send ``command`` ("land" or "emergency") now, and keep sending it.
        ``edge_sent``: the emergency's edge went out already (the entry point,
        :mod:`ardrone_nmpc.cli.first_datagram`): this link's first datagram holds bit 8 low.

        Raises :class:`LinkError` if the address does not resolve or the first datagram
        cannot be sent."""
        if command not in _COMMANDS:
            raise ValueError(f"command must be one of {_COMMANDS}, got {command!r}")
        if self._at is not None or self._stop.is_set():
            raise LinkError("this OperatorLink was started already")
        try:
            self._host_ip = socket.gethostbyname(self.host)
            self._at = self._open(self.at_local_port, fall_back=True)
            self._nav = self._open(0)
        except OSError as exc:
            self.close()
            raise LinkError(f"cannot open a link to {self.host}: {exc}") from exc
        with self._lock:
            self._prime = command == "emergency" and not edge_sent
            self._send_locked(raise_errors=True)
        self._thread = threading.Thread(target=self._loop, name="operator-link", daemon=True)
        self._thread.start()

    def _open(self, port: int, fall_back: bool = False) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.bind_host, port))
        except OSError:
            if not fall_back:
                sock.close()
                raise
            sock.bind((self.bind_host, 0))   # local port 5556 busy: the drone takes any
        return sock

    def close(self) -> None:
        """Stop sending and close the sockets (idempotent). Sends nothing more."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        with self._lock:
            for sock in (self._at, self._nav):
                if sock is not None:
                    sock.close()
            self._lock.notify_all()

    def __enter__(self) -> OperatorLink:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ----------------------------------------------------------------------------- commands

    def land(self) -> None:
        """Send REF land now (it is what every datagram holds; the session's landing calls)."""
        self._send_now(edge=False)

    def emergency(self) -> None:
        """Cut the motors: an edge of bit 8 in a datagram now (then REF land again) — unless
        the latest packet shows the drone in emergency already (an edge would clear it)."""
        state = self._state
        self._send_now(edge=state is None or DroneState.EMERGENCY not in state)

    def _send_now(self, edge: bool) -> None:
        with self._lock:
            if self._stop.is_set() or self._at is None:
                raise LinkError("the operator link is closed")
            self._prime = edge
            self._send_locked(raise_errors=True)

    def wake_navdata(self) -> None:
        """Start waking the navdata stream (and keep it awake) to confirm the command."""
        with self._lock:
            self._waking = True

    # ----------------------------------------------------------------------------- readings

    @property
    def connected(self) -> bool:
        """True while the command is being sent."""
        return self._at is not None and not self._stop.is_set()

    def wait_for(self, predicate, timeout_s: float) -> bool:
        """Wait until ``predicate(self)`` holds (checked on every packet); False on timeout."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while not predicate(self):
                remaining = deadline - time.monotonic()
                if remaining <= 0.0 or self._stop.is_set():
                    return predicate(self)
                self._lock.wait(min(remaining, 0.05))
            return True

    # ----------------------------------------------------------------------------- the thread

    def _bodies_locked(self, now: float) -> list[AtBody]:
        bodies: list[AtBody] = [Ref.landing()]
        if self._prime:               # the edge: low (the REF land above), then high
            bodies.append(Ref.emergency())
            self._prime = False
            self.edges += 1
            self.last_edge_t = now
        bodies.append(Pcmd.hover())
        state = self._state
        if state is not None and DroneState.NAVDATA_BOOTSTRAP in state \
                and now - self._last_answer >= BOOTSTRAP_ANSWER_EVERY_S:
            self._last_answer = now
            self.bootstrap_answers += 1
            if self.config_ids is not None:
                bodies.append(ConfigIds(*self.config_ids))
            bodies.append(Config.of("general:navdata_demo", True))
        elif state is not None and DroneState.COMMAND in state:
            bodies.append(Ctrl(CTRL_MODE_ACK, 0))
        return bodies

    def _send_locked(self, raise_errors: bool) -> None:
        sock = self._at
        if sock is None:
            return
        datagrams = AtSequencer().pack(self._bodies_locked(time.monotonic()))  # from seq 1
        for data in datagrams:
            try:
                sock.sendto(data, (self._host_ip, self.at_port))
                self.sent_datagrams += 1
            except OSError as exc:
                self.last_error = f"AT send to {self.host}:{self.at_port}: {exc}"
                if raise_errors:
                    raise LinkError(self.last_error) from exc

    def _loop(self) -> None:
        next_send = time.monotonic() + self.interval_s
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_send:
                with self._lock:
                    if self._stop.is_set():
                        return
                    self._send_locked(raise_errors=False)
                next_send = max(next_send + self.interval_s, now)
            if self._waking and now - self._last_rx > WAKE_EVERY_S \
                    and now - self._last_wake >= WAKE_EVERY_S:
                self._last_wake = now
                try:
                    self._nav.sendto(NAVDATA_WAKEUP, (self._host_ip, self.navdata_port))
                except OSError as exc:
                    self.last_error = f"navdata wake-up: {exc}"
            try:
                ready, _, _ = select.select([self._nav], [], [],
                                            max(0.0, min(next_send - now, 0.05)))
                if ready:
                    data, addr = self._nav.recvfrom(RECV_BUFFER_BYTES)
                    if addr[0] == self._host_ip:
                        self._on_packet(data)
            except (OSError, ValueError):
                if self._stop.wait(0.05):
                    return

    def _on_packet(self, data: bytes) -> None:
        # the conversions load the numerical stack: imported at the first packet, long after
        # the first datagram went out
        from ardrone_nmpc.links.drone_link import flight_mode_of, navdata_sample_of

        t_s = self._clock()
        try:
            packet = decode_navdata(data)
        except NavdataError:
            self.malformed += 1
            return
        major = packet.demo.ctrl_major if packet.demo is not None else None
        mode, sample = flight_mode_of(packet.state, major), navdata_sample_of(packet, t_s)
        with self._lock:
            self._last_rx = time.monotonic()
            self.packets += 1
            self._note_packet(packet.state, mode, sample, t_s)
            self._lock.notify_all()
