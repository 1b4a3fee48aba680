"""Operator commands that work against any drone address: ``land``, ``emergency``, ``reset``,
``status`` (docs/first-flight.md, "Operator keys and commands").

They exist for the moments ``fly`` cannot help: its process died (the drone hovers on its own
watchdog), or the drone is somebody else's. Each connects its own link, does one thing and
exits 0 on success, non-zero with one ``error:`` line otherwise.

* ``land`` — REF land until navdata shows the drone down (never gives up on its own; Ctrl-C
  twice within 2 s cuts the motors). If a ``fly`` on this machine holds the drone, it is asked
  to land first (SIGTERM: its own session lands it); only if it has not let go within 10 s does
  ``land`` take over.
* ``emergency`` — cut the motors now (a ``fly`` holding the drone is told to land first, so
  it stops sending take-off); confirmed by navdata's emergency bit.
* ``reset`` — clear an emergency on the ground.
* ``status`` — one navdata snapshot: state bits, ctrl_state, battery, altitude, attitude and
  the limits the firmware holds (read back over the control port).

``land`` and ``emergency`` always go through; ``reset`` and ``status`` take the drone's flight
lock (a running ``fly`` would lose its navdata to them).
"""

from __future__ import annotations

import os
import signal
import time

import typer

from ardrone_nmpc.cli.options import non_empty, port

__all__ = ["register"]

HANDOVER_S = 10.0          # how long a holding `fly` gets to land and let go
EMERGENCY_CONFIRM_S = 3.0
_LIMIT_KEYS = ("control:euler_angle_max", "control:control_vz_max", "control:control_yaw",
               "control:altitude_max", "control:outdoor", "control:flight_without_shell",
               "control:flying_mode")

DRONE = typer.Option("192.168.1.1", "--drone", callback=non_empty,
                     help="Drone address (the AR.Drone's own network: 192.168.1.1).")
AT_PORT = typer.Option(5556, "--at-port", callback=port(), help="AT command UDP port.")
NAVDATA_PORT = typer.Option(5554, "--navdata-port", callback=port(), help="Navdata UDP port.")


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
        link.connect(timeout_s=5.0)
    except LinkError as err:
        _fail(str(err))
    if link.at_bind_warning:
        typer.echo(f"warning: {link.at_bind_warning}", err=True)


def _ask_holder_to_land(drone: str, at_port: int) -> bool:
    """If a ``fly`` here holds the drone: SIGTERM it (it lands through its own session) and
    wait up to :data:`HANDOVER_S` for it to let go. True if it did."""
    from ardrone_nmpc.links.flight_lock import FlightLock

    lock = FlightLock(drone, at_port)
    pid = lock.holder()
    if pid is None or pid == os.getpid():
        return False
    typer.echo(f"a flight (pid {pid}) holds the drone: asking it to land (SIGTERM)", err=True)
    try:
        os.kill(pid, signal.SIGTERM)
    except OSError as err:
        typer.echo(f"warning: cannot signal pid {pid}: {err}", err=True)
        return False
    deadline = time.monotonic() + HANDOVER_S
    while time.monotonic() < deadline:
        if lock.holder() is None:
            return True
        time.sleep(0.1)
    typer.echo(f"pid {pid} still holds the drone after {HANDOVER_S:.0f} s: landing it from here",
               err=True)
    return False


def _take_lock(drone: str, at_port: int):
    from ardrone_nmpc.links.flight_lock import DroneBusy, FlightLock

    lock = FlightLock(drone, at_port)
    try:
        lock.acquire()
    except DroneBusy as err:
        _fail(str(err))
    return lock


def land(drone: str = DRONE, at_port: int = AT_PORT, navdata_port: int = NAVDATA_PORT) -> None:
    """Land the drone: REF land until navdata shows it on the ground (a `fly` holding it is
    asked to land first). Ctrl-C twice within 2 s cuts the motors instead."""
    from ardrone_nmpc.runtime.session import FlightSession
    from ardrone_nmpc.runtime.signals import exit_code_of, landing_signals

    link = _link(drone, at_port, navdata_port)
    if _ask_holder_to_land(drone, at_port):
        typer.echo("the flight landed the drone and ended")
        return
    with link:
        _connect(link)
        session = FlightSession(None, link, None, event=lambda kind, **fields: None,
                                warn=lambda line: typer.echo(line, err=True))
        try:
            with landing_signals():
                landed = session.land()
        except KeyboardInterrupt as err:
            done = ("motors cut (emergency)" if session.landed_cleanly
                    else "landing not confirmed by navdata — check the drone")
            _fail(f"interrupted: {done}", exit_code_of(err))
    if not landed:
        _fail("landing not confirmed by navdata — check the drone")
    typer.echo(f"landed ({link.navdata.mode.value})")


def emergency(drone: str = DRONE, at_port: int = AT_PORT,
              navdata_port: int = NAVDATA_PORT) -> None:
    """Cut the motors now (the drone falls). Confirmed by navdata's emergency bit."""
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.links.flight_lock import FlightLock

    link = _link(drone, at_port, navdata_port)
    pid = FlightLock(drone, at_port).holder()
    if pid is not None and pid != os.getpid():
        try:  # it must stop holding take-off, or its REFs and ours make edge after edge
            os.kill(pid, signal.SIGTERM)
            typer.echo(f"told the flight holding the drone (pid {pid}) to land", err=True)
        except OSError:
            pass
    with link:
        _connect(link)
        link.emergency()
        deadline = time.monotonic() + EMERGENCY_CONFIRM_S
        while time.monotonic() < deadline:
            nav = link.navdata
            if nav is not None and nav.mode is FlightMode.EMERGENCY and \
                    link.navdata_rx_t_s > time.monotonic() - 0.5:
                link.land()  # bit 8 low again: no further edges (which would clear it)
                typer.echo("motors cut (emergency); clear it on the ground with "
                           "`ardrone-nmpc reset`")
                return
            time.sleep(0.02)
        mode = link.navdata.mode.value if link.navdata is not None else "no navdata"
    _fail(f"emergency not confirmed by navdata within {EMERGENCY_CONFIRM_S:.0f} s ({mode}) — "
          "check the drone")


def reset(drone: str = DRONE, at_port: int = AT_PORT, navdata_port: int = NAVDATA_PORT) -> None:
    """Clear an emergency (the drone must be on the ground)."""
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.links.drone_link import LinkError

    link = _link(drone, at_port, navdata_port)
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
                                            help="TCP configuration port.")) -> None:
    """One navdata snapshot: state, ctrl_state, battery, altitude and the firmware-held
    limits."""
    from ardrone_nmpc.links.drone_link import LinkError
    from ardrone_nmpc.protocol.navdata import CtrlMajor, DroneState

    link = _link(drone, at_port, navdata_port, control_port=control_port)
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

