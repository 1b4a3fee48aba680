"""Operator commands that work against any drone address: ``land``, ``emergency``, ``reset``,
``status`` (docs/first-flight.md, "Operator keys and commands").

They exist for the moments ``fly`` cannot help: its process died (the drone hovers on its own
watchdog), or the drone is somebody else's. Each exits 0 on success, non-zero with one
``error:`` line otherwise.

* ``land`` and ``emergency`` act first and ask later
  (:class:`~ardrone_nmpc.links.operator_link.OperatorLink`): REF land / emergency goes out in
  the first datagram and is repeated every 30 ms, each datagram numbered from seq 1 so the
  drone takes it whoever spoke before — with or without navdata, with or without a
  configuration session. Navdata only confirms, any packet (bootstrap too).
* ``land`` — if a ``fly`` on this machine holds the drone it is told to land too (SIGTERM:
  its own session lands it) and given :data:`HANDOVER_S` to let go of the navdata stream; then
  the landing is the session's: until a packet shows the drone down, Ctrl-C twice within 2 s
  cuts the motors, and with no navdata at all it stops after
  :data:`~ardrone_nmpc.runtime.schedule.BLIND_LANDING_S` with an ``error:`` line.
* ``emergency`` — cut the motors now: the edge of REF bit 8 in the first datagram, REF land
  after it (a second edge would undo the cut). A ``fly`` holding the drone is sent SIGUSR2
  (:data:`~ardrone_nmpc.runtime.signals.EMERGENCY_SIGNAL`): it stops flying and holds the cut
  (its session makes an edge of its own only if navdata does not show this one), and lets go.
  Confirmed by navdata's emergency bit; a fresh packet without it gets one more edge.
* ``reset`` — clear an emergency on the ground.
* ``status`` — one navdata snapshot: state bits, the fault bits by name, ctrl_state, battery,
  altitude, attitude, and the limits and session ids the firmware holds (read back over the
  control port).

``land`` and ``emergency`` always go through; ``reset`` and ``status`` take the drone's flight
lock (a running ``fly`` would lose its navdata to them) and connect with the configuration
handshake. Every command takes ``--config-ids`` for a drone in a multiconfig session.
"""

from __future__ import annotations

import os
import signal
import time

import typer

from ardrone_nmpc.cli.options import non_empty, port

__all__ = ["register"]

HANDOVER_S = 10.0          # how long a holding `fly` gets to land (or cut) and let go
CONNECT_TIMEOUT_S = 5.0    # reset, status: the configuration handshake
EMERGENCY_CONFIRM_S = 3.0  # how long navdata gets to show the cut, once it is woken
_FRESH_S = 0.5
_EDGE_ACTS_S = 0.2         # a packet this long after an edge shows whether it acted
_LIMIT_KEYS = ("control:euler_angle_max", "control:control_vz_max", "control:control_yaw",
               "control:altitude_max", "control:outdoor", "control:flight_without_shell",
               "control:flying_mode", "custom:session_id", "custom:profile_id",
               "custom:application_id")


def _config_ids(value: str | None) -> tuple[str, str, str] | None:
    """``--config-ids SESSION,PROFILE,APPLICATION`` (8 hex digits each)."""
    from ardrone_nmpc.links.drone_config import check_config_id

    if value is None:
        return None
    ids = tuple(v.strip() for v in value.split(","))
    try:
        if len(ids) != 3:
            raise ValueError("three are needed")
        for v in ids:
            check_config_id(v)
    except ValueError:
        raise typer.BadParameter(f"{value!r}: three ids of 8 hex digits, "
                                 "session,profile,application (e.g. d2e081a3,be27e2e4,d87f7e0c)"
                                 ) from None
    return ids  # type: ignore[return-value]


DRONE = typer.Option("192.168.1.1", "--drone", callback=non_empty,
                     help="Drone address (the AR.Drone's own network: 192.168.1.1).")
AT_PORT = typer.Option(5556, "--at-port", callback=port(), help="AT command UDP port.")
NAVDATA_PORT = typer.Option(5554, "--navdata-port", callback=port(), help="Navdata UDP port.")
CONFIG_IDS = typer.Option(None, "--config-ids", callback=_config_ids,
                          help="Multiconfig session,profile,application ids (8 hex digits "
                               "each) of a drone left in a configuration session.")


def _fail(message: str, code: int = 1):
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code=code)


def _link(drone: str, at_port: int, navdata_port: int, **options):
    from ardrone_nmpc.links.drone_link import DroneLink

    try:
        return DroneLink(drone, at_port=at_port, navdata_port=navdata_port,
                         allow_airborne=True, **options)
    except ValueError as err:
        _fail(str(err))


def _connect(link) -> None:
    from ardrone_nmpc.links.drone_link import LinkError

    try:
        link.connect(timeout_s=CONNECT_TIMEOUT_S)
    except LinkError as err:
        _fail(str(err))
    if link.at_bind_warning:
        typer.echo(f"warning: {link.at_bind_warning}", err=True)


def _act(drone: str, at_port: int, navdata_port: int, config_ids, command: str):
    """An :class:`OperatorLink` already sending ``command`` (its first datagram is out — or
    was sent by the entry point, :mod:`ardrone_nmpc.cli.first_datagram`, before typer loaded)."""
    from ardrone_nmpc.cli import first_datagram
    from ardrone_nmpc.links.drone_config import LinkError
    from ardrone_nmpc.links.operator_link import OperatorLink

    try:
        link = OperatorLink(drone, at_port=at_port, navdata_port=navdata_port,
                            config_ids=config_ids)
        link.start(command, edge_sent=first_datagram.SENT == (command, drone, at_port))
    except (ValueError, LinkError) as err:
        _fail(str(err))
    return link


def _holder(drone: str, at_port: int) -> int | None:
    """The pid of another process on this machine holding the drone's flight lock."""
    from ardrone_nmpc.links.flight_lock import FlightLock

    pid = FlightLock(drone, at_port).holder()
    return None if pid is None or pid == os.getpid() else pid


def _tell_holder(pid: int, sig: int, what: str) -> bool:
    """Send ``sig`` to the flight holding the drone; True if it was delivered."""
    try:
        os.kill(pid, sig)
    except OSError as err:
        typer.echo(f"warning: cannot signal the flight (pid {pid}): {err}", err=True)
        return False
    typer.echo(f"a flight (pid {pid}) holds the drone: told it to {what}", err=True)
    return True


def _wait_for_release(drone: str, at_port: int, pid: int) -> None:
    """Up to :data:`HANDOVER_S` for ``pid`` to let go of the drone (and its navdata)."""
    from ardrone_nmpc.links.flight_lock import FlightLock

    lock = FlightLock(drone, at_port)
    deadline = time.monotonic() + HANDOVER_S
    while time.monotonic() < deadline:
        if lock.holder() is None:
            typer.echo(f"the flight (pid {pid}) let go of the drone", err=True)
            return
        time.sleep(0.05)
    typer.echo(f"pid {pid} still holds the drone after {HANDOVER_S:g} s: confirming from "
               "here", err=True)


def _take_lock(drone: str, at_port: int):
    from ardrone_nmpc.links.flight_lock import DroneBusy, FlightLock

    lock = FlightLock(drone, at_port)
    try:
        lock.acquire()
    except DroneBusy as err:
        _fail(str(err))
    return lock


def _confirm_cut(link) -> bool:
    """Wait up to :data:`EMERGENCY_CONFIRM_S` for a fresh packet showing the emergency; one
    that shows none (received well after the last edge) gets one more edge."""
    from ardrone_nmpc.core.types import FlightMode

    deadline = time.monotonic() + EMERGENCY_CONFIRM_S
    recut = False
    while True:
        def seen(lk):  # a packet sent after the last edge had time to act
            return lk.state_rx_t_s > max(lk.last_edge_t + _EDGE_ACTS_S,
                                         time.monotonic() - _FRESH_S)
        if not link.wait_for(seen, deadline - time.monotonic()):
            return False
        if link.packet_mode is FlightMode.EMERGENCY:
            return True
        if recut:
            return False
        recut = True
        typer.echo(f"navdata shows the drone {link.packet_mode.value}, not cut: cutting again",
                   err=True)
        link.emergency()


def _unheard(link, what: str) -> str:
    return (f"{what} sent to {link.host}:{link.at_port} ({link.sent_datagrams} datagrams) but "
            f"no navdata from {link.host}:{link.navdata_port} confirmed it — look at the drone")


def land(drone: str = DRONE, at_port: int = AT_PORT, navdata_port: int = NAVDATA_PORT,
         config_ids: str | None = CONFIG_IDS) -> None:
    """Land the drone: REF land at once and until navdata shows it on the ground (a `fly`
    holding it is told to land too). Ctrl-C twice within 2 s cuts the motors instead."""
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.runtime.session import FlightSession
    from ardrone_nmpc.runtime.signals import exit_code_of, landing_signals

    with _act(drone, at_port, navdata_port, config_ids, "land") as link:
        pid = _holder(drone, at_port)
        if pid is not None and _tell_holder(pid, signal.SIGTERM, "land (SIGTERM)"):
            _wait_for_release(drone, at_port, pid)
        link.wake_navdata()
        session = FlightSession(None, link, None, event=lambda kind, **fields: None,
                                warn=lambda line: typer.echo(line, err=True))
        try:
            with landing_signals():
                landed = session.land()
        except KeyboardInterrupt as err:  # the session landed (or cut) first
            mode = link.packet_mode
            done = ("motors cut (emergency)" if mode is FlightMode.EMERGENCY
                    else f"landed ({mode.value})" if session.landed_cleanly
                    else "landing not confirmed by navdata — check the drone")
            _fail(f"interrupted: {done}", exit_code_of(err))
    if not landed:
        _fail(_unheard(link, "REF land") if link.packets == 0 else
              f"landing not confirmed by navdata (the drone's last mode "
              f"{link.packet_mode.value}, {time.monotonic() - link.state_rx_t_s:.0f} s ago) — "
              "look at the drone")
    typer.echo(f"landed ({link.packet_mode.value})")


def emergency(drone: str = DRONE, at_port: int = AT_PORT, navdata_port: int = NAVDATA_PORT,
              config_ids: str | None = CONFIG_IDS) -> None:
    """Cut the motors now (the drone falls); a `fly` holding it cuts them too. Confirmed by
    navdata's emergency bit."""
    from ardrone_nmpc.runtime.signals import EMERGENCY_SIGNAL

    with _act(drone, at_port, navdata_port, config_ids, "emergency") as link:
        pid = _holder(drone, at_port)
        if pid is not None and _tell_holder(pid, EMERGENCY_SIGNAL, "cut the motors too "
                                            f"({signal.Signals(EMERGENCY_SIGNAL).name})"):
            _wait_for_release(drone, at_port, pid)
        link.wake_navdata()
        cut = _confirm_cut(link)
    if cut:
        typer.echo("motors cut (emergency); clear it on the ground with `ardrone-nmpc reset`")
        return
    if link.packets == 0:
        _fail(_unheard(link, "REF emergency"))
    _fail(f"emergency not confirmed by navdata within {EMERGENCY_CONFIRM_S:.0f} s (mode "
          f"{link.packet_mode.value}) — check the drone")


def reset(drone: str = DRONE, at_port: int = AT_PORT, navdata_port: int = NAVDATA_PORT,
          config_ids: str | None = CONFIG_IDS) -> None:
    """Clear an emergency (the drone must be on the ground)."""
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.links.drone_link import LinkError

    link = _link(drone, at_port, navdata_port, config_ids=config_ids)
    with _take_lock(drone, at_port), link:
        _connect(link)
        nav = link.navdata
        if nav.mode is not FlightMode.EMERGENCY:
            _fail(f"the drone is not in emergency (mode {nav.mode.value}): nothing to reset")
        try:
            link.reset_emergency(timeout_s=3.0)
        except LinkError as err:
            _fail(str(err))
    typer.echo("emergency cleared")


def status(drone: str = DRONE, at_port: int = AT_PORT, navdata_port: int = NAVDATA_PORT,
           control_port: int = typer.Option(5559, "--control-port", callback=port(),
                                            help="TCP configuration port."),
           config_ids: str | None = CONFIG_IDS) -> None:
    """One navdata snapshot: state, ctrl_state, battery, altitude and the firmware-held
    limits."""
    from ardrone_nmpc.links.drone_link import LinkError
    from ardrone_nmpc.protocol.navdata import CtrlMajor, DroneState
    from ardrone_nmpc.safety import drone_alarms

    link = _link(drone, at_port, navdata_port, control_port=control_port,
                 config_ids=config_ids)
    with _take_lock(drone, at_port), link:
        _connect(link)
        nav, state = link.navdata, link.state
        major = None if nav.ctrl_state is None else nav.ctrl_state >> 16
        names = [f.name for f in DroneState if f.value & int(state) and f.name]
        try:
            major_name = CtrlMajor(major).name
        except ValueError:
            major_name = "unknown"
        lines = [f"drone      {drone}:{at_port}/{navdata_port}",
                 f"mode       {nav.mode.value}",
                 f"state      0x{int(state):08x} {' '.join(names)}",
                 f"faults     {', '.join(f.line() for f in drone_alarms(int(state))) or 'none'}",
                 f"ctrl_state 0x{nav.ctrl_state or 0:08x} (major {major} {major_name}, "
                 f"minor {(nav.ctrl_state or 0) & 0xFFFF})",
                 f"battery    {nav.battery_pct:.0f} %",
                 f"altitude   {nav.altitude_m:.3f} m",
                 f"attitude   roll {nav.roll_deg:+.1f}° pitch {nav.pitch_deg:+.1f}° "
                 f"yaw {nav.yaw_deg:+.1f}°"]
        try:
            held = link.read_config(timeout_s=2.0)
            lines += [f"{key:<29}{held.get(key, '(missing)')}" for key in _LIMIT_KEYS]
        except LinkError as err:
            lines.append(f"limits     not read: {err}")
    for line in lines:
        typer.echo(line)


def register(app: typer.Typer) -> None:
    """Add the four operator commands to ``app``."""
    for command in (land, emergency, reset, status):
        app.command(name=command.__name__)(command)

