"""FlightSession against a scripted drone on a fake clock: verification, preflight refusals,
trim timing, take-off (and landing after it fails), the heading check, and a landing that never
gives up. Fast and deterministic (no sockets); the same paths against a drone stand-in over
real UDP are in tests/integration/test_session_standin.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.config.schema import load_config
from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample
from ardrone_nmpc.links.drone_config import LinkError
from ardrone_nmpc.runtime.operator_input import OperatorAbort, OperatorRequests
from ardrone_nmpc.runtime.session import (
    NOTICE_EVERY_S,
    TRIM_TO_TAKEOFF_S,
    DroneLandedItself,
    FlightSession,
    PreflightError,
)
from ardrone_nmpc.runtime.signals import Terminated

WRITTEN = {"control:euler_angle_max": "0.2094", "control:control_vz_max": "700",
           "control:control_yaw": "1.745", "control:altitude_max": "3000"}
PROFILE = {"control:outdoor": "FALSE", "control:flight_without_shell": "FALSE",
           "control:flying_mode": "0"}


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t

    def sleep(self, dt):
        self.t += dt


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
        self.self_landing = None
        self.connected = True
        self.at_bind_warning = None
        self.land_errors: list[Exception] = []

    def connect(self, timeout_s):
        self.calls.append("connect")

    def configure_limits(self, **kw):
        self.calls.append("configure_limits")
        return dict(WRITTEN)

    def configure_profile(self, *, flight_without_shell):
        self.calls.append(f"profile:{flight_without_shell}")
        return dict(PROFILE, **{"control:flight_without_shell":
                                "TRUE" if flight_without_shell else "FALSE"})

    def read_config(self, timeout_s):
        self.calls.append("read_config")
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
        mode = self.mode
        yaw = self.yaw[1] if mode is FlightMode.FLYING else self.yaw[0]
        return NavdataSample(self.clock(), mode, self.battery, self.roll, self.pitch, yaw,
                             0.0, 0.0, 0.0, 0.0, ctrl_state=0x20000)

    @property
    def navdata_rx_t_s(self):
        t = self.clock()
        return t - 10.0 if t < self.nav_lost_until else t


class Mocap:
    port, sender = 51001, "10.0.0.2:4000"

    def __init__(self, clock, drone=None, xyz=(0.0, 0.0, 0.0), psi=(0.0, 0.0), visible=True):
        self.clock, self.drone, self.xyz, self.psi, self.visible = clock, drone, xyz, psi, visible
        self.foreign_senders = {}

    def latest(self):
        if not self.visible:
            return None, -math.inf
        flying = self.drone is not None and self.drone.mode is FlightMode.FLYING
        pose = MocapPose(self.clock(), np.array(self.xyz, dtype=float), np.zeros(3),
                         self.psi[1] if flying else self.psi[0])
        return pose, self.clock()


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
         event=None):
    clock = Clock()
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
        assert drone.calls == ["connect", "configure_limits", "profile:False", "read_config",
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
    assert "power-cycle" in msg and "more key" not in msg
    assert "takeoff" not in drone.calls and "flat_trim" not in drone.calls
    assert "land" not in drone.calls  # nothing that could start the motors went out
    assert ("config_mismatch", {"key": "control:euler_angle_max", "written": "0.2094",
                                "held": "0.52"}) in events
    assert not session.lock.held


def test_several_differences_are_counted_and_a_missing_key_is_one():
    held = {**WRITTEN, **PROFILE, "control:control_vz_max": "2000"}
    del held["control:flying_mode"]
    session, drone, events, _, _ = make(drone_kw={"held": held})
    with pytest.raises(PreflightError, match=r"control:control_vz_max.*and 1 more key"):
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
    ({}, {"visible": False}, r"mocap object 'ardrone' not visible on port 51001"),
    ({}, {"xyz": (0.51, 0.0, 0.0)}, r"0\.51 m from the experiment's start: mocap \(\+0\.51, "
                                    r"\+0\.00\) m, start \(\+0\.00, \+0\.00\)"),
    ({}, {"xyz": (0.0, -0.6, 0.0)}, r"0\.60 m from the experiment's start"),
    ({}, {"xyz": (0.4, 0.31, 0.0)}, r"0\.51 m from"),
    ({}, {"xyz": (0.0, 0.0, 0.6)}, r"at z = \+0\.60 m"),
    ({}, {"xyz": (0.0, 0.0, -0.6)}, r"at z = -0\.60 m"),
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
    with pytest.raises(RuntimeError, match=r"take-off did not complete in 10 s \(landed\)"):
        session.__enter__()
    assert clock() - t0 >= FlightSession.TAKEOFF_TIMEOUT_S
    assert drone.calls.index("takeoff") < drone.calls.index("land")
    assert session.landed_cleanly is True
    assert ("landing", {"reason": "RuntimeError"}) in events and "landed" in kinds(events)
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
