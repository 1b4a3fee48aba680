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
from ardrone_nmpc.runtime.tick import Tick, TickInputs
from ardrone_nmpc.runs.rundir import RunRecorder, read_run, write_summary
from ardrone_nmpc.safety import Action
from ardrone_nmpc.runtime.session import DroneLandedItself, FlightSession
from ardrone_nmpc.runtime.lockstep import experiment_trajectory
from ardrone_nmpc.runtime.operator_input import KeyReader, OperatorAbort, OperatorRequests
from ardrone_nmpc.runtime.signals import Terminated, exit_code_of, landing_signals  # noqa: F401
from ardrone_nmpc.runs.summary import summarise

EXIT_SIGINT = 130
EXIT_SIGTERM = 143
MAX_FLIGHT_S = 86400.0  # settle + experiment: a day of ticks is far beyond any battery


class LandingNotConfirmed(RuntimeError):
    """Navdata never showed the drone landed: go and look at it."""


class FlightResult:
    """Filled in as the flight goes, so the caller knows the run directory even on failure."""

    path: Path | None = None
    landed: bool | None = None


class LinkLost(RuntimeError):
    """Navdata went silent beyond ``safety.navdata_land_ms``."""


class SupervisorLanding(RuntimeError):
    """The supervisor decided to land (battery, geofence, mocap lost): the flight is cut short."""


class DroneEmergency(RuntimeError):
    """The drone reported an emergency (motors cut)."""


def tick_counts(cfg) -> tuple[int, int]:
    """(settle ticks, all ticks) of the flight; ValueError if they cannot be flown."""
    period = cfg.loop.period_s
    total_s = cfg.sim.settle_s + cfg.duration_s
    if not (math.isfinite(total_s) and 0.0 <= total_s <= MAX_FLIGHT_S):
        raise ValueError(f"duration_s + sim.settle_s = {total_s:g} s: a flight lasts at most "
                         f"{MAX_FLIGHT_S:.0f} s")
    n_settle = math.ceil(cfg.sim.settle_s / period - 1e-9)
    return n_settle, n_settle + int(round(cfg.duration_s / period)) + 1


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
               warn=None, operator_keys: bool = False) -> Path:
    """Fly ``cfg``; return the run directory. ``status(dict)`` receives live figures;
    ``result`` holds the run directory and the landing outcome whatever happens; ``warn(line)``
    shows the session's messages (stderr by default); ``operator_keys`` reads the land and
    emergency keys from the terminal on stdin."""
    result = result if result is not None else FlightResult()
    from ardrone_nmpc.links.drone_link import DroneLink
    from ardrone_nmpc.links.flight_lock import FlightLock
    from ardrone_nmpc.links.mocap_link import MocapLink

    seed = cfg.sim.seed if seed is None else seed
    tick_counts(cfg)  # before anything: a count that cannot be flown is the user's error
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
            if not sim:
                mocap = stack.enter_context(MocapLink(
                    cfg.mocap.bind_host, mocap_port, object_name=cfg.mocap.object_name,
                    other_objects=others))
            recorder = stack.enter_context(RunRecorder.create(log_dir, cfg, seed=seed))
            result.path = recorder.path
            t_origin = time.monotonic()
            event = lambda kind, **f: recorder.event(time.monotonic() - t_origin, kind, **f)
            event("links", drone=f"{host}:{at_port}/{navdata_port}", mocap_port=mocap.port,
                  sim=sim)
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
                                    start_position_m=_start_position(tick), lock=lock,
                                    **({"warn": warn} if warn is not None else {}))
            fault_clock = getattr(loop, "set_fault_clock", None) if sim else None
            try:
                with session:
                    _control_loop(cfg, tick, drone, mocap, recorder, event, status,
                                  fault_clock, requests)
            finally:
                for ev in mocap.take_events():  # senders seen since the last tick
                    event(ev.pop("kind"), **ev)
                result.landed = session.landed_cleanly
                for t_exp, ev in (getattr(loop, "fault_events", None) or []) if sim else ():
                    fields = dict(ev)  # the loopback's injected faults, on experiment time
                    event(fields.pop("kind"), t_exp_s=t_exp, **fields)
                event("session_end", landed=session.landed_cleanly)
            path = recorder.path
        if result.landed is False:
            raise LandingNotConfirmed("navdata never showed the drone landed: check it")
        return path
    finally:
        if result.path is not None:  # however the flight ended: the run dir is complete
            _write_summary_quietly(result.path)


def _emergency_now(drone, requests) -> None:
    """The operator's emergency key: cut the motors from the key thread, at once."""
    requests.request_emergency()
    try:
        drone.emergency()
    except Exception:  # noqa: BLE001 - not connected yet: the session sees the request
        pass


def _start_position(tick):
    """The experiment's position at time 0 (None for a live reference: it follows an object)."""
    if getattr(tick.trajectory, "observe", None) is not None:
        return None
    import numpy as np

    state = tick.trajectory.state_at(np.array([0.0]))[0]
    return (float(state[0]), float(state[2]), float(state[4]))


def _write_summary_quietly(path: Path) -> None:
    """summary.csv of the run at ``path``; a failure here must not mask the flight's outcome."""
    try:
        write_summary(path, summarise(read_run(path)))
    except Exception as err:  # noqa: BLE001 - the log is intact; `summary RUN` redoes it
        print(f"warning: {path / 'summary.csv'} not written: {err}", file=sys.stderr)


def _control_loop(cfg, tick: Tick, drone, mocap, recorder, event, status,
                  fault_clock=None, requests=None) -> None:
    """The 65 ms loop until the experiment ends or the supervisor, the drone or the operator
    ends it (an exception: the session's exit lands the drone). ``fault_clock(t0)`` receives
    the monotonic time of experiment time 0 (the loopback's fault injection runs on it)."""
    period = cfg.loop.period_s
    follow = tracked_object(cfg)  # the second mocap object: followed, or a moving obstacle
    n_settle, n_ticks = tick_counts(cfg)
    rate = Rate(period)
    while True:
        late_s = rate.sleep()
        k = rate.index  # deadline number: overrun deadlines are skipped, time stays wall time
        if k >= n_ticks:
            break
        now = time.monotonic()
        if k == 0 and fault_clock is not None:  # experiment time 0 for the injected faults
            fault_clock(now + n_settle * period)
        pose, pose_rx = mocap.latest()
        nav, nav_rx = drone.navdata, drone.navdata_rx_t_s
        target, target_rx = mocap.latest_of(follow) if follow else (None, -math.inf)
        t_exp = (k - n_settle) * period
        for ev in mocap.take_events():  # a foreign sender: logged and shown, never used
            event(ev.pop("kind"), t_exp_s=t_exp, **ev)
        out = tick.step(TickInputs(now, pose, pose_rx, nav, nav_rx, target, target_rx),
                        t_exp_s=t_exp,
                        mode="settle" if t_exp < 0 else "track")
        for ev in out.events:
            event(ev.pop("kind"), t_exp_s=t_exp, **ev)
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
        if status is not None:
            status({**row, "progress": (k + 1) / n_ticks, "overruns": rate.overruns,
                    "navdata_rate_hz": drone.stats.rate_hz, "mocap_rate_hz": mocap.stats.rate_hz,
                    "mocap_sender": mocap.sender, "mocap_foreign": mocap.foreign_senders})
        if out.action is Action.LAND:   # the session's exit lands it
            if row["mode"] == "land-navdata-lost":
                raise LinkLost(f"navdata silent for more than {cfg.safety.navdata_land_ms:.0f} ms")
            raise SupervisorLanding(f"the supervisor landed the drone: {row['mode']}")
        if out.action is Action.STOP:
            raise DroneEmergency("the drone reports an emergency (motors cut): check it")
        _stop_if_ended_outside(drone, requests, event, t_exp)  # after the tick's row: logged
    jitter = rate.jitter_ms()
    _stop_if_ended_outside(drone, requests, event, (n_ticks - 1 - n_settle) * period)
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
