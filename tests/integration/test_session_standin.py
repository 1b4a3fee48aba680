"""The flight session and the drone link against the SDK stand-in (tests/standins/sdk_drone.py),
over real UDP/TCP on 127.0.0.1 — a drone written from the SDK's documented behaviour, not our
simulator: config read-back over its control port, a drone that ignores writes, multiconfig
ids, a drone that lands by itself, one found airborne, the heading check, re-wake, the local
AT port and the flight lock. Every wait has a timeout; tests wait for states, not wall time.
"""

from __future__ import annotations

import math
import socket
import time

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.links.drone_link import DroneAirborne, DroneLink, LinkError
from ardrone_nmpc.links.flight_lock import DroneBusy, FlightLock
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.runtime.session import DroneLandedItself, FlightSession, PreflightError
from tests.standins.sdk_drone import OUTDOOR_HELD, REF_TAKEOFF, MocapStandIn, SdkDrone

IDS = ("d2e081a3", "be27e2e4", "d87f7e0c")
pytestmark = pytest.mark.timeout(60)


def wait_until(predicate, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return False


def link_to(drone: SdkDrone, **options) -> DroneLink:
    options.setdefault("at_local_port", 0)
    return DroneLink("127.0.0.1", at_port=drone.at_port, navdata_port=drone.navdata_port,
                     control_port=drone.control_port, bind_host="127.0.0.1", **options)


class Flight:
    """A stand-in drone, its mocap stream, a mocap link and a session, torn down in order."""

    def __init__(self, tmp_path, drone_options=(), sets=(), mirrored=False, link_options=None):
        self.drone = SdkDrone(**dict(drone_options)).start()
        self.mocap = MocapLink("127.0.0.1", 0, object_name="ardrone")
        self.mocap.start()
        sign = -1.0 if mirrored else 1.0
        alt = {"hovering": 1.0, "takeoff": 0.5, "landing": 0.3}
        self.stream = MocapStandIn(self.mocap.port, lambda: (
            (0.0, 0.0, alt.get(self.drone.phase, 0.0)), sign * self.drone.true_psi_rad))
        self.stream.__enter__()
        self.link = link_to(self.drone, **(link_options or {}))
        self.events, self.warnings = [], []
        cfg = load_config(None, ["mocap.bind_host=127.0.0.1", *sets])
        self.session = FlightSession(cfg, self.link, self.mocap,
                                     event=lambda kind, **f: self.events.append((kind, f)),
                                     warn=self.warnings.append, start_position_m=(0, 0, 1),
                                     lock=FlightLock("127.0.0.1", self.drone.at_port,
                                                     directory=tmp_path))

    def kinds(self):
        return [k for k, _ in self.events]

    def close(self):
        self.link.close()
        self.stream.__exit__()
        self.mocap.close()
        self.drone.stop()


@pytest.fixture
def flight(tmp_path):
    made = []

    def make(**kw):
        made.append(Flight(tmp_path, **kw))
        return made[-1]

    yield make
    for f in made:
        f.close()


def test_limits_read_back_verified_then_trim_take_off_and_land(flight):
    f = flight()
    with f.session:
        assert f.drone.phase == "hovering"
    assert f.session.landed_cleanly is True and f.drone.phase == "landed"
    read = dict(f.events)["config_read"]
    assert read["control:euler_angle_max"] == "0.2094" and read["control:control_vz_max"] == "700"
    assert read["control:outdoor"] == "FALSE" and read["control:flying_mode"] == "0"
    first_takeoff = min(t for t, _, args, _ in f.drone.commands("REF") if args[0] & REF_TAKEOFF)
    assert len(f.drone.ftrims) == 1
    assert first_takeoff - f.drone.ftrims[0] >= 0.5          # FTRIM, then ≥ 0.5 s
    assert f.drone.takeoffs == 1
    assert f.kinds()[-1] == "landed"


def test_a_drone_that_ignores_config_writes_gets_no_take_off(flight):
    f = flight(drone_options={"ignore_config_writes": True, "held": OUTDOOR_HELD})
    with pytest.raises(PreflightError) as err:
        f.session.__enter__()
    msg = str(err.value)
    assert "control:outdoor = 'TRUE', not the 'FALSE' written" in msg
    assert "and 3 more key(s)" in msg  # tilt 0.52, vz 2000, yaw 6.11
    assert f.drone.commands("REF") == [] and f.drone.ftrims == [] and f.drone.takeoffs == 0
    mismatched = {fields["key"] for kind, fields in f.events if kind == "config_mismatch"}
    assert mismatched == {"control:euler_angle_max", "control:control_vz_max",
                          "control:control_yaw", "control:outdoor"}


def test_a_silent_control_port_refuses_unless_verification_is_off(flight):
    f = flight(drone_options={"serve_control_port": False})
    with pytest.raises(PreflightError, match="did not answer"):
        f.session.__enter__()
    assert f.drone.commands("REF") == []
    g = flight(drone_options={"serve_control_port": False}, sets=["drone.verify_config=false"])
    with g.session:
        assert g.drone.phase == "hovering"
    assert any("UNVERIFIED" in w for w in g.warnings)


def test_config_ids_precede_every_config_and_verify(flight):
    f = flight(sets=[f"drone.config_ids=[{','.join(IDS)}]"], link_options={"config_ids": IDS})
    with f.session:
        pass
    log = [(name, args) for _, name, args, _ in f.drone.log if name in ("CONFIG", "CONFIG_IDS")]
    configs = [i for i, (name, _) in enumerate(log) if name == "CONFIG"]
    assert len(configs) >= 11  # 3 session ids + navdata_demo + 7 checked keys
    assert all(log[i - 1] == ("CONFIG_IDS", list(IDS)) for i in configs)
    assert f.drone.config["custom:session_id"] == IDS[0]
    assert f.drone.config["control:euler_angle_max"] == "0.2094"


def test_without_ids_a_drone_in_another_session_never_acknowledges(flight):
    held = {"custom:session_id": IDS[0], "custom:profile_id": IDS[1],
            "custom:application_id": IDS[2]}
    f = flight(drone_options={"held": held})
    with pytest.raises(LinkError, match=r"general:navdata_demo.*no ACK"):
        f.session.__enter__()
    assert f.drone.commands("REF") == []


def test_a_drone_found_airborne_is_not_taken_over(flight):
    f = flight(drone_options={"airborne_at_start": True})
    with pytest.raises(DroneAirborne, match="airborne .* not taking it over; land it with "
                                            "`ardrone-nmpc land --drone 127.0.0.1`"):
        f.session.__enter__()
    assert f.drone.log == []  # not one AT command: no REF, no PCMD, no CONFIG
    assert f.drone.phase == "hovering"


@pytest.mark.parametrize("codes", ["sdk", "fw24"])
def test_a_drone_that_lands_by_itself_is_never_launched_again(flight, codes):
    f = flight(drone_options={"land_by_itself_after_s": 0.5, "ctrl_codes": codes})
    with pytest.raises(DroneLandedItself):
        with f.session:
            assert wait_until(lambda: f.link.self_landing is not None)
            raise DroneLandedItself(f.link.self_landing)
    assert wait_until(lambda: f.drone.self_landed_t is not None)
    time.sleep(0.3)  # keepalives after touch-down: every one must hold land
    assert f.drone.takeoff_refs_after_touchdown() == []
    assert f.drone.takeoffs == 1 and f.drone.phase == "landed"
    assert f"major {8 if codes == 'sdk' else 9}" in f.link.self_landing
    assert f.link.takeoff_barred.startswith("the drone landed by itself")
    with pytest.raises(LinkError, match="take-off refused: the drone landed by itself"):
        f.link.takeoff()
    assert f.session.landed_cleanly is True


def test_a_mirrored_mocap_heading_lands_with_the_measured_offset(flight):
    f = flight(drone_options={"takeoff_yaw_dps": 30.0}, mirrored=True)
    with pytest.raises(PreflightError, match=r"mocap heading turned [+-]\d+\.\d° and navdata's "
                                             r"yaw [+-]\d+\.\d° \(offset [+-]\d+\.\d°"):
        f.session.__enter__()
    check = dict(f.events)["heading_check"]
    assert check["offset_rad"] == pytest.approx(-2 * check["navdata_turn_rad"], abs=0.05)
    assert abs(check["navdata_turn_rad"]) > 0.15
    assert f.drone.phase == "landed" and f.session.landed_cleanly is True
    g = flight(drone_options={"takeoff_yaw_dps": 30.0})          # the same turn, right frame
    with g.session:
        assert abs(dict(g.events)["heading_check"]["offset_rad"]) < 0.05


def test_preflight_refusals_against_the_stand_in(flight):
    for options, match in (({"battery_pct": 15}, "battery 15 %"),
                           ({"attitude_deg": (3.0, 0.0)}, "not level")):
        f = flight(drone_options=options)
        with pytest.raises(PreflightError, match=match):
            f.session.__enter__()
        assert f.drone.commands("REF") == [] and f.drone.ftrims == []


def test_navdata_is_woken_again_within_0_2_s_of_silence():
    with SdkDrone() as drone, link_to(drone) as link:
        link.connect(timeout_s=3.0)
        assert wait_until(lambda: getattr(drone, "last_navdata_t", None) is not None)
        n = len(drone.wakeups)
        drone.silent_until = time.monotonic() + 1.0
        last = drone.last_navdata_t
        assert wait_until(lambda: len(drone.wakeups) > n, timeout_s=2.0)
        gap = drone.wakeups[n] - last
        assert gap < 0.2 + 0.05 + 0.05, gap  # re-wake after 0.2 s, noticed within one poll


def test_the_at_socket_uses_local_port_5556_style_binding_and_falls_back():
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    with SdkDrone() as drone, link_to(drone, at_local_port=port) as link:
        link.connect(timeout_s=3.0)
        assert link.at_bind_warning is None
        assert drone.at_sources == {("127.0.0.1", port)}
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    try:
        taken = busy.getsockname()[1]
        with SdkDrone() as drone, link_to(drone, at_local_port=taken) as link:
            link.connect(timeout_s=3.0)
            assert f"local UDP port {taken} is busy" in link.at_bind_warning
            assert drone.at_sources and all(p != taken for _, p in drone.at_sources)
    finally:
        busy.close()


def test_a_second_flight_at_the_same_drone_is_refused_before_any_datagram(tmp_path):
    with SdkDrone() as drone:
        holder = FlightLock("localhost", drone.at_port, directory=tmp_path)
        holder.acquire()
        try:
            link = link_to(drone)
            session = FlightSession(load_config(None), link, None, event=lambda *a, **k: None,
                                    lock=FlightLock("127.0.0.1", drone.at_port,
                                                    directory=tmp_path))
            with pytest.raises(DroneBusy, match=r"127\.0\.0\.1:\d+ is being flown from this "
                                                r"machine \(pid \d+"):
                session.__enter__()
            time.sleep(0.1)
            assert drone.wakeups == [] and drone.log == []
            assert FlightLock("127.0.0.1", drone.at_port, directory=tmp_path).holder() > 0
        finally:
            holder.release()
        assert FlightLock("127.0.0.1", drone.at_port, directory=tmp_path).holder() is None


def test_emergency_primes_the_edge_on_a_fresh_link():
    with SdkDrone(airborne_at_start=True) as drone, link_to(drone, allow_airborne=True) as link:
        link.connect(timeout_s=3.0)
        link.emergency()
        assert wait_until(lambda: link.navdata.mode is FlightMode.EMERGENCY, 3.0)
        refs = [args[0] for _, _, args, _ in drone.commands("REF")]
        assert refs[0] & REF_TAKEOFF and not refs[0] & (1 << 8)  # hovering: bit 9 kept
        assert refs[1] & (1 << 8)
        assert math.isfinite(link.navdata.battery_pct)

