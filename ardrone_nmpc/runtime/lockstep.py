"""Lockstep simulation: the real tick against the simulated AR.Drone on a manual clock.

No sockets and no sleeping: the runner advances the plant between sensor and tick events
and hands the tick exactly what the links would hold — the newest mocap pose (sampled at
``sim.mocap_rate_hz``, delivered ``noise.mocap_latency_ms`` later) and the newest navdata
(``sim.navdata_rate_hz``, body-frame velocities). Sequence: take off (on-board), hold the
reference's start for ``sim.settle_s`` (rows with t_s < 0), fly the experiment for
``duration_s``, land. Deterministic for a seed.

Before take-off the limits are written to the simulated drone's configuration and read back,
and the session's own check refuses (:class:`TakeoffRefused`, a ``takeoff_refused`` event) a
drone that holds other values or whose control port does not answer — the
``FlightSession.configure`` of ``fly``, not a second copy. A drone that lands by itself
during the flight ends the run (``land-drone-landed-itself``); nothing takes it off again.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.links.drone_config import ConfigHandshake, LinkError, parse_config_text
from ardrone_nmpc.protocol.at import Config
from ardrone_nmpc.reference.experiment import experiment_trajectory
from ardrone_nmpc.runs.verdict import VerdictTally
from ardrone_nmpc.runtime.schedule import (LANDING_TIMEOUT_S, TAKEOFF_TIMEOUT_S, Schedule, phase,
                                           write_events)
from ardrone_nmpc.runtime.session import FlightSession, PreflightError
from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action, takeoff_refusal
from ardrone_nmpc.sim.faults import FaultSchedule, PlantFaults
from ardrone_nmpc.sim.backends import make_plant
from ardrone_nmpc.sim.drone_config import ConfigStore
from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.sim.sensors import WireSensors, drone_status
from ardrone_nmpc.sim.target import target_pose
from ardrone_nmpc.errors import UserError


@dataclass
class SimResult:
    """What a lockstep run produced (the rows are also in the recorder, if one was given).

    ``ending`` says how the flight ended: ``"completed"`` (the experiment ran to its end and
    did its job), a failed verdict of :mod:`ardrone_nmpc.runs.verdict` (it ran to its end
    without tracking, or never saw the object it follows), ``"land-<reason>"`` (the
    supervisor landed it), ``"stop-<reason>"`` (the drone cut its motors, or reported a motor
    fault and was cut); ``final_mode`` is the drone's mode after the run.
    """

    ticks: int
    final_mode: FlightMode
    run_dir: Path | None
    loop_wall_s: float = math.nan  # wall time of the flight itself (JIT warm-up excluded)
    ending: str = "completed"
    end_t_s: float = math.nan  # experiment time when it ended: touch-down, or rest after a stop


class TakeoffRefused(UserError, RuntimeError):
    """The pre-flight check failed (battery at or below the floor, limits the drone does not
    hold, no configuration read back): nothing took off."""


#: The event of a refused take-off (``reason``: the one-line refusal); no flight follows.
REFUSED_EVENT = "takeoff_refused"
#: The ending of a run whose drone landed by itself (the supervisor's ``land-<reason>`` form).
SELF_LANDED = "land-drone-landed-itself"


class _SimConfigPort(ConfigHandshake):
    """The simulated drone's configuration as :class:`FlightSession` sees a link's: the same
    writes (:meth:`ConfigHandshake.configure_limits`, ``configure_profile``: the key texts the
    wire would carry) into a :class:`~ardrone_nmpc.sim.drone_config.ConfigStore`, no sockets;
    the read-back is the store's dump, unless the control port fault keeps it silent."""

    host = "simulated-drone"

    def __init__(self, cfg, store: ConfigStore, port_mode: str):
        self.store = store
        self.control_port = cfg.drone.control_port
        self.config_ids = cfg.drone.config_ids
        self._port_mode = port_mode
        if self.config_ids is not None:  # the session switch DroneLink.connect makes first
            for key, value in zip(("custom:session_id", "custom:profile_id",
                                   "custom:application_id"), self.config_ids):
                self.write_config(key, value)

    def write_config(self, key, value, timeout_s: float = 1.0) -> str:
        text = Config.of(key, value).value
        if not self.store.acknowledges(key, self.config_ids):
            raise LinkError(f"config {key}={text!r}: no ACK from the drone (a multiconfig "
                            "session that ignores plain CONFIG: set drone.config_ids to it)")
        self.store.write(key, text, self.config_ids)  # acknowledged, applied or not
        return text

    def read_config(self, timeout_s: float = 2.0) -> dict[str, str]:
        if self._port_mode != "serve":
            raise LinkError(f"fault control_port_drop: {self._port_mode}, no configuration dump")
        return parse_config_text(self.store.text())


def _configure(cfg, plant, faults: FaultSchedule, events: list) -> None:
    """Write the limits, read them back and refuse as ``fly`` does (TakeoffRefused)."""
    store = ConfigStore(plant, altitude_max_m=cfg.drone.altitude_max_m,
                        session=faults.held_session(), outdoor=faults.outdoor_profiles())
    port = _SimConfigPort(cfg, store, faults.control_port_mode())
    session = FlightSession(cfg, port, None, event=lambda kind, **f: events.append((kind, f)),
                            warn=lambda message: None)  # the warning is in the events
    try:
        session.configure()
    except (PreflightError, LinkError) as err:
        raise TakeoffRefused(str(err)) from None


class _Sensors:
    """Sensor events of the lockstep clock: which sample the links hold at time t."""

    def __init__(self, cfg, plant: AirframePlant):
        self.plant = plant
        self.mocap_period_s = 1.0 / cfg.sim.mocap_rate_hz
        self.mocap_latency_s = cfg.sim.noise.mocap_latency_ms * 1e-3
        self.nav_period_s = 1.0 / cfg.sim.navdata_rate_hz
        self.pose = None
        self.pose_rx_t_s = -math.inf
        self.nav = None
        self.nav_rx_t_s = -math.inf
        self._next_mocap_k = 0
        self._next_nav_k = 0
        self.target_cfg = cfg.sim.target
        self.target = None
        self.target_rx_t_s = -math.inf
        self._target_rng = np.random.default_rng([cfg.sim.seed, 0x7A26])
        self._target_std_m = cfg.sim.noise.mocap_position_std_m

    def advance_to(self, t_s: float) -> None:
        """Run the plant to ``t_s``, sampling the sensors on their own grids on the way.

        Only the newest sample of each stream before ``t_s`` is what a link would hand the
        tick, so intermediate mocap frames are skipped (their noise draws with them; the
        stream stays deterministic for a seed).
        """
        plant = self.plant
        k_mocap = math.floor((t_s - self.mocap_latency_s) / self.mocap_period_s + 1e-9)
        k_nav = math.floor(t_s / self.nav_period_s + 1e-9)
        events = []
        if k_mocap >= self._next_mocap_k:
            events.append((k_mocap * self.mocap_period_s, "mocap"))
            self._next_mocap_k = k_mocap + 1
        if k_nav >= self._next_nav_k:
            events.append((k_nav * self.nav_period_s, "nav"))
            self._next_nav_k = k_nav + 1
        for t_event, kind in sorted(events):
            if t_event > plant.t_s:
                plant.advance(t_event - plant.t_s)
            if kind == "mocap":
                self.pose = plant.mocap_pose()
                self.pose_rx_t_s = t_event + self.mocap_latency_s
                if self.target_cfg is not None:  # the scripted second object, same frame
                    self.target = target_pose(self.target_cfg, t_event, self._target_rng,
                                              self._target_std_m)
                    self.target_rx_t_s = self.pose_rx_t_s
            else:
                self.nav = plant.navdata()
                self.nav_rx_t_s = t_event
        if t_s > plant.t_s:
            plant.advance(t_s - plant.t_s)

    def inputs(self, t_s: float) -> TickInputs:
        return TickInputs(t_s, self.pose, self.pose_rx_t_s, self.nav, self.nav_rx_t_s,
                          self.target, self.target_rx_t_s)


def truth_columns(plant: AirframePlant) -> dict:
    truth = plant.truth
    return {"x_true_m": truth.position_m[0], "y_true_m": truth.position_m[1],
            "z_true_m": truth.position_m[2], "psi_true_rad": truth.psi_rad,
            "vz_true_mps": truth.velocity_mps[2]}


def run_lockstep(cfg, *, recorder=None, seed: int | None = None,
                 progress: Callable[[float], None] | None = None) -> SimResult:
    """Fly ``cfg`` against the simulated drone; rows go to ``recorder.write_row``.

    ``progress(fraction)`` is called every tick with the fraction of the run done. The
    supervisor's verdicts are obeyed as on the real drone: ``land`` lands (rows go on until
    touch-down), ``stop`` (emergency) ends the run. Events are stamped with experiment time.
    Raises :class:`TakeoffRefused` (after a :data:`REFUSED_EVENT`) when the battery is at or
    below ``safety.battery_floor_pct`` or the configuration read back refuses (module doc),
    :class:`~ardrone_nmpc.runtime.schedule.ScheduleError` for times that give no tick count.
    A drone that lands by itself ends the run with :data:`SELF_LANDED`.
    """
    schedule = Schedule.from_config(cfg)
    seed = cfg.sim.seed if seed is None else seed
    plant = make_plant(cfg.sim, cfg.drone, seed=seed)
    faults = FaultSchedule(cfg.faults, seed)
    tick = Tick(cfg, experiment_trajectory(cfg))
    sensors = WireSensors(cfg, plant, faults) if faults.touches_sensors else _Sensors(cfg, plant)
    plant_faults = PlantFaults(faults, plant)
    period = schedule.period_s
    write_event = recorder.event if recorder is not None else (lambda *a, **k: None)

    preflight_events: list[tuple[str, dict]] = []  # stamped once experiment time exists
    try:
        if not plant.battery_pct > cfg.safety.battery_floor_pct:  # NaN is no charge either
            raise TakeoffRefused(f"battery {plant.battery_pct:.0f} % is at or below the floor "
                                 f"safety.battery_floor_pct = "
                                 f"{cfg.safety.battery_floor_pct:.0f} %: take-off refused")
        refusal = takeoff_refusal(int(drone_status(plant).state_bits()))  # as fly's preflight
        if refusal is not None:
            raise TakeoffRefused(refusal)
        _configure(cfg, plant, faults, preflight_events)
    except TakeoffRefused as err:  # no experiment time: nothing took off
        for kind, fields in preflight_events:
            write_event(math.nan, kind, **fields)
        write_event(math.nan, REFUSED_EVENT, reason=str(err))
        raise
    t_takeoff = plant.t_s
    plant.wind_mps = faults.wind_mps(-math.inf)  # a constant wind blows from the start
    plant.takeoff()
    while plant.mode is not FlightMode.FLYING and plant.t_s < TAKEOFF_TIMEOUT_S:
        sensors.advance_to(plant.t_s + period)
    if plant.mode is not FlightMode.FLYING:
        raise RuntimeError(f"simulated take-off did not complete (mode {plant.mode.value})")
    # The settle phase starts now, on whole ticks: experiment time 0 is n_settle ticks later.
    t_first = plant.t_s
    t_start = t_first + schedule.settle_span_s  # experiment time 0 on the plant clock
    sensors.t_zero_s = t_start
    for kind, fields in preflight_events:
        write_event(t_takeoff - t_start, kind, **fields)
    write_event(t_takeoff - t_start, "takeoff")
    if faults.any:
        write_event(schedule.t_exp_s(0), "faults", windows=[list(w) for w in faults.windows()])
    wall0 = time.perf_counter()
    ending, k, flown = "completed", 0, 0
    tally = VerdictTally(follow=tick.follow is not None)
    for k in range(schedule.n_ticks):
        t_exp = schedule.t_exp_s(k)
        write_events(write_event, t_exp, plant_faults.update(t_exp))
        sensors.advance_to(t_first + k * period)
        if _landed_itself(sensors.nav):  # the drone's word: no command, no take-off again
            write_event(t_exp, "drone_landed_itself", drone_mode=sensors.nav.mode.value)
            ending = SELF_LANDED
            break
        flown = k + 1
        out = tick.step(sensors.inputs(t_first + k * period), t_exp_s=t_exp, mode=phase(t_exp))
        write_events(write_event, t_exp, out.events)
        if not faults.at_lost(t_exp):
            pcmd = out.pcmd
            plant.command(pcmd.roll_frac, pcmd.pitch_frac, pcmd.gaz_frac, pcmd.yaw_frac,
                          progressive=out.progressive)
        _record(recorder, out.row, plant)
        tally.add(out.row)
        if progress is not None:
            progress(schedule.fraction_done(k))
        if out.action in (Action.LAND, Action.STOP):
            ending = out.row["mode"]
            break
    ending = tally.verdict(ending)
    loop_wall_s = time.perf_counter() - wall0
    t_end = t_first + flown * period - t_start
    if ending.startswith("stop"):
        if plant.emergency():  # a motor fault bit: the tool cuts, as the session does
            write_event(t_end, "emergency", reason=ending)
        write_event(t_end, "stopped", reason=ending, drone_mode=plant.mode.value)
        sensors.advance_to(plant.t_s + 3.0)  # let it come to rest: the truth shows the fall
    else:
        _land(cfg, tick, sensors, plant, plant_faults, recorder, write_event,
              t_first, t_start, flown, logged=ending.startswith("land"))
    return SimResult(flown, plant.mode, recorder.path if recorder is not None else None,
                     loop_wall_s, ending, plant.t_s - t_start)


def _landed_itself(nav) -> bool:
    """Navdata shows the drone landing or landed while the run holds it in flight."""
    return nav is not None and nav.mode in (FlightMode.LANDING, FlightMode.LANDED)


def _record(recorder, row: dict, plant: AirframePlant) -> None:
    if recorder is not None:
        row.update(truth_columns(plant))
        recorder.write_row(row)


def _land(cfg, tick, sensors, plant, plant_faults, recorder, write_event, t_first, t_start,
          k0, *, logged: bool) -> None:
    """Land and wait for touch-down. After a supervisor landing the ticks go on (logged, the
    supervisor hovering the link) so the log shows the descent; after a completed experiment
    only the events are written."""
    period = cfg.loop.period_s
    plant.land()
    write_event(t_first + k0 * period - t_start, "land")
    deadline = plant.t_s + LANDING_TIMEOUT_S
    k = k0
    while plant.mode is not FlightMode.LANDED and plant.t_s < deadline:
        if plant.mode is FlightMode.EMERGENCY:
            break
        t_plant = t_first + k * period
        plant_faults.update(t_plant - t_start)
        sensors.advance_to(t_plant)
        if logged:
            out = tick.step(sensors.inputs(t_plant), t_exp_s=t_plant - t_start)
            out.row["mode"] = "landing"
            _record(recorder, out.row, plant)
        k += 1
    write_event(plant.t_s - t_start, "landed" if plant.mode is FlightMode.LANDED else "not-landed",
                drone_mode=plant.mode.value)
