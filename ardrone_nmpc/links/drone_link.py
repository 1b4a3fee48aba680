"""The AR.Drone 2.0 link: AT-command sender with keepalive, navdata receiver, config handshake.

specs/ardrone-protocol.md. Bytes are encoded and decoded by :mod:`ardrone_nmpc.protocol`; this
module owns the sockets, the two threads and the protocol *behaviour*:

Navdata (§1.1, §4)
    :meth:`DroneLink.connect` binds a UDP socket on an ephemeral port and sends the wake-up
    datagram (``01 00 00 00``) to ``host:navdata_port``; the drone answers to that source port.
    The receiver thread re-sends the wake-up every ``wake_retry_s`` until navdata arrives and,
    once connected, after more than ``rewake_after_s`` (1 s, the SDK's value) of silence — then
    it also forgets the last navdata sequence (the drone may restart at 1). Only datagrams from
    the drone's address are read. Malformed packets (:class:`NavdataError`) are counted in
    :attr:`DroneLink.stats`, never raised. A packet whose sequence is not newer than the last is
    dropped (SDK, node-ar-drone) unless it is 1 or carries the com-watchdog bit 30 (the drone
    re-initialised; §2.6 "reset the navdata seq expectation"). Sequence gaps count as loss.
    Packets without the demo option (bootstrap) update :attr:`DroneLink.state` only.

Bootstrap exit and configuration (§1.1 step 3, §3.2, §3.3)
    :meth:`DroneLink.connect` writes ``general:navdata_demo = TRUE`` with the ACK handshake and
    waits for the first demo packet. Every :meth:`DroneLink.write_config` is one key at a time:
    clear a pending ACK first (``AT*CTRL=seq,5,0``), send ``AT*CONFIG`` (re-sent every
    ``config_resend_s`` — UDP may drop it), wait for state bit 6 in a packet received *after*
    the send, send ``AT*CTRL=seq,5,0`` (re-sent every 50 ms, node-ar-drone) until bit 6 reads
    0; any step past ``timeout_s`` raises :class:`LinkError`.
    **Multiconfig:** by default the link stays in the default session and sends plain
    ``AT*CONFIG`` — §3.3: CONFIG_IDS is required only once a non-default session is active, the
    keys this tool writes (``general:navdata_demo``, the ``control:*`` limits) are writable in the
    default session, and node-ar-drone flies 2.0 drones this way. Passing
    ``config_ids=(session, profile, application)`` switches to that session at connect (writes
    ``custom:session_id``/``profile_id``/``application_id``) and precedes every ``AT*CONFIG``
    with ``AT*CONFIG_IDS`` in the same datagram (SDK, cvdrone).
    **Read-back:** :meth:`DroneLink.read_config` implements §1.3 (TCP ``control_port`` 5559,
    ``AT*CTRL=seq,4,0``, text up to a NUL byte, ACK cleared with ``CTRL 5``).

AT commands (§2)
    One :class:`AtSequencer` numbers every command from 1 under one lock, whichever thread
    sends. The keepalive thread sends, every ``keepalive_interval_s`` (30 ms, §2.6) on absolute
    deadlines, the current ``AT*REF`` and the latest ``AT*PCMD`` in one datagram, plus one
    ``AT*COMWDG`` after a navdata packet showed the com-watchdog bit 30 outside bootstrap (SDK
    behaviour). A controller command older than ``stale_command_s`` (250 ms, the drone's own
    com-watchdog time) is replaced by hover (``AT*PCMD=seq,0,0,0,0,0``: flag 0 = position hold)
    and counted. Commands are also sent at once when set, so the keepalive only *re*-sends.
    **REF semantics (§2.4):** bit 9 is a level — :meth:`DroneLink.takeoff` holds
    ``290718208`` in every keepalive datagram while flying, :meth:`DroneLink.land` holds
    ``290717696``. Before the first of them the link sends **no** REF at all (absence of REF
    neither takes off nor lands, §2.4), so connecting to a drone that is already flying does not
    land it (node-ar-drone #55); that decision belongs to the session. Bit 8 acts on its rising
    edge: :meth:`DroneLink.emergency` holds ``290717952`` (a lost datagram cannot swallow the
    edge, and holding it cannot toggle twice); :meth:`DroneLink.reset_emergency` makes a fresh
    edge on the ground to clear an emergency.

Closing the link (``close``/``__exit__``) stops both threads and closes the sockets. It never
sends land: the session decides that, before it closes the link.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Callable, Sequence

from ardrone_nmpc.links.udp import RECV_BUFFER_BYTES, Clock, LinkStats, open_udp
from ardrone_nmpc.protocol.at import (
    AT_PORT,
    CTRL_MODE_ACK,
    CTRL_MODE_CFG_GET,
    AtBody,
    AtSequencer,
    Comwdg,
    Config,
    ConfigIds,
    Ctrl,
    Ftrim,
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
from ardrone_nmpc.errors import UserError

__all__ = [
    "CONTROL_PORT", "DEFAULT_HOST", "LinkError", "DroneLink", "flight_mode_of",
    "navdata_sample_of", "parse_config_text",
]

DEFAULT_HOST = "192.168.1.1"
CONTROL_PORT = 5559                  # TCP: configuration dump after AT*CTRL=seq,4,0 (§1.3)
EULER_ANGLE_MAX_LIMIT_RAD = 0.52     # control:euler_angle_max range 0 … 0.52 (30°), §3.1
_HOVER = Pcmd.hover()
_RX_POLL_S = 0.05                    # receiver recv timeout: how fast it notices stop / silence
_CTRL_ACK_RESEND_S = 0.05            # node-ar-drone resends CTRL 5 every 50 ms
_CONFIG_DUMP_MAX_BYTES = 1 << 20
_CONFIG_GET_RESEND_S = 0.5           # CTRL 4 resend period while the dump has not started


class LinkError(UserError, RuntimeError):
    """The drone link failed: no navdata, no config acknowledgement, a closed link, a socket
    error on an explicit command. The message says which and after how long."""


# ----------------------------------------------------------------------------- conversions

_TAKEOFF_MAJORS = (int(CtrlMajor.TRANS_TAKEOFF), int(CtrlMajor.TRANS_GOTOFIX))     # 6 (SDK), 7 (fw)
_LANDING_MAJORS = (int(CtrlMajor.TRANS_LANDING), int(CtrlMajor.TRANS_LOOPING))     # 8 (SDK), 9 (fw)
_FLYING_MAJORS = (int(CtrlMajor.FLYING), int(CtrlMajor.HOVERING))


def flight_mode_of(state: DroneState, ctrl_major: int | None) -> FlightMode:
    """The :class:`FlightMode` shown by a navdata packet (§4.5 client advice).

    Emergency (bit 31) wins; then the transition codes — 6 or 7 take-off, 8 or 9 landing (the
    SDK header says 6/8, real 2.x firmware reports 7/9; this client never flies 'go to fix' or
    loops, so both readings are safe); 3/4 flying, 2 landed; any other code (0 default, 1 init,
    10 flip, …) or no demo option falls back to state bit 0 (airborne/landed).
    """
    if DroneState.EMERGENCY in state:
        return FlightMode.EMERGENCY
    if ctrl_major is not None:
        if ctrl_major in _TAKEOFF_MAJORS:
            return FlightMode.TAKING_OFF
        if ctrl_major in _LANDING_MAJORS:
            return FlightMode.LANDING
        if ctrl_major in _FLYING_MAJORS:
            return FlightMode.FLYING
        if ctrl_major == CtrlMajor.LANDED:
            return FlightMode.LANDED
    return FlightMode.FLYING if DroneState.FLY in state else FlightMode.LANDED


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
        vy_body_mps=d.vy_body_mps, vz_mps=d.vz_mps)


def parse_config_text(text: str) -> dict[str, str]:
    """The configuration dump of TCP 5559 (``section:key = value`` lines) as a dict.

    A plain-text line split, kept here because :mod:`ardrone_nmpc.protocol` has no config-text
    codec yet; it belongs there (and the simulator's dump writer with it).
    """
    out: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        key = key.strip()
        if sep and key:
            out[key] = value.strip()
    return out


def _number_text(x: float) -> int | float:
    """A config number: whole values as int (``1000``), others as the float (``0.35``)."""
    r = round(x, 6)
    return int(r) if r == int(r) else x


def _check_frac(name: str, v: float) -> float:
    if isinstance(v, bool):
        raise TypeError(f"{name} must be a number, got bool")
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v!r}")
    if not -1.0 <= v <= 1.0:
        raise ValueError(f"{name} must be in [-1, 1], got {v!r}")
    return v


def _check_positive(name: str, v: float) -> float:
    v = float(v)
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {v!r}")
    return v


def _check_config_id(v: str) -> str:
    if not (isinstance(v, str) and len(v) == 8
            and all(c in "0123456789abcdefABCDEF" for c in v)):
        raise ValueError(f"config ids must be 8 hex digits, got {v!r}")
    return v


# ----------------------------------------------------------------------------- the link


class DroneLink:
    """AT commands out (UDP ``at_port``), navdata in (UDP ``navdata_port``) — see the module doc.

    Parameters
    ----------
    host : the drone's address (192.168.1.1 on its own Wi-Fi; 127.0.0.1 for the simulator).
    at_port, navdata_port, control_port : UDP 5556, UDP 5554, TCP 5559.
    keepalive_interval_s : REF + PCMD resend period (≤ 30 ms recommended, §2.6).
    stale_command_s : a progressive command older than this is replaced by hover.
    clock : receipt stamps, command times and ages (threads sleep on real time regardless).
    bind_host : local address of the navdata socket (ephemeral port).
    config_ids : ``(session, profile, application)`` 8-hex-digit ids for multiconfig, or None
        (default session, plain ``AT*CONFIG``).
    rewake_after_s : navdata silence after which the wake-up is re-sent (SDK: 1 s).
    wake_retry_s : wake-up period before the first navdata arrives.
    config_resend_s : ``AT*CONFIG`` resend period while waiting for its ACK.

    Use as a context manager (``with DroneLink(...) as link: link.connect()``); ``__exit__``
    closes the link without landing.
    """

    def __init__(self, host: str = DEFAULT_HOST, *, at_port: int = AT_PORT,
                 navdata_port: int = NAVDATA_PORT, keepalive_interval_s: float = 0.03,
                 stale_command_s: float = 0.25, clock: Clock = time.monotonic,
                 bind_host: str = "0.0.0.0", control_port: int = CONTROL_PORT,
                 config_ids: Sequence[str] | None = None, rewake_after_s: float = 1.0,
                 wake_retry_s: float = 0.2, config_resend_s: float = 0.3) -> None:
        self.host = host
        self.at_port = int(at_port)
        self.navdata_port = int(navdata_port)
        self.control_port = int(control_port)
        self.bind_host = bind_host
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
                self._at_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
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
            self._tx_thread = threading.Thread(target=self._tx_loop, name="drone-at-keepalive",
                                               daemon=True)
            self._tx_thread.start()
            if self.config_ids is not None:
                for key, value in zip(("custom:session_id", "custom:profile_id",
                                       "custom:application_id"), self.config_ids):
                    self.write_config(key, value, timeout_s=self._remaining(deadline, key))
            self.write_config("general:navdata_demo", True,
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

    def takeoff(self) -> None:
        """Hold REF take-off (bit 9 = 1) from now on; the command is reset to hover."""
        with self._at_lock:
            self._require_open()
            if self._state is not None and DroneState.EMERGENCY in self._state:
                raise LinkError("take-off refused: the drone is in emergency (state bit 31); "
                                "call reset_emergency() on the ground first")
            self._ref = Ref.takeoff()
            self._set_pcmd_locked(_HOVER, None)
            self._send_current_locked(raise_errors=True)

    def land(self) -> None:
        """Hold REF land (bit 9 = 0) from now on; the command is reset to hover."""
        with self._at_lock:
            self._require_open()
            self._ref = Ref.landing()
            self._set_pcmd_locked(_HOVER, None)
            self._send_current_locked(raise_errors=True)

    def emergency(self) -> None:
        """Cut the motors: hold REF with bit 8 (its rising edge acts) and bit 9 = 0."""
        with self._at_lock:
            self._require_open()
            self._ref = Ref.emergency()
            self._set_pcmd_locked(_HOVER, None)
            self._send_current_locked(raise_errors=True)

    def reset_emergency(self, timeout_s: float = 2.0) -> None:
        """Clear an emergency on the ground: REF bit 8 low for two keepalive periods, then high
        until navdata shows bit 31 cleared, then REF land. Refused unless the latest navdata
        shows the emergency bit (an edge on a drone *not* in emergency would cut its motors).
        Raises :class:`LinkError` if bit 31 is still set after ``timeout_s``.
        """
        timeout_s = _check_positive("timeout_s", timeout_s)
        state = self._state
        if state is None or DroneState.EMERGENCY not in state:
            raise LinkError("reset_emergency refused: navdata does not show an emergency")
        with self._at_lock:
            self._require_open()
            self._ref = Ref.landing()
            self._set_pcmd_locked(_HOVER, None)
            self._send_current_locked(raise_errors=True)
        if self._stop.wait(2.0 * self.keepalive_interval_s):
            raise LinkError("link closed during reset_emergency")
        with self._nav_cond:
            index = self._nav_index
        try:
            with self._at_lock:
                self._require_open()
                self._ref = Ref.emergency()
                self._send_current_locked(raise_errors=True)
            if not self._await_state(lambda s: DroneState.EMERGENCY not in s, index, timeout_s):
                raise LinkError(f"emergency not cleared (state bit 31 still set after "
                                f"{timeout_s:.2f} s)")
        finally:
            with self._at_lock:
                self._ref = Ref.landing()
                if self._at_sock is not None:
                    self._send_current_locked(raise_errors=False)

    def flat_trim(self) -> None:
        """``AT*FTRIM``: current attitude = level. Only on the ground on a level surface;
        refused (LinkError) while navdata shows the drone flying."""
        with self._at_lock:
            self._require_open()
            if self._state is not None and DroneState.FLY in self._state:
                raise LinkError("flat trim refused: the drone is flying (state bit 0)")
            self._send_locked([Ftrim()], raise_errors=True)

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

    # ----------------------------------------------------------------------------- configuration

    def write_config(self, key: str, value: bool | int | float | str,
                     timeout_s: float = 1.0) -> str:
        """Write one configuration key with the ACK handshake (module doc); returns the value
        text sent. Raises :class:`LinkError` when the drone does not acknowledge within
        ``timeout_s`` (the message names the key and the step), ValueError/TypeError for a
        value the wire cannot carry."""
        timeout_s = _check_positive("timeout_s", timeout_s)
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
        the ACK handshake; returns ``{key: value text}`` as written, for the session's log.

        ``euler_angle_max_rad`` must be in (0, 0.52]; the others finite and > 0 (the drone's
        recommended ranges are 200–2000 mm/s and 0.7–6.11 rad/s; values outside them are sent
        as given). ``timeout_s`` applies to each key.
        """
        e = _check_positive("euler_angle_max_rad", euler_angle_max_rad)
        if e > EULER_ANGLE_MAX_LIMIT_RAD:
            raise ValueError(f"euler_angle_max_rad must be <= {EULER_ANGLE_MAX_LIMIT_RAD} "
                             f"(30°), got {e!r}")
        vz_mmps = _check_positive("control_vz_max_mps", control_vz_max_mps) * 1000.0
        yaw = _check_positive("control_yaw_radps", control_yaw_radps)
        alt_mm = round(_check_positive("altitude_max_m", altitude_max_m) * 1000.0)
        if alt_mm < 1:
            raise ValueError(f"altitude_max_m must be at least 1 mm, got {altitude_max_m!r}")
        written: dict[str, str] = {}
        for key, value in (("control:euler_angle_max", e),
                           ("control:control_vz_max", _number_text(vz_mmps)),
                           ("control:control_yaw", yaw),
                           ("control:altitude_max", int(alt_mm))):
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
        timeout_s = _check_positive("timeout_s", timeout_s)
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
        if (DroneState.COM_WATCHDOG in state
                and DroneState.NAVDATA_BOOTSTRAP not in state):
            self._comwdg_pending = True
