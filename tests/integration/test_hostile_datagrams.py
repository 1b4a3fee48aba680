"""Every UDP receiver survives garbage: it counts each bad datagram and keeps decoding.

Receivers: the drone link's navdata receiver, the mocap link, and the simulated drone's AT
receiver. Each gets a few hundred malformed datagrams of many kinds (random bytes, truncated
and bit-flipped valid packets, bad checksums, zero-size options, lying counts, bad AT numbers
and quotes) plus *well-formed but hostile* ones (non-finite floats, non-ASCII names, absurd
configuration values), all over 127.0.0.1; then a valid datagram must still be decoded. The
garbage is seeded, so a failure reproduces.
"""

from __future__ import annotations

import math
import random
import socket
import struct
import threading
import time

import pytest

from ardrone_nmpc.config.schema import ExperimentConfig
from ardrone_nmpc.links.drone_link import DroneLink
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.protocol.at import parse_datagram_lenient
from ardrone_nmpc.protocol.mocap import (
    MocapError,
    MocapFrame,
    MocapObjectPose,
    decode_mocap,
    encode_mocap,
)
from ardrone_nmpc.protocol.navdata import (
    DEMO_SIZE,
    NAVDATA_MAGIC,
    NAVDATA_WAKEUP,
    DemoOption,
    DroneState,
    Navdata,
    NavdataError,
    decode_navdata,
    encode_navdata,
)
from ardrone_nmpc.sim.drone_server import DroneServer
from ardrone_nmpc.sim.plant import AirframePlant

LOOPBACK = "127.0.0.1"
SEED = 20240501


def wait_until(predicate, timeout_s: float = 5.0, poll_s: float = 0.005) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return bool(predicate())


def thread_alive(name: str) -> bool:
    return any(t.name == name and t.is_alive() for t in threading.enumerate())


def mutations(rng: random.Random, valid: bytes, n: int) -> list[bytes]:
    """``n`` damaged copies of ``valid``: truncations, bit flips, lying u16 fields, random
    bytes, random lengths."""
    out = []
    for i in range(n):
        kind = i % 4
        if kind == 0:
            out.append(valid[:rng.randrange(len(valid))])
        elif kind == 1:
            buf = bytearray(valid)
            for _ in range(rng.randint(1, 4)):
                buf[rng.randrange(len(buf))] ^= 1 << rng.randrange(8)
            out.append(bytes(buf))
        elif kind == 2:
            buf = bytearray(valid)
            at = rng.randrange(len(buf) - 1)
            buf[at:at + 2] = struct.pack("<H", rng.choice((0, 1, 3, 0xFFFF, len(buf))))
            out.append(bytes(buf))
        else:
            out.append(rng.randbytes(rng.randrange(0, 300)))
    return out


def send_paced(sock: socket.socket, addr, datagrams: list[bytes], counted, start: int) -> None:
    """Send in batches of 10 and wait for each batch to be counted, so that a full receive
    buffer never drops garbage (the counts must then match exactly)."""
    for i in range(0, len(datagrams), 10):
        for d in datagrams[i:i + 10]:
            sock.sendto(d, addr)
        expected = start + min(i + 10, len(datagrams))
        assert wait_until(lambda: counted() >= expected), (counted(), expected)


@pytest.fixture
def raw_sock():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((LOOPBACK, 0))
    yield s
    s.close()


@pytest.fixture
def drone_server():
    cfg = ExperimentConfig()
    server = DroneServer(AirframePlant.from_config(cfg.sim, cfg.drone, seed=1),
                         navdata_timeout_s=None)
    server.start()
    yield server
    server.stop()


# ----------------------------------------------------------------------------- navdata


def _demo_packet(seq: int, yaw_mdeg: float) -> bytes:
    """A checksum-valid demo packet with a non-finite yaw and speeds (hostile but decodable)."""
    demo = struct.pack("<HHIIfffifffI9f3fII9f3f", 0, DEMO_SIZE, 4 << 16, 50, 0.0, 0.0,
                       yaw_mdeg, 800, math.nan, math.inf, -math.inf, 0, *([0.0] * 12), 0, 3,
                       *([0.0] * 12))
    body = struct.pack("<IIIi", NAVDATA_MAGIC, int(DroneState.FLY), seq, 0) + demo
    return body + struct.pack("<HHI", 0xFFFF, 8, sum(body) & 0xFFFFFFFF)


def navdata_garbage(rng: random.Random, n: int) -> list[bytes]:
    valid = encode_navdata(Navdata(DroneState.FLY, 5, demo=DemoOption(altitude_mm=900)))
    out = []
    for d in mutations(rng, valid, n):
        try:
            decode_navdata(d)
        except NavdataError:
            out.append(d)                  # keep only the certainly malformed ones
    return out


@pytest.mark.timeout(60)
def test_drone_link_counts_garbage_navdata_and_keeps_decoding(drone_server, raw_sock):
    rng = random.Random(SEED)
    garbage = navdata_garbage(rng, 400)
    assert len(garbage) > 250
    link = DroneLink(LOOPBACK, at_port=drone_server.at_port,
                     navdata_port=drone_server.navdata_port, bind_host=LOOPBACK)
    with link:
        link.connect(timeout_s=20.0)               # the plant's first steps compile kernels
        link_addr = (LOOPBACK, drone_server.navdata_client[1])
        malformed0 = link.stats.malformed
        send_paced(raw_sock, link_addr, garbage, lambda: link.stats.malformed, malformed0)
        # well-formed but hostile: ±inf/NaN floats (seq 1 = "the drone re-initialised")
        for yaw in (math.inf, -math.inf, math.nan):
            raw_sock.sendto(_demo_packet(1, yaw), link_addr)
        time.sleep(0.2)
        assert thread_alive("drone-navdata-rx")
        assert link.stats.malformed == malformed0 + len(garbage)
        assert link.last_error is not None and link.last_error.startswith("navdata: ")
        # the simulated drone's next packets are still decoded and used
        t0 = link.navdata_rx_t_s
        assert wait_until(lambda: link.navdata_rx_t_s > t0 and link.navdata is not None
                          and math.isfinite(link.navdata.yaw_deg))
        assert link.navdata.altitude_m >= 0.0


# ----------------------------------------------------------------------------- mocap


def pose_frame(number: int, name: str = "ardrone", t_mm=(1000.0, -500.0, 1200.0),
               r_rad=(0.01, -0.02, 0.5)) -> bytes:
    return encode_mocap(MocapFrame.of(number, [MocapObjectPose(name, t_mm, r_rad)]))


def mocap_garbage(rng: random.Random, n: int) -> list[bytes]:
    two = encode_mocap(MocapFrame.of(9, [MocapObjectPose("ardrone", (1.0, 2.0, 3.0), (0, 0, 0)),
                                         MocapObjectPose("wand", (4.0, 5.0, 6.0), (0, 0, 0))]),
                       pad=False)
    out = []
    for d in mutations(rng, two, n):
        try:
            decode_mocap(d)
        except MocapError:
            out.append(d)
    return out


@pytest.mark.timeout(30)
def test_mocap_link_counts_garbage_and_keeps_the_latest_good_pose(raw_sock):
    rng = random.Random(SEED)
    garbage = mocap_garbage(rng, 400)
    assert len(garbage) > 200
    with MocapLink(LOOPBACK, 0, object_name="ardrone") as link:
        addr = (LOOPBACK, link.port)
        send_paced(raw_sock, addr, garbage, lambda: link.stats.malformed, 0)
        # hostile but well-formed: non-finite pose, non-ASCII name, all-zero pose
        hostile = [pose_frame(1, t_mm=(math.nan, 0.0, 0.0)),
                   pose_frame(2, t_mm=(math.inf, 1.0, 1.0), r_rad=(0.0, 0.0, -math.inf)),
                   struct.pack("<IBBH24s6d", 3, 1, 0, 72, b"\xe9\xff\x80drone", *([1.0] * 6)),
                   pose_frame(4, t_mm=(0.0, 0.0, 0.0), r_rad=(0.0, 0.0, 0.0))]
        send_paced(raw_sock, addr, hostile, lambda: link.stats.datagrams, len(garbage))
        assert link.latest() == (None, -math.inf)     # nothing fresh reached the controller
        assert link.zero_poses == 3 and link.missing == 1
        raw_sock.sendto(pose_frame(5), addr)
        assert wait_until(lambda: link.latest()[0] is not None)
        pose, _ = link.latest()
        assert pose.position_m.tolist() == pytest.approx([1.0, -0.5, 1.2])
        assert link.stats.malformed == len(garbage)
        assert thread_alive("mocap-rx")


# ----------------------------------------------------------------------------- AT commands


def at_garbage(rng: random.Random) -> list[bytes]:
    valid = (b'AT*CONFIG=3,"control:altitude_max","3000"\rAT*PCMD=4,1,0,0,1056964608,0\r'
             b"AT*REF=5,290718208\r")
    fixed = [b"garbage", b"AT*REF=abc\r", b"AT*REF=5,290718208", b"AT*PCMD=5,1,2143289344,0,0,0\r",
             b"AT*REF=5,2147483648\r", b'AT*CONFIG=5,"a"b","c"\r', b"AT*REF=5,\xe9\r",
             b"\r".join([b"AT*COMWDG=9"] * 120) + b"\r",          # over 1024 bytes
             bytes(range(256))]
    out = []
    for d in fixed + mutations(rng, valid, 300):
        if parse_datagram_lenient(d)[1]:
            out.append(d)                  # keep only datagrams with a malformed part
    return out


@pytest.mark.timeout(60)
def test_simulated_drone_counts_garbage_at_datagrams_and_keeps_flying(drone_server,
                                                                      raw_sock):
    rng = random.Random(SEED)
    garbage = at_garbage(rng)
    assert len(garbage) > 150
    at_addr = (LOOPBACK, drone_server.at_port)
    raw_sock.sendto(NAVDATA_WAKEUP, (LOOPBACK, drone_server.navdata_port))
    raw_sock.sendto(b'AT*CONFIG=1,"general:navdata_demo","TRUE"\r', at_addr)
    assert wait_until(lambda: drone_server.config.get("general:navdata_demo") == "TRUE")
    before = drone_server.counters
    send_paced(raw_sock, at_addr, garbage, lambda: drone_server.counters.at_datagrams_in,
               before.at_datagrams_in)
    after = drone_server.counters
    assert after.malformed_datagrams - before.malformed_datagrams == len(garbage)
    # well-formed but absurd limits are clamped, not applied (the navdata thread died on
    # the int32 altitude they led to)
    raw_sock.sendto(b'AT*CONFIG=500,"control:control_vz_max","1e300"\r'
                    b'AT*CONFIG=501,"control:altitude_max","2500"\r', at_addr)
    assert wait_until(lambda: drone_server.config.get("control:altitude_max") == "2500")
    assert drone_server.plant.params.control_vz_max_mps == pytest.approx(2.0)
    assert all(thread_alive(f"drone-server-{n}") for n in ("physics", "at", "navdata"))
    # navdata keeps flowing and decoding
    raw_sock.settimeout(0.0)
    try:
        while True:
            raw_sock.recv(4096)
    except BlockingIOError:
        pass
    raw_sock.settimeout(2.0)
    raw_sock.sendto(NAVDATA_WAKEUP, (LOOPBACK, drone_server.navdata_port))
    packet = decode_navdata(raw_sock.recv(4096))
    assert packet.demo is not None
