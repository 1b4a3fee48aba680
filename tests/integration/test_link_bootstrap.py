"""The drone link answers bootstrap after connecting, as ARDroneLib does
(``ardrone_general_navdata.c``: on a bootstrap packet, the session id again, then
``navdata_demo``), against the SDK stand-in (tests/standins/sdk_drone.py) over UDP on 127.0.0.1.
A drone that lost its client — a Wi-Fi blackout — restarts its stream in bootstrap, and a link
that only read demo packets would go blind although packets arrive.
"""

from __future__ import annotations

import time

import pytest

from tests.integration.test_session_standin import IDS, link_to, wait_until
from tests.standins.sdk_drone import SdkDrone

pytestmark = pytest.mark.timeout(30)


@pytest.mark.parametrize("ids", [None, IDS])
def test_a_bootstrap_packet_after_connecting_is_answered_as_the_sdk_does(ids):
    """ardrone_general_navdata.c: on a bootstrap packet, the session id again, then
    navdata_demo — the stream is demo again, and the link never waited in the receiver."""
    held = None if ids is None else dict(zip(("custom:session_id", "custom:profile_id",
                                              "custom:application_id"), IDS))
    with SdkDrone(held=held) as drone, link_to(drone, config_ids=ids) as link:
        link.connect(timeout_s=3.0)
        assert link.bootstrap_answers == 0
        with drone.lock:
            t0 = time.monotonic()
            drone.bootstrap = True                  # the drone lost us and came back
        assert wait_until(lambda: not drone.bootstrap, 3.0)
        assert wait_until(lambda: time.monotonic() - link.navdata_rx_t_s < 0.2, 3.0)
        writes = [args[:2] for t, name, args, _ in drone.log if name == "CONFIG" and t > t0]
        keys = [k for k, _ in writes]
        assert keys[-1] == "general:navdata_demo" and writes[-1][1] == "TRUE"
        assert ("custom:session_id" in keys) is (ids is not None)
        if ids is not None:
            assert keys.index("custom:session_id") < keys.index("general:navdata_demo")
        assert link.bootstrap_answers == 1 and link.connected


def test_every_bootstrap_is_answered_and_an_unanswered_one_is_said():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=3.0)
        for n in (1, 2):                            # two blackouts, two answers
            with drone.lock:
                drone.bootstrap = True
            assert wait_until(lambda: not drone.bootstrap, 3.0)
            assert wait_until(lambda: link.bootstrap_answers == n, 3.0)
        with drone.lock:                            # now left in another session: no ACK
            drone.config.update(dict(zip(("custom:session_id", "custom:profile_id",
                                          "custom:application_id"), IDS)))
            drone.bootstrap = True
        assert wait_until(lambda: (link.last_error or "").startswith("bootstrap answer: "),
                          5.0)
        assert "general:navdata_demo='TRUE': no ACK" in link.last_error
        assert link.connected and drone.bootstrap


def test_every_packet_updates_what_a_landing_reads():
    """DroneLink's receiver, packet by packet (packed here from docs/protocol.md §4): the state
    word and mode of any packet; the demo sample of demo packets only; a demo packet's
    ctrl_state decides (bit 0 clear but major 8 is still landing)."""
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.links.drone_link import DroneLink
    from tests.integration.test_operator_link import BOOTSTRAP, DEMO, FLY, packet

    clock = iter(float(t) for t in range(100, 200))
    link = DroneLink("127.0.0.1", clock=lambda: next(clock))
    link._host_ip = "127.0.0.1"
    here = ("127.0.0.1", 5554)
    link._handle_navdata(packet(FLY | BOOTSTRAP, seq=1), here)
    assert (link.packet_mode, link.navdata, link.state_rx_t_s) == (FlightMode.FLYING, None, 100.0)
    assert link.state == FLY | BOOTSTRAP and link.bootstrap_answers == 0  # not connected yet
    link._handle_navdata(packet(DEMO, seq=2, major=8), here)
    assert link.packet_mode is FlightMode.LANDING and link.state_rx_t_s == 101.0
    assert link.navdata.mode is FlightMode.LANDING and link.navdata.t_s == 101.0
    assert link.navdata_rx_t_s == 101.0 and link.navdata.battery_pct == 60.0
    link._handle_navdata(packet(BOOTSTRAP, seq=3), here)    # the demo sample stays
    assert link.packet_mode is FlightMode.LANDED and link.navdata_rx_t_s == 101.0
    link._handle_navdata(b"\x88\x77\x66\x55bad", here)
    assert link.stats.malformed == 1 and link.last_error.startswith("navdata: ")
    link.close()


def test_the_bootstrap_answer_runs_in_a_named_daemon_thread():
    """Named for diagnostics; a daemon, so a process that ends never waits for an answer."""
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=3.0)
        with drone.lock:
            drone.bootstrap = True
        assert wait_until(lambda: link._bootstrap_thread is not None, 3.0)
        assert link._bootstrap_thread.name == "drone-bootstrap-answer"
        assert link._bootstrap_thread.daemon is True
