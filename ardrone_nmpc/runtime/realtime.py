"""``ardrone-nmpc fly``: the real-time loop over real UDP — the drone, or the loopback simulators.

The same :class:`~ardrone_nmpc.runtime.tick.Tick` as ``simulate``; here the clock is the wall clock
(absolute deadlines, :class:`~ardrone_nmpc.core.clock.Rate`) and the measurements come from the
links. The session lands the drone however the loop ends; every catchable terminating signal
is turned into an exception so that it lands too (:mod:`ardrone_nmpc.runtime.signals`).
Everything that can fail before the motors start is checked first: tick counts, addresses and
ports, the drone's flight lock — a refusal leaves no run directory.
"""

from __future__ import annotations

import math
import sys
import time
from contextlib import ExitStack
from pathlib import Path

from ardrone_nmpc.core.clock import Rate
from ardrone_nmpc.config.schema import tracked_object
from ardrone_nmpc.reference.experiment import experiment_trajectory
from ardrone_nmpc.runs.rundir import RunRecorder
from ardrone_nmpc.runs.summary import write_run_summary
from ardrone_nmpc.runs.verdict import FAILED_VERDICTS, VerdictTally, verdict_message
from ardrone_nmpc.runtime.schedule import Schedule, on_wall_clock, phase, write_events
from ardrone_nmpc.runtime.operator_input import KeyReader, OperatorAbort, OperatorRequests
from ardrone_nmpc.runtime.session import CutMotors, DroneLandedItself, FlightSession
from ardrone_nmpc.runtime.signals import landing_signals
from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action, drone_faults
from ardrone_nmpc.errors import UserError

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


def _endpoints(cfg, drone_host, at_port, navdata_port, mocap_port):
    """The drone's and the mocap's addresses and ports, checked (an option given as 0 or ''
    is an error, never a silent fall-back to the default)."""
    from ardrone_nmpc.links.udp import check_host, check_port

    pick = lambda given, default: default if given is None else given  # noqa: E731
    return (check_host("--drone", pick(drone_host, cfg.drone.host)),
            check_port("--at-port", pick(at_port, cfg.drone.at_port)),
            check_port("--navdata-port", pick(navdata_port, cfg.drone.navdata_port)),
            check_port("--mocap-port", pick(mocap_port, cfg.mocap.port)))


def run_flight(*, cfg, sim: bool, drone_host: str | None, at_port: int | None,
               navdata_port: int | None, mocap_port: int | None, log_dir: Path,
               seed: int | None, status=None, result: FlightResult | None = None,
               sink=None, warn=None, operator_keys: bool = False) -> Path:
    """Fly ``cfg``; return the run directory. ``status(dict)`` receives live figures;
    ``result`` holds the run directory and the landing outcome whatever happens; ``sink``
    (e.g. :class:`~ardrone_nmpc.viz.live.LiveView`) sees every row and event as the recorder
    does (``sink.tee(recorder)``) and must never block; ``warn(line)`` shows the session's
    messages (stderr by default); ``operator_keys`` reads the land and emergency keys from the
    terminal on stdin."""
    result = result if result is not None else FlightResult()
    from ardrone_nmpc.links.drone_link import DroneLink
    from ardrone_nmpc.links.flight_lock import FlightLock
    from ardrone_nmpc.links.mocap_link import MocapLink
    from ardrone_nmpc.links.mocap_factory import open_mocap_source

    seed = cfg.sim.seed if seed is None else seed
    schedule = Schedule.from_config(cfg)  # before anything starts: its errors fly nothing
    experiment_trajectory(cfg)  # nor does a reference that leaves the geofence
    if not sim:
        host, at_port, navdata_port, mocap_port = _endpoints(cfg, drone_host, at_port,
                                                             navdata_port, mocap_port)
    follow = tracked_object(cfg)  # the second mocap object: followed, or a moving obstacle
    others = (follow,) if follow else ()
    try:
        with landing_signals(), ExitStack() as stack:
            if sim:
                from ardrone_nmpc.sim.loopback import start_loopback

                mocap = stack.enter_context(MocapLink(
                    "127.0.0.1", 0, object_name=cfg.mocap.object_name, other_objects=others))
                loop = stack.enter_context(start_loopback(cfg, seed=seed, mocap_port=mocap.port,
                                                          control_port=0))
                host, at_port, navdata_port = loop.drone_host, loop.at_port, loop.navdata_port
                link_options = {"bind_host": "127.0.0.1", "at_local_port": 0,
                                "control_port": loop.control_port}
            else:
                link_options = {"control_port": cfg.drone.control_port}
            lock = FlightLock(host, at_port)
            lock.acquire()  # one flight per drone: refused before a datagram or a run dir
            stack.callback(lock.release)
            if not sim:  # mocap.kind: Vicon UDP or a libmotioncapture system
                mocap = stack.enter_context(open_mocap_source(
                    cfg.mocap, other_objects=others, port=mocap_port))
            recorder = stack.enter_context(RunRecorder.create(log_dir, cfg, seed=seed))
            cfg = recorder.config  # the run reads its own copy of its input files
            if sink is not None:
                recorder = sink.tee(recorder)
            result.path = recorder.path
            t_origin = time.monotonic()
            event = lambda kind, **f: recorder.event(time.monotonic() - t_origin, kind, **f)
            event("links", drone=f"{host}:{at_port}/{navdata_port}", mocap_port=mocap.port,
                  mocap=mocap.where, sim=sim)
            drone = stack.enter_context(DroneLink(
                host, at_port=at_port, navdata_port=navdata_port,
                keepalive_interval_s=cfg.drone.keepalive_interval_s,
                config_ids=cfg.drone.config_ids, navdata_demo=cfg.drone.navdata_demo,
                **link_options))
            tick = Tick(cfg, experiment_trajectory(cfg))
            requests = OperatorRequests()
            if operator_keys:
                stack.enter_context(KeyReader(
                    sys.stdin.fileno(), on_land=requests.request_land,
                    on_emergency=lambda: _emergency_now(drone, requests)))
            session = FlightSession(cfg, drone, mocap, event=event, requests=requests,
                                    start_position_m=_start_position(tick),
                                    **({"warn": warn} if warn is not None else {}))
            fault_clock = loop.set_fault_clock if sim else None
            tally = VerdictTally(follow=tick.follow is not None)
            try:
                with session:
                    _control_loop(cfg, schedule, tick, drone, mocap, recorder, event,
                                  status, fault_clock, requests, tally)
            finally:
                result.landed = session.landed_cleanly
                for ev in mocap.take_events():  # senders seen since the last tick
                    event(ev.pop("kind"), **ev)
                for t_exp, ev in loop.fault_events if sim else ():
                    # the loopback's injected faults, on experiment time
                    write_events(on_wall_clock(event), t_exp, [ev])
                event("drone_link", rewakes=drone.rewakes, stale_hovers=drone.stale_hovers,
                      bootstrap_answers=drone.bootstrap_answers)
                event("session_end", landed=session.landed_cleanly)
            verdict = tally.verdict("completed")
            if verdict in FAILED_VERDICTS:
                event("verdict", verdict=verdict)
            path = recorder.path
        if result.landed is False:
            raise LandingNotConfirmed("navdata never showed the drone landed: check it")
        if verdict in FAILED_VERDICTS:
            raise FlightFailed(f"{verdict}: {verdict_message(verdict)}")
        return path
    finally:
        if result.path is not None:  # however the flight ended: the run dir is complete
            _write_summary_quietly(result.path)


def _write_summary_quietly(path: Path) -> None:
    """summary.csv of the run at ``path``; a failure here must not mask the flight's outcome."""
    try:
        write_run_summary(path)
    except Exception as err:  # noqa: BLE001 - the log is intact; `summary RUN` redoes it
        print(f"warning: {path / 'summary.csv'} not written: {err}", file=sys.stderr)


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


def _control_loop(cfg, schedule: Schedule, tick: Tick, drone, mocap, recorder, event, status,
                  fault_clock=None, requests=None, tally: VerdictTally | None = None) -> None:
    """The 65 ms loop until the experiment ends or the supervisor, the drone or the operator
    ends it (an exception: the session's exit lands the drone, or cuts it on
    :class:`~ardrone_nmpc.runtime.session.CutMotors`). ``fault_clock(t0)`` receives the
    monotonic time of experiment time 0 (the loopback's fault injection runs on it);
    ``tally`` sees every row written."""
    follow = tracked_object(cfg)  # the second mocap object: followed, or a moving obstacle
    write = on_wall_clock(event)
    rate = Rate(schedule.period_s)
    while True:
        skipped = rate.overruns
        late_s = rate.sleep()
        k = rate.index  # deadline number: overrun deadlines are skipped, time stays wall time
        if k >= schedule.n_ticks:  # deadlines skipped after the last logged tick are not
            rate.overruns = skipped  # counted, so loop_timing agrees with summary.csv
            break
        now = time.monotonic()
        if k == 0 and fault_clock is not None:  # experiment time 0 for the injected faults
            fault_clock(now + schedule.settle_span_s)
        pose, pose_rx = mocap.latest()
        nav, nav_rx = drone.navdata, drone.navdata_rx_t_s
        target, target_rx = mocap.latest_of(follow) if follow else (None, -math.inf)
        t_exp = schedule.t_exp_s(k)
        for ev in mocap.take_events():  # a foreign sender: logged and shown, never used
            event(ev.pop("kind"), t_exp_s=t_exp, **ev)
        out = tick.step(TickInputs(now, pose, pose_rx, nav, nav_rx, target, target_rx),
                        t_exp_s=t_exp, mode=phase(t_exp))
        write_events(write, t_exp, out.events)
        pcmd = out.pcmd
        if out.progressive:
            drone.set_command(pcmd.roll_frac, pcmd.pitch_frac, pcmd.gaz_frac, pcmd.yaw_frac)
        else:
            drone.hover()
        row = out.row
        row["tick_late_ms"] = late_s * 1e3
        row["nav_ctrl_state"] = (nav.ctrl_state if nav is not None and nav.ctrl_state is not None
                                 else math.nan)
        recorder.write_row(row)
        if tally is not None:
            tally.add(row)
        if status is not None:
            status({**row, "progress": schedule.fraction_done(k), "overruns": rate.overruns,
                    "navdata_rate_hz": drone.stats.rate_hz, "mocap_rate_hz": mocap.stats.rate_hz,
                    "mocap_sender": mocap.sender, "mocap_foreign": mocap.foreign_senders})
        faults = drone_faults(nav.state_bits if nav is not None else None)
        said = f" — the drone reports {faults[0].line()}" if faults else ""
        if out.action is Action.LAND:   # the session's exit lands it
            if row["mode"] == "land-navdata-lost":
                raise LinkLost(f"navdata silent for more than {cfg.safety.navdata_land_ms:.0f} ms")
            raise SupervisorLanding(f"the supervisor landed the drone: {row['mode']}{said}")
        if out.action is Action.STOP:
            if row["mode"] != "stop-emergency":  # a motor fault bit: the session's exit cuts
                raise CutMotors(f"the supervisor cut the motors: {row['mode']}{said}")
            raise DroneEmergency("the drone reports an emergency (motors cut): check it")
        _stop_if_ended_outside(drone, requests, event, t_exp)  # after the tick's row: logged
    _stop_if_ended_outside(drone, requests, event, schedule.t_exp_s(schedule.n_ticks - 1))
    jitter = rate.jitter_ms()
    event("loop_timing", overruns=rate.overruns, jitter_p50_ms=jitter["p50"],
          jitter_p99_ms=jitter["p99"], jitter_max_ms=jitter["max"])


def _stop_if_ended_outside(drone, requests, event, t_exp: float) -> None:
    """Leave the loop if the drone landed by itself or the operator pressed a key."""
    landed_itself = drone.self_landing
    if landed_itself:
        event("drone_landed_itself", t_exp_s=t_exp, what=landed_itself)
        raise DroneLandedItself(f"the drone landed by itself at t = {t_exp:.1f} s: "
                                f"{landed_itself} — the take-off bit was dropped at once and "
                                "never sent again; check battery and motors")
    if requests is not None and requests.land:
        what = "cut the motors" if requests.emergency else "land"
        event("operator", t_exp_s=t_exp, action=what)
        raise OperatorAbort(f"the operator asked to {what} at t = {t_exp:.1f} s")
