"""The loopback simulators of one experiment: the simulated drone served over UDP.

:func:`start_loopback` is what ``fly --sim`` (in-process, free ports) and ``sim-drone``
(fixed ports) use: it builds the experiment's :class:`~ardrone_nmpc.sim.drone.SimulatedDrone`
(the one ``simulate`` flies in lockstep), serves it with a
:class:`~ardrone_nmpc.sim.drone_server.DroneServer` on 127.0.0.1 and streams its pose with a
:class:`~ardrone_nmpc.sim.mocap_server.MocapServer`, all sharing one lock.

The config's ``faults`` are injected by both servers through the drone's one
:class:`~ardrone_nmpc.sim.fault_injection.ServerFaults`; their experiment time starts when the
runner calls :meth:`Loopback.start_experiment` (``sim-drone`` calls it when it starts serving).
The firmware faults (ctrl_state codes, another config session, a silent control port) act from
the start. The drone serves its TCP control port (a free port by default), so a client's
configuration read-back works as against the real drone.
"""

from __future__ import annotations

import copy
import socket
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from typing import Optional

from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.links.backend import OpenedDrone

from ardrone_nmpc.sim.addresses import require_loopback_host
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim.drone_server import DroneServer
from ardrone_nmpc.sim.fault_injection import FaultCounters, ServerFaults
from ardrone_nmpc.sim.mocap_server import MocapServer
from ardrone_nmpc.sim.plant import AirframePlant

__all__ = ["Loopback", "free_udp_port", "open_loopback_drone", "start_loopback", "warm_physics"]

_WARM_UP_LIMIT_S = 30.0  # plant seconds a warm-up phase may take (a take-off takes ~2 s)


def free_udp_port(host: str = "127.0.0.1") -> int:
    """A UDP port free on ``host`` right now (bound and released; the caller binds it next)."""
    host = require_loopback_host(host)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


class Loopback:
    """Running simulators (context manager: exit stops them and closes every socket).

    Attributes
    ----------
    plant : the simulated drone (read it under :attr:`lock`, or use :meth:`truth`).
    drone : the :class:`DroneServer`.
    mocap : the :class:`MocapServer`.
    lock : the lock shared by the physics, AT, navdata and mocap threads.
    drone_host : address of the simulated drone (the bind address, 127.0.0.1).
    at_port, navdata_port : its UDP ports; control_port : its TCP 5559 stand-in or None.
    mocap_host, mocap_port : where the pose stream is sent.
    object_name : the mocap object name.
    faults : the servers' shared :class:`ServerFaults` (None: no fault injection).
    """

    def __init__(self, plant: AirframePlant, drone: DroneServer, mocap: MocapServer,
                 faults: Optional[ServerFaults] = None,
                 simulated: Optional[SimulatedDrone] = None) -> None:
        self.plant = plant
        self.drone = drone
        self.mocap = mocap
        self.lock = drone.lock
        self.faults = faults
        self.simulated = (simulated if simulated is not None
                          else SimulatedDrone(plant, faults=faults))

    def start_experiment(self, t0_mono: float) -> list[dict]:
        """Experiment time 0 (of the injected faults) is ``t0_mono`` (``time.monotonic()``, s);
        returns the events announcing what is injected."""
        with self.lock:
            return self.simulated.start_experiment(t0_mono)

    set_fault_clock = start_experiment

    def take_events(self) -> list[tuple[float, dict]]:
        """``(experiment time s, event)`` of the plant faults that started since the last call."""
        return self.simulated.take_events()

    @property
    def fault_events(self) -> list[tuple[float, dict]]:
        """``(experiment time s, event)`` of each plant fault that started so far."""
        return [] if self.faults is None else self.faults.events

    @property
    def fault_counters(self) -> FaultCounters:
        """How often each injected fault acted so far."""
        return FaultCounters() if self.faults is None else self.faults.counters

    @property
    def drone_host(self) -> str:
        return self.drone.bind_host

    @property
    def at_port(self) -> int:
        return self.drone.at_port

    @property
    def navdata_port(self) -> int:
        return self.drone.navdata_port

    @property
    def control_port(self) -> Optional[int]:
        return self.drone.control_port

    @property
    def mocap_host(self) -> str:
        return self.mocap.target[0]

    @property
    def mocap_port(self) -> int:
        return self.mocap.target[1]

    @property
    def object_name(self) -> str:
        return self.mocap.object_name

    def truth(self):
        """The plant's true state now (:class:`~ardrone_nmpc.core.types.PlantTruth`)."""
        with self.lock:
            return self.plant.truth

    def close(self) -> None:
        """Stop both servers (idempotent)."""
        self.mocap.stop()
        self.drone.stop()

    def __enter__(self) -> Loopback:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"Loopback(drone={self.drone_host}:{self.at_port}/{self.navdata_port}, "
                f"mocap→{self.mocap_host}:{self.mocap_port} {self.object_name!r})")


def warm_physics(plant, step_s: float) -> tuple:
    """Load (or, on a cold cache, compile) the kernels the physics and mocap threads call —
    on a copy of ``plant``, flown through a take-off, a second of flight and a landing in
    ``step_s`` steps (the landing started by an empty battery inside a two-step advance,
    which the plant flies step by step, where it can be told its level) — before the servers
    start. Compiled in the physics thread instead, the first take-off of a fresh install
    stalls it for seconds and the client sees the navdata stop (``take-off failed: navdata
    lost``). ``plant`` itself is left untouched; returns the copy's modes, in the order it
    went through them (none for a plant that cannot be copied: it is served cold)."""
    try:
        twin = copy.deepcopy(plant)
    except (TypeError, copy.Error):  # a user's backend holding a lock, a socket …
        return ()
    modes = [twin.mode]

    def fly_while(mode) -> None:
        t_end = twin.t_s + _WARM_UP_LIMIT_S
        while twin.mode is mode and twin.t_s < t_end:
            twin.advance(step_s)
        modes.append(twin.mode)

    if twin.takeoff():
        modes.append(twin.mode)
        fly_while(FlightMode.TAKING_OFF)
    if twin.mode is FlightMode.FLYING:  # (or a plant that starts aloft: z₀ > 0)
        twin.command(0.01, -0.01, 0.02, 0.01)
        for _ in range(max(1, round(1.0 / step_s))):
            twin.advance(step_s)
        twin.mocap_pose()
        twin.navdata()
        _ = twin.truth  # a property (its angle wrap)
        # a late physics wake-up advances several steps at once; when the climb settles or
        # the battery empties inside one, the plant flies the rest step by step (another
        # kernel): an empty battery makes it land so, where a plant can be told its level
        set_battery_pct = getattr(twin, "set_battery_pct", None)
        if set_battery_pct is not None:
            set_battery_pct(0.0)
            twin.advance(2 * step_s)
            if twin.mode is FlightMode.LANDING:
                modes.append(twin.mode)
                fly_while(FlightMode.LANDING)
        elif twin.land():
            modes.append(twin.mode)
            fly_while(FlightMode.LANDING)
    return tuple(modes)


def start_loopback(cfg, *, seed: Optional[int] = None, mocap_port: Optional[int] = None,
                   mocap_host: str = "127.0.0.1", bind_host: str = "127.0.0.1",
                   at_port: int = 0, navdata_port: int = 0, control_port: Optional[int] = 0,
                   mocap_drop_probability: float = 0.0, **drone_options) -> Loopback:
    """Build the plant of ``cfg`` and start its simulators; returns the running :class:`Loopback`.

    Parameters
    ----------
    cfg : ExperimentConfig (sections ``sim``, ``drone``, ``mocap``, ``faults`` are read).
    seed : seed of the plant and the stream faults (default ``cfg.sim.seed``).
    mocap_port : where the pose stream goes; None = a free port on ``mocap_host``, reported as
        :attr:`Loopback.mocap_port` (the caller binds it).
    mocap_host, bind_host : loopback addresses (ValueError otherwise).
    at_port, navdata_port : drone UDP ports; 0 = free ports.
    control_port : TCP configuration port (0 = a free port, the default; None = not served).
    mocap_drop_probability : fraction of mocap frames not sent (seeded).
    drone_options : further :class:`DroneServer` keyword arguments (watchdog times …).
    """
    seed = cfg.sim.seed if seed is None else int(seed)
    bind_host = require_loopback_host(bind_host, "bind address")
    mocap_host = require_loopback_host(mocap_host, "mocap target")
    if mocap_port is None:
        mocap_port = free_udp_port(mocap_host)
    server_keys = ("step_s", "demo_rate_hz", "full_rate_hz", "bootstrap_rate_hz",
                   "navdata_timeout_s", "control_port_mode", "lock", "clock")
    server_options = {k: drone_options.pop(k) for k in server_keys if k in drone_options}
    simulated = SimulatedDrone.from_config(cfg, seed=seed, **drone_options)  # firmware options
    plant, faults = simulated.plant, simulated.faults
    options = dict(demo_rate_hz=cfg.sim.navdata_rate_hz,
                   step_s=cfg.sim.plant.integration_step_s,
                   control_port_mode=simulated.control_port_mode)
    options.update(server_options)
    warm_physics(plant, options["step_s"])  # before its threads start
    drone = DroneServer(plant, bind_host=bind_host, at_port=at_port, navdata_port=navdata_port,
                        control_port=control_port, drone=simulated, **options)
    try:
        mocap = MocapServer(plant, target=(mocap_host, mocap_port), rate_hz=cfg.sim.mocap_rate_hz,
                            object_name=cfg.mocap.object_name,
                            latency_ms=cfg.sim.noise.mocap_latency_ms, lock=drone.lock,
                            drop_probability=mocap_drop_probability, seed=seed, faults=faults,
                            second_object=cfg.sim.target)
    except BaseException:
        drone.stop()
        raise
    try:
        drone.start()
        mocap.start()
    except BaseException:
        mocap.stop()
        drone.stop()
        raise
    return Loopback(plant, drone, mocap, faults, simulated)


@contextmanager
def open_loopback_drone(cfg, *, seed: Optional[int] = None,
                        other_objects: tuple[str, ...] = ()) -> Iterator[OpenedDrone]:
    """The ``sim://loopback`` backend (``fly --sim``): the experiment's simulated drone served
    on free loopback ports, its pose streamed to a mocap link, and the link to it — an
    :class:`~ardrone_nmpc.links.backend.OpenedDrone` like a real drone's."""
    from ardrone_nmpc.links import drone_link
    from ardrone_nmpc.links.flight_lock import FlightLock
    from ardrone_nmpc.links.mocap_link import MocapLink

    with ExitStack() as stack:
        mocap = stack.enter_context(MocapLink("127.0.0.1", 0, object_name=cfg.mocap.object_name,
                                              other_objects=other_objects))
        loop = stack.enter_context(start_loopback(cfg, seed=seed, mocap_port=mocap.port,
                                                  control_port=0))
        lock = FlightLock(loop.drone_host, loop.at_port)
        lock.acquire()
        stack.callback(lock.release)
        link = stack.enter_context(drone_link.DroneLink(
            loop.drone_host, at_port=loop.at_port, navdata_port=loop.navdata_port,
            keepalive_interval_s=cfg.drone.keepalive_interval_s,
            config_ids=cfg.drone.config_ids, navdata_demo=cfg.drone.navdata_demo,
            bind_host="127.0.0.1", at_local_port=0, control_port=loop.control_port))
        yield OpenedDrone(link, mocap, f"sim://loopback ({loop.drone_host}:{loop.at_port}/"
                          f"{loop.navdata_port})", simulated=True,
                          start_experiment=loop.start_experiment, take_events=loop.take_events,
                          solver_divergence=loop.simulated.solver_divergence)
