"""``ardrone-nmpc fly``: the live display around a real-time flight, and its exit codes.

The flight itself (the drone's backend, session, loop, landing, the run directory) is
:func:`~ardrone_nmpc.experiments.flight.run_flight`; this module shows its figures while it
flies (on a terminal) and decides how the command ends. Whatever happens, the landing outcome and the run directory are printed:

* the flight completed: its summary table, then ``run: <dir>``; exit 0;
* a flight error (link lost, supervisor landing, emergency, pre-flight refusal, a ``faults``
  section on a drone that is not simulated): its ``error:`` line, exit 1;
* Ctrl-C: exit 130; any other terminating signal (TERM, HUP, QUIT, USR1/2, PIPE): exit
  128 + its number (the session has landed in every case);
* navdata never confirmed the landing: ``error: landing not confirmed by navdata — check
  the drone`` in every case, and at least exit 1.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from ardrone_nmpc.cli.handler import report
from ardrone_nmpc.errors import EXIT_ERROR, EXIT_INTERRUPTED, UserError

LANDING_NOT_CONFIRMED = "landing not confirmed by navdata — check the drone"


def fly_command(*, config: Path, overrides: list[str], sim: bool, drone: str | None,
                at_port: int | None, navdata_port: int | None, mocap_port: int | None,
                duration_s: float | None, log_dir: Path, dashboard: bool,
                seed: int | None, foxglove: bool = False, foxglove_port: int = 8765,
                mcap: Path | None = None) -> None:
    """Fly ``config`` (see the module docstring for what is printed and the exit codes)."""
    from rich.live import Live

    from ardrone_nmpc.cli.console import stderr_console
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.experiments.flight import run_flight
    from ardrone_nmpc.runtime.realtime import FlightResult, LandingNotConfirmed
    from ardrone_nmpc.runtime.signals import Terminated, exit_code_of
    from ardrone_nmpc.viz.dashboard import LiveStatus
    from ardrone_nmpc.viz.live import open_live_view

    overrides = list(overrides)
    if duration_s is not None:
        overrides.append(f"duration_s={duration_s!r}")
    cfg = load_config(config, overrides)
    # the land / cut-motors keys need a terminal to read them from and to show them on
    keys = bool(sys.stdin and sys.stdin.isatty() and sys.stderr and sys.stderr.isatty())
    view = LiveStatus(f"{cfg.name} — {'sim://loopback' if sim else drone or cfg.drone.host}",
                      **({} if keys else {"keys_help": None}))
    use_live = dashboard and sys.stderr is not None and sys.stderr.isatty()
    console = stderr_console()
    live = Live(view, console=console, refresh_per_second=4, transient=True)
    result = FlightResult()
    code = 0
    error: BaseException | None = None
    try:
        with open_live_view(foxglove, foxglove_port, cfg=cfg, seed=seed, mcap=mcap,
                            echo=lambda line: typer.echo(line, err=True)) as sink:
            if use_live:
                live.start()
            run_flight(cfg=cfg, sim=sim, drone_host=drone, at_port=at_port,
                       navdata_port=navdata_port, mocap_port=mocap_port, log_dir=log_dir,
                       seed=seed, status=view.update if use_live else None, result=result,
                       sink=sink, operator_keys=keys,
                       warn=(lambda line: console.print(line, markup=False, highlight=False))
                       if use_live else None)
    except Terminated as err:  # before KeyboardInterrupt: it is one
        code = exit_code_of(err)
    except KeyboardInterrupt:
        code = EXIT_INTERRUPTED
    except UserError as err:  # the session has landed: first why, then how the landing went
        error = err
        code = err.exit_code
    except BaseException as err:  # an OSError or a bug: reported by the central handler
        error = err
        raise
    finally:
        if use_live:
            live.stop()
        if isinstance(error, UserError):
            report(error.messages)
        if result.landed is False and not isinstance(error, LandingNotConfirmed):
            report([LANDING_NOT_CONFIRMED])
            code = code or EXIT_ERROR
        _print_outcome(result.path, summary=code == 0 and error is None)
    if code:
        raise typer.Exit(code=code)


def _print_outcome(path: Path | None, *, summary: bool) -> None:
    """The run's summary table (a completed flight only), then ``run: <dir>``."""
    if path is None:
        return
    if summary:
        from ardrone_nmpc.cli.summary import summary_command

        summary_command(run_dirs=[path])
    typer.echo(f"run: {path}")
