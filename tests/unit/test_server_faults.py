"""The loopback servers' fault decisions (ardrone_nmpc.sim.fault_injection), without sockets:
the experiment clock, which datagrams go out for a navdata packet or a mocap frame, AT loss,
and the plant faults."""

import math

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.sim.faults import FaultSchedule
from ardrone_nmpc.protocol.navdata import NavdataError, decode_navdata
from ardrone_nmpc.sim.faults import Disorder
from ardrone_nmpc.sim.fault_injection import NO_MOCAP_FAULT, ServerFaults
from ardrone_nmpc.sim.plant import AirframePlant
from tests.standins.navdata_packets import plain_packet

NOW = 1000.0  # a monotonic time (s); experiment time 0 is set to it where the clock is set


def server_faults(*overrides, plant=None, seed=0, clock_set=True) -> ServerFaults:
    cfg = load_config(None, list(overrides))
    faults = ServerFaults(FaultSchedule(cfg.faults, seed), plant)
    if clock_set:
        faults.set_clock(NOW)
    return faults


def packet(seq=5) -> bytes:
    cfg = load_config(None)
    return plain_packet(AirframePlant.from_config(cfg.sim, cfg.drone), seq)


# ----------------------------------------------------------------------------- disorder
def test_disorder_holds_one_back_behind_the_next_and_duplicates():
    d = Disorder()
    assert d(b"1", duplicate=False, hold=True) == [] and d.holding
    assert d(b"2", duplicate=False, hold=True) == [b"2", b"1"]  # released: no second hold
    assert not d.holding
    assert d(b"3", duplicate=True, hold=False) == [b"3", b"3"]
    assert d(b"4", duplicate=True, hold=True) == [b"4"] and d.holding  # the copy goes now
    assert d(b"5", duplicate=False, hold=False) == [b"5", b"4"]


# ----------------------------------------------------------------------------- the clock
def test_no_window_fault_acts_before_the_clock_is_set():
    args = ["faults.mocap_dropout.start_s=-1e6", "faults.mocap_dropout.duration_s=1e7",
            "faults.navdata_loss.start_s=-1e6", "faults.navdata_loss.duration_s=1e7",
            "faults.at_loss.start_s=-1e6", "faults.at_loss.duration_s=1e7"]
    faults = server_faults(*args, clock_set=False)
    assert faults.t_exp(NOW) == -math.inf
    assert not faults.mocap_frame(NOW).dropped
    assert not faults.navdata_lost(NOW)
    assert faults.navdata_datagrams(NOW, b"x") == [b"x"]
    assert not faults.at_lost(NOW)
    faults.set_clock(NOW - 2.0)
    assert faults.t_exp(NOW) == pytest.approx(2.0)
    assert faults.mocap_frame(NOW).dropped
    assert faults.navdata_lost(NOW)
    assert faults.at_lost(NOW)
    c = faults.counters
    assert (c.mocap_dropped, c.navdata_lost, c.at_lost) == (1, 1, 1)


# ----------------------------------------------------------------------------- navdata
@pytest.mark.parametrize("kind", ["checksum", "truncated", "zero_option"])
def test_navdata_corrupted_in_its_window_only(kind):
    faults = server_faults("faults.navdata_corrupt.start_s=1",
                           "faults.navdata_corrupt.duration_s=0.5",
                           f"faults.navdata_corrupt.kind={kind}")
    clean = packet()
    assert faults.navdata_datagrams(NOW + 0.99, clean) == [clean]
    (bad,) = faults.navdata_datagrams(NOW + 1.2, clean)
    with pytest.raises(NavdataError):
        decode_navdata(bad)
    assert faults.navdata_datagrams(NOW + 1.5, clean) == [clean]
    assert faults.counters.navdata_corrupted == 1


def test_navdata_reordered_and_duplicated_only_on_its_stream():
    faults = server_faults("faults.disorder.stream=navdata", "faults.disorder.start_s=0",
                           "faults.disorder.duration_s=1", "faults.disorder.reorder_probability=1",
                           "faults.disorder.duplicate_probability=0")
    out = [faults.navdata_datagrams(NOW + 0.1 * i, bytes([i])) for i in range(4)]
    assert out == [[], [b"\x01", b"\x00"], [], [b"\x03", b"\x02"]]
    assert faults.mocap_datagrams(NOW + 0.1, b"m") == [b"m"]  # the other stream is untouched
    assert faults.navdata_datagrams(NOW + 1.0, b"z") == [b"z"]  # window over
    assert faults.counters.reordered == 2 and faults.counters.duplicated == 0


# ----------------------------------------------------------------------------- mocap
def test_mocap_frame_faults_by_sampling_time():
    faults = server_faults("faults.mocap_occlusion.start_s=1",
                           "faults.mocap_occlusion.duration_s=1",
                           "faults.mocap_occlusion.zero_pose=true",
                           "faults.mocap_latency.start_s=1.5", "faults.mocap_latency.duration_s=1",
                           "faults.mocap_latency.extra_latency_ms=150")
    f = [faults.mocap_frame(NOW + t) for t in (0.5, 1.2, 1.7, 2.2, 2.6)]
    assert [x.occlusion for x in f] == [None, "zero", "zero", None, None]
    assert [x.extra_latency_s for x in f] == pytest.approx([0, 0, 0.15, 0.15, 0])
    assert not any(x.dropped for x in f)
    c = faults.counters
    assert (c.mocap_occluded, c.mocap_delayed) == (2, 2)


def test_mocap_duplicates_with_certainty():
    faults = server_faults("faults.disorder.start_s=0", "faults.disorder.duration_s=1",
                           "faults.disorder.reorder_probability=0",
                           "faults.disorder.duplicate_probability=1")
    assert faults.mocap_datagrams(NOW + 0.5, b"m") == [b"m", b"m"]
    assert faults.counters.duplicated == 1


# ----------------------------------------------------------------------------- AT + plant
def test_at_loss_draws_with_the_configured_probability():
    faults = server_faults("faults.at_loss.start_s=0", "faults.at_loss.duration_s=100",
                           "faults.at_loss.probability=0.5", seed=7)
    lost = [faults.at_lost(NOW + 0.01 * i) for i in range(2000)]
    assert 0.4 < np.mean(lost) < 0.6
    assert faults.counters.at_lost == sum(lost)
    assert not faults.at_lost(NOW + 100.0)


def test_plant_faults_follow_the_experiment_clock():
    cfg = load_config(None)
    plant = AirframePlant.from_config(cfg.sim, cfg.drone)
    faults = server_faults("faults.battery_floor.start_s=2", "faults.battery_floor.level_pct=19",
                           "faults.wind.velocity_mps=[0.5,0,0]",
                           "faults.wind_gust.start_s=1", "faults.wind_gust.duration_s=1",
                           "faults.wind_gust.velocity_mps=[0,1,0]", plant=plant, clock_set=False)
    assert faults.update_plant(NOW) == []  # before the clock: only the constant wind
    np.testing.assert_allclose(plant.wind_mps, [0.5, 0, 0])
    assert plant.battery_pct == 100.0
    faults.set_clock(NOW)
    faults.update_plant(NOW + 1.5)
    np.testing.assert_allclose(plant.wind_mps, [0.5, 1, 0])
    faults.update_plant(NOW + 2.5)
    assert plant.battery_pct == pytest.approx(19.0)
    np.testing.assert_allclose(plant.wind_mps, [0.5, 0, 0])
    events = [(t, ev["fault"], ev.get("on")) for t, ev in faults.events]
    assert events == [(1.5, "wind_gust", True), (2.5, "battery_floor", None),
                      (2.5, "wind_gust", False)]


# ----------------------------------------------------------------------------- firmware faults
def test_self_land_lands_a_flying_drone_at_its_time():
    from ardrone_nmpc.core.types import FlightMode

    cfg = load_config(None)
    plant = AirframePlant.from_config(cfg.sim, cfg.drone)
    plant.takeoff()
    while plant.mode is not FlightMode.FLYING:
        plant.advance(0.05)
    faults = server_faults("faults.self_land.start_s=3", plant=plant)
    assert faults.update_plant(NOW + 2.9) == [] and plant.mode is FlightMode.FLYING
    assert faults.update_plant(NOW + 3.0) == [{"kind": "fault", "fault": "self_land",
                                               "accepted": True}]
    assert plant.mode is FlightMode.LANDING          # through landing, not a motor cut
    while plant.mode is FlightMode.LANDING:
        plant.advance(0.05)
    assert plant.mode is FlightMode.LANDED and plant.truth.position_m[2] == 0.0
    assert faults.update_plant(NOW + 4.0) == []      # once


@pytest.mark.parametrize("overrides, codes, port", [
    ([], "sdk", "serve"),
    (["faults.ctrl_codes.codes=fw2.4"], "fw2.4", "serve"),
    (["faults.control_port_drop.mode=silent"], "sdk", "silent"),
    (["faults.control_port_drop.mode=refused"], "sdk", "refused"),
])
def test_firmware_fault_options(overrides, codes, port):
    cfg = load_config(None, overrides)
    schedule = FaultSchedule(cfg.faults)
    assert schedule.ctrl_codes().value == codes
    assert schedule.control_port_mode() == port
    assert schedule.held_session() is None
    assert schedule.touches_sensors is (codes != "sdk")   # the lockstep goes through the bytes


def test_wire_sensors_report_the_configured_codes_in_transitions():
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

    majors = {}
    for codes in ("sdk", "fw2.4"):
        cfg = load_config(None, [f"faults.ctrl_codes.codes={codes}"])
        drone = LockstepDrone(cfg)
        assert drone.sensors.wire                       # the codes are in the bytes
        seen = []
        drone.sensors.on_navdata = lambda state, major: seen.append(major)
        drone.connect()
        drone.takeoff()
        while drone.truth.mode is not FlightMode.FLYING:
            drone.advance_to(drone.truth.t_s + 0.1)
        takeoff_major = seen[0]
        drone.land()
        drone.advance_to(drone.truth.t_s + 0.1)
        majors[codes] = (takeoff_major, seen[-1])
        assert drone.navdata.mode is FlightMode.LANDING  # the client reads both codes alike
    assert majors == {"sdk": (6, 8), "fw2.4": (7, 9)}


# ----------------------------------------------------------------------------- quiet spans
class _RecordingPlant:
    """The plant calls the plant faults make, recorded (what acted), and the wind set."""

    def __init__(self) -> None:
        self.calls: list[str] = []
        self.wind_mps = np.zeros(3)

    def set_battery_pct(self, value) -> None:
        self.calls.append("battery")

    def emergency(self) -> None:
        self.calls.append("emergency")

    def set_command_delay_s(self, value) -> None:
        self.calls.append("delay")

    def land(self) -> bool:
        self.calls.append("land")
        return True


QUIET_CASES = {
    "plant": ("faults.battery_floor.start_s=-0.5", "faults.delay_jump.start_s=3",
              "faults.at_loss.start_s=6", "faults.at_loss.duration_s=0.2",
              "faults.at_loss.probability=0.5", "faults.wind_gust.start_s=8.0013",
              "faults.wind_gust.duration_s=0.0005", "faults.wind.velocity_mps=[0.4,0.1,0]"),
    "sensors": ("faults.mocap_dropout.start_s=2", "faults.mocap_dropout.duration_s=0.5",
                "faults.mocap_dropout.repeat_every_s=3", "faults.navdata_corrupt.start_s=1",
                "faults.disorder.start_s=0.5", "faults.disorder.stream=mocap",
                "faults.blackout.start_s=-1", "faults.blackout.duration_s=0.2"),
    "one_shots": ("faults.emergency.start_s=1", "faults.self_land.start_s=2",
                  "faults.drone_faults.start_s=3", "faults.mocap_latency.start_s=4",
                  "faults.mocap_occlusion.start_s=5", "faults.navdata_loss.start_s=6",
                  "faults.solver_diverge.start_s=7", "faults.wind_gust.start_s=8"),
    "flight_wide": ("faults.wind.velocity_mps=[0.4,0.1,0]",
                    "faults.outdoor_profile.euler_angle_max_rad=0.35",
                    "faults.ctrl_codes.codes=fw2.4", "faults.drone_faults.start_s=null"),
}


def _acts(faults: ServerFaults, plant: _RecordingPlant, t: float, wind) -> bool:
    """Every decision the drone asks at ``t`` (and the plant faults due): whether any
    differs from a fault-free drone's — or drew, counted or announced something."""
    rng_state, counters = faults.schedule.rng.bit_generator.state, faults.counters
    calls = len(plant.calls)
    acted = [faults.at_loss_acts(t), faults.at_lost(t), faults.wakeup_lost(t),
             faults.navdata_lost(t), faults.navdata_datagrams(t, b"nav") != [b"nav"],
             faults.mocap_frame(t) != NO_MOCAP_FAULT,
             faults.mocap_datagrams(t, b"mocap") != [b"mocap"],
             faults.schedule.solver_diverges(t), bool(faults.update_plant(t)),
             len(plant.calls) != calls, not np.array_equal(plant.wind_mps, wind),
             faults.schedule.rng.bit_generator.state != rng_state,
             faults.counters != counters]
    return any(acted)


@pytest.mark.parametrize("name", list(QUIET_CASES))
def test_no_fault_acts_before_quiet_until(name):
    """On a fine grid of times (every decision asked at each, the plant faults updated as
    the ticks would): nothing acts at a time before the answer of ``quiet_until_s`` asked
    at an earlier one, and where something acts, the answer asked there says so."""
    plant = _RecordingPlant()
    faults = server_faults(*QUIET_CASES[name], plant=plant)
    faults.set_clock(0.0)  # (the lockstep drone's: its clock is experiment time)
    wind = faults.schedule.wind_mps(-math.inf)
    plant.wind_mps = wind.copy()
    bound, quiet, acting = -math.inf, 0, 0
    for i in range(-2000, 12000):
        t = i * 1e-3
        if not t < bound:  # (asked again once reached, as the blocks ask)
            bound = faults.quiet_until_s(t)
        acted = _acts(faults, plant, t, wind)
        assert not (acted and t < bound), f"{name}: a fault acts at {t} before {bound}"
        quiet += t < bound
        acting += acted
    if name == "flight_wide":
        assert bound == math.inf and quiet == 14000 and not acting
    else:
        assert quiet > 1000 and acting > 0


@pytest.mark.parametrize("name", list(QUIET_CASES))
def test_with_the_bursts_asked_no_fault_but_a_dropout_acts_before_quiet_until(name):
    """``quiet_until_s(…, bursts_asked=True)`` (the lockstep's quiet wire ticks, which ask
    ``mocap_dropped`` of every frame): before its answer nothing acts where the schedule
    drops no frame — and a repeated dropout's bursts no longer end the quiet for good."""
    plant = _RecordingPlant()
    faults = server_faults(*QUIET_CASES[name], plant=plant)
    faults.set_clock(0.0)
    wind = faults.schedule.wind_mps(-math.inf)
    plant.wind_mps = wind.copy()
    bound, quiet, quiet_all = -math.inf, 0, 0
    for i in range(-2000, 12000):
        t = i * 1e-3
        if not t < bound:
            bound = faults.quiet_until_s(t, bursts_asked=True)
        quiet += t < faults.quiet_until_s(t, bursts_asked=True)  # (asked now, both ways)
        quiet_all += t < faults.quiet_until_s(t)
        dropped = faults.schedule.mocap_dropped(t)
        acted = _acts(faults, plant, t, wind)
        assert not (acted and t < bound and not dropped), f"{name}: acts at {t}"
    if name == "sensors":  # the bursts every 3 s: quiet between them, after the first too
        assert quiet > quiet_all + 3000
    else:
        assert quiet == quiet_all
