"""UDP helpers shared by the links: socket opening, the clock protocol, receive statistics.

:class:`LinkStats` is updated by a receiver thread and read by anyone (its own lock): datagrams
read, packets accepted, a sliding-window receive rate, loss from sequence (navdata) or frame
(mocap) number gaps, malformed and out-of-order counts, the last receipt time and the age.
Times are whatever the link's :class:`Clock` returns (seconds, monotonic).
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Protocol

__all__ = ["Clock", "DEFAULT_CLOCK", "RECV_BUFFER_BYTES", "check_host", "check_port", "open_udp",
           "LinkStats", "LinkStatsSnapshot"]

# Receive buffer for one datagram: ≥ 2048 for padded mocap datagrams, > 4096 (navdata maximum)
# so an oversized navdata packet arrives whole and is rejected by the decoder, not truncated.
RECV_BUFFER_BYTES = 8192


class Clock(Protocol):
    """A zero-argument callable returning monotonic seconds (``time.monotonic`` by default;
    a manual clock in tests). Used for receipt stamps, command times and ages only — the
    threads themselves always sleep on real time."""

    def __call__(self) -> float: ...


def check_port(name: str, port) -> int:
    """``port`` as an int in 1–65535, or ValueError naming ``name``: 0 ("any port") and
    negative numbers are user errors here, never a silent fall-back to a default."""
    if isinstance(port, bool) or not isinstance(port, int):
        raise ValueError(f"{name} must be a port number 1–65535, got {port!r}")
    if not 1 <= port <= 65535:
        raise ValueError(f"{name} must be a port number 1–65535, got {port}")
    return port


def check_host(name: str, host) -> str:
    """``host`` as a non-empty address or host name without spaces, or ValueError."""
    if not isinstance(host, str) or not host.strip() or any(c.isspace() for c in host):
        raise ValueError(f"{name} must be an address or host name, got {host!r}")
    return host


def open_udp(bind_host: str, port: int = 0, *, timeout_s: float | None) -> socket.socket:
    """A bound IPv4 UDP socket with a receive timeout.

    Parameters
    ----------
    bind_host : local address to bind (``"0.0.0.0"`` all interfaces, ``"127.0.0.1"`` loopback).
    port : local port; 0 picks a free one (read it back with ``sock.getsockname()[1]``).
    timeout_s : ``recv`` timeout in seconds (None blocks; a receiver thread should pass a short
        timeout so it notices a stop request).

    Raises OSError if the address cannot be bound; the socket is closed on failure.
    """
    if timeout_s is not None and not (math.isfinite(timeout_s) and timeout_s > 0.0):
        raise ValueError(f"timeout_s must be > 0 or None, got {timeout_s!r}")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        try:   # a roomy kernel buffer: a 100 Hz stream must survive a GC pause of the reader
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        except OSError:
            pass
        sock.bind((bind_host, int(port)))
        sock.settimeout(timeout_s)
    except BaseException:
        sock.close()
        raise
    return sock


@dataclass(frozen=True, slots=True)
class LinkStatsSnapshot:
    """A consistent copy of :class:`LinkStats` at ``now_s`` (for logs and summaries).

    Attributes
    ----------
    datagrams : datagrams read (accepted, malformed, out of order, foreign).
    packets : datagrams accepted (decoded, in sequence).
    lost : sequence/frame numbers skipped between accepted packets.
    loss_frac : lost / (packets + lost); 0 before any packet.
    malformed : datagrams the decoder rejected.
    out_of_order : decoded datagrams whose number was not newer than the last (duplicates,
        reordering), dropped.
    foreign : datagrams from an unexpected source, dropped.
    restarts : sequence restarts accepted (the sender re-initialised its numbering).
    rate_hz : accepted packets per second over the sliding window (see :attr:`LinkStats.rate_hz`).
    last_rx_t_s : receipt time of the last accepted packet (−inf before the first).
    age_ms : ``now_s − last_rx_t_s`` in ms (inf before the first packet).
    """

    datagrams: int
    packets: int
    lost: int
    loss_frac: float
    malformed: int
    out_of_order: int
    foreign: int
    restarts: int
    rate_hz: float
    last_rx_t_s: float
    age_ms: float


class LinkStats:
    """Receive statistics of one stream; thread-safe (writer: the receiver thread).

    Parameters
    ----------
    window_s : length of the sliding window the rate is measured over (s).
    restart_backjump : a sequence number this far *below* the last accepted one is taken as the
        sender restarting its numbering (accepted, counted in ``restarts``) rather than as a
        late duplicate (dropped, counted in ``out_of_order``).
    """

    def __init__(self, window_s: float = 1.0, restart_backjump: int = 100) -> None:
        if not (math.isfinite(window_s) and window_s > 0.0):
            raise ValueError(f"window_s must be > 0, got {window_s!r}")
        if restart_backjump < 1:
            raise ValueError(f"restart_backjump must be >= 1, got {restart_backjump}")
        self.window_s = float(window_s)
        self.restart_backjump = int(restart_backjump)
        self._lock = threading.Lock()
        self._times: deque[float] = deque()
        self._datagrams = 0
        self._packets = 0
        self._lost = 0
        self._malformed = 0
        self._out_of_order = 0
        self._foreign = 0
        self._restarts = 0
        self._last_seq: int | None = None
        self._last_rx_t_s = -math.inf

    # ----------------------------------------------------------------------------- writers

    def record_datagram(self) -> None:
        """One datagram read from the socket (whatever becomes of it)."""
        with self._lock:
            self._datagrams += 1

    def record_malformed(self) -> None:
        """One datagram the decoder rejected."""
        with self._lock:
            self._malformed += 1

    def record_foreign(self) -> None:
        """One datagram from an unexpected source address."""
        with self._lock:
            self._foreign += 1

    def accept_sequence(self, seq: int | None, *, restart_ok: bool = False) -> bool:
        """Whether a decoded packet numbered ``seq`` is new; updates the gap and order counts.

        The first number after construction or :meth:`reset_sequence` is always accepted; then
        ``seq > last`` is accepted and ``seq − last − 1`` numbers count as lost; ``seq`` more than
        ``restart_backjump`` below ``last`` is a restart (accepted, no loss counted); anything
        else is a duplicate or reordered packet (rejected) — unless ``restart_ok`` (the caller
        knows the sender may have restarted: after a silence), then it is a restart too.
        ``None`` (unnumbered) is accepted.
        Call :meth:`record_packet` for accepted packets.
        """
        if seq is None:
            return True
        with self._lock:
            return self._accept_locked(seq, restart_ok)

    def _accept_locked(self, seq: int, restart_ok: bool) -> bool:
        last = self._last_seq
        if last is None:
            self._last_seq = seq
            return True
        if seq > last:
            self._lost += seq - last - 1
            self._last_seq = seq
            return True
        if restart_ok or last - seq > self.restart_backjump:
            self._restarts += 1
            self._last_seq = seq
            return True
        self._out_of_order += 1
        return False

    def reset_sequence(self) -> None:
        """Forget the last sequence number (after a re-wake: the sender may restart at 1)."""
        with self._lock:
            self._last_seq = None

    def record_packet(self, t_s: float) -> None:
        """One accepted packet received at ``t_s``."""
        with self._lock:
            self._record_locked(t_s)

    def _record_locked(self, t_s: float) -> None:
        self._packets += 1
        self._last_rx_t_s = t_s
        times = self._times
        times.append(t_s)
        cutoff = t_s - self.window_s
        while times and times[0] < cutoff:
            times.popleft()

    def record_numbered(self, numbered) -> list[bool]:
        """:meth:`record_datagram`, :meth:`accept_sequence` and, if accepted,
        :meth:`record_packet` of each ``(seq, t_s, restart_ok)`` of ``numbered`` in turn
        (``seq`` an int), under one lock: the state the calls one by one leave (a lockstep
        receiver's bulk receipt). Returns whether each was accepted."""
        accepted = []
        append = accepted.append
        with self._lock:
            self._datagrams += len(numbered)
            times, window_s = self._times, self.window_s
            last, lost, packets = self._last_seq, 0, 0
            for seq, t_s, restart_ok in numbered:
                # (the usual frame, a newer number: _accept_locked's and _record_locked's
                # steps spelled out — a lockstep flight's quiet ticks take ~8 a tick)
                if last is not None and seq > last:
                    lost += seq - last - 1
                    last = seq
                else:
                    self._last_seq, self._lost = last, self._lost + lost
                    lost = 0
                    ok = self._accept_locked(seq, restart_ok)
                    last = self._last_seq
                    if not ok:
                        append(False)
                        continue
                packets += 1
                self._last_rx_t_s = t_s
                times.append(t_s)
                cutoff = t_s - window_s
                while times and times[0] < cutoff:
                    times.popleft()
                append(True)
            self._last_seq, self._lost = last, self._lost + lost
            self._packets += packets
        return accepted

    # ----------------------------------------------------------------------------- readers

    @property
    def datagrams(self) -> int:
        return self._datagrams

    @property
    def packets(self) -> int:
        return self._packets

    @property
    def lost(self) -> int:
        return self._lost

    @property
    def malformed(self) -> int:
        return self._malformed

    @property
    def out_of_order(self) -> int:
        return self._out_of_order

    @property
    def foreign(self) -> int:
        return self._foreign

    @property
    def restarts(self) -> int:
        return self._restarts

    @property
    def last_rx_t_s(self) -> float:
        """Receipt time of the last accepted packet (−inf before the first)."""
        return self._last_rx_t_s

    def _loss_frac_locked(self) -> float:
        total = self._packets + self._lost
        return self._lost / total if total else 0.0

    def _rate_locked(self) -> float:
        if len(self._times) < 2:
            return 0.0
        span = self._times[-1] - self._times[0]
        return (len(self._times) - 1) / span if span > 0.0 else 0.0

    @property
    def loss_frac(self) -> float:
        """lost / (packets + lost); 0.0 before any packet."""
        with self._lock:
            return self._loss_frac_locked()

    @property
    def rate_hz(self) -> float:
        """Accepted packets per second over the window ending at the last receipt:
        (n − 1) / (t_last − t_first) of the n packets in it; 0.0 with fewer than two.

        It describes the stream while it runs; when it stops, :meth:`age_ms` grows instead.
        """
        with self._lock:
            return self._rate_locked()

    def age_ms(self, now_s: float) -> float:
        """Milliseconds since the last accepted packet (inf before the first)."""
        return (now_s - self._last_rx_t_s) * 1e3

    def snapshot(self, now_s: float) -> LinkStatsSnapshot:
        """All counters at once, consistent with each other (for a log row or a summary)."""
        with self._lock:
            return LinkStatsSnapshot(
                datagrams=self._datagrams, packets=self._packets, lost=self._lost,
                loss_frac=self._loss_frac_locked(), malformed=self._malformed,
                out_of_order=self._out_of_order, foreign=self._foreign, restarts=self._restarts,
                rate_hz=self._rate_locked(), last_rx_t_s=self._last_rx_t_s,
                age_ms=(now_s - self._last_rx_t_s) * 1e3)


DEFAULT_CLOCK: Clock = time.monotonic
