"""``ardrone-nmpc robustness``: fly a config over a grid of plant deviations, judge each
flight, write ``robustness.csv`` and the map (docs/robustness.md).

The pure parts are in :mod:`ardrone_nmpc.experiments.robustness`; this module drives them:
options, progress (stderr), the map's table and the clean region (stdout).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from ardrone_nmpc.cli.console import stdout_console

MAP_FILE = "robustness.png"
_STYLE = {"clean": "green", "settled": "yellow", "limit cycle": "dark_orange",
          "supervisor": "magenta", "diverged": "red", "failed": "red"}


def _tables(outcome) -> list[Table]:
    from ardrone_nmpc.experiments.robustness.report import cells

    grid = outcome.grid
    tables = []
    for panel, by_xy in cells(outcome.rows, grid).items():
        xs = sorted({k[0] for k in by_xy}, key=float)
        ys = sorted({k[1] for k in by_xy}, key=float)
        name = lambda p: p.rsplit(".", 1)[-1]  # noqa: E731
        table = Table(title=f"{name(grid.panel)} = {panel}" if grid.panel else None)
        table.add_column(f"{name(grid.y)} \\ {name(grid.x)}")
        for xv in xs:
            table.add_column(xv, justify="center")
        for yv in ys:
            cells_row = []
            for xv in xs:
                cell = by_xy.get((xv, yv))
                if cell is None:
                    cells_row.append("")
                    continue
                style = _STYLE.get(cell.label, "white")
                cells_row.append(f"[{style}]{cell.clean}/{cell.flights} {escape(cell.label)}[/]")
            table.add_row(yv, *cells_row)
        tables.append(table)
    return tables


def _report(outcome, config: Path, report: Path, fig, command: str) -> None:
    """Copy the CSV and the map into ``report`` and write its markdown."""
    import shutil

    from ardrone_nmpc.experiments.robustness.doc import commit_of, markdown
    from ardrone_nmpc.viz.figure import save_figure

    report.mkdir(parents=True, exist_ok=True)
    name = config.stem
    shutil.copyfile(outcome.csv_path, report / f"{name}.csv")
    if fig is not None:
        save_figure(fig, report / f"{name}.png")
    text = markdown(name, outcome.rows, outcome.grid, command=command,
                    commit=commit_of(Path(__file__).parent))
    (report / f"{name}.md").write_text(text, encoding="utf-8")
    typer.echo(f"report: {report / (name + '.md')}")


def run_robustness_command(*, config: Path, overrides, grid_file: Optional[Path],
                           out_dir: Path, jobs: int, engine: str, scheduler: Optional[str],
                           console: Console | None = None, report: Optional[Path] = None,
                           command: str = "ardrone-nmpc robustness") -> Path:
    """Run it and print the tables and the clean region; returns ``robustness.csv``."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from ardrone_nmpc.cli.sweep import engine_errors
    from ardrone_nmpc.config.schema import ConfigError
    from ardrone_nmpc.experiments.robustness.grid import load_grid
    from ardrone_nmpc.experiments.robustness.report import region_lines
    from ardrone_nmpc.experiments.robustness.run import run_robustness

    errors = engine_errors(engine=engine, scheduler=scheduler)
    if errors:
        raise ConfigError(errors)
    grid = load_grid(grid_file)
    console = console or stdout_console()
    with Progress(TextColumn("robustness"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("", total=grid.size)
        outcome = run_robustness(config=config, overrides=overrides, grid=grid,
                                 out_dir=out_dir, jobs=jobs, engine=engine,
                                 scheduler=scheduler,
                                 progress=lambda row: bar.update(task, advance=1))
    for table in _tables(outcome):
        console.print(table)
    for line in region_lines(outcome.rows, grid):
        console.print(escape(line))
    counts = ", ".join(f"{n} {k}" for k, n in outcome.counts.items() if n)
    console.print(f"{len(outcome.rows)} flights ({outcome.flown} flown, {outcome.resumed} "
                  f"resumed): {outcome.clean} clean; {counts}; {outcome.wall_s:.1f} s wall "
                  f"({engine}, {jobs} jobs)")
    fig = None
    try:
        from ardrone_nmpc.viz.figure import save_figure
        from ardrone_nmpc.viz.robustness_map import figure_robustness_map

        fig = figure_robustness_map([r.as_row() for r in outcome.rows], x=grid.x, y=grid.y,
                                    panel=grid.panel, title=f"{config.stem}: robustness")
        typer.echo(f"map: {save_figure(fig, Path(out_dir) / MAP_FILE)}")
    except ImportError:
        typer.echo("map: not drawn (matplotlib missing: pip install 'ardrone-nmpc[plot]')",
                   err=True)
    if report is not None:
        _report(outcome, config, Path(report), fig, command)
    return outcome.csv_path


def register(app: typer.Typer) -> None:
    """Add the ``robustness`` command to ``app``."""
    from ardrone_nmpc.cli.options import MAX_JOBS, choice, non_empty

    @app.command()
    def robustness(
        config: Path = typer.Argument(..., help="Experiment YAML file."),
        grid_file: Optional[Path] = typer.Option(None, "--grid-file", help="YAML of the grid's axes (dotted.path: [values]) and map (x, y, panel); default: delay 0–0.4 s × attitude gain 0.6–2 × lag 0.05/0.2 s × vertical gain 0.6/1.4 × wind 0/0.4 m/s (160 flights)."),
        jobs: Optional[int] = typer.Option(None, "--jobs", min=1, max=MAX_JOBS, help="Parallel workers (default: the CPU count); 1 = in this process."),
        engine: str = typer.Option("local", "--engine", **choice(("local", "dask")), help="'local': a process pool on this machine; 'dask': a Dask cluster."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", callback=non_empty, help="Dask scheduler address (tcp://host:8786); default: a local cluster of --jobs workers."),
        out: Optional[Path] = typer.Option(None, "-o", "--output", help="Directory: one run directory per flight, robustness.csv, robustness.png (default: logs/robustness/<config name>). Finished flights in it are judged again, not flown."),
        set_: List[str] = typer.Option([], "--set", help="Override a config value: dotted.path=value (repeatable), before the grid."),
        report: Optional[Path] = typer.Option(None, "--report", help="Also write DIR/<config>.csv, .png and .md (the committed docs/robustness/ files)."),
    ) -> None:
        """Fly the config in lockstep over a grid of plant deviations (delay, attitude gain
        and lag, vertical gain, wind), classify each flight (settled, limit cycle,
        supervisor, diverged; clean or not), print the map and the clean region. Last
        line: robustness: <robustness.csv>."""
        out_dir = out if out is not None else Path("logs") / "robustness" / config.stem
        n_jobs = jobs if jobs is not None else os.cpu_count() or 1
        import shlex
        import sys

        command = ("ardrone-nmpc " + " ".join(shlex.quote(a) for a in sys.argv[1:])
                   if sys.argv[1:2] == ["robustness"] else f"ardrone-nmpc robustness {config}")
        path = run_robustness_command(config=config, overrides=set_, grid_file=grid_file,
                                      out_dir=out_dir, jobs=n_jobs, engine=engine,
                                      scheduler=scheduler, report=report, command=command)
        typer.echo(f"robustness: {path}")
