"""``ardrone-nmpc fly``: open the drone ``--drone`` names, record a real-time flight of it.

The drone is opened by its backend (:data:`DRONE_BACKENDS`, by the scheme of its address;
docs/architecture.md §4) and flown by :func:`~ardrone_nmpc.runtime.realtime.fly` into a run
directory made by :func:`~ardrone_nmpc.experiments.record.record` — the one recording of every
command. Everything that can fail before the motors start is checked first, in this order, and
a refusal leaves no run directory: tick counts, the address, a ``faults`` section on a drone
that is not simulated (faults are injected only in simulation), ports, the drone's flight lock.
``sim://lockstep`` owns its clock: it is flown by the lockstep runner, as ``simulate`` flies it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

from ardrone_nmpc.control.diverging import diverging_wrapper
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.experiments.record import record, record_lockstep
from ardrone_nmpc.links.backend import DroneAddress, open_udp_drone, parse_drone_address
from ardrone_nmpc.runtime.realtime import FlightResult, fly
from ardrone_nmpc.runtime.schedule import Schedule

__all__ = ["DRONE_BACKENDS", "FaultsNotSimulated", "run_flight"]


class FaultsNotSimulated(UserError, ValueError):
    """A ``faults`` section on a drone that is not simulated: refused before anything flies."""


def _udp(cfg, address: DroneAddress, *, seed, ports, other_objects):
    from ardrone_nmpc.links.udp import check_host, check_port

    at_port, navdata_port, mocap_port = ports
    pick = lambda given, default: default if given is None else given  # noqa: E731
    return open_udp_drone(
        cfg, host=check_host("--drone", address.where),
        at_port=check_port("--at-port", pick(at_port, cfg.drone.at_port)),
        navdata_port=check_port("--navdata-port", pick(navdata_port, cfg.drone.navdata_port)),
        mocap_port=check_port("--mocap-port", pick(mocap_port, cfg.mocap.port)),
        other_objects=other_objects)


def _loopback(cfg, address: DroneAddress, *, seed, ports, other_objects):
    from ardrone_nmpc.sim.loopback import open_loopback_drone

    return open_loopback_drone(cfg, seed=seed, other_objects=other_objects)


#: The drone backends: ``scheme`` or ``scheme://where`` → the opener of an
#: :class:`~ardrone_nmpc.links.backend.OpenedDrone` (a context manager). Another drone (a
#: Crazyflie through cflib: ``radio``; a Tello) plugs in here with its own opener.
DRONE_BACKENDS: dict[str, Callable] = {
    "udp": _udp,                  # an AR.Drone 2.0 over its UDP protocol (links/backend.py)
    "sim://loopback": _loopback,  # the simulated drone served on 127.0.0.1 (sim/loopback.py)
}
#: The backend whose drone owns its clock: flown in lockstep (sim/lockstep_drone.py).
LOCKSTEP = "sim://lockstep"
SIMULATED = ("sim://loopback", LOCKSTEP)


def _address(cfg, drone: str | None, sim: bool) -> DroneAddress:
    if sim:
        return DroneAddress("sim", "loopback")
    try:
        return parse_drone_address(cfg.drone.host if drone is None else drone)
    except ValueError as err:
        raise UserError(str(err)) from None


def _refuse_faults_on_a_real_drone(cfg, address: DroneAddress) -> None:
    active = cfg.faults.active()
    if active and str(address) not in SIMULATED:
        raise FaultsNotSimulated(
            f"faults: {', '.join(sorted(active))} — faults are injected only in simulation, "
            f"and {address} is no simulated drone: remove the faults section (or fly "
            "--drone sim://loopback)")


def run_flight(*, cfg, sim: bool = False, drone_host: str | None = None,
               at_port: int | None = None, navdata_port: int | None = None,
               mocap_port: int | None = None, log_dir: Path, seed: int | None,
               status=None, result: FlightResult | None = None, sink=None, warn=None,
               operator_keys: bool = False) -> Path:
    """Fly ``cfg`` with the drone ``drone_host`` names (an address or a URI; ``sim`` is
    ``sim://loopback``) into a new run directory under ``log_dir``; return its path.

    ``status(dict)`` receives live figures; ``result`` holds the run directory and the landing
    outcome whatever happens; ``sink`` (e.g. :class:`~ardrone_nmpc.viz.live.LiveView`) sees
    every row and event as the recorder does (``sink.tee(recorder)``) and must never block;
    ``warn(line)`` shows the session's messages; ``operator_keys`` reads the land and
    emergency keys from the terminal. The run directory is summarised however the flight
    ended.
    """
    from ardrone_nmpc.config.schema import tracked_object
    from ardrone_nmpc.runtime.signals import landing_signals

    result = result if result is not None else FlightResult()
    seed = cfg.sim.seed if seed is None else seed
    schedule = Schedule.from_config(cfg)  # before anything starts: its errors fly nothing
    address = _address(cfg, drone_host, sim)
    opener = DRONE_BACKENDS.get(str(address)) or DRONE_BACKENDS.get(address.scheme)
    if opener is None and str(address) != LOCKSTEP:
        raise UserError(f"--drone {address}: no such drone backend (known: udp://HOST, "
                        f"{', '.join(SIMULATED)})")
    _refuse_faults_on_a_real_drone(cfg, address)
    if str(address) == LOCKSTEP:
        recording = record_lockstep(cfg, log_dir, seed=seed, live=sink)
        result.path, result.landed = recording.path, recording.result.final_mode.value == "landed"
        return recording.path
    follow = tracked_object(cfg)  # the second mocap object: followed, or a moving obstacle
    with landing_signals(), opener(cfg, address, seed=seed,
                                   ports=(at_port, navdata_port, mocap_port),
                                   other_objects=(follow,) if follow else ()) as opened:
        wrap_solver = diverging_wrapper(opened.solver_divergence)

        def flight(recorder) -> None:
            result.path = recorder.path
            sink_or_recorder = sink.tee(recorder) if sink is not None else recorder
            fly(cfg=recorder.config, drone=opened, recorder=sink_or_recorder,
                schedule=schedule, status=status, result=result, warn=warn,
                operator_keys=operator_keys, wrap_solver=wrap_solver)

        return record(cfg, log_dir, seed=seed, fly=flight,
                      summarise_failed=_write_summary_quietly).path


def _write_summary_quietly(path: Path) -> None:
    """summary.csv of the run at ``path``; a failure here must not mask the flight's outcome."""
    from ardrone_nmpc.runs.summary import write_run_summary

    try:
        write_run_summary(path)
    except Exception as err:  # noqa: BLE001 - the log is intact; `summary RUN` redoes it
        print(f"warning: {path / 'summary.csv'} not written: {err}", file=sys.stderr)
