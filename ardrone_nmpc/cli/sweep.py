"""``ardrone-nmpc sweep``: run a grid of lockstep simulations, write ``sweep.csv``, rank them.

The pure parts (grid, cases, metrics, status, engines) are in :mod:`ardrone_nmpc.experiments.sweep`; this
module drives them: resume, progress bar (stderr), ``sweep.csv`` as cases finish, Ctrl-C, the
ranked table (stdout).
"""

from __future__ import annotations

import importlib.util
import math
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                           TimeElapsedColumn, TimeRemainingColumn)
from rich.table import Table

from ardrone_nmpc.cli.console import stdout_console
from ardrone_nmpc.cli.narrow import fit
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.errors import EXIT_INTERRUPTED, UserError
from ardrone_nmpc.experiments.sweep import (DIVERGE_M, PARTIAL_DIR, RANK_METRICS, STATUSES, SWEEP_FILE, Case,
                                CaseResult, SweepCsvAppender, build_cases, finished_result,
                                iter_dask, iter_local, parse_grid, rank_rows, resume_results,
                                sweep_columns, sweep_row, write_sweep_csv)

ENGINES = ("local", "dask")


class SweepEngineError(UserError, RuntimeError):
    """The engine could not run (no Dask scheduler at the address, …): one line, exit 1."""


class SweepInterrupted(UserError):
    """Ctrl-C stopped the sweep; what finished is in sweep.csv (exit 130)."""

    exit_code = EXIT_INTERRUPTED


class SweepFailures(UserError):
    """Some cases failed (their message is in sweep.csv); exit 1."""


@dataclass
class SweepOutcome:
    """What a sweep did: case counts per status, how many were flown and resumed, whether
    Ctrl-C stopped it, where ``sweep.csv`` is, the wall time (s)."""

    csv_path: Path
    total: int
    flown: int = 0
    resumed: int = 0
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(STATUSES, 0))
    interrupted: bool = False
    wall_s: float = math.nan


def engine_errors(*, engine: str, scheduler: str | None) -> list[str]:
    """The ``--engine`` / ``--scheduler`` mistakes (one ``--option: message`` line each) of
    the commands that fly many cases: ``sweep`` and ``tune``."""
    errors = []
    if engine not in ENGINES:
        errors.append(f"--engine: unknown engine {engine!r}; choose {', '.join(ENGINES)}")
    if scheduler is not None and engine != "dask":
        errors.append("--scheduler: only with --engine dask")
    if engine == "dask" and importlib.util.find_spec("distributed") is None:
        errors.append("--engine dask: needs dask.distributed "
                      "(pip install 'ardrone-nmpc[distributed]')")
    return errors


def check_options(*, engine: str, scheduler: str | None, rank_by: str) -> None:
    """Raise :class:`ConfigError` (one ``--option: message`` line each) for bad options."""
    errors = engine_errors(engine=engine, scheduler=scheduler)
    if rank_by not in RANK_METRICS:
        errors.append(f"--rank-by: unknown metric {rank_by!r}; choose "
                      f"{', '.join(RANK_METRICS)}")
    if errors:
        raise ConfigError(errors)


def _out_dir(out_dir: Path) -> Path:
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"--output {out_dir}: exists and is not a directory")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:  # under a file, on a read-only disk, no permission
        raise ConfigError(f"--output {out_dir}: cannot create the directory: "
                          f"{err.strerror or err}") from None
    return out_dir


def _check_inputs(cases: Sequence[Case]) -> None:
    """Read and check every waypoint file the cases name, before any case flies."""
    from ardrone_nmpc.reference.trajectories import path_file

    checked = set()
    for case in cases:
        ref = case.config.reference
        if (ref.kind == "path" or ref.path_file) and ref.path_file not in checked:
            path_file(ref)
            checked.add(ref.path_file)


def _engine(pending: Sequence[Case], *, engine: str, out_dir: Path, jobs: int,
            scheduler: str | None, diverge_m: float) -> Iterator[CaseResult]:
    if engine == "dask":
        return iter_dask(pending, out_dir=out_dir, jobs=jobs, scheduler=scheduler,
                         diverge_m=diverge_m)
    return iter_local(pending, out_dir=out_dir, jobs=jobs, diverge_m=diverge_m)


def _progress(console: Console) -> Progress:
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), TimeRemainingColumn(), console=console,
                    transient=True)


def _describe(results: Mapping[str, CaseResult]) -> str:
    counts = {s: sum(r.status == s for r in results.values()) for s in STATUSES}
    return "sweep " + " · ".join(f"{s} {n}" for s, n in counts.items())


def _run_pending(pending: Sequence[Case], *, cases_by_id: Mapping[str, Case],
                 results: dict[str, CaseResult], csv_path: Path, columns: Sequence[str],
                 outcome: SweepOutcome, err_console: Console, engine: str,
                 **engine_options) -> None:
    """Fly ``pending``, appending each result to ``results`` and ``sweep.csv`` as it comes.
    Ctrl-C sets ``outcome.interrupted``: the cases not started are cancelled."""
    appender = SweepCsvAppender(csv_path, columns)
    stream = _engine(pending, engine=engine, **engine_options)
    try:
        with _progress(err_console) as progress:
            task = progress.add_task(_describe(results), total=len(pending))
            for result in stream:
                results[result.case_id] = result
                appender.append(sweep_row(cases_by_id[result.case_id], result))
                outcome.flown += 1
                progress.update(task, advance=1, description=_describe(results))
    except KeyboardInterrupt:
        outcome.interrupted = True
    except (OSError, TimeoutError) as err:
        if engine != "dask":
            raise
        raise SweepEngineError(f"--engine dask: {' '.join(str(err).split())}") from None
    finally:
        try:
            stream.close()  # cancels what has not started, waits for what is running
        finally:
            appender.close()


def _finish(cases: Sequence[Case], *, results: dict[str, CaseResult], out_dir: Path,
            columns: Sequence[str], csv_path: Path, diverge_m: float) -> int:
    """Pick up cases that finished without being reported (Ctrl-C), rewrite ``sweep.csv``
    in case order, drop the empty staging directory. Returns how many were picked up."""
    picked = 0
    for case in cases:
        if case.case_id not in results:
            found = finished_result(case, out_dir=out_dir, diverge_m=diverge_m)
            if found is not None:
                results[case.case_id] = found
                picked += 1
    write_sweep_csv(csv_path, columns,
                    [sweep_row(c, results[c.case_id]) for c in cases if c.case_id in results])
    try:
        (out_dir / PARTIAL_DIR).rmdir()
    except OSError:  # absent, or holds an interrupted case (removed when it is re-run)
        pass
    return picked


def _cell(text: str) -> str:
    try:
        value = float(text)
    except ValueError:
        return text
    if math.isnan(value):
        return "—"
    return f"{int(value)}" if value.is_integer() and abs(value) < 1e15 else f"{value:.4g}"


def short_labels(paths: Sequence[str]) -> list[str]:
    """The shortest distinct trailing parts of dotted paths (table headers):
    ``controller.dtau_s`` → ``dtau_s``; ``a.q``, ``b.q`` stay ``a.q``, ``b.q``."""
    for depth in range(1, max((p.count(".") + 1 for p in paths), default=1) + 1):
        labels = [".".join(p.split(".")[-depth:]) for p in paths]
        if len(set(labels)) == len(labels):
            return labels
    return list(paths)


def render_ranked(rows: Sequence[Mapping[str, str]], *, params: Sequence[str], rank_by: str,
                  top: int | None = None, title: str | None = None) -> Table:
    """The ``sweep.csv`` rows as a ``rich`` table, best first by ``--rank-by`` (see
    :func:`~ardrone_nmpc.experiments.sweep.rank_rows`); ``top`` keeps the first rows only."""
    column = RANK_METRICS[rank_by]
    ranked = rank_rows(rows, metric=column)[:top]
    metrics = ["rmse_m", "settling_s", "overshoot_pct", "path_deviation_m", "solve_p99_us",
               "fallbacks"]
    metrics = [m for m in metrics if m == column or any(_cell(r[m]) != "—" for r in rows)]
    table = Table(title=title)
    table.add_column("#", justify="right")
    for label in short_labels(params):
        table.add_column(label)
    for name in metrics:
        table.add_column(f"[bold]{name}[/]" if name == column else name, justify="right")
    table.add_column("status")
    table.add_column("note", overflow="fold", max_width=48)
    style = {"ok": "green", "unstable": "yellow", "failed": "red"}
    for i, row in enumerate(ranked, start=1):
        status = row["status"]
        table.add_row(str(i), *(escape(row[p]) for p in params),
                      *(_cell(row[m]) for m in metrics),
                      f"[{style.get(status, 'white')}]{escape(status)}[/]", escape(row["message"]))
    return table


def run_sweep_command(*, config: Path, grid: Sequence[str], overrides: Sequence[str],
                      out_dir: Path, jobs: int, engine: str = "local",
                      scheduler: str | None = None, rank_by: str = "rmse",
                      top: int | None = None, diverge_m: float = DIVERGE_M,
                      console: Console | None = None,
                      err_console: Console | None = None) -> SweepOutcome:
    """Run the sweep: validate every case, skip the finished ones, fly the rest with
    ``engine`` on ``jobs`` workers, keep ``out_dir/sweep.csv`` current, print the ranked
    table. Raises :class:`ConfigError` for bad input (before anything runs) and
    :class:`SweepEngineError` if the engine cannot run."""
    check_options(engine=engine, scheduler=scheduler, rank_by=rank_by)
    cases = build_cases(config_path=config, overrides=overrides, grid=parse_grid(grid))
    _check_inputs(cases)
    out_dir = _out_dir(Path(out_dir))
    console = console or stdout_console()
    wall0 = time.perf_counter()
    params = [path for path, _ in cases[0].params]
    columns = sweep_columns(params)
    results = resume_results(cases, out_dir=out_dir, diverge_m=diverge_m)
    outcome = SweepOutcome(out_dir / SWEEP_FILE, len(cases), resumed=len(results))
    pending = [c for c in cases if c.case_id not in results]
    try:
        write_sweep_csv(outcome.csv_path, columns,
                        [sweep_row(c, results[c.case_id]) for c in cases if c.case_id in results])
        if pending:
            _run_pending(pending, cases_by_id={c.case_id: c for c in cases}, results=results,
                         csv_path=outcome.csv_path, columns=columns, outcome=outcome,
                         err_console=err_console or Console(stderr=True), engine=engine,
                         out_dir=out_dir, jobs=jobs, scheduler=scheduler, diverge_m=diverge_m)
    finally:
        outcome.flown += _finish(cases, results=results, out_dir=out_dir, columns=columns,
                                 csv_path=outcome.csv_path, diverge_m=diverge_m)
    outcome.wall_s = time.perf_counter() - wall0
    for result in results.values():
        outcome.counts[result.status] += 1
    rows = [sweep_row(c, results[c.case_id]) for c in cases if c.case_id in results]
    title = (f"{cases[0].config.name}: {len(rows)} of {len(cases)} cases, best "
             f"{RANK_METRICS[rank_by]} first")
    if rows:
        console.print(fit(render_ranked(rows, params=params, rank_by=rank_by, top=top,
                                        title=title), console))
    console.print(f"{outcome.total} cases: {outcome.flown} flown, {outcome.resumed} resumed"
                  f"{' (interrupted)' if outcome.interrupted else ''}; "
                  + ", ".join(f"{n} {s}" for s, n in outcome.counts.items())
                  + f"; {outcome.wall_s:.1f} s wall ({engine}, {jobs} jobs)")
    return outcome


def sweep_command(*, config: Path, grid: Sequence[str], overrides: Sequence[str],
                  out: Path | None, jobs: int | None, engine: str, scheduler: str | None,
                  rank_by: str, top: int | None, diverge_m: float) -> None:
    """The ``sweep`` command: run it, print ``sweep: <sweep.csv>``; Ctrl-C is
    :class:`SweepInterrupted` (exit 130), failed cases :class:`SweepFailures` (exit 1)."""
    import os

    import typer

    out_dir = out if out is not None else Path("logs") / "sweeps" / config.stem
    n_jobs = jobs if jobs is not None else os.cpu_count() or 1
    resume = "interrupted: re-run the same command to resume"
    try:
        outcome = run_sweep_command(config=config, grid=grid, overrides=overrides,
                                    out_dir=out_dir, jobs=n_jobs, engine=engine,
                                    scheduler=scheduler, rank_by=rank_by, top=top,
                                    diverge_m=diverge_m)
    except KeyboardInterrupt:
        raise SweepInterrupted(resume) from None
    typer.echo(f"sweep: {outcome.csv_path}")
    if outcome.interrupted:
        raise SweepInterrupted(resume)
    if outcome.counts["failed"]:
        raise SweepFailures(f"{outcome.counts['failed']} of {outcome.total} cases failed (see "
                            f"the message column of {outcome.csv_path})")
