"""Drone backends: one way to open a drone, chosen by the address ``--drone`` names.

A backend opens (a context manager) an :class:`OpenedDrone`: the link to the drone — an AT
sender, a navdata receiver and a configuration port, the interface of
:class:`~ardrone_nmpc.links.drone_link.DroneLink` that :class:`~ardrone_nmpc.runtime.session.
FlightSession` and the real-time loop use and never look behind — and the mocap source that
sees it, plus what a simulated drone adds (the experiment clock of its injected faults, their
events, the solver divergence it injects). The runner does not branch on which backend it got.

Addresses (docs/architecture.md §4):

* ``192.168.1.1`` or ``udp://192.168.1.1`` — an AR.Drone 2.0 over its UDP protocol
  (:func:`open_udp_drone`, here) and the lab's motion capture;
* ``sim://loopback`` — the simulated drone served over UDP on 127.0.0.1 with its mocap
  streamer (``fly --sim``; :func:`~ardrone_nmpc.sim.loopback.open_loopback_drone`);
* ``sim://lockstep`` — the simulated drone in lockstep, no sockets: it owns its clock, so it
  is flown by the lockstep runner (``simulate``; :class:`~ardrone_nmpc.sim.lockstep_drone.
  LockstepDrone`).

The table of schemes is :data:`~ardrone_nmpc.experiments.flight.DRONE_BACKENDS`. Another drone
plugs in there: a Crazyflie through cflib (``radio://0/80/2M/E7E7E7E7E7``) or a Tello would add
an opener yielding an :class:`OpenedDrone` whose link offers ``connect``, ``takeoff``,
``land``, ``emergency``, ``set_command``/``hover`` (fractions of its limits), ``navdata``/
``navdata_rx_t_s``/``self_landing`` (a :class:`~ardrone_nmpc.core.types.NavdataSample` from
its telemetry), ``configure_limits``/``configure_profile``/``read_config`` (its parameters)
and ``flat_trim``; the conformance tests (tests/integration/test_backend_conformance.py) are
what it must pass.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from typing import Any

__all__ = ["DroneAddress", "OpenedDrone", "open_udp_drone", "parse_drone_address"]


@dataclass(frozen=True)
class DroneAddress:
    """A parsed ``--drone``: ``scheme`` (``udp``, ``sim``) and what follows ``://``."""

    scheme: str
    where: str

    def __str__(self) -> str:
        return f"{self.scheme}://{self.where}"


def parse_drone_address(text: str) -> DroneAddress:
    """``"192.168.1.1"`` → ``udp://192.168.1.1``; ``"sim://loopback"`` as written. Raises
    ValueError for an empty address or an empty part."""
    text = str(text).strip()
    scheme, sep, where = text.partition("://")
    if not sep:
        scheme, where = "udp", text
    scheme = scheme.lower()
    if not scheme or not where:
        raise ValueError(f"--drone {text!r}: expected an address (192.168.1.1) or a URI "
                         "(udp://192.168.1.1, sim://loopback, sim://lockstep)")
    return DroneAddress(scheme, where)


@dataclass
class OpenedDrone:
    """A drone a backend opened: what a runner flies (module docstring).

    Attributes
    ----------
    link : the AT sender, navdata receiver and configuration port.
    mocap : the :class:`~ardrone_nmpc.links.mocap_source.MocapSource` that sees the drone.
    address : where it is, for the run's ``links`` event and the display.
    simulated : a simulated drone (the only kind a ``faults`` section may be flown with).
    start_experiment : ``start_experiment(t0)`` — experiment time 0 is ``t0`` on
        ``time.monotonic``; returns events to log (a simulation announcing its faults).
    take_events : ``(experiment time s, event)`` of what the drone did on its own since the
        last call (a simulation's injected faults).
    solver_divergence : a predicate of experiment time: when a simulation makes the ground
        station's solver diverge (None: never).
    """

    link: Any
    mocap: Any
    address: str
    simulated: bool = False
    start_experiment: Callable[[float], list[dict]] = field(default=lambda t0_s: [])
    take_events: Callable[[], list[tuple[float, dict]]] = field(default=lambda: [])
    solver_divergence: Callable[[float], bool] | None = None


@contextmanager
def open_udp_drone(cfg, *, host: str, at_port: int, navdata_port: int, mocap_port: int,
                   other_objects: tuple[str, ...] = ()) -> Iterator[OpenedDrone]:
    """The AR.Drone 2.0 at ``host`` and the configured motion capture (``mocap.kind``): the
    flight lock first (one flight per drone, refused before a datagram), then the mocap
    source; the link connects when the session starts."""
    from ardrone_nmpc.links import drone_link  # looked up now: tests swap the class
    from ardrone_nmpc.links.flight_lock import FlightLock
    from ardrone_nmpc.links.mocap_factory import open_mocap_source

    with ExitStack() as stack:
        lock = FlightLock(host, at_port)
        lock.acquire()
        stack.callback(lock.release)
        mocap = stack.enter_context(open_mocap_source(cfg.mocap, other_objects=other_objects,
                                                      port=mocap_port))
        link = stack.enter_context(drone_link.DroneLink(
            host, at_port=at_port, navdata_port=navdata_port,
            keepalive_interval_s=cfg.drone.keepalive_interval_s,
            config_ids=cfg.drone.config_ids, navdata_demo=cfg.drone.navdata_demo,
            control_port=cfg.drone.control_port))
        yield OpenedDrone(link, mocap, f"udp://{host}:{at_port}/{navdata_port}")
