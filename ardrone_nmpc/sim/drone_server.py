"""Loopback AR.Drone 2.0: AT commands in, navdata out, over real UDP on 127.0.0.1.

Serves an :class:`~ardrone_nmpc.sim.plant.AirframePlant` with the drone's wire protocol
(specs/ardrone-protocol.md) so that the project's own links — or an unmodified third-party
client (python-ardrone, node-ar-drone style: wake-up, ``AT*REF`` take-off, ``AT*PCMD``,
``AT*REF`` land) — fly it as they would fly the real drone.

Threads (all sharing :attr:`DroneServer.lock` with each other and with a
:class:`~ardrone_nmpc.sim.mocap_server.MocapServer` given the same lock):

* **physics** — advances the plant on the monotonic clock in ``step_s`` increments against
  absolute deadlines (plant time = whole steps since start; a late wake-up advances all the
  steps due, so plant time never drifts from wall time), evaluates the communication
  watchdogs and the altitude cap.
* **AT receiver** (UDP ``at_port``) — :func:`~ardrone_nmpc.protocol.at.parse_datagram_lenient`;
  malformed commands and datagrams are counted and ignored; commands are applied in datagram
  order under the sequence-number rule (§2.2).
* **navdata** (UDP ``navdata_port``) — waits for a wake-up datagram, then streams to the
  source address of the last datagram received on the port: bootstrap packets (header +
  checksum, state bits 10+11) until ``general:navdata_demo`` is written, then demo packets at
  ``demo_rate_hz`` (15 Hz) or, with ``navdata_demo = FALSE``, full-rate packets at
  ``full_rate_hz`` (200 Hz).
* **control** (optional TCP ``control_port``, the drone's 5559) — accepts connections;
  ``AT*CTRL=seq,4,0`` writes the configuration text (``section:key = value`` lines + NUL).

Behaviour (protocol §5; [?] marks the spec's design choices, taken as written there)
------------------------------------------------------------------------------------
* Sequence numbers: a command runs only if ``seq == 1`` or ``seq > last``; ``last`` resets
  to 0 after :attr:`link_loss_s` (2 s) without an accepted command [?]. Ignored commands are
  counted (``at_commands_stale``) and are no traffic for the watchdogs, so a client restarted
  with a high seq is accepted again after 2 s.
* ``AT*REF``: only bits 8 and 9 are read. Bit 9 is a level — set while landed (not in
  emergency, battery ≥ the plant's take-off floor) takes off; clear while taking off or flying
  lands. Bit 8 acts on its 0→1 edge between successive REFs: not in emergency → emergency
  (motors cut, the drone falls; state bits 31 and 16); in emergency and on the ground →
  cleared [?].
* ``AT*PCMD`` / ``AT*PCMD_MAG``: flag bit 0 set → the four fractions go to
  :meth:`AirframePlant.command` (the plant clips to [−1, 1] and ignores them unless flying);
  flag bit 0 clear → hover (position hold). ``psi`` of PCMD_MAG is ignored.
* Altitude cap (rule 8): a climbing gaz is replaced by 0 (ctrl minor ALT_OUT_ZONE) once the
  altitude where the climb would stop — z + v_z·(command delay + τ_z) — reaches
  ``control:altitude_max``. The plant has no altitude limit of its own, so the cap acts on the
  command, ahead of the plant's delay; the drone stops close to (not exactly at) the cap.
  ``control:altitude_min`` is not enforced.
* ``AT*FTRIM``: accepted (counted) only when landed; no state change. ``AT*CALIB``: accepted
  (counted) only in flight; the spin manoeuvre is not simulated.
* ``AT*CONFIG``: stored in :attr:`config`; sets the command-ACK bit 6 until ``AT*CTRL=…,5``.
  ``control:euler_angle_max`` (rad, clamped to 0.52), ``control:control_vz_max`` (mm/s,
  clamped to 200–2000), ``control:control_yaw`` (rad/s, clamped to 0.7–6.11) replace the
  plant's params (``PlantParams.replace``);
  ``control:altitude_max`` (mm) sets the cap; ``general:navdata_demo`` leaves bootstrap
  (TRUE = demo packets, FALSE = full rate); ``general:navdata_options`` selects the options
  the simulator can produce (bit 0 demo, bit 1 time, bit 16 vision_detect). Values that do
  not parse are stored and acknowledged but not applied. ``AT*CONFIG_IDS`` is stored; the
  multiconfiguration rules (§3.3) are not enforced — every CONFIG is taken as in the default
  session, which is what minimal clients rely on.
* ``AT*CTRL``: mode 5 clears bit 6; mode 4 writes the configuration on the control port (if
  served) and sets bit 6; mode 6 writes an empty custom-config list and sets bit 6.
* ``AT*COMWDG`` and unknown commands (``ANIM``, ``LED``…) are accepted traffic; COMWDG
  clears the com-watchdog bit.
* Watchdogs, measured from the last accepted AT command: > :attr:`comwdg_s` (50 ms) → state
  bit 30 (set from start until the first command). By default any accepted command clears it
  (spec: "also defensible"); with ``comwdg_clear="comwdg"`` it latches until ``AT*COMWDG``.
  > :attr:`hover_after_s` (250 ms) while airborne → the held PCMD is dropped and the drone
  hovers (ctrl HOVERING / LOST_COM) until the next PCMD. > :attr:`link_loss_s` (2 s) → state
  bit 13 (cleared by the next command), the AT sequence resets; the drone keeps hovering (the
  plant lands by itself when its battery is empty).
* Navdata stops after :attr:`navdata_timeout_s` (2 s) without any client datagram (AT or
  navdata port); a new wake-up restarts it. The navdata sequence keeps counting up across
  restarts (starts at 1), so no client's "discard seq ≤ last" rule drops the new stream.
* State bits: FLY (motors running: taking off, flying, landing), USER_FEEDBACK_START (last REF
  bit 9), COMMAND (ACK), NAVDATA_DEMO (bootstrap and demo mode), NAVDATA_BOOTSTRAP, COM_LOST,
  VBAT_LOW (battery < ``vbat_low_pct``, 20 %), USER_EL and EMERGENCY (emergency),
  COM_WATCHDOG; ALTITUDE, PIC_VERSION and the four thread bits always, as in the captured
  bootstrap packet 0x4F800C10.
* State bits and ctrl_state come from :class:`~ardrone_nmpc.protocol.navdata.DroneStatus` (the
  one encoder of every simulated drone): LANDED 2, FLYING 3 (progressive command with a
  non-zero value), HOVERING 4, EMERGENCY 0, take-off / landing 6 / 8 (SDK header,
  ``ctrl_codes="sdk"``) or 7 / 9 (reported for 2.4.x firmware, ``"fw2.4"``).

Not simulated: video (TCP 5555), multicast navdata (wake-up value 2 is served unicast),
animations and LEDs, magnetometer calibration, the tilt / cut-out / motor emergencies of rule
10, navdata options other than demo, time and an empty vision_detect.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import math
import select
import socket
import threading
import time
from dataclasses import dataclass
from typing import Callable, Literal, Optional

from ardrone_nmpc.protocol.at import (
    CTRL_MODE_ACK,
    CTRL_MODE_CFG_GET,
    CTRL_MODE_CUSTOM_CFG_GET,
    AtCommand,
    Calib,
    Comwdg,
    Config,
    ConfigIds,
    Ctrl,
    Ftrim,
    Pcmd,
    PcmdFlag,
    PcmdMag,
    Ref,
    parse_datagram_lenient,
)
from ardrone_nmpc.protocol.navdata import (
    DEFAULT_NAVDATA_OPTIONS,
    CtrlCodes,
    DroneState,
    DroneStatus,
    encode_drone_navdata,
)
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.plant import AirframePlant

__all__ = ["DroneServer", "DroneServerCounters", "require_loopback_host", "EULER_ANGLE_MAX_LIMIT_RAD"]

EULER_ANGLE_MAX_LIMIT_RAD = 0.52          # dev guide range of control:euler_angle_max
# Recommended ranges of the other two limits (protocol §3.1). Written values are clamped to
# them: an unbounded value (a client may send "1e300") would drive the plant to altitudes no
# navdata int32 field can carry, and the navdata thread would die on it.
_CONTROL_VZ_MAX_RANGE_MMPS = (200.0, 2000.0)
_CONTROL_YAW_RANGE_RADPS = (0.7, 6.11)
_RECV_BYTES = 4096
_POLL_S = 0.05                            # socket timeout: shutdown latency of the threads

_HOVER_CMD = (0, 0.0, 0.0, 0.0, 0.0)      # (flags, roll, pitch, gaz, yaw)


def require_loopback_host(host: str, what: str = "address") -> str:
    """``host`` as a numeric IPv4 loopback address (127.0.0.0/8; ``localhost`` → 127.0.0.1).

    Raises ValueError for anything else: the simulators only ever talk to this machine.
    """
    text = str(host).strip()
    if text.lower() == "localhost":
        return "127.0.0.1"
    try:
        addr = ipaddress.ip_address(text)
    except ValueError:
        raise ValueError(f"{what} {host!r} is not a loopback address (use 127.0.0.1)") from None
    if addr.version != 4 or not addr.is_loopback:
        raise ValueError(f"{what} {host!r} is not a loopback address (use 127.0.0.1)")
    return str(addr)


def _is_loopback(addr) -> bool:
    try:
        return ipaddress.ip_address(addr[0]).is_loopback
    except (ValueError, TypeError, IndexError):
        return False


def _parse_bool(text: str) -> bool:
    return text.strip().upper() in ("TRUE", "1", "YES", "ON")


def _parse_float(text: str) -> float | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


@dataclass
class DroneServerCounters:
    """Traffic and timing counters of a :class:`DroneServer` (a snapshot copy when read)."""

    at_datagrams_in: int = 0          # datagrams on the AT port (incl. malformed ones)
    at_commands_in: int = 0           # well-formed commands
    at_commands_applied: int = 0      # accepted by the sequence rule and executed
    at_commands_stale: int = 0        # ignored by the sequence rule
    at_commands_unknown: int = 0      # well-formed commands of other names (ANIM, LED, …)
    malformed_datagrams: int = 0      # datagrams with at least one malformed part
    malformed_commands: int = 0       # malformed commands (an oversized datagram counts one)
    config_writes: int = 0
    ftrim_accepted: int = 0
    calib_accepted: int = 0
    navdata_datagrams_in: int = 0     # wake-ups (any datagram on the navdata port)
    navdata_packets_out: int = 0
    navdata_send_errors: int = 0
    navdata_stream_starts: int = 0
    navdata_stream_stops: int = 0     # streams stopped for lack of client traffic
    control_connections: int = 0
    config_dumps: int = 0
    physics_steps: int = 0
    physics_max_lag_s: float = 0.0    # largest lateness of a physics wake-up
    link_losses: int = 0
    at_datagrams_lost: int = 0        # discarded on arrival by an injected AT-loss fault


class DroneServer:
    """The simulated AR.Drone's network side (see the module docstring for the behaviour).

    Parameters
    ----------
    plant : the simulated drone; every call to it is made under :attr:`lock`.
    bind_host : loopback address to bind (ValueError otherwise).
    at_port, navdata_port : UDP ports; 0 picks free ports (see the properties for the actual).
    control_port : TCP configuration port (5559 on the drone); None = not served, 0 = free port.
    step_s : physics step (s) on the monotonic clock.
    demo_rate_hz, full_rate_hz, bootstrap_rate_hz : navdata rates of demo, full
        (``navdata_demo = FALSE``) and bootstrap streaming.
    comwdg_s, hover_after_s, link_loss_s, navdata_timeout_s : the watchdog times (s) of §2.6 and
        §1.1 (0.05, 0.25, 2.0, 2.0); ``navdata_timeout_s=None`` streams forever.
    comwdg_clear : "any" — any accepted command clears state bit 30; "comwdg" — only
        ``AT*COMWDG`` does (latched).
    ctrl_codes : :class:`~ardrone_nmpc.protocol.navdata.CtrlCodes` (or its value): "sdk"
        (take-off 6, landing 8) or "fw2.4" (7, 9).
    altitude_max_m : initial ``control:altitude_max`` (m).
    vbat_low_pct : battery level (%) below which state bit 15 is set.
    lock : the lock to share (default: a new ``threading.RLock``).
    clock : the time source (s), ``time.monotonic`` by default.
    faults : injected faults (:class:`~ardrone_nmpc.sim.fault_injection.ServerFaults`, None =
        none): plant faults each physics step, navdata packets lost / corrupted / disordered,
        AT datagrams lost on arrival; their experiment time runs on ``clock``.
    """

    def __init__(self, plant: AirframePlant, *, bind_host: str = "127.0.0.1", at_port: int = 0,
                 navdata_port: int = 0, control_port: Optional[int] = None,
                 step_s: float = 0.005, demo_rate_hz: float = 15.0, full_rate_hz: float = 200.0,
                 bootstrap_rate_hz: Optional[float] = None, comwdg_s: float = 0.05,
                 hover_after_s: float = 0.25, link_loss_s: float = 2.0,
                 navdata_timeout_s: Optional[float] = 2.0,
                 comwdg_clear: Literal["any", "comwdg"] = "any",
                 ctrl_codes: CtrlCodes | str = CtrlCodes.SDK,
                 altitude_max_m: float = 3.0, vbat_low_pct: float = 20.0,
                 lock: Optional[threading.RLock] = None,
                 clock: Callable[[], float] = time.monotonic, faults=None) -> None:
        self.bind_host = require_loopback_host(bind_host, "bind address")
        for name, v in (("step_s", step_s), ("demo_rate_hz", demo_rate_hz),
                        ("full_rate_hz", full_rate_hz), ("comwdg_s", comwdg_s),
                        ("hover_after_s", hover_after_s), ("link_loss_s", link_loss_s),
                        ("altitude_max_m", altitude_max_m)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        if comwdg_clear not in ("any", "comwdg"):
            raise ValueError(f"comwdg_clear must be 'any' or 'comwdg', got {comwdg_clear!r}")
        self.ctrl_codes = CtrlCodes(ctrl_codes)   # ValueError for an unknown value
        self.plant = plant
        self.lock = lock if lock is not None else threading.RLock()
        self.step_s = float(step_s)
        self.demo_rate_hz = float(demo_rate_hz)
        self.full_rate_hz = float(full_rate_hz)
        self.bootstrap_rate_hz = float(bootstrap_rate_hz or demo_rate_hz)
        self.comwdg_s = float(comwdg_s)
        self.hover_after_s = float(hover_after_s)
        self.link_loss_s = float(link_loss_s)
        self.navdata_timeout_s = None if navdata_timeout_s is None else float(navdata_timeout_s)
        self.comwdg_clear = comwdg_clear
        self.vbat_low_pct = float(vbat_low_pct)
        self._clock = clock
        self._faults = faults

        # protocol state (under self.lock)
        self._last_seq = 0
        self._last_cmd_t: Optional[float] = None      # last accepted AT command
        self._last_traffic_t: Optional[float] = None  # last datagram on either port
        self._comwdg_latched = True
        self._lost_com_hover = False
        self._link_lost = False
        self._ref_start = False
        self._ref_emergency = False
        self._user_emergency = False
        self._ack = False
        self._bootstrap = True
        self._demo = True
        self._navdata_options = DEFAULT_NAVDATA_OPTIONS
        self._pcmd = _HOVER_CMD
        self._applied: tuple | None = None
        self._alt_capped = False
        self.altitude_max_m = float(altitude_max_m)
        self._config: dict[str, str] = {}
        self._config_ids: tuple[str, str, str] = ("00000000", "00000000", "00000000")
        self._counters = DroneServerCounters()
        self._nav_client: Optional[tuple] = None
        self._streaming = False
        self._nav_seq = 0

        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._started = False
        self._closed = False
        self._control_clients: list[socket.socket] = []
        self._at_sock = self._nav_sock = self._ctl_sock = None
        try:
            self._at_sock = self._udp(at_port)
            self._nav_sock = self._udp(navdata_port)
            if control_port is not None:
                s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                s.bind((self.bind_host, int(control_port)))
                s.listen(4)
                s.settimeout(_POLL_S)
                self._ctl_sock = s
        except BaseException:
            self._close_sockets()
            raise

    def _udp(self, port: int) -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind((self.bind_host, int(port)))
        s.settimeout(_POLL_S)
        return s

    # ------------------------------------------------------------------ public state

    @property
    def at_port(self) -> int:
        """The UDP port AT commands are read from."""
        return self._at_sock.getsockname()[1]

    @property
    def navdata_port(self) -> int:
        """The UDP port of navdata (wake-ups in, packets out)."""
        return self._nav_sock.getsockname()[1]

    @property
    def control_port(self) -> Optional[int]:
        """The TCP configuration port, or None when not served."""
        return None if self._ctl_sock is None else self._ctl_sock.getsockname()[1]

    @property
    def config(self) -> dict[str, str]:
        """The configuration keys written by ``AT*CONFIG`` (a copy), key → value text."""
        with self.lock:
            return dict(self._config)

    @property
    def config_ids(self) -> tuple[str, str, str]:
        """The last ``AT*CONFIG_IDS`` (session, profile, application)."""
        with self.lock:
            return self._config_ids

    @property
    def counters(self) -> DroneServerCounters:
        """A snapshot of the counters."""
        with self.lock:
            return dataclasses.replace(self._counters)

    @property
    def navdata_client(self) -> Optional[tuple]:
        """The (ip, port) navdata is sent to, or None before the first wake-up."""
        with self.lock:
            return self._nav_client

    @property
    def streaming(self) -> bool:
        """True while navdata is being streamed."""
        with self.lock:
            return self._streaming

    @property
    def bootstrap(self) -> bool:
        """True until ``general:navdata_demo`` is written."""
        with self.lock:
            return self._bootstrap

    def state_bits(self) -> DroneState:
        """The drone state bits navdata would report now."""
        with self.lock:
            return self._state_bits(self._clock())

    # ------------------------------------------------------------------ life cycle

    def start(self) -> DroneServer:
        """Start the threads (once)."""
        if self._closed:
            raise RuntimeError("DroneServer is closed")
        if self._started:
            raise RuntimeError("DroneServer already started")
        self._started = True
        targets = [("physics", self._physics_loop), ("at", self._at_loop),
                   ("navdata", self._navdata_loop)]
        if self._ctl_sock is not None:
            targets.append(("control", self._control_loop))
        for name, fn in targets:
            t = threading.Thread(target=fn, name=f"drone-server-{name}", daemon=True)
            self._threads.append(t)
        for t in self._threads:
            t.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop and join the threads and close the sockets (idempotent)."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout_s)
        self._threads.clear()
        self._close_sockets()
        self._closed = True

    close = stop

    def _close_sockets(self) -> None:
        for s in (self._at_sock, self._nav_sock, self._ctl_sock, *self._control_clients):
            if s is not None:
                try:
                    s.close()
                except OSError:  # pragma: no cover
                    pass
        self._control_clients.clear()

    def __enter__(self) -> DroneServer:
        if not self._started:
            self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        return (f"DroneServer({self.bind_host}, at={self.at_port}, navdata={self.navdata_port}"
                f"{'' if self._ctl_sock is None else f', control={self.control_port}'})")

    # ------------------------------------------------------------------ physics + watchdogs

    def _physics_loop(self) -> None:
        clock, step = self._clock, self.step_s
        t0 = clock()
        done = 0
        while not self._stop.is_set():
            deadline = t0 + (done + 1) * step
            delay = deadline - clock()
            if delay > 0:
                self._stop.wait(delay)
                if self._stop.is_set():
                    break
            now = clock()
            due = int((now - t0) / step) - done
            if due <= 0:
                continue
            with self.lock:
                c = self._counters
                c.physics_max_lag_s = max(c.physics_max_lag_s, now - deadline)
                if self._faults is not None:   # battery, emergency, delay jump, wind
                    self._faults.update_plant(now)
                self.plant.advance(due * step)
                done += due
                c.physics_steps += due
                self._watchdogs(now)
                self._apply_command()

    def _silence(self, now: float) -> float:
        return math.inf if self._last_cmd_t is None else now - self._last_cmd_t

    def _watchdogs(self, now: float) -> None:
        silence = self._silence(now)
        if silence > self.comwdg_s:
            self._comwdg_latched = True
        if (silence > self.hover_after_s and not self._lost_com_hover
                and self.plant.mode.airborne):
            self._lost_com_hover = True
            self._pcmd = _HOVER_CMD
        if silence > self.link_loss_s and not self._link_lost and self._last_cmd_t is not None:
            self._link_lost = True
            self._last_seq = 0
            self._counters.link_losses += 1
        if (self._streaming and self.navdata_timeout_s is not None
                and (self._last_traffic_t is None
                     or now - self._last_traffic_t > self.navdata_timeout_s)):
            self._streaming = False
            self._counters.navdata_stream_stops += 1

    def _apply_command(self) -> None:
        """Send the effective PCMD (held command, altitude cap) to the plant when it changes."""
        flags, roll, pitch, gaz, yaw = self._pcmd
        progressive = bool(flags & PcmdFlag.PROGRESSIVE)
        at_cap = False
        if self.plant.mode.airborne:
            truth, params = self.plant.truth, self.plant.params
            # where the climb stops if gaz drops to 0 now: the command delay, then the
            # first-order vertical loop (τ_z) still rises v_z·(T_d + τ_z)
            lead = getattr(params, "command_delay_s", 0.0) + getattr(params, "tau_vz_s", 0.0)
            z_stop = float(truth.position_m[2]) + max(0.0, float(truth.velocity_mps[2])) * lead
            at_cap = z_stop >= self.altitude_max_m
        if at_cap and progressive and gaz > 0.0:
            gaz = 0.0
        self._alt_capped = at_cap
        cmd = (roll, pitch, gaz, yaw, True) if progressive else (0.0, 0.0, 0.0, 0.0, False)
        if cmd != self._applied:
            self.plant.command(*cmd[:4], progressive=cmd[4])
            self._applied = cmd

    # ------------------------------------------------------------------ AT commands

    def _at_loop(self) -> None:
        sock = self._at_sock
        while not self._stop.is_set():
            try:
                data, addr = sock.recvfrom(_RECV_BYTES)
            except socket.timeout:
                continue
            except OSError:
                if self._stop.is_set():
                    break
                continue
            if not _is_loopback(addr):   # pragma: no cover - the socket is loopback-bound
                continue
            self.handle_at_datagram(data)

    def handle_at_datagram(self, data: bytes) -> None:
        """Apply one AT datagram (as received on the AT port)."""
        if self._faults is not None and self._faults.at_lost(self._clock()):
            with self.lock:   # lost before the drone: no traffic for its watchdogs either
                self._counters.at_datagrams_lost += 1
            return
        commands, errors = parse_datagram_lenient(data)
        now = self._clock()
        with self.lock:
            c = self._counters
            c.at_datagrams_in += 1
            self._last_traffic_t = now
            if errors:
                c.malformed_datagrams += 1
                c.malformed_commands += len(errors)
            for cmd in commands:
                c.at_commands_in += 1
                self._execute(cmd, now)
            self._apply_command()

    def _execute(self, cmd: AtCommand, now: float) -> None:
        c = self._counters
        if not (cmd.seq == 1 or cmd.seq > self._last_seq):
            c.at_commands_stale += 1
            return
        self._last_seq = cmd.seq
        c.at_commands_applied += 1
        self._last_cmd_t = now
        self._link_lost = False
        self._lost_com_hover = False
        if self.comwdg_clear == "any":
            self._comwdg_latched = False
        body = cmd.body
        plant = self.plant
        if isinstance(body, Ref):
            self._on_ref(body)
        elif isinstance(body, (Pcmd, PcmdMag)):
            self._pcmd = (body.flags, body.roll_frac, body.pitch_frac, body.gaz_frac,
                          body.yaw_frac)
        elif isinstance(body, Comwdg):
            self._comwdg_latched = False
        elif isinstance(body, Config):
            self._on_config(body.key, body.value)
        elif isinstance(body, ConfigIds):
            self._config_ids = (body.session_id, body.profile_id, body.application_id)
        elif isinstance(body, Ctrl):
            self._on_ctrl(body.mode)
        elif isinstance(body, Ftrim):
            if plant.mode is FlightMode.LANDED:
                c.ftrim_accepted += 1
        elif isinstance(body, Calib):
            if plant.mode is FlightMode.FLYING:
                c.calib_accepted += 1
        else:
            c.at_commands_unknown += 1

    def _on_ref(self, ref: Ref) -> None:
        plant = self.plant
        start, emergency = ref.is_takeoff, ref.is_emergency
        if emergency and not self._ref_emergency:        # 0→1 edge of bit 8
            if plant.mode is FlightMode.EMERGENCY:
                if plant.reset_emergency():
                    self._user_emergency = False
            elif plant.emergency():
                self._user_emergency = True
                self._pcmd = _HOVER_CMD
        self._ref_emergency = emergency
        self._ref_start = start
        mode = plant.mode
        if start and mode is FlightMode.LANDED:
            plant.takeoff()                               # refused on low battery
        elif not start and mode in (FlightMode.TAKING_OFF, FlightMode.FLYING):
            plant.land()

    def _on_config(self, key: str, value: str) -> None:
        self._config[key] = value
        self._counters.config_writes += 1
        self._ack = True
        plant = self.plant
        if key == "general:navdata_demo":
            self._bootstrap = False
            self._demo = _parse_bool(value)
        elif key == "general:navdata_options":
            try:
                self._navdata_options = int(value) & 0xFFFFFFFF
            except ValueError:
                pass
        elif key == "control:altitude_max":
            v = _parse_float(value)
            if v is not None and v > 0:
                self.altitude_max_m = v / 1000.0
        elif key in ("control:euler_angle_max", "control:control_vz_max", "control:control_yaw"):
            v = _parse_float(value)
            if v is None or v <= 0:
                return
            if key == "control:euler_angle_max":
                change = {"euler_angle_max_rad": min(v, EULER_ANGLE_MAX_LIMIT_RAD)}
            elif key == "control:control_vz_max":
                lo, hi = _CONTROL_VZ_MAX_RANGE_MMPS
                change = {"control_vz_max_mps": min(max(v, lo), hi) / 1000.0}
            else:
                lo, hi = _CONTROL_YAW_RANGE_RADPS
                change = {"control_yaw_radps": min(max(v, lo), hi)}
            try:
                plant.params = plant.params.replace(**change)
            except (ValueError, TypeError, AttributeError):   # keep the old params
                pass

    def _on_ctrl(self, mode: int) -> None:
        if mode == CTRL_MODE_ACK:
            self._ack = False
        elif mode == CTRL_MODE_CFG_GET:
            self._dump_to_control_clients(self._config_text())
            self._ack = True
        elif mode == CTRL_MODE_CUSTOM_CFG_GET:
            self._dump_to_control_clients("")
            self._ack = True

    # ------------------------------------------------------------------ control port (TCP)

    def _config_text(self) -> str:
        p = self.plant.params
        values = {
            "general:num_version_soft": "2.4.8",
            "general:navdata_demo": "TRUE" if self._demo else "FALSE",
            "general:navdata_options": str(self._navdata_options),
            "general:com_watchdog": "2",
            "general:vbat_min": "9000",
            "control:euler_angle_max": f"{p.euler_angle_max_rad:.4f}",
            "control:altitude_max": str(int(round(self.altitude_max_m * 1000))),
            "control:altitude_min": "50",
            "control:control_vz_max": f"{p.control_vz_max_mps * 1000:.1f}",
            "control:control_yaw": f"{p.control_yaw_radps:.4f}",
            "control:outdoor": "FALSE",
            "control:flight_without_shell": "FALSE",
            "control:flying_mode": "0",
            "video:video_codec": "129",
            "video:video_channel": "0",
            "custom:session_id": self._config_ids[0],
            "custom:profile_id": self._config_ids[1],
            "custom:application_id": self._config_ids[2],
        }
        values.update(self._config)
        values["general:navdata_demo"] = "TRUE" if self._demo else "FALSE"
        return "".join(f"{k} = {v}\n" for k, v in values.items())

    def _dump_to_control_clients(self, text: str) -> None:
        if not self._control_clients:
            return
        data = text.encode("ascii", errors="replace") + b"\0"
        for s in list(self._control_clients):
            try:
                s.settimeout(0.5)
                s.sendall(data)
            except OSError:
                self._control_clients.remove(s)
                s.close()
        self._counters.config_dumps += 1

    def _control_loop(self) -> None:
        lsock = self._ctl_sock
        while not self._stop.is_set():
            try:
                conn, addr = lsock.accept()
            except socket.timeout:
                self._reap_control_clients()
                continue
            except OSError:
                if self._stop.is_set():
                    break
                continue
            if not _is_loopback(addr):   # pragma: no cover
                conn.close()
                continue
            with self.lock:
                self._control_clients.append(conn)
                self._counters.control_connections += 1

    def _reap_control_clients(self) -> None:
        """Drop connections the client has closed (and discard anything it sent)."""
        with self.lock:
            clients = list(self._control_clients)
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
                    if s in self._control_clients:
                        self._control_clients.remove(s)
                s.close()

    # ------------------------------------------------------------------ navdata

    def _navdata_period(self) -> float:
        if self._bootstrap:
            return 1.0 / self.bootstrap_rate_hz
        return 1.0 / (self.demo_rate_hz if self._demo else self.full_rate_hz)

    def _navdata_loop(self) -> None:
        sock, clock = self._nav_sock, self._clock
        next_send = math.inf
        while not self._stop.is_set():
            now = clock()
            timeout = min(_POLL_S, max(0.0, next_send - now))
            try:
                readable, _, _ = select.select([sock], [], [], timeout)
            except (OSError, ValueError):
                if self._stop.is_set():
                    break
                continue
            if readable:
                try:
                    _, addr = sock.recvfrom(_RECV_BYTES)
                except OSError:
                    continue
                if not _is_loopback(addr):   # pragma: no cover
                    continue
                now = clock()
                with self.lock:
                    self._counters.navdata_datagrams_in += 1
                    self._last_traffic_t = now
                    self._nav_client = addr
                    if not self._streaming:
                        self._streaming = True
                        self._counters.navdata_stream_starts += 1
                        next_send = now
                continue
            now = clock()
            with self.lock:
                if not self._streaming:
                    next_send = math.inf
                    continue
                if now < next_send:
                    continue
                packet = self._packet(now)
                target = self._nav_client
                period = self._navdata_period()
                # injected faults: none (lost), corrupted, duplicated or held back
                datagrams = ([packet] if self._faults is None
                             else self._faults.navdata_datagrams(now, packet))
            for packet in datagrams:
                try:
                    sock.sendto(packet, target)
                    with self.lock:
                        self._counters.navdata_packets_out += 1
                except OSError:
                    with self.lock:
                        self._counters.navdata_send_errors += 1
            next_send += period
            if next_send < now - period:   # fell behind by more than a period: re-anchor
                next_send = now + period

    def _status(self, now: float) -> DroneStatus:
        """What the drone reports about itself now (under the lock)."""
        flags, roll, pitch, gaz, yaw = self._pcmd
        return DroneStatus(
            self.plant.mode.value,
            moving=bool(flags & PcmdFlag.PROGRESSIVE) and any((roll, pitch, gaz, yaw)),
            alt_out_zone=self._alt_capped, lost_com=self._lost_com_hover,
            user_emergency=self._user_emergency, start_button=self._ref_start, ack=self._ack,
            bootstrap=self._bootstrap, demo=self._demo,
            com_watchdog=self._comwdg_latched or (self.comwdg_clear == "any"
                                                  and self._silence(now) > self.comwdg_s),
            com_lost=self._link_lost, battery_low=self.plant.battery_pct < self.vbat_low_pct)

    def _state_bits(self, now: float) -> DroneState:
        return self._status(now).state_bits()

    def _packet(self, now: float) -> bytes:
        """The next navdata packet (under the lock)."""
        self._nav_seq = self._nav_seq + 1 if self._nav_seq < 0xFFFFFFFF else 1
        status = self._status(now)
        sample = None if status.bootstrap else self.plant.navdata()
        return encode_drone_navdata(status, self._nav_seq, sample, codes=self.ctrl_codes,
                                    options_mask=self._navdata_options, t_s=self.plant.t_s)
