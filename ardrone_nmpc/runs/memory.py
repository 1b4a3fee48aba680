"""An in-memory recorder: the rows and events of a run kept in lists, no run directory.

Many short simulations (``tune``) only need a run's metrics: writing ``log.csv`` and
``events.jsonl`` and reading them back costs more than the metrics. :class:`MemoryRecorder`
takes the calls :class:`~ardrone_nmpc.runs.rundir.RunRecorder` takes (``write_row``,
``event``) and builds the :class:`~ardrone_nmpc.runs.rundir.RunData` that
:func:`~ardrone_nmpc.runs.summary.summarise` needs, with the column types
:func:`~ardrone_nmpc.runs.rundir.read_run` gives (float64, object arrays of str for
:data:`~ardrone_nmpc.runs.rundir.STRING_COLUMNS`, every :data:`LOG_COLUMNS` name present).
Values are kept as given, not rounded through text: the same as a run directory read back,
since ``log.csv`` round-trips every double.
"""

from __future__ import annotations

import functools
import itertools
import math
import operator
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ardrone_nmpc.runs.block_rows import BlockRows
from ardrone_nmpc.runs.lazy_columns import LazyColumns
from ardrone_nmpc.runs.log_columns import (LOG_COLUMNS, STRING_COLUMNS, TICK_CELL_KEYS,
                                          cells_row)
from ardrone_nmpc.runs.rundir import RunData

__all__ = ["MEMORY_PATH", "MemoryRecorder"]

#: The ``path`` of a run that was never written (RunData needs one).
MEMORY_PATH = Path("<memory>")


def _number(value: Any) -> float:
    if value is None or (isinstance(value, str) and value == ""):
        return math.nan
    return float(value)


def _text(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return value.value if hasattr(value, "value") and isinstance(value.value, str) else str(value)


def _numbers(cells: list, n: int) -> np.ndarray:
    """float64 of the cells (None → NaN) in one numpy call; cell by cell ("" → NaN) when
    that fails, and an object array of text for a column that is not numeric."""
    try:
        return np.array(cells, dtype=np.float64).reshape(n)
    except (TypeError, ValueError):
        pass
    try:
        return np.fromiter((_number(c) for c in cells), dtype=np.float64, count=n)
    except (TypeError, ValueError):  # an extra column of text
        arr = np.empty(n, dtype=object)
        arr[:] = [_text(c) for c in cells]
        return arr


def _column(name: str, cells: Sequence | None, n: int) -> np.ndarray:
    """The array of a column's cells (None: no row has it; made now: :class:`_Deferred`)."""
    if cells.__class__ is _Deferred:
        cells = cells.cells()
    if cells is None:
        return (np.full(n, "", dtype=object) if name in STRING_COLUMNS
                else np.full(n, math.nan))  # numpy's NaN for None, alike
    if name in STRING_COLUMNS:
        arr = np.empty(n, dtype=object)
        arr[:] = [c if c.__class__ is str else _text(c) for c in cells]
        return arr
    return _numbers(cells, n)


_CELLS = object()  # the group of write_cells' rows (no key tuple equals it)
_TICK_CELL_SLOTS = [LOG_COLUMNS.index(k) for k in TICK_CELL_KEYS]  # their cells' columns


def _row_keys(row) -> Any:
    return _CELLS if row.__class__ is list or row.__class__ is BlockRows else tuple(row)


class _Deferred:
    """A column's cells over a run of rows of cells and blocks of rows, made when the column
    is first read (:func:`_column`): a block gives its column's cells
    (:meth:`~ardrone_nmpc.runs.block_rows.BlockRows.column_cells`), no column is made for
    all at once."""

    __slots__ = ("run", "index")

    def __init__(self, run: list, index: int) -> None:
        self.run, self.index = run, index

    def cells(self) -> list:
        i, out = self.index, []
        for row in self.run:
            if row.__class__ is BlockRows:
                out += row.column_cells(i)
            else:
                out.append(row[i])
        return out


def _cell_columns(run: list) -> list:
    """The columns (``LOG_COLUMNS`` order) of a run of rows of cells: transposed at C speed,
    or — blocks of rows among them (:class:`~ardrone_nmpc.runs.block_rows.BlockRows`) —
    each made when read (:class:`_Deferred`)."""
    if all(row.__class__ is list for row in run):
        return list(zip(*run))
    return [_Deferred(run, i) for i in range(len(LOG_COLUMNS))]


def _expanded(rows: list) -> list:
    """``rows`` with each block of rows replaced by its rows' cells."""
    if not any(row.__class__ is BlockRows for row in rows):
        return rows
    out: list = []
    for row in rows:
        if row.__class__ is BlockRows:
            out.extend(row.cells())
        else:
            out.append(row)
    return out


def _count(rows: list) -> int:
    """How many rows ``rows`` hold (a block of rows: its own)."""
    return sum(len(r) if r.__class__ is BlockRows else 1 for r in rows)


def _transposed(rows: list, n_rows: int) -> dict[str, tuple | list]:
    """Each key any row has → its cells over the rows (None where a row lacks it): the rows
    of one key sequence (a runner builds its rows alike tick after tick) transposed at C
    speed, ~10× faster than a ``row.get`` per row and key. A row of cells
    (:meth:`MemoryRecorder.write_cells`) has the keys and values of its dict
    (:func:`~ardrone_nmpc.runs.log_columns.cells_row`)."""
    runs = []  # (keys, rows, columns) of each run of rows alike
    for keys, run in itertools.groupby(zip(map(_row_keys, rows), rows),
                                       key=operator.itemgetter(0)):
        run = [row for _, row in run]
        if keys is _CELLS:  # every column transposed, then those the cells hold
            columns = _cell_columns(run)
            runs.append((TICK_CELL_KEYS, _count(run), [columns[i] for i in _TICK_CELL_SLOTS]))
        else:
            runs.append((keys, len(run), list(zip(*map(dict.values, run)))))
    if len(runs) == 1:
        keys, _, columns = runs[0]
        return dict(zip(keys, columns))
    out: dict[str, list] = {}
    done = 0
    for keys, n, columns in runs:
        for key, cells in zip(keys, columns):
            column = out.get(key)
            if column is None:
                column = out[key] = [None] * n_rows
            column[done:done + n] = cells.cells() if cells.__class__ is _Deferred else cells
        done += n
    return out


class MemoryRecorder:
    """Collects rows and events in memory; :meth:`run_data` turns them into a RunData.

    ``path`` is None: a runner that reports where the run went (``SimResult.run_dir``)
    reports nothing.
    """

    path = None

    def __init__(self) -> None:
        # dicts, cells (write_cells) or blocks of rows (write_block)
        self._rows: list[Mapping[str, Any] | list | BlockRows] = []
        self.events: list[dict[str, Any]] = []

    @property
    def rows_written(self) -> int:
        return _count(self._rows)

    @property
    def rows(self) -> list[Mapping[str, Any]]:
        """The rows kept, as dicts (a row given as cells: its
        :func:`~ardrone_nmpc.runs.log_columns.cells_row`, built now)."""
        return [cells_row(r) if r.__class__ is list else r for r in _expanded(self._rows)]

    def write_row(self, row: Mapping[str, Any]) -> None:
        """Keep ``row`` (not copied: the caller must not change it afterwards)."""
        self._rows.append(row)

    def write_cells(self, cells: list) -> None:
        """Keep a lockstep tick's row given as its cells in :data:`LOG_COLUMNS` order
        (:func:`~ardrone_nmpc.runs.log_columns.tick_cells`, truth put; not copied): the row
        :func:`~ardrone_nmpc.runs.log_columns.cells_row` gives, without building it."""
        self._rows.append(cells)

    def write_block(self, rows: BlockRows) -> None:
        """Keep a block of lockstep ticks' rows (not copied): :meth:`write_cells` of each of
        its rows' cells, made only when the rows or their columns are read."""
        self._rows.append(rows)

    def event(self, t_s: float, kind: str, **fields: Any) -> None:
        self.events.append({"t_s": float(t_s), "kind": str(kind), **fields})

    def flush(self) -> None:
        """Nothing to flush (RunRecorder's interface)."""

    def close(self) -> None:
        """Nothing to close (RunRecorder's interface)."""

    def columns(self) -> Mapping[str, np.ndarray]:
        """Every :data:`LOG_COLUMNS` name (and any extra key a row had) → array over the
        rows: float64 (missing → NaN) or, for string columns, object arrays (missing → "");
        each made when first read (:class:`~ardrone_nmpc.runs.lazy_columns.LazyColumns`)."""
        rows = self._rows
        n = _count(rows)
        plain = all(r.__class__ is dict or r.__class__ is list or r.__class__ is BlockRows
                    for r in rows)
        cells_of = _transposed(rows, n) if n and plain else None
        if cells_of is None:
            rows = [cells_row(r) if r.__class__ is list else r for r in _expanded(rows)]
            extra = set().union(*rows) - set(LOG_COLUMNS) if rows else set()
        else:
            extra = set(cells_of) - set(LOG_COLUMNS)
        names = [*LOG_COLUMNS, *sorted(extra)]
        if cells_of is None:
            cells_of = {name: [row.get(name) for row in rows] for name in names}
        return LazyColumns({name: cells_of.get(name) for name in names},
                           functools.partial(_column, n=n))

    def run_data(self, cfg, *, seed: int | None = None) -> RunData:
        """The run as :func:`~ardrone_nmpc.runs.rundir.read_run` would give it back."""
        return RunData(path=MEMORY_PATH, config=cfg, columns=self.columns(),
                       events=list(self.events), seed=seed)
