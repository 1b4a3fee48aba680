"""Parameter sweeps (DESIGN.md §7): the Cartesian grid of lockstep simulations.

Grid syntax
-----------
``--grid dotted.path=v1,v2,…`` sweeps one config field over values parsed exactly like
``--set`` values (YAML: ``5`` → int, ``0.1`` → float, ``null``, ``p`` → str). Values are
separated by commas *outside brackets and quotes*, so vector-valued fields take YAML lists::

    --grid controller.r=[4,12,12,24],[1,12,12,24]     # two values of a 4-vector
    --grid estimator.kind=kalman,luenberger
    --grid 'reference.target_m=[-1.5, 0, 1],[-0.5, 0, 1]'

Several ``--grid`` options make the Cartesian product, the first one varying slowest. A grid
value is applied after the ``--set`` overrides, and every case's config is validated before any
simulation runs, so a typo fails at once with ``field.path: message``.

Cases and resume
----------------
A case id is ``<leaf>=<value>__<leaf>=<value>__<hash8>``: the swept fields' last path
components with their values (characters outside ``A-Za-z0-9._+-`` become ``_``), then the
first 8 hex digits of a SHA-256 of the case's whole resolved config. The id is stable across
re-runs of the same sweep (resume finds the case again) and changes when anything else about
the case changes (another base config or ``--set``), so a stale result is never reused.

Each case is a normal run directory ``DIR/<case id>/`` (DESIGN.md §5), flown into
``DIR/.partial/<case id>/`` and moved into place once its ``summary.csv`` is written: **a
case is finished when ``DIR/<case id>/summary.csv`` exists**, and a re-run skips it, keeping
its row of the earlier ``sweep.csv`` (status ok/unstable) or, without one, reading its
metrics and status back from the run directory (delete ``sweep.csv`` to re-classify every
finished case, e.g. with another ``diverge_m``). A failed case's run directory is moved to
``DIR/<case id>/`` without ``summary.csv``: kept for inspection, flown again on the next run.

``DIR/sweep.csv`` (:func:`sweep_columns`) gets a row as each case finishes (flushed), and is
rewritten in case order at the end; it lists the cases of the current grid only.

Status
------
``failed``: the simulation raised (``message`` holds the exception). ``unstable``: the run
completed, but over the experiment window (``t_s ≥ 0``) one of these holds (``message`` says
which): a non-finite position; a position outside the geofence
(``safety.geofence_min_m``/``geofence_max_m``); a tick whose mode is a ground mode or names a
landing or emergency (the supervisor aborted the experiment); or a 3-D distance from the
reference above ``diverge_m`` (default 0.5 m) anywhere in the last quarter of the experiment
(it did not converge, or it oscillates). Otherwise ``ok``. Unstable cases are results.

Metrics (``sweep.csv``; the names carry the units)
--------------------------------------------------
``rmse_m``: RMSE of the 3-D distance from the logged reference over the experiment's flying
ticks (the plant truth when logged, as in :func:`~ardrone_nmpc.runs.summary.summarise`; for path
experiments this is the summary's ``xyz rmse``). ``settling_s``, ``overshoot_pct``: the worst
stepped axis of the summary (NaN without a step, and ``settling_s`` NaN when an axis never
settles). ``path_deviation_m``: the summary's mean path deviation (NaN if not a path
experiment). ``solve_mean_us``, ``solve_p99_us``, ``fallbacks`` (ticks): the summary's solver
and loop rows. Everything but the solve times (measured wall time) is deterministic.

Engines
-------
:func:`iter_local` (in this process with ``jobs=1``, else a pool of long-lived worker
processes forked from a forkserver that loaded the numba kernels once) and :func:`iter_dask`
(a Dask cluster) run the same :func:`run_case` and yield :class:`CaseResult` s as cases
finish. Dask workers need this package and the sweep directory at the same path (a shared
filesystem for a multi-machine cluster); configs travel with the cases, resolved.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import product
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.config.io import config_to_dict, load_config

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.config.schema import ExperimentConfig
    from ardrone_nmpc.runs.rundir import RunData
    from ardrone_nmpc.runs.summary import SummaryRow

__all__ = [
    "METRIC_COLUMNS",
    "RANK_METRICS",
    "STATUSES",
    "Case",
    "CaseResult",
    "GridParam",
    "SweepCsvAppender",
    "build_cases",
    "case_id",
    "case_metrics",
    "classify",
    "finished_result",
    "iter_dask",
    "iter_local",
    "parse_grid",
    "rank_rows",
    "read_sweep_csv",
    "resume_results",
    "run_case",
    "split_values",
    "sweep_columns",
    "sweep_row",
    "value_text",
    "warm_up",
    "write_sweep_csv",
]

#: Metric columns of ``sweep.csv``, in order (after ``case`` and the swept parameters).
METRIC_COLUMNS: tuple[str, ...] = ("rmse_m", "settling_s", "overshoot_pct", "path_deviation_m",
                                   "solve_mean_us", "solve_p99_us", "fallbacks")
#: Case statuses, in ranking order.
STATUSES: tuple[str, ...] = ("ok", "unstable", "failed")
#: ``--rank-by`` choices → the ``sweep.csv`` column ranked (ascending: smaller is better).
RANK_METRICS: dict[str, str] = {"rmse": "rmse_m", "settling": "settling_s",
                                "overshoot": "overshoot_pct", "path_deviation": "path_deviation_m",
                                "solve_p99": "solve_p99_us"}
SWEEP_FILE = "sweep.csv"
SUMMARY_FILE = "summary.csv"  # a run directory's, written last (recorder.SUMMARY_FILE)
PARTIAL_DIR = ".partial"
DIVERGE_M = 0.5
TAIL_FRACTION = 0.25  # the part of the experiment that must stay within diverge_m
_ID_PART_CHARS = re.compile(r"[^A-Za-z0-9._+-]+")
_MAX_ID_TEXT = 120  # readable part of a case id (a directory name is at most 255 bytes)


# ----------------------------------------------------------------------------- grid


@dataclass(frozen=True)
class GridParam:
    """One ``--grid`` option: a dotted config path and its values (``texts`` as given, the
    YAML text of each value; ``values`` parsed)."""

    path: str
    texts: tuple[str, ...]
    values: tuple[Any, ...]


def split_values(text: str) -> list[str]:
    """Split ``text`` on commas outside ``[]``/``{}`` and quotes; items are stripped.

    Raises ``ValueError`` on unbalanced brackets or quotes.
    """
    items, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise ValueError(f"unbalanced {ch!r} at character {i + 1}")
        elif ch == "," and depth == 0:
            items.append(text[start:i].strip())
            start = i + 1
    if quote or depth:
        raise ValueError("unclosed " + ("quote" if quote else "bracket"))
    items.append(text[start:].strip())
    return items


def _parse_one(spec: str) -> tuple[GridParam | None, list[str]]:
    path, sep, rest = spec.partition("=")
    path = path.strip()
    keys = path.split(".")
    if not sep or any(not k.strip() or k != k.strip() for k in keys):
        return None, [f"--grid {spec!r}: expected dotted.path=v1,v2,…"]
    where = f"--grid {path}"
    try:
        texts = split_values(rest)
    except ValueError as err:
        return None, [f"{where}: {err}"]
    if any(not t for t in texts):
        return None, [f"{where}: empty value in {rest!r} (values are separated by commas)"]
    values, errors = [], []
    for text in texts:
        try:
            values.append(yaml.safe_load(text))
        except yaml.YAMLError as exc:
            errors.append(f"{where}: value {text!r} is not valid YAML: "
                          f"{str(exc).splitlines()[0]}")
    for i, value in enumerate(values):
        if value in values[:i]:
            errors.append(f"{where}: value {texts[i]!r} given twice")
    return (None if errors else GridParam(path, tuple(texts), tuple(values))), errors


def parse_grid(specs: Sequence[str]) -> list[GridParam]:
    """Parse ``--grid`` options (see the module docstring for the syntax).

    Raises
    ------
    ConfigError
        One ``--grid …: message`` line per problem: no grid, a spec without ``=``, an empty
        or unbalanced value list, a value that is not YAML, a repeated value or path.
    """
    if not specs:
        raise ConfigError("--grid: give at least one dotted.path=v1,v2,…")
    params, errors = [], []
    for spec in specs:
        param, errs = _parse_one(spec)
        errors += errs
        if param is not None:
            if any(p.path == param.path for p in params):
                errors.append(f"--grid {param.path}: swept twice (give all its values in one "
                              "--grid)")
            params.append(param)
    if errors:
        raise ConfigError(errors)
    return params


# ----------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class Case:
    """One point of the grid.

    ``params`` pairs each swept dotted path with its value's text (``sweep.csv`` cells);
    ``config`` is the validated, resolved configuration flown.
    """

    index: int
    case_id: str
    params: tuple[tuple[str, str], ...]
    config: ExperimentConfig = field(repr=False)


def value_text(value: Any) -> str:
    """The canonical text of a parsed grid value (``sweep.csv`` cell): strings as they are,
    everything else as compact JSON (``0.1``, ``5``, ``[4,12,12,24]``, ``true``, ``null``)."""
    return value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))


def case_id(*, params: Sequence[tuple[str, str]], cfg: ExperimentConfig) -> str:
    """The case's directory name: readable swept values, then a hash of the whole config."""
    data = json.dumps(config_to_dict(cfg), sort_keys=True, separators=(",", ":"))
    digest = hashlib.sha256(data.encode("utf-8")).hexdigest()[:8]
    parts = [f"{path.rsplit('.', 1)[-1]}={_ID_PART_CHARS.sub('_', text).strip('_')}"
             for path, text in params]
    return f"{'__'.join(parts)[:_MAX_ID_TEXT]}__{digest}"


def build_cases(*, config_path: str | Path | None, overrides: Sequence[str],
                grid: Sequence[GridParam]) -> list[Case]:
    """Every case of the grid, first grid parameter varying slowest, each validated.

    Parameters
    ----------
    config_path : the experiment YAML (None: all defaults).
    overrides : ``--set`` overrides ``dotted.path=value``, applied to every case before the
        grid values.
    grid : from :func:`parse_grid`.

    Raises
    ------
    ConfigError
        Each distinct ``field.path: message`` line once, with the first case it occurred in
        appended, before anything runs.
    """
    cases, errors = [], {}
    for index, combo in enumerate(product(*(range(len(p.values)) for p in grid))):
        texts = [p.texts[i] for p, i in zip(grid, combo)]
        case_overrides = [*overrides, *(f"{p.path}={t}" for p, t in zip(grid, texts))]
        params = tuple((p.path, value_text(p.values[i])) for p, i in zip(grid, combo))
        try:
            cfg = load_config(config_path, case_overrides)
        except ConfigError as err:
            label = ", ".join(f"{path}={text}" for path, text in params)
            for message in err.messages:
                errors.setdefault(message, f"{message} (case {label})")
            continue
        cases.append(Case(index, case_id(params=params, cfg=cfg), params, cfg))
    if errors:
        raise ConfigError(list(errors.values()))
    return cases


# ----------------------------------------------------------------------------- metrics, status


@dataclass(frozen=True)
class _Window:
    """The experiment window of a run (``t_s ≥ 0``; all rows if none): times (s), positions
    and reference (K, 3) (m), mode, and which ticks were flying (not a ground mode)."""

    t_s: np.ndarray
    pos_m: np.ndarray
    ref_m: np.ndarray
    mode: np.ndarray
    flying: np.ndarray


def _window(run: RunData) -> _Window:
    from ardrone_nmpc.runs.summary import GROUND_MODES

    cols = run.columns
    t = np.asarray(cols["t_s"], dtype=np.float64)
    window = np.isfinite(t) & (t >= 0.0)
    if not window.any():
        window = np.isfinite(t)
    mode = np.array(["" if not isinstance(m, str) else m for m in cols["mode"]],
                    dtype=object)[window]
    # as summarise: a mode column with one value (or none) says nothing about the ground
    flying = (~np.isin(mode, list(GROUND_MODES)) if len(set(mode.tolist())) > 1
              else np.ones(mode.size, dtype=bool))
    truth = all(np.isfinite(cols[c]).any() for c in ("x_true_m", "y_true_m", "z_true_m",
                                                      "psi_true_rad"))
    names = ("x_true_m", "y_true_m", "z_true_m") if truth else ("x_m", "y_m", "z_m")
    pos = np.column_stack([np.asarray(cols[c], dtype=np.float64)[window] for c in names])
    ref = np.column_stack([np.asarray(cols[c], dtype=np.float64)[window]
                           for c in ("x_ref_m", "y_ref_m", "z_ref_m")])
    return _Window(t[window], pos, ref, mode, flying)


def _row_value(rows: Sequence[SummaryRow], axis: str, metric: str) -> float:
    for r in rows:
        if r.axis == axis and r.metric == metric:
            return float(r.value)
    return math.nan


def _worst(rows: Sequence[SummaryRow], metric: str) -> float:
    """The largest ``metric`` over the stepped axes; NaN if none or if any is NaN."""
    values = [float(r.value) for r in rows if r.metric == metric
              and r.axis in ("x", "y", "z", "psi")]
    return max(values) if values and not any(math.isnan(v) for v in values) else math.nan


def case_metrics(*, run: RunData, rows: Sequence[SummaryRow]) -> dict[str, float]:
    """The ``sweep.csv`` metrics of a run (see the module docstring)."""
    w = _window(run)
    dist = np.linalg.norm(w.pos_m[w.flying] - w.ref_m[w.flying], axis=1)
    dist = dist[np.isfinite(dist)]
    fallbacks = _row_value(rows, "loop", "fallbacks")
    return {
        "rmse_m": float(np.sqrt(np.mean(dist * dist))) if dist.size else math.nan,
        "settling_s": _worst(rows, "settling_time"),
        "overshoot_pct": _worst(rows, "overshoot"),
        "path_deviation_m": _row_value(rows, "path", "mean_deviation"),
        "solve_mean_us": _row_value(rows, "solver", "solve_time_mean"),
        "solve_p99_us": _row_value(rows, "solver", "solve_time_p99"),
        "fallbacks": fallbacks if math.isnan(fallbacks) else int(fallbacks),
    }


def _aborted(mode: np.ndarray) -> str | None:
    from ardrone_nmpc.runs.summary import GROUND_MODES

    for m in mode:
        if m in GROUND_MODES or "land" in m or "emergency" in m:
            return m
    return None


def classify(*, run: RunData, diverge_m: float = DIVERGE_M) -> tuple[str, str]:
    """``("ok", "")`` or ``("unstable", reasons)`` for a completed run.

    Parameters
    ----------
    run : the run read back (:func:`~ardrone_nmpc.runs.rundir.read_run`).
    diverge_m : largest 3-D distance from the reference (m) allowed in the last quarter of
        the experiment window.

    The rule is the module docstring's (Status); ``reasons`` joins every one that holds.
    """
    w = _window(run)
    t, pos, ref = w.t_s[w.flying], w.pos_m[w.flying], w.ref_m[w.flying]
    reasons = []
    if not np.all(np.isfinite(pos)):
        reasons.append("non-finite position")
    safety = run.config.safety
    lo, hi = np.asarray(safety.geofence_min_m), np.asarray(safety.geofence_max_m)
    outside = np.any((pos < lo) | (pos > hi), axis=1)
    if outside.any():
        reasons.append(f"left the geofence at t = {t[np.argmax(outside)]:.2f} s")
    mode_hit = _aborted(w.mode)
    if mode_hit is not None:
        reasons.append(f"aborted (mode {mode_hit})")
    if t.size:
        tail = t >= t[-1] - TAIL_FRACTION * (t[-1] - t[0])
        dist = np.linalg.norm(pos[tail] - ref[tail], axis=1)
        worst = float(np.max(dist, initial=0.0, where=np.isfinite(dist)))
        if worst > diverge_m:
            reasons.append(f"{worst:.3g} m from the reference in the last "
                           f"{TAIL_FRACTION:.0%} (> {diverge_m:g} m)")
    return ("unstable", "; ".join(reasons)) if reasons else ("ok", "")


# ----------------------------------------------------------------------------- running a case


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


def _nan_metrics() -> dict[str, float]:
    return {name: math.nan for name in METRIC_COLUMNS}


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def _fly(cfg: ExperimentConfig, log_dir: Path) -> tuple[Path, RunData, list[SummaryRow]]:
    """Fly ``cfg`` in lockstep into a new run directory under ``log_dir``, write its
    summary; return (run dir, run read back, summary rows). On an exception the partial run
    directory is left in ``log_dir`` with a ``sweep-case-failed`` event."""
    from ardrone_nmpc.runs.rundir import RunRecorder, read_run
    from ardrone_nmpc.runtime.lockstep import run_lockstep
    from ardrone_nmpc.runs.summary import summarise

    seed = cfg.sim.seed
    with RunRecorder.create(log_dir, cfg, seed=seed) as recorder:
        cfg = recorder.config  # the run reads its own copy of its input files
        wall0 = time.perf_counter()
        try:
            result = run_lockstep(cfg, recorder=recorder, seed=seed)
        except Exception as err:
            recorder.event(math.nan, "sweep-case-failed", message=_one_line(err))
            raise
        recorder.event(0.0, "simulated", wall_s=time.perf_counter() - wall0,
                       ticks=result.ticks, final_mode=result.final_mode.value)
        run = read_run(recorder.path)
        rows = summarise(run)
        recorder.write_summary(rows)  # last: its presence marks the case finished
    return recorder.path, run, rows


def _move_into_place(staging: Path, final: Path, *, finished: bool) -> None:
    """Move the one run directory ``RunRecorder`` made under ``staging`` to ``final``; an
    unfinished one loses any ``summary.csv`` (it must be flown again on resume)."""
    made = [p for p in staging.iterdir() if p.is_dir()] if staging.is_dir() else []
    if len(made) == 1:
        if not finished:
            (made[0] / SUMMARY_FILE).unlink(missing_ok=True)
        shutil.rmtree(final, ignore_errors=True)
        os.replace(made[0], final)
    shutil.rmtree(staging, ignore_errors=True)


def run_case(case: Case, *, out_dir: str | Path, diverge_m: float = DIVERGE_M) -> CaseResult:
    """Fly one case into ``out_dir/<case id>/`` and classify it.

    Parameters
    ----------
    case : from :func:`build_cases` (its config travels with it, resolved).
    out_dir : the sweep directory (absolute in a worker: its working directory may differ).
    diverge_m : see :func:`classify` (m).

    Never raises for a failing case: the exception becomes status ``failed`` and its one-line
    message. Runs in a pool worker, a Dask worker thread, or this process.
    """
    out = Path(out_dir)
    final = out / case.case_id
    staging = out / PARTIAL_DIR / case.case_id
    shutil.rmtree(staging, ignore_errors=True)  # a case interrupted earlier
    wall0 = time.perf_counter()
    try:
        _, run, rows = _fly(case.config, staging)
        metrics = case_metrics(run=run, rows=rows)
        status, message = classify(run=run, diverge_m=diverge_m)
    except Exception as err:  # noqa: BLE001 - a failed case is a row of the table
        status, message, metrics = "failed", _one_line(err), _nan_metrics()
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
    metrics = {name: _as_float(row[name]) for name in METRIC_COLUMNS}
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
        recorded = {row.get("case"): row for row in read_sweep_csv(out / SWEEP_FILE)}
    except (OSError, UnicodeDecodeError, csv.Error):  # absent or damaged: read the runs
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
    into a temporary directory; once per process. ~2 s, then each case runs at full speed."""
    global _WARM
    if _WARM:
        return
    from ardrone_nmpc.config.schema import config_from_dict

    cfg = config_from_dict({"name": "warm-up", "duration_s": 0.2, "sim": {"settle_s": 0.0},
                            "reference": {"kind": "step", "target_m": [-0.5, 0.0, 1.0]}})
    with tempfile.TemporaryDirectory(prefix="ardrone-nmpc-warm-") as tmp:
        _, run, rows = _fly(cfg, Path(tmp))
        case_metrics(run=run, rows=rows)
        classify(run=run)
    _WARM = True


# ----------------------------------------------------------------------------- engines


def _init_worker() -> None:
    """Pool worker start: Ctrl-C is the parent's to handle (it cancels the pending cases and
    lets the running ones finish), so workers ignore SIGINT; then load the kernels (a no-op
    when forked from the warm forkserver)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    warm_up()


def _pool_context():
    """A forkserver whose process has imported and warmed the kernels (see
    :mod:`ardrone_nmpc.experiments._sweep_preload`): workers fork from it warm, without inheriting the
    parent's threads (numba and ``fork`` of a threaded process do not mix). Spawn where
    there is no forkserver (Windows)."""
    import multiprocessing

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["ardrone_nmpc.experiments._sweep_preload"])
    return ctx


def _noop() -> None:
    """A process that does nothing (see :func:`_start_forkserver`)."""


def _start_forkserver(ctx):
    """Start the warm forkserver now and wait for its warm-up, by starting a process that
    does nothing through it. A Ctrl-C during the wait then leaves nothing half-started (the
    pool's first worker would be, and would print a traceback when it finds its pool gone).
    Returns the process (join it later), or None with another start method."""
    if ctx.get_start_method() != "forkserver":
        return None
    process = ctx.Process(target=_noop, name="sweep-forkserver-warm-up")
    process.start()  # returns once the forkserver has forked it: after its preload
    return process


def _failed(case: Case, err: BaseException) -> CaseResult:
    return CaseResult(case.case_id, "failed", f"worker: {_one_line(err)}", _nan_metrics(),
                      case.case_id)


def iter_local(cases: Sequence[Case], *, out_dir: str | Path, jobs: int,
               diverge_m: float = DIVERGE_M) -> Iterator[CaseResult]:
    """Run ``cases`` on this machine and yield their results as they finish.

    ``jobs == 1``: one after another in this process. Otherwise a pool of ``min(jobs,
    len(cases))`` long-lived worker processes. Closing the generator (or Ctrl-C while it
    waits) cancels the cases not started and waits for the running ones.
    """
    out = str(Path(out_dir).resolve())
    if jobs == 1:
        for case in cases:
            yield run_case(case, out_dir=out, diverge_m=diverge_m)
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ctx = _pool_context()
    warm = _start_forkserver(ctx)
    pool = ProcessPoolExecutor(max(1, min(jobs, len(cases))), mp_context=ctx,
                               initializer=_init_worker)
    futures = {}
    try:
        for case in cases:
            futures[pool.submit(run_case, case, out_dir=out, diverge_m=diverge_m)] = case
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as err:  # noqa: BLE001 - a dead worker fails its case
                yield _failed(futures[future], err)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if warm is not None:
            warm.join()


def _dask_client(*, scheduler: str | None, jobs: int):
    """(client, cluster or None): a client of ``scheduler``, or of a new local cluster of
    ``jobs`` single-threaded worker processes bound to 127.0.0.1 without a dashboard."""
    import logging

    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        return Client(scheduler, timeout="10s"), None
    cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None,
                           silence_logs=logging.ERROR)
    try:
        return Client(cluster), cluster
    except BaseException:
        cluster.close()
        raise


def iter_dask(cases: Sequence[Case], *, out_dir: str | Path, jobs: int,
              scheduler: str | None = None,
              diverge_m: float = DIVERGE_M) -> Iterator[CaseResult]:
    """Run ``cases`` on a Dask cluster (``scheduler`` address, or a local cluster of
    ``jobs`` workers) and yield their results as they finish. ``out_dir`` must be reachable
    at the same path from every worker (a shared filesystem for a multi-machine cluster),
    and the workers need this package installed. Closing the generator cancels the rest."""
    import uuid

    from dask.distributed import as_completed

    out = str(Path(out_dir).resolve())
    client, cluster = _dask_client(scheduler=scheduler, jobs=max(1, min(jobs, len(cases))))
    token = uuid.uuid4().hex[:8]  # keys unique on a scheduler shared by several sweeps
    futures = {}
    try:
        for case in cases:
            future = client.submit(run_case, case, out_dir=out, diverge_m=diverge_m,
                                   key=f"sweep-{token}-{case.case_id}", pure=False)
            futures[future.key] = (future, case)
        for future in as_completed([f for f, _ in futures.values()]):
            try:
                yield future.result()
            except Exception as err:  # noqa: BLE001 - a lost worker fails its case
                yield _failed(futures[future.key][1], err)
    finally:
        client.cancel([f for f, _ in futures.values()])
        client.close()
        if cluster is not None:
            cluster.close()


# ----------------------------------------------------------------------------- sweep.csv


def sweep_columns(param_paths: Sequence[str]) -> list[str]:
    """The ``sweep.csv`` header: ``case``, the swept paths, the metrics, ``status``,
    ``message``, ``run_dir``."""
    return ["case", *param_paths, *METRIC_COLUMNS, "status", "message", "run_dir"]


def sweep_row(case: Case, result: CaseResult) -> dict[str, str]:
    """One ``sweep.csv`` row (text cells; numbers as in ``log.csv``, NaN as ``nan``)."""
    from ardrone_nmpc.runs.rundir import format_number

    row = {"case": case.case_id, **dict(case.params)}
    for name in METRIC_COLUMNS:
        row[name] = format_number(result.metrics[name])
    row.update(status=result.status, message=result.message, run_dir=result.run_dir)
    return row


def write_sweep_csv(path: str | Path, columns: Sequence[str],
                    rows: Sequence[Mapping[str, str]]) -> None:
    """Write ``sweep.csv`` atomically (a temporary file renamed over it)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(columns))
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, path)


class SweepCsvAppender:
    """Appends rows to ``sweep.csv`` as cases finish, each flushed to the OS at once (a
    crash loses no finished case's row)."""

    def __init__(self, path: str | Path, columns: Sequence[str]) -> None:
        self._file = open(path, "a", newline="", encoding="utf-8")  # noqa: SIM115
        self._writer = csv.DictWriter(self._file, fieldnames=list(columns))

    def append(self, row: Mapping[str, str]) -> None:
        self._writer.writerow(row)
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def read_sweep_csv(path: str | Path) -> list[dict[str, str]]:
    """The rows of a ``sweep.csv`` as dicts of text cells (header names as keys)."""
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _as_float(text: str) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def rank_rows(rows: Sequence[Mapping[str, str]], *, metric: str) -> list[Mapping[str, str]]:
    """``rows`` best first by the ``sweep.csv`` column ``metric`` (ascending): ok cases,
    then unstable, then failed; within a status NaN last; ties keep their order."""
    order = {status: i for i, status in enumerate(STATUSES)}

    def key(item):
        i, row = item
        value = _as_float(row.get(metric, ""))
        return (order.get(row.get("status", ""), len(order)), math.isnan(value),
                0.0 if math.isnan(value) else value, i)

    return [row for _, row in sorted(enumerate(rows), key=key)]
