"""Fault injection: the schedule, the byte corruptions, the plant faults, and every fault of the
matrix flown end to end in lockstep with the outcome and event it must produce."""

import math
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.faultmatrix import (FAULT_CASES, REQUIRED_OUTCOME, classify,
                                                  deviation_from, log_complete, recovery_time_s)
from ardrone_nmpc.sim.faults import FaultSchedule, corrupt_navdata
from ardrone_nmpc.protocol.navdata import NavdataError, decode_navdata
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.runtime.lockstep import REFUSED_EVENT, TakeoffRefused, run_lockstep
from ardrone_nmpc.runs.summary import summarise
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone
from tests.standins.navdata_packets import plain_packet

CONFIGS = Path(__file__).parents[2] / "configs"
SHORT = ["duration_s=5", "sim.settle_s=1"]


def flying_plant(cfg, seed=0) -> AirframePlant:
    plant = AirframePlant.from_config(cfg.sim, cfg.drone, seed=seed)
    plant.takeoff()
    while plant.mode is not FlightMode.FLYING:
        plant.advance(0.05)
    return plant


# ----------------------------------------------------------------------------- bytes
@pytest.mark.parametrize("kind, message", [
    ("checksum", "checksum mismatch"), ("truncated", r"overruns|no checksum|shorter"),
    ("zero_option", "invalid size 0")])
def test_each_corruption_is_rejected_by_the_decoder(kind, message):
    cfg = load_config(None)
    data = plain_packet(flying_plant(cfg), 7)
    assert decode_navdata(data).sequence == 7  # the clean packet decodes
    with pytest.raises(NavdataError, match=message):
        decode_navdata(corrupt_navdata(data, kind))
    with pytest.raises(ValueError, match="unknown navdata corruption"):
        corrupt_navdata(data, "scrambled")


# ----------------------------------------------------------------------------- schedule
def test_schedule_windows_and_repeats():
    cfg = load_config(None, ["faults.mocap_dropout.start_s=2", "faults.mocap_dropout.duration_s=0.5",
                             "faults.mocap_dropout.repeat_every_s=3",
                             "faults.wind_gust.start_s=1", "faults.wind_gust.duration_s=1",
                             "faults.wind.velocity_mps=[0.5,0,0]"])
    s = FaultSchedule(cfg.faults)
    assert [s.mocap_dropped(t) for t in (1.99, 2.0, 2.49, 2.5, 5.1, 5.6, 8.2)] == \
        [False, True, True, False, True, False, True]
    np.testing.assert_allclose(s.wind_mps(-math.inf), [0.5, 0, 0])
    np.testing.assert_allclose(s.wind_mps(1.5), [2.0, 0, 0])  # gust (1.5) on top of the wind
    np.testing.assert_allclose(s.wind_mps(2.0), [0.5, 0, 0])
    assert not s.navdata_lost(3.0) and s.touches_sensors


def test_disorder_draws_are_seeded():
    cfg = load_config(None, ["faults.disorder.start_s=0", "faults.disorder.duration_s=10"])
    schedules = [FaultSchedule(cfg.faults, seed) for seed in (3, 3, 4)]
    draws = [[s.disorder("mocap", 1.0) for _ in range(20)] for s in schedules]
    assert draws[0] == draws[1] != draws[2]
    assert FaultSchedule(cfg.faults, 3).disorder("navdata", 1.0) == (False, False)


# ----------------------------------------------------------------------------- plant faults
def test_command_delay_jump_delays_the_response():
    """A roll command reaches the tilt loop command_delay_s later; after the jump, later."""
    cfg = load_config(None)

    def response_time_s(delay_s):
        plant = flying_plant(cfg)
        if delay_s is not None:
            plant.set_command_delay_s(delay_s)
        t0 = plant.t_s
        plant.command(1.0, 0.0, 0.0, 0.0)
        while abs(plant.truth.roll_rad) < 1e-3:
            plant.advance(0.005)
        return plant.t_s - t0

    base = response_time_s(None)
    assert base == pytest.approx(cfg.sim.plant.command_delay_s, abs=0.02)
    assert response_time_s(0.6) == pytest.approx(0.6, abs=0.02)
    assert response_time_s(0.0) < 0.02
    with pytest.raises(ValueError, match="delay_s"):
        flying_plant(cfg).set_command_delay_s(-1.0)


def test_battery_fault_and_takeoff_refusal(tmp_path):
    cfg = load_config(None)
    plant = flying_plant(cfg)
    plant.set_battery_pct(10.0)
    assert plant.navdata().battery_pct == 10.0
    with pytest.raises(ValueError, match="level_pct"):
        plant.set_battery_pct(101.0)
    low = load_config(CONFIGS / "hover.yaml", ["sim.plant.battery_start_pct=15", *SHORT])
    with pytest.raises(TakeoffRefused, match="battery 15 % is at or below the floor"):
        run_lockstep(low)


# ----------------------------------------------------------------------------- wire sensors
def test_wire_sensors_reject_duplicates_and_reordered_frames():
    cfg = load_config(None, ["faults.disorder.start_s=-100", "faults.disorder.duration_s=1000",
                             "faults.disorder.duplicate_probability=0.5",
                             "faults.disorder.reorder_probability=0.5"])
    drone = LockstepDrone(cfg, seed=1)
    drone.connect()
    drone.start_experiment(0.0)
    drone.takeoff()
    sensors = drone.sensors
    times = []
    for k in range(1, 60):
        drone.advance_to(drone.truth.t_s + 0.065)
        pose, rx = sensors.mocap.latest()
        times.append(pose.t_s)
    stats = sensors.mocap.stats
    assert stats.out_of_order > 10  # duplicates and overtaken frames were seen …
    assert np.all(np.diff(times) > 0)  # … and none of them became the newest pose


def test_wire_sensors_track_the_direct_sensors():
    """A clean run through the bytes flies like the direct one (noise drawn in another order)."""
    base = load_config(CONFIGS / "step_x.yaml", SHORT)
    wire = load_config(CONFIGS / "step_x.yaml", [*SHORT, "faults.disorder.start_s=100"])
    runs = []
    for cfg in (base, wire):
        rows = []

        class Rec:
            path = None
            write_row = rows.append

            def event(self, *a, **k):
                pass
        run_lockstep(cfg, recorder=Rec())
        runs.append(np.array([[r["x_true_m"], r["z_true_m"]] for r in rows]))
    assert runs[0].shape == runs[1].shape
    np.testing.assert_allclose(runs[1], runs[0], atol=0.03)
    assert runs[0][-1, 0] == pytest.approx(-1.5, abs=0.05)


# ----------------------------------------------------------------------------- end to end
#: fault → (expected ending, a mode/fault/stop event that must appear (kind, key, value))
EXPECTED = {
    "mocap_dropout_bursts": ("completed", ("mode", "reason", "stale-mocap")),
    "mocap_lost": ("land-mocap-lost", ("mode", "mode", "land-mocap-lost")),
    "mocap_occlusion": ("completed", ("mode", "reason", "stale-mocap")),
    "mocap_latency_spike": ("completed", ("mode", "mode", "hold-stale-mocap")),
    "navdata_loss": ("land-navdata-lost", ("mode", "mode", "land-navdata-lost")),
    "navdata_bad_checksum": ("completed", ("faults", None, None)),
    "navdata_truncated": ("completed", ("faults", None, None)),
    "navdata_zero_option": ("completed", ("faults", None, None)),
    "mocap_dup_reorder": ("completed", ("faults", None, None)),
    "navdata_dup_reorder": ("completed", ("faults", None, None)),
    "at_loss": ("completed", ("faults", None, None)),
    "solver_diverge": ("completed", ("mode", "mode", "fallback-solver")),
    "battery_floor": ("land-battery", ("mode", "mode", "land-battery")),
    "emergency": ("stop-emergency", ("stopped", "reason", "stop-emergency")),
    "wind_gust": ("completed", ("fault", "fault", "wind_gust")),
    "wind_constant": ("completed", ("faults", None, None)),
    "delay_jump": ("completed", ("fault", "fault", "delay_jump")),
    "ctrl_codes_fw24": ("completed", ("faults", None, None)),
    "cutout": ("stop-cutout", ("emergency", "reason", "stop-cutout")),
    "motors": ("stop-motors", ("stopped", "reason", "stop-motors")),
    "software_fault": ("land-software-fault", ("mode", "mode", "land-software-fault")),
    "vbat_low_threshold": ("land-vbat-low", ("mode", "mode", "land-vbat-low")),
    "blackout": ("land-navdata-lost", ("mode", "mode", "land-navdata-lost")),
    "outdoor_profile": ("completed", ("config_read", "control:euler_angle_max", "0.2094")),
}
#: Rows the pre-flight check refuses (nothing flies), and the row that lands by itself.
REFUSED = {"foreign_session", "control_port_silent", "faults_at_power_on",
           "vbat_low_at_power_on", "session_ignores_config"}
SELF_LANDED = {"self_land"}


def fly(tmp_path, fault, experiment="hover.yaml"):
    overrides = [*SHORT, *(FAULT_CASES[fault] if fault else ())]
    cfg = load_config(CONFIGS / experiment, overrides)
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        result = run_lockstep(cfg, recorder=rec)
    rec.write_summary(summarise(read_run(rec.path)))
    return result, read_run(rec.path)


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    return fly(tmp_path_factory.mktemp("base"), None)[1]


def test_matrix_covers_every_fault_kind():
    from ardrone_nmpc.config.schema import FaultsConfig

    covered = {name for overrides in FAULT_CASES.values() for o in overrides
               for name in [o.split(".")[1]]}
    assert covered == set(FaultsConfig.model_fields)
    special = REFUSED | SELF_LANDED
    assert set(EXPECTED) | special == set(FAULT_CASES) and not set(EXPECTED) & special
    assert special <= set(REQUIRED_OUTCOME) <= set(FAULT_CASES)


@pytest.mark.parametrize("fault", sorted(set(FAULT_CASES) - REFUSED - SELF_LANDED))
def test_each_fault_ends_by_policy_with_a_complete_log(tmp_path, baseline, fault):
    result, run = fly(tmp_path, fault)
    ending, (kind, key, value) = EXPECTED[fault]
    assert result.ending == ending
    assert any(e["kind"] == kind and (key is None or e.get(key) == value) for e in run.events), \
        [e for e in run.events if e["kind"] != "mode"]
    complete, why = log_complete(run.path, result.ticks)
    assert complete, why
    cmds = np.column_stack([run.columns[c] for c in ("cmd_roll_frac", "cmd_pitch_frac",
                                                     "cmd_gaz_frac", "cmd_yaw_frac")])
    assert np.all(np.isfinite(cmds))
    outcome = classify(run, result.ending, fault)
    assert outcome == ("completed" if ending == "completed" else
                       "stopped" if ending.startswith("stop") else "landed")
    if ending.startswith("land"):
        assert result.final_mode is FlightMode.LANDED
        assert run.columns["mode"][-1] == "landing"  # the descent is in the log


def test_sensor_faults_show_in_the_logged_ages(tmp_path):
    _, run = fly(tmp_path, "navdata_bad_checksum")
    assert np.nanmax(run.columns["navdata_age_ms"]) > 250  # 0.3 s of packets rejected
    _, run = fly(tmp_path, "mocap_latency_spike")
    ages = run.columns["mocap_age_ms"]
    assert np.nanmax(ages) > 150 and np.nanmedian(ages) < 20


def test_solver_divergence_is_never_flown(tmp_path):
    _, run = fly(tmp_path, "solver_diverge")
    status, mode = run.columns["solver_status"], run.columns["mode"]
    diverged = status == "diverged"
    assert diverged.sum() >= 10  # 1 s of forced divergence
    assert set(mode[diverged]) <= {"hold-solver", "fallback-solver"}
    assert np.all(np.isfinite(run.columns["cmd_pitch_frac"][diverged]))


def test_wind_pushes_and_the_deviation_metrics(tmp_path, baseline):
    _, run = fly(tmp_path, "wind_gust")
    t, dev = deviation_from(run, baseline)
    assert dev.max() > 0.1  # the gust moved it
    assert recovery_time_s(t, dev, 2.0) < 3.0  # and it came back
    assert recovery_time_s(np.array([0.0, 1.0]), np.array([0.2, 0.2]), 0.0) != \
        recovery_time_s(np.array([0.0, 1.0]), np.array([0.2, 0.05]), 0.0)


def test_summary_counts_the_supervisor_verdicts(tmp_path):
    from ardrone_nmpc.runs.summary import read_summary

    _, run = fly(tmp_path, "solver_diverge")
    figures = {(r.axis, r.metric): r.value for r in read_summary(run.path)}
    mode = list(run.columns["mode"])
    assert figures[("supervisor", "hold_ticks")] == mode.count("hold-solver") == 2
    assert figures[("supervisor", "fallback_ticks")] == mode.count("fallback-solver") > 10
    assert figures[("supervisor", "land_ticks")] == 0


# ----------------------------------------------------------------------------- firmware rows
def test_firmware_2_4_codes_change_no_flight(tmp_path, baseline):
    """7 / 9 instead of 6 / 8 in the transitions: the client reads them alike; the flight
    differs from the direct-sensor baseline only by the wire path's noise order."""
    result, run = fly(tmp_path, "ctrl_codes_fw24")
    assert result.ending == "completed"
    _, dev = deviation_from(run, baseline)
    assert dev.max() < 0.05


def refused_run(tmp_path, fault, *extra):
    """Fly ``fault`` expecting the refusal; (the refusal, the run directory read back)."""
    cfg = load_config(CONFIGS / "hover.yaml", [*SHORT, *FAULT_CASES[fault], *extra])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        with pytest.raises(TakeoffRefused) as refusal:
            run_lockstep(cfg, recorder=rec)
    return refusal.value, read_run(rec.path)


def assert_nothing_flew(run, fault):
    kinds = [e["kind"] for e in run.events]
    assert kinds[-1] == REFUSED_EVENT and "takeoff" not in kinds and run.n_rows == 0
    assert classify(run, "exception", fault) == "refused"
    assert log_complete(run.path, 0) == (True, "")


def test_lockstep_refuses_a_drone_that_holds_other_limits(tmp_path):
    err, run = refused_run(tmp_path, "foreign_session")
    assert "control:euler_angle_max" in str(err) and "'0.2094' written" in str(err)
    assert_nothing_flew(run, "foreign_session")
    # the session's own check: every limit the drone kept, with what it holds (0.52, 2000, 6.11)
    held = {e["key"]: float(e["held"]) for e in run.events if e["kind"] == "config_mismatch"}
    assert held == pytest.approx({"control:euler_angle_max": 0.52,
                                  "control:control_vz_max": 2000.0,
                                  "control:control_yaw": 6.11})


def test_lockstep_flies_a_foreign_session_it_writes_into(tmp_path):
    """With the drone's session ids (drone.config_ids) the writes apply: read back, verified,
    flown — so the refusal above is the check, not the fault itself."""
    cfg = load_config(CONFIGS / "hover.yaml", [*SHORT, *FAULT_CASES["foreign_session"],
                                               "drone.config_ids=[d2e081a3,be27e2e4,d87f7e0c]"])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        result = run_lockstep(cfg, recorder=rec)
    run = read_run(rec.path)
    read = next(e for e in run.events if e["kind"] == "config_read")
    assert float(read["control:euler_angle_max"]) == pytest.approx(0.2094, abs=1e-4)
    assert result.ending == "completed"


def test_lockstep_refuses_without_a_configuration_read_back(tmp_path):
    err, run = refused_run(tmp_path, "control_port_silent")
    assert "control port" in str(err) and "drone.verify_config: false" in str(err)
    assert_nothing_flew(run, "control_port_silent")


def test_unverified_limits_fly_with_a_warning_when_asked(tmp_path):
    cfg = load_config(CONFIGS / "hover.yaml", [*SHORT, *FAULT_CASES["control_port_silent"],
                                               "drone.verify_config=false"])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        result = run_lockstep(cfg, recorder=rec)
    kinds = [e["kind"] for e in read_run(rec.path).events]
    assert result.ending == "completed"
    assert kinds.index("config_unverified") < kinds.index("takeoff")


def test_lockstep_stops_when_the_drone_lands_by_itself(tmp_path):
    result, run = fly(tmp_path, "self_land")
    assert result.ending == "land-drone-landed-itself"
    assert classify(run, result.ending, "self_land") in REQUIRED_OUTCOME["self_land"]
    complete, why = log_complete(run.path, result.ticks)
    assert complete, why
    kinds = [e["kind"] for e in run.events]
    assert kinds.count("takeoff") == 1                      # never launched again
    landed_itself = next(e for e in run.events if e["kind"] == "drone_landed_itself")
    assert 2.0 <= landed_itself["t_s"] < 2.2                # the fault at 2 s, seen in navdata
    t, mode = run.columns["t_s"], run.columns["mode"]
    assert set(mode[t >= landed_itself["t_s"]]) == {"landing"}   # no tick flown after it
    assert result.final_mode is FlightMode.LANDED and run.columns["z_true_m"][-1] < 0.02


_DIRECT_IMPORTS = """
import sys
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone
run_lockstep(load_config(None, ["duration_s=0.5", "sim.settle_s=0"]))
udp = ("ardrone_nmpc.links.drone_link", "ardrone_nmpc.links.mocap_link",
       "ardrone_nmpc.sim.mocap_server", "ardrone_nmpc.sim.drone_server")
print(sorted(m for m in udp if m in sys.modules))
wired = LockstepDrone(load_config(None, ["faults.disorder.start_s=0",
                                         "faults.disorder.duration_s=1"]))
print(type(wired.sensors.mocap).__name__, sorted(m for m in udp if m in sys.modules))
"""


@pytest.mark.timeout(300)
def test_a_direct_run_imports_no_udp_link_and_a_wired_one_its_receiver():
    """The UDP links' and servers' modules are the wire sensors' only: a lockstep flight
    without sensor faults (a sweep's worker) does without their import; a wired drone has
    its mocap receiver."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _DIRECT_IMPORTS], capture_output=True,
                          text=True, timeout=240, check=True)
    direct, wired = done.stdout.splitlines()[-2:]
    assert direct == "[]"
    assert wired == "MocapLink ['ardrone_nmpc.links.mocap_link']"
