"""``sweep.csv``: the results table of a sweep directory — its columns, writers, reader and
ranking.

Columns: ``case``, the swept dotted paths, :data:`METRIC_COLUMNS`, ``status``, ``message``,
``run_dir``; one row per case, numbers as in ``log.csv`` (NaN as ``nan``). A sweep appends a
row as each case finishes (flushed) and rewrites the table in case order at the end; it lists
the cases of the current grid only.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from ardrone_nmpc.core.atomic import atomic_write

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
_TAIL = ("status", "message", "run_dir")  # the columns after the metrics


def sweep_columns(param_paths: Sequence[str]) -> list[str]:
    """The ``sweep.csv`` header: ``case``, the swept paths, the metrics, ``status``,
    ``message``, ``run_dir``."""
    return ["case", *param_paths, *METRIC_COLUMNS, "status", "message", "run_dir"]


def write_sweep_csv(path: str | Path, columns: Sequence[str],
                    rows: Sequence[Mapping[str, str]]) -> None:
    """Write ``sweep.csv`` atomically (a temporary file renamed over it)."""
    write_csv_table(path, columns, rows)


def write_csv_table(path: str | Path, columns: Sequence[str], rows: Sequence[Mapping]) -> None:
    """Write a results table (``sweep.csv``, a tune's ``trials.csv``) atomically: a temporary
    file renamed over it, so a reader never sees half a table."""
    with atomic_write(path, newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(columns))
        writer.writeheader()
        writer.writerows(rows)


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


class SweepTableError(ValueError):
    """A ``sweep.csv`` that cannot be read: ``<file>[:<line>]: <message>``."""


@dataclass(frozen=True)
class SweepTable:
    """``sweep.csv`` read back.

    Attributes
    ----------
    path : the file.
    params : swept parameters (dotted config paths), the columns between ``case`` and the
        first metric.
    metrics : metric columns present (of :data:`METRIC_COLUMNS`).
    rows : one dict per case, cells as text.
    warnings : notes on recoverable damage (a torn last row dropped).
    """

    path: Path
    params: tuple[str, ...]
    metrics: tuple[str, ...]
    rows: tuple[dict[str, str], ...]
    warnings: tuple[str, ...] = ()


def _header(path: Path, lines: list[list[str]]) -> tuple[list[str], tuple[str, ...]]:
    """The header's cells and the swept parameters it names."""
    if not lines or not lines[0]:
        raise SweepTableError(f"{path}:1: empty file: expected a header row")
    header = [c.strip() for c in lines[0]]
    if header[0] != "case":
        raise SweepTableError(f"{path}:1: the first column must be 'case', got {header[0]!r}")
    end = next((i for i, c in enumerate(header) if c in METRIC_COLUMNS or c in _TAIL), None)
    if end is None:
        raise SweepTableError(f"{path}:1: no metric columns ({', '.join(METRIC_COLUMNS)})")
    params = tuple(header[1:end])
    if not params:
        raise SweepTableError(f"{path}:1: no swept parameter columns between 'case' and "
                              f"{header[end]!r}")
    return header, params


def read_sweep(path: str | Path) -> SweepTable:
    """Read ``sweep.csv`` (a file or its sweep directory): the one reader of the format.

    Raises
    ------
    SweepTableError
        ``<file>[:<line>]: <message>`` for a missing or unreadable file, a header without
        ``case`` or without metrics, no swept parameter, a row of the wrong width, or no
        rows. A short *last* row (a sweep still appending, or killed mid-row) is dropped with
        a note in :attr:`SweepTable.warnings` instead.
    """
    path = Path(path)
    if path.is_dir():
        path = path / SWEEP_FILE
    try:
        with open(path, newline="", encoding="utf-8") as f:
            lines = list(csv.reader(f))
    except (OSError, UnicodeDecodeError) as exc:
        raise SweepTableError(f"{path}: cannot read: {exc}") from None
    except csv.Error as exc:
        raise SweepTableError(f"{path}: not a CSV file: {exc}") from None
    header, params = _header(path, lines)
    rows, warnings = [], []
    body = [(i, cells) for i, cells in enumerate(lines[1:], start=2) if cells]
    for k, (i, cells) in enumerate(body):
        if len(cells) != len(header):
            if k == len(body) - 1 and len(cells) < len(header):
                warnings.append(f"{path}:{i}: incomplete last row dropped")
                break
            raise SweepTableError(f"{path}:{i}: expected {len(header)} cells, got {len(cells)}")
        rows.append(dict(zip(header, (c.strip() for c in cells))))
    if not rows:
        raise SweepTableError(f"{path}: no cases in the table")
    metrics = tuple(c for c in header if c in METRIC_COLUMNS)
    return SweepTable(path=path, params=params, metrics=metrics, rows=tuple(rows),
                      warnings=tuple(warnings))


def as_float(text: str | None) -> float:
    """A ``sweep.csv`` cell as a number; NaN if it is not one."""
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
        value = as_float(row.get(metric, ""))
        return (order.get(row.get("status", ""), len(order)), math.isnan(value),
                0.0 if math.isnan(value) else value, i)

    return [row for _, row in sorted(enumerate(rows), key=key)]
