"""``ardrone-nmpc simulate``: fly a config in lockstep simulation into a run directory.

A flight that reached its end without doing its job (a failed verdict,
:mod:`ardrone_nmpc.runs.verdict`) prints its summary and ``run: <dir>`` like any other, with
one ``error:`` line before, and exits 1."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from ardrone_nmpc.cli.console import config_notes, stdout_console
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.record import Recording, record_lockstep
from ardrone_nmpc.cli.tables import render_summary


def simulate_command(*, config: Path, overrides: list[str], log_dir: Path, seed: int | None,
                     quiet: bool, foxglove: bool = False, foxglove_port: int = 8765) -> None:
    """The ``simulate`` command: load, fly (served live with ``foxglove``), print; last line
    ``run: <dir>``."""
    import typer

    from ardrone_nmpc.viz.live import open_live_view

    from ardrone_nmpc.cli.handler import report
    from ardrone_nmpc.errors import EXIT_ERROR
    from ardrone_nmpc.runs.verdict import FAILED_VERDICTS, verdict_message

    cfg = load_config(config, overrides)
    config_notes(cfg)
    with open_live_view(foxglove, foxglove_port, cfg=cfg, seed=seed, pace=True,
                        echo=lambda line: typer.echo(line, err=True)) as live:
        recording = run_simulate_command(cfg=cfg, log_dir=log_dir, seed=seed, quiet=quiet,
                                         live=live)
    ending = recording.result.ending
    if ending in FAILED_VERDICTS:
        report([f"{ending}: {verdict_message(ending)}"])
    typer.echo(f"run: {recording.path}")
    if ending in FAILED_VERDICTS:
        raise typer.Exit(code=EXIT_ERROR)


def run_simulate_command(*, cfg, log_dir: Path, seed: int | None, quiet: bool,
                         console: Console | None = None, live=None) -> Recording:
    """Fly ``cfg`` in lockstep simulation into a new run directory; return its recording.
    ``live`` (a :class:`~ardrone_nmpc.viz.live.LiveView`) sees every row and event too."""
    console = console or stdout_console()
    seed = cfg.sim.seed if seed is None else seed
    if not quiet:
        console.print(f"simulating [bold]{cfg.name}[/]: {cfg.duration_s:g} s "
                      f"(+{cfg.sim.settle_s:g} s settle), controller {cfg.controller.kind}"
                      f"{'/' + cfg.controller.solver.method if cfg.controller.kind == 'nmpc' else ''},"
                      f" estimator {cfg.estimator.kind}, seed {seed}")
    columns = [TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
               TimeRemainingColumn()]
    with Progress(*columns, console=console, disable=quiet, transient=True) as progress:
        task = progress.add_task("flying", total=1.0)
        recording = record_lockstep(cfg, log_dir, seed=seed, live=live,
                                    progress=lambda f: progress.update(task, completed=f))
    result, path = recording.result, recording.path
    if not quiet:
        console.print(render_summary(recording.summary, title=f"{cfg.name} — {path.name}"))
        sim_s = cfg.duration_s + cfg.sim.settle_s
        loop_s = result.loop_wall_s
        console.print(f"{result.ticks} ticks, {sim_s:g} s flown in {loop_s:.2f} s "
                      f"({sim_s / loop_s:.0f}× real time); {recording.wall_s:.1f} s in all, "
                      f"kernels loaded or compiled included; ended: {result.ending}, drone "
                      f"{result.final_mode.value}")
    return recording
