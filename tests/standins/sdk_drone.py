"""A minimal AR.Drone 2.0 stand-in written from the SDK's documented behaviour, not from this
project's ``sim-drone`` — so the flight session is not only tested against itself.

It imports nothing from ``ardrone_nmpc``: its own AT parser, its own navdata encoder, its own
mocap encoder. What it does, and where that is written down (AutonomyLab/ardronelib, the SDK
the ROS driver ardrone_autonomy builds on; docs/protocol.md summarises the same):

* ports (``Soft/Common/config.h``): navdata UDP, AT UDP, control TCP — here on 127.0.0.1,
  free ports;
* navdata (``ardrone_navdata_client.c``, ``navdata_common.h``): streams to the source of the
  last wake-up datagram; header ``0x55667788``, state word, sequence (+1 per packet), vision
  flag, options ``tag,size`` (size includes the 4-byte head), checksum option 0xFFFF last
  (unsigned sum of every byte before it); bootstrap packets (state bit 11, no demo option)
  until ``general:navdata_demo`` is written, then demo packets (tag 0, 148 bytes) at 15 Hz;
* state word (``config.h`` ``def_ardrone_state_mask_t``): bit 0 FLY, 6 COMMAND (config ACK),
  10 NAVDATA_DEMO, 11 NAVDATA_BOOTSTRAP, 12 MOTORS, 14 SOFTWARE_FAULT, 15 VBAT_LOW (battery
  below ``vbat_low_pct``: no take-off then), 21 ULTRASOUND, 22 CUTOUT (any of these set through
  :attr:`SdkDrone.fault_bits`), 30 COM_WATCHDOG (no AT command for 50 ms), 31 EMERGENCY;
* ctrl_state (``control_states.h``): major << 16 | minor; 2 LANDED, 4 HOVERING, 6 TRANS_TAKEOFF,
  8 TRANS_LANDING — or firmware 2.4's observed 7 take-off / 9 landing (``ctrl_codes="fw24"``);
* AT (``ardrone_at_mutex.c``, ATcodec): ``AT*NAME=seq,args\\r``, several per datagram; a
  command runs only if its seq is 1 or above the last; ``AT*REF`` bit 9 a level (take-off
  while set, land while clear), bit 8 acting on its rising edge (emergency; on the ground in
  emergency: cleared); ``AT*FTRIM`` only on the ground; ``AT*CONFIG`` sets the ACK bit 6,
  ``AT*CTRL=seq,5,0`` clears it; once a non-default multiconfig session is active an
  ``AT*CONFIG`` counts only right after an ``AT*CONFIG_IDS`` with the current ids;
* control port (``ardrone_control_configuration.c``): ``AT*CTRL=seq,4,0`` → every
  ``section:key = value`` line on the TCP connection, a NUL byte, then the ACK bit;
* profiles (``config_keys.h``: ``control:outdoor`` and the ``indoor_*`` / ``outdoor_*``
  triples): ``control:outdoor`` loads the stored triple of its profile into the three limit
  keys, a write of a limit key is stored into the active profile;
* a client "disconnects" after 2 s without an AT command (the guide's link loss): the
  sequence counter resets, the stream stops, and the next wake-up gets bootstrap packets again
  until ``general:navdata_demo`` is written (``ardrone_general_navdata.c`` answers exactly that
  bootstrap: "the navdata stream will be resumed if the drone is disconnected and
  reconnected");
* several AT clients: one sequence counter for all of them (the seq rule above), counted per
  source address (:attr:`SdkDrone.accepted_from`, :attr:`SdkDrone.ignored_from`).

Options model what a real lab meets: ``ignore_config_writes`` (acknowledge, keep its own values
— a drone in another session, an outdoor profile), ``serve_control_port``,
``land_by_itself_after_s`` (low battery, a cut-out: it lands after hovering that long),
``airborne_at_start``, ``attitude_deg``, ``battery_pct``, ``takeoff_yaw_dps`` (navdata yaw
turning during take-off, clockwise positive as the SDK reports it), ``vbat_low_pct`` (its
VBAT_LOW level), ``last_flown_outdoors`` (``control:outdoor`` TRUE, with an indoor profile
other than the defaults), ``navdata_gap_at_takeoff`` (navdata silent from a delay after the
take-off REF, for a while), :attr:`SdkDrone.fault_bits` and :meth:`SdkDrone.blackout` (a Wi-Fi
blackout: nothing passes either way for a while).
"""

from __future__ import annotations

import math
import re
import select
import socket
import struct
import threading
import time

LOOPBACK = "127.0.0.1"
FLY, COMMAND, DEMO, BOOTSTRAP, COM_WATCHDOG, EMERGENCY = (1 << 0, 1 << 6, 1 << 10, 1 << 11,
                                                          1 << 30, 1 << 31)
MOTORS, SOFTWARE_FAULT, VBAT_LOW, ULTRASOUND, CUTOUT = (1 << 12, 1 << 14, 1 << 15, 1 << 21,
                                                        1 << 22)
LINK_LOSS_S = 2.0
REF_EMERGENCY, REF_TAKEOFF = 1 << 8, 1 << 9
LANDED, HOVERING = 2, 4
SDK_CODES = {"takeoff": 6, "landing": 8}
FW24_CODES = {"takeoff": 7, "landing": 9}
DEFAULT_CONFIG = {  # config_keys.h defaults, indoor profile
    "general:navdata_demo": "FALSE", "control:euler_angle_max": "0.2094",
    "control:control_vz_max": "700", "control:control_yaw": "1.745",
    "control:altitude_max": "3000", "control:outdoor": "FALSE",
    "control:flight_without_shell": "FALSE", "control:flying_mode": "0",
    "custom:session_id": "00000000", "custom:profile_id": "00000000",
    "custom:application_id": "00000000",
}
OUTDOOR_HELD = {"control:euler_angle_max": "0.52", "control:control_vz_max": "2000",
                "control:control_yaw": "6.11", "control:outdoor": "TRUE"}
LIMITS = ("euler_angle_max", "control_vz_max", "control_yaw")
#: The stored profiles of a drone last flown outdoors: the user's indoor triple and the
#: config_keys.h outdoor defaults (20°, 1000 mm/s, 200°/s).
INDOOR_PROFILE = {"control:indoor_euler_angle_max": "0.25",
                  "control:indoor_control_vz_max": "800", "control:indoor_control_yaw": "2.0"}
OUTDOOR_PROFILE = {"control:outdoor_euler_angle_max": "0.3491",
                   "control:outdoor_control_vz_max": "1000",
                   "control:outdoor_control_yaw": "3.491"}
_COMMAND_RE = re.compile(rb'AT\*([A-Z_]+)=(\d+)((?:,(?:"[^"]*"|-?\d*))*)')
_ARG_RE = re.compile(rb'"([^"]*)"|(-?\d+)')


def float_of(int32_text: int) -> float:
    return struct.unpack("<f", struct.pack("<i", int32_text))[0]


class SdkDrone:
    """The stand-in; ``start()`` … ``stop()`` (or a context manager). Thread-safe reads of
    :attr:`log` (every accepted command: ``(t, name, args, phase_before)``)."""

    TAKEOFF_S = 0.6
    LANDING_S = 0.4
    NAVDATA_PERIOD_S = 1.0 / 15.0

    def __init__(self, *, ignore_config_writes=False, held=None, serve_control_port=True,
                 land_by_itself_after_s=None, airborne_at_start=False, ctrl_codes="sdk",
                 attitude_deg=(0.3, -0.2), battery_pct=80, takeoff_yaw_dps=0.0,
                 vbat_low_pct=20.0, last_flown_outdoors=False, navdata_gap_at_takeoff=None):
        self.ignore_config_writes = ignore_config_writes
        indoor = {f"control:indoor_{k}": DEFAULT_CONFIG[f"control:{k}"] for k in LIMITS}
        self.config = dict(DEFAULT_CONFIG, **indoor, **OUTDOOR_PROFILE)
        if last_flown_outdoors:
            self.config.update(INDOOR_PROFILE, **{"control:outdoor": "TRUE"})
            self._load_profile()
        self.config.update(held or {})
        self.vbat_low_pct = vbat_low_pct
        self.fault_bits = 0         # MOTORS, SOFTWARE_FAULT, ULTRASOUND, CUTOUT … as reported
        self.serve_control_port = serve_control_port
        self.land_by_itself_after_s = land_by_itself_after_s
        self.codes = FW24_CODES if ctrl_codes == "fw24" else SDK_CODES
        self.attitude_deg = attitude_deg
        self.battery_pct = battery_pct
        self.takeoff_yaw_dps = takeoff_yaw_dps
        self.lock = threading.Lock()
        self.phase = "hovering" if airborne_at_start else "landed"
        self.phase_t = time.monotonic()
        self.hover_since = self.phase_t if airborne_at_start else None
        self.yaw_deg = 10.0
        self.ack = False
        self.bootstrap = True
        self.last_seq = 0
        self.last_ref = None
        self.last_cmd_t = -1e9
        self.pending_ids = None  # CONFIG_IDS just before (same datagram)
        self.log: list = []
        self.takeoffs = 0           # landed → take-off transitions
        self.self_landed_t = None   # when it touched down after landing by itself
        self.self_landing_start_t = None  # when it began to land by itself
        self.ftrims = []            # accepted FTRIM times
        self.wakeups: list = []     # times of datagrams on the navdata port
        self.at_sources: set = set()  # (address, port) AT datagrams came from
        self.silent_until = -1.0    # no navdata before this time (a Wi-Fi hiccup) …
        self.silent_from = -1e18    # … from this time on
        self.navdata_gap_at_takeoff = navdata_gap_at_takeoff  # (delay s, duration s) or None
        self.blackout_until = -1.0  # nothing passes either way before this time
        self.accepted_from: dict = {}  # source address → AT commands accepted
        self.ignored_from: dict = {}   # source address → AT commands ignored (stale seq)
        self.link_losses = 0
        self.phases: list = []         # (time, phase) of every change
        self._stop = threading.Event()
        self._client = None
        self._ctl_clients: list = []
        self.at = self._udp()
        self.nav = self._udp()
        self.ctl = None
        if serve_control_port:
            self.ctl = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.ctl.bind((LOOPBACK, 0))
            self.ctl.listen(4)
        self._thread = threading.Thread(target=self._loop, daemon=True, name="sdk-drone")

    @staticmethod
    def _udp():
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind((LOOPBACK, 0))
        return s

    # ports -------------------------------------------------------------------------------
    at_port = property(lambda self: self.at.getsockname()[1])
    navdata_port = property(lambda self: self.nav.getsockname()[1])
    control_port = property(lambda self: self.ctl.getsockname()[1] if self.ctl else 1)

    def start(self):
        self._thread.start()
        return self

    def stop(self):
        self._stop.set()
        self._thread.join(timeout=2.0)
        for s in [self.at, self.nav, self.ctl, *self._ctl_clients]:
            if s is not None:
                s.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    # reading ------------------------------------------------------------------------------
    def commands(self, name, since_t=-1e9):
        with self.lock:
            return [entry for entry in self.log if entry[1] == name and entry[0] >= since_t]

    def blackout(self, seconds):
        """A Wi-Fi blackout from now: no datagram passes either way for ``seconds``."""
        with self.lock:
            self.blackout_until = time.monotonic() + seconds

    def takeoff_refs_after_touchdown(self):
        """REFs with bit 9 accepted after the drone landed by itself and touched down."""
        if self.self_landed_t is None:
            return []
        return [e for e in self.commands("REF", self.self_landed_t) if e[2][0] & REF_TAKEOFF]

    @property
    def true_psi_rad(self):
        """The heading counter-clockwise (the SDK's yaw is clockwise-positive)."""
        return -math.radians(self.yaw_deg)

    # the loop -----------------------------------------------------------------------------
    def _loop(self):
        next_nav = time.monotonic()
        while not self._stop.is_set():
            socks = [self.at, self.nav] + ([self.ctl] if self.ctl else [])
            ready, _, _ = select.select(socks, [], [], max(0.0, next_nav - time.monotonic()))
            now = time.monotonic()
            for s in ready:
                if s is self.ctl:
                    conn, _ = self.ctl.accept()
                    self._ctl_clients.append(conn)
                    continue
                data, addr = s.recvfrom(4096)
                with self.lock:
                    if now < self.blackout_until:
                        continue                       # lost on the way
                    if s is self.nav:
                        self._client = addr            # wake-up: stream there
                        self.wakeups.append(now)
                    else:
                        self.at_sources.add(addr)
                        self._on_datagram(data, now, addr)
            with self.lock:
                self._advance(now)
            if now >= next_nav:
                next_nav = now + self.NAVDATA_PERIOD_S
                self._send_navdata(now)

    def _on_datagram(self, data, now, addr=None):
        self.pending_ids = None
        for m in _COMMAND_RE.finditer(data):
            name, seq = m.group(1).decode(), int(m.group(2))
            if not (seq == 1 or seq > self.last_seq):
                self.ignored_from[addr] = self.ignored_from.get(addr, 0) + 1
                continue
            self.accepted_from[addr] = self.accepted_from.get(addr, 0) + 1
            self.last_seq = seq
            self.last_cmd_t = now
            args = [int(b) if b else a.decode() for a, b in _ARG_RE.findall(m.group(3))]
            self.log.append((now, name, args, self.phase))
            getattr(self, f"_at_{name.lower()}", lambda *a: None)(args, now)

    # commands
    def _at_ref(self, args, now):
        bits = int(args[0])
        edge = bits & REF_EMERGENCY and not (self.last_ref or 0) & REF_EMERGENCY
        self.last_ref = bits
        if edge:
            if self.phase == "emergency":
                self._set("landed", now)
            else:
                self._set("emergency", now)
            return
        if self.phase == "emergency":
            return
        if bits & REF_TAKEOFF and self.phase == "landed" and not self._state_faults() & VBAT_LOW:
            self.takeoffs += 1
            self._set("takeoff", now)
        elif not bits & REF_TAKEOFF and self.phase in ("takeoff", "hovering"):
            self._set("landing", now)

    def _at_ftrim(self, args, now):
        if self.phase == "landed":
            self.ftrims.append(now)

    def _at_config_ids(self, args, now):
        self.pending_ids = tuple(args[:3])

    def _at_config(self, args, now):
        key, value = args[0], args[1]
        ids = (self.config["custom:session_id"], self.config["custom:profile_id"],
               self.config["custom:application_id"])
        if ids != ("00000000",) * 3 and self.pending_ids != ids and not key.startswith("custom:"):
            return  # a non-default session: a CONFIG without the current ids is ignored
        self.pending_ids = None
        self.ack = True
        if key == "general:navdata_demo":
            self.bootstrap = False
        if self.ignore_config_writes and key.startswith("control:"):
            return  # acknowledged, not applied
        self.config[key] = value
        if key == "control:outdoor":
            self._load_profile()
        elif key[len("control:"):] in LIMITS:  # stored into the active profile
            self.config[f"control:{self._profile()}_{key[len('control:'):]}"] = value

    def _profile(self):
        return "outdoor" if self.config["control:outdoor"].upper() == "TRUE" else "indoor"

    def _load_profile(self):
        profile = self._profile()
        for k in LIMITS:
            self.config[f"control:{k}"] = self.config[f"control:{profile}_{k}"]

    def _at_ctrl(self, args, now):
        mode = int(args[0])
        if mode == 5:
            self.ack = False
        elif mode == 4:
            text = "".join(f"{k} = {v}\n" for k, v in self.config.items()).encode() + b"\0"
            for c in list(self._ctl_clients):
                try:
                    c.sendall(text)
                except OSError:
                    self._ctl_clients.remove(c)
            self.ack = True

    # physics (phases) ---------------------------------------------------------------------
    def _set(self, phase, now):
        if phase == "takeoff":
            self._takeoff_yaw0 = self.yaw_deg
            if self.navdata_gap_at_takeoff is not None:  # the link fails as it climbs
                delay, duration = self.navdata_gap_at_takeoff
                self.silent_from, self.silent_until = now + delay, now + delay + duration
        if phase == "hovering":
            self.hover_since = now
        if phase == "landed" and self.phase == "landing" and self._landing_by_itself:
            self.self_landed_t = now
        if phase == "landing":
            self._landing_by_itself = False
        self.phase, self.phase_t = phase, now
        self.phases.append((now, phase))

    _landing_by_itself = False

    def _advance(self, now):
        if self.last_cmd_t > 0 and now - self.last_cmd_t > LINK_LOSS_S and self._client:
            self.link_losses += 1                       # the client "disconnected"
            self.last_seq = 0
            self._client = None
            self.bootstrap = True
            self.last_cmd_t = -1e9
        dt = now - self.phase_t
        if self.phase == "takeoff":
            self.yaw_deg = self._takeoff_yaw0 + self.takeoff_yaw_dps * min(dt, self.TAKEOFF_S)
            if dt >= self.TAKEOFF_S:
                self._set("hovering", now)
        elif self.phase == "hovering" and self.land_by_itself_after_s is not None and \
                now - self.hover_since >= self.land_by_itself_after_s:
            self._set("landing", now)
            self._landing_by_itself = True
            self.self_landing_start_t = now
            self.land_by_itself_after_s = None  # once
        elif self.phase == "landing" and dt >= self.LANDING_S:
            self._set("landed", now)

    # navdata ------------------------------------------------------------------------------
    _nav_seq = 0

    def _state_and_ctrl(self, now):
        state = 0
        phase = self.phase
        if phase in ("takeoff", "hovering", "landing"):
            state |= FLY
        major = {"landed": LANDED, "hovering": HOVERING, "takeoff": self.codes["takeoff"],
                 "landing": self.codes["landing"], "emergency": 0}[phase]
        if phase == "emergency":
            state |= EMERGENCY
        if self.ack:
            state |= COMMAND
        state |= BOOTSTRAP if self.bootstrap else DEMO
        if now - self.last_cmd_t > 0.05:
            state |= COM_WATCHDOG
        return state | self._state_faults(), major << 16

    def _state_faults(self):
        return self.fault_bits | (VBAT_LOW if self.battery_pct < self.vbat_low_pct else 0)

    def _send_navdata(self, now):
        with self.lock:
            client = self._client
            if client is None or self.silent_from <= now < self.silent_until \
                    or now < self.blackout_until:
                return
            self.last_navdata_t = now
            self._nav_seq += 1
            state, ctrl = self._state_and_ctrl(now)
            body = struct.pack("<IIIi", 0x55667788, state, self._nav_seq, 0)
            if not self.bootstrap:
                alt_mm = {"hovering": 1000, "takeoff": 500, "landing": 300}.get(self.phase, 0)
                roll, pitch = self.attitude_deg
                demo = struct.pack("<HHIIfffifffI", 0, 148, ctrl, self.battery_pct,
                                   pitch * 1000.0, roll * 1000.0, self.yaw_deg * 1000.0,
                                   alt_mm, 0.0, 0.0, 0.0, 0)
                body += demo + bytes(148 - len(demo))
            body += struct.pack("<HHI", 0xFFFF, 8, sum(body) & 0xFFFFFFFF)
        try:
            self.nav.sendto(body, client)
        except OSError:
            pass


class MocapStandIn:
    """A pose stream in the Vicon-style UDP layout (``<IB`` frame, count; items ``<BH`` id,
    size; pose ``<24s6d`` name, mm, rad), independently encoded, 100 Hz, to ``port`` on
    127.0.0.1. ``pose()`` returns ((x, y, z) m, ψ rad) each frame."""

    def __init__(self, port, pose, name="ardrone", first_frame=1):
        self.port, self.pose, self.name = port, pose, name
        self.frame = first_frame
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((LOOPBACK, 0))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True, name="mocap-standin")

    @property
    def address(self):
        return f"{LOOPBACK}:{self.sock.getsockname()[1]}"

    def datagram(self):
        (x, y, z), psi = self.pose()
        jitter_mm = 0.01 * (self.frame % 5)  # a tracker never repeats a pose bit for bit
        item = struct.pack("<24s6d", self.name.encode(), x * 1000 + jitter_mm, y * 1000,
                           z * 1000, 0.0, 0.0, psi)
        return struct.pack("<IB", self.frame, 1) + struct.pack("<BH", 0, len(item)) + item

    def _loop(self):
        while not self._stop.wait(0.01):
            try:
                self.sock.sendto(self.datagram(), (LOOPBACK, self.port))
            except OSError:
                pass
            self.frame += 1

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(timeout=1.0)
        self.sock.close()
