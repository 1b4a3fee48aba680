"""The supervisor's policies (ardrone_nmpc/safety.py), one condition at a time, and their order."""

import math

import numpy as np
import pytest

from ardrone_nmpc.config.schema import SafetyConfig
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.safety import Action, Decision, Supervisor
from ardrone_nmpc.core.types import FlightMode, NavdataSample

CFG = SafetyConfig()


def nav(mode=FlightMode.FLYING, battery=80.0, roll_deg=0.0, pitch_deg=0.0) -> NavdataSample:
    return NavdataSample(0.0, mode, battery, roll_deg, pitch_deg, 0.0, 1.0, 0.0, 0.0, 0.0)


def feedback(sup, mocap_ms=10.0, navdata_ms=30.0, navdata=None):
    return sup.check_feedback(mocap_age_ms=mocap_ms, navdata_age_ms=navdata_ms,
                              navdata=navdata or nav())


def state(x=0.0, y=0.0, z=1.0, vx=0.0, vy=0.0, vz=0.0):
    return np.array([x, vx, y, vy, z, vz, 0.0])


@pytest.mark.parametrize("mocap_ms, expected", [
    (CFG.mocap_hold_ms, Decision(Action.CONTROL)),
    (CFG.mocap_hold_ms + 1, Decision(Action.HOLD, "stale-mocap")),
    (CFG.mocap_hover_ms + 1, Decision(Action.HOVER, "stale-mocap")),
    (CFG.mocap_land_ms + 1, Decision(Action.LAND, "mocap-lost")),
    (math.inf, Decision(Action.LAND, "mocap-lost")),
])
def test_mocap_age_thresholds(mocap_ms, expected):
    assert feedback(Supervisor(CFG), mocap_ms=mocap_ms) == expected


def test_navdata_silence_battery_and_emergency_and_their_order():
    assert feedback(Supervisor(CFG), navdata_ms=CFG.navdata_land_ms + 1) == \
        Decision(Action.LAND, "navdata-lost")
    assert feedback(Supervisor(CFG), navdata_ms=math.nan).action is Action.LAND
    assert feedback(Supervisor(CFG), navdata=nav(battery=CFG.battery_floor_pct)) == \
        Decision(Action.LAND, "battery")
    assert feedback(Supervisor(CFG), navdata=nav(battery=CFG.battery_floor_pct + 1)).action \
        is Action.CONTROL
    # emergency outranks everything, even a lost mocap and an empty battery
    both = feedback(Supervisor(CFG), mocap_ms=math.inf,
                    navdata=nav(FlightMode.EMERGENCY, battery=0.0))
    assert both == Decision(Action.STOP, "emergency")


def test_land_and_stop_latch():
    sup = Supervisor(CFG)
    assert feedback(sup, mocap_ms=math.inf).action is Action.LAND
    assert feedback(sup).action is Action.LAND  # fresh data again: still landing
    assert sup.latched == Decision(Action.LAND, "mocap-lost")
    sup = Supervisor(CFG)
    feedback(sup, navdata=nav(FlightMode.EMERGENCY))
    assert feedback(sup).action is Action.STOP


def test_state_checks():
    sup = Supervisor(CFG)
    assert sup.check_state(state(), nav()).action is Action.CONTROL
    assert sup.check_state(state(x=math.nan), nav()) == Decision(Action.HOVER, "nonfinite-state")
    assert sup.check_state(state(vx=1.5, vy=1.5), nav()) == Decision(Action.HOVER, "speed")
    assert sup.check_state(state(vx=1.9), nav()).action is Action.CONTROL
    tilt_deg = math.degrees(CFG.max_tilt_rad) + 1
    assert sup.check_state(state(), nav(pitch_deg=-tilt_deg)) == Decision(Action.HOVER, "tilt")
    assert sup.check_state(state(z=CFG.geofence_max_m[2] + 0.01), nav()) == \
        Decision(Action.LAND, "geofence")
    assert sup.latched is not None
    hover_fence = Supervisor(CFG.model_copy(update={"geofence_action": "hover"}))
    assert hover_fence.check_state(state(x=-3.5), nav()) == Decision(Action.HOVER, "geofence")
    assert hover_fence.latched is None


@pytest.mark.parametrize("policy, after_hold", [("p", Action.FALLBACK), ("hover", Action.HOVER),
                                                ("hold", Action.HOLD)])
def test_solver_failure_chain_and_recovery(policy, after_hold):
    cfg = CFG.model_copy(update={"solver_fallback": policy, "solver_hold_ticks": 2,
                                 "solver_recover_ticks": 3, "solver_hover_ticks": 4})
    sup = Supervisor(cfg)
    good, bad = np.zeros(4), np.full(4, math.nan)
    assert sup.check_solution(True, good).action is Action.CONTROL
    actions = [sup.check_solution(False, good).action for _ in range(4)]
    assert actions == [Action.HOLD, Action.HOLD, after_hold, after_hold]
    if policy == "hold":  # holding too long: hover
        assert sup.check_solution(False, good).action is Action.HOVER
    # a finite-looking 'ok' with a NaN input is a failure too
    assert sup.check_solution(True, bad).action is not Action.CONTROL
    # three good solves in a row before the NMPC flies again
    recovering = [sup.check_solution(True, good).action for _ in range(3)]
    assert recovering[:2] == [after_hold if policy != "hold" else Action.HOLD] * 2
    assert recovering[2] is Action.CONTROL


def test_tilt_clip_and_mode_events():
    sup = Supervisor(CFG)
    cap = CFG.max_tilt_rad
    assert sup.clip_tilt_rad(cap + 0.1) == (cap, True)
    assert sup.clip_tilt_rad(-cap - 0.1) == (-cap, True)
    assert sup.clip_tilt_rad(0.1) == (0.1, False)
    assert sup.record(Decision(Action.CONTROL), "settle") == "settle"
    assert sup.record(Decision(Action.CONTROL), "track") == "track"
    assert sup.take_events() == []  # the runner's own schedule is no supervisor event
    assert sup.record(Decision(Action.HOVER, "stale-mocap"), "track") == "hover-stale-mocap"
    assert sup.record(Decision(Action.HOVER, "stale-mocap"), "track") == "hover-stale-mocap"
    assert sup.record(Decision(Action.CONTROL), "track") == "track"
    events = sup.take_events()
    assert [(e["mode"], e["previous"]) for e in events] == [
        ("hover-stale-mocap", "track"), ("track", "hover-stale-mocap")]
    assert events[0]["reason"] == "stale-mocap" and events[0]["action"] == "hover"


def test_config_validation_of_the_new_fields():
    from ardrone_nmpc.config.schema import ConfigError

    with pytest.raises(ConfigError, match=r"safety\.solver_hold_ticks"):
        load_config(None, ["safety.solver_hold_ticks=-1"])
    with pytest.raises(ConfigError, match=r"safety\.geofence_action"):
        load_config(None, ["safety.geofence_action=crash"])
    with pytest.raises(ConfigError, match=r"faults\.mocap_dropout\.duration_s"):
        load_config(None, ["faults.mocap_dropout.duration_s=0"])
    with pytest.raises(ConfigError, match=r"faults\.navdata_corrupt\.kind"):
        load_config(None, ["faults.navdata_corrupt.kind=garbled"])
    cfg = load_config(None, ["faults.wind.velocity_mps=[1,0,0]"])
    assert cfg.faults.active() == ["wind"]


# ----------------------------------------------------------------------------- fault bits
# The state word's fault bits (docs/protocol.md §4.2, ARDroneLib config.h): in flight CUTOUT and
# MOTORS stop (the runner cuts the motors), SOFTWARE_FAULT and VBAT_LOW land; before take-off
# every one of them refuses.

def with_bits(*names, mode=FlightMode.FLYING, battery=80.0):
    from ardrone_nmpc.protocol.navdata import DroneState

    bits = 0
    for name in names:
        bits |= int(DroneState[name])
    return NavdataSample(0.0, mode, battery, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0,
                         state_bits=bits)


def test_the_fault_table_is_the_firmwares_state_word():
    from ardrone_nmpc.protocol.navdata import DroneState
    from ardrone_nmpc.safety import DRONE_ALARMS

    assert {f.name: f.mask for f in DRONE_ALARMS} == {
        "CUTOUT": 1 << 22, "MOTORS": 1 << 12, "SOFTWARE_FAULT": 1 << 14, "VBAT_LOW": 1 << 15,
        "ULTRASOUND": 1 << 21}
    assert all(int(DroneState[f.name]) == f.mask for f in DRONE_ALARMS)


@pytest.mark.parametrize("bits, expected", [
    (("CUTOUT",), Decision(Action.STOP, "cutout")),
    (("MOTORS",), Decision(Action.STOP, "motors")),
    (("SOFTWARE_FAULT",), Decision(Action.LAND, "software-fault")),
    (("VBAT_LOW",), Decision(Action.LAND, "vbat-low")),
    (("VBAT_LOW", "MOTORS"), Decision(Action.STOP, "motors")),     # a cut outranks a landing
    (("SOFTWARE_FAULT", "CUTOUT"), Decision(Action.STOP, "cutout")),
    (("ULTRASOUND",), Decision(Action.CONTROL)),                     # before take-off only
    (("MAGNETO_NEEDS_CALIB", "COM_LOST", "WIND"), Decision(Action.CONTROL)),  # not faults here
])
def test_fault_bits_in_flight(bits, expected):
    sup = Supervisor(CFG)
    assert feedback(sup, navdata=with_bits(*bits)) == expected
    if expected.action is not Action.CONTROL:  # latched: the bit clearing changes nothing
        assert feedback(sup) == expected and sup.latched == expected


def test_fault_bits_rank_between_the_emergency_and_the_rest():
    # the drone's own emergency first; a motor fault before the battery floor; the battery
    # floor (the tool's own measurement) before the firmware's landing requests
    assert feedback(Supervisor(CFG), navdata=with_bits("CUTOUT", mode=FlightMode.EMERGENCY)) \
        == Decision(Action.STOP, "emergency")
    assert feedback(Supervisor(CFG), navdata=with_bits("MOTORS", battery=5.0)) == \
        Decision(Action.STOP, "motors")
    assert feedback(Supervisor(CFG), navdata=with_bits("VBAT_LOW", battery=5.0)) == \
        Decision(Action.LAND, "battery")
    assert feedback(Supervisor(CFG), navdata_ms=math.inf, mocap_ms=math.inf,
                    navdata=with_bits("SOFTWARE_FAULT")) == Decision(Action.LAND,
                                                                      "software-fault")
    # no state word (simulation without a wire): nothing to read
    assert feedback(Supervisor(CFG), navdata=nav()) == Decision(Action.CONTROL)


def test_every_fault_bit_refuses_a_take_off_in_one_line_naming_it():
    from ardrone_nmpc.safety import drone_alarms, takeoff_refusal

    assert takeoff_refusal(None) is None and takeoff_refusal(0) is None
    assert takeoff_refusal(1 << 18 | 1 << 13 | 1 << 0) is None  # calibration, com lost, fly
    for name, bit in (("CUTOUT", 22), ("MOTORS", 12), ("SOFTWARE_FAULT", 14), ("VBAT_LOW", 15),
                      ("ULTRASOUND", 21)):
        line = takeoff_refusal(1 << bit)
        assert f"{name} (state bit {bit}: " in line and line.count("state bit") == 1
        assert line.startswith("the drone reports ") and "refusing take-off" in line
    both = takeoff_refusal(1 << 12 | 1 << 14 | 1 << 18 | 1 << 21)  # issue 21's drone
    assert both == ("the drone reports MOTORS (state bit 12: motor problem), SOFTWARE_FAULT "
                    "(state bit 14: software fault, land as soon as possible), ULTRASOUND "
                    "(state bit 21: ultrasound sensor deaf): refusing take-off — check the "
                    "drone (`ardrone-nmpc status`)")
    assert "\n" not in both
    assert [f.name for f in drone_alarms(1 << 15 | 1 << 22)] == ["CUTOUT", "VBAT_LOW"]
    assert [f.reason for f in drone_alarms(1 << 14)] == ["software-fault"]
