"""The configuration half of the drone link (links/drone_config.py ``ConfigHandshake``) against
the SDK stand-in (tests/standins/sdk_drone.py, written from ARDroneLib's documented behaviour):
what ``configure_profile`` leaves the drone holding, the timeouts it and ``read_config`` are
given, a control port that never accepts, and an ACK left pending by an earlier write.

Over UDP/TCP on 127.0.0.1; every test has a timeout.
"""

from __future__ import annotations

import errno
import os
import socket
import struct
import threading
import time

import pytest

from ardrone_nmpc.links.drone_config import verify_config
from ardrone_nmpc.links.drone_link import DroneLink, LinkError
from ardrone_nmpc.protocol.navdata import DroneState
from tests.integration.test_session_standin import wait_until
from tests.standins.sdk_drone import INDOOR_PROFILE, LOOPBACK, SdkDrone

pytestmark = pytest.mark.timeout(30)


def link_to(drone: SdkDrone, **options) -> DroneLink:
    options = {"control_port": drone.control_port, **options}
    return DroneLink(LOOPBACK, at_port=drone.at_port, navdata_port=drone.navdata_port,
                     bind_host=LOOPBACK, at_local_port=0, **options)


def lose_ctrl4(drone: SdkDrone, n: int) -> None:
    """The first ``n`` ``AT*CTRL=seq,4,0`` lost on the way (UDP)."""
    answer, lost = drone._at_ctrl, [n]

    def at_ctrl(args, now):
        if int(args[0]) == 4 and lost[0] > 0:
            lost[0] -= 1
            return
        answer(args, now)
    drone._at_ctrl = at_ctrl


def drop_ctrl(drone: SdkDrone, mode: int | None = None) -> None:
    """Every ``AT*CTRL`` of ``mode`` (every one, if None) lost on the way (UDP)."""
    answer = drone._at_ctrl
    drone._at_ctrl = lambda args, now: (None if mode is None or int(args[0]) == mode
                                        else answer(args, now))


def raise_ack(drone: SdkDrone, link: DroneLink) -> None:
    """An earlier write's ACK (state bit 6) still raised, and the link has seen it."""
    with drone.lock:
        drone.ack = True
    assert wait_until(lambda: DroneState.COMMAND in link.state, 3.0)


def ctrl4_args(drone: SdkDrone, since_t: float) -> list:
    return [args for _, _, args, _ in drone.commands("CTRL", since_t) if args[0] == 4]


def read_timed(link: DroneLink, timeout_s: float) -> tuple[dict, int]:
    """``read_config`` and how many ``CTRL 4`` it may send: the first, then one re-send per
    0.5 s (``_CONFIG_GET_RESEND_S``) while no byte of the dump has come."""
    t0 = time.monotonic()
    held = link.read_config(timeout_s=timeout_s)
    return held, 1 + int((time.monotonic() - t0) / 0.5)


class NetworkDown:
    """The link's AT socket once the network is down: every ``sendto`` fails with
    ENETUNREACH — after the first ``lost`` ``CTRL 4`` datagrams went out (and were lost)."""

    def __init__(self, sock, lost: int = 0):
        self.sock, self.lost = sock, lost

    def sendto(self, data, address):
        if b",4,0" in data and self.lost > 0:
            self.lost -= 1
            return len(data)
        raise OSError(errno.ENETUNREACH, os.strerror(errno.ENETUNREACH))

    def __getattr__(self, name):
        return getattr(self.sock, name)


def lose_every_config(drone: SdkDrone) -> None:
    """Every ``AT*CONFIG`` lost on the way (UDP): the drone never raises its ACK bit."""
    drone._at_config = lambda args, now: None


@pytest.mark.parametrize("hull", [True, False])
def test_the_profile_brings_an_outdoor_drone_indoors_with_the_hull_as_said(hull):
    """docs/protocol.md §3: control:outdoor FALSE loads the indoor triple, the hull key as
    fitted, flying_mode 0 (free flight) — in the drone's own store, not only in the reply."""
    with SdkDrone(last_flown_outdoors=True) as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        written = link.configure_profile(flight_without_shell=hull)
        held = link.read_config(timeout_s=2.0)
        store = dict(drone.config)
    expected = {"control:outdoor": "FALSE",
                "control:flight_without_shell": "TRUE" if hull else "FALSE",
                "control:flying_mode": "0"}
    assert written == expected
    assert {k: store[k] for k in expected} == expected
    assert verify_config(written, held) == []
    for key, value in INDOOR_PROFILE.items():  # the indoor profile's triple is the one in use
        assert store[key.replace("indoor_", "")] == value


def test_a_profile_the_drone_never_acknowledges_fails_in_the_time_given():
    """``timeout_s`` applies to each key (1 s unless given); the error names the key."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        lose_every_config(drone)
        with pytest.raises(LinkError, match=r"config control:outdoor='FALSE': no ACK from the "
                                            r"drone \(state bit 6 not set within 0\.30 s\)"):
            link.configure_profile(flight_without_shell=False, timeout_s=0.3)
        with pytest.raises(LinkError, match=r"not set within 1\.00 s"):
            link.configure_profile(flight_without_shell=False)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_read_config_refuses_a_timeout_that_is_not_positive(bad):
    link = DroneLink(LOOPBACK, at_port=5556, navdata_port=5554, bind_host=LOOPBACK)
    with pytest.raises(ValueError, match="^timeout_s must be finite and > 0"):
        link.read_config(timeout_s=bad)


@pytest.mark.timeout(20)
def test_a_control_port_that_never_accepts_fails_read_config_in_its_time():
    """A listener whose accept queue is full drops the SYN: the connect itself must time out
    (with no timeout it would retry for minutes), and the error names the port."""
    with socket.socket() as full:
        full.bind((LOOPBACK, 0))
        full.listen(0)
        port = full.getsockname()[1]
        with socket.create_connection((LOOPBACK, port), timeout=1.0):  # fills the queue
            with SdkDrone(serve_control_port=False) as drone, \
                    link_to(drone, control_port=port) as link:
                link.connect(timeout_s=5.0)
                with pytest.raises(LinkError, match=f"^control port {LOOPBACK}:{port}: "):
                    link.read_config(timeout_s=0.5)


@pytest.mark.parametrize("lost", [0, 1])
def test_read_config_first_clears_an_ack_left_pending(lost):
    """An earlier write's ACK still raised (state bit 6): ``AT*CTRL=seq,5,0`` (re-sent every
    50 ms while the bit stays: UDP may lose it) clears it before ``CTRL 4`` asks for the dump,
    and the dump is read."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        raise_ack(drone, link)
        answer, gone = drone._at_ctrl, [lost]

        def at_ctrl(args, now):  # the first ``lost`` CTRL 5 lost on the way
            if int(args[0]) == 5 and gone[0] > 0:
                gone[0] -= 1
                return
            answer(args, now)
        drone._at_ctrl = at_ctrl
        t0 = time.monotonic()
        held = link.read_config(timeout_s=2.0)
        ctrls = [args for _, _, args, _ in drone.commands("CTRL", t0)]
    assert held["control:euler_angle_max"] == "0.2094"
    first_dump = ctrls.index([4, 0])
    assert first_dump >= 1 + lost and ctrls[:first_dump] == [[5, 0]] * first_dump


def test_a_drone_that_raises_no_ack_after_the_dump_still_gives_it():
    """The ACK after the dump is waited for only a short grace (some firmwares send none)."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        answer = drone._at_ctrl

        def at_ctrl(args, now):
            answer(args, now)
            drone.ack = False
        drone._at_ctrl = at_ctrl
        held = link.read_config(timeout_s=1.0)
    assert held["control:outdoor"] == "FALSE"


def test_an_ack_after_the_dump_that_never_clears_fails_read_config_naming_it():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        drop_ctrl(drone, 5)
        with pytest.raises(LinkError, match=r"^read_config: ACK \(state bit 6\) not cleared "
                                            r"by AT\*CTRL 5 in time"):
            link.read_config(timeout_s=1.0)


def test_an_ack_that_never_clears_fails_read_config_naming_the_step():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        drop_ctrl(drone)  # the drone keeps its ACK bit
        raise_ack(drone, link)
        with pytest.raises(LinkError, match=r"^read_config: a previous ACK: ACK \(state bit 6\) "
                                            r"not cleared"):
            link.read_config(timeout_s=0.5)


def test_a_dump_that_never_comes_fails_read_config_saying_how_long_it_waited():
    """The port accepts but ``CTRL 4`` is never answered (lost each time it is re-sent)."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        drop_ctrl(drone, 4)
        t0 = time.monotonic()
        with pytest.raises(LinkError, match=r"^configuration dump not finished within 0\.90 s "
                                            r"\(0 bytes read\)"):
            link.read_config(timeout_s=0.9)
        assert len(ctrl4_args(drone, t0)) >= 2  # re-sent every 0.5 s while nothing came


def test_a_byte_outside_ascii_in_the_dump_is_replaced_not_fatal():
    """The dump is ASCII text (docs/protocol.md §3); a stray byte in a free-text key must not
    cost the read-back of the limits."""
    with SdkDrone() as drone, link_to(drone) as link:
        drone.config["custom:application_desc"] = "caf\u00e9"   # sent as UTF-8 bytes
        link.connect(timeout_s=5.0)
        held = link.read_config(timeout_s=2.0)
    assert held["custom:application_desc"].startswith("caf")
    assert held["control:euler_angle_max"] == "0.2094" and held["control:outdoor"] == "FALSE"


def test_a_dump_in_many_pieces_is_asked_for_once():
    """``AT*CTRL=seq,4,0``, re-sent only while nothing of the dump has come (a re-send per
    piece would start a dump per piece), and 1 s is time enough on loopback."""
    with SdkDrone() as drone, link_to(drone) as link:
        for i in range(400):                         # ~16 kB: many TCP reads
            drone.config[f"custom:filler_{i:03d}"] = "x" * 16
        link.connect(timeout_s=5.0)
        t0 = time.monotonic()
        held, most = read_timed(link, 1.0)
        sent = ctrl4_args(drone, t0)
        assert sent[0] == [4, 0] and len(sent) <= most
    assert held["custom:filler_399"] == "x" * 16 and held["control:control_vz_max"] == "700"


def test_a_lost_dump_request_is_sent_again_the_same():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        lose_ctrl4(drone, 1)
        t0 = time.monotonic()
        held, most = read_timed(link, 3.0)
        sent = ctrl4_args(drone, t0)
        assert sent[:2] == [[4, 0], [4, 0]] and len(sent) <= most
    assert held["control:euler_angle_max"] == "0.2094"


@pytest.mark.parametrize("lost, pending_ack", [(0, False), (1, False), (0, True)])
def test_a_network_gone_down_fails_read_config_at_once_naming_the_send(lost, pending_ack):
    """The dump request (or its re-send, after the first was lost; or the CTRL 5 clearing an
    ACK left pending) cannot be sent: the error says so when it happens, not as a dump that
    did not come or an ACK that did not clear in time."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        if pending_ack:
            raise_ack(drone, link)
        with link._at_lock:
            link._at_sock = NetworkDown(link._at_sock, lost)
        with pytest.raises(LinkError, match=rf"^AT send to {LOOPBACK}:{drone.at_port}: "):
            link.read_config(timeout_s=0.3 if lost == 0 else 2.0)


@pytest.mark.parametrize("arg, name", [(0, "euler_angle_max_rad"), (1, "control_vz_max_mps"),
                                       (2, "control_yaw_radps"), (3, "altitude_max_m")])
def test_configure_limits_names_the_limit_that_is_not_positive(arg, name):
    limits = [0.2, 0.7, 1.75, 3.0]
    limits[arg] = -limits[arg]
    link = DroneLink(LOOPBACK, at_port=5556, navdata_port=5554, bind_host=LOOPBACK)
    with pytest.raises(ValueError, match=f"^{name} must be finite and > 0"):
        link.configure_limits(*limits)


def test_the_tilt_limit_takes_30_degrees_itself_and_each_key_its_time():
    """docs/protocol.md §3.1: euler_angle_max in (0, 0.52] rad; ``timeout_s`` per key, 1 s
    unless given."""
    from ardrone_nmpc.links.drone_config import EULER_ANGLE_MAX_LIMIT_RAD

    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        written = link.configure_limits(EULER_ANGLE_MAX_LIMIT_RAD, 0.7, 1.75, 3.0)
        assert float(written["control:euler_angle_max"]) == pytest.approx(0.52)
        assert float(drone.config["control:euler_angle_max"]) == pytest.approx(0.52)
        lose_every_config(drone)
        with pytest.raises(LinkError, match=r"config control:euler_angle_max=.*not set within "
                                            r"1\.00 s"):
            link.configure_limits(0.2, 0.7, 1.75, 3.0)


def serve_once(listener: socket.socket, drone: SdkDrone, answer) -> threading.Thread:
    """Accept one connection on ``listener`` (the drone's control port) and ``answer`` it
    once the dump has been asked for (``CTRL 4`` at the drone: the link is reading)."""
    def run():
        conn, _ = listener.accept()
        with conn:
            wait_until(lambda: ctrl4_args(drone, 0.0), 5.0)
            answer(conn)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def reset(conn):  # an RST instead of a FIN
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))


@pytest.mark.parametrize("answer, error", [
    (lambda conn: conn.sendall(b"control:outdoor = FALSE\n"),
     r"^control port closed before the configuration's NUL terminator \(24 bytes read\)"),
    (reset, r"^control port read failed: "),
    (lambda conn: conn.sendall(b"x" * (1 << 20) + b"y"),
     r"^configuration dump over 1 MiB without a NUL byte$"),
])
def test_a_control_port_that_fails_mid_dump_is_named(answer, error):
    with socket.socket() as listener, SdkDrone(serve_control_port=False) as drone:
        listener.bind((LOOPBACK, 0))
        listener.listen(1)
        with link_to(drone, control_port=listener.getsockname()[1]) as link:
            link.connect(timeout_s=5.0)
            thread = serve_once(listener, drone, answer)
            with pytest.raises(LinkError, match=error):
                link.read_config(timeout_s=3.0)
            thread.join(timeout=5.0)


def test_a_dump_of_exactly_1_mib_with_its_nul_is_read():
    text = b"control:outdoor = FALSE\n"
    dump = text + b"custom:pad = " + b"p" * ((1 << 20) - len(text) - 15) + b"\n\0"
    assert len(dump) == 1 << 20
    with socket.socket() as listener, SdkDrone(serve_control_port=False) as drone:
        listener.bind((LOOPBACK, 0))
        listener.listen(1)
        with link_to(drone, control_port=listener.getsockname()[1]) as link:
            link.connect(timeout_s=5.0)
            thread = serve_once(listener, drone, lambda conn: conn.sendall(dump))
            held = link.read_config(timeout_s=3.0)
            thread.join(timeout=5.0)
    assert held["control:outdoor"] == "FALSE" and len(held["custom:pad"]) == (1 << 20) - 39


def test_the_altitude_limit_is_whole_millimetres_at_least_one():
    """§3.1: control:altitude_max in mm; 1 mm is the least the drone can hold."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        written = link.configure_limits(0.2, 0.7, 1.75, 0.001)
        assert written["control:altitude_max"] == "1" == drone.config["control:altitude_max"]
        with pytest.raises(ValueError, match=r"^altitude_max_m must be at least 1 mm, got "
                                             r"0\.0004$"):
            link.configure_limits(0.2, 0.7, 1.75, 0.0004)
        lose_every_config(drone)
        with pytest.raises(LinkError, match=r"not set within 0\.30 s"):
            link.configure_limits(0.2, 0.7, 1.75, 3.0, timeout_s=0.3)


def test_a_lost_config_is_re_sent_every_config_resend_s_and_no_more_often():
    """UDP may lose ``AT*CONFIG``: re-sent every ``config_resend_s`` (0.3 s) until the ACK —
    at most 1 + 1.0/0.3 times in a 1 s wait, not on every navdata packet (15 Hz)."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        lose_every_config(drone)
        t0 = time.monotonic()
        with pytest.raises(LinkError, match="no ACK"):
            link.write_config("control:flying_mode", 0, timeout_s=1.0)
        sent = drone.commands("CONFIG", t0)
    assert 2 <= len(sent) <= 4


def test_a_drone_gone_silent_fails_a_config_write_in_its_time():
    """No navdata at all (a Wi-Fi blackout): the wait for the ACK ends at its timeout, it
    does not wait for a packet that never comes."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        drone.blackout(20.0)
        with pytest.raises(LinkError, match=r"not set within 0\.50 s"):
            link.write_config("control:flying_mode", 0, timeout_s=0.5)


# ----------------------------------------------------------------------------- write_config
# What mutmut's full drone_config run left alive in write_config: its timeout's name and 1 s
# default, the ACK left pending before the write and the one after it, a send that fails.
KEY_TEXT = r"config control:flying_mode='0'"


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_write_config_refuses_a_timeout_that_is_not_positive(bad):
    link = DroneLink(LOOPBACK, at_port=5556, navdata_port=5554, bind_host=LOOPBACK)
    with pytest.raises(ValueError, match="^timeout_s must be finite and > 0"):
        link.write_config("control:flying_mode", 0, timeout_s=bad)


def test_a_config_write_waits_1_s_for_its_ack_unless_told():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        lose_every_config(drone)
        with pytest.raises(LinkError, match=rf"^{KEY_TEXT}: no ACK from the drone \(state bit "
                                            r"6 not set within 1\.00 s\)"):
            link.write_config("control:flying_mode", 0)


def test_an_ack_left_pending_that_never_clears_fails_the_write_naming_it():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        drop_ctrl(drone)  # the drone keeps its ACK bit
        raise_ack(drone, link)
        t0 = time.monotonic()
        with pytest.raises(LinkError, match=rf"^{KEY_TEXT}: a previous ACK: ACK \(state bit 6\) "
                                            r"not cleared"):
            link.write_config("control:flying_mode", 0, timeout_s=0.5)
        assert not drone.commands("CONFIG", t0)  # nothing written over a pending ACK


def test_the_write_s_own_ack_that_never_clears_fails_it_naming_the_key():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        drop_ctrl(drone, 5)
        with pytest.raises(LinkError, match=rf"^{KEY_TEXT}: ACK \(state bit 6\) not cleared"):
            link.write_config("control:flying_mode", 0, timeout_s=0.5)


def test_a_network_gone_down_fails_a_config_write_at_once_naming_the_send():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=5.0)
        with link._at_lock:
            link._at_sock = NetworkDown(link._at_sock)
        t0 = time.monotonic()
        with pytest.raises(LinkError, match=rf"^AT send to {LOOPBACK}:{drone.at_port}: "):
            link.write_config("control:flying_mode", 0, timeout_s=20.0)
        assert time.monotonic() - t0 < 10.0  # at once, not at the ACK's 20 s timeout
