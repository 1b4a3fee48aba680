"""The loopback AR.Drone over real UDP on 127.0.0.1 (ardrone_nmpc.sim.drone_server).

The client here is deliberately *not* the project's links module: a few raw sockets, bytes
written with the protocol/at.py encoders (or typed by hand, as third-party clients do) and
navdata decoded with protocol/navdata.py. Every socket and server is closed by a fixture
finaliser; every test has a timeout; nothing is sent anywhere but 127.0.0.1.
"""

from __future__ import annotations

import socket
import threading
import time

import pytest

from ardrone_nmpc.config.schema import ExperimentConfig, NoiseConfig
from ardrone_nmpc.protocol.at import (
    CTRL_MODE_ACK,
    CTRL_MODE_CFG_GET,
    AtCommand,
    AtSequencer,
    Comwdg,
    Config,
    Ctrl,
    Pcmd,
    Ref,
)
from ardrone_nmpc.protocol.mocap import decode_mocap
from ardrone_nmpc.protocol.navdata import (
    CtrlMajor,
    DroneState,
    NAVDATA_WAKEUP,
    Navdata,
    NavdataError,
    OptionTag,
    decode_navdata,
)
from ardrone_nmpc.sim.drone_server import DroneServer, require_loopback_host
from ardrone_nmpc.sim.mocap_server import MocapServer
from ardrone_nmpc.sim.plant import AirframePlant, FlightMode, PlantParams

LOCALHOST = "127.0.0.1"
S = DroneState
QUIET = NoiseConfig(mocap_position_std_m=0.0, mocap_angle_std_rad=0.0,
                    navdata_attitude_std_rad=0.0, navdata_yaw_std_rad=0.0,
                    navdata_altitude_std_m=0.0, navdata_velocity_std_mps=0.0)
# take off / land faster than the default plant so the flight tests stay short
FAST = dict(takeoff_climb_mps=1.0, landing_speed_mps=1.0)


# ----------------------------------------------------------------------------- raw client


class RawClient:
    """A minimal AR.Drone client: node-ar-drone's shape (REF + PCMD every 30 ms).

    ``ref`` and ``pcmd`` are the levels it keeps sending; ``keepalive=False`` in the helpers
    goes silent on the AT port.
    """

    def __init__(self, at_port: int, navdata_port: int) -> None:
        self.at_addr = (LOCALHOST, at_port)
        self.nav_addr = (LOCALHOST, navdata_port)
        self.nav = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.nav.bind((LOCALHOST, 0))
        self.at = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.seq = AtSequencer()
        self.ref = Ref.landing()
        self.pcmd = Pcmd.hover()
        self.last: Navdata | None = None
        self.bad_packets = 0

    def close(self) -> None:
        self.nav.close()
        self.at.close()

    # --- sending
    def send(self, *bodies) -> None:
        for dg in self.seq.pack(bodies):
            self.at.sendto(dg, self.at_addr)

    def send_raw(self, data: bytes) -> None:
        self.at.sendto(data, self.at_addr)

    def wake(self, payload: bytes = NAVDATA_WAKEUP) -> None:
        self.nav.sendto(payload, self.nav_addr)

    def keepalive(self) -> None:
        self.send(self.ref, self.pcmd)

    # --- receiving
    def _recv(self, timeout: float) -> tuple[float, Navdata] | None:
        self.nav.settimeout(max(1e-4, timeout))
        try:
            data, addr = self.nav.recvfrom(65536)
        except socket.timeout:
            return None
        t = time.monotonic()
        assert addr == self.nav_addr, f"navdata from {addr}, expected {self.nav_addr}"
        try:
            nav = decode_navdata(data)
        except NavdataError:
            self.bad_packets += 1
            raise
        self.last = nav
        return t, nav

    def drain(self) -> None:
        while self._recv(0.0) is not None:
            pass

    def collect(self, duration_s: float, *, keepalive: bool = True,
                interval_s: float = 0.03) -> list[tuple[float, Navdata]]:
        """Every packet received during ``duration_s`` (sending the levels meanwhile)."""
        out = []
        end = time.monotonic() + duration_s
        next_ka = time.monotonic()
        while (now := time.monotonic()) < end:
            if keepalive and now >= next_ka:
                self.keepalive()
                next_ka = now + interval_s
            got = self._recv(min(end, next_ka if keepalive else end) - now)
            if got is not None:
                out.append(got)
        return out

    def wait_for(self, predicate, timeout_s: float, *, what: str = "condition",
                 keepalive: bool = True, interval_s: float = 0.03) -> Navdata:
        """The first packet satisfying ``predicate`` within ``timeout_s``."""
        end = time.monotonic() + timeout_s
        next_ka = time.monotonic()
        while (now := time.monotonic()) < end:
            if keepalive and now >= next_ka:
                self.keepalive()
                next_ka = now + interval_s
            got = self._recv(min(end, next_ka if keepalive else end) - now)
            if got is not None and predicate(got[1]):
                return got[1]
        last = self.last
        raise AssertionError(
            f"timed out after {timeout_s} s waiting for {what}; last state "
            f"{None if last is None else repr(S(last.state))}, demo "
            f"{None if last is None or last.demo is None else last.demo.ctrl_state >> 16}")

    def start_demo(self) -> Navdata:
        """Wake-up, CONFIG navdata_demo, ACK, CTRL 5: the SDK's start-up handshake."""
        self.wake()
        self.wait_for(lambda n: True, 2.0, what="first navdata", keepalive=False)
        self.send(Config.of("general:navdata_demo", True))
        self.wait_for(lambda n: n.state & S.COMMAND and n.demo is not None, 2.0, what="ACK")
        self.send(Ctrl(CTRL_MODE_ACK))
        return self.wait_for(lambda n: not n.state & S.COMMAND, 2.0, what="ACK cleared")


def major(nav: Navdata) -> int:
    return nav.demo.ctrl_state >> 16


def minor(nav: Navdata) -> int:
    return nav.demo.ctrl_state & 0xFFFF


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture
def make_server():
    """DroneServer factory: ``make_server(plant_overrides..., server=dict(...))``; all stopped
    at teardown."""
    servers: list[DroneServer] = []

    def make(*, server: dict | None = None, noise=QUIET, seed: int = 3, **plant_changes):
        plant = AirframePlant(PlantParams(**plant_changes), noise, seed=seed)
        srv = DroneServer(plant, **(server or {}))
        servers.append(srv)
        return srv.start()

    yield make
    for srv in servers:
        srv.stop()
    for srv in servers:
        assert not any(t.name.startswith("drone-server") and t.is_alive()
                       for t in threading.enumerate()), "server threads still running"


@pytest.fixture
def make_client():
    clients: list[RawClient] = []

    def make(server: DroneServer) -> RawClient:
        c = RawClient(server.at_port, server.navdata_port)
        clients.append(c)
        return c

    yield make
    for c in clients:
        c.close()


@pytest.fixture
def mocap_rx():
    """A UDP socket on a free 127.0.0.1 port standing in for the mocap receiver."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((LOCALHOST, 0))
    yield s
    s.close()


def latest_mocap(sock: socket.socket, name: str = "ardrone", timeout_s: float = 1.0):
    """A pose sent after this call: discards what is queued (a full receive buffer drops the
    newest datagrams, so the queue can be stale), then waits for the next datagram."""
    sock.settimeout(0.0)
    try:
        while True:
            sock.recv(2048)
    except BlockingIOError:
        pass
    sock.settimeout(timeout_s)
    return decode_mocap(sock.recv(2048)).poses[name]


# ----------------------------------------------------------------------------- start-up


@pytest.mark.timeout(20)
def test_bootstrap_then_ack_handshake_then_demo_packets_at_15_hz(make_server, make_client):
    srv = make_server()
    cli = make_client(srv)
    cli.wake()
    boot = [n for _, n in cli.collect(0.5, keepalive=False)]
    assert len(boot) >= 3, "bootstrap packets are streamed after the wake-up"
    for n in boot:
        assert n.demo is None and n.options == ()
        assert n.state & S.NAVDATA_BOOTSTRAP and n.state & S.NAVDATA_DEMO
        assert n.state & S.COM_WATCHDOG            # no AT traffic yet
        assert not n.state & (S.FLY | S.COMMAND | S.EMERGENCY)
    assert [n.sequence for n in boot] == list(range(boot[0].sequence,
                                                    boot[0].sequence + len(boot)))
    assert boot[0].sequence == 1
    assert srv.navdata_client == cli.nav.getsockname()

    cli.send(Config.of("general:navdata_demo", True))
    acked = cli.wait_for(lambda n: n.state & S.COMMAND, 2.0, what="config ACK")
    assert not acked.state & S.NAVDATA_BOOTSTRAP and acked.state & S.NAVDATA_DEMO
    assert srv.config["general:navdata_demo"] == "TRUE"
    cli.send(Ctrl(CTRL_MODE_ACK))
    cli.wait_for(lambda n: not n.state & S.COMMAND, 2.0, what="ACK cleared by CTRL 5")

    packets = cli.collect(1.2)
    # the rate is the server's schedule (a wall-time rate measured here would fail on a loaded
    # machine: timings live in benchmarks); the packets are every one it sent, in order
    assert srv.navdata_period_s == pytest.approx(1.0 / 15.0)
    assert len(packets) >= 2
    seqs = [n.sequence for _, n in packets]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    for _, n in packets:
        assert n.demo is not None and n.option(OptionTag.VISION_DETECT) is not None
        assert major(n) == CtrlMajor.LANDED and n.demo.battery_pct == 100
        assert not n.state & (S.FLY | S.COMMAND | S.NAVDATA_BOOTSTRAP)
    # bit 30 clears with the client's traffic (a keepalive late by > 50 ms on a loaded
    # machine sets it again for a packet, as on the drone)
    assert any(not n.state & S.COM_WATCHDOG for _, n in packets)
    assert cli.bad_packets == 0


@pytest.mark.timeout(20)
def test_navdata_demo_false_streams_full_rate_without_the_demo_bit(make_server, make_client):
    srv = make_server()
    cli = make_client(srv)
    cli.wake()
    cli.wait_for(lambda n: True, 2.0, keepalive=False)
    cli.send(Config.of("general:navdata_demo", False))
    cli.wait_for(lambda n: n.state & S.COMMAND and not n.state & S.NAVDATA_BOOTSTRAP, 2.0)
    cli.send(Ctrl(CTRL_MODE_ACK))
    packets = cli.collect(0.6)
    assert srv.navdata_period_s == pytest.approx(1.0 / 200.0)  # the schedule, not wall time
    assert len(packets) >= 2
    n = packets[-1][1]
    assert not n.state & S.NAVDATA_DEMO and n.demo is not None
    assert n.option(OptionTag.TIME) is not None


# ----------------------------------------------------------------------------- flight


@pytest.mark.timeout(30)
def test_takeoff_fly_forward_lose_com_and_land(make_server, make_client, mocap_rx):
    srv = make_server(noise=NoiseConfig(), **FAST)    # default sensor noise
    cli = make_client(srv)
    mocap = MocapServer(srv.plant, target=mocap_rx.getsockname(), lock=srv.lock)
    with mocap:
        cli.start_demo()
        cli.ref = Ref.takeoff()
        t0 = time.monotonic()
        first = cli.wait_for(lambda n: n.state & S.FLY, 1.0, what="FLY bit")
        assert first.state & S.USER_FEEDBACK_START
        assert major(first) in (6, 7, CtrlMajor.HOVERING)
        cli.wait_for(lambda n: n.demo.altitude_mm > 300, 5.0 - (time.monotonic() - t0),
                     what="altitude rising within 5 s")
        cli.wait_for(lambda n: major(n) == CtrlMajor.HOVERING, 5.0, what="hovering")
        cli.collect(0.8)                      # the vertical loop settles at ≈ 0.9 m
        assert 700 < cli.last.demo.altitude_mm < 1200
        assert major(cli.last) == CtrlMajor.HOVERING

        x0 = latest_mocap(mocap_rx).position_m[0]
        cli.pcmd = Pcmd.move(0.0, -0.5, 0.0, 0.0)         # nose down = forward
        moving = cli.wait_for(lambda n: major(n) == CtrlMajor.FLYING, 1.0, what="FLYING")
        cli.collect(1.5)
        pose = latest_mocap(mocap_rx)
        assert pose.position_m[0] > x0 + 0.3, (x0, pose.position_m)
        assert abs(pose.position_m[1]) < 0.1
        assert cli.last.demo.pitch_deg < -3.0 and cli.last.demo.vx_mmps > 200
        assert moving.state & S.FLY

        # silent AT port: com watchdog bit, then hover (LOST_COM) after 250 ms
        lost = cli.wait_for(lambda n: major(n) == CtrlMajor.HOVERING
                            and minor(n) == 8, 1.0, keepalive=False, what="LOST_COM hover")
        assert lost.state & S.COM_WATCHDOG and lost.state & S.FLY
        assert not lost.state & S.COM_LOST
        cli.pcmd = Pcmd.hover()
        cli.wait_for(lambda n: not n.state & S.COM_WATCHDOG and minor(n) == 0, 1.0)

        cli.ref = Ref.landing()
        landing = cli.wait_for(lambda n: major(n) in (8, 9), 1.0, what="landing state")
        assert landing.state & S.FLY
        landed = cli.wait_for(lambda n: not n.state & S.FLY, 5.0, what="landed")
        assert major(landed) == CtrlMajor.LANDED and landed.demo.altitude_mm == 0
        assert srv.plant.mode is FlightMode.LANDED
        assert latest_mocap(mocap_rx).position_m[2] < 0.01
    c = srv.counters
    assert c.at_commands_stale == 0 and c.malformed_commands == 0
    assert c.physics_steps > 0 and c.navdata_packets_out > 50


@pytest.mark.timeout(20)
def test_emergency_on_rising_edge_cuts_motors_and_resets_on_the_ground(make_server,
                                                                         make_client):
    srv = make_server(initial_position_m=(0.0, 0.0, 1.0))   # starts hovering at 1 m
    cli = make_client(srv)
    cli.ref = Ref.takeoff()                  # stay airborne (a landing REF would land it)
    nav = cli.start_demo()
    assert nav.state & S.FLY and major(nav) == CtrlMajor.HOVERING

    cli.ref = Ref.emergency()                # held, as node-ar-drone does while bit 31 is 1
    em = cli.wait_for(lambda n: n.state & S.EMERGENCY, 1.0, what="emergency bit")
    assert em.state & S.USER_EL and not em.state & S.FLY
    assert major(em) == CtrlMajor.DEFAULT
    cli.collect(0.8)                         # falls 1 m in ≈ 0.45 s; held bit 8 is no edge
    assert srv.plant.mode is FlightMode.EMERGENCY
    assert srv.plant.truth.position_m[2] == 0.0

    cli.ref = Ref.takeoff()                  # refused while in emergency
    n = cli.collect(0.3)[-1][1]
    assert n.state & S.EMERGENCY and not n.state & S.FLY

    cli.ref = Ref.landing()
    cli.collect(0.1)
    cli.ref = Ref.emergency()                # new 0→1 edge: clears the emergency
    ok = cli.wait_for(lambda n: not n.state & S.EMERGENCY, 1.0, what="emergency cleared")
    assert not ok.state & S.USER_EL and major(ok) == CtrlMajor.LANDED
    assert srv.plant.mode is FlightMode.LANDED


@pytest.mark.timeout(20)
def test_altitude_max_caps_the_climb(make_server, make_client):
    srv = make_server(initial_position_m=(0.0, 0.0, 1.0))
    cli = make_client(srv)
    cli.ref = Ref.takeoff()
    cli.start_demo()
    cli.send(Config.of("control:altitude_max", 1300))
    cli.wait_for(lambda n: n.state & S.COMMAND, 1.0)
    cli.send(Ctrl(CTRL_MODE_ACK))
    assert srv.altitude_max_m == pytest.approx(1.3)
    cli.pcmd = Pcmd.move(0.0, 0.0, 1.0, 0.0)       # full climb
    packets = cli.collect(3.0)
    top = max(n.demo.altitude_mm for _, n in packets)
    assert 1200 <= top <= 1400, top
    assert any(major(n) == CtrlMajor.FLYING and minor(n) == 3 for _, n in packets)


@pytest.mark.timeout(30)
def test_landing_by_itself_then_a_held_takeoff_ref_relaunches_it(make_server, make_client):
    """The firmware hazard a client must avoid: the drone lands on its own decision (state bit
    0 clears, ctrl_state LANDED), and a REF still carrying the take-off bit starts it again."""
    srv = make_server(**FAST)
    cli = make_client(srv)
    cli.start_demo()
    cli.ref = Ref.takeoff()
    cli.wait_for(lambda n: major(n) == CtrlMajor.HOVERING, 6.0, what="hovering")
    assert srv.land_by_itself()
    landing = cli.wait_for(lambda n: major(n) == 8, 1.0, what="landing (SDK code 8)")
    assert landing.state & S.FLY and landing.state & S.USER_FEEDBACK_START
    cli.ref = Ref.landing()          # this client drops the take-off bit: it stays down
    down = cli.wait_for(lambda n: not n.state & S.FLY, 5.0, what="landed")
    assert major(down) == CtrlMajor.LANDED and down.demo.altitude_mm == 0
    cli.collect(0.3)
    assert not cli.last.state & S.FLY and srv.plant.mode is FlightMode.LANDED
    assert not srv.land_by_itself()  # on the ground: nothing to land

    cli.ref = Ref.takeoff()          # airborne again, then landed by the drone once more …
    cli.wait_for(lambda n: major(n) == CtrlMajor.HOVERING, 6.0, what="hovering again")
    srv.land_by_itself()
    cli.wait_for(lambda n: major(n) == 8, 1.0, what="landing by itself")
    # … while this client keeps sending the take-off bit: the drone touches down and takes
    # off again within a keepalive period, so navdata (15 Hz) may never even show it landed
    relaunch = cli.wait_for(lambda n: major(n) == 6, 5.0, what="take-off again")
    assert relaunch.state & S.FLY and srv.plant.mode is not FlightMode.LANDED


@pytest.mark.timeout(30)
def test_firmware_2_4_codes_for_take_off_and_landing(make_server, make_client):
    srv = make_server(server=dict(ctrl_codes="fw2.4"), **FAST)
    cli = make_client(srv)
    cli.start_demo()
    cli.ref = Ref.takeoff()
    up = cli.wait_for(lambda n: n.state & S.FLY, 1.0, what="FLY bit")
    assert major(up) == 7                      # the SDK header's GOTOFIX
    cli.wait_for(lambda n: major(n) == CtrlMajor.HOVERING, 6.0, what="hovering")
    cli.ref = Ref.landing()
    down = cli.wait_for(lambda n: major(n) != CtrlMajor.HOVERING, 1.0, what="landing")
    assert major(down) == 9 and down.state & S.FLY   # the header's LOOPING
    cli.wait_for(lambda n: major(n) == CtrlMajor.LANDED, 5.0, what="landed")
    with pytest.raises(ValueError):
        DroneServer(srv.plant, ctrl_codes="observed")


# ----------------------------------------------------------------------------- AT parsing


@pytest.mark.timeout(20)
def test_malformed_datagrams_are_counted_and_ignored(make_server, make_client):
    srv = make_server()
    cli = make_client(srv)
    cli.start_demo()
    before = srv.counters
    bad = [b"garbage", b"AT*REF=abc\r", b"AT*REF=5,290718208",            # unterminated
           b"AT*PCMD=6,1,2,3\r", b"\xff\xfe\r", b"AT*REF=7,290718208\r" * 60,   # > 1024 bytes
           b"AT*CONFIG=8,general:x,1\r"]
    for dg in bad:
        cli.send_raw(dg)
    # one good command after a bad one in the same datagram is still applied
    cli.send_raw(b"AT*REF=abc\r" + AtCommand(1000, Config("custom:probe", "1")).encode())
    cli.seq.reset(1001)
    cli.wait_for(lambda n: n.state & S.COMMAND, 2.0, what="ACK of the good command")
    after = srv.counters
    assert after.malformed_datagrams - before.malformed_datagrams == len(bad) + 1
    assert after.malformed_commands - before.malformed_commands >= len(bad) + 1
    assert srv.config["custom:probe"] == "1"
    assert "general:x" not in srv.config
    assert srv.plant.mode is FlightMode.LANDED          # no take-off slipped through
    assert all(t.is_alive() for t in srv._threads)


@pytest.mark.timeout(20)
def test_sequence_numbers_ignore_older_commands_and_reset_on_1(make_server, make_client):
    srv = make_server()
    cli = make_client(srv)

    def send(seq, key):
        cli.send_raw(AtCommand(seq, Config(key, "v")).encode())

    def settle(n_in):
        end = time.monotonic() + 2.0
        while srv.counters.at_commands_in < n_in and time.monotonic() < end:
            time.sleep(0.005)

    send(10, "a:ten")
    send(5, "a:five")          # older: ignored
    send(10, "a:ten_again")    # not greater: ignored
    send(1, "a:one")           # 1 resets the counter
    send(2, "a:two")
    settle(5)
    cfg = srv.config
    assert set(cfg) == {"a:ten", "a:one", "a:two"}
    assert srv.counters.at_commands_stale == 2


@pytest.mark.timeout(20)
def test_node_style_first_command_with_seq_0_is_ignored(make_server, make_client):
    srv = make_server()
    cli = make_client(srv)
    cli.send_raw(b"AT*CONFIG=0,\"a:zero\",\"1\"\rAT*CONFIG=1,\"a:one\",\"1\"\r")
    end = time.monotonic() + 2.0
    while srv.counters.at_commands_in < 2 and time.monotonic() < end:
        time.sleep(0.005)
    assert set(srv.config) == {"a:one"}


# ----------------------------------------------------------------------------- watchdogs


@pytest.mark.timeout(20)
def test_com_watchdog_bit_after_silence_cleared_by_comwdg(make_server, make_client):
    srv = make_server(server=dict(comwdg_clear="comwdg"))
    cli = make_client(srv)
    cli.start_demo()
    # the latch survives ordinary commands: clear it first with COMWDG
    cli.send(Comwdg())
    cli.wait_for(lambda n: not n.state & S.COM_WATCHDOG, 1.0, what="bit 30 clear")
    n = cli.wait_for(lambda n: n.state & S.COM_WATCHDOG, 0.5, keepalive=False,
                     what="bit 30 after > 50 ms of silence")
    assert not n.state & S.COM_LOST
    cli.collect(0.2)                          # REF + PCMD traffic: still latched
    assert cli.last.state & S.COM_WATCHDOG
    cli.send(Comwdg())
    cli.wait_for(lambda n: not n.state & S.COM_WATCHDOG, 1.0, what="bit 30 cleared by COMWDG")


@pytest.mark.timeout(20)
def test_link_loss_after_2_s_sets_com_lost_and_resets_the_sequence(make_server, make_client):
    srv = make_server()
    cli = make_client(srv)
    cli.start_demo()
    cli.collect(0.3)                          # seq is now well above 3
    assert cli.seq.next_seq > 10
    t_end = time.monotonic() + 2.5
    while time.monotonic() < t_end:           # navdata traffic only (wake-ups) keeps it streaming
        cli.wake()
        cli.collect(0.4, keepalive=False)
    n = cli.last
    assert n.state & S.COM_LOST and n.state & S.COM_WATCHDOG
    assert srv.counters.link_losses == 1
    cli.seq.reset(3)                          # neither 1 nor above the old counter
    cli.send(Config.of("a:after_loss", 1))
    cli.wait_for(lambda n: n.state & S.COMMAND and not n.state & S.COM_LOST, 1.0,
                 what="command accepted after the reset")
    assert "a:after_loss" in srv.config


@pytest.mark.timeout(20)
def test_navdata_stops_without_client_traffic_and_restarts_on_wakeup(make_server, make_client):
    srv = make_server(server=dict(navdata_timeout_s=0.4))
    cli = make_client(srv)
    cli.wake()
    first = cli.collect(0.3, keepalive=False)
    assert first
    time.sleep(0.4)
    cli.drain()
    assert cli.collect(0.4, keepalive=False) == []
    assert not srv.streaming and srv.counters.navdata_stream_stops == 1
    cli.wake(b"\x01")                          # node-ar-drone's one-byte wake-up
    again = cli.collect(0.3, keepalive=False)
    assert again and again[0][1].sequence > first[-1][1].sequence


# ----------------------------------------------------------------------------- configuration


@pytest.mark.timeout(20)
def test_config_keys_set_the_plant_limits_with_one_ack_each(make_server, make_client):
    srv = make_server()
    cli = make_client(srv)
    cli.start_demo()
    for key, value in [("control:euler_angle_max", 0.35), ("control:control_vz_max", 1000),
                       ("control:control_yaw", 3.0), ("control:altitude_max", 2000),
                       ("control:outdoor", False)]:
        cli.send(Config.of(key, value))
        cli.wait_for(lambda n: n.state & S.COMMAND, 1.0, what=f"ACK of {key}")
        cli.send(Ctrl(CTRL_MODE_ACK))
        cli.wait_for(lambda n: not n.state & S.COMMAND, 1.0, what=f"ACK of {key} cleared")
    p = srv.plant.params
    assert p.euler_angle_max_rad == pytest.approx(0.35)
    assert p.control_vz_max_mps == pytest.approx(1.0)
    assert p.control_yaw_radps == pytest.approx(3.0)
    assert srv.altitude_max_m == pytest.approx(2.0)
    assert srv.config["control:outdoor"] == "FALSE"
    cli.send(Config.of("control:euler_angle_max", 0.9))     # beyond the 0.52 rad range
    cli.send(Config.of("control:control_vz_max", "fast"))   # not a number: stored only
    cli.wait_for(lambda n: n.state & S.COMMAND
                 and srv.config.get("control:control_vz_max") == "fast", 1.0)
    assert srv.plant.params.euler_angle_max_rad == pytest.approx(0.52)
    assert srv.plant.params.control_vz_max_mps == pytest.approx(1.0)
    assert srv.config["control:control_vz_max"] == "fast"


@pytest.mark.timeout(20)
def test_control_port_dumps_the_configuration_after_ctrl_4(make_server, make_client):
    srv = make_server(server=dict(control_port=0))
    cli = make_client(srv)
    cli.start_demo()
    cli.send(Config.of("control:altitude_max", 2500))
    cli.wait_for(lambda n: n.state & S.COMMAND, 1.0)
    cli.send(Ctrl(CTRL_MODE_ACK))
    cli.wait_for(lambda n: not n.state & S.COMMAND, 1.0)
    with socket.create_connection((LOCALHOST, srv.control_port), timeout=2.0) as tcp:
        end = time.monotonic() + 2.0
        while srv.counters.control_connections < 1 and time.monotonic() < end:
            time.sleep(0.01)
        cli.send(Ctrl(CTRL_MODE_CFG_GET))
        buf = b""
        while not buf.endswith(b"\0"):
            chunk = tcp.recv(8192)
            assert chunk, "control connection closed before the NUL"
            buf += chunk
    text = buf[:-1].decode("ascii")
    lines = dict(line.split(" = ", 1) for line in text.splitlines())
    assert lines["control:altitude_max"] == "2500"
    assert lines["general:navdata_demo"] == "TRUE"
    assert "control:euler_angle_max" in lines
    cli.wait_for(lambda n: n.state & S.COMMAND, 1.0, what="ACK after the dump")


# ----------------------------------------------------------------------------- third-party clients


@pytest.mark.timeout(20)
def test_node_ar_drone_style_client_takes_off_moves_and_lands(make_server, make_client):
    """node-ar-drone: one-byte wake-up, seq from 0, REF 512/0 without the base bits, REF +
    PCMD every 30 ms, navdata_demo + CTRL 5, waits for ctrl_state HOVERING / LANDED."""
    srv = make_server(**FAST)
    cli = make_client(srv)
    seq = [0]
    level = {"ref": 0, "pcmd": "0,0,0,0,0"}

    def tick():
        a = f"AT*REF={seq[0]},{level['ref']}\r"
        b = f"AT*PCMD={seq[0] + 1},{level['pcmd']}\r"
        seq[0] += 2
        cli.send_raw((a + b).encode())

    cli.keepalive = tick
    cli.wake(b"\x01")
    cli.wait_for(lambda n: True, 2.0)          # sends REF seq 0 (ignored) + PCMD seq 1
    cli.send_raw(f'AT*CONFIG={seq[0]},"general:navdata_demo","TRUE"\r'.encode())
    seq[0] += 1
    cli.wait_for(lambda n: n.state & S.COMMAND, 2.0)
    cli.send_raw(f"AT*CTRL={seq[0]},5,0\r".encode())
    seq[0] += 1
    level["ref"] = 512
    cli.wait_for(lambda n: n.demo is not None and major(n) == CtrlMajor.HOVERING, 6.0,
                 what="hovering")
    y0 = float(srv.plant.truth.position_m[1])
    # client.right(0.5): roll = +0.5 → flies to the right = world −y
    level["pcmd"] = f"1,{1056964608},0,0,0"
    cli.collect(1.2)
    assert float(srv.plant.truth.position_m[1]) < y0 - 0.1
    level["pcmd"] = "0,0,0,0,0"
    level["ref"] = 0
    cli.wait_for(lambda n: major(n) == CtrlMajor.LANDED, 6.0, what="landed")
    assert srv.plant.mode is FlightMode.LANDED
    assert srv.counters.at_commands_stale == 1        # the seq-0 REF


@pytest.mark.timeout(20)
def test_python_ardrone_style_client_single_takeoff_ref_then_only_comwdg(make_server,
                                                                            make_client):
    """cvdrone / python-ardrone shapes: FTRIM with a trailing comma, a socket per command, one
    take-off REF then only COMWDG every 100 ms (absence of REF does not land it), then land."""
    srv = make_server(**FAST)
    cli = make_client(srv)
    counter = [1]

    def send(cmd: str) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(f"AT*{cmd.replace('#', str(counter[0]))}\r".encode(), cli.at_addr)
        counter[0] += 1

    cli.keepalive = lambda: send("COMWDG=#")
    cli.wake()
    send('CONFIG=#,"general:navdata_demo","TRUE"')
    cli.wait_for(lambda n: n.state & S.COMMAND, 2.0, interval_s=0.1)
    send("CTRL=#,5,0")
    send("FTRIM=#,")
    cli.wait_for(lambda n: not n.state & S.COMMAND, 2.0, interval_s=0.1)
    assert srv.counters.ftrim_accepted == 1
    send("REF=#,290718208")
    cli.wait_for(lambda n: n.demo is not None and n.demo.altitude_mm > 700, 5.0, interval_s=0.1, what="airborne")
    cli.collect(0.5, interval_s=0.1)
    assert cli.last.state & S.FLY and not cli.last.state & S.COM_LOST
    send("FTRIM=#,")                                  # ignored in flight
    send("PCMD=#,1,0,-1085485875,0,0")                # forward at 0.8 · euler_angle_max
    cli.collect(0.8, interval_s=0.1)
    assert srv.plant.truth.velocity_mps[0] > 0.3
    for _ in range(3):
        send("REF=#,290717696")
    cli.wait_for(lambda n: not n.state & S.FLY, 5.0, interval_s=0.1, what="landed")
    assert srv.counters.ftrim_accepted == 1 and srv.counters.malformed_commands == 0


# ----------------------------------------------------------------------------- loopback + serve


@pytest.mark.timeout(20)
def test_start_loopback_serves_drone_and_mocap_on_free_ports(mocap_rx):
    from ardrone_nmpc.sim.loopback import start_loopback

    cfg = ExperimentConfig()
    with start_loopback(cfg, seed=5, mocap_port=mocap_rx.getsockname()[1]) as loop:
        assert loop.drone_host == LOCALHOST and loop.mocap_port == mocap_rx.getsockname()[1]
        assert loop.at_port != loop.navdata_port
        cli = RawClient(loop.at_port, loop.navdata_port)
        try:
            nav = cli.start_demo()
            assert major(nav) == CtrlMajor.LANDED
        finally:
            cli.close()
        pose = latest_mocap(mocap_rx, cfg.mocap.object_name)
        truth = loop.truth()
        assert pose.position_m == pytest.approx(tuple(truth.position_m), abs=0.005)
        ports = (loop.at_port, loop.navdata_port)
    for port in ports:          # released
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind((LOCALHOST, port))
    assert not any(t.name.startswith(("drone-server", "mocap-server")) and t.is_alive()
                   for t in threading.enumerate())


@pytest.mark.timeout(20)
def test_start_loopback_picks_a_free_mocap_port_when_none_is_given():
    from ardrone_nmpc.sim.loopback import start_loopback

    with start_loopback(ExperimentConfig()) as loop:
        assert 0 < loop.mocap_port < 65536 and loop.mocap_host == LOCALHOST


@pytest.mark.timeout(20)
def test_serve_prints_what_it_serves_and_stops_cleanly(mocap_rx):
    from ardrone_nmpc.sim.serve import serve

    lines: list[str] = []
    stop = threading.Event()
    port = mocap_rx.getsockname()[1]
    errors: list[BaseException] = []

    def run():
        try:
            serve(cfg=ExperimentConfig(), bind=LOCALHOST, at_port=0, navdata_port=0,
                  control_port=0, mocap_to=f"{LOCALHOST}:{port}", seed=1, echo=lines.append,
                  stop_event=stop)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    t = threading.Thread(target=run)
    t.start()
    try:
        mocap_rx.settimeout(3.0)
        assert "ardrone" in decode_mocap(mocap_rx.recv(2048)).poses
    finally:
        stop.set()
        t.join(5.0)
    assert not t.is_alive() and not errors
    text = "\n".join(lines)
    assert "AT commands udp/" in text and "navdata udp/" in text
    assert "config tcp/" in text          # the control port is served by default
    assert f"{LOCALHOST}:{port}" in text and "'ardrone'" in text
    assert lines[-1].startswith("stopped:")


@pytest.mark.timeout(20)
def test_serve_starts_the_fault_clock(mocap_rx):
    """sim-drone has no experiment: its injected faults count from when it starts serving —
    an occlusion from 0 s on leaves the object out of the streamed frames."""
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.sim.serve import serve

    cfg = load_config(None, ["faults.mocap_occlusion.start_s=0",
                             "faults.mocap_occlusion.duration_s=100"])
    lines: list[str] = []
    stop = threading.Event()
    port = mocap_rx.getsockname()[1]
    t = threading.Thread(target=serve, kwargs=dict(
        cfg=cfg, bind=LOCALHOST, at_port=0, navdata_port=0, control_port=0,
        mocap_to=f"{LOCALHOST}:{port}", seed=1, echo=lines.append, stop_event=stop))
    t.start()
    try:
        mocap_rx.settimeout(3.0)
        frames = [decode_mocap(mocap_rx.recv(2048)) for _ in range(30)]
    finally:
        stop.set()
        t.join(5.0)
    assert not t.is_alive()
    assert any("faults mocap_occlusion" in line for line in lines)
    assert "ardrone" not in frames[-1].poses  # occluded once the clock runs


@pytest.mark.timeout(20)
@pytest.mark.parametrize("kwargs, message", [
    (dict(bind="0.0.0.0"), "--bind"),
    (dict(bind="192.0.2.1"), "--bind"),
    (dict(mocap_to="198.51.100.2:51001"), "--mocap-to"),
    (dict(mocap_to="10.1.2.3:51001"), "--mocap-to"),
    (dict(mocap_to="127.0.0.1"), "--mocap-to"),
    (dict(mocap_to="127.0.0.1:99999"), "--mocap-to"),
])
def test_serve_refuses_non_loopback_addresses(kwargs, message):
    from ardrone_nmpc.sim.serve import serve

    args = dict(cfg=ExperimentConfig(), bind=LOCALHOST, at_port=0, navdata_port=0,
                control_port=0, mocap_to="127.0.0.1:51001", seed=None, echo=lambda s: None,
                stop_event=threading.Event())
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        serve(**args)


def test_servers_refuse_non_loopback_binds():
    plant = AirframePlant(PlantParams(), QUIET)
    for host in ("0.0.0.0", "192.0.2.1", "::1", "example.com"):  # RFC 5737 test address
        with pytest.raises(ValueError, match="loopback"):
            DroneServer(plant, bind_host=host)
    assert require_loopback_host("localhost") == LOCALHOST
    assert require_loopback_host("127.1.2.3") == "127.1.2.3"


@pytest.mark.timeout(20)
@pytest.mark.parametrize("args, message", [
    (["--bind", "0.0.0.0"], "--bind '0.0.0.0' is not a loopback address"),
    (["--mocap-to", "198.51.100.2:51001"], "--mocap-to '198.51.100.2' is not a loopback address"),
])
def test_sim_drone_command_refuses_non_loopback_addresses(args, message):
    from typer.testing import CliRunner

    from ardrone_nmpc.cli.app import app

    result = CliRunner().invoke(app, ["sim-drone", "--at-port", "0", "--navdata-port", "0",
                                      "--control-port", "0", *args])
    assert result.exit_code == 1
    assert message in result.output
    assert "Traceback" not in result.output
