"""The real-time loop of ``ardrone-nmpc fly``: an opened drone flown on the wall clock.

The same :class:`~ardrone_nmpc.runtime.tick.Tick` as ``simulate``; here the clock is the wall
clock (absolute deadlines, :class:`~ardrone_nmpc.core.clock.Rate`) and the measurements come
from the links of whatever drone a backend opened (:class:`~ardrone_nmpc.links.backend.
OpenedDrone`: a real AR.Drone or the loopback simulators — this loop does not ask which). The
session lands the drone however the loop ends; every catchable terminating signal is turned
into an exception so that it lands too (:mod:`ardrone_nmpc.runtime.signals`). Opening the
drone and the run directory is :func:`~ardrone_nmpc.experiments.flight.run_flight`'s.
"""

from __future__ import annotations

import math
import sys
import time
from contextlib import ExitStack
from pathlib import Path

from ardrone_nmpc.config.schema import tracked_object
from ardrone_nmpc.core.clock import Rate
from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.links.backend import OpenedDrone
from ardrone_nmpc.reference.experiment import experiment_trajectory
from ardrone_nmpc.runs.log_columns import link_columns
from ardrone_nmpc.runs.verdict import FAILED_VERDICTS, VerdictTally, verdict_message
from ardrone_nmpc.runtime.operator_input import KeyReader, OperatorAbort, OperatorRequests
from ardrone_nmpc.runtime.schedule import EventClock, Schedule, phase, write_events
from ardrone_nmpc.runtime.session import CutMotors, DroneLandedItself, FlightSession
from ardrone_nmpc.runtime.signals import landing_signals, polled_signals
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action, drone_alarms


class LandingNotConfirmed(UserError, RuntimeError):
    """Navdata never showed the drone landed: go and look at it."""


class FlightResult:
    """Filled in as the flight goes, so the caller knows the run directory even on failure."""

    path: Path | None = None
    landed: bool | None = None


class LinkLost(UserError, RuntimeError):
    """Navdata went silent beyond ``safety.navdata_land_ms``."""


class SupervisorLanding(UserError, RuntimeError):
    """The supervisor decided to land (battery, geofence, mocap lost): the flight is cut short."""


class DroneEmergency(UserError, RuntimeError):
    """The drone reported an emergency (motors cut)."""


class FlightFailed(UserError, RuntimeError):
    """The flight ran to its end without doing its job (:mod:`ardrone_nmpc.runs.verdict`)."""


def fly(*, cfg, drone: OpenedDrone, recorder, schedule: Schedule, status=None,
        result: FlightResult | None = None, warn=None, operator_keys: bool = False,
        wrap_solver=None) -> None:
    """Fly ``cfg`` with the opened ``drone`` into ``recorder``: the session (connect, verify,
    preflight, take off … land, whatever happens) around the 65 ms loop.

    ``status(dict)`` receives live figures; ``result.landed`` tells the landing's outcome
    whatever happens; ``warn(line)`` shows the session's messages (stderr by default);
    ``operator_keys`` reads the land and emergency keys from the terminal on stdin;
    ``wrap_solver`` is handed to the tick. Events are stamped on the experiment clock
    (:class:`~ardrone_nmpc.runtime.schedule.EventClock`). Raises
    :class:`LandingNotConfirmed` when navdata never showed the drone landed, then
    :class:`FlightFailed` when it ran to its end without doing its job.
    """
    result = result if result is not None else FlightResult()
    link, mocap = drone.link, drone.mocap
    clock = EventClock(recorder.event, time.monotonic)
    event = clock.event
    try:
        with landing_signals(), ExitStack() as stack:
            event("links", drone=drone.address, mocap_port=mocap.port, mocap=mocap.where,
                  sim=drone.simulated)
            tick = Tick(cfg, experiment_trajectory(cfg), wrap_solver=wrap_solver)
            requests = OperatorRequests()
            if operator_keys:
                stack.enter_context(KeyReader(
                    sys.stdin.fileno(), on_land=requests.request_land,
                    on_emergency=lambda: _emergency_now(link, requests)))
            session = FlightSession(cfg, link, mocap, event=event, requests=requests,
                                    start_position_m=_start_position(tick),
                                    **({"warn": warn} if warn is not None else {}))
            tally = VerdictTally(follow=tick.follow is not None)
            try:
                with session:
                    _control_loop(cfg, schedule, tick, drone, recorder, clock, status,
                                  requests, tally)
            finally:
                result.landed = session.landed_cleanly
                for ev in mocap.take_events():  # senders seen since the last tick
                    event(ev.pop("kind"), **ev)
                _drone_events(drone, clock)
                event("drone_link", **_link_counts(link))
                event("session_end", landed=session.landed_cleanly)
            verdict = tally.verdict("completed")
            if verdict in FAILED_VERDICTS:
                event("verdict", verdict=verdict)
    finally:
        clock.close()
    if result.landed is False:
        raise LandingNotConfirmed("navdata never showed the drone landed: check it")
    if verdict in FAILED_VERDICTS:
        raise FlightFailed(f"{verdict}: {verdict_message(verdict)}")


#: What a link counts of its own recoveries (a backend's link may count none of them).
_LINK_COUNTS = ("rewakes", "stale_hovers", "bootstrap_answers")


def _link_counts(link) -> dict:
    return {name: getattr(link, name) for name in _LINK_COUNTS if hasattr(link, name)}


def _drone_events(drone: OpenedDrone, clock: EventClock) -> None:
    """What the drone did on its own (a simulation's injected faults), at its times."""
    for t_exp, ev in drone.take_events():
        write_events(clock.at, t_exp, [ev])


def _emergency_now(drone, requests) -> None:
    """The operator's emergency key: cut the motors from the key thread, at once."""
    requests.request_emergency()
    try:
        drone.emergency()
    except Exception:  # noqa: BLE001 - not connected yet: the session sees the request
        pass


def _start_position(tick):
    """The experiment's position at time 0 (None for a live reference: it follows an object)."""
    if tick.follow is not None:
        return None
    import numpy as np

    state = tick.trajectory.state_at(np.array([0.0]))[0]
    return (float(state[0]), float(state[2]), float(state[4]))


def _control_loop(cfg, schedule: Schedule, tick: Tick, drone: OpenedDrone, recorder,
                  clock: EventClock, status, requests=None,
                  tally: VerdictTally | None = None) -> None:
    """The 65 ms loop until the experiment ends or the supervisor, the drone or the operator
    ends it (an exception: the session's exit lands the drone, or cuts it on
    :class:`~ardrone_nmpc.runtime.session.CutMotors`). At the first tick experiment time 0 is
    fixed, ``sim.settle_s`` ahead, for the events and for the drone; ``tally`` sees every row
    written."""
    link, mocap = drone.link, drone.mocap
    follow = tracked_object(cfg)  # the second mocap object: followed, or a moving obstacle
    rate = Rate(schedule.period_s)
    while True:
        skipped = rate.overruns
        late_s = rate.sleep()
        k = rate.index  # deadline number: overrun deadlines are skipped, time stays wall time
        if k >= schedule.n_ticks:  # deadlines skipped after the last logged tick are not
            rate.overruns = skipped  # counted, so loop_timing agrees with summary.csv
            break
        now = time.monotonic()
        t_exp = schedule.t_exp_s(k)
        if k == 0:  # experiment time 0 on the monotonic clock
            t0 = now + schedule.settle_span_s
            clock.start(t0)
            write_events(clock.at, t_exp, drone.start_experiment(t0))
        pose, pose_rx = mocap.latest()
        nav, nav_rx = link.navdata, link.navdata_rx_t_s
        target, target_rx = mocap.latest_of(follow) if follow else (None, -math.inf)
        for ev in mocap.take_events():  # a foreign sender: logged and shown, never used
            clock.at(t_exp, ev.pop("kind"), **ev)
        _drone_events(drone, clock)
        with polled_signals():  # a signal inside the compiled calls is raised after them
            out = tick.step(TickInputs(now, pose, pose_rx, nav, nav_rx, target, target_rx),
                            t_exp_s=t_exp, mode=phase(t_exp))
        write_events(clock.at, t_exp, out.events)
        pcmd = out.pcmd
        if out.progressive:
            link.set_command(pcmd.roll_frac, pcmd.pitch_frac, pcmd.gaz_frac, pcmd.yaw_frac)
        else:
            link.hover()
        row = out.row
        row |= link_columns(late_s, nav)
        recorder.write_row(row)
        if tally is not None:
            tally.add(row)
        if status is not None:
            status({**row, "progress": schedule.fraction_done(k), "overruns": rate.overruns,
                    "navdata_rate_hz": link.stats.rate_hz, "mocap_rate_hz": mocap.stats.rate_hz,
                    "mocap_sender": mocap.sender, "mocap_foreign": mocap.foreign_senders})
        alarms = drone_alarms(nav.state_bits if nav is not None else None)
        said = f" — the drone reports {alarms[0].line()}" if alarms else ""
        if out.action is Action.LAND:   # the session's exit lands it
            if row["mode"] == "land-navdata-lost":
                raise LinkLost(f"navdata silent for more than {cfg.safety.navdata_land_ms:.0f} ms")
            raise SupervisorLanding(f"the supervisor landed the drone: {row['mode']}{said}")
        if out.action is Action.STOP:
            if row["mode"] != "stop-emergency":  # a motor fault bit: the session's exit cuts
                raise CutMotors(f"the supervisor cut the motors: {row['mode']}{said}")
            raise DroneEmergency("the drone reports an emergency (motors cut): check it")
        _stop_if_ended_outside(link, requests, clock, t_exp)  # after the tick's row: logged
    _stop_if_ended_outside(link, requests, clock, schedule.t_exp_s(schedule.n_ticks - 1))
    jitter = rate.jitter_ms()
    clock.event("loop_timing", overruns=rate.overruns, jitter_p50_ms=jitter["p50"],
                jitter_p99_ms=jitter["p99"], jitter_max_ms=jitter["max"])


def _stop_if_ended_outside(link, requests, clock: EventClock, t_exp: float) -> None:
    """Leave the loop if the drone landed by itself or the operator pressed a key."""
    landed_itself = link.self_landing
    if landed_itself:
        clock.at(t_exp, "drone_landed_itself", what=landed_itself)
        raise DroneLandedItself(f"the drone landed by itself at t = {t_exp:.1f} s: "
                                f"{landed_itself} — the take-off bit was dropped at once and "
                                "never sent again; check battery and motors")
    if requests is not None and requests.land:
        what = "cut the motors" if requests.emergency else "land"
        clock.at(t_exp, "operator", action=what)
        raise OperatorAbort(f"the operator asked to {what} at t = {t_exp:.1f} s")
