"""Flying one case of a sweep, and finding the cases an earlier run finished.

Each case is a normal run directory ``DIR/<case id>/``, flown as
``DIR/.partial/<case id>/`` and moved into place once its ``summary.csv`` is written: **a
case is finished when ``DIR/<case id>/summary.csv`` exists**, and a re-run skips it, keeping
its row of the earlier ``sweep.csv`` (status ok/unstable) or, without one, reading its
metrics and status back from the run directory (delete ``sweep.csv`` to re-classify every
finished case, e.g. with another ``diverge_m``). A failed case's run directory is moved to
``DIR/<case id>/`` without ``summary.csv``: kept for inspection, flown again on the next run.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ardrone_nmpc.experiments import record
from ardrone_nmpc.experiments.record import one_line
from ardrone_nmpc.experiments.sweep.status import DIVERGE_M, case_metrics, case_window, classify
from ardrone_nmpc.runs.sweep_table import (METRIC_COLUMNS, SWEEP_FILE, SweepTableError,
                                                  as_float, read_sweep)
from ardrone_nmpc.runs.rundir import SUMMARY_FILE
from ardrone_nmpc.runs.verdict import FAILED_VERDICTS, verdict_message

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.config.schema import ExperimentConfig
    from ardrone_nmpc.experiments.sweep.grid import Case
    from ardrone_nmpc.runs.rundir import RunData
    from ardrone_nmpc.runs.summary import SummaryRow

PARTIAL_DIR = ".partial"


@dataclass(frozen=True)
class CaseResult:
    """What one case produced: its ``status`` (:data:`STATUSES`), a one-line ``message``
    (empty when ok), the :data:`METRIC_COLUMNS` values (NaN when failed), its run directory
    relative to the sweep directory, the wall time spent on it (s) and whether it was
    ``resumed`` (read back from an earlier run instead of flown)."""

    case_id: str
    status: str
    message: str
    metrics: dict[str, float]
    run_dir: str
    wall_s: float = math.nan
    resumed: bool = False


def nan_metrics() -> dict[str, float]:
    """The metrics of a case that failed: every one NaN."""
    return {name: math.nan for name in METRIC_COLUMNS}


def _fly(cfg: ExperimentConfig, staging: Path) -> tuple[RunData, list[SummaryRow]]:
    """Record ``cfg`` in lockstep as the run directory ``staging`` (the run read back and its
    summary); a flight that raises leaves it without ``summary.csv``. A flight that
    reached its end without doing its job raises :class:`VerdictFailed`."""
    # (looked up per call: tests replace it)
    recording = record.record_lockstep(cfg, staging.parent, name=staging.name)
    ending = recording.result.ending
    if ending in FAILED_VERDICTS:
        raise VerdictFailed(f"{ending}: {verdict_message(ending)}")
    return recording.run, recording.summary


class VerdictFailed(RuntimeError):
    """The case flew to its end without doing its job (:mod:`ardrone_nmpc.runs.verdict`)."""


def _move_into_place(staging: Path, final: Path, *, finished: bool) -> None:
    """Move the run directory ``staging`` (if the recorder made it) to ``final``; an
    unfinished one loses any ``summary.csv`` (it must be flown again on resume). One rename:
    no directory is removed (an ``rmdir`` cost ~1 ms a case on average, up to ~4 ms, on an
    ext4 disk mounted with ``discard``)."""
    if staging.is_dir():
        if not finished:
            (staging / SUMMARY_FILE).unlink(missing_ok=True)
        shutil.rmtree(final, ignore_errors=True)
        os.replace(staging, final)


def run_case(case: Case, *, out_dir: str | Path, diverge_m: float = DIVERGE_M) -> CaseResult:
    """Fly one case into ``out_dir/<case id>/`` and classify it.

    Parameters
    ----------
    case : from :func:`~ardrone_nmpc.experiments.sweep.grid.build_cases` (its config travels
        with it, resolved).
    out_dir : the sweep directory (absolute in a worker: its working directory may differ).
    diverge_m : see :func:`~ardrone_nmpc.experiments.sweep.status.classify` (m).

    Never raises for a failing case: the exception becomes status ``failed`` and its one-line
    message. Runs in a pool worker, a Dask worker thread, or this process.
    """
    out = Path(out_dir)
    final = out / case.case_id
    staging = out / PARTIAL_DIR / case.case_id
    shutil.rmtree(staging, ignore_errors=True)  # a case interrupted earlier
    wall0 = time.perf_counter()
    try:
        run, rows = _fly(case.config, staging)
        window = case_window(run)
        metrics = case_metrics(run=run, rows=rows, window=window)
        status, message = classify(run=run, diverge_m=diverge_m, window=window)
    except VerdictFailed as err:  # flown, but it did not do its job
        status, message, metrics = "failed", str(err), nan_metrics()
    except Exception as err:  # noqa: BLE001 - a failed case is a row of the table
        status, message, metrics = "failed", one_line(err), nan_metrics()
    _move_into_place(staging, final, finished=status != "failed")
    return CaseResult(case.case_id, status, message, metrics, case.case_id,
                      time.perf_counter() - wall0)


def finished_result(case: Case, *, out_dir: str | Path,
                    diverge_m: float = DIVERGE_M) -> CaseResult | None:
    """The result of a case finished by an earlier run (``summary.csv`` present), read back
    from its run directory; None if it has to be flown (absent, partial or unreadable)."""
    from ardrone_nmpc.runs.rundir import LogError, read_run
    from ardrone_nmpc.runs.summary import read_summary

    run_dir = Path(out_dir) / case.case_id
    if not (run_dir / SUMMARY_FILE).is_file():
        return None
    try:
        run = read_run(run_dir)
        rows = read_summary(run_dir)
    except LogError:
        return None
    status, message = classify(run=run, diverge_m=diverge_m)
    return CaseResult(case.case_id, status, message, case_metrics(run=run, rows=rows),
                      case.case_id, resumed=True)


def _result_from_row(case: Case, row: Mapping[str, str | None]) -> CaseResult | None:
    """A finished case's result as an earlier run recorded it in ``sweep.csv``; None for a
    row that is torn (a crash while writing) or not finished."""
    if row.get("status") not in ("ok", "unstable") or any(
            row.get(name) is None for name in (*METRIC_COLUMNS, "message", "run_dir")):
        return None
    metrics = {name: as_float(row[name]) for name in METRIC_COLUMNS}
    if not math.isnan(metrics["fallbacks"]):
        metrics["fallbacks"] = int(metrics["fallbacks"])
    return CaseResult(case.case_id, row["status"], row["message"], metrics, row["run_dir"],
                      resumed=True)


def resume_results(cases: Sequence[Case], *, out_dir: str | Path,
                   diverge_m: float = DIVERGE_M) -> dict[str, CaseResult]:
    """The results of the cases an earlier run finished (``DIR/<case id>/summary.csv``
    present), by case id. Taken from the earlier ``sweep.csv`` row when it has one with
    status ok/unstable (not re-read: its status keeps the ``diverge_m`` it was classified
    with), else read back from the run directory (:func:`finished_result`)."""
    out = Path(out_dir)
    recorded: dict[str, Mapping[str, str | None]] = {}
    try:
        recorded = {row.get("case"): row for row in read_sweep(out / SWEEP_FILE).rows}
    except SweepTableError:  # absent or damaged: read the runs
        pass
    results = {}
    for case in cases:
        if not (out / case.case_id / SUMMARY_FILE).is_file():
            continue
        row = recorded.get(case.case_id)
        result = _result_from_row(case, row) if row is not None else None
        if result is None:
            result = finished_result(case, out_dir=out, diverge_m=diverge_m)
        if result is not None:
            results[case.case_id] = result
    return results


_WARM = False


def warm_up() -> None:
    """Load every numba kernel a case uses (from the on-disk cache) by flying a 0.2 s case
    into a temporary directory; once per process. ~2 s, then each case runs at full speed.
    A square: a waypoint reference's kernels (``nmpc_inputs``) and its summary's path
    deviation load too, which a step's flight does not — else each worker loaded them on its
    first such case (~25 ms of CPU, measured), after the forkserver's preload."""
    global _WARM
    if _WARM:
        return
    from ardrone_nmpc.config.schema import config_from_dict

    cfg = config_from_dict({"name": "warm-up", "duration_s": 0.2, "sim": {"settle_s": 0.0},
                            "reference": {"kind": "square"}})
    with tempfile.TemporaryDirectory(prefix="ardrone-nmpc-warm-") as tmp:
        run, rows = _fly(cfg, Path(tmp) / "run")
        case_metrics(run=run, rows=rows)
        classify(run=run)
    _WARM = True


def warm_worker() -> None:
    """:func:`warm_up`, then the garbage collector set for a process that flies one flight
    after another (a pool worker; they inherit it from the forkserver): garbage is still
    collected, only less often.

    The warm heap (modules, numba's dispatchers and types: ~135 000 objects) lives as long
    as the process: frozen (moved out of the generations, never collected: the warm-up
    flight's few cycles of garbage stay), a full collection walks only what the flights made
    since (~1 ms) instead of it all (~60–80 ms, one every few dozen flights). A flight frees
    nearly all it allocates (its rows, when it ends): at the default 700 net allocations a
    young collection ran ~3 times a flight, walking the rows kept so far and finding no
    garbage (~1 ms a flight in all, more with a run directory's rows); at 10 000, about once
    in 20 flights."""
    import gc

    warm_up()
    gc.freeze()
    gc.set_threshold(10_000, *gc.get_threshold()[1:])


def sweep_row(case: Case, result: CaseResult) -> dict[str, str]:
    """One ``sweep.csv`` row (text cells; numbers as in ``log.csv``, NaN as ``nan``)."""
    from ardrone_nmpc.runs.rundir import format_number

    row = {"case": case.case_id, **dict(case.params)}
    for name in METRIC_COLUMNS:
        row[name] = format_number(result.metrics[name])
    row.update(status=result.status, message=result.message, run_dir=result.run_dir)
    return row
