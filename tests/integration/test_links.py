"""Integration tests of the links (DroneLink, MocapLink) over real UDP/TCP sockets on 127.0.0.1.

The drone side is a tiny fake written here with raw sockets and the protocol codecs (not the
simulator in ``sim/``): it answers the navdata wake-up, streams bootstrap then demo navdata,
sets the ACK state bit on AT*CONFIG and clears it on AT*CTRL 5, follows REF take-off / land /
emergency edges, and can be told to drop the ACK, skip sequence numbers, raise the com-watchdog
bit, fall silent, or send garbage. Every packet goes to 127.0.0.1 only; every test has a timeout
and closes its sockets and threads.
"""

from __future__ import annotations

import itertools
import math
import select
import socket
import statistics
import struct
import threading
import time

import numpy as np
import pytest

from ardrone_nmpc.links.drone_link import (
    DroneLink,
    LinkError,
    flight_mode_of,
    parse_config_text,
)
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.links.udp import LinkStats, open_udp
from ardrone_nmpc.protocol.at import (
    CTRL_MODE_ACK,
    CTRL_MODE_CFG_GET,
    AtCommand,
    Comwdg,
    Config,
    ConfigIds,
    Ctrl,
    Ftrim,
    Pcmd,
    PcmdFlag,
    Ref,
    parse_datagram_lenient,
)
from ardrone_nmpc.protocol.mocap import (
    MocapFrame,
    MocapObjectPose,
    encode_mocap,
    rotation_heading_rad,
)
from ardrone_nmpc.protocol.navdata import (
    NAVDATA_WAKEUP,
    CtrlMajor,
    DemoOption,
    DroneState,
    Navdata,
    ctrl_state_value,
    empty_vision_detect_option,
    encode_navdata,
)
from ardrone_nmpc.core.types import FlightMode

LOOPBACK = "127.0.0.1"
REF_TAKEOFF = 290718208
REF_LAND = 290717696
REF_EMERGENCY = 290717952
_THREAD_NAMES = ("drone-navdata-rx", "drone-at-keepalive", "mocap-rx")


def wait_until(predicate, timeout_s: float = 2.0, poll_s: float = 0.005) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return bool(predicate())


def link_threads_alive() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name in _THREAD_NAMES and t.is_alive()]


# ----------------------------------------------------------------------------- the fake drone


class FakeDrone:
    """A minimal AR.Drone 2.0 on 127.0.0.1 (navdata UDP, AT UDP, optional control TCP)."""

    BASE_STATE = (DroneState.PIC_VERSION | DroneState.ATCODEC_THREAD_ON
                  | DroneState.NAVDATA_THREAD_ON | DroneState.ALTITUDE)

    def __init__(self, *, ack: bool = True, rate_hz: float = 50.0,
                 control_text: str | None = None) -> None:
        self.ack_enabled = ack
        self.period_s = 1.0 / rate_hz
        self.control_text = control_text
        self.nav = open_udp(LOOPBACK, 0, timeout_s=None)
        self.at = open_udp(LOOPBACK, 0, timeout_s=None)
        self.tcp: socket.socket | None = None
        if control_text is not None:
            self.tcp = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.tcp.bind((LOOPBACK, 0))
            self.tcp.listen(1)
        self.tcp_conns: list[socket.socket] = []
        self.lock = threading.Lock()
        # protocol state
        self.client: tuple[str, int] | None = None
        self.bootstrap = True
        self.ack = False
        self.flying = False
        self.emergency = False
        self.prev_ref_emergency = False
        self.seq = 0
        self.extra_state = DroneState(0)
        self.skip_next = 0
        # records
        self.wakeups = 0
        self.at_log: list[tuple[float, bytes, list[AtCommand]]] = []
        self.at_errors = 0
        self.nav_sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fake-drone", daemon=True)

    @property
    def nav_port(self) -> int:
        return self.nav.getsockname()[1]

    @property
    def at_port(self) -> int:
        return self.at.getsockname()[1]

    @property
    def control_port(self) -> int:
        return self.tcp.getsockname()[1] if self.tcp is not None else 1

    def start(self) -> FakeDrone:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        for s in (self.nav, self.at, self.tcp, *self.tcp_conns):
            if s is not None:
                s.close()

    # ------------------------------------------------------------------ views for the tests

    def commands(self, since_t: float = -math.inf) -> list[AtCommand]:
        with self.lock:
            return [c for t, _, cmds in self.at_log if t >= since_t for c in cmds]

    def datagrams(self, since_t: float = -math.inf) -> list[tuple[float, list[AtCommand]]]:
        with self.lock:
            return [(t, cmds) for t, _, cmds in self.at_log if t >= since_t]

    def bodies(self, kind, since_t: float = -math.inf) -> list:
        return [c.body for c in self.commands(since_t) if isinstance(c.body, kind)]

    def ref_runs(self) -> list[tuple[int, int]]:
        """The REF bits received, in sequence-number order (the order the drone executes
        them, whatever the scheduler did to receipt times), as ``(bits, count)`` runs."""
        refs = sorted((c for c in self.commands() if isinstance(c.body, Ref)),
                      key=lambda c: c.seq)
        return [(bits, len(list(run)))
                for bits, run in itertools.groupby(c.body.bits for c in refs)]

    def pause(self) -> None:
        """Fall silent and forget the client (only a new wake-up restarts the stream)."""
        with self.lock:
            self.client = None

    def send_raw(self, data: bytes) -> None:
        with self.lock:
            client = self.client
        assert client is not None and client[0] == LOOPBACK
        self.nav.sendto(data, client)

    def packet(self, seq: int | None = None) -> bytes:
        """Navdata bytes of the current state (``seq`` defaults to the next number, unused)."""
        with self.lock:
            return encode_navdata(self._navdata_locked(self.seq + 1 if seq is None else seq))

    # ------------------------------------------------------------------ internals

    def _state_locked(self) -> DroneState:
        s = self.BASE_STATE | DroneState.NAVDATA_DEMO | self.extra_state
        if self.bootstrap:
            s |= DroneState.NAVDATA_BOOTSTRAP
        if self.ack:
            s |= DroneState.COMMAND
        if self.flying:
            s |= DroneState.FLY
        if self.emergency:
            s |= DroneState.EMERGENCY | DroneState.USER_EL
        return s

    def _navdata_locked(self, seq: int) -> Navdata:
        state = self._state_locked()
        if self.bootstrap:
            return Navdata(state, seq)
        major = (CtrlMajor.DEFAULT if self.emergency
                 else CtrlMajor.HOVERING if self.flying else CtrlMajor.LANDED)
        demo = DemoOption.from_si(
            ctrl_state=ctrl_state_value(major), battery_pct=87, pitch_deg=2.0, roll_deg=-1.0,
            yaw_deg=190.0, altitude_m=1.234 if self.flying else 0.0, vx_body_mps=0.1,
            vy_body_mps=-0.2, vz_mps=0.05)
        return Navdata(state, seq, demo=demo, options=(empty_vision_detect_option(),))

    def _send_navdata(self) -> None:
        with self.lock:
            if self.client is None:
                return
            self.seq += 1 + self.skip_next
            self.skip_next = 0
            data = encode_navdata(self._navdata_locked(self.seq))
            client = self.client
        assert client[0] == LOOPBACK
        self.nav.sendto(data, client)
        self.nav_sent += 1

    def _on_at(self, data: bytes) -> None:
        t = time.monotonic()
        cmds, errors = parse_datagram_lenient(data)
        with self.lock:
            self.at_log.append((t, data, cmds))
            self.at_errors += len(errors)
            for c in cmds:
                b = c.body
                if isinstance(b, Config):
                    if self.ack_enabled:
                        self.ack = True
                        self.bootstrap = False
                elif isinstance(b, Ctrl) and b.mode == CTRL_MODE_ACK:
                    self.ack = False
                elif isinstance(b, Ctrl) and b.mode == CTRL_MODE_CFG_GET:
                    if self.tcp_conns and self.control_text is not None:
                        self.tcp_conns[-1].sendall(self.control_text.encode("ascii") + b"\0")
                        self.ack = True
                elif isinstance(b, Ref):
                    if b.is_emergency and not self.prev_ref_emergency:
                        self.emergency = not self.emergency
                        if self.emergency:
                            self.flying = False
                    self.prev_ref_emergency = b.is_emergency
                    if not self.emergency:
                        self.flying = b.is_takeoff

    def _run(self) -> None:
        next_nav = time.monotonic()
        while not self._stop.is_set():
            # The listening socket first: accept a control connection before reading the
            # AT*CTRL 4 that asks for the dump on it.
            socks = ([self.tcp] if self.tcp is not None else []) + [self.nav, self.at]
            timeout = max(0.0, next_nav - time.monotonic())
            readable, _, _ = select.select(socks, [], [], min(timeout, 0.05))
            for s in readable:
                if s is self.tcp:
                    conn, _ = self.tcp.accept()
                    self.tcp_conns.append(conn)
                    continue
                data, addr = s.recvfrom(8192)
                if s is self.nav:
                    assert addr[0] == LOOPBACK
                    with self.lock:
                        self.client = addr
                        self.wakeups += 1
                else:
                    self._on_at(data)
            if time.monotonic() >= next_nav:
                self._send_navdata()
                next_nav += self.period_s
                if next_nav < time.monotonic():
                    next_nav = time.monotonic() + self.period_s


@pytest.fixture
def drone():
    d = FakeDrone().start()
    yield d
    d.close()


def make_link(d: FakeDrone, **kw) -> DroneLink:
    return DroneLink(LOOPBACK, at_port=d.at_port, navdata_port=d.nav_port,
                     control_port=d.control_port, bind_host=LOOPBACK, **kw)


def assert_one_sequencer(d: FakeDrone) -> None:
    seqs = [c.seq for c in d.commands()]
    assert seqs[0] == 1
    assert seqs == list(range(1, len(seqs) + 1)), "AT seq must increase by 1 per command"


# ----------------------------------------------------------------------------- DroneLink


@pytest.mark.timeout(10)
def test_connect_wakes_navdata_and_leaves_bootstrap_with_ack_handshake(drone):
    with make_link(drone) as link:
        link.connect(timeout_s=3.0)
        assert link.connected
        assert drone.wakeups >= 1
        cmds = drone.commands()
        i_cfg = next(i for i, c in enumerate(cmds) if isinstance(c.body, Config))
        assert cmds[i_cfg].body == Config("general:navdata_demo", "TRUE")
        assert not any(isinstance(c.body, ConfigIds) for c in cmds)   # default session
        i_ack = next(i for i, c in enumerate(cmds)
                     if isinstance(c.body, Ctrl) and c.body.mode == CTRL_MODE_ACK)
        assert i_ack > i_cfg
        state = link.state
        assert DroneState.NAVDATA_BOOTSTRAP not in state
        assert DroneState.COMMAND not in state            # ACK cleared before connect returned
        nav = link.navdata
        assert nav is not None and link.navdata_rx_t_s <= time.monotonic()
        assert nav.mode is FlightMode.LANDED and nav.battery_pct == 87.0
        assert nav.pitch_deg == pytest.approx(2.0) and nav.roll_deg == pytest.approx(-1.0)
        assert nav.yaw_deg == pytest.approx(-170.0)       # 190° wrapped to (−180, 180]
        assert nav.vx_body_mps == pytest.approx(0.1) and nav.vy_body_mps == pytest.approx(-0.2)
        assert nav.vz_mps == pytest.approx(0.05) and nav.altitude_m == 0.0
        assert wait_until(lambda: link.stats.rate_hz > 20.0)
        assert link.stats.age_ms(time.monotonic()) < 500.0
        assert_one_sequencer(drone)
    assert link_threads_alive() == []


@pytest.mark.timeout(10)
def test_configure_limits_writes_four_keys_in_drone_units(drone):
    with make_link(drone) as link:
        link.connect(timeout_s=3.0)
        t0 = time.monotonic()
        written = link.configure_limits(euler_angle_max_rad=0.35, control_vz_max_mps=1.0,
                                        control_yaw_radps=3.0, altitude_max_m=3.0)
        expected = {"control:euler_angle_max": "0.35", "control:control_vz_max": "1000",
                    "control:control_yaw": "3.0", "control:altitude_max": "3000"}
        assert written == expected
        configs = drone.bodies(Config, since_t=t0)
        assert [(c.key, c.value) for c in configs] == list(expected.items())
        # One key at a time: a CTRL 5 (ACK clear) after every CONFIG, before the next one.
        kinds = [("cfg" if isinstance(c.body, Config) else "ack")
                 for c in drone.commands(t0)
                 if isinstance(c.body, Config)
                 or (isinstance(c.body, Ctrl) and c.body.mode == CTRL_MODE_ACK)]
        assert kinds[0] == "cfg" and kinds[-1] == "ack"
        assert "cfg,cfg" not in ",".join(kinds)
        assert link.configure_limits(0.2094, 0.7, 1.745, 2.5)["control:control_vz_max"] == "700"
        with pytest.raises(ValueError, match="euler_angle_max"):
            link.configure_limits(0.6, 1.0, 3.0, 3.0)
        with pytest.raises(ValueError, match="control_vz_max"):
            link.configure_limits(0.3, -1.0, 3.0, 3.0)
        assert_one_sequencer(drone)


@pytest.mark.timeout(10)
def test_keepalive_resends_within_interval(drone):
    with make_link(drone, keepalive_interval_s=0.03) as link:
        link.connect(timeout_s=3.0)
        t0 = time.monotonic()
        time.sleep(1.0)
        times = [t for t, cmds in drone.datagrams(t0)
                 if any(isinstance(c.body, Pcmd) for c in cmds)]
        gaps = np.diff(times)
        print(f"\nkeepalive: {len(times)} PCMD datagrams in 1 s, gap mean "
              f"{1e3 * statistics.fmean(gaps):.1f} ms, p99 {1e3 * np.quantile(gaps, 0.99):.1f} "
              f"ms, max {1e3 * gaps.max():.1f} ms")
        assert len(times) >= 25
        assert gaps.max() <= 0.060                  # 30 ms + generous jitter (shared machines)
        assert statistics.fmean(gaps) <= 0.036
        assert link.sent_count >= len(times)
        # Before any take-off/land call the link sends no REF (it never lands a flying drone
        # on its own); the PCMD is hover.
        assert drone.bodies(Ref) == []
        assert link.ref is None
        assert all(p == Pcmd.hover() for p in drone.bodies(Pcmd, since_t=t0))


@pytest.mark.timeout(10)
def test_stale_command_is_replaced_by_hover(drone):
    with make_link(drone, stale_command_s=0.12) as link:
        link.connect(timeout_s=3.0)
        t0 = time.monotonic()
        link.set_command(0.1, -0.2, 0.3, -0.4)
        time.sleep(0.4)
        pcmds = drone.bodies(Pcmd, since_t=t0)
        flags = [p.flags for p in pcmds]
        first_hover = flags.index(0)
        assert first_hover >= 3                       # sent at once, then resent while fresh
        assert all(f == int(PcmdFlag.PROGRESSIVE) for f in flags[:first_hover])
        assert all(f == 0 for f in flags[first_hover:])   # never back without a new command
        assert len(flags) - first_hover >= 4
        p = pcmds[0]
        assert (p.roll_frac, p.pitch_frac, p.gaz_frac, p.yaw_frac) == pytest.approx(
            (0.1, -0.2, 0.3, -0.4), abs=1e-7)
        assert all(h == Pcmd.hover() for h in pcmds[first_hover:])
        assert link.stale_hovers >= 4 and link.stale_episodes == 1
        # A new command is fresh again; an explicit hover never counts as stale.
        t1 = time.monotonic()
        link.set_command(0.0, 0.5, 0.0, 0.0)
        assert wait_until(lambda: any(p.flags for p in drone.bodies(Pcmd, since_t=t1)))
        link.hover()
        n = link.stale_hovers
        time.sleep(0.25)
        assert link.stale_hovers == n
        assert link.command == Pcmd.hover()
        assert_one_sequencer(drone)


@pytest.mark.timeout(10)
def test_ref_bits_take_off_land_emergency_and_reset(drone):
    """Each REF is held by the keepalive until the next call replaces it, and no stale REF
    follows a newer one. Checked in sequence-number order and by waiting for the drone to
    have received them: a keepalive datagram sent just before land() may well be read by the
    fake drone after land() returned (a loaded machine), so receipt times prove nothing."""

    def ref_bits():
        return [bits for bits, _ in drone.ref_runs()]

    def held(bits):
        """The newest REF run is ``bits``, repeated by the keepalive at least 4 times."""
        def check():
            runs = drone.ref_runs()
            return bool(runs) and runs[-1][0] == bits and runs[-1][1] >= 4
        return check

    with make_link(drone) as link:
        link.connect(timeout_s=3.0)
        with pytest.raises(ValueError):
            link.set_command(1.5, 0.0, 0.0, 0.0)
        link.takeoff()
        assert wait_until(lambda: link.navdata.mode is FlightMode.FLYING)
        assert wait_until(held(REF_TAKEOFF))
        assert ref_bits() == [REF_TAKEOFF]                 # level, held
        assert link.navdata.altitude_m == pytest.approx(1.234)
        with pytest.raises(LinkError, match="flying"):
            link.flat_trim()

        link.land()
        assert wait_until(lambda: link.navdata.mode is FlightMode.LANDED)
        assert wait_until(held(REF_LAND))
        assert ref_bits() == [REF_TAKEOFF, REF_LAND]

        link.flat_trim()
        assert wait_until(lambda: len(drone.bodies(Ftrim)) == 1)

        link.emergency()
        assert wait_until(lambda: link.navdata.mode is FlightMode.EMERGENCY)
        assert wait_until(held(REF_EMERGENCY))
        assert ref_bits() == [REF_TAKEOFF, REF_LAND, REF_EMERGENCY]
        assert drone.emergency                        # held bit 8: one edge, no toggling back
        with pytest.raises(LinkError, match="take-off refused: the link landed the drone"):
            link.takeoff()                            # barred for good since land()
        link.reset_emergency(timeout_s=2.0)
        assert wait_until(lambda: link.navdata.mode is FlightMode.LANDED)
        assert link.ref == Ref.landing() and not drone.emergency
        # the reset: bit 8 low, then one rising edge, then land held
        assert wait_until(lambda: ref_bits() == [REF_TAKEOFF, REF_LAND, REF_EMERGENCY,
                                                 REF_LAND, REF_EMERGENCY, REF_LAND])
        with pytest.raises(LinkError, match="does not show an emergency"):
            link.reset_emergency()
        assert_one_sequencer(drone)


@pytest.mark.timeout(10)
def test_handshake_timeout_raises_link_error_and_closes():
    d = FakeDrone(ack=False).start()
    try:
        link = make_link(d)
        t0 = time.monotonic()
        with pytest.raises(LinkError, match=r"general:navdata_demo.*no ACK"):
            link.connect(timeout_s=0.6)
        assert time.monotonic() - t0 < 2.0
        assert not link.connected
        assert wait_until(lambda: link_threads_alive() == [])
        assert len(d.bodies(Config)) >= 2               # the CONFIG was re-sent while waiting
        with pytest.raises(LinkError, match="not connected"):
            link.takeoff()
        with pytest.raises(LinkError, match="closed"):
            link.connect()
    finally:
        d.close()


@pytest.mark.timeout(10)
def test_no_navdata_raises_link_error():
    silent = open_udp(LOOPBACK, 0, timeout_s=0.5)
    try:
        link = DroneLink(LOOPBACK, navdata_port=silent.getsockname()[1], at_port=1,
                         bind_host=LOOPBACK, wake_retry_s=0.1)
        with pytest.raises(LinkError, match="no navdata"):
            link.connect(timeout_s=0.5)
        assert link.wakeups >= 3
        assert silent.recv(64) == NAVDATA_WAKEUP
        assert wait_until(lambda: link_threads_alive() == [])
    finally:
        silent.close()


@pytest.mark.timeout(10)
def test_malformed_navdata_is_counted_and_gaps_are_loss(drone):
    with make_link(drone) as link:
        link.connect(timeout_s=3.0)
        good = drone.packet()
        bad_cks = bytearray(good)
        bad_cks[20] ^= 0xFF
        zero_size = good[:16] + struct.pack("<HH", 43150, 0) + good[20:]
        for raw in (b"garbage", bytes(bad_cks), zero_size, good[:30]):
            drone.send_raw(raw)
        assert wait_until(lambda: link.stats.malformed == 4)
        n = link.stats.packets
        assert wait_until(lambda: link.stats.packets > n + 3)     # still receiving
        assert link.last_error is not None and "navdata" in link.last_error
        # A stale sequence number is dropped, a skipped range counts as lost.
        drone.send_raw(drone.packet(seq=max(2, drone.seq - 2)))
        assert wait_until(lambda: link.stats.out_of_order >= 1)
        with drone.lock:
            drone.skip_next = 5
        assert wait_until(lambda: link.stats.lost >= 5)
        snap = link.stats.snapshot(time.monotonic())
        assert snap.lost >= 5 and 0.0 < snap.loss_frac < 0.5 and snap.malformed == 4


@pytest.mark.timeout(10)
def test_comwdg_answers_watchdog_bit(drone):
    with make_link(drone) as link:
        link.connect(timeout_s=3.0)
        t0 = time.monotonic()
        with drone.lock:
            drone.extra_state = DroneState.COM_WATCHDOG
        assert wait_until(lambda: len(drone.bodies(Comwdg, since_t=t0)) >= 1)
        with drone.lock:
            drone.extra_state = DroneState(0)
        assert link.comwdg_sent >= 1


@pytest.mark.timeout(10)
def test_rewake_after_navdata_silence(drone):
    with make_link(drone, rewake_after_s=0.3) as link:
        link.connect(timeout_s=3.0)
        wakes = drone.wakeups
        drone.pause()
        assert wait_until(lambda: link.rewakes >= 1, timeout_s=3.0)
        assert wait_until(lambda: drone.wakeups > wakes)
        n = link.stats.packets
        assert wait_until(lambda: link.stats.packets > n + 3)
        assert link.stats.age_ms(time.monotonic()) < 200.0


@pytest.mark.timeout(10)
def test_read_config_over_control_port():
    text = ("general:num_version_config = 1\ncontrol:euler_angle_max = 2.0943952e-01\n"
            "control:control_vz_max = 7.0000000e+02\ncontrol:altitude_max = 3000\n")
    d = FakeDrone(control_text=text).start()
    try:
        with make_link(d) as link:
            link.connect(timeout_s=3.0)
            t0 = time.monotonic()
            cfg = link.read_config(timeout_s=2.0)
            assert cfg == parse_config_text(text)
            assert cfg["control:altitude_max"] == "3000"
            assert cfg["control:euler_angle_max"] == "2.0943952e-01"
            ctrls = [b.mode for b in d.bodies(Ctrl, since_t=t0)]
            assert ctrls[0] == CTRL_MODE_CFG_GET and CTRL_MODE_ACK in ctrls[1:]
            assert wait_until(lambda: DroneState.COMMAND not in link.state)
    finally:
        d.close()


@pytest.mark.timeout(10)
def test_multiconfig_ids_precede_every_config(drone):
    ids = ("0a1b2c3d", "be27e2e4", "d87f7e0c")
    with make_link(drone, config_ids=ids) as link:
        link.connect(timeout_s=3.0)
        link.write_config("control:outdoor", False)
        keys = []
        for _, cmds in drone.datagrams():
            for i, c in enumerate(cmds):
                if isinstance(c.body, Config):
                    assert i > 0 and cmds[i - 1].body == ConfigIds(*ids)
                    assert cmds[i - 1].seq == c.seq - 1
                    keys.append(c.body.key)
        assert keys[:5] == ["custom:session_id", "custom:profile_id", "custom:application_id",
                            "general:navdata_demo", "control:outdoor"]
    with pytest.raises(ValueError, match="8 hex"):
        DroneLink(LOOPBACK, config_ids=("xyz", "0", "0"))


@pytest.mark.timeout(5)
def test_commands_validate_without_a_connection():
    link = DroneLink(LOOPBACK)
    for bad in (math.nan, math.inf, 1.0001, -2.0):
        with pytest.raises(ValueError):
            link.set_command(0.0, bad, 0.0, 0.0)
    link.set_command(0.2, 0.0, -1.0, 1.0)             # stored, nothing sent (not open)
    assert link.command == Pcmd.move(0.2, 0.0, -1.0, 1.0) and link.sent_count == 0
    with pytest.raises(LinkError, match="not connected"):
        link.takeoff()
    with pytest.raises(LinkError, match="not connected"):
        link.write_config("control:outdoor", False)
    link.close()
    assert link.navdata is None and link.navdata_rx_t_s == -math.inf and link.state is None


@pytest.mark.parametrize("state,major,mode", [
    (DroneState.EMERGENCY | DroneState.FLY, 4, FlightMode.EMERGENCY),
    (DroneState.FLY, 6, FlightMode.TAKING_OFF),
    (DroneState.FLY, 7, FlightMode.TAKING_OFF),
    (DroneState.FLY, 8, FlightMode.LANDING),
    (DroneState.FLY, 9, FlightMode.LANDING),
    (DroneState.FLY, 3, FlightMode.FLYING),
    (DroneState.FLY, 4, FlightMode.FLYING),
    (DroneState(0), 2, FlightMode.LANDED),
    # airborne is bit 0 alone, landed is major 2 alone: an unknown code in the air is never
    # taken for flying, a code other than 2 on the ground is not "landed" yet
    (DroneState.FLY, 10, FlightMode.LANDING),
    (DroneState.FLY, 2, FlightMode.LANDING),
    (DroneState(0), 0, FlightMode.LANDING),
    (DroneState(0), 4, FlightMode.LANDING),
    (DroneState(0), 9, FlightMode.LANDING),
    (DroneState(0), 6, FlightMode.TAKING_OFF),
    (DroneState.FLY, None, FlightMode.FLYING),
    (DroneState(0), None, FlightMode.LANDED),
    (DroneState.EMERGENCY, 2, FlightMode.EMERGENCY),
])
def test_flight_mode_of(state, major, mode):
    assert flight_mode_of(state, major) is mode


def test_link_stats_sequence_rules():
    s = LinkStats(window_s=1.0, restart_backjump=10)
    for seq, t in ((5, 0.0), (6, 0.1), (9, 0.2)):
        assert s.accept_sequence(seq)
        s.record_packet(t)
    assert not s.accept_sequence(9) and not s.accept_sequence(7)
    assert s.lost == 2 and s.out_of_order == 2
    assert s.accept_sequence(1000) and s.accept_sequence(3)      # jump ahead; restart
    assert s.restarts == 1
    assert s.rate_hz == pytest.approx(10.0)
    assert s.age_ms(0.5) == pytest.approx(300.0)
    assert LinkStats().age_ms(1.0) == math.inf


# ----------------------------------------------------------------------------- MocapLink


class Streamer:
    """Sends mocap datagrams to the link on 127.0.0.1 and waits until it has read them."""

    def __init__(self, link: MocapLink) -> None:
        self.link = link
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sent = 0

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, (LOOPBACK, self.link.port))
        self.sent += 1
        assert wait_until(lambda: self.link.stats.datagrams >= self.sent, timeout_s=2.0)

    def send(self, frame_number: int, *poses: MocapObjectPose) -> None:
        self.send_raw(encode_mocap(MocapFrame.of(frame_number, poses)))

    def close(self) -> None:
        self.sock.close()


def pose(name="ardrone", t=(1000.0, -500.0, 1500.0), r=(0.01, -0.02, 0.5)) -> MocapObjectPose:
    return MocapObjectPose(name, t, r)


@pytest.fixture
def mocap():
    ticks = itertools.count(1)
    with MocapLink(LOOPBACK, 0, object_name="ardrone",
                   clock=lambda: float(next(ticks))) as link:
        streamer = Streamer(link)
        yield link, streamer
        streamer.close()
    assert link_threads_alive() == []


@pytest.mark.timeout(10)
def test_mocap_latest_pose_converted_and_stamped(mocap):
    link, st = mocap
    assert link.port != 0
    assert link.latest() == (None, -math.inf)
    st.send(1, pose("wand", (1.0, 2.0, 3.0)), pose())
    p, rx = link.latest()
    assert rx == 1.0 and p.t_s == 1.0
    np.testing.assert_allclose(p.position_m, [1.0, -0.5, 1.5])
    np.testing.assert_allclose(p.rotation_xyz_rad, [0.01, -0.02, 0.5])
    assert p.psi_rad == pytest.approx(rotation_heading_rad(0.01, -0.02, 0.5))
    assert not p.position_m.flags.writeable
    st.send(2, pose(t=(1010.0, -500.0, 1500.0)))
    p, rx = link.latest()
    assert rx == 2.0 and p.position_m[0] == pytest.approx(1.01)
    assert link.poses == 2 and link.stats.packets == 2 and link.stats.lost == 0


@pytest.mark.timeout(10)
def test_mocap_age_grows_when_object_disappears():
    with MocapLink(LOOPBACK, 0) as link:
        st = Streamer(link)
        try:
            for k in range(1, 4):
                st.send(k, pose(t=(1000.0 + k, 0.0, 1000.0)))
            _, rx = link.latest()
            for k in range(4, 9):
                st.send(k, pose("wand"))
            p, rx2 = link.latest()
            assert rx2 == rx and p.position_m[0] == pytest.approx(1.003)
            assert link.missing == 5
            a1 = link.age_ms(time.monotonic())
            time.sleep(0.05)
            a2 = link.age_ms(time.monotonic())
            assert a2 >= a1 + 40.0
            assert link.stats.packets == 8 and link.stats.rate_hz > 0.0
            assert link.stats.age_ms(time.monotonic()) < a2    # the stream itself is alive
        finally:
            st.close()


@pytest.mark.timeout(10)
def test_mocap_all_zero_pose_ignored(mocap):
    link, st = mocap
    st.send(1, pose())
    st.send(2, pose(t=(0.0, 0.0, 0.0), r=(0.0, 0.0, 0.0)))
    st.send(3, pose(t=(0.0, 0.0, 0.0), r=(0.0, 0.0, 0.0)))
    p, rx = link.latest()
    assert rx == 1.0 and p.position_m[2] == pytest.approx(1.5)
    assert link.zero_poses == 2 and link.poses == 1


@pytest.mark.timeout(10)
def test_mocap_repeated_identical_pose_stops_being_fresh(mocap):
    link, st = mocap
    for k in range(1, 7):
        st.send(k, pose())                           # bit-identical six frames running
    _, rx = link.latest()
    assert rx == 2.0                                 # frames 1–2 accepted, 3rd on ignored
    assert link.poses == 2 and link.repeats == 4
    st.send(7, pose(t=(1000.0, -500.0, 1500.0 + 1e-9)))
    p, rx = link.latest()
    assert rx == 7.0 and link.poses == 3
    # Repeats interrupted by a different pose start counting again.
    st.send(8, pose())
    st.send(9, pose(t=(999.0, -500.0, 1500.0)))
    st.send(10, pose())
    assert link.poses == 6


@pytest.mark.timeout(10)
def test_mocap_frame_gaps_reordering_and_malformed():
    now = [0.0]
    with MocapLink(LOOPBACK, 0, object_name="ardrone", clock=lambda: now[0]) as link:
        st = Streamer(link)
        try:
            _gaps_reordering_and_malformed(link, st, now)
        finally:
            st.close()


def _gaps_reordering_and_malformed(link, st, now):
    def send(k, x_mm, dt_s=0.01):
        now[0] += dt_s
        st.send(k, pose(t=(x_mm, 1.0, 1.0)))

    send(1, 1.0)
    send(2, 2.0)
    send(5, 5.0)
    send(4, 4.0)                                      # late: dropped
    send(6, 6.0)
    assert link.stats.lost == 2 and link.stats.out_of_order == 1 and link.stats.packets == 4
    assert link.latest()[0].position_m[0] == pytest.approx(0.006)
    st.send_raw(b"\x01\x02")                         # shorter than the header
    good = encode_mocap(MocapFrame.of(7, [pose()]), pad=False)
    st.send_raw(good[:40])                           # the item overruns the datagram
    assert link.stats.malformed == 2 and link.last_error.startswith("mocap")
    send(5000, 7.0)
    send(3, 8.0)                                     # far below, but no silence: dropped
    assert link.stats.restarts == 0 and link.stats.out_of_order == 2
    assert link.latest()[0].position_m[0] == pytest.approx(0.007)
    send(3, 9.0, dt_s=0.6)                           # after a 0.6 s silence: a restart
    assert link.stats.restarts == 1
    assert link.latest()[0].position_m[0] == pytest.approx(0.009)
