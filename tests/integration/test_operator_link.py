"""The operator's link (ardrone_nmpc/links/operator_link.py) byte by byte against two bare UDP
sockets on 127.0.0.1 playing the drone: the command in the first datagram, every datagram
numbered from 1 (docs/protocol.md §2.2), the REF values of §2.4 (land 290717696, emergency
290717952), navdata only once asked, bootstrap packets answered as ARDroneLib does. Expected
bytes are typed by hand; navdata packets are packed here from the documented layout (§4.1).
"""

from __future__ import annotations

import socket
import struct
import time

import pytest

from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.links.operator_link import OperatorLink

pytestmark = pytest.mark.timeout(30)
IDS = ("d2e081a3", "be27e2e4", "d87f7e0c")
FLY, ACK, DEMO, BOOTSTRAP, EMERGENCY = 1 << 0, 1 << 6, 1 << 10, 1 << 11, 1 << 31


def packet(state: int, seq: int = 1, major: int | None = None) -> bytes:
    """A bootstrap-style packet — the header, then only the checksum option — or, with a
    ctrl_state ``major``, a demo packet (the 148-byte demo option, §4.4)."""
    body = struct.pack("<IIIi", 0x55667788, state, seq, 0)
    if major is not None:
        demo = struct.pack("<HHIIfffifffI", 0, 148, major << 16, 60, 0.0, 0.0, 0.0, 300, 0.0,
                           0.0, 0.0, 0)
        body += demo + bytes(148 - len(demo))
    return body + struct.pack("<HHI", 0xFFFF, 8, sum(body) & 0xFFFFFFFF)


class Drone:
    """The drone's two UDP ports; it records what arrives and answers wake-ups on demand."""

    def __init__(self):
        self.at = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.nav = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for s in (self.at, self.nav):
            s.bind(("127.0.0.1", 0))
            s.settimeout(2.0)

    def link(self, **kw) -> OperatorLink:
        return OperatorLink("127.0.0.1", at_port=self.at.getsockname()[1],
                            navdata_port=self.nav.getsockname()[1], bind_host="127.0.0.1",
                            at_local_port=0, **kw)

    def datagrams(self, n: int) -> list[bytes]:
        return [self.at.recvfrom(4096)[0] for _ in range(n)]

    def close(self):
        self.at.close()
        self.nav.close()


@pytest.fixture
def drone():
    d = Drone()
    yield d
    d.close()


def test_land_goes_out_in_the_first_datagram_and_every_one_is_whole(drone):
    with drone.link() as link:
        t0 = time.monotonic()
        link.start("land")
        first = drone.at.recvfrom(4096)[0]
        assert first == b"AT*REF=1,290717696\rAT*PCMD=2,0,0,0,0,0\r"
        assert drone.datagrams(5) == [first] * 5            # repeated, numbered from 1 again
        drone.nav.settimeout(0.2)
        with pytest.raises(socket.timeout):                  # navdata: not asked yet
            drone.nav.recvfrom(64)
        assert time.monotonic() - t0 < 1.0 and link.packets == 0


def test_emergency_makes_its_edge_once_then_holds_bit_8_low(drone):
    """One edge: a second one, from any client's REFs interleaved, would undo the cut."""
    with drone.link() as link:
        link.start("emergency")
        first, *repeats = drone.datagrams(4)
        assert first == (b"AT*REF=1,290717696\rAT*REF=2,290717952\r"
                         b"AT*PCMD=3,0,0,0,0,0\r")
        assert repeats == [b"AT*REF=1,290717696\rAT*PCMD=2,0,0,0,0,0\r"] * 3
        assert link.edges == 1
        link.emergency()                                     # asked again: a new edge
        assert drone.datagrams(1)[0] == (b"AT*REF=1,290717696\rAT*REF=2,290717952\r"
                                         b"AT*PCMD=3,0,0,0,0,0\r")
        assert link.edges == 2 and drone.datagrams(1)[0].count(b"AT*REF") == 1


def test_navdata_is_woken_once_asked_and_any_packet_confirms(drone):
    with drone.link() as link:
        link.start("land")
        link.wake_navdata()
        wake, client = drone.nav.recvfrom(64)
        assert wake == b"\x01\x00\x00\x00"
        assert link.packet_mode is None and link.state is None
        drone.nav.sendto(packet(FLY | BOOTSTRAP), client)
        assert link.wait_for(lambda lk: lk.packets == 1, 2.0)
        assert link.packet_mode is FlightMode.FLYING and link.navdata is None
        drone.nav.sendto(packet(BOOTSTRAP, seq=2), client)   # touched down: bit 0 clear
        assert link.wait_for(lambda lk: lk.packet_mode is FlightMode.LANDED, 2.0)
        assert time.monotonic() - link.state_rx_t_s < 1.0
        drone.nav.sendto(b"\x88\x77\x66\x55garbage", client)
        drone.nav.sendto(b"\x00", client)
        assert link.wait_for(lambda lk: lk.malformed == 2, 2.0)
        # a demo packet: its ctrl_state decides (bit 0 clear but major 8 is still landing)
        drone.nav.sendto(packet(DEMO, seq=3, major=8), client)
        assert link.wait_for(lambda lk: lk.packet_mode is FlightMode.LANDING, 2.0)
        assert link.navdata is not None and link.navdata.battery_pct == 60.0
        assert link.navdata.t_s == link.navdata_rx_t_s == link.state_rx_t_s
        assert link.navdata.altitude_m == pytest.approx(0.3)
        drone.nav.sendto(packet(DEMO, seq=4, major=2), client)
        assert link.wait_for(lambda lk: lk.packet_mode is FlightMode.LANDED, 2.0)
        assert link.packets == 4


def test_bootstrap_is_answered_with_the_session_ids_and_an_ack_cleared(drone):
    with drone.link(config_ids=IDS) as link:
        link.start("land")
        link.wake_navdata()
        _, client = drone.nav.recvfrom(64)
        drone.nav.sendto(packet(BOOTSTRAP | FLY), client)
        assert link.wait_for(lambda lk: lk.packets == 1, 2.0)
        answer = next(d for d in drone.datagrams(10) if b"CONFIG" in d)
        assert answer == (b'AT*REF=1,290717696\rAT*PCMD=2,0,0,0,0,0\r'
                          b'AT*CONFIG_IDS=3,"d2e081a3","be27e2e4","d87f7e0c"\r'
                          b'AT*CONFIG=4,"general:navdata_demo","TRUE"\r')
        drone.nav.sendto(packet(FLY | ACK, seq=2), client)    # demo now, ACK raised
        assert link.wait_for(lambda lk: lk.packets == 2, 2.0)
        assert any(d.endswith(b"AT*CTRL=3,5,0\r") for d in drone.datagrams(5))
        assert link.bootstrap_answers == 1


def test_no_edge_is_sent_to_a_drone_already_in_emergency(drone):
    with drone.link() as link:
        link.start("land")
        link.wake_navdata()
        _, client = drone.nav.recvfrom(64)
        drone.nav.sendto(packet(EMERGENCY), client)
        assert link.wait_for(lambda lk: lk.packet_mode is FlightMode.EMERGENCY, 2.0)
        link.emergency()                        # on the ground an edge would clear it
        assert all(b"290717952" not in d for d in drone.datagrams(5))


def test_arguments_are_checked_before_anything_is_sent(drone):
    with pytest.raises(ValueError, match="config ids must be 8 hex digits"):
        drone.link(config_ids=("xyz", "0", "0"))
    with pytest.raises(ValueError, match="interval_s"):
        drone.link(interval_s=0.5)
    link = drone.link()
    with pytest.raises(ValueError, match="command must be one of"):
        link.start("takeoff")
    link.close()
    with pytest.raises(Exception, match="started already|closed"):
        link.start("land")


# ----------------------------------------------------------------------------- the entry point
@pytest.mark.parametrize("args, where", [
    ([], ("192.168.1.1", 5556)),
    (["--drone", "10.0.0.7", "--at-port", "7000"], ("10.0.0.7", 7000)),
    (["--navdata-port", "5554", "--drone=h.local", "--at-port=6000"], ("h.local", 6000)),
    (["--config-ids", "a,b,c", "--drone", "127.0.0.1"], ("127.0.0.1", 5556)),
    (["--help"], None), (["-h"], None), (["--drone"], None), (["--drone", " "], None),
    (["--at-port", "1"], ("192.168.1.1", 1)), (["--at-port", "65535"], ("192.168.1.1", 65535)),
    (["--at-port", "0"], None), (["--at-port", "65536"], None), (["--at-port", "-1"], None),
    (["--at-port", "x"], None), (["--at-port", "²"], None), (["--at-port"], None),
    (["--at-port=2", "-x"], ("192.168.1.1", 2)),
])
def test_the_entry_point_reads_only_what_it_is_sure_of(args, where):
    from ardrone_nmpc.cli.first_datagram import target

    assert target(args) == where


@pytest.mark.parametrize("command, expected", [
    ("emergency", b"AT*REF=1,290717696\rAT*REF=2,290717952\rAT*PCMD=3,0,0,0,0,0\r"),
    ("land", b"AT*REF=1,290717696\rAT*PCMD=2,0,0,0,0,0\r")])
def test_the_entry_point_sends_the_first_datagram_before_typer_loads(drone, monkeypatch,
                                                                      command, expected):
    from ardrone_nmpc.cli import first_datagram as launch

    monkeypatch.setattr(launch, "SENT", None)
    source = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    source.bind(("127.0.0.1", 0))                 # a free port stands for the guide's 5556
    monkeypatch.setattr(launch, "_LOCAL_AT_PORT", source.getsockname()[1])
    source.close()
    port = drone.at.getsockname()[1]
    launch.send_first([command, "--drone", "127.0.0.1", "--at-port", str(port)])
    data, sender = drone.at.recvfrom(4096)
    assert data == expected and sender[1] == launch._LOCAL_AT_PORT
    assert launch.SENT == (command, "127.0.0.1", port)
    with drone.link() as link:                     # the command's own link: no second edge
        link.start(command, edge_sent=launch.SENT[0] == "emergency")
        assert drone.datagrams(1)[0] == b"AT*REF=1,290717696\rAT*PCMD=2,0,0,0,0,0\r"
        assert link.edges == 0


def test_the_entry_point_leaves_other_commands_and_doubtful_lines_alone(drone, monkeypatch):
    from ardrone_nmpc.cli import first_datagram as launch

    monkeypatch.setattr(launch, "SENT", None)
    port = str(drone.at.getsockname()[1])
    for argv in (["status", "--drone", "127.0.0.1", "--at-port", port], [],
                 ["emergency", "--drone", "127.0.0.1", "--at-port", port, "--help"],
                 ["emergency", "--drone", "no.such.host.invalid", "--at-port", port]):
        launch.send_first(argv)
    drone.at.settimeout(0.3)
    with pytest.raises(socket.timeout):
        drone.at.recvfrom(4096)
    assert launch.SENT is None


def test_ardrone_nmpc_emergency_cuts_from_its_first_datagram(drone, tmp_path):
    """The installed command as an operator types it: its first datagram (the edge) arrives
    before typer has loaded, then the command's own link holds REF land."""
    import os
    import subprocess
    import sys

    port = drone.at.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "ardrone_nmpc.cli.launch", "emergency",
                             "--drone", "127.0.0.1", "--at-port", str(port), "--navdata-port",
                             str(drone.nav.getsockname()[1])],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, XDG_RUNTIME_DIR=str(tmp_path)))
    try:
        drone.at.settimeout(20)
        datagrams = drone.datagrams(3)
    finally:
        proc.kill()
        proc.communicate()
    assert datagrams[0] == b"AT*REF=1,290717696\rAT*REF=2,290717952\rAT*PCMD=3,0,0,0,0,0\r"
    assert datagrams[1:] == [b"AT*REF=1,290717696\rAT*PCMD=2,0,0,0,0,0\r"] * 2


def test_wait_for_waits_its_whole_timeout_for_a_late_packet(drone):
    import threading

    with drone.link() as link:
        link.start("land")
        link.wake_navdata()
        _, client = drone.nav.recvfrom(64)
        threading.Timer(0.8, lambda: drone.nav.sendto(packet(0), client)).start()
        t0 = time.monotonic()
        assert link.wait_for(lambda lk: lk.packets == 1, 1.5)          # arrives at 0.8 s
        assert 0.7 < time.monotonic() - t0 < 1.5
        assert not link.wait_for(lambda lk: lk.packets == 2, 0.2)     # and a timeout is one


def test_a_link_not_started_or_closed_sends_nothing_and_says_so(drone):
    from ardrone_nmpc.links.drone_config import LinkError

    never = drone.link()
    with pytest.raises(LinkError, match=r"^the operator link is closed$"):
        never.land()
    with drone.link() as link:
        link.start("land")
        drone.datagrams(1)
    with pytest.raises(LinkError, match=r"^the operator link is closed$"):
        link.emergency()
    assert link.edges == 0


class _BrokenSocket:
    """An AT socket whose every send fails (the Wi-Fi interface gone)."""

    def sendto(self, data, address):
        raise OSError("network is unreachable")

    def close(self):
        pass


def test_a_command_whose_datagram_cannot_be_sent_raises(drone):
    from ardrone_nmpc.links.drone_config import LinkError

    with drone.link() as link:
        link.start("land")
        real, link._at = link._at, _BrokenSocket()
        try:
            with pytest.raises(LinkError, match=r"^AT send to 127\.0\.0\.1:\d+: network is "
                                                r"unreachable$"):
                link.emergency()
        finally:
            link._at = real


def test_a_busy_local_at_port_falls_back_to_any_port(drone):
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    try:
        port = busy.getsockname()[1]
        with OperatorLink("127.0.0.1", at_port=drone.at.getsockname()[1],
                          navdata_port=drone.nav.getsockname()[1], bind_host="127.0.0.1",
                          at_local_port=port) as link:
            link.start("land")
            data, source = drone.at.recvfrom(4096)
            assert data.startswith(b"AT*REF=1,290717696\r") and source[1] != port
    finally:
        busy.close()


def drain(sock) -> list[bytes]:
    """Every datagram waiting on ``sock`` (after the sender closed)."""
    sock.settimeout(0.2)
    out = []
    try:
        while True:
            out.append(sock.recvfrom(4096)[0])
    except socket.timeout:
        return out


def test_every_datagram_sent_is_counted(drone):
    with drone.link() as link:
        link.start("emergency")
        drone.datagrams(4)
    assert link.sent_datagrams == 4 + len(drain(drone.at)) and link.sent_datagrams >= 4


def test_the_keepalive_outlives_a_failed_send_and_says_why(drone):
    with drone.link() as link:
        link.start("land")
        drone.datagrams(1)
        with link._lock:
            real, link._at = link._at, _BrokenSocket()
        time.sleep(0.1)                                       # sends fail for a while …
        with link._lock:
            link._at = real
            sent = link.sent_datagrams
        assert link.last_error.endswith(": network is unreachable")
        assert link.last_error.startswith("AT send to 127.0.0.1:")
        assert link.wait_for(lambda lk: lk.sent_datagrams >= sent + 3, 5.0)  # … then on


class _MuteSocket:
    """The navdata socket, whose sends (the wake-ups) fail."""

    def __init__(self, real):
        self.real = real

    def fileno(self):
        return self.real.fileno()

    def sendto(self, data, address):
        raise OSError("network is unreachable")

    def recvfrom(self, n):
        return self.real.recvfrom(n)

    def close(self):
        self.real.close()


def test_a_wake_up_that_cannot_be_sent_is_said(drone):
    with drone.link() as link:
        link.start("land")
        with link._lock:
            link._nav = _MuteSocket(link._nav)
        link.wake_navdata()
        deadline = time.monotonic() + 2.0
        while link.last_error is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert link.last_error == "navdata wake-up: network is unreachable"


def test_bootstrap_is_answered_again_while_it_lasts(drone):
    """Every BOOTSTRAP_ANSWER_EVERY_S while the newest packet shows bootstrap; each answer
    counted once, as it goes out."""
    with drone.link() as link:
        link.start("land")
        link.wake_navdata()
        _, client = drone.nav.recvfrom(64)
        drone.nav.sendto(packet(BOOTSTRAP | FLY), client)
        deadline = time.monotonic() + 5.0
        while link.bootstrap_answers < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
    sent = drain(drone.at)
    assert link.bootstrap_answers >= 2
    assert sum(b"navdata_demo" in d for d in sent) == link.bootstrap_answers


@pytest.mark.parametrize("host, ports, ids, message", [
    ("", (5556, 5554), None, "drone address must be an address or host name, got ''"),
    ("127.0.0.1", (0, 5554), None, "AT port must be a port number 1–65535, got 0"),
    ("127.0.0.1", (5556, 70000), None, "navdata port must be a port number 1–65535, got 70000"),
    ("127.0.0.1", (5556, 5554), ("d2e081a3", "be27e2e4"),
     "config_ids must be (session, profile, application)"),
])
def test_each_argument_is_named_in_its_refusal(host, ports, ids, message):
    with pytest.raises(ValueError) as err:
        OperatorLink(host, at_port=ports[0], navdata_port=ports[1], config_ids=ids)
    assert str(err.value) == message


def test_a_link_starts_once_on_the_default_interface_in_a_named_daemon_thread(drone):
    from ardrone_nmpc.links.drone_config import LinkError

    with OperatorLink("127.0.0.1", at_port=drone.at.getsockname()[1],
                      navdata_port=drone.nav.getsockname()[1], at_local_port=0) as link:
        link.start("land")                      # bound on every interface, sent to 127.0.0.1
        assert drone.datagrams(1)[0].startswith(b"AT*REF=1,290717696\r")
        assert (link._thread.name, link._thread.daemon) == ("operator-link", True)
        with pytest.raises(LinkError) as err:
            link.start("emergency")
        assert str(err.value) == "this OperatorLink was started already"
