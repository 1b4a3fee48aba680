"""``ardrone-nmpc simulate`` and ``summary``: run directories in, tables out."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from ardrone_nmpc.experiments.record import record_lockstep
from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.runs.summary import render_side_by_side, render_summary, summarise


def run_simulate_command(*, cfg, log_dir: Path, seed: int | None, quiet: bool,
                         console: Console | None = None, live=None) -> Path:
    """Fly ``cfg`` in lockstep simulation into a new run directory; return its path.
    ``live`` (a :class:`~ardrone_nmpc.viz.live.LiveView`) sees every row and event too."""
    console = console or _console()
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
    return path


def _console() -> Console:
    """The terminal's width on a TTY; 150 columns when piped (tables of runs are wide)."""
    import sys

    return Console(width=None if sys.stdout.isatty() else 150)


def run_summary_command(*, run_dirs: list[Path], console: Console | None = None) -> None:
    console = console or _console()
    runs = []
    for run_dir in run_dirs:
        run = read_run(run_dir)
        for warning in run.warnings:
            console.print(f"[yellow]warning[/]: {warning}")
        runs.append((Path(run_dir).name, summarise(run)))
    if len(runs) == 1:
        console.print(render_summary(runs[0][1], title=runs[0][0]))
    else:
        console.print(render_side_by_side(runs))
