"""``ardrone-nmpc simulate``: fly a config in lockstep simulation into a run directory."""

from __future__ import annotations

import time
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from ardrone_nmpc.cli.console import stdout_console
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.runs.summary import render_summary, summarise


def simulate_command(*, config: Path, overrides: list[str], log_dir: Path, seed: int | None,
                     quiet: bool) -> None:
    """The ``simulate`` command: load, fly, print; last line ``run: <dir>``."""
    import typer

    cfg = load_config(config, overrides)
    path = run_simulate_command(cfg=cfg, log_dir=log_dir, seed=seed, quiet=quiet)
    typer.echo(f"run: {path}")


def run_simulate_command(*, cfg, log_dir: Path, seed: int | None, quiet: bool,
                         console: Console | None = None) -> Path:
    """Fly ``cfg`` in lockstep simulation into a new run directory; return its path."""
    console = console or stdout_console()
    seed = cfg.sim.seed if seed is None else seed
    if seed != cfg.sim.seed:  # the run directory must reproduce the run: record the seed used
        cfg = cfg.model_copy(update={"sim": cfg.sim.model_copy(update={"seed": seed})})
    wall0 = time.perf_counter()
    with RunRecorder.create(log_dir, cfg, seed=seed) as recorder:
        if not quiet:
            console.print(f"simulating [bold]{cfg.name}[/]: {cfg.duration_s:g} s "
                          f"(+{cfg.sim.settle_s:g} s settle), controller {cfg.controller.kind}"
                          f"{'/' + cfg.controller.solver.method if cfg.controller.kind == 'nmpc' else ''},"
                          f" estimator {cfg.estimator.kind}, seed {seed}")
        columns = [TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                   TimeRemainingColumn()]
        with Progress(*columns, console=console, disable=quiet, transient=True) as progress:
            task = progress.add_task("flying", total=1.0)
            result = run_lockstep(recorder.config, recorder=recorder, seed=seed,
                                  progress=lambda f: progress.update(task, completed=f))
        wall_s = time.perf_counter() - wall0
        recorder.event(result.ticks * cfg.loop.period_s - cfg.sim.settle_s, "simulated",
                       wall_s=wall_s, ticks=result.ticks, ending=result.ending,
                       final_mode=result.final_mode.value)
        recorder.flush()
        rows = summarise(read_run(recorder.path))
        recorder.write_summary(rows)
    if not quiet:
        console.print(render_summary(rows, title=f"{cfg.name} — {recorder.path.name}"))
        sim_s = cfg.duration_s + cfg.sim.settle_s
        loop_s = result.loop_wall_s
        console.print(f"{result.ticks} ticks, {sim_s:g} s flown in {loop_s:.2f} s "
                      f"({sim_s / loop_s:.0f}× real time); {wall_s:.1f} s in all, kernels "
                      f"loaded or compiled included; ended: {result.ending}, drone "
                      f"{result.final_mode.value}")
    return recorder.path
