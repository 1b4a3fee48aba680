"""The loopback drone models what the tool now handles (issue 21), datagram by datagram through
an unstarted DroneServer on a fixed clock: fault bits in the state word, the VBAT_LOW level and
its take-off refusal, bootstrap after a link loss, a session that ignores plain CONFIG, the
indoor/outdoor profiles (ARDroneLib config_keys.h: ``control:outdoor`` selects the stored
``indoor_*`` / ``outdoor_*`` triple, limit writes go into the active one), a second AT client
under the one sequence rule, and the Wi-Fi blackout. Datagrams are typed by hand.
"""

from __future__ import annotations

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.protocol.navdata import DroneState, decode_navdata
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim.drone_config import ConfigStore, HeldSession, OutdoorProfiles
from ardrone_nmpc.sim.drone_server import DroneServer
from ardrone_nmpc.sim.fault_injection import ServerFaults
from ardrone_nmpc.sim.faults import FaultSchedule
from ardrone_nmpc.sim.plant import AirframePlant

IDS = ("d2e081a3", "be27e2e4", "d87f7e0c")
LAND, TAKEOFF, EMERGENCY = 290717696, 290718208, 290717952


def plant(*sets):
    cfg = load_config(None, list(sets))
    return AirframePlant.from_config(cfg.sim, cfg.drone, seed=1)


def at(text: str) -> bytes:
    return text.replace("\n", "\r").encode()


class Clock:
    def __init__(self):
        self.t = 50.0

    def __call__(self):
        return self.t


@pytest.fixture
def make():
    made = []

    def server(p=None, **kw):
        clock = Clock()
        srv = DroneServer(p or plant(), clock=clock, **kw)
        srv.clock = clock
        made.append(srv)
        return srv
    yield server
    for srv in made:
        srv.stop()


# ----------------------------------------------------------------------------- fault bits
def served(make, *sets):
    """The experiment's simulated drone (its faults from ``sets``) behind an unstarted server."""
    cfg = load_config(None, list(sets))
    drone = SimulatedDrone.from_config(cfg, seed=1)
    return make(drone.plant, drone=drone), drone


def test_injected_fault_bits_and_vbat_low_are_in_the_state_word(make):
    srv, _ = served(make, "faults.drone_faults.start_s=null",
                    "faults.drone_faults.bits=[CUTOUT,ULTRASOUND]")        # from power-on
    bits = srv.state_bits()
    assert DroneState.CUTOUT in bits and DroneState.ULTRASOUND in bits
    assert DroneState.VBAT_LOW not in bits and DroneState.MOTORS not in bits
    packet = decode_navdata(srv._packet(srv.clock()))          # on the wire too
    assert DroneState.CUTOUT in packet.state and DroneState.ULTRASOUND in packet.state


def test_the_vbat_low_level_sets_bit_15_and_refuses_the_take_off(make):
    srv, drone = served(make, "faults.vbat_low.threshold_pct=30")
    p = drone.plant
    p.set_battery_pct(25.0)             # above the tool's 20 % floor, below the firmware's 30
    assert DroneState.VBAT_LOW in srv.state_bits()
    srv.handle_at_datagram(at(f"AT*REF=1,{TAKEOFF}\n"))
    assert p.mode is FlightMode.LANDED                       # refused
    p.set_battery_pct(31.0)
    assert DroneState.VBAT_LOW not in srv.state_bits()
    srv.handle_at_datagram(at(f"AT*REF=2,{LAND}\nAT*REF=3,{TAKEOFF}\n"))
    assert p.mode is FlightMode.TAKING_OFF


def test_an_injected_vbat_low_refuses_the_take_off_whatever_the_charge(make):
    srv, drone = served(make)
    drone.firmware.fault_bits = int(DroneState.VBAT_LOW)
    srv.handle_at_datagram(at(f"AT*REF=1,{TAKEOFF}\n"))
    assert drone.plant.battery_pct == 100.0 and drone.plant.mode is FlightMode.LANDED


def test_fault_bits_start_at_their_time_with_an_event():
    cfg = load_config(None, ["faults.drone_faults.start_s=2",
                             "faults.drone_faults.bits=[SOFTWARE_FAULT,MOTORS]"])
    drone = SimulatedDrone.from_config(cfg, seed=1)
    drone.faults.set_clock(100.0)
    drone.update_faults(101.9)
    assert drone.take_events() == [] and drone.firmware.fault_bits == 0
    drone.update_faults(102.0)
    assert drone.take_events() == [(2.0, {"kind": "fault", "fault": "drone_faults",
                                          "bits": ["MOTORS", "SOFTWARE_FAULT"]})]
    assert drone.firmware.fault_bits == int(DroneState.SOFTWARE_FAULT | DroneState.MOTORS)
    state = drone.firmware.status(drone.plant.t_s).state_bits()
    assert DroneState.SOFTWARE_FAULT in state and DroneState.MOTORS in state


# ----------------------------------------------------------------------------- link loss
def test_after_a_link_loss_navdata_falls_back_to_bootstrap_until_demo_is_written(make):
    srv = make()
    srv.handle_at_datagram(at('AT*CONFIG=1,"general:navdata_demo","TRUE"\n'))
    assert not srv.bootstrap
    srv.clock.t += 2.5                    # no command for 2.5 s: the client "disconnected"
    srv._firmware.watchdogs(srv.clock())
    assert srv.bootstrap and srv.counters.link_losses == 1
    packet = decode_navdata(srv._packet(srv.clock()))
    assert DroneState.NAVDATA_BOOTSTRAP in packet.state and packet.demo is None
    assert DroneState.COM_LOST in packet.state
    srv.handle_at_datagram(at('AT*CONFIG=5,"general:navdata_demo","TRUE"\n'))  # SDK's answer
    assert not srv.bootstrap and decode_navdata(srv._packet(srv.clock())).demo is not None


def test_a_blackout_loses_commands_wake_ups_and_navdata_in_its_window():
    cfg = load_config(None, ["faults.blackout.start_s=1", "faults.blackout.duration_s=3"])
    faults = ServerFaults(FaultSchedule(cfg.faults))
    faults.set_clock(100.0)
    assert not faults.wakeup_lost(100.9) and not faults.at_lost(100.9)
    assert faults.wakeup_lost(101.0) and faults.at_lost(103.9)
    assert faults.navdata_lost(102.0)
    assert not faults.wakeup_lost(104.0) and not faults.navdata_lost(104.0)


# ----------------------------------------------------------------------------- sessions
def test_a_session_that_ignores_plain_config_does_not_even_acknowledge_it(make):
    srv = make(session=HeldSession(IDS, ignores_plain_config=True))
    srv.handle_at_datagram(at('AT*CONFIG=1,"general:navdata_demo","TRUE"\n'))
    assert DroneState.COMMAND not in srv.state_bits() and srv.bootstrap
    assert srv.counters.config_writes_unacknowledged == 1
    ids = f'AT*CONFIG_IDS=2,"{IDS[0]}","{IDS[1]}","{IDS[2]}"\n'
    srv.handle_at_datagram(at(ids + 'AT*CONFIG=3,"general:navdata_demo","TRUE"\n'))
    assert DroneState.COMMAND in srv.state_bits() and not srv.bootstrap
    lenient = make(session=HeldSession(IDS))    # the other reading: acknowledged, not applied
    lenient.handle_at_datagram(at('AT*CONFIG=1,"control:euler_angle_max","0.2"\n'))
    assert DroneState.COMMAND in lenient.state_bits()
    assert lenient.plant.params.euler_angle_max_rad == 0.52


def test_the_strict_session_fault_refuses_the_lockstep_take_off():
    from ardrone_nmpc.runtime.lockstep import TakeoffRefused, run_lockstep

    cfg = load_config(None, ["duration_s=1", "faults.foreign_session.ignores_plain_config=true"])
    with pytest.raises(TakeoffRefused, match=r"config general:navdata_demo='TRUE': no ACK from "
                                             r"the drone .*set drone.config_ids"):
        run_lockstep(cfg)
    ok = load_config(None, ["duration_s=1", "faults.foreign_session.ignores_plain_config=true",
                            f"drone.config_ids=[{','.join(IDS)}]"])
    assert run_lockstep(ok).ending == "completed"


# ----------------------------------------------------------------------------- profiles
OUTDOORS = OutdoorProfiles(indoor=(0.25, 0.8, 2.0), outdoor=(0.35, 1.0, 3.49))
WRITTEN = {"control:euler_angle_max": "0.2094", "control:control_vz_max": "700",
           "control:control_yaw": "1.745"}


def test_a_drone_last_flown_outdoors_flies_its_outdoor_profile():
    store = ConfigStore(plant(), altitude_max_m=3.0, outdoor=OUTDOORS)
    held = store.held()
    assert held["control:outdoor"] == "TRUE" and held["control:euler_angle_max"] == "0.3500"
    assert float(held["control:indoor_euler_angle_max"]) == 0.25


def test_limits_written_before_outdoor_false_are_lost_and_overwrite_the_outdoor_profile():
    store = ConfigStore(plant(), altitude_max_m=3.0, outdoor=OUTDOORS)
    for key, value in WRITTEN.items():                   # the old order: limits first …
        store.write(key, value)
    store.write("control:outdoor", "FALSE")             # … then the indoor triple is loaded
    held = store.held()
    assert held["control:euler_angle_max"] == "0.2500"  # not the 0.2094 written
    assert float(held["control:outdoor_euler_angle_max"]) == 0.2094  # the user's 0.35 gone


def test_outdoor_false_then_the_limits_keep_them_and_the_outdoor_profile():
    store = ConfigStore(plant(), altitude_max_m=3.0, outdoor=OUTDOORS)
    store.write("control:outdoor", "FALSE")             # the order the session writes
    for key, value in WRITTEN.items():
        store.write(key, value)
    held = store.held()
    assert held["control:euler_angle_max"] == "0.2094"
    assert float(held["control:control_vz_max"]) == 700.0
    assert float(held["control:indoor_euler_angle_max"]) == 0.2094
    assert float(held["control:outdoor_euler_angle_max"]) == 0.35   # untouched
    store.write("control:outdoor_control_yaw", "3.0")   # the inactive profile: stored only
    assert store.plant.params.control_yaw_radps == pytest.approx(1.745)
    store.write("control:outdoor", "TRUE")
    assert store.plant.params.control_yaw_radps == pytest.approx(3.0)


def test_the_outdoor_profile_fault_flies_in_lockstep_with_the_written_limits():
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    events = []

    class Rec:
        path = None

        def write_row(self, row):
            pass

        def event(self, t, kind, **fields):
            events.append((kind, fields))
    cfg = load_config(None, ["duration_s=1", "faults.outdoor_profile.euler_angle_max_rad=0.4"])
    assert run_lockstep(cfg, recorder=Rec()).ending == "completed"
    read = dict(events)["config_read"]
    assert read["control:euler_angle_max"] == "0.2094" and read["control:outdoor"] == "FALSE"


# ----------------------------------------------------------------------------- two clients
def test_a_second_client_counts_only_by_the_one_sequence_rule(make):
    """A `fly` at seq 5000 and an operator starting at 1: each datagram of the operator is
    taken (seq 1 restarts the counter), the fly's next command after it too (above 2)."""
    srv = make()
    srv.handle_at_datagram(at(f"AT*REF=4999,{LAND}\nAT*PCMD=5000,0,0,0,0,0\n"))
    srv.handle_at_datagram(at("AT*PCMD=2,1,0,0,0,0\n"))           # a plain second client
    assert srv.counters.at_commands_stale == 1
    srv.handle_at_datagram(at(f"AT*REF=1,{EMERGENCY}\nAT*PCMD=2,0,0,0,0,0\n"))  # self-contained
    assert srv.counters.at_commands_stale == 1 and srv.plant.mode is FlightMode.EMERGENCY
    srv.handle_at_datagram(at("AT*PCMD=5001,0,0,0,0,0\n"))
    assert srv.counters.at_commands_stale == 1


# ----------------------------------------------------------------------------- lockstep
def test_the_lockstep_drone_answers_bootstrap_after_a_blackout_as_the_link_does():
    """A 3 s blackout: the firmware loses its client (2 s), its navdata restarts in bootstrap;
    the lockstep drone writes navdata_demo again at the first bootstrap packet it receives,
    and demo samples come back."""
    from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

    cfg = load_config(None, ["faults.blackout.start_s=1", "faults.blackout.duration_s=3"])
    drone = LockstepDrone(cfg, seed=1)
    drone.connect()
    drone.takeoff()
    t_zero = drone.truth.t_s
    drone.start_experiment(t_zero)
    period = cfg.loop.period_s
    fresh_after = []
    for k in range(int(6.0 / period)):
        t = t_zero + k * period
        drone.advance_to(t, t - t_zero)
        drone.hover()
        fresh_after.append((t - t_zero, t - drone.navdata_rx_t_s))
    assert drone.sim.counters.link_losses == 1 and drone.bootstrap_answers >= 1
    assert not drone.sim.firmware.config.bootstrap                 # demo again
    assert max(age for t, age in fresh_after if 1.2 < t < 3.9) > 2.0  # nothing in the blackout
    assert all(age < 0.2 for t, age in fresh_after if t > 4.5)      # samples came back


def test_the_lockstep_run_refuses_a_drone_reporting_a_fault_bit_and_cuts_a_motor_fault():
    from ardrone_nmpc.runtime.lockstep import TakeoffRefused, run_lockstep

    at_power_on = load_config(None, ["duration_s=1", "faults.drone_faults.start_s=null",
                                     "faults.drone_faults.bits=[ULTRASOUND]"])
    with pytest.raises(TakeoffRefused, match=r"^the drone reports ULTRASOUND \(state bit 21"):
        run_lockstep(at_power_on)
    in_flight = load_config(None, ["duration_s=2", "faults.drone_faults.start_s=1",
                                   "faults.drone_faults.bits=[MOTORS]"])
    result = run_lockstep(in_flight)
    assert result.ending == "stop-motors" and result.final_mode is FlightMode.EMERGENCY
