"""The supervisor (docs/design.md §2): between the controller and the mapping, it decides what flies.

Every tick it looks at the feedback (ages of the mocap pose and of navdata, the drone's state
bits and battery), at the state estimate (finite, inside the geofence, not too fast, not too
tilted) and at the controller's solution (solver status, finite values) and returns a
:class:`Decision`: fly the controller's command, hold the last good command, fly the P
controller instead, hover (AT*PCMD flag 0: the drone's own position hold), land, or stop (the
drone reports an emergency: nothing more is sent).

Policies (``safety`` config section, :class:`~ardrone_nmpc.config.schema.SafetyConfig`):

=====================================  ==========================================================
condition                              action
=====================================  ==========================================================
drone in emergency (navdata)           ``stop`` (latched; reported)
CUTOUT or MOTORS fault bit (navdata)   ``stop`` (latched; the runner cuts the motors)
battery ≤ ``battery_floor_pct``        ``land`` (latched)
SOFTWARE_FAULT or VBAT_LOW bit         ``land`` (latched)
navdata age > ``navdata_land_ms``      ``land`` (latched)
mocap age > ``mocap_land_ms``          ``land`` (latched)
mocap age > ``mocap_hover_ms``         ``hover``
mocap age > ``mocap_hold_ms``          ``hold`` the last command sent
state estimate not finite              ``hover``
position outside the geofence          ``geofence_action`` (``land`` latched, or ``hover``)
speed > ``max_speed_mps``              ``hover`` (the drone brakes itself)
measured tilt > ``max_tilt_rad``       ``hover``
solver failed (below)                  ``hold`` for ``solver_hold_ticks``, then
                                       ``solver_fallback``: ``p`` (P controller), ``hover``, or
                                       ``hold`` (then ``hover`` after ``solver_hover_ticks``);
                                       the NMPC flies again after ``solver_recover_ticks`` good
                                       solves in a row
commanded tilt > ``max_tilt_rad``      clipped (flagged in ``cmd_saturated``)
=====================================  ==========================================================

Every comparison is written so that a NaN fails it: a non-finite age, battery level, tilt or
estimate is a breach of its check, never a pass (``max(abs(nan), 1.0) > cap`` is False).

The fault bits are those of the navdata state word (:data:`DRONE_ALARMS`, docs/protocol.md
§4.2), read when the sample carries one; :func:`takeoff_refusal` is the pre-flight side of the
same table (every fault bit there refuses a take-off).

A solve *failed* when its status is ``diverged`` or ``non-finite``, when its input is not finite,
or when it is ``max-iterations`` and ``solver_accept_max_iterations`` is false.

Precedence is the table's order: the first condition that holds wins. ``land`` and ``stop``
latch: once decided, they stay until the run ends. Every change of mode is an event (``kind``
``"mode"``, with the reason) that the runner writes to ``events.jsonl``; the mode is the log's
``mode`` column and the dashboard's.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from numpy import ndarray as _NDARRAY

from ardrone_nmpc.core.modes import Mode
from ardrone_nmpc.core.types import FlightMode, NavdataSample

__all__ = ["ALARM_BITS", "Action", "DRONE_ALARMS", "Decision", "DroneAlarm", "Supervisor",
           "drone_alarms", "takeoff_refusal"]


class Action(str, enum.Enum):
    """What the tick does with the drone."""

    CONTROL = "control"    # fly the controller's command
    HOLD = "hold"          # resend the last command sent
    FALLBACK = "fallback"  # fly the P controller's command
    HOVER = "hover"        # PCMD flag 0: the drone holds its position itself
    LAND = "land"          # land now (the runner commands it)
    STOP = "stop"          # the drone is in emergency: send nothing, report


# bound once: an enum member's lookup goes through the enum's metaclass (~0.1 µs a tick)
_CONTROL, _EMERGENCY = Action.CONTROL, FlightMode.EMERGENCY

#: Actions after which the run does not go back to flying the experiment.
LATCHING = frozenset({Action.LAND, Action.STOP})


@dataclass(frozen=True, slots=True)
class Decision:
    """The supervisor's verdict for one tick: ``action`` and why (``reason``; "" if nominal).

    ``mode`` is the log's ``mode`` label: ``"<action>-<reason>"`` (``hold-stale-mocap``,
    ``fallback-solver``, ``land-geofence``, …) or the nominal label the runner gave.
    """

    action: Action
    reason: str = ""

    def mode(self, nominal: str) -> str:
        if self.action is _CONTROL:
            return nominal
        return Mode(self.action.value, self.reason).label


NOMINAL = Decision(Action.CONTROL)


@dataclass(frozen=True, slots=True)
class DroneAlarm:
    """A fault bit of the drone's navdata state word (``def_ardrone_state_mask_t``).

    ``in_flight`` is what the supervisor does when it is set airborne: ``stop`` (the runner
    cuts the motors: a motor that cut out or fails cannot be flown on), ``land``, or None
    (reported before take-off only). Every fault bit refuses a take-off.
    """

    bit: int
    name: str
    meaning: str
    in_flight: Action | None

    @property
    def mask(self) -> int:
        return 1 << self.bit

    @property
    def reason(self) -> str:
        """The supervisor's reason label (``cutout``, ``software-fault``, …)."""
        return self.name.lower().replace("_", "-")

    def line(self) -> str:
        """``NAME (state bit N: meaning)``."""
        return f"{self.name} (state bit {self.bit}: {self.meaning})"


#: The fault bits the tool acts on, most severe first (docs/protocol.md §4.2; ARDroneLib
#: config.h). COM_LOST (13) is not among them: it reports the link this packet just crossed.
DRONE_ALARMS: tuple[DroneAlarm, ...] = (
    DroneAlarm(22, "CUTOUT", "motor cut-out detected", Action.STOP),
    DroneAlarm(12, "MOTORS", "motor problem", Action.STOP),
    DroneAlarm(14, "SOFTWARE_FAULT", "software fault, land as soon as possible", Action.LAND),
    DroneAlarm(15, "VBAT_LOW", "battery too low for the firmware", Action.LAND),
    DroneAlarm(21, "ULTRASOUND", "ultrasound sensor deaf", None),
)

#: Every bit of :data:`DRONE_ALARMS` in one mask (the supervisor's and ``runtime/before_solve``'s).
ALARM_BITS = sum(f.mask for f in DRONE_ALARMS)


def drone_alarms(state_bits: int | None) -> list[DroneAlarm]:
    """The :data:`DRONE_ALARMS` set in ``state_bits`` (none for None), most severe first."""
    if state_bits is None or not state_bits & ALARM_BITS:  # the usual tick: none set
        return []
    return [f for f in DRONE_ALARMS if state_bits & f.mask]


def takeoff_refusal(state_bits: int | None) -> str | None:
    """One line naming every fault bit set in ``state_bits`` (None when there is none): the
    drone reports a fault, so nothing takes off."""
    faults = drone_alarms(state_bits)
    if not faults:
        return None
    return ("the drone reports " + ", ".join(f.line() for f in faults)
            + ": refusing take-off — check the drone (`ardrone-nmpc status`)")


class Supervisor:
    """Stateful policy of :mod:`ardrone_nmpc.safety` for one flight.

    Parameters
    ----------
    safety : :class:`~ardrone_nmpc.config.schema.SafetyConfig`.

    Attributes
    ----------
    events : list of dict
        Mode changes since the last :meth:`take_events` (``{"kind": "mode", "mode": …,
        "previous": …, "reason": …}``); the runner stamps and writes them.
    """

    def __init__(self, safety) -> None:
        self.cfg = safety
        self._latched: Decision | None = None
        self._solver_failures = 0   # consecutive failed solves
        self._solver_good = 0       # consecutive good solves while in a solver fallback
        self._solver_fallback = False
        #: The mode label of the last tick :meth:`record` noted ("" before the first): a
        #: nominal tick of the same label changes nothing (the tick skips the call then).
        self.label = ""
        self.events: list[dict] = []

    @property
    def cfg(self):
        """The :class:`~ardrone_nmpc.config.schema.SafetyConfig` it enforces."""
        return self._cfg

    @cfg.setter
    def cfg(self, safety) -> None:
        self._cfg = safety
        # the limits every tick's checks read, unpacked once (attribute lookups cost µs a tick)
        self._fence_lo = tuple(safety.geofence_min_m)
        self._fence_hi = tuple(safety.geofence_max_m)
        #: The commanded roll/pitch cap (rad, ``max_tilt_rad``): :meth:`clip_tilt_rad`'s, and
        #: what the supervision clips to every tick.
        self.max_tilt_rad = safety.max_tilt_rad
        self._tilt_cap_deg = math.degrees(safety.max_tilt_rad)
        self._max_speed_mps = safety.max_speed_mps
        self._battery_floor_pct = safety.battery_floor_pct
        self._navdata_land_ms = safety.navdata_land_ms
        # an age within the smallest mocap limit passes all three; a NaN limit (no validated
        # config has one) fails every age, so then none passes without the chain
        mocap_ms = (safety.mocap_hold_ms, safety.mocap_hover_ms, safety.mocap_land_ms)
        self._mocap_nominal_ms = (-math.inf if any(v != v for v in mocap_ms)
                                  else min(mocap_ms))

    # ------------------------------------------------------------------ the three checks
    def check_feedback(self, *, mocap_age_ms: float, navdata_age_ms: float,
                       navdata: NavdataSample | None) -> Decision:
        """Before estimation: may the tick use the measurements at all? (Its usual tick's
        compiled twin, the nominal tick's: ``runtime/before_solve.py``, kept equal by
        ``tests/unit/test_before_solve.py``.)"""
        if self._latched is None and navdata is not None:
            # the usual tick: no emergency, no fault bit, battery above the floor, both ages
            # within their limits — what the chain below answers NOMINAL to, in one test
            bits = navdata.state_bits
            if (navdata.mode is not _EMERGENCY and (bits is None or not bits & ALARM_BITS)
                    and navdata.battery_pct > self._battery_floor_pct
                    and navdata_age_ms <= self._navdata_land_ms
                    and mocap_age_ms <= self._mocap_nominal_ms):
                return NOMINAL
        return self._feedback_chain(mocap_age_ms, navdata_age_ms, navdata)

    def _feedback_chain(self, mocap_age_ms: float, navdata_age_ms: float,
                        navdata: NavdataSample | None) -> Decision:
        """:meth:`check_feedback`, every condition in the table's order."""
        if self._latched is not None:
            return self._latched
        cfg = self.cfg
        if navdata is not None:
            if navdata.mode is _EMERGENCY:
                return self._latch(Decision(Action.STOP, "emergency"))
            bits = navdata.state_bits
            # drone_alarms' own test first: the usual tick has no fault bit, and no call
            faults = drone_alarms(bits) if bits is not None and bits & ALARM_BITS else ()
            for fault in faults:
                if fault.in_flight is Action.STOP:
                    return self._latch(Decision(Action.STOP, fault.reason))
            if not navdata.battery_pct > cfg.battery_floor_pct:
                return self._latch(Decision(Action.LAND, "battery"))
            for fault in faults:
                if fault.in_flight is Action.LAND:
                    return self._latch(Decision(Action.LAND, fault.reason))
        if not navdata_age_ms <= cfg.navdata_land_ms:  # NaN/inf (never received) included
            return self._latch(Decision(Action.LAND, "navdata-lost"))
        if not mocap_age_ms <= cfg.mocap_land_ms:
            return self._latch(Decision(Action.LAND, "mocap-lost"))
        if not mocap_age_ms <= cfg.mocap_hover_ms:
            return Decision(Action.HOVER, "stale-mocap")
        if not mocap_age_ms <= cfg.mocap_hold_ms:
            return Decision(Action.HOLD, "stale-mocap")
        return NOMINAL

    def check_state(self, x, navdata: NavdataSample | None) -> Decision:
        """After estimation: is the state estimate usable, and is the drone where it may be?

        ``x`` is the (7,) estimate ``[x, ẋ, y, ẏ, z, ż, ψ]``. Its compiled twin, the nominal
        tick's: ``runtime/before_solve.py`` (kept equal: ``tests/unit/test_before_solve.py``).
        """
        # floats: numpy's scalars are slow (the class test first: hasattr costs more)
        xs = x.tolist() if x.__class__ is _NDARRAY or hasattr(x, "tolist") else x
        total = sum(xs)  # finite only if every one is (or, rarely, all are and the sum is not)
        if not (total - total == 0.0 or all(map(math.isfinite, xs))):
            return Decision(Action.HOVER, "nonfinite-state")
        lo, hi = self._fence_lo, self._fence_hi
        if not (lo[0] <= xs[0] <= hi[0] and lo[1] <= xs[2] <= hi[1] and lo[2] <= xs[4] <= hi[2]):
            if self.cfg.geofence_action == "land":
                return self._latch(Decision(Action.LAND, "geofence"))
            return Decision(Action.HOVER, "geofence")
        # ``** 2`` (the C library's pow, as numpy's scalars do), not v * v: the same bits
        if not math.sqrt(xs[1] ** 2 + xs[3] ** 2 + xs[5] ** 2) <= self._max_speed_mps:
            return Decision(Action.HOVER, "speed")
        if navdata is not None:
            cap_deg = self._tilt_cap_deg  # |v| <= cap as -cap <= v <= cap: no abs() calls
            if not (-cap_deg <= navdata.roll_deg <= cap_deg
                    and -cap_deg <= navdata.pitch_deg <= cap_deg):
                return Decision(Action.HOVER, "tilt")
        return NOMINAL

    def check_solution(self, ok: bool, u) -> Decision:
        """After the NMPC: fly it, hold, fall back or hover (the solver-failure chain).

        ``ok`` is the solver's status; ``u`` its (4,) input (checked for finiteness here too:
        the supervisor never trusts the solver to have done so). The nominal verdict has a
        compiled twin, ``runtime/after_solve.py`` (kept equal: ``tests/unit/test_after_solve.py``).
        """
        if ok:
            us = u.tolist() if u.__class__ is _NDARRAY or hasattr(u, "tolist") else u
            total = sum(us)  # finite only if every one is (check_state's test)
            good = total - total == 0.0 or all(map(math.isfinite, us))
        else:
            good = False
        if good:
            self._solver_failures = 0
            if not self._solver_fallback:
                return NOMINAL
            self._solver_good += 1
            if self._solver_good >= self.cfg.solver_recover_ticks:
                self._solver_fallback = False
                return NOMINAL
        else:
            self._solver_failures += 1
            self._solver_good = 0
            if self._solver_failures <= self.cfg.solver_hold_ticks and not self._solver_fallback:
                return Decision(Action.HOLD, "solver")
            self._solver_fallback = True
        # in the fallback: until the NMPC has been good long enough
        cfg = self.cfg
        policy = cfg.solver_fallback
        if policy == "p":
            return Decision(Action.FALLBACK, "solver")
        if policy == "hold" and self._solver_failures <= cfg.solver_hover_ticks:
            return Decision(Action.HOLD, "solver")
        return Decision(Action.HOVER, "solver")

    def clip_tilt_rad(self, angle_rad: float) -> tuple[float, bool]:
        """A commanded roll/pitch clipped to ``±max_tilt_rad``, and whether it was."""
        cap = self.max_tilt_rad
        if angle_rad > cap:
            return cap, True
        if angle_rad < -cap:
            return -cap, True
        return angle_rad, False

    # ------------------------------------------------------------------ mode bookkeeping
    def record(self, decision: Decision, nominal: str) -> str:
        """Note the tick's final decision; return its mode label (an event if it changed).

        The one home of the usual tick's test (``Tick.step``, ``Tick._nominal_cells`` call
        this every tick): a control verdict of the label noted last notes nothing.
        """
        # Decision.mode's nominal case without its call (the usual tick)
        mode = nominal if decision.action is _CONTROL else decision.mode(nominal)
        if mode != self.label:
            # the settle → track switch is the runner's schedule, not a supervisor event
            if not (decision.action is Action.CONTROL and self.label in ("", "settle", "track")):
                self.events.append({"kind": "mode", "mode": mode, "previous": self.label,
                                    "action": decision.action.value, "reason": decision.reason})
            self.label = mode
        return mode

    def take_events(self) -> list[dict]:
        """The mode-change events since the last call (and forget them)."""
        events, self.events = self.events, []
        return events

    @property
    def latched(self) -> Decision | None:
        """The ``land``/``stop`` decision the run is bound to, if any."""
        return self._latched

    def _latch(self, decision: Decision) -> Decision:
        self._latched = decision
        return decision
