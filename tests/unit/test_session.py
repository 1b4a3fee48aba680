"""FlightSession against a scripted drone on a fake clock: verification, preflight refusals,
trim timing, take-off (and landing after it fails), the heading check, and a landing that never
gives up. Fast and deterministic (no sockets); the same paths against a drone stand-in over
real UDP are in tests/integration/test_session_standin.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample
from ardrone_nmpc.links.drone_config import LinkError
from ardrone_nmpc.runtime.operator_input import OperatorAbort, OperatorRequests
from ardrone_nmpc.runtime.session import (
    NOTICE_EVERY_S,
    TRIM_TO_TAKEOFF_S,
    CutMotors,
    DroneLandedItself,
    FlightSession,
    PreflightError,
    TakeoffFailed,
)
from ardrone_nmpc.runtime.signals import Terminated
from tests.conftest import ManualClock as Clock

WRITTEN = {"control:euler_angle_max": "0.2094", "control:control_vz_max": "700",
           "control:control_yaw": "1.745", "control:altitude_max": "3000"}
PROFILE = {"control:outdoor": "FALSE", "control:flight_without_shell": "FALSE",
           "control:flying_mode": "0"}




class Drone:
    """A scripted link: modes change on the fake clock after take-off/land."""

    host, control_port = "10.0.0.9", 5559

    def __init__(self, clock, *, held=None, read_error=None, takeoff_s=1.0, landing_s=0.5,
                 mode=FlightMode.LANDED, battery=80.0, roll=0.3, pitch=-0.2, yaw=(10.0, 10.0),
                 never_flies=False, never_lands=False):
        self.clock = clock
        self.calls: list[str] = []
        self.held = {**WRITTEN, **PROFILE} if held is None else held
        self.read_error = read_error
        self.takeoff_s, self.landing_s = takeoff_s, landing_s
        self._mode, self.battery, self.roll, self.pitch = mode, battery, roll, pitch
        self.yaw = yaw  # navdata yaw (°) on the ground / after take-off
        self.never_flies, self.never_lands = never_flies, never_lands
        self.t_takeoff = self.t_land = None
        self.nav_lost_until = -math.inf
        self.nav_gone = (math.inf, math.inf)  # navdata None in this time window
        self.nav_age_s = lambda t: 0.0        # age of the newest navdata
        self.gap_after_flying = 0.0           # navdata None this long after the first flying
        self.gap_after_airborne = 0.0         # … after the first airborne sample
        self._first_flying = self._first_airborne = None
        self.args: dict = {}
        self.self_landing = None
        self.connected = True
        self.at_bind_warning = None
        self.land_errors: list[Exception] = []
        self.state_bits = None                # the state word navdata carries (fault bits)
        self.bootstrap_only = False           # packets arrive, but no demo sample
        self.silent_since = None              # no packet at all from this time on

    def connect(self, timeout_s):
        self.calls.append("connect")
        self.args["connect"] = timeout_s

    def configure_limits(self, **kw):
        self.calls.append("configure_limits")
        self.args["configure_limits"] = kw
        return dict(WRITTEN)

    def configure_profile(self, *, flight_without_shell):
        self.calls.append(f"profile:{flight_without_shell}")
        return dict(PROFILE, **{"control:flight_without_shell":
                                "TRUE" if flight_without_shell else "FALSE"})

    def read_config(self, timeout_s):
        self.calls.append("read_config")
        self.args["read_config"] = timeout_s
        if self.read_error:
            raise self.read_error
        return dict(self.held)

    def flat_trim(self):
        self.calls.append("flat_trim")
        self.t_trim = self.clock()

    def takeoff(self):
        self.calls.append("takeoff")
        self.t_takeoff = self.clock()

    def land(self):
        self.calls.append("land")
        if self.land_errors:
            raise self.land_errors.pop(0)
        if self.t_land is None:
            self.t_land = self.clock()

    def emergency(self):
        self.calls.append("emergency")
        self._mode = FlightMode.EMERGENCY

    @property
    def mode(self):
        t = self.clock()
        if self._mode is FlightMode.EMERGENCY:
            return self._mode
        if self.t_land is not None and not self.never_lands:
            if t - self.t_land >= self.landing_s:
                return FlightMode.LANDED
            return FlightMode.LANDING if self.t_takeoff is not None else self._mode
        if self.t_takeoff is not None and not self.never_flies:
            return FlightMode.FLYING if t - self.t_takeoff >= self.takeoff_s \
                else FlightMode.TAKING_OFF
        if self.t_land is not None and self.t_takeoff is not None:
            return FlightMode.FLYING
        return self._mode

    @property
    def navdata(self):
        if self.nav_gone[0] <= self.clock() < self.nav_gone[1]:
            return None
        mode = self.mode
        if self.gap_after_flying and mode is FlightMode.FLYING:
            if self._first_flying is None:
                self._first_flying = self.clock()  # this sample is seen, then a gap
            elif self.clock() < self._first_flying + self.gap_after_flying:
                return None
        if self.gap_after_airborne and mode.airborne:
            if self._first_airborne is None:
                self._first_airborne = self.clock()
            elif self.clock() < self._first_airborne + self.gap_after_airborne:
                return None
        yaw = self.yaw[1] if mode is FlightMode.FLYING else self.yaw[0]
        return NavdataSample(self.clock(), mode, self.battery, self.roll, self.pitch, yaw,
                             0.0, 0.0, 0.0, 0.0, ctrl_state=0x20000,
                             state_bits=self.state_bits)

    @property
    def state_rx_t_s(self):  # any packet: bootstrap ones too
        t = self.clock()
        if self.silent_since is not None and t >= self.silent_since:
            return self.silent_since
        return t - 10.0 if t < self.nav_lost_until else t - self.nav_age_s(t)

    @property
    def navdata_rx_t_s(self):  # demo packets only
        return -math.inf if self.bootstrap_only else self.state_rx_t_s

    @property
    def packet_mode(self):
        return self.mode

    @property
    def state(self):
        return self.state_bits


class Mocap:
    port, sender, where = 51001, "10.0.0.2:4000", "udp 0.0.0.0:51001"
    contenders: list = []

    def __init__(self, clock, drone=None, xyz=(0.0, 0.0, 0.0), psi=(0.0, 0.0), visible=True,
                 age_s=0.0, visible_from=-math.inf, gone=(math.inf, math.inf), contenders=()):
        self.contenders = list(contenders)
        self.clock, self.drone, self.xyz, self.psi, self.visible = clock, drone, xyz, psi, visible
        self.age_s, self.visible_from, self.gone = age_s, visible_from, gone
        self.foreign_senders = {}

    def latest(self):
        t = self.clock()
        if not self.visible or t < self.visible_from or self.gone[0] <= t < self.gone[1]:
            return None, -math.inf
        flying = self.drone is not None and self.drone.mode is FlightMode.FLYING
        pose = MocapPose(self.clock(), np.array(self.xyz, dtype=float), np.zeros(3),
                         self.psi[1] if flying else self.psi[0])
        return pose, self.clock() - self.age_s


class Lock:
    def __init__(self):
        self.held = False
        self.log = []

    def acquire(self):
        self.held = True
        self.log.append("acquire")

    def release(self):
        self.held = False
        self.log.append("release")


def make(drone_kw=None, mocap_kw=None, cfg_sets=(), start=(0.0, 0.0, 1.0), requests=None,
         event=None, clock=None):
    clock = clock or Clock()
    drone = Drone(clock, **(drone_kw or {}))
    mocap = Mocap(clock, drone, **(mocap_kw or {}))
    events, warnings = [], []
    sink = event or (lambda kind, **f: events.append((kind, f)))
    session = FlightSession(load_config(None, list(cfg_sets)), drone, mocap, event=sink,
                            clock=clock, sleep=clock.sleep, warn=warnings.append,
                            start_position_m=start, requests=requests, lock=Lock())
    return session, drone, events, warnings, clock


def kinds(events):
    return [k for k, _ in events]


# ----------------------------------------------------------------------------- the happy path

def test_enter_verifies_trims_and_takes_off_in_order_then_exit_lands():
    session, drone, events, warnings, clock = make()
    with session:
        assert session.lock.held
        # the profile (control:outdoor, the hull) before the limits: outdoor selects the
        # stored triple the limits are written into
        assert drone.calls == ["connect", "profile:False", "configure_limits", "read_config",
                               "flat_trim", "takeoff"]
        assert drone.mode is FlightMode.FLYING
        assert drone.t_takeoff - drone.t_trim >= TRIM_TO_TAKEOFF_S
        assert drone.t_takeoff - drone.t_trim < TRIM_TO_TAKEOFF_S + 0.05
    assert drone.calls[-1] == "land" and session.landed_cleanly is True
    assert not session.lock.held and session.lock.log == ["acquire", "release"]
    assert kinds(events) == ["config_written", "config_read", "preflight_ok", "flat_trim",
                             "takeoff", "heading_check", "landing", "landed"]
    written = dict(events[0][1])
    assert written == {**WRITTEN, **PROFILE}
    assert dict(events[-2][1]) == {"reason": "end"} and events[-1][1] == {"mode": "landed"}
    assert warnings == []


def test_outdoor_hull_is_written_as_flight_without_shell():
    held = {**WRITTEN, **PROFILE, "control:flight_without_shell": "TRUE"}
    session, drone, events, _, _ = make(cfg_sets=["drone.hull=outdoor"],
                                        drone_kw={"held": held})
    with session:
        pass
    assert "profile:True" in drone.calls
    assert events[0][1]["control:flight_without_shell"] == "TRUE"


# ----------------------------------------------------------------------------- verification

def test_a_held_value_that_differs_refuses_naming_key_written_and_held():
    held = {**WRITTEN, **PROFILE, "control:euler_angle_max": "0.52"}
    session, drone, events, _, _ = make(drone_kw={"held": held})
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    msg = str(err.value)
    assert "control:euler_angle_max" in msg and "'0.52'" in msg and "'0.2094'" in msg
    assert "set drone.config_ids" in msg and "more key" not in msg
    assert "takeoff" not in drone.calls and "flat_trim" not in drone.calls
    assert "land" not in drone.calls  # nothing that could start the motors went out
    assert ("config_mismatch", {"key": "control:euler_angle_max", "written": "0.2094",
                                "held": "0.52"}) in events
    assert not session.lock.held


def test_several_differences_are_counted_and_a_missing_key_is_one():
    held = {**WRITTEN, **PROFILE, "control:control_vz_max": "2000"}
    del held["control:flying_mode"]
    session, drone, events, _, _ = make(drone_kw={"held": held})
    with pytest.raises(PreflightError, match=r"control:flying_mode.*and 1 more key"):
        session.__enter__()
    assert kinds(events).count("config_mismatch") == 2
    assert ("config_mismatch", {"key": "control:flying_mode", "written": "0", "held": None}) \
        in events


def test_values_equal_beyond_rounding_pass():
    held = {**WRITTEN, **PROFILE, "control:euler_angle_max": "2.0940001e-01",
            "control:control_vz_max": "700.0", "control:outdoor": "false"}
    session, drone, *_ = make(drone_kw={"held": held})
    with session:
        assert "takeoff" in drone.calls


def test_a_silent_control_port_refuses_unless_verification_is_off():
    session, drone, events, warnings, _ = make(
        drone_kw={"read_error": LinkError("connection refused")})
    with pytest.raises(PreflightError, match=r"control port 10\.0\.0\.9:5559 did not answer"
                                             r".*verify_config: false"):
        session.__enter__()
    assert "takeoff" not in drone.calls and warnings == []
    session, drone, events, warnings, _ = make(
        drone_kw={"read_error": LinkError("connection refused")},
        cfg_sets=["drone.verify_config=false"])
    with session:
        assert "takeoff" in drone.calls
    assert len(warnings) == 1 and "UNVERIFIED" in warnings[0] and "refused" in warnings[0]
    assert "config_unverified" in kinds(events) and "config_read" not in kinds(events)


# ----------------------------------------------------------------------------- preflight

@pytest.mark.parametrize("drone_kw, mocap_kw, match", [
    ({"mode": FlightMode.EMERGENCY}, {}, r"in emergency: clear it with `ardrone-nmpc reset "
                                         r"--drone 10\.0\.0\.9`"),
    ({"mode": FlightMode.FLYING}, {}, r"not landed and ready \(mode flying, ctrl_state "
                                      r"0x00020000\)"),
    ({"mode": FlightMode.LANDING}, {}, r"not landed and ready"),
    ({"battery": 20.0}, {}, r"battery 20 % at or below the floor \(20 %"),
    ({"battery": math.nan}, {}, r"battery nan %"),
    ({"roll": 2.0}, {}, r"not level \(roll \+2\.0°, pitch -0\.2°"),
    ({"roll": -2.5}, {}, r"not level"),
    ({"pitch": 2.0}, {}, r"not level \(roll \+0\.3°, pitch \+2\.0°"),
    ({"pitch": -2.0}, {}, r"not level"),
    ({"pitch": math.nan}, {}, r"not level"),
    ({}, {"visible": False}, r"mocap object 'ardrone' not visible from udp 0.0.0.0:51001"),
    ({}, {"xyz": (0.51, 0.0, 0.0)}, r"0\.51 m from the experiment's start: mocap \(\+0\.51, "
                                    r"\+0\.00\) m, start \(\+0\.00, \+0\.00\)"),
    ({}, {"xyz": (0.0, -0.6, 0.0)}, r"0\.60 m from the experiment's start"),
    ({}, {"xyz": (0.4, 0.31, 0.0)}, r"0\.51 m from"),
    ({}, {"xyz": (0.0, 0.0, 0.6)}, r"at z = \+0\.60 m"),
    ({}, {"xyz": (0.0, 0.0, -0.6)}, r"at z = -0\.60 m"),
    ({}, {"contenders": ["127.0.0.1:40000"]},
     r"comes from more than one sender: the link took 10\.0\.0\.2:4000, 127\.0\.0\.1:40000 "
     r"also sends it"),
])
def test_preflight_refusals_send_nothing_that_flies(drone_kw, mocap_kw, match):
    session, drone, events, _, _ = make(drone_kw, mocap_kw)
    with pytest.raises(PreflightError, match=match):
        session.__enter__()
    assert "takeoff" not in drone.calls and "flat_trim" not in drone.calls
    assert "land" not in drone.calls and "preflight_ok" not in kinds(events)
    assert not session.lock.held


@pytest.mark.parametrize("drone_kw, mocap_kw, start", [
    ({"battery": 20.5, "roll": 1.9, "pitch": -1.9}, {"xyz": (0.3, 0.39, 0.49)}, (0, 0, 1)),
    ({"roll": -1.99, "pitch": 1.99}, {"xyz": (-0.49, 0.0, -0.49)}, (0, 0, 1)),
    ({}, {"xyz": (5.0, 5.0, 0.0)}, None),            # a live reference: no start to check
    ({}, {"xyz": (1.2, -0.1, 0.0)}, (1.0, 0.0, 1.0)),
])
def test_preflight_passes_inside_every_bound(drone_kw, mocap_kw, start):
    session, drone, events, _, _ = make(drone_kw, mocap_kw, start=start)
    session.__enter__()
    assert "takeoff" in drone.calls
    ok = dict(events)["preflight_ok"]
    assert ok["battery_pct"] == drone.battery and ok["mocap_sender"] == Mocap.sender
    assert (ok["x_m"], ok["y_m"], ok["z_m"]) == pytest.approx(mocap_kw["xyz"])


def test_a_foreign_mocap_sender_is_named_when_the_object_is_not_visible():
    session, drone, *_ = make(mocap_kw={"visible": False})
    session.mocap.foreign_senders = {"10.0.0.7:9999": 120}
    with pytest.raises(PreflightError, match=r"other senders ignored: 10\.0\.0\.7:9999"):
        session.__enter__()


def test_the_flat_trim_rechecks_the_ground_state():
    session, drone, *_ = make()
    session.configure()
    session.preflight()
    drone.roll = 3.0  # picked up meanwhile
    with pytest.raises(PreflightError, match="not level"):
        session.trim()
    drone.roll, drone._mode = 0.0, FlightMode.TAKING_OFF
    with pytest.raises(PreflightError, match="left the ground state"):
        session.trim()
    assert "flat_trim" not in drone.calls


def test_an_operator_request_before_take_off_aborts_without_taking_off():
    requests = OperatorRequests()
    requests.request_land()
    session, drone, *_ = make(requests=requests)
    with pytest.raises(OperatorAbort, match="land before take-off"):
        session.__enter__()
    assert "takeoff" not in drone.calls and "land" not in drone.calls


# ----------------------------------------------------------------------------- take-off

def test_a_take_off_that_never_completes_lands_then_raises():
    session, drone, events, _, clock = make(drone_kw={"never_flies": True})
    t0 = clock()
    with pytest.raises(TakeoffFailed, match=r"take-off did not complete in 10 s \(landed\): the "
                                            r"drone never showed flying — landing"):
        session.__enter__()
    assert clock() - t0 >= FlightSession.TAKEOFF_TIMEOUT_S
    assert drone.calls.index("takeoff") < drone.calls.index("land")
    assert session.landed_cleanly is True
    assert ("landing", {"reason": "TakeoffFailed"}) in events and "landed" in kinds(events)
    assert not session.lock.held


def test_an_interrupted_take_off_lands_then_reraises():
    session, drone, events, warnings, clock = make()
    real_sleep = clock.sleep

    def sleep(dt):
        real_sleep(dt)
        if drone.t_takeoff is not None and clock() - drone.t_takeoff > 0.3 \
                and "interrupted" not in drone.calls:
            drone.calls.append("interrupted")
            raise KeyboardInterrupt

    session.sleep = sleep
    with pytest.raises(KeyboardInterrupt):
        session.__enter__()
    assert drone.calls[-2:] == ["interrupted", "land"]
    assert session.landed_cleanly is True and "landed" in kinds(events)
    assert any("Ctrl-C again within 2 s" in w for w in warnings)


def test_a_drone_that_lands_itself_during_take_off_ends_it():
    session, drone, events, *_ = make(drone_kw={"never_flies": True})
    drone.self_landing = "the drone touched down (state bit 0 cleared)"
    with pytest.raises(DroneLandedItself, match="take-off: the drone touched down"):
        session.__enter__()
    assert "land" in drone.calls


def test_an_operator_request_during_take_off_lands():
    requests = OperatorRequests()
    session, drone, *_ = make(requests=requests, drone_kw={"never_flies": True})
    real = session.sleep

    def sleep(dt):
        real(dt)
        if drone.t_takeoff is not None:
            requests.request_land()

    session.sleep = sleep
    with pytest.raises(OperatorAbort, match="land during take-off"):
        session.__enter__()
    assert drone.calls[-1] == "land"


@pytest.mark.parametrize("psi, yaw_deg, ok", [
    ((0.0, 0.3), (10.0, 10.0 - math.degrees(0.3)), True),    # CCW turn: navdata yaw decreases
    ((0.0, 0.3), (10.0, 10.0 + math.degrees(0.3)), False),   # mirrored axis: offset 0.6 rad
    ((0.0, 0.0), (10.0, 10.0 + math.degrees(0.19)), True),   # just inside 0.2 rad
    ((0.0, 0.0), (10.0, 10.0 + math.degrees(0.21)), False),
    ((0.0, -0.25), (10.0, 10.0), False),                      # mocap turned, drone did not
    ((3.1, -3.1), (-178.0, 182.0 - math.degrees(2 * math.pi - 6.2)), True),  # across ±180°
])
def test_the_heading_check_compares_turns_in_the_sdk_sign(psi, yaw_deg, ok):
    session, drone, events, _, _ = make(drone_kw={"yaw": yaw_deg}, mocap_kw={"psi": psi})
    if ok:
        session.__enter__()
        check = dict(events)["heading_check"]
        assert abs(check["offset_rad"]) <= 0.2
        assert check["mocap_turn_rad"] == pytest.approx(math.remainder(psi[1] - psi[0],
                                                                       2 * math.pi))
    else:
        with pytest.raises(PreflightError, match=r"mocap heading turned .*offset .*landing"):
            session.__enter__()
        assert drone.calls[-1] == "land" and session.landed_cleanly is True
        assert abs(dict(events)["heading_check"]["offset_rad"]) > 0.2


# ----------------------------------------------------------------------------- landing

def flying(**drone_kw):
    session, drone, events, warnings, clock = make(drone_kw=drone_kw)
    session.__enter__()
    events.clear()
    return session, drone, events, warnings, clock


def test_landing_waits_for_fresh_navdata_and_says_so_while_it_is_lost():
    session, drone, events, warnings, clock = flying(landing_s=10.5)
    drone.nav_lost_until = clock() + 11.0
    t0 = clock()
    assert session.land() is True
    assert clock() - t0 >= 11.0  # landed at 10.5 s, but navdata said so only after 11 s
    lost = [f for k, f in events if k == "landing_navdata_lost"]
    assert len(lost) == int(11.0 // NOTICE_EVERY_S)
    assert all(f["age_s"] == pytest.approx(10.0) for f in lost)
    assert sum("no navdata" in w and "still sending land" in w for w in warnings) == len(lost)
    assert kinds(events)[-1] == "landed"


def test_landing_notices_name_the_mode_while_navdata_flows():
    session, drone, events, warnings, clock = flying(landing_s=7.0)
    assert session.land() is True
    assert kinds(events).count("landing_wait") == 2
    assert "waiting for the drone to touch down (mode landing" in warnings[0]


def test_landing_never_gives_up_on_its_own():
    session, drone, events, warnings, clock = flying(never_lands=True)
    t0 = clock()
    real = session.sleep

    def sleep(dt):
        real(dt)
        if clock() - t0 > 120.0:
            drone.never_lands = False  # two minutes later it finally lands
    session.sleep = sleep
    assert session.land() is True and clock() - t0 > 120.0
    assert kinds(events).count("landing_wait") >= 39


def test_a_first_interrupt_during_landing_is_announced_a_second_within_2_s_cuts():
    session, drone, events, warnings, clock = flying(landing_s=5.0)
    real = session.sleep
    presses = [clock() + 1.0, clock() + 2.5]

    def sleep(dt):
        real(dt)
        if presses and clock() >= presses[0]:
            presses.pop(0)
            raise KeyboardInterrupt
    session.sleep = sleep
    with pytest.raises(KeyboardInterrupt):
        session.land()
    assert drone.calls[-1] == "emergency" and drone.calls.count("emergency") == 1
    assert warnings[0].startswith("landing — press Ctrl-C again within 2 s")
    assert warnings[1] == "cutting the motors (emergency): a second Ctrl-C"
    assert ("emergency", {"reason": "a second Ctrl-C"}) in events
    assert session.landed_cleanly is True  # navdata confirmed the emergency


def test_interrupts_further_apart_or_other_signals_only_keep_landing():
    session, drone, events, warnings, clock = flying(landing_s=8.0)
    real = session.sleep
    presses = [(clock() + 1.0, KeyboardInterrupt()), (clock() + 3.5, KeyboardInterrupt()),
               (clock() + 4.0, Terminated(15)), (clock() + 4.5, Terminated(1))]

    def sleep(dt):
        real(dt)
        if presses and clock() >= presses[0][0]:
            raise presses.pop(0)[1]
    session.sleep = sleep
    with pytest.raises(KeyboardInterrupt) as err:
        session.land()
    assert type(err.value) is KeyboardInterrupt  # the first interrupt is the one re-raised
    assert "emergency" not in drone.calls and session.landed_cleanly is True
    assert sum("press Ctrl-C again" in w for w in warnings) == 2


def test_the_operators_emergency_key_cuts_during_landing():
    requests = OperatorRequests()
    session, drone, events, warnings, clock = make(requests=requests,
                                                   drone_kw={"landing_s": 5.0})
    session.__enter__()
    requests.request_emergency()
    assert session.land() is True
    assert drone.calls.count("emergency") == 1
    assert warnings[-1] == "cutting the motors (emergency): the operator's emergency key"


def test_an_unconfirmed_cut_ends_the_wait_as_not_landed():
    session, drone, events, warnings, clock = flying(never_lands=True)
    drone.emergency = lambda: drone.calls.append("emergency")  # the drone does not react
    drone.nav_lost_until = math.inf
    session._cut_motors("test")
    t0 = clock()
    assert session.land() is False and 2.0 < clock() - t0 < 2.1
    assert ("landing_failed", {"error": "motor cut not confirmed by navdata"}) in events


def test_the_landing_outcome_comes_from_navdata_not_from_the_log():
    written = []

    def event(kind, **fields):
        if kind in ("landed", "landing"):
            raise OSError("No space left on device")
        written.append(kind)

    session, drone, _, warnings, clock = make(event=event)
    session.__enter__()
    session.__exit__(None, None, None)
    assert session.landed_cleanly is True
    assert any("'landed' not logged: No space left on device" in w for w in warnings)
    assert "land" in drone.calls


def test_a_failing_land_send_is_retried_and_a_closed_link_ends_it():
    session, drone, events, warnings, clock = flying()
    drone.land_errors = [LinkError("Network is unreachable")] * 3
    assert session.land() is True and drone.calls.count("land") == 4
    session, drone, events, warnings, clock = flying()
    drone.connected = False
    drone.land_errors = [LinkError("the drone link is not connected")]
    assert session.land() is False and session.landed_cleanly is False
    assert ("landing_failed", {"error": "the drone link is not connected"}) in events


def test_exit_lands_even_if_the_landing_event_fails_and_never_swallows():
    session, drone, events, warnings, clock = flying()
    assert session.__exit__(ValueError, ValueError("x"), None) is False
    assert ("landing", {"reason": "ValueError"}) in events and drone.calls[-1] == "land"
    session, drone, events, warnings, clock = flying()
    session.__exit__(KeyboardInterrupt, KeyboardInterrupt(), None)
    assert warnings[0].startswith("landing — press Ctrl-C again")
    session, drone, events, warnings, clock = flying()
    session.__exit__(Terminated, Terminated(1), None)
    assert warnings == []  # a signal is not a Ctrl-C: no motor-cut announcement


class StepClock(Clock):
    """Exact binary steps, so boundaries (2 s, 0.5 s) are hit exactly."""

    def sleep(self, dt):
        self.t += 0.25


# ----------------------------------------------------------------------------- exact words
# What each refusal says is part of the interface (docs/first-flight.md lists them).

def test_what_is_asked_of_the_drone_and_how_long_it_is_waited_for():
    session, drone, events, *_ = make(cfg_sets=["drone.euler_angle_max_rad=0.3",
                                                "drone.control_vz_max_mps=1.1",
                                                "drone.control_yaw_radps=2.5",
                                                "drone.altitude_max_m=2.2"])
    with session:
        pass
    assert drone.args == {"connect": 5.0, "read_config": 2.0, "configure_limits": {
        "euler_angle_max_rad": 0.3, "control_vz_max_mps": 1.1, "control_yaw_radps": 2.5,
        "altitude_max_m": 2.2}}
    assert dict(events)["config_read"] == {**WRITTEN, **PROFILE}
    assert dict(events)["flat_trim"] == {"roll_deg": 0.3, "pitch_deg": -0.2}
    assert dict(events)["preflight_ok"]["ctrl_state"] == 0x20000
    check = dict(events)["heading_check"]
    assert check == {"mocap_turn_rad": 0.0, "navdata_turn_rad": 0.0, "offset_rad": 0.0}
    assert session.landed_cleanly is True


def test_a_refusal_leaves_the_landing_outcome_unknown():
    session, *_ = make(drone_kw={"battery": 5.0})
    with pytest.raises(PreflightError):
        session.__enter__()
    assert session.landed_cleanly is None


@pytest.mark.parametrize("drone_kw, mocap_kw, message", [
    ({"mode": FlightMode.EMERGENCY}, {},
     "the drone is in emergency: clear it with `ardrone-nmpc reset --drone 10.0.0.9` before "
     "flying"),
    ({"roll": 2.0}, {}, "the drone is not level (roll +2.0°, pitch -0.2°; the flat trim needs "
                        "both within ±2°): put it on a level surface"),
    ({"battery": 12.4}, {}, "battery 12 % at or below the floor (20 %, "
                            "safety.battery_floor_pct): charge it"),
    ({}, {"xyz": (1.0, 2.51, 0.0)}, "the drone is 0.51 m from the experiment's start: mocap "
     "(+1.00, +2.51) m, start (+1.00, +2.00) m (safety.start_tolerance_m 0.50 m) — put it there "
     "or check the mocap origin"),
    ({}, {"xyz": (1.0, 2.0, 0.75)}, "the mocap puts the landed drone at z = +0.75 m (more than "
     "safety.start_tolerance_m 0.50 m off the floor): check the mocap origin and the object's "
     "z axis (up)"),
    ({}, {"visible": False}, "mocap object 'ardrone' not visible from udp 0.0.0.0:51001 (last pose age "
                             "inf ms)"),
    ({}, {"age_s": 1.0}, "mocap object 'ardrone' not visible from udp 0.0.0.0:51001 (last pose age "
                         "1000 ms)"),
])
def test_refusal_messages_word_for_word(drone_kw, mocap_kw, message):
    if "xyz" not in mocap_kw:
        mocap_kw = {**mocap_kw, "xyz": (1.0, 2.0, 0.0)}
    session, *_ = make(drone_kw, mocap_kw, start=(1.0, 2.0, 1.0))
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value) == message


def test_config_refusal_messages_word_for_word():
    session, *_ = make(drone_kw={"held": {**WRITTEN, **PROFILE, "control:control_yaw": "6.11"}})
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value) == (
        "the drone holds control:control_yaw = '6.11', not the '1.745' written: it did not "
        "keep the write — a drone in another multiconfig session keeps its own limits: set "
        "drone.config_ids to that session (`ardrone-nmpc status` shows its ids and what it "
        "holds), then retry")
    session, *_ = make(drone_kw={"read_error": LinkError("timed out")})
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value) == (
        "the drone's control port 10.0.0.9:5559 did not answer (timed out): the limits it holds "
        "cannot be verified, so no take-off — check drone.control_port, or set "
        "drone.verify_config: false to fly unverified")
    session, _, events, warnings, _ = make(drone_kw={"read_error": LinkError("timed out")},
                                           cfg_sets=["drone.verify_config=false"])
    session.configure()
    line = ("WARNING: flying with UNVERIFIED limits — control port 10.0.0.9:5559 did not answer "
            "(timed out); drone.verify_config is false")
    assert warnings == [line] and events[-1] == ("config_unverified", {"message": line})


def test_the_busy_at_port_is_said_and_logged():
    session, drone, events, warnings, _ = make()
    drone.at_bind_warning = "local UDP port 5556 is busy (in use)"
    with session:
        pass
    assert warnings[0] == "local UDP port 5556 is busy (in use)"
    assert ("at_port_busy", {"message": warnings[0]}) in events


def test_not_ready_names_the_raw_ctrl_state_or_none():
    session, drone, *_ = make(drone_kw={"mode": FlightMode.LANDING})
    real = Drone.navdata.fget
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value) == ("the drone is not landed and ready (mode landing, ctrl_state "
                              "0x00020000): refusing take-off")
    type(drone).navdata = property(lambda self: NavdataSample(
        self.clock(), FlightMode.LANDING, 80.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    try:
        session, *_ = make()
        with pytest.raises(PreflightError, match=r"ctrl_state none\)"):
            session.__enter__()
    finally:
        type(drone).navdata = property(real)


def test_waits_last_as_long_as_they_should():
    # no navdata for 2 s: refused at 2 s
    session, drone, _, _, clock = make()
    drone.nav_gone = (0.0, math.inf)
    t0 = clock()
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value) == "no navdata from the drone" and 2.0 < clock() - t0 < 2.05
    # mocap appearing after 1.9 s is waited for; after 2.1 s it is not
    for after_s, ok in ((1.9, True), (2.1, False)):
        session, drone, _, _, clock = make()
        session.mocap.visible_from = clock() + after_s
        if ok:
            session.preflight()
        else:
            with pytest.raises(PreflightError, match="not visible"):
                session.preflight()
    # navdata gone 0.9 s at the trim is waited for, 1.1 s is not
    for gone_s, ok in ((0.9, True), (1.1, False)):
        session, drone, _, _, clock = make()
        session.configure()
        session.preflight()
        drone.nav_gone = (clock(), clock() + gone_s)
        if ok:
            session.trim()
        else:
            with pytest.raises(PreflightError, match="no navdata"):
                session.trim()


@pytest.mark.parametrize("gap_s, ok", [(0.4, True), (0.6, False)])
def test_after_take_off_mocap_and_navdata_are_waited_for_half_a_second(gap_s, ok):
    for which in ("mocap", "navdata"):
        session, drone, events, _, clock = make(drone_kw={"takeoff_s": 1.0})
        session.configure()
        session.preflight()
        session.trim()
        t = clock()
        gap = (t + 1.0, t + 1.0 + gap_s)  # around the moment it reports flying
        if which == "mocap":
            session.mocap.gone = gap
        else:
            drone.gap_after_flying = gap_s
        if ok:
            session.takeoff()
        else:
            with pytest.raises(PreflightError):
                session.takeoff()


def test_the_take_off_deadline_is_one_for_both_phases():
    session, drone, _, _, clock = make(drone_kw={"never_flies": True})
    session.configure()
    session.preflight()
    session.trim()
    drone._mode = FlightMode.TAKING_OFF  # airborne at once, never flying
    t0 = clock()
    with pytest.raises(RuntimeError) as err:
        session.takeoff()
    assert str(err.value).startswith("take-off did not complete in 10 s (taking_off): ")
    assert 10.0 < clock() - t0 < 10.05
    drone.nav_gone = (clock(), math.inf)
    drone._mode = FlightMode.LANDED
    with pytest.raises(RuntimeError) as err:
        session.takeoff()
    assert str(err.value).startswith("take-off did not complete in 10 s (no navdata): ")


def test_mocap_age_is_in_milliseconds_against_the_hover_limit():
    for age_s, ok in ((0.2499, True), (0.2501, False)):
        session, *_ = make(mocap_kw={"age_s": age_s})
        if ok:
            session.preflight()
        else:
            with pytest.raises(PreflightError, match="last pose age 250 ms"):
                session.preflight()


def test_a_start_position_anywhere_is_checked_relative_to_it():
    session, *_ = make(mocap_kw={"xyz": (-3.0, 1.0, 0.0)}, start=(-3.0, 1.0, 1.0))
    session.preflight()
    session, *_ = make(mocap_kw={"xyz": (0.5, 0.0, 0.5)}, start=(0.0, 0.0, 1.0))
    session.preflight()  # exactly at the tolerance, both horizontally and vertically


@pytest.mark.parametrize("emergency, word", [(False, "land"), (True, "cut")])
def test_operator_requests_while_waiting_for_mocap(emergency, word):
    requests = OperatorRequests()
    session, drone, *_ = make(requests=requests, mocap_kw={"visible_from": math.inf})
    real = session.sleep
    session.sleep = lambda dt: (real(dt), requests.request_emergency() if emergency
                                else requests.request_land())
    with pytest.raises(OperatorAbort) as err:
        session.preflight()
    assert str(err.value) == f"the operator asked to {word} before take-off"
    session, drone, *_ = make(requests=requests)
    drone.nav_gone = (0.0, math.inf)
    with pytest.raises(OperatorAbort) as err:
        session.preflight()
    assert str(err.value) == f"the operator asked to {word} before take-off"




def stepped(**drone_kw):
    session, drone, events, warnings, clock = flying(**drone_kw)
    step = StepClock()
    step.t = 200.0
    for obj in (session, drone, session.mocap):
        obj.clock = step
    session.sleep = step.sleep
    return session, drone, events, warnings, step


def test_a_second_ctrl_c_exactly_2_s_later_still_cuts():
    session, drone, events, warnings, clock = stepped(landing_s=5.0)
    presses = [clock() + 1.0, clock() + 3.0]
    real = session.sleep

    def sleep(dt):
        real(dt)
        if presses and clock() >= presses[0]:
            presses.pop(0)
            raise KeyboardInterrupt
    session.sleep = sleep
    with pytest.raises(KeyboardInterrupt):
        session.land()
    assert "emergency" in drone.calls


def test_navdata_exactly_half_a_second_old_is_fresh():
    session, drone, events, warnings, clock = stepped(landing_s=0.0)
    drone.nav_age_s = lambda t: 0.5
    t0 = clock()
    assert session.land() is True and clock() - t0 == 0.0
    assert warnings == []


def test_an_unconfirmed_cut_is_given_exactly_its_2_s():
    session, drone, events, warnings, clock = stepped(never_lands=True)
    drone.emergency = lambda: drone.calls.append("emergency")
    drone.nav_lost_until = math.inf
    session._cut_motors("test")
    t0 = clock()
    assert session.land() is False and clock() - t0 == 2.25


def test_notices_come_every_3_s_exactly():
    session, drone, events, warnings, clock = stepped(landing_s=6.25)
    t0 = clock()
    session.land()
    assert clock() - t0 == 6.25 and kinds(events).count("landing_wait") == 2  # at 3 s and 6 s
    notice = [f for k, f in events if k == "landing_wait"][0]
    assert notice == {"message": "landing: waiting for the drone to touch down (mode landing, "
                                 "ctrl_state 0x00020000)"}
    session, drone, events, warnings, clock = stepped(landing_s=4.0)
    drone.nav_lost_until = math.inf
    real = session.sleep
    session.sleep = lambda dt: (real(dt), clock() - 200 > 4.0 and
                                setattr(drone, "nav_lost_until", -math.inf))
    session.land()
    lost = [f for k, f in events if k == "landing_navdata_lost"][0]
    assert lost == {"message": "landing: no navdata for 10 s — still sending land (for up to "
                               "10 s without any); watch the drone (Ctrl-C twice within 2 s "
                               "cuts the motors)", "age_s": 10.0}


def test_the_default_warning_goes_to_stderr_and_survives_a_dead_terminal(capsys, monkeypatch):
    from ardrone_nmpc.runtime import session as session_module

    session_module._stderr("hello operator")
    assert capsys.readouterr().err == "hello operator\n"

    class Dead:
        def write(self, text):
            raise OSError(5, "Input/output error")

        def flush(self):
            raise OSError(5, "Input/output error")

    monkeypatch.setattr("sys.stderr", Dead())
    session_module._stderr("nobody hears this")  # no exception


def test_wait_deadlines_are_exclusive():
    session, drone, _, _, clock = make(clock=StepClock())
    drone.nav_gone = (0.0, math.inf)
    t0 = clock()
    with pytest.raises(PreflightError):
        session.preflight()
    assert clock() - t0 == 2.25  # 2.0 is still inside the wait
    session, drone, _, _, clock = make(mocap_kw={"visible": False}, clock=StepClock())
    t0 = clock()
    with pytest.raises(PreflightError):
        session.preflight()
    assert clock() - t0 == 2.25
    session, drone, _, _, clock = make(drone_kw={"never_flies": True}, clock=StepClock())
    session.configure()
    session.preflight()
    t_trim = clock()
    session.trim()
    assert clock() - t_trim == 0.5  # FTRIM, then exactly 0.5 s
    t0 = clock()
    with pytest.raises(RuntimeError):
        session.takeoff()
    assert clock() - t0 == 10.25


def test_a_pose_exactly_at_the_hover_age_is_visible_and_exactly_tolerated_offset_passes():
    session, *_ = make(mocap_kw={"age_s": 0.25}, clock=StepClock())
    session.preflight()
    session, drone, events, _, _ = make(mocap_kw={"psi": (0.0, 0.25)},
                                        cfg_sets=["safety.heading_tolerance_rad=0.25"])
    session.__enter__()
    assert dict(events)["heading_check"]["offset_rad"] == 0.25


def test_landing_notice_with_navdata_exactly_half_a_second_old_is_a_wait_notice():
    session, drone, events, warnings, clock = stepped(landing_s=3.25)
    drone.nav_age_s = lambda t: 0.5
    session.land()
    assert kinds(events).count("landing_wait") == 1 and "landing_navdata_lost" not in kinds(events)


def test_foreign_senders_are_listed():
    session, *_ = make(mocap_kw={"visible": False})
    session.mocap.foreign_senders = {"10.0.0.7:9999": 120, "10.0.0.8:1": 3}
    with pytest.raises(PreflightError) as err:
        session.preflight()
    assert str(err.value).endswith("; frames from other senders ignored: 10.0.0.7:9999, "
                                   "10.0.0.8:1")


def test_take_off_messages_word_for_word():
    requests = OperatorRequests()
    session, drone, *_ = make(requests=requests, drone_kw={"never_flies": True})
    session.configure()
    session.preflight()
    session.trim()
    requests.request_land()
    with pytest.raises(OperatorAbort) as err:
        session.takeoff()
    assert str(err.value) == "the operator asked to land during take-off"
    session, drone, *_ = make(drone_kw={"never_flies": True})
    drone.self_landing = "the drone touched down (state bit 0 cleared); ctrl_state 0x00020000"
    with pytest.raises(DroneLandedItself) as err:
        session.__enter__()
    assert str(err.value) == ("take-off: the drone touched down (state bit 0 cleared); "
                              "ctrl_state 0x00020000")
    session, drone, *_ = make(drone_kw={"yaw": (0.0, 0.0)}, mocap_kw={"psi": (0.0, 0.5)})
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value) == (
        "during take-off the mocap heading turned +28.6° and navdata's yaw +0.0° (offset +28.6°,"
        " safety.heading_tolerance_rad 11.5°): the mocap object's frame does not match the "
        "drone — landing; fix the object (x forward, z up) before flying")


@pytest.mark.parametrize("which", ["mocap", "navdata"])
@pytest.mark.parametrize("gap_s, ok", [(0.4, True), (0.6, False)])
def test_at_the_first_airborne_sample_mocap_and_navdata_get_half_a_second(which, gap_s, ok):
    session, drone, *_ = make(drone_kw={"takeoff_s": 2.0})
    session.configure()
    session.preflight()
    session.trim()
    if which == "mocap":
        session.mocap.gone = (session.clock(), session.clock() + gap_s)
    else:
        drone.gap_after_airborne = gap_s
    if ok:
        session.takeoff()
    else:
        with pytest.raises(PreflightError):
            session.takeoff()


def test_preflight_waits_for_fresh_navdata_and_refuses_a_silent_drone():
    """A sample from before the link went silent is no check of the drone: the preflight
    waits for fresh navdata, and refuses when none comes."""
    session, drone, events, _, _ = make({}, {})
    drone.nav_age_s = lambda t: 5.0  # the newest sample is 5 s old, and stays so
    with pytest.raises(PreflightError, match="no fresh navdata from the drone"):
        session.__enter__()
    assert "takeoff" not in drone.calls and "flat_trim" not in drone.calls


# ----------------------------------------------------------------------------- issue 21
# The drone's own alarms, navdata freshness from the first take-off REF to the last landing
# REF, a landing confirmed by any packet and bounded without one, the operator's emergency.

def test_preflight_refuses_a_drone_reporting_fault_bits_naming_them():
    session, drone, events, *_ = make()
    drone.state_bits = 1 << 22 | 1 << 21
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value).startswith("the drone reports CUTOUT (state bit 22: motor cut-out "
                                     "detected), ULTRASOUND (state bit 21: ")
    assert "takeoff" not in drone.calls and "flat_trim" not in drone.calls
    assert "land" not in drone.calls and not session.lock.held
    assert ("drone_faults", {"phase": "preflight", "bits": ["CUTOUT", "ULTRASOUND"]}) in events
    session, drone, *_ = make()
    drone.state_bits = 1 << 18 | 1 << 13      # calibration wanted, com lost: no fault
    with session:
        pass
    assert "takeoff" in drone.calls


def test_no_take_off_on_navdata_that_went_stale_during_the_trim_wait():
    session, drone, events, _, clock = make()
    drone.nav_age_s = lambda t: 0.6 if drone.calls[-1:] == ["flat_trim"] else 0.0
    with pytest.raises(PreflightError, match=r"no fresh navdata before take-off \(the newest is "
                                             r"600 ms old, safety.navdata_land_ms 500 ms\)"):
        session.__enter__()
    assert "takeoff" not in drone.calls and "land" not in drone.calls


def test_navdata_lost_during_take_off_fails_it_in_half_a_second_and_lands():
    session, drone, events, warnings, clock = make()
    drone.nav_age_s = lambda t: (0.0 if drone.t_takeoff is None or t < drone.t_takeoff + 0.3
                                 else 0.0 if t > drone.t_takeoff + 2.0
                                 else t - (drone.t_takeoff + 0.3))
    with pytest.raises(TakeoffFailed) as err:
        session.__enter__()
    assert str(err.value).startswith("take-off failed: navdata lost (none for 5")
    assert "safety.navdata_land_ms 500 ms) — landing" in str(err.value)
    assert drone.calls[-2:] == ["takeoff", "land"]
    assert 0.8 <= drone.t_land - drone.t_takeoff <= 0.85   # 0.3 s flowing + 0.5 s lost
    assert session.landed_cleanly is True                  # navdata came back: confirmed
    assert ("landing", {"reason": "TakeoffFailed"}) in events and not session.lock.held


@pytest.mark.parametrize("bit, cut", [(14, False), (15, False), (12, True), (22, True)])
def test_a_fault_bit_during_take_off_ends_it_by_a_landing_or_a_cut(bit, cut):
    session, drone, events, warnings, clock = make(drone_kw={"takeoff_s": 3.0})
    real = session.sleep

    def sleep(dt):
        real(dt)
        if drone.t_takeoff is not None and clock() - drone.t_takeoff > 1.0:
            drone.state_bits = 1 << bit
    session.sleep = sleep
    with pytest.raises(CutMotors if cut else TakeoffFailed) as err:
        session.__enter__()
    assert f"(state bit {bit}: " in str(err.value)
    assert str(err.value).endswith("cutting the motors" if cut else "landing")
    assert ("emergency" in drone.calls) is cut and ("land" in drone.calls) is not cut
    assert session.landed_cleanly is True
    assert dict(events)["drone_faults"]["phase"] == "takeoff"


def test_a_landing_is_confirmed_by_bootstrap_packets_alone():
    session, drone, events, warnings, clock = flying(landing_s=2.0)
    drone.bootstrap_only = True            # the stream fell back to bootstrap: no demo sample
    t0 = clock()
    assert session.land() is True
    assert 2.0 <= clock() - t0 < 2.1 and kinds(events)[-1] == "landed"


def test_a_landing_without_any_navdata_ends_after_the_blind_bound():
    from ardrone_nmpc.runtime.schedule import BLIND_LANDING_S

    session, drone, events, warnings, clock = flying(never_lands=True)
    drone.state_bits = 0x1
    drone.silent_since = clock() - 0.7     # the link died before the landing began
    t0 = clock()
    assert session.land() is False and session.landed_cleanly is False
    assert BLIND_LANDING_S < clock() - t0 < BLIND_LANDING_S + 0.05  # from the first land REF
    failed = dict(events)["landing_failed"]
    assert failed["error"] == "no navdata for 10 s while landing"
    assert failed["last_mode"] == "flying" and failed["last_state"] == 1
    assert failed["last_age_s"] == pytest.approx(BLIND_LANDING_S + 0.7, abs=0.05)
    assert "landed" not in kinds(events)


def test_a_blind_landing_never_ends_while_packets_arrive():
    session, drone, events, warnings, clock = flying(never_lands=True)
    drone.bootstrap_only = True             # no demo sample, but the state word arrives
    real = session.sleep
    t0 = clock()
    session.sleep = lambda dt: (real(dt), clock() - t0 > 60.0
                                and setattr(drone, "never_lands", False))
    assert session.land() is True and clock() - t0 > 60.0


def test_a_ctrl_c_during_a_blind_landing_does_not_hang_it():
    session, drone, events, warnings, clock = flying(never_lands=True)
    drone.silent_since = clock()
    real = session.sleep
    presses = [clock() + 1.0]

    def sleep(dt):
        real(dt)
        if presses and clock() >= presses[0]:
            presses.pop()
            raise KeyboardInterrupt
    session.sleep = sleep
    with pytest.raises(KeyboardInterrupt):
        session.land()
    assert session.landed_cleanly is False and "emergency" not in drone.calls


@pytest.mark.parametrize("operator_cut_acts", [True, False])
@pytest.mark.parametrize("where", ["flight", "landing"])
def test_the_emergency_command_holds_the_cut_instead_of_landing(where, operator_cut_acts):
    """SIGUSR2: the operator's own link made the edge; the session holds bit 8 low (REF land:
    a second edge would undo the cut) and makes its own edge only if navdata has not shown
    the cut within 2 s."""
    from ardrone_nmpc.runtime.session import EMERGENCY_CONFIRM_S
    from ardrone_nmpc.runtime.signals import EMERGENCY_SIGNAL, EmergencyRequested

    session, drone, events, warnings, clock = flying(landing_s=50.0)
    signal_in = EmergencyRequested(EMERGENCY_SIGNAL)

    def operator_cuts():
        if operator_cut_acts:
            drone._mode = FlightMode.EMERGENCY      # the operator's edge reached the drone
    t0 = clock()
    if where == "flight":
        operator_cuts()
        assert session.__exit__(EmergencyRequested, signal_in, None) is False
    else:
        real = session.sleep
        raised = []

        def sleep(dt):
            real(dt)
            if not raised:
                raised.append(1)
                operator_cuts()
                raise signal_in
        session.sleep = sleep
        with pytest.raises(EmergencyRequested):
            session.land()
    after = drone.calls[drone.calls.index("takeoff") + 1:]
    assert ("emergency", {"reason": "the operator's `emergency` command (SIGUSR2)"}) in events
    assert warnings[-1] == ("cutting the motors (emergency): the operator's `emergency` "
                            "command (SIGUSR2)")
    assert session.landed_cleanly is True and dict(events)["landed"] == {"mode": "emergency"}
    if operator_cut_acts:
        assert "emergency" not in after and clock() - t0 < 0.1
    else:                                         # its own edge, once, after 2 s
        assert after.count("emergency") == 1 and after[-1] == "emergency"
        assert EMERGENCY_CONFIRM_S < clock() - t0 < EMERGENCY_CONFIRM_S + 0.1


def test_a_motor_fault_in_flight_cuts_through_the_sessions_exit():
    session, drone, events, warnings, clock = flying()
    err = CutMotors("the supervisor cut the motors: stop-cutout")
    assert session.__exit__(CutMotors, err, None) is False
    assert drone.calls[-1] == "emergency" and "land" not in drone.calls[-2:]
    assert ("landing", {"reason": "CutMotors"}) in events
    assert session.landed_cleanly is True


# ----------------------------------------------------------------------------- issue 21, exact
def on_step_clock(session, drone, t=200.0):
    step = StepClock()
    step.t = t
    for obj in (session, drone, session.mocap):
        obj.clock = step
    session.sleep = step.sleep
    return step


def test_take_off_failure_messages_word_for_word():
    session, drone, events, _, _ = make(cfg_sets=["safety.navdata_land_ms=1000"],
                                        drone_kw={"takeoff_s": 3.0})
    session.configure()
    session.preflight()
    session.trim()
    clock = on_step_clock(session, drone)
    drone.nav_age_s = lambda t: 0.0 if t < clock.t0 + 0.5 else t - (clock.t0 + 0.5)
    clock.t0 = clock.t
    with pytest.raises(TakeoffFailed) as err:
        session.takeoff()
    assert str(err.value) == ("take-off failed: navdata lost (none for 1250 ms, "
                              "safety.navdata_land_ms 1000 ms) — landing; check the Wi-Fi "
                              "link (docs/first-flight.md §3)")
    session, drone, events, _, _ = make(drone_kw={"never_flies": True})
    session.configure()
    session.preflight()
    session.trim()
    with pytest.raises(TakeoffFailed) as err:
        session.takeoff()
    assert str(err.value) == ("take-off did not complete in 10 s (landed): the drone never "
                              "showed flying — landing; check battery, propellers and hull")


def test_navdata_exactly_at_the_limit_is_fresh_for_the_take_off():
    session, drone, events, _, _ = make()
    session.configure()
    session.preflight()
    clock = on_step_clock(session, drone)
    drone.nav_age_s = lambda t: 0.5                       # exactly safety.navdata_land_ms
    session.trim()                                         # no refusal at 0.5 s …
    drone.nav_age_s = lambda t: 0.5 if t < clock.t + 0.5 else 0.0
    session.takeoff()                                      # … nor during the take-off
    assert "takeoff" in drone.calls
    drone._mode = FlightMode.LANDED
    drone.t_takeoff = None
    drone.nav_age_s = lambda t: 0.75 if drone.calls[-1] == "flat_trim" else 0.0
    with pytest.raises(PreflightError) as err:
        session.trim()
    assert str(err.value) == ("no fresh navdata before take-off (the newest is 750 ms old, "
                              "safety.navdata_land_ms 500 ms): no take-off")
    session, drone, *_ = make(cfg_sets=["safety.navdata_land_ms=1000"])
    session.configure()
    session.preflight()
    on_step_clock(session, drone)
    drone.nav_age_s = lambda t: 1.25 if drone.calls[-1] == "flat_trim" else 0.0
    with pytest.raises(PreflightError, match=r"is 1250 ms old, safety.navdata_land_ms 1000 ms"):
        session.trim()


def test_a_fault_during_take_off_is_one_line_naming_bit_mode_and_ctrl_state():
    session, drone, events, warnings, clock = make(drone_kw={"takeoff_s": 3.0})
    session.configure()
    session.preflight()
    session.trim()
    real = session.sleep

    def sleep(dt):
        real(dt)
        if clock() - drone.t_takeoff > 1.0:
            drone.state_bits = 1 << 14 | 1 << 21
    session.sleep = sleep
    with pytest.raises(TakeoffFailed) as err:
        session.takeoff()
    assert str(err.value) == ("take-off failed: the drone reports SOFTWARE_FAULT (state bit 14: "
                              "software fault, land as soon as possible) (mode taking_off, "
                              "ctrl_state 0x00020000) — landing")
    assert ("drone_faults", {"phase": "takeoff", "bits": ["SOFTWARE_FAULT", "ULTRASOUND"]}) \
        in events


def test_the_second_sender_refusal_word_for_word():
    session, *_ = make(mocap_kw={"contenders": ["127.0.0.1:40000", "127.0.0.1:40001"]})
    with pytest.raises(PreflightError) as err:
        session.__enter__()
    assert str(err.value) == (
        "mocap object 'ardrone' comes from more than one sender: the link took 10.0.0.2:4000, "
        "127.0.0.1:40000, 127.0.0.1:40001 also sends it — stop the other stream (a replay "
        "--broadcast?) before flying")
