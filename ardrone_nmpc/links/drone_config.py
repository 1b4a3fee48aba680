"""The drone's configuration over the link: the ACK handshake, the read-back and its check.

docs/protocol.md §3 (keys, handshake, multiconfig) and §1.3 (control port). Split from
:mod:`ardrone_nmpc.links.drone_link` by concept: :class:`ConfigHandshake` is the part of
:class:`~ardrone_nmpc.links.drone_link.DroneLink` that talks configuration (it uses the link's
sockets, locks and navdata state), and :func:`verify_config` compares what was written with
what the drone says it holds.

Every :meth:`~ConfigHandshake.write_config` is one key at a time: clear a pending ACK first
(``AT*CTRL=seq,5,0``), send ``AT*CONFIG`` (re-sent every ``config_resend_s`` — UDP may drop
it), wait for state bit 6 in a packet received *after* the send, send ``AT*CTRL=seq,5,0``
(re-sent every 50 ms, node-ar-drone) until bit 6 reads 0. With ``config_ids`` set,
``AT*CONFIG_IDS`` precedes every ``AT*CONFIG`` in the same datagram, as the SDK does.

An ACK only says the drone *received* the write: a drone in another multiconfig session, or
one that keeps an outdoor profile, acknowledges and keeps its own values. That is why the
session reads the configuration back (TCP ``control_port``, ``AT*CTRL=seq,4,0``, text up to a
NUL byte) and refuses to take off on any difference (:func:`verify_config`).
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ardrone_nmpc.errors import UserError
from ardrone_nmpc.protocol.at import (
    CTRL_MODE_ACK,
    CTRL_MODE_CFG_GET,
    AtBody,
    Config,
    ConfigIds,
    Ctrl,
)
from ardrone_nmpc.protocol.config_text import EULER_ANGLE_MAX_LIMIT_RAD, parse_config_text
from ardrone_nmpc.protocol.navdata import DroneState

__all__ = ["ConfigHandshake", "ConfigMismatch", "EULER_ANGLE_MAX_LIMIT_RAD", "LinkError",
           "check_config_id", "parse_config_text", "verify_config"]

_CTRL_ACK_RESEND_S = 0.05            # node-ar-drone resends CTRL 5 every 50 ms
_CONFIG_DUMP_MAX_BYTES = 1 << 20
_CONFIG_GET_RESEND_S = 0.5           # CTRL 4 resend period while the dump has not started
# "Beyond rounding": the firmware stores these keys as float32 and prints them back with a few
# digits (0.2094 → "2.0940000e-01"); a part in a thousand is far below any real difference
# (the outdoor profile's 0.35 vs 0.21 rad, 1000 vs 700 mm/s).
_REL_TOLERANCE = 1e-3


class LinkError(UserError, RuntimeError):
    """The drone link failed: no navdata, no config acknowledgement, a closed link, a socket
    error on an explicit command. The message says which and after how long."""


@dataclass(frozen=True, slots=True)
class ConfigMismatch:
    """One key the drone does not hold as written (``held`` None: absent from its dump)."""

    key: str
    written: str
    held: str | None

    def line(self) -> str:
        """The one-line refusal: the key, both values and what to do."""
        held = "nothing (key missing)" if self.held is None else repr(self.held)
        return (f"the drone holds {self.key} = {held}, not the {self.written!r} written: it "
                "did not keep the write — a drone in another multiconfig session keeps its "
                "own limits: set drone.config_ids to that session (`ardrone-nmpc status` shows "
                "its ids and what it holds), then retry")


def _same(written: str, held: str) -> bool:
    w, h = written.strip(), held.strip()
    # A boolean written compares case-insensitively. One held against a number needs no case
    # of its own: float() reads neither TRUE nor FALSE, so it ends in the exact text comparison.
    if w.upper() in ("TRUE", "FALSE"):
        return w.upper() == h.upper()
    try:
        a, b = float(w), float(h)
    except ValueError:
        return w == h
    if not (math.isfinite(a) and math.isfinite(b)):
        return False
    return abs(a - b) <= _REL_TOLERANCE * max(abs(a), abs(b), 1e-9)


def verify_config(written: Mapping[str, str], held: Mapping[str, str]) -> list[ConfigMismatch]:
    """The keys of ``written`` that ``held`` (a read-back) lacks or holds differently beyond
    rounding (a relative 1e-3 for numbers; TRUE/FALSE case-insensitively), in written order."""
    out = []
    for key, value in written.items():
        got = held.get(key)
        if got is None or not _same(str(value), got):
            out.append(ConfigMismatch(key, str(value), got))
    return out


def _number_text(x: float) -> int | float:
    """A config number: whole values as int (``1000``), others as the float (``0.35``)."""
    r = round(x, 6)
    return int(r) if r == int(r) else x


def check_config_id(v: str) -> str:
    """A multiconfig id: 8 hex digits (ValueError otherwise)."""
    if not (isinstance(v, str) and len(v) == 8
            and all(c in "0123456789abcdefABCDEF" for c in v)):
        raise ValueError(f"config ids must be 8 hex digits, got {v!r}")
    return v



def check_positive(name: str, v: float) -> float:
    v = float(v)
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {v!r}")
    return v


class ConfigHandshake:
    """The configuration half of :class:`~ardrone_nmpc.links.drone_link.DroneLink` (a mixin:
    it needs the link's ``_send``, ``_require_open``, ``_config_lock``, ``_nav_cond``,
    ``_nav_index``, ``_state``, ``_stop``, ``_host_ip``, ``control_port`` and ``config_ids``)."""

    def write_config(self, key: str, value: bool | int | float | str,
                     timeout_s: float = 1.0) -> str:
        """Write one configuration key with the ACK handshake (module doc); returns the value
        text sent. Raises :class:`LinkError` when the drone does not acknowledge within
        ``timeout_s`` (the message names the key and the step), ValueError/TypeError for a
        value the wire cannot carry."""
        timeout_s = check_positive("timeout_s", timeout_s)
        cfg = Config.of(key, value)
        what = f"config {key}={cfg.value!r}"
        with self._config_lock:
            self._require_open()
            deadline = time.monotonic() + timeout_s
            self._clear_ack(deadline, f"{what}: a previous ACK")
            index = self._nav_index
            bodies: list[AtBody] = ([ConfigIds(*self.config_ids)] if self.config_ids else [])
            bodies.append(cfg)
            send = lambda: self._send(bodies, raise_errors=True)  # noqa: E731
            send()
            if not self._await_state(lambda s: DroneState.COMMAND in s, index,
                                     deadline - time.monotonic(), send, self.config_resend_s):
                raise LinkError(f"{what}: no ACK from the drone (state bit 6 not set within "
                                f"{timeout_s:.2f} s)")
            self._clear_ack(deadline, what)
        return cfg.value

    def configure_limits(self, euler_angle_max_rad: float, control_vz_max_mps: float,
                         control_yaw_radps: float, altitude_max_m: float, *,
                         timeout_s: float = 1.0) -> dict[str, str]:
        """Write the four command limits (§3.1 units: rad, **mm/s**, rad/s, **mm**), each with
        the ACK handshake; returns ``{key: value text}`` as written.

        ``euler_angle_max_rad`` must be in (0, 0.52]; the others finite and > 0 (the drone's
        recommended ranges are 200–2000 mm/s and 0.7–6.11 rad/s; values outside them are sent
        as given). ``timeout_s`` applies to each key.
        """
        e = check_positive("euler_angle_max_rad", euler_angle_max_rad)
        if e > EULER_ANGLE_MAX_LIMIT_RAD:
            raise ValueError(f"euler_angle_max_rad must be <= {EULER_ANGLE_MAX_LIMIT_RAD} "
                             f"(30°), got {e!r}")
        vz_mmps = check_positive("control_vz_max_mps", control_vz_max_mps) * 1000.0
        yaw = check_positive("control_yaw_radps", control_yaw_radps)
        alt_mm = round(check_positive("altitude_max_m", altitude_max_m) * 1000.0)
        if alt_mm < 1:
            raise ValueError(f"altitude_max_m must be at least 1 mm, got {altitude_max_m!r}")
        written: dict[str, str] = {}
        for key, value in (("control:euler_angle_max", e),
                           ("control:control_vz_max", _number_text(vz_mmps)),
                           ("control:control_yaw", yaw),
                           ("control:altitude_max", int(alt_mm))):
            written[key] = self.write_config(key, value, timeout_s)
        return written

    def configure_profile(self, *, flight_without_shell: bool,
                          timeout_s: float = 1.0) -> dict[str, str]:
        """Write the keys that change what the limits mean: ``control:outdoor`` FALSE (the
        outdoor profile swaps in its own tilt/climb/yaw triple), ``control:flight_without_shell``
        (the hull fitted) and ``control:flying_mode`` 0 (free flight, no roundel hover)."""
        written: dict[str, str] = {}
        for key, value in (("control:outdoor", False),
                           ("control:flight_without_shell", bool(flight_without_shell)),
                           ("control:flying_mode", 0)):
            written[key] = self.write_config(key, value, timeout_s)
        return written

    def read_config(self, timeout_s: float = 2.0) -> dict[str, str]:
        """Read the drone's whole configuration over TCP ``control_port`` (§1.3).

        Connects, clears a pending ACK, sends ``AT*CTRL=seq,4,0``, reads text up to the NUL
        byte (``CTRL 4`` is re-sent every 0.5 s until the first byte arrives: UDP may drop it),
        then clears the ACK the drone raises (``CTRL 5``). Returns ``{"section:key":
        "value"}``. Raises :class:`LinkError` if the port refuses, the dump does not end within
        ``timeout_s`` or the connection closes early.
        """
        timeout_s = check_positive("timeout_s", timeout_s)
        with self._config_lock:
            self._require_open()
            deadline = time.monotonic() + timeout_s
            try:
                tcp = socket.create_connection((self._host_ip, self.control_port),
                                               timeout=timeout_s)
            except OSError as exc:
                raise LinkError(f"control port {self.host}:{self.control_port}: {exc}") from exc
            try:
                self._clear_ack(deadline, "read_config: a previous ACK")
                index = self._nav_index
                buf = self._read_dump(tcp, deadline, timeout_s)
            finally:
                tcp.close()
            text = bytes(buf[:buf.index(b"\0")]).decode("ascii", errors="replace")
            # The drone raises ACK after the dump; clear it so the next config can go (a short
            # grace past the deadline: the dump itself is already here).
            grace = max(deadline, time.monotonic() + 0.3)
            if self._await_state(lambda s: DroneState.COMMAND in s, index,
                                 grace - time.monotonic()):
                self._clear_ack(grace, "read_config")
        return parse_config_text(text)

    def _read_dump(self, tcp: socket.socket, deadline: float, timeout_s: float) -> bytearray:
        self._send([Ctrl(CTRL_MODE_CFG_GET, 0)], raise_errors=True)
        next_resend = time.monotonic() + _CONFIG_GET_RESEND_S
        buf = bytearray()
        while b"\0" not in buf:
            now = time.monotonic()
            remaining = deadline - now
            if remaining <= 0.0:
                raise LinkError(f"configuration dump not finished within "
                                f"{timeout_s:.2f} s ({len(buf)} bytes read)")
            if not buf and now >= next_resend:   # CTRL 4 lost (UDP) or sent too early
                self._send([Ctrl(CTRL_MODE_CFG_GET, 0)], raise_errors=True)
                next_resend = now + _CONFIG_GET_RESEND_S
            tcp.settimeout(min(remaining, max(1e-3, next_resend - now))
                           if not buf else remaining)
            try:
                chunk = tcp.recv(4096)
            except socket.timeout:
                continue
            except OSError as exc:
                raise LinkError(f"control port read failed: {exc}") from exc
            if not chunk:
                raise LinkError("control port closed before the configuration's NUL "
                                f"terminator ({len(buf)} bytes read)")
            buf += chunk
            if len(buf) > _CONFIG_DUMP_MAX_BYTES:
                raise LinkError("configuration dump over 1 MiB without a NUL byte")
        return buf

    def _clear_ack(self, deadline: float, what: str) -> None:
        """If state bit 6 is set: send ``CTRL 5`` (every 50 ms) until a packet shows it clear."""
        state = self._state
        if state is None or DroneState.COMMAND not in state:
            return
        index = self._nav_index
        send = lambda: self._send([Ctrl(CTRL_MODE_ACK, 0)], raise_errors=True)  # noqa: E731
        send()
        if not self._await_state(lambda s: DroneState.COMMAND not in s, index,
                                 deadline - time.monotonic(), send, _CTRL_ACK_RESEND_S):
            raise LinkError(f"{what}: ACK (state bit 6) not cleared by AT*CTRL 5 in time")

    def _await_state(self, predicate: Callable[[DroneState], bool], after_index: int,
                     timeout_s: float, resend: Callable[[], None] | None = None,
                     resend_every_s: float = math.inf) -> bool:
        """Wait for a navdata packet accepted after ``after_index`` whose state satisfies
        ``predicate``; call ``resend`` every ``resend_every_s`` meanwhile. False on timeout or
        when the link closes."""
        now = time.monotonic()
        deadline = now + max(0.0, timeout_s)
        next_resend = now + resend_every_s if resend is not None else math.inf
        while True:
            with self._nav_cond:
                if (self._nav_index > after_index and self._state is not None
                        and predicate(self._state)):
                    return True
                now = time.monotonic()
                if now >= deadline or self._stop.is_set():
                    return False
                self._nav_cond.wait(min(deadline, next_resend) - now)
            if resend is not None and time.monotonic() >= next_resend:
                resend()
                next_resend += resend_every_s
