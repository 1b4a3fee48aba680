"""The AR.Drone 2.0 link: AT-command sender with keepalive, navdata receiver.

docs/protocol.md. Bytes are encoded and decoded by :mod:`ardrone_nmpc.protocol`; this module
owns the sockets, the two threads and the protocol *behaviour*; the configuration handshake
and read-back live in :mod:`ardrone_nmpc.links.drone_config` (mixed into :class:`DroneLink`).

Navdata (§1.1, §4)
    :meth:`DroneLink.connect` binds a UDP socket on an ephemeral port and sends the wake-up
    datagram (``01 00 00 00``) to ``host:navdata_port``; the drone answers to that source port.
    The receiver thread re-sends the wake-up every ``wake_retry_s`` until navdata arrives and,
    once connected, after ``rewake_after_s`` (0.2 s: well inside the session's 0.5 s
    navdata-loss landing, where the SDK's 1 s would come too late) of silence — then it also
    forgets the last navdata sequence (the drone may restart at 1). Only datagrams from the
    drone's address are read. Malformed packets (:class:`NavdataError`) are counted in
    :attr:`DroneLink.stats`, never raised. A packet whose sequence is not newer than the last is
    dropped (SDK, node-ar-drone) unless it is 1 or carries the com-watchdog bit 30 (the drone
    re-initialised). Sequence gaps count as loss. Packets without the demo option (bootstrap)
    update :attr:`DroneLink.state` only.

Connecting (§1.1 step 3)
    A drone whose first packet shows it airborne (state bit 0) is somebody else's flight:
    :meth:`DroneLink.connect` refuses (:class:`DroneAirborne`) before sending any AT command,
    unless ``allow_airborne`` (the operator's ``land``/``emergency``/``status``). Then it
    switches to ``config_ids`` if set, writes ``general:navdata_demo`` and waits for the first
    packet with the demo option.

AT commands (§2)
    The AT socket is bound to local port ``at_local_port`` (5556, as the developer guide asks)
    when it is free; otherwise an ephemeral port is used and :attr:`DroneLink.at_bind_warning`
    says so. One :class:`AtSequencer` numbers every command from 1 under one lock, whichever
    thread sends. The keepalive thread sends, every ``keepalive_interval_s`` (30 ms) on
    absolute deadlines, the current ``AT*REF`` and the latest ``AT*PCMD`` in one datagram, plus
    one ``AT*COMWDG`` after a navdata packet showed the com-watchdog bit 30 outside bootstrap.
    A controller command older than ``stale_command_s`` (250 ms, the drone's own com-watchdog
    time) is replaced by hover (``AT*PCMD=seq,0,0,0,0,0``) and counted.
    **REF semantics (§2.4):** bit 9 is a level — :meth:`DroneLink.takeoff` holds
    ``290718208`` in every keepalive datagram, :meth:`DroneLink.land` holds ``290717696``.
    Before the first of them the link sends **no** REF at all (node-ar-drone #55). Bit 8 acts on
    its rising edge: :meth:`DroneLink.emergency` holds ``290717952`` (primed by one REF with bit
    8 low if this link sent none yet); :meth:`DroneLink.reset_emergency` makes a fresh edge on
    the ground to clear an emergency.
    These commands and the **take-off guard** (the take-off bit dropped at once and for good
    when the drone lands or cuts by itself) are in :mod:`ardrone_nmpc.links.drone_commands`.

Closing the link (``close``/``__exit__``) stops both threads and closes the sockets. It never
sends land: the session decides that, before it closes the link.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Sequence

from ardrone_nmpc.links.drone_commands import _FLYING_MAJORS, FlightCommands, TakeoffGuard
from ardrone_nmpc.protocol.config_text import CONTROL_PORT
from ardrone_nmpc.links.drone_config import (
    ConfigHandshake,
    LinkError,
    check_positive as _check_positive,
    parse_config_text,
)
from ardrone_nmpc.links.udp import (
    RECV_BUFFER_BYTES,
    Clock,
    LinkStats,
    check_host,
    check_port,
    open_udp,
)
from ardrone_nmpc.protocol.at import (
    AT_PORT,
    AtBody,
    AtSequencer,
    Comwdg,
    Pcmd,
    PcmdFlag,
    Ref,
)
from ardrone_nmpc.protocol.navdata import (
    NAVDATA_PORT,
    NAVDATA_WAKEUP,
    CtrlMajor,
    DroneState,
    Navdata,
    NavdataError,
    decode_navdata,
)
from ardrone_nmpc.core.angles import wrap_angle_deg
from ardrone_nmpc.core.types import FlightMode, NavdataSample

__all__ = [
    "CONTROL_PORT", "DEFAULT_HOST", "DroneAirborne", "LinkError", "DroneLink", "flight_mode_of",
    "navdata_sample_of", "parse_config_text",
]

DEFAULT_HOST = "192.168.1.1"
_HOVER = Pcmd.hover()
_RX_POLL_S = 0.05                    # receiver recv timeout: how fast it notices stop / silence


class DroneAirborne(LinkError):
    """The drone was airborne when the link connected: another client is flying it."""


# ----------------------------------------------------------------------------- conversions

_TAKEOFF_MAJORS = (int(CtrlMajor.TRANS_TAKEOFF), int(CtrlMajor.TRANS_GOTOFIX))     # 6 (SDK), 7 (fw)


def flight_mode_of(state: DroneState, ctrl_major: int | None) -> FlightMode:
    """The :class:`FlightMode` shown by a navdata packet.

    Airborne or not is state bit 0 alone, landed is ctrl_state major 2 alone (the codes 6–9
    mean different things in the SDK header and in firmware 2.x). Emergency (bit 31) wins.
    Airborne: major 3/4 (or no demo option) FLYING, 6/7 TAKING_OFF (take-off or go-to-fix in
    either numbering), anything else LANDING — a state nobody may take for flying. On the
    ground (bit 0 clear): major 2 (or no demo option) LANDED, 6/7 TAKING_OFF, anything else
    LANDING — not confirmed down until the drone reports major 2.
    """
    if DroneState.EMERGENCY in state:
        return FlightMode.EMERGENCY
    if ctrl_major in _TAKEOFF_MAJORS:
        return FlightMode.TAKING_OFF
    if DroneState.FLY in state:
        return (FlightMode.FLYING if ctrl_major is None or ctrl_major in _FLYING_MAJORS
                else FlightMode.LANDING)
    return (FlightMode.LANDED if ctrl_major is None or ctrl_major == CtrlMajor.LANDED
            else FlightMode.LANDING)


def navdata_sample_of(packet: Navdata, t_s: float) -> NavdataSample | None:
    """The packet's demo option as a :class:`NavdataSample` stamped ``t_s`` (None without one).

    Units converted (°, m, m/s), signs kept (the drone's body frame), yaw wrapped to (−180, 180].
    """
    d = packet.demo
    if d is None:
        return None
    return NavdataSample(
        t_s=t_s, mode=flight_mode_of(packet.state, d.ctrl_major),
        battery_pct=float(d.battery_pct), roll_deg=d.roll_deg, pitch_deg=d.pitch_deg,
        yaw_deg=wrap_angle_deg(d.yaw_deg), altitude_m=d.altitude_m, vx_body_mps=d.vx_body_mps,
        vy_body_mps=d.vy_body_mps, vz_mps=d.vz_mps, ctrl_state=d.ctrl_state)


def _check_frac(name: str, v: float) -> float:
    if isinstance(v, bool):
        raise TypeError(f"{name} must be a number, got bool")
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v!r}")
    if not -1.0 <= v <= 1.0:
        raise ValueError(f"{name} must be in [-1, 1], got {v!r}")
    return v


def _check_config_id(v: str) -> str:
    if not (isinstance(v, str) and len(v) == 8
            and all(c in "0123456789abcdefABCDEF" for c in v)):
        raise ValueError(f"config ids must be 8 hex digits, got {v!r}")
    return v


# ----------------------------------------------------------------------------- the link


class DroneLink(FlightCommands, ConfigHandshake):
    """AT commands out (UDP ``at_port``), navdata in (UDP ``navdata_port``) — see the module doc.

    Parameters
    ----------
    host : the drone's address (192.168.1.1 on its own Wi-Fi; 127.0.0.1 for the simulator).
    at_port, navdata_port, control_port : UDP 5556, UDP 5554, TCP 5559.
    keepalive_interval_s : REF + PCMD resend period (≤ 30 ms recommended, §2.6).
    stale_command_s : a progressive command older than this is replaced by hover.
    clock : receipt stamps, command times and ages (threads sleep on real time regardless).
    bind_host : local address of the navdata (ephemeral port) and AT sockets.
    at_local_port : local port of the AT socket (5556, the guide's); 0 = ephemeral. A busy
        port falls back to an ephemeral one (:attr:`at_bind_warning`).
    config_ids : ``(session, profile, application)`` 8-hex-digit ids for multiconfig, or None
        (default session, plain ``AT*CONFIG``).
    navdata_demo : the ``general:navdata_demo`` value written at connect (TRUE: 15 Hz demo
        packets; FALSE: full-rate packets, which carry the demo option too).
    allow_airborne : connect to a drone that is already flying (the operator's commands);
        otherwise :meth:`connect` refuses it (:class:`DroneAirborne`).
    rewake_after_s : navdata silence after which the wake-up is re-sent.
    wake_retry_s : wake-up period before the first navdata arrives.
    config_resend_s : ``AT*CONFIG`` resend period while waiting for its ACK.

    Use as a context manager (``with DroneLink(...) as link: link.connect()``); ``__exit__``
    closes the link without landing.
    """

    def __init__(self, host: str = DEFAULT_HOST, *, at_port: int = AT_PORT,
                 navdata_port: int = NAVDATA_PORT, keepalive_interval_s: float = 0.03,
                 stale_command_s: float = 0.25, clock: Clock = time.monotonic,
                 bind_host: str = "0.0.0.0", control_port: int = CONTROL_PORT,
                 config_ids: Sequence[str] | None = None, rewake_after_s: float = 0.2,
                 wake_retry_s: float = 0.2, config_resend_s: float = 0.3,
                 at_local_port: int = AT_PORT, navdata_demo: bool = True,
                 allow_airborne: bool = False) -> None:
        self.host = check_host("drone address", host)
        self.at_port = check_port("AT port", at_port)
        self.navdata_port = check_port("navdata port", navdata_port)
        self.control_port = check_port("control port", control_port)
        self.at_local_port = 0 if at_local_port == 0 else check_port("local AT port",
                                                                     at_local_port)
        self.bind_host = bind_host
        self.navdata_demo = bool(navdata_demo)
        self.allow_airborne = bool(allow_airborne)
        self.at_bind_warning: str | None = None
        """Why the AT socket is not on :attr:`at_local_port` (None when it is, or 0 asked)."""
        self.keepalive_interval_s = _check_positive("keepalive_interval_s", keepalive_interval_s)
        self.stale_command_s = _check_positive("stale_command_s", stale_command_s)
        self.rewake_after_s = _check_positive("rewake_after_s", rewake_after_s)
        self.wake_retry_s = _check_positive("wake_retry_s", wake_retry_s)
        self.config_resend_s = _check_positive("config_resend_s", config_resend_s)
        if config_ids is not None:
            config_ids = tuple(_check_config_id(v) for v in config_ids)
            if len(config_ids) != 3:
                raise ValueError("config_ids must be (session, profile, application)")
        self.config_ids: tuple[str, str, str] | None = config_ids  # type: ignore[assignment]
        self._clock = clock

        self._host_ip: str | None = None
        self._nav_sock: socket.socket | None = None
        self._at_sock: socket.socket | None = None
        self._rx_thread: threading.Thread | None = None
        self._tx_thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._opened = False
        self._closed = False
        self._connected = False

        # AT side (guarded by _at_lock)
        self._at_lock = threading.Lock()
        self._seq = AtSequencer()
        self._ref: Ref | None = None
        self._pcmd: Pcmd = _HOVER
        self._cmd_t_s: float | None = None
        self._stale = False
        self._comwdg_pending = False
        self._sent_count = 0
        self._sent_commands = 0
        self._send_errors = 0
        self._stale_hovers = 0
        self._stale_episodes = 0
        self._comwdg_sent = 0
        self._last_send_error: str | None = None
        self._takeoff_barred: str | None = None   # why the take-off bit may never go out again
        self._self_landing: str | None = None     # the drone landed/cut by itself: what it showed
        self._guard = TakeoffGuard()              # the drone landing by itself, since take-off

        # navdata side (guarded by _nav_cond)
        self._nav_cond = threading.Condition()
        self._nav_index = 0                   # accepted packets so far
        self._state: DroneState | None = None
        self._navdata: NavdataSample | None = None
        self._navdata_rx_t_s = -math.inf
        self._last_nav_mono = -math.inf
        self._last_wake_mono = -math.inf
        self._wakeups = 0
        self._rewakes = 0
        self._last_decode_error: str | None = None
        self.stats = LinkStats(window_s=1.0, restart_backjump=1000)
        """Navdata receive statistics (rate, loss from sequence gaps, malformed, age)."""

        self._config_lock = threading.Lock()

    # ----------------------------------------------------------------------------- lifecycle

    def __enter__(self) -> DroneLink:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def connect(self, timeout_s: float = 5.0) -> None:
        """Open the sockets, wake the navdata stream, leave bootstrap (``navdata_demo TRUE``
        with the ACK handshake; first the session switch if ``config_ids`` is set) and wait
        for the first demo packet, all within ``timeout_s``.

        Raises :class:`LinkError` (the link is closed again) if no navdata arrives, a config is
        not acknowledged, or demo navdata does not follow; OSError-derived failures to resolve
        or bind are wrapped in :class:`LinkError` too.
        """
        timeout_s = _check_positive("timeout_s", timeout_s)
        if self._closed:
            raise LinkError("this DroneLink was closed; create a new one")
        if self._opened:
            raise LinkError("already connected")
        deadline = time.monotonic() + timeout_s
        self._opened = True
        try:
            try:
                self._host_ip = socket.gethostbyname(self.host)
                self._nav_sock = open_udp(self.bind_host, 0, timeout_s=_RX_POLL_S)
                self._at_sock = self._open_at_socket()
            except OSError as exc:
                raise LinkError(f"cannot open the drone link to {self.host}: {exc}") from exc
            self._rx_thread = threading.Thread(target=self._rx_loop, name="drone-navdata-rx",
                                               daemon=True)
            self._rx_thread.start()
            with self._nav_cond:
                got = self._nav_cond.wait_for(
                    lambda: self._nav_index > 0 or self._stop.is_set(),
                    max(0.0, deadline - time.monotonic()))
            if not got or self._nav_index == 0:
                raise LinkError(
                    f"no navdata from {self.host}:{self.navdata_port} within {timeout_s:.2f} s "
                    f"({self._wakeups} wake-up datagrams sent, {self.stats.malformed} malformed "
                    "packets received); is the drone's Wi-Fi joined?")
            state = self._state
            if state is not None and DroneState.FLY in state and not self.allow_airborne:
                raise DroneAirborne(
                    f"the drone at {self.host} is airborne (navdata state bit 0): another "
                    "client is flying it — not taking it over; land it with `ardrone-nmpc "
                    f"land --drone {self.host}` (or from its own client) first")
            self._tx_thread = threading.Thread(target=self._tx_loop, name="drone-at-keepalive",
                                               daemon=True)
            self._tx_thread.start()
            if self.config_ids is not None:
                for key, value in zip(("custom:session_id", "custom:profile_id",
                                       "custom:application_id"), self.config_ids):
                    self.write_config(key, value, timeout_s=self._remaining(deadline, key))
            self.write_config("general:navdata_demo", self.navdata_demo,
                              timeout_s=self._remaining(deadline, "general:navdata_demo"))
            with self._nav_cond:
                ok = self._nav_cond.wait_for(
                    lambda: self._navdata is not None or self._stop.is_set(),
                    max(0.0, deadline - time.monotonic()))
            if not ok or self._navdata is None:
                raise LinkError(f"navdata from {self.host} still in bootstrap mode (no demo "
                                f"option) {timeout_s:.2f} s after connecting, although "
                                "general:navdata_demo was acknowledged")
            self._connected = True
        except BaseException:
            self.close()
            raise

    def _open_at_socket(self) -> socket.socket:
        """The AT socket, on local port :attr:`at_local_port` when it is free."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if self.at_local_port:
            try:
                sock.bind((self.bind_host, self.at_local_port))
            except OSError as exc:
                self.at_bind_warning = (f"local UDP port {self.at_local_port} is busy ({exc}); "
                                        "AT commands go out from an ephemeral port")
        return sock

    def close(self) -> None:
        """Stop the threads and close the sockets (idempotent). Sends nothing — no land."""
        self._closed = True
        self._connected = False
        self._stop.set()
        with self._nav_cond:
            self._nav_cond.notify_all()
        for t in (self._tx_thread, self._rx_thread):
            if t is not None and t is not threading.current_thread():
                t.join(timeout=2.0)
        with self._at_lock:
            for s in (self._at_sock, self._nav_sock):
                if s is not None:
                    s.close()
            self._at_sock = None
            self._nav_sock = None

    @property
    def connected(self) -> bool:
        """True between a successful :meth:`connect` and :meth:`close`."""
        return self._connected

    @staticmethod
    def _remaining(deadline: float, what: str) -> float:
        r = deadline - time.monotonic()
        if r <= 0.0:
            raise LinkError(f"connect timed out before {what}")
        return r

    # ----------------------------------------------------------------------------- readings

    @property
    def navdata(self) -> NavdataSample | None:
        """The latest demo navdata sample (None before the first)."""
        return self._navdata

    @property
    def navdata_rx_t_s(self) -> float:
        """Receipt time (link clock) of :attr:`navdata`; −inf before the first."""
        return self._navdata_rx_t_s

    @property
    def state(self) -> DroneState | None:
        """State bits of the latest accepted navdata packet (bootstrap packets included)."""
        return self._state

    @property
    def sent_count(self) -> int:
        """AT datagrams sent."""
        return self._sent_count

    @property
    def sent_commands(self) -> int:
        """AT commands sent (several per datagram); also ``next seq − 1``."""
        return self._sent_commands

    @property
    def send_errors(self) -> int:
        """Datagrams the socket refused (OSError); the last message is :attr:`last_error`."""
        return self._send_errors

    @property
    def stale_hovers(self) -> int:
        """Keepalive datagrams that carried hover because the command was stale."""
        return self._stale_hovers

    @property
    def stale_episodes(self) -> int:
        """Times the controller command went stale (fresh → stale transitions)."""
        return self._stale_episodes

    @property
    def comwdg_sent(self) -> int:
        """``AT*COMWDG`` commands sent in answer to state bit 30."""
        return self._comwdg_sent

    @property
    def wakeups(self) -> int:
        """Wake-up datagrams sent to the navdata port (initial retries and re-wakes)."""
        return self._wakeups

    @property
    def rewakes(self) -> int:
        """Re-wakes after navdata silence (> ``rewake_after_s``) once data had flowed."""
        return self._rewakes

    @property
    def last_error(self) -> str | None:
        """The latest send or decode error message (diagnostics)."""
        return self._last_send_error or self._last_decode_error

    @property
    def ref(self) -> Ref | None:
        """The REF held by the keepalive (None before the first take-off/land/emergency)."""
        return self._ref

    @property
    def command(self) -> Pcmd:
        """The latest PCMD set (what the keepalive sends while it is fresh)."""
        return self._pcmd

    # ----------------------------------------------------------------------------- commands

    def set_command(self, roll_frac: float, pitch_frac: float, gaz_frac: float,
                    yaw_frac: float, *, progressive: bool = True) -> None:
        """Set the PCMD the keepalive repeats, and send it now (if the link is open).

        Fractions of the configured limits, each finite and in [−1, 1] (ValueError otherwise;
        the mapping saturates and flags before this). ``progressive=False`` sends hover
        (flag 0, values ignored). The set time (link clock) is what staleness is measured from.
        """
        values = (_check_frac("roll_frac", roll_frac), _check_frac("pitch_frac", pitch_frac),
                  _check_frac("gaz_frac", gaz_frac), _check_frac("yaw_frac", yaw_frac))
        pcmd = Pcmd.move(*values) if progressive else _HOVER
        with self._at_lock:
            self._set_pcmd_locked(pcmd, self._clock())
            if self._at_sock is not None and not self._stop.is_set():
                self._send_current_locked(raise_errors=False)

    def hover(self) -> None:
        """Command hover (PCMD flag 0: the drone holds position on its bottom camera)."""
        self.set_command(0.0, 0.0, 0.0, 0.0, progressive=False)

    # ----------------------------------------------------------------------------- AT sending

    def _require_open(self) -> None:
        if self._at_sock is None or self._stop.is_set():
            raise LinkError("the drone link is not connected")

    def _set_pcmd_locked(self, pcmd: Pcmd, t_s: float | None) -> None:
        self._pcmd = pcmd
        self._cmd_t_s = t_s
        self._stale = False

    def _current_bodies_locked(self, now_s: float, count: bool) -> list[AtBody]:
        bodies: list[AtBody] = []
        if self._ref is not None:
            bodies.append(self._ref)
        pcmd = self._pcmd
        if (pcmd.flags & PcmdFlag.PROGRESSIVE and self._cmd_t_s is not None
                and now_s - self._cmd_t_s > self.stale_command_s):
            pcmd = _HOVER
            if count:
                self._stale_hovers += 1
                if not self._stale:
                    self._stale_episodes += 1
                    self._stale = True
        bodies.append(pcmd)
        if self._comwdg_pending:
            self._comwdg_pending = False
            self._comwdg_sent += 1
            bodies.append(Comwdg())
        return bodies

    def _send_current_locked(self, *, raise_errors: bool, count: bool = True) -> None:
        self._send_locked(self._current_bodies_locked(self._clock(), count), raise_errors)

    def _send(self, bodies: list[AtBody], *, raise_errors: bool) -> None:
        with self._at_lock:
            if self._at_sock is None:
                if raise_errors:
                    raise LinkError("the drone link is closed")
                return
            self._send_locked(bodies, raise_errors)

    def _send_locked(self, bodies: list[AtBody], raise_errors: bool) -> None:
        sock = self._at_sock
        if sock is None:
            if raise_errors:
                raise LinkError("the drone link is closed")
            return
        datagrams = self._seq.pack(bodies)
        self._sent_commands += len(bodies)
        for d in datagrams:
            try:
                sock.sendto(d, (self._host_ip, self.at_port))
                self._sent_count += 1
            except OSError as exc:
                self._send_errors += 1
                self._last_send_error = f"AT send to {self.host}:{self.at_port}: {exc}"
                if raise_errors:
                    raise LinkError(self._last_send_error) from exc

    def _tx_loop(self) -> None:
        period = self.keepalive_interval_s
        next_t = time.monotonic()
        while not self._stop.is_set():
            with self._at_lock:
                if self._at_sock is None:
                    return
                self._send_current_locked(raise_errors=False)
            next_t += period
            now = time.monotonic()
            if next_t < now - period:      # fell behind (suspended): restart, don't burst
                next_t = now
            if self._stop.wait(max(0.0, next_t - now)):
                return

    # ----------------------------------------------------------------------------- navdata

    def _send_wakeup(self, now_mono: float) -> None:
        sock = self._nav_sock
        if sock is None:
            return
        try:
            sock.sendto(NAVDATA_WAKEUP, (self._host_ip, self.navdata_port))
            self._wakeups += 1
        except OSError as exc:
            self._last_send_error = f"navdata wake-up to {self.host}:{self.navdata_port}: {exc}"
        self._last_wake_mono = now_mono

    def _rx_loop(self) -> None:
        sock = self._nav_sock
        assert sock is not None
        while not self._stop.is_set():
            now = time.monotonic()
            had_data = self._last_nav_mono > -math.inf
            retry = self.rewake_after_s if had_data else self.wake_retry_s
            if now - self._last_nav_mono > retry and now - self._last_wake_mono >= retry:
                if had_data:                   # silence: the drone may restart its numbering
                    self._rewakes += 1
                    self.stats.reset_sequence()
                self._send_wakeup(now)
            try:
                data, addr = sock.recvfrom(RECV_BUFFER_BYTES)
            except socket.timeout:
                continue
            except OSError:
                if self._stop.is_set():
                    return
                self._stop.wait(_RX_POLL_S)    # e.g. ICMP port unreachable on some platforms
                continue
            self._handle_navdata(data, addr)

    def _handle_navdata(self, data: bytes, addr) -> None:
        t_s = self._clock()
        stats = self.stats
        stats.record_datagram()
        if addr[0] != self._host_ip:
            stats.record_foreign()
            return
        try:
            packet = decode_navdata(data)
        except NavdataError as exc:
            stats.record_malformed()
            self._last_decode_error = f"navdata: {exc}"
            return
        self._last_nav_mono = time.monotonic()
        state = packet.state
        if not stats.accept_sequence(packet.sequence):
            if packet.sequence == 1 or DroneState.COM_WATCHDOG in state:
                stats.reset_sequence()         # the drone re-initialised its stream
                stats.accept_sequence(packet.sequence)
            else:
                return
        sample = navdata_sample_of(packet, t_s)
        with self._nav_cond:
            self._state = state
            self._nav_index += 1
            if sample is not None:
                self._navdata = sample
                self._navdata_rx_t_s = t_s
            self._nav_cond.notify_all()
        stats.record_packet(t_s)
        self._watch_takeoff(state, packet)
        if (DroneState.COM_WATCHDOG in state
                and DroneState.NAVDATA_BOOTSTRAP not in state):
            self._comwdg_pending = True
