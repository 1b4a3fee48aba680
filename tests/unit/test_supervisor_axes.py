"""Every supervisor check on every axis, at its boundary and with NaN (safety.py).

The hand mutations of issue 17 (tilt without roll, geofence without y, speed without vz) each
left every other test green; these fail on each of them, and on an off-by-equality boundary.
"""

import math

import numpy as np
import pytest

from ardrone_nmpc.config.schema import SafetyConfig
from ardrone_nmpc.core.types import FlightMode, NavdataSample
from ardrone_nmpc.safety import NOMINAL, Action, Decision, Supervisor

CFG = SafetyConfig()
LO, HI = CFG.geofence_min_m, CFG.geofence_max_m
CAP_DEG = math.degrees(CFG.max_tilt_rad)


def nav(battery=80.0, roll=0.0, pitch=0.0, mode=FlightMode.FLYING):
    return NavdataSample(0.0, mode, battery, roll, pitch, 0.0, 1.0, 0.0, 0.0, 0.0)


def state(**kw):
    x = dict(x=0.0, vx=0.0, y=0.0, vy=0.0, z=1.0, vz=0.0, psi=0.0)
    x.update(kw)
    return np.array([x["x"], x["vx"], x["y"], x["vy"], x["z"], x["vz"], x["psi"]])


def feedback(mocap_ms=10.0, navdata_ms=30.0, navdata=None, cfg=CFG):
    return Supervisor(cfg).check_feedback(mocap_age_ms=mocap_ms, navdata_age_ms=navdata_ms,
                                          navdata=navdata if navdata is not None else nav())


# ----------------------------------------------------------------------------- geofence

@pytest.mark.parametrize("axis, index", [("x", 0), ("y", 1), ("z", 2)])
@pytest.mark.parametrize("side", ["low", "high"])
def test_geofence_on_every_axis_and_side(axis, index, side):
    bound = LO[index] if side == "low" else HI[index]
    outside = bound - 0.01 if side == "low" else bound + 0.01
    sup = Supervisor(CFG)
    assert sup.check_state(state(**{axis: bound}), nav()) is NOMINAL  # on the fence: inside
    assert sup.latched is None
    assert sup.check_state(state(**{axis: outside}), nav()) == Decision(Action.LAND, "geofence")
    assert sup.latched == Decision(Action.LAND, "geofence")
    hover = Supervisor(CFG.model_copy(update={"geofence_action": "hover"}))
    assert hover.check_state(state(**{axis: outside}), nav()) == \
        Decision(Action.HOVER, "geofence")
    assert hover.latched is None


# ----------------------------------------------------------------------------- speed

@pytest.mark.parametrize("axis", ["vx", "vy", "vz"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_speed_on_every_axis(axis, sign):
    sup = Supervisor(CFG)
    v = CFG.max_speed_mps
    assert sup.check_state(state(**{axis: sign * v}), nav()) is NOMINAL      # at the limit
    assert sup.check_state(state(**{axis: sign * (v + 0.01)}), nav()) == \
        Decision(Action.HOVER, "speed")


@pytest.mark.parametrize("pair", [("vx", "vy"), ("vx", "vz"), ("vy", "vz")])
def test_speed_is_the_norm_of_all_three(pair):
    below = 0.75 * CFG.max_speed_mps  # each alone below the limit, together 1.06 × above
    assert Supervisor(CFG).check_state(state(**{pair[0]: below}), nav()) is NOMINAL
    assert Supervisor(CFG).check_state(state(**dict.fromkeys(pair, below)), nav()) == \
        Decision(Action.HOVER, "speed")


# ----------------------------------------------------------------------------- tilt

@pytest.mark.parametrize("which", ["roll", "pitch"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_tilt_on_roll_and_pitch(which, sign):
    sup = Supervisor(CFG)
    assert sup.check_state(state(), nav(**{which: sign * CAP_DEG})) is NOMINAL
    assert sup.check_state(state(), nav(**{which: sign * (CAP_DEG + 0.1)})) == \
        Decision(Action.HOVER, "tilt")


@pytest.mark.parametrize("roll, pitch", [(math.nan, 0.0), (0.0, math.nan), (math.nan, 1.0),
                                         (1.0, math.nan), (math.inf, 0.0), (0.0, -math.inf)])
def test_a_non_finite_tilt_is_a_breach(roll, pitch):
    assert Supervisor(CFG).check_state(state(), nav(roll=roll, pitch=pitch)) == \
        Decision(Action.HOVER, "tilt")


def test_no_navdata_skips_only_the_tilt_check():
    sup = Supervisor(CFG)
    assert sup.check_state(state(), None) is NOMINAL
    assert sup.check_state(state(vz=3.0), None) == Decision(Action.HOVER, "speed")


@pytest.mark.parametrize("index", range(7))
def test_a_non_finite_state_component_hovers(index):
    x = state()
    x[index] = math.nan
    assert Supervisor(CFG).check_state(x, nav()) == Decision(Action.HOVER, "nonfinite-state")
    x[index] = math.inf
    assert Supervisor(CFG).check_state(x, nav()) == Decision(Action.HOVER, "nonfinite-state")


def test_state_check_order_fence_before_speed_before_tilt():
    far_fast_tilted = state(x=HI[0] + 1, vx=5.0)
    assert Supervisor(CFG).check_state(far_fast_tilted, nav(roll=40.0)).reason == "geofence"
    assert Supervisor(CFG).check_state(state(vx=5.0), nav(roll=40.0)).reason == "speed"


# ----------------------------------------------------------------------------- feedback

@pytest.mark.parametrize("mocap_ms, expected", [
    (0.0, NOMINAL),
    (CFG.mocap_hold_ms, NOMINAL),
    (CFG.mocap_hold_ms + 0.1, Decision(Action.HOLD, "stale-mocap")),
    (CFG.mocap_hover_ms, Decision(Action.HOLD, "stale-mocap")),
    (CFG.mocap_hover_ms + 0.1, Decision(Action.HOVER, "stale-mocap")),
    (CFG.mocap_land_ms, Decision(Action.HOVER, "stale-mocap")),
    (CFG.mocap_land_ms + 0.1, Decision(Action.LAND, "mocap-lost")),
    (math.nan, Decision(Action.LAND, "mocap-lost")),
])
def test_mocap_age_boundaries(mocap_ms, expected):
    assert feedback(mocap_ms=mocap_ms) == expected


@pytest.mark.parametrize("navdata_ms, expected", [
    (CFG.navdata_land_ms, NOMINAL),
    (CFG.navdata_land_ms + 0.1, Decision(Action.LAND, "navdata-lost")),
    (math.inf, Decision(Action.LAND, "navdata-lost")),
    (math.nan, Decision(Action.LAND, "navdata-lost")),
])
def test_navdata_age_boundaries(navdata_ms, expected):
    assert feedback(navdata_ms=navdata_ms) == expected


@pytest.mark.parametrize("battery, expected", [
    (CFG.battery_floor_pct + 0.1, NOMINAL),
    (CFG.battery_floor_pct, Decision(Action.LAND, "battery")),
    (0.0, Decision(Action.LAND, "battery")),
    (math.nan, Decision(Action.LAND, "battery")),
])
def test_battery_floor_and_nan(battery, expected):
    assert feedback(navdata=nav(battery=battery)) == expected


def test_feedback_order_and_latches():
    # emergency before battery before navdata age before mocap age
    assert feedback(mocap_ms=math.inf, navdata_ms=math.inf,
                    navdata=nav(battery=0.0, mode=FlightMode.EMERGENCY)).reason == "emergency"
    assert feedback(mocap_ms=math.inf, navdata_ms=math.inf,
                    navdata=nav(battery=0.0)).reason == "battery"
    assert feedback(mocap_ms=math.inf, navdata_ms=math.inf).reason == "navdata-lost"
    sup = Supervisor(CFG)
    first = sup.check_feedback(mocap_age_ms=10.0, navdata_age_ms=30.0, navdata=nav(battery=5.0))
    assert sup.check_feedback(mocap_age_ms=10.0, navdata_age_ms=30.0, navdata=nav()) is first
    stop = Supervisor(CFG)
    stop.check_feedback(mocap_age_ms=10.0, navdata_age_ms=30.0,
                        navdata=nav(mode=FlightMode.EMERGENCY))
    assert stop.check_feedback(mocap_age_ms=10.0, navdata_age_ms=30.0, navdata=nav()) == \
        Decision(Action.STOP, "emergency")
    assert stop.latched == Decision(Action.STOP, "emergency")
    none = Supervisor(CFG).check_feedback(mocap_age_ms=10.0, navdata_age_ms=30.0, navdata=None)
    assert none is NOMINAL


# ----------------------------------------------------------------------------- solver

def test_one_bad_input_component_fails_the_solve():
    for j in range(4):
        u = np.zeros(4)
        u[j] = math.nan
        sup = Supervisor(CFG)
        assert sup.check_solution(True, u) == Decision(Action.HOLD, "solver")


def test_the_hold_count_is_exact_and_recovery_needs_consecutive_good_solves():
    cfg = CFG.model_copy(update={"solver_fallback": "hover", "solver_hold_ticks": 3,
                                 "solver_recover_ticks": 2})
    sup = Supervisor(cfg)
    good = np.zeros(4)
    got = [sup.check_solution(False, good) for _ in range(4)]
    assert got == [Decision(Action.HOLD, "solver")] * 3 + [Decision(Action.HOVER, "solver")]
    assert sup.check_solution(True, good) == Decision(Action.HOVER, "solver")
    assert sup.check_solution(False, good) == Decision(Action.HOVER, "solver")  # resets count
    assert sup.check_solution(True, good) == Decision(Action.HOVER, "solver")
    assert sup.check_solution(True, good) is NOMINAL
    # back to normal: a new failure holds first again
    assert sup.check_solution(False, good) == Decision(Action.HOLD, "solver")


def test_hold_policy_hovers_after_exactly_solver_hover_ticks():
    cfg = CFG.model_copy(update={"solver_fallback": "hold", "solver_hold_ticks": 1,
                                 "solver_hover_ticks": 3})
    sup = Supervisor(cfg)
    got = [sup.check_solution(False, np.zeros(4)) for _ in range(5)]
    assert got == [Decision(Action.HOLD, "solver")] * 3 + [Decision(Action.HOVER, "solver")] * 2


def test_zero_hold_ticks_falls_back_at_once():
    sup = Supervisor(CFG.model_copy(update={"solver_fallback": "p", "solver_hold_ticks": 0}))
    assert sup.check_solution(False, np.zeros(4)) == Decision(Action.FALLBACK, "solver")


# ----------------------------------------------------------------------------- clip, record

def test_clip_at_exactly_the_cap_is_not_flagged():
    cap = CFG.max_tilt_rad
    sup = Supervisor(CFG)
    assert sup.clip_tilt_rad(cap) == (cap, False)
    assert sup.clip_tilt_rad(-cap) == (-cap, False)
    assert sup.clip_tilt_rad(math.nextafter(cap, 9)) == (cap, True)
    assert sup.clip_tilt_rad(math.nextafter(-cap, -9)) == (-cap, True)


def test_mode_labels_and_events():
    assert Decision(Action.LAND, "geofence").mode("track") == "land-geofence"
    assert Decision(Action.HOVER).mode("track") == "hover"
    assert NOMINAL.mode("settle") == "settle"
    sup = Supervisor(CFG)
    assert sup.record(Decision(Action.HOLD, "solver"), "settle") == "hold-solver"
    events = sup.take_events()
    assert events == [{"kind": "mode", "mode": "hold-solver", "previous": "", "action": "hold",
                       "reason": "solver"}]
    assert sup.take_events() == []
    sup.record(NOMINAL, "track")
    assert sup.take_events()[0]["previous"] == "hold-solver"
    # the runner's own labels switching under a nominal verdict are no supervisor event
    for label in ("settle", "track", "settle"):
        assert sup.record(NOMINAL, label) == label
    assert sup.take_events() == []
