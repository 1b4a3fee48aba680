"""The simulated drone's configuration (ardrone_nmpc.sim.drone_config) and the firmware faults
that act on it, datagram by datagram through an unstarted DroneServer (no timing).

The multiconfig rule checked here is the SDK's shape (ARDroneLib ardrone_at_mutex.c
``ardrone_at_set_toy_configuration_ids``): ``AT*CONFIG_IDS`` then ``AT*CONFIG`` in one datagram.
Datagrams are typed by hand, not built with the project's encoders.
"""

from __future__ import annotations

import pytest

from ardrone_nmpc.config.schema import ConfigError, ExperimentConfig

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.protocol.navdata import DroneState
from ardrone_nmpc.sim.drone_config import ConfigStore, HeldSession
from ardrone_nmpc.sim.drone_server import DroneServer
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim.faults import FaultSchedule
from ardrone_nmpc.sim.plant import AirframePlant

IDS = ("d2e081a3", "be27e2e4", "d87f7e0c")
OTHER = ("0a0b0c0d", "be27e2e4", "d87f7e0c")


def plant():
    cfg = ExperimentConfig()
    return AirframePlant.from_config(cfg.sim, cfg.drone, seed=1)


@pytest.fixture
def drone():
    """A drone left in session IDS (threads not started: datagrams applied one by one)."""
    srv = DroneServer(plant(), session=HeldSession(IDS), clock=lambda: 50.0)
    yield srv
    srv.stop()


def at(text: str) -> bytes:
    return text.replace("\n", "\r").encode()


def ids_cmd(seq: int, ids) -> str:
    return f'AT*CONFIG_IDS={seq},"{ids[0]}","{ids[1]}","{ids[2]}"\n'


def test_a_held_session_flies_and_reports_its_own_limits(drone):
    p = drone.plant.params
    assert (p.euler_angle_max_rad, p.control_vz_max_mps, p.control_yaw_radps) == (0.52, 2.0, 6.11)
    held = drone.config_held
    assert held["control:euler_angle_max"] == "0.5200"
    assert float(held["control:control_vz_max"]) == 2000.0
    assert held["control:control_yaw"] == "6.1100"
    assert (held["custom:session_id"], held["custom:profile_id"],
            held["custom:application_id"]) == IDS


def test_writes_without_the_sessions_ids_are_acked_not_applied(drone):
    drone.handle_at_datagram(at('AT*CONFIG=1,"control:euler_angle_max","0.2094"\n'))
    assert DroneState.COMMAND in drone.state_bits()          # acknowledged …
    assert drone.plant.params.euler_angle_max_rad == 0.52     # … not applied
    assert drone.config_held["control:euler_angle_max"] == "0.5200"
    assert "control:euler_angle_max" not in drone.config
    # other ids, or the right ids in an earlier datagram: still not applied
    drone.handle_at_datagram(at(ids_cmd(2, OTHER) + 'AT*CONFIG=3,"control:control_yaw","1.745"\n'))
    drone.handle_at_datagram(at(ids_cmd(4, IDS)))
    drone.handle_at_datagram(at('AT*CONFIG=5,"control:control_vz_max","700"\n'))
    assert drone.plant.params.control_yaw_radps == 6.11
    assert drone.plant.params.control_vz_max_mps == 2.0
    c = drone.counters
    assert (c.config_writes, c.config_writes_ignored) == (3, 3)


def test_keys_every_session_shares_apply_without_ids(drone):
    # config_keys.h: navdata_demo, altitude_max, outdoor are CAT_COMMON; flying_mode CAT_SESSION
    drone.handle_at_datagram(at('AT*CONFIG=1,"general:navdata_demo","TRUE"\n'
                                'AT*CONFIG=2,"control:altitude_max","2000"\n'
                                'AT*CONFIG=3,"control:outdoor","FALSE"\n'
                                'AT*CONFIG=4,"control:flying_mode","1"\n'))
    assert not drone.bootstrap and drone.altitude_max_m == pytest.approx(2.0)
    assert drone.config["control:outdoor"] == "FALSE"
    assert "control:flying_mode" not in drone.config
    assert drone.counters.config_writes_ignored == 1


def test_the_sessions_ids_right_before_a_write_apply_it(drone):
    drone.handle_at_datagram(at(ids_cmd(1, IDS) + 'AT*CONFIG=2,"control:control_vz_max","700"\n'))
    assert drone.plant.params.control_vz_max_mps == pytest.approx(0.7)
    assert float(drone.config_held["control:control_vz_max"]) == 700.0
    assert drone.counters.config_writes_ignored == 0


def test_a_client_switching_to_its_own_session_is_then_obeyed(drone):
    mine = ("11111111", "22222222", "33333333")
    for seq, key, value in ((1, "session_id", mine[0]), (3, "profile_id", mine[1]),
                            (5, "application_id", mine[2])):
        drone.handle_at_datagram(at(ids_cmd(seq, mine) + f'AT*CONFIG={seq + 1},"custom:{key}",'
                                                         f'"{value}"\n'))
    drone.handle_at_datagram(at(ids_cmd(7, mine) + 'AT*CONFIG=8,"control:euler_angle_max",'
                                                   '"0.2094"\n'))
    assert drone.plant.params.euler_angle_max_rad == pytest.approx(0.2094)
    assert drone.config_held["custom:session_id"] == mine[0]


def test_the_default_session_applies_plain_writes_and_reports_the_clamped_value():
    store = ConfigStore(plant(), altitude_max_m=3.0)
    assert not store.multiconfig
    assert store.write("control:euler_angle_max", "0.9")
    assert store.plant.params.euler_angle_max_rad == 0.52
    assert store.written["control:euler_angle_max"] == "0.9"
    assert store.held()["control:euler_angle_max"] == "0.5200"   # what it flies
    assert "control:euler_angle_max = 0.5200\n" in store.text()
    with pytest.raises(ValueError, match="not all 00000000"):
        HeldSession(("00000000",) * 3)


def test_the_foreign_session_fault_reaches_the_one_simulated_drone():
    cfg = load_config(None, ["faults.foreign_session.control_vz_max_mps=1.5"])
    schedule = FaultSchedule(cfg.faults)
    assert schedule.held_session().ids == IDS
    drone = SimulatedDrone.from_config(cfg)  # what simulate flies and fly --sim serves
    assert drone.firmware.config.active_ids == IDS
    p = drone.plant.params
    assert p.control_vz_max_mps == 1.5 and p.euler_angle_max_rad == 0.52
    assert load_config(None).faults.foreign_session is None
    with pytest.raises(ConfigError, match="session_id"):
        load_config(None, ["faults.foreign_session.session_id=xyz"])
