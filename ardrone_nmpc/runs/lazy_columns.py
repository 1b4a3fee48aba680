"""A run's columns made from the cells a recorder kept, each column when it is first read.

:meth:`~ardrone_nmpc.runs.rundir.RunRecorder.kept_columns` and
:meth:`~ardrone_nmpc.runs.memory.MemoryRecorder.columns` give what
:func:`~ardrone_nmpc.runs.rundir.read_run` parses from ``log.csv``; a sweep case's or a tune
trial's metrics read about half of the 52 columns, and turning a column of Python cells into
an array costs ~15 µs (~1 ms a flight for them all). :class:`LazyColumns` is a read-only
mapping (the dict's interface a run's columns are read through: ``[]``, ``get``, ``in``,
iteration in column order, ``items``) that converts each column once, on first access, from
the cells transposed when it was made (a snapshot: later rows do not change it).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence

import numpy as np

__all__ = ["LazyColumns"]


class LazyColumns(Mapping):
    """``name → convert(name, cells)`` for each of ``cells`` (name → the column's cells, in
    column order), computed on first access and kept."""

    __slots__ = ("_cells", "_convert", "_arrays")

    def __init__(self, cells: dict[str, Sequence],
                 convert: Callable[[str, Sequence], np.ndarray]) -> None:
        self._cells = cells
        self._convert = convert
        self._arrays: dict[str, np.ndarray] = {}

    def __getitem__(self, name: str) -> np.ndarray:
        arr = self._arrays.get(name)
        if arr is None:
            arr = self._arrays[name] = self._convert(name, self._cells[name])
        return arr

    def __contains__(self, name: object) -> bool:
        return name in self._cells

    def __iter__(self) -> Iterator[str]:
        return iter(self._cells)

    def __len__(self) -> int:
        return len(self._cells)

    def __repr__(self) -> str:
        return f"LazyColumns({list(self._cells)!r})"
