"""Flying a config over a grid of plant deviations and judging every flight.

The flights are a sweep's cases (:mod:`ardrone_nmpc.experiments.sweep`: one run directory
each under ``DIR/<case id>/``, resumable, in this process, a local pool or on Dask); each
finished case is read back and judged (:mod:`.judge`) in this process, and
``DIR/robustness.csv`` holds one row per flight.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ardrone_nmpc.experiments.robustness.grid import RobustnessGrid
from ardrone_nmpc.experiments.robustness.judge import CLASSES, FlightVerdict, judge_columns
from ardrone_nmpc.experiments.sweep import (Case, CaseResult, build_cases, iter_dask,
                                            iter_local, resume_results)
from ardrone_nmpc.runs.rundir import format_number
from ardrone_nmpc.runs.sweep_table import write_csv_table

__all__ = ["ROBUSTNESS_FILE", "RobustnessOutcome", "RobustnessRow", "judge_case",
           "robustness_columns", "run_robustness"]

ROBUSTNESS_FILE = "robustness.csv"
#: The class of a flight that could not run (the exception is its reason).
FAILED = "failed"
_VERDICT_COLUMNS = ("verdict", "clean", "amplitude_m", "period_s", "saturation_frac",
                    "steady_error_m", "supervisor_ticks", "reason")


@dataclass(frozen=True)
class RobustnessRow:
    """One flight: its case, the grid values (path → text), its verdict, its run directory."""

    case_id: str
    params: tuple[tuple[str, str], ...]
    verdict: FlightVerdict
    run_dir: str

    def as_row(self) -> dict[str, str]:
        row = {"case": self.case_id, **dict(self.params)}
        for name, value in self.verdict.as_row().items():
            row[name] = (value if isinstance(value, str) else str(value).lower()
                         if isinstance(value, bool) else format_number(value))
        row["run_dir"] = self.run_dir
        return row


@dataclass
class RobustnessOutcome:
    """Every flight's row (grid order), the counts per class, the clean flights, the
    flights flown now and resumed, and the wall time (s)."""

    rows: list[RobustnessRow]
    grid: RobustnessGrid
    csv_path: Path
    flown: int = 0
    resumed: int = 0
    wall_s: float = math.nan
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def clean(self) -> int:
        return sum(r.verdict.clean for r in self.rows)


def robustness_columns(grid: RobustnessGrid) -> list[str]:
    return ["case", *(p for p, _ in grid.axes), *_VERDICT_COLUMNS, "run_dir"]


def judge_case(case: Case, result: CaseResult, out_dir: Path) -> FlightVerdict:
    """The verdict of a finished case, read back from its run directory."""
    from ardrone_nmpc.runs.rundir import LogError, read_run

    if result.status == "failed":
        return _failed(result.message)
    try:
        run = read_run(Path(out_dir) / result.run_dir)
    except LogError as err:
        return _failed(str(err))
    ending = next((e.get("ending", "completed") for e in reversed(run.events)
                   if e.get("kind") == "simulated"), "completed")
    safety = run.config.safety
    return judge_columns(run.columns, geofence_min_m=safety.geofence_min_m,
                         geofence_max_m=safety.geofence_max_m, ending=ending)


def _failed(message: str) -> FlightVerdict:
    return FlightVerdict(FAILED, False, math.nan, math.nan, math.nan, math.nan, 0,
                         " ".join(message.split()))


def _engine(cases: Sequence[Case], *, engine: str, out_dir: Path, jobs: int,
            scheduler: str | None) -> Iterator[CaseResult]:
    if engine == "dask":
        return iter_dask(cases, out_dir=out_dir, jobs=jobs, scheduler=scheduler)
    return iter_local(cases, out_dir=out_dir, jobs=jobs)


def run_robustness(*, config: str | Path | None, overrides: Sequence[str],
                   grid: RobustnessGrid, out_dir: str | Path, jobs: int,
                   engine: str = "local", scheduler: str | None = None,
                   progress: Callable[[RobustnessRow], None] | None = None
                   ) -> RobustnessOutcome:
    """Fly ``config`` (with ``overrides``) at every point of ``grid`` into ``out_dir``,
    judge each flight and write ``out_dir/robustness.csv``. Cases an earlier run finished
    are judged again from their run directories, not flown. ``progress(row)`` is called as
    each flight is judged. Raises ConfigError (before anything flies) for a bad grid value.
    """
    wall0 = time.perf_counter()
    out = Path(out_dir)
    cases = build_cases(config_path=config, overrides=overrides, grid=grid.params())
    out.mkdir(parents=True, exist_ok=True)  # once every case is valid
    by_id = {c.case_id: c for c in cases}
    done = resume_results(cases, out_dir=out)
    rows: dict[str, RobustnessRow] = {}

    def add(result: CaseResult) -> None:
        case = by_id[result.case_id]
        row = RobustnessRow(case.case_id, case.params, judge_case(case, result, out),
                            result.run_dir)
        rows[case.case_id] = row
        if progress is not None:
            progress(row)

    for result in done.values():
        add(result)
    pending = [c for c in cases if c.case_id not in done]
    stream = _engine(pending, engine=engine, out_dir=out, jobs=jobs, scheduler=scheduler)
    try:
        for result in stream:
            add(result)
    finally:
        stream.close()
        ordered = [rows[c.case_id] for c in cases if c.case_id in rows]
        csv_path = out / ROBUSTNESS_FILE
        write_csv_table(csv_path, robustness_columns(grid), [r.as_row() for r in ordered])
    counts = {k: sum(r.verdict.verdict == k for r in ordered) for k in (*CLASSES, FAILED)}
    return RobustnessOutcome(ordered, grid, csv_path, flown=len(ordered) - len(done),
                             resumed=len(done), wall_s=time.perf_counter() - wall0,
                             counts=counts)
