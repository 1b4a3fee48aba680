"""A flight session: lock → connect → configure and verify → preflight → trim → take off
(``__enter__``) … land (``__exit__``).

It trusts nothing it has not seen: the limits the drone *holds* (read back over its control
port, not the ACK of the write), the drone on the ground and level before the flat trim, the
mocap pose where the experiment starts, and the mocap heading turning with navdata's yaw
during take-off (a wrong object frame is the classic first-flight crash). Every refusal is one
line naming what was measured and what to do (docs/first-flight.md lists them); a refusal
before take-off sends nothing that could start the motors.

Landing is structure, not the caller's job: leaving the ``with`` block for any reason after
take-off was commanded — the end, Ctrl-C or another terminating signal, an exception, a lost
link, the operator's key — lands the drone, and :meth:`FlightSession.land` holds REF land
until a fresh navdata packet — any packet, bootstrap ones included: the state word is in every
one — shows the drone landed or in emergency, saying every few seconds what it waits for.
While navdata flows it never gives up; with no packet at all for
:data:`~ardrone_nmpc.runtime.schedule.BLIND_LANDING_S` it stops waiting (``landing_failed``,
with the drone's last known state), so the process ends, writes its summary and lets go of
the drone. A second Ctrl-C within 2 s cuts the motors instead (announced on the first); so do
the operator's emergency key, the ``emergency`` command (SIGUSR2,
:class:`~ardrone_nmpc.runtime.signals.EmergencyRequested`) and a motor fault bit
(:class:`CutMotors`). Whether the landing is confirmed is decided by navdata alone — a log that
cannot be written is reported as such, not as a landing failure.

The navdata freshness rule holds from the first take-off REF to the last landing REF: the
take-off fails (:class:`TakeoffFailed`, one line) on navdata older than
``safety.navdata_land_ms``, on a drone fault bit, or when the drone does not fly in time.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Callable

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.links.drone_config import LinkError, verify_config
from ardrone_nmpc.runtime.operator_input import OperatorAbort
from ardrone_nmpc.runtime.schedule import BLIND_LANDING_S, TAKEOFF_TIMEOUT_S
from ardrone_nmpc.runtime.signals import EmergencyRequested, Terminated, signal_name
from ardrone_nmpc.safety import Action, drone_alarms, takeoff_refusal
from ardrone_nmpc.errors import UserError

__all__ = ["CutMotors", "DroneLandedItself", "FlightSession", "PreflightError",
           "TakeoffFailed"]

LEVEL_MAX_DEG = 2.0          # flat trim only this level: it takes the attitude as horizontal
TRIM_TO_TAKEOFF_S = 0.5      # the drone re-zeroes its attitude after FTRIM: no take-off meanwhile
SECOND_INTERRUPT_S = 2.0     # a second Ctrl-C this soon during landing cuts the motors
NOTICE_EVERY_S = 3.0         # landing: how often to say what it is waiting for
NAVDATA_FRESH_S = 0.5        # landing: navdata older than this counts as lost
EMERGENCY_CONFIRM_S = 2.0    # after a cut: how long to wait for navdata to confirm it
_POLL_S = 0.02


class PreflightError(UserError, RuntimeError):
    """A check before (or during) take-off failed; the message says what and what to do."""


class DroneLandedItself(UserError, RuntimeError):
    """The drone landed or cut its motors by itself during the flight."""


class TakeoffFailed(UserError, RuntimeError):
    """The take-off REF went out but the take-off did not complete: the message says why
    (navdata lost, a drone fault bit, no flight in time); the drone has been landed (or cut)."""


class CutMotors(UserError, RuntimeError):
    """The flight ends with the motors cut, not a landing: the drone reports a motor fault
    (CUTOUT, MOTORS). The session's exit cuts them."""


def _stderr(message: str) -> None:
    try:
        print(message, file=sys.stderr)  # stderr is line-buffered: no flush needed
    except (OSError, ValueError):  # the terminal is gone (SIGHUP): the landing goes on
        pass


class FlightSession:
    """Owns verification, take-off and landing of one experiment.

    Parameters
    ----------
    cfg : ExperimentConfig (``drone`` limits and ports, ``safety`` floors and tolerances).
    drone : a connectable :class:`~ardrone_nmpc.links.drone_link.DroneLink`.
    mocap : a running :class:`~ardrone_nmpc.links.mocap_source.MocapSource`.
    event : ``event(kind, **fields)`` sink for the run's events.jsonl.
    clock, sleep : monotonic seconds and the wait between polls.
    warn : one line for the operator (stderr by default).
    start_position_m : the experiment's (x, y, z) at time 0 (None: not checked — a live
        reference).
    requests : :class:`~ardrone_nmpc.runtime.operator_input.OperatorRequests` (the keys).
    lock : a :class:`~ardrone_nmpc.links.flight_lock.FlightLock`, held until the drone is down.
    """

    TAKEOFF_TIMEOUT_S = TAKEOFF_TIMEOUT_S  # runtime/schedule.py; per session so tests can shorten it

    def __init__(self, cfg, drone, mocap, *, event: Callable[..., None],
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 warn: Callable[[str], None] = _stderr, start_position_m=None,
                 requests=None, lock=None):
        self.cfg = cfg
        self.drone = drone
        self.mocap = mocap
        self.event = event
        self.clock = clock
        self.sleep = sleep
        self.warn = warn
        self.start_position_m = start_position_m
        self.requests = requests
        self.lock = lock
        self.landed_cleanly: bool | None = None
        self._last_sigint: float | None = None
        self._cut_t: float | None = None  # when the motors were cut (None: not cut)
        self._own_edge_due = False  # the operator made the edge: ours only if it did not act

    # -- entering: connect, verify, preflight, trim, take off -----------------------------
    def __enter__(self) -> "FlightSession":
        if self.lock is not None:
            self.lock.acquire()  # before a single datagram: one flight per drone
        try:
            self.drone.connect(timeout_s=5.0)  # refuses a drone that is already airborne
            if self.drone.at_bind_warning:
                self._note("at_port_busy", self.drone.at_bind_warning)
            self.configure()
            self.preflight()
            self.trim()
        except BaseException:  # nothing that could start the motors was sent: nothing to land
            self._release()
            raise
        try:
            self.takeoff()
        except BaseException as err:
            self._interrupted(err)
            try:
                self._log("landing", reason=_why(err))
            finally:
                self.land()  # whatever went wrong, the motors may have started
                self._release()
            raise
        return self

    def configure(self) -> None:
        """Write the profile keys, then the limits; read them back, refuse on any difference.

        The profile keys go first: ``control:outdoor`` selects which stored triple the limit
        keys are written into (and, changed afterwards, would load the other one over them)."""
        d = self.cfg.drone
        drone = self.drone
        written = drone.configure_profile(flight_without_shell=d.hull == "outdoor")
        written.update(drone.configure_limits(
            euler_angle_max_rad=d.euler_angle_max_rad, control_vz_max_mps=d.control_vz_max_mps,
            control_yaw_radps=d.control_yaw_radps, altitude_max_m=d.altitude_max_m))
        self.event("config_written", **written)
        try:
            held = drone.read_config(timeout_s=2.0)
        except LinkError as err:
            where = f"{drone.host}:{drone.control_port}"
            if d.verify_config:
                raise PreflightError(
                    f"the drone's control port {where} did not answer ({err}): the limits it "
                    "holds cannot be verified, so no take-off — check drone.control_port, or "
                    "set drone.verify_config: false to fly unverified") from None
            self._note("config_unverified",
                       f"WARNING: flying with UNVERIFIED limits — control port {where} did "
                       f"not answer ({err}); drone.verify_config is false")
            return
        self.event("config_read", **{k: held.get(k) for k in written})
        mismatches = verify_config(written, held)
        if mismatches:
            for m in mismatches:
                self.event("config_mismatch", key=m.key, written=m.written, held=m.held)
            more = f" (and {len(mismatches) - 1} more key(s))" if len(mismatches) > 1 else ""
            raise PreflightError(mismatches[0].line() + more)

    def preflight(self) -> None:
        """On the ground, ready, charged, level; mocap visible where the experiment starts."""
        nav = self._wait_navdata(2.0)
        if nav.mode is FlightMode.EMERGENCY:
            raise PreflightError(f"the drone is in emergency: clear it with `ardrone-nmpc reset "
                                 f"--drone {self.drone.host}` before flying")
        if nav.mode is not FlightMode.LANDED:
            raise PreflightError(f"the drone is not landed and ready (mode {nav.mode.value}, "
                                 f"ctrl_state {_ctrl(nav)}): refusing take-off")
        floor = self.cfg.safety.battery_floor_pct
        if not nav.battery_pct > floor:
            raise PreflightError(f"battery {nav.battery_pct:.0f} % at or below the floor "
                                 f"({floor:.0f} %, safety.battery_floor_pct): charge it")
        refusal = takeoff_refusal(nav.state_bits)
        if refusal is not None:
            self._log("drone_faults", phase="preflight",
                      bits=[f.name for f in drone_alarms(nav.state_bits)])
            raise PreflightError(refusal)
        self._require_level(nav)
        pose = self._wait_mocap(2.0)
        contenders = self.mocap.contenders
        if contenders:  # which stream is the drone? the first heard need not be the tracker
            raise PreflightError(
                f"mocap object {self.cfg.mocap.object_name!r} comes from more than one sender: "
                f"the link took {self.mocap.sender}, {', '.join(contenders)} also sends it — "
                "stop the other stream (a replay --broadcast?) before flying")
        self._require_at_start(pose)
        self.event("preflight_ok", battery_pct=nav.battery_pct, ctrl_state=nav.ctrl_state,
                   mocap_sender=self.mocap.sender,
                   x_m=float(pose.position_m[0]), y_m=float(pose.position_m[1]),
                   z_m=float(pose.position_m[2]))

    def trim(self) -> None:
        """FTRIM on the ground and level (checked again on fresh navdata), then wait
        :data:`TRIM_TO_TAKEOFF_S` before anything may take off — and no take-off on navdata
        that went stale meanwhile."""
        nav = self._wait_navdata(1.0)
        if nav.mode is not FlightMode.LANDED:
            raise PreflightError(f"the drone left the ground state before the flat trim "
                                 f"(mode {nav.mode.value}): refusing take-off")
        self._require_level(nav)
        self.drone.flat_trim()
        self.event("flat_trim", roll_deg=nav.roll_deg, pitch_deg=nav.pitch_deg)
        until = self.clock() + TRIM_TO_TAKEOFF_S
        while self.clock() < until:
            self._check_operator("before take-off")
            self.sleep(_POLL_S)
        self._require_fresh_navdata()

    def takeoff(self) -> None:
        """REF take-off until navdata shows flying, then the heading check: the turn of the
        mocap heading and of navdata's yaw from the first airborne sample (the drone re-zeroes
        its yaw as it takes off) to flying. From the take-off REF on, navdata must stay fresh
        (module doc)."""
        deadline = self.clock() + self.TAKEOFF_TIMEOUT_S
        self.drone.takeoff()
        self.event("takeoff")
        self._wait_takeoff(lambda m: m.airborne, deadline)
        psi0 = self._wait_mocap(0.5).psi_rad
        yaw0_deg = self._wait_navdata(0.5).yaw_deg
        self._wait_takeoff(lambda m: m is FlightMode.FLYING, deadline)
        psi1 = self._wait_mocap(0.5).psi_rad
        yaw1_deg = self._wait_navdata(0.5).yaw_deg
        mocap_turn = wrap_angle_rad(psi1 - psi0)
        # navdata yaw is clockwise-positive, mocap ψ counter-clockwise (docs/protocol.md §4.4)
        navdata_turn = wrap_angle_rad(math.radians(yaw0_deg - yaw1_deg))
        offset = wrap_angle_rad(mocap_turn - navdata_turn)
        self.event("heading_check", mocap_turn_rad=mocap_turn, navdata_turn_rad=navdata_turn,
                   offset_rad=offset)
        tol = self.cfg.safety.heading_tolerance_rad
        if not abs(offset) <= tol:
            raise PreflightError(
                f"during take-off the mocap heading turned {math.degrees(mocap_turn):+.1f}° "
                f"and navdata's yaw {math.degrees(navdata_turn):+.1f}° (offset "
                f"{math.degrees(offset):+.1f}°, safety.heading_tolerance_rad "
                f"{math.degrees(tol):.1f}°): the mocap object's frame does not match the "
                "drone — landing; fix the object (x forward, z up) before flying")

    # -- leaving: land, always ------------------------------------------------------------
    def __exit__(self, exc_type, exc, tb) -> bool:
        self._interrupted(exc)
        try:
            self._log("landing", reason="end" if exc is None else _why(exc))
        finally:  # a failing log (disk full) must not keep the drone in the air
            try:
                self.land()
            finally:
                self._release()
        return False  # never swallow the exception

    def land(self) -> bool:
        """Hold REF land until navdata shows the drone landed or in emergency; True then.

        Never gives up on its own. Interrupts meanwhile do not stop it (the first is re-raised
        once the drone is down); a second Ctrl-C within :data:`SECOND_INTERRUPT_S` — or the
        operator's emergency key — cuts the motors instead. False only if the link cannot send
        at all any more (closed), or a cut was not confirmed.
        """
        interrupt: BaseException | None = None
        t_start = self.clock()
        next_notice = t_start + NOTICE_EVERY_S
        commanded = False
        while True:
            try:
                if self.requests is not None and self.requests.emergency and self._cut_t is None:
                    self._cut_motors("the operator's emergency key")
                if not commanded and self._cut_t is None:  # after a cut, REF emergency stays held
                    self.drone.land()  # the link holds REF land from now on
                    commanded = True
                done = self._landing_done(t_start)
                if done is not None:
                    self.landed_cleanly = done
                    break
                if self.clock() >= next_notice:
                    self._landing_notice()
                    next_notice += NOTICE_EVERY_S
                self.sleep(_POLL_S)
            except KeyboardInterrupt as err:
                interrupt = interrupt or err
                self._interrupted(err)
            except LinkError as err:
                if not self.drone.connected:
                    self.landed_cleanly = False
                    self._log("landing_failed", error=str(err))
                    break
                commanded = False  # a send failed (Wi-Fi gone?): keep trying
                self.sleep(_POLL_S)
        if self.landed_cleanly:
            self._log("landed", mode=self.drone.packet_mode.value)
        if interrupt is not None:
            raise interrupt
        return bool(self.landed_cleanly)

    # -- helpers --------------------------------------------------------------------------
    def _landing_done(self, t_start: float) -> bool | None:
        """True once a fresh packet (any: the state word is in every one) shows landed or
        emergency; False after an unconfirmed cut, or after :data:`BLIND_LANDING_S` of REF
        land without a single packet (the module doc)."""
        now = self.clock()
        if (now - self.drone.state_rx_t_s <= NAVDATA_FRESH_S
                and self.drone.packet_mode in (FlightMode.LANDED, FlightMode.EMERGENCY)):
            return True
        if self._cut_t is not None and now - self._cut_t > EMERGENCY_CONFIRM_S:
            if self._own_edge_due:  # the operator's cut did not show: now this link cuts
                self._own_edge_due = False
                self._cut_t = now
                self.drone.emergency()
                return None
            self._log("landing_failed", error="motor cut not confirmed by navdata")
            return False
        blind_s = now - max(self.drone.state_rx_t_s, t_start)
        if blind_s > BLIND_LANDING_S:
            state, mode = self.drone.state, self.drone.packet_mode
            self._log("landing_failed", error=f"no navdata for {blind_s:.0f} s while landing",
                      last_mode=None if mode is None else mode.value,
                      last_state=None if state is None else int(state),
                      last_age_s=now - self.drone.state_rx_t_s)
            return False
        return None

    def _landing_notice(self) -> None:
        nav = self.drone.navdata
        age_s = self.clock() - self.drone.state_rx_t_s
        if not age_s <= NAVDATA_FRESH_S:
            self._note("landing_navdata_lost",
                       f"landing: no navdata for {age_s:.0f} s — still sending land (for up "
                       f"to {BLIND_LANDING_S:.0f} s without any); watch the drone (Ctrl-C "
                       "twice within 2 s cuts the motors)", age_s=age_s)
        else:
            self._note("landing_wait", f"landing: waiting for the drone to touch down "
                       f"(mode {self.drone.packet_mode.value}, ctrl_state {_ctrl(nav)})")

    def _interrupted(self, err) -> None:
        """A Ctrl-C: the first announces the motor cut, a second within 2 s does it. The
        ``emergency`` command's signal and a motor fault cut at once."""
        if isinstance(err, (EmergencyRequested, CutMotors)):
            if self._cut_t is None:
                self._cut_motors(str(err), edge=not isinstance(err, EmergencyRequested))
            return
        if not isinstance(err, KeyboardInterrupt) or isinstance(err, Terminated):
            return
        now = self.clock()
        if self._last_sigint is not None and now - self._last_sigint <= SECOND_INTERRUPT_S:
            if self._cut_t is None:
                self._cut_motors("a second Ctrl-C")
            return
        self._last_sigint = now
        self.warn("landing — press Ctrl-C again within 2 s to cut the motors (emergency)")

    def _cut_motors(self, why: str, edge: bool = True) -> None:
        """Cut the motors: REF bit 8's edge (the drone link holds it). Without ``edge`` the
        ``emergency`` command has made it already, from its own link: this one holds bit 8
        low (a second edge, from either link, would undo the cut) and bit 9 low, and makes its
        own edge only if navdata has not shown the cut within :data:`EMERGENCY_CONFIRM_S`."""
        self.warn(f"cutting the motors (emergency): {why}")
        self._cut_t = self.clock()
        self._own_edge_due = not edge
        try:
            if edge:
                self.drone.emergency()
            else:
                self.drone.land()
        finally:
            self._log("emergency", reason=why)

    def _note(self, kind: str, message: str, **fields) -> None:
        self.warn(message)
        self._log(kind, message=message, **fields)

    def _log(self, kind: str, **fields) -> None:
        """An event that must not change the flight's course if it cannot be written."""
        try:
            self.event(kind, **fields)
        except Exception as err:  # noqa: BLE001 - disk full: say so, keep flying the procedure
            self.warn(f"warning: event {kind!r} not logged: {err}")

    def _release(self) -> None:
        if self.lock is not None:
            self.lock.release()

    def _check_operator(self, when: str) -> None:
        r = self.requests
        if r is not None and r.land:
            raise OperatorAbort(f"the operator asked to {'cut' if r.emergency else 'land'} "
                                f"{when}")

    def _require_level(self, nav) -> None:
        if not (abs(nav.roll_deg) < LEVEL_MAX_DEG and abs(nav.pitch_deg) < LEVEL_MAX_DEG):
            raise PreflightError(
                f"the drone is not level (roll {nav.roll_deg:+.1f}°, pitch "
                f"{nav.pitch_deg:+.1f}°; the flat trim needs both within ±{LEVEL_MAX_DEG:.0f}°):"
                " put it on a level surface")

    def _require_at_start(self, pose) -> None:
        start = self.start_position_m
        if start is None:
            return
        tol = self.cfg.safety.start_tolerance_m
        x, y, z = (float(v) for v in pose.position_m)
        off = math.hypot(x - start[0], y - start[1])
        if not off <= tol:
            raise PreflightError(
                f"the drone is {off:.2f} m from the experiment's start: mocap ({x:+.2f}, "
                f"{y:+.2f}) m, start ({start[0]:+.2f}, {start[1]:+.2f}) m "
                f"(safety.start_tolerance_m {tol:.2f} m) — put it there or check the mocap "
                "origin")
        if not abs(z) <= tol:
            raise PreflightError(
                f"the mocap puts the landed drone at z = {z:+.2f} m (more than "
                f"safety.start_tolerance_m {tol:.2f} m off the floor): check the mocap origin "
                "and the object's z axis (up)")

    def _wait_navdata(self, timeout_s: float):
        """The newest navdata sample once it is fresh (≤ NAVDATA_FRESH_S old): a check on a
        sample from before the link went silent would judge a drone nobody hears."""
        deadline = self.clock() + timeout_s
        while (self.drone.navdata is None
               or not self.clock() - self.drone.navdata_rx_t_s <= NAVDATA_FRESH_S):
            if self.clock() > deadline:
                what = "no navdata" if self.drone.navdata is None else "no fresh navdata"
                raise PreflightError(f"{what} from the drone")
            self._check_operator("before take-off")
            self.sleep(_POLL_S)
        return self.drone.navdata

    def _wait_mocap(self, timeout_s: float):
        deadline = self.clock() + timeout_s
        while True:
            pose, rx_t = self.mocap.latest()  # rx_t is −inf before the first pose
            age_ms = (self.clock() - rx_t) * 1e3
            if age_ms <= self.cfg.safety.mocap_hover_ms:
                return pose
            if self.clock() > deadline:
                foreign = self.mocap.foreign_senders
                hint = (f"; frames from other senders ignored: {', '.join(foreign)}"
                        if foreign else "")
                raise PreflightError(
                    f"mocap object {self.cfg.mocap.object_name!r} not visible from "
                    f"{self.mocap.where} (last pose age {age_ms:.0f} ms){hint}")
            self._check_operator("before take-off")
            self.sleep(_POLL_S)

    def _require_fresh_navdata(self) -> None:
        """Refuse (nothing sent) unless the newest navdata is fresh (``navdata_land_ms``)."""
        age_s = self.clock() - self.drone.navdata_rx_t_s
        if not age_s <= self._fresh_s:
            raise PreflightError(f"no fresh navdata before take-off (the newest is "
                                 f"{age_s * 1e3:.0f} ms old, safety.navdata_land_ms "
                                 f"{self._fresh_s * 1e3:.0f} ms): no take-off")

    @property
    def _fresh_s(self) -> float:
        return self.cfg.safety.navdata_land_ms * 1e-3

    def _wait_takeoff(self, done, deadline: float) -> None:
        while True:
            nav = self.drone.navdata
            age_s = self.clock() - self.drone.navdata_rx_t_s
            if not age_s <= self._fresh_s:
                raise TakeoffFailed(
                    f"take-off failed: navdata lost (none for {age_s * 1e3:.0f} ms, "
                    f"safety.navdata_land_ms {self._fresh_s * 1e3:.0f} ms) — landing; check "
                    "the Wi-Fi link (docs/first-flight.md §3)")
            if nav is not None:
                if done(nav.mode):
                    return
                self._check_takeoff_alarms(nav)
            if self.drone.self_landing:
                raise DroneLandedItself(f"take-off: {self.drone.self_landing}")
            if self.clock() > deadline:
                mode = nav.mode.value if nav is not None else "no navdata"
                raise TakeoffFailed(f"take-off did not complete in "
                                    f"{self.TAKEOFF_TIMEOUT_S:.0f} s ({mode}): the "
                                    "drone never showed flying — landing; check battery, "
                                    "propellers and hull")
            self._check_operator("during take-off")
            self.sleep(_POLL_S)

    def _check_takeoff_alarms(self, nav) -> None:
        """A fault bit during take-off ends it: the motor faults by a cut, the others by a
        landing (the supervisor is not running yet)."""
        alarms = drone_alarms(nav.state_bits)
        if not alarms:
            return
        self._log("drone_faults", phase="takeoff", bits=[f.name for f in alarms])
        line = (f"take-off failed: the drone reports {alarms[0].line()} (mode "
                f"{nav.mode.value}, ctrl_state {_ctrl(nav)})")
        if alarms[0].in_flight is Action.STOP:
            raise CutMotors(f"{line} — cutting the motors")
        raise TakeoffFailed(f"{line} — landing")


def _ctrl(nav) -> str:
    return "none" if nav is None or nav.ctrl_state is None else f"0x{nav.ctrl_state:08x}"


def _why(err: BaseException) -> str:
    """The ``landing`` event's reason: the signal (``SIGINT``, ``SIGHUP``, …) or the error's
    type."""
    return signal_name(err) if isinstance(err, KeyboardInterrupt) else type(err).__name__
