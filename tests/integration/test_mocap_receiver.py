"""The receivers of the mocap sources, for real: the Vicon UDP link over a 127.0.0.1 socket
(links/mocap_link.py) — the port asked for, the sender named by its address and port, a
thread that outlives idle polls and a transient network error, never keeps the process alive,
and stops with the socket on close; ``start`` once only — and the libmotioncapture source
with the installed library's ``mock`` system in its child process. Every wait is for a
state, bounded by a timeout."""

from __future__ import annotations

import math
import socket
import threading

import pytest

from ardrone_nmpc.links import mocap_link
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.links.motioncapture_source import MotionCaptureSource
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap
from ardrone_nmpc.sim.loopback import free_udp_port

from tests.integration.test_links import wait_until

LOOPBACK = "127.0.0.1"


def _datagram(k: int, x_mm: float = 1000.0) -> bytes:
    return encode_mocap(MocapFrame.of(k, [MocapObjectPose("ardrone", (x_mm, 0.0, 1000.0),
                                                          (0.0, 0.0, 0.2))]))


@pytest.fixture
def sender():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((LOOPBACK, 0))
    yield sock
    sock.close()


@pytest.mark.timeout(10)
def test_the_link_listens_on_the_port_asked_and_names_the_sender(sender):
    port = free_udp_port()
    now = [41.5]
    link = MocapLink(LOOPBACK, port, object_name="ardrone", clock=lambda: now[0])
    assert link.port == port and link.where == f"udp {LOOPBACK}:{port}"
    with link:
        assert link.port == port
        sender.sendto(_datagram(1), (LOOPBACK, port))
        assert wait_until(lambda: link.poses == 1)
        assert link.latest()[1] == 41.5                     # stamped by the link's clock
        assert link.sender == f"{LOOPBACK}:{sender.getsockname()[1]}"
        assert link.frames_from(link.sender) == 1 and link.foreign_senders == {}


@pytest.mark.timeout(10)
def test_the_receiver_outlives_idle_polls_never_holds_the_process_and_stops_on_close(sender):
    link = MocapLink(LOOPBACK, 0, object_name="ardrone")
    link.close()                                          # never started: nothing to stop
    link = MocapLink(LOOPBACK, 0, object_name="ardrone")
    link.start()
    try:
        rx = next(t for t in threading.enumerate() if t.name == "mocap-rx" and t.is_alive()
                  and t is link._thread)
        assert rx.daemon                                  # a hung receiver never blocks exit
        rx.join(timeout=4 * mocap_link._RX_POLL_S)        # several empty receive timeouts…
        assert rx.is_alive()
        sender.sendto(_datagram(1), (LOOPBACK, link.port))
        assert wait_until(lambda: link.poses == 1)        # …and it still receives
    finally:
        link.close()
    assert not rx.is_alive() and link._sock.fileno() == -1
    link.close()                                          # idempotent


@pytest.mark.timeout(10)
def test_start_is_once_only():
    link = MocapLink(LOOPBACK, 0)
    with link:
        with pytest.raises(RuntimeError, match=r"^MocapLink already started \(or closed\)$"):
            link.start()
    with pytest.raises(RuntimeError, match=r"^MocapLink already started \(or closed\)$"):
        link.start()                                      # nor after close


class _FlakySocket:
    """A bound socket whose first receive fails as a network going down does (ENETDOWN)."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock, self.failed = sock, threading.Event()

    def recvfrom(self, n):
        if not self.failed.is_set():
            self.failed.set()
            raise OSError(100, "Network is down")
        return self.sock.recvfrom(n)

    def __getattr__(self, name):
        return getattr(self.sock, name)


@pytest.mark.timeout(10)
def test_a_receive_error_is_waited_out_not_the_end_of_the_receiver(sender, monkeypatch):
    made = []
    real_open = mocap_link.open_udp

    def flaky_open(*args, **kw):
        made.append(_FlakySocket(real_open(*args, **kw)))
        return made[-1]

    monkeypatch.setattr(mocap_link, "open_udp", flaky_open)
    with MocapLink(LOOPBACK, 0, object_name="ardrone") as link:
        assert made[0].failed.wait(5.0)
        sender.sendto(_datagram(1, 1234.0), (LOOPBACK, link.port))
        assert wait_until(lambda: link.poses == 1)
        assert link.latest()[0].position_m[0] == pytest.approx(1.234)
        assert link._thread.is_alive()


# ----------------------------------------------------------------------------- library process


@pytest.mark.timeout(60)
def test_the_real_librarys_mock_system_through_the_library_process():
    """``MotionCaptureSource`` with the installed libmotioncapture (the ``mocap`` extra) in its
    child process: the ``mock`` system's rigid body (``name(x,y,z,qw,qx,qy,qz)``, the
    library's documented option) arrives converted; close ends the process and its pipe."""
    c, s = math.cos(0.2), math.sin(0.2)                   # a 0.4 rad yaw
    src = MotionCaptureSource("mock", {"hostname": "localhost", "frequency": "100",
                                       "rigid_bodies": f"ardrone(0.1,0.2,0.3,{c!r},0,0,{s!r})"},
                              repeat_limit=None, connect_timeout_s=30.0)
    src.close()                                           # never started: nothing to stop
    src = MotionCaptureSource("mock", dict(src.options), repeat_limit=None,
                              connect_timeout_s=30.0)
    src.start()
    child = src._child
    try:
        assert wait_until(lambda: src.poses >= 3, timeout_s=30.0)
        pose, _ = src.latest()
        assert pose.position_m.tolist() == pytest.approx([0.1, 0.2, 0.3], abs=1e-6)
        assert pose.psi_rad == pytest.approx(0.4, abs=1e-6)   # float32 in the library
    finally:
        src.close()
    assert child.poll() is not None and child.stdout.closed and not src._thread.is_alive()
    src.close()                                           # idempotent
