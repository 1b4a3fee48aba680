"""The run directory (docs/design.md): write it while flying, read it back for summaries and replay.

A run directory ``<log_dir>/<YYYYmmdd-HHMMSS>-<name>/`` stands on its own (it can be moved to
another machine) and holds:

* ``config.yaml`` — the resolved :class:`~ardrone_nmpc.config.schema.ExperimentConfig`, written at
  creation (before the first row), with ``#`` comment lines ``ardrone-nmpc <version>``,
  ``seed: <seed>``, ``created: <ISO time>`` and where each input file was copied from;
  :func:`~ardrone_nmpc.config.io.load_config` reads it.
* ``inputs/`` — a copy of every input file the config names (the waypoint file of reference
  kind 'path'), checked before the directory is made; ``config.yaml`` names the copy by a
  path relative to the run directory, and the run reads the copy. Runs written before the
  copy existed name the original by its absolute path and still read.
* ``log.csv`` — a header row, then one row per control tick, columns :data:`LOG_COLUMNS`
  (names, units and builders: :mod:`~ardrone_nmpc.runs.log_columns`).
  Plain CSV without quoting: string cells never contain ``,``, ``"`` or line breaks (the writer
  refuses them). Numbers are written as the *shortest* decimal that reads back to the same
  double — Python's ``repr(float(v))`` without a trailing ``.0`` (``0.1``, ``-0``, ``5``,
  ``1e-05``, ``1.7976931348623157e+308``) — so every double, −0.0 and subnormals included,
  round-trips bit for bit; NaN and ±inf are ``nan``/``inf``/``-inf``; a missing key is an empty
  cell (read back as NaN).
* ``events.jsonl`` — one JSON object per line, ``{"t_s": …, "kind": …, …}``; ``t_s`` is
  experiment time in every runner (negative before the experiment starts, NaN for events
  of a flight that never started), a real-time run's wall time in ``wall_s``.
  :func:`read_run` moves the events of older ``fly`` runs (wall time in ``t_s``) onto the
  experiment clock.
* ``summary.csv`` — ``axis,metric,value,unit`` rows (:class:`SummaryRow`), computed by
  :mod:`ardrone_nmpc.runs.summary`, written and read here (:func:`write_summary`,
  :func:`read_summary`).

Reading a run directory back (:func:`read_run`, :class:`RunData`, :class:`LogError`) lives in
:mod:`ardrone_nmpc.runs.run_reading` and is re-exported here.

Crash safety: ``log.csv`` and ``events.jsonl`` are opened unbuffered, and each row/event is
handed to the kernel by one ``write`` call, so a killed process (SIGKILL included) loses at
most the row being written. A lockstep simulation's recording hands its rows over in blocks
(``rows_per_write`` 64: ≈ 5 ms of wall time at its speed, never held longer than
:attr:`RunRecorder.HOLD_S`); any exception or Ctrl-C writes the block held, a killed
simulation loses it. :func:`read_run` drops a final line without its newline (with a
note in :attr:`RunData.warnings`). Rows are not ``fsync``-ed: a power cut of the *ground
station* may lose what the OS had not yet written to disk.

Speed: a row is formatted by one ``orjson.dumps`` call (its floats are printed by Ryu, the
shortest round-trip algorithm): ≈ 2 µs per row, where CPython's own float formatting costs
≈ 1 µs per number on a 2 GHz machine and a row holds up to 35 numbers, written every tick
also in 100×-real-time simulation. Its text can differ from ``repr`` (``5.0``, ``1e-7``) but
reads back to the same double. A row of plain cells (float, np.float64 — printed by orjson
as the float it is —, int, None, str) takes no Python call per cell; its NaN and ±inf cells
are printed as :func:`format_number` prints them. Other numpy scalars are widened to Python
floats first; rows with bools take the pure-Python path (:func:`format_number`). The lockstep
runner hands its usual NMPC rows as their cells in column order (:meth:`RunRecorder.write_cells`,
:func:`~ardrone_nmpc.runs.log_columns.tick_cells`): no dict to build and map back.
"""

from __future__ import annotations

import datetime as _dt
import enum
import json
import math
import os
import shutil
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ardrone_nmpc import __version__
from ardrone_nmpc.config.io import dump_config
from ardrone_nmpc.config.schema import ExperimentConfig
from ardrone_nmpc.core.atomic import atomic_path, write_text_atomic
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, TICK_CELL_KEYS, cells_row
from ardrone_nmpc.runs.log_columns import STRING_COLUMNS  # noqa: F401 - its home's name
from ardrone_nmpc.runs.run_inputs import INPUTS_DIR  # noqa: F401 - its home's name
from ardrone_nmpc.runs.run_inputs import copy_inputs as _copy_inputs
from ardrone_nmpc.runs.run_inputs import read_inputs as _read_inputs
from ardrone_nmpc.runs.run_reading import (CONFIG_FILE, EVENTS_FILE, LOG_FILE, SUMMARY_FILE,
                                           LogError, RunData, read_run, read_text)
from ardrone_nmpc.runs.row_text import (_EMPTY_CELLS, _FORBIDDEN, BlockCheck, KeptRows,
                                        _fast_line, _plain_line, block_text, careful_line,
                                        format_number, row_plan)

__all__ = ["LogError", "RunData", "RunRecorder", "SummaryRow", "format_number", "read_run",
           "read_summary", "write_summary"]

_TICK_PLAN = row_plan(TICK_CELL_KEYS)


def _json_default(obj: Any) -> Any:
    """JSON for the odd types events carry; never raises (an event must not stop a flight)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, (set, frozenset)):
        return sorted(obj, key=repr)
    if isinstance(obj, (Path, _dt.datetime, _dt.date)):
        return str(obj)
    return repr(obj)


#: The events' encoder, made once (json.dumps given arguments makes one per call: ~5 µs).
_EVENT_JSON = json.JSONEncoder(default=_json_default, separators=(",", ":"))


def _write_all(raw: Any, data: bytes) -> None:
    """Write ``data`` to an unbuffered file: one ``write`` call unless the OS takes less."""
    n = raw.write(data)
    while n is not None and n < len(data):  # pragma: no cover - regular files take it all
        data = data[n:]
        n = raw.write(data)


class RunRecorder:
    """Writes one run directory; a context manager (leaving it closes the files).

    Make one with :meth:`create`. :meth:`write_row` and :meth:`event` hand each line to the OS
    at once (see the module docstring). :attr:`config` is the configuration the run must fly:
    the one given, with its input files replaced by their copies in the run directory.
    """

    def __init__(self, path: Path, log_file: Any, events_file: Any,
                 config: ExperimentConfig | None = None, *, rows_per_write: int = 1) -> None:
        self.path = path
        self.config = config
        self._log = log_file
        self._events = events_file
        self.rows_written = 0
        #: ``t_s`` of the last row written (NaN before the first).
        self.last_t_s = math.nan
        self._plans: dict[tuple, tuple] = {}
        self._kept = KeptRows(self.KEEP_ROWS)
        self._rows_per_write = max(1, int(rows_per_write))
        self._held: list[tuple[list, tuple]] = []  # (cells, plan) of rows not yet written
        self._held_since = 0.0
        self._writing: tuple | None = None  # (held, file position, rows): _write_held's
        self._blockable = BlockCheck()
        self._tick_plan = _TICK_PLAN  # the plan of write_cells' rows
        #: Whether ``config.yaml`` and ``summary.csv`` are ``fsync``-ed (:meth:`create`).
        self.durable = True

    #: How many rows :meth:`kept_columns` keeps (~1.5 kB each: ~20 min at 16 Hz); a longer run
    #: is summarised from its file.
    KEEP_ROWS = 20_000
    #: The longest a row is held for its block (s of wall time; ``rows_per_write``).
    HOLD_S = 0.25

    # -- creation ---------------------------------------------------------------------------
    @classmethod
    def create(cls, log_dir: str | Path, cfg: ExperimentConfig, *, seed: int | None,
               now: _dt.datetime | None = None, rows_per_write: int = 1,
               durable: bool = True, name: str | None = None) -> RunRecorder:
        """Create ``log_dir/<YYYYmmdd-HHMMSS>-<cfg.name>/`` (``-2``, ``-3``, … appended if it
        exists; parents created) — or ``log_dir/<name>/`` as named (FileExistsError if it
        exists: a sweep's staging directory) —, copy the input files into ``inputs/``, write
        ``config.yaml``, open ``log.csv`` (header row written) and ``events.jsonl``. Fly
        :attr:`config` (it reads the copies).

        The input files are read and checked first: a missing or malformed waypoint file
        raises :class:`~ardrone_nmpc.reference.waypoints.ReferenceError` before anything is
        created; a failure while filling the directory removes it again.

        Parameters
        ----------
        log_dir : directory holding the runs.
        cfg : the resolved experiment configuration.
        seed : the run's random seed (recorded in ``config.yaml``'s header), or None.
        now : the creation time for the name and header (default: the local time now).
        rows_per_write : hand the rows to the OS in blocks of up to this many (1: each row
            at once; see :meth:`write_row`).
        durable : ``fsync`` ``config.yaml`` (and ``summary.csv``, :attr:`durable`). False for
            a simulation, which its config flies again bit for bit: an ``fsync`` after a
            flight's ~0.7 MB log costs ~2.5 ms of wall time (the journal writes the log first).
        """
        inputs = _read_inputs(cfg)  # checked before anything is created
        now = now if now is not None else _dt.datetime.now().astimezone()
        log_dir = Path(log_dir)
        log_dir.mkdir(parents=True, exist_ok=True)
        base = f"{now.strftime('%Y%m%d-%H%M%S')}-{cfg.name}" if name is None else name
        suffix = 1
        while True:
            path = log_dir / (base if suffix == 1 else f"{base}-{suffix}")
            try:
                path.mkdir()  # atomic: two recorders never share a directory
                break
            except FileExistsError:
                if name is not None:
                    raise
                suffix += 1
        try:
            return cls._fill(path, cfg, inputs, seed=seed, now=now,
                             rows_per_write=rows_per_write, durable=durable)
        except BaseException:  # a disk full or read-only: no half-made run directory
            shutil.rmtree(path, ignore_errors=True)
            raise

    @classmethod
    def _fill(cls, path: Path, cfg: ExperimentConfig, inputs: dict, *, seed: int | None,
              now: _dt.datetime, rows_per_write: int = 1, durable: bool = True
              ) -> RunRecorder:
        """Copy the inputs, write ``config.yaml``, open ``log.csv`` and ``events.jsonl``."""
        recorded, flown, origins = _copy_inputs(path, cfg, inputs)
        header = (f"ardrone-nmpc {__version__}\nseed: {seed}\n"
                  f"created: {now.isoformat(timespec='seconds')}{origins}")
        with open(path / CONFIG_FILE, "w", encoding="utf-8") as f:
            f.write(dump_config(recorded, header=header))
            if durable:
                f.flush()
                os.fsync(f.fileno())
        log_file = open(path / LOG_FILE, "xb", buffering=0)  # noqa: SIM115 - closed in close()
        try:
            _write_all(log_file, (",".join(LOG_COLUMNS) + "\n").encode("ascii"))
            events_file = open(path / EVENTS_FILE, "xb", buffering=0)  # noqa: SIM115
        except BaseException:
            log_file.close()
            raise
        recorder = cls(path, log_file, events_file, flown, rows_per_write=rows_per_write)
        recorder.durable = durable
        return recorder

    # -- writing ----------------------------------------------------------------------------
    def write_row(self, row: Mapping[str, Any]) -> None:
        """Append one tick to ``log.csv`` (columns in :data:`LOG_COLUMNS` order) and hand the
        line to the OS.

        A missing key (or ``""``) is an empty cell. Numeric cells take numbers (float, numpy
        scalars, int — exact up to 2**53 —, bool; None is NaN; numpy also parses a numeric
        string); string columns take str (a str enum writes its value). Raises ValueError for
        an unknown key, a value of the wrong kind, or a string holding ``,``, ``"`` or a line
        break; nothing is written then.

        Cost ≈ 10 µs per row on a 2 GHz VM (≈ 2 µs of it the ``write`` system call): the
        keys are checked once per key sequence (callers build their rows the same way every
        tick) and a row of plain cells is printed by one orjson call (:func:`_plain_line`).

        With ``rows_per_write`` > 1 (lockstep recordings) a row whose writing cannot fail
        (:class:`BlockCheck`) is held, and the block printed by one orjson call and one
        ``write`` (:func:`block_text`, the same text; ≈ 7 µs a row in all) when full, when a
        row was held :attr:`HOLD_S`, before a row not held, and on :meth:`flush`,
        :meth:`kept_columns` and :meth:`close` (errors and Ctrl-C close the recorder).
        """
        keys = tuple(row)
        plan = self._plans.get(keys)
        if plan is None:
            plan = self._plan(keys)  # validates the keys; raises for an unknown one
        cells = list(map(row.get, LOG_COLUMNS, _EMPTY_CELLS))
        if self._rows_per_write > 1:
            if self._blockable(cells, plan[5]):
                self._hold(cells, plan, row.get("t_s", self.last_t_s))
                return
            if self._held:
                self._write_held()  # in order: the rows held before this one
        line = _plain_line(cells, plan[4])
        if line is None:
            line, cells = self._line(row, plan), None
        _write_all(self._log, line)
        self.rows_written += 1
        self.last_t_s = row.get("t_s", self.last_t_s)
        self._kept.add(cells, line)

    def write_cells(self, cells: list) -> None:
        """:meth:`write_row` of a lockstep tick's row given as its cells in
        :data:`LOG_COLUMNS` order (:func:`~ardrone_nmpc.runs.log_columns.tick_cells`, truth
        put): the same line, the same errors, without a dict to map back to column order.
        The list is kept (held, :meth:`kept_columns`): the caller must not change it."""
        if self._rows_per_write > 1 and self._blockable.tick_cells(cells):
            self._hold(cells, self._tick_plan, cells[0])
        else:  # one at a time, or a cell to look at closely
            self.write_row(cells_row(cells))

    def _hold(self, cells: list, plan: tuple, t_s: float) -> None:
        """Hold a row for its block; write the block when full or held :attr:`HOLD_S`."""
        held = self._held
        if not held:
            self._held_since = time.monotonic()
        held.append((cells, plan))
        self.rows_written += 1
        self.last_t_s = t_s
        if (len(held) >= self._rows_per_write
                or time.monotonic() - self._held_since > self.HOLD_S):
            self._write_held()

    def _write_held(self) -> None:
        """Print the held rows as one block, hand it to the OS by one ``write``; interrupted,
        they stay held (:meth:`close` writes them) unless they reached the file (``_writing``)."""
        writing, self._writing = self._writing, None
        if writing and writing[0] is self._held and self._log.tell() != writing[1]:
            self._held = writing[0][writing[2]:]  # written, its bookkeeping cut: not again
            self._kept.extend(cells for cells, _ in writing[0][:writing[2]])
        held = self._held
        rows = [cells for cells, _ in held]
        text = block_text(rows)
        kept = [] if text is None else None  # (cells, line) of rows printed one by one
        if text is None:  # a ±inf among them: row by row, as write_row prints them
            for cells, plan in held:
                line = _plain_line(cells, plan[4])
                if line is None:  # pragma: no cover - BlockCheck's rows print plain
                    present = {LOG_COLUMNS[i]: cells[i] for i in plan[1]}
                    line, cells = self._line(present, plan), None
                kept.append((cells, line))
            text = b"".join(line for _, line in kept)
        at = self._log.tell()
        self._writing = (held, at, len(held))  # one store: an interrupt's trace (above)
        try:
            _write_all(self._log, text)
        finally:  # the file grew: written, even if a signal's KeyboardInterrupt followed
            if self._log.tell() != at:
                self._held = []
                if kept is None:  # the block's rows as they are: one list.extend
                    self._kept.extend(rows)
                for cells, line in kept or ():
                    self._kept.add(cells, line)
            self._writing = None

    def kept_columns(self) -> Mapping[str, np.ndarray] | None:
        """The columns of the rows written, as :func:`read_run` would parse them from
        ``log.csv`` (None for a run longer than :attr:`KEEP_ROWS` rows: read it back)."""
        if self._held:
            self._write_held()
        return self._kept.columns()

    def _line(self, row: Mapping[str, Any], plan: tuple) -> bytes:
        """A row :func:`_plain_line` does not take (numpy scalars of other types, bools, a
        value to refuse): the cells one by one into orjson, or :meth:`_careful_line`."""
        template, slots, get_values, string_slots, quotes, _ = plan
        cells = template.copy()
        for slot, value in zip(slots, get_values(row)):
            cells[slot] = value
        line = None
        if all(cells[i].__class__ is str and not _FORBIDDEN.search(cells[i])
               for i in string_slots):
            line = _fast_line(cells, quotes)
        if line is None:
            line = self._careful_line(row)  # NaN/inf/bool cells, or a value to refuse
        return line

    def _plan(self, keys: tuple) -> tuple:
        """Cell template, slots and getter for rows with these keys (cached per key order)."""
        plan = row_plan(keys)  # raises for an unknown key
        if len(self._plans) >= 64:  # rows of ever-changing shapes: keep the cache small
            self._plans.clear()
        self._plans[keys] = plan
        return plan

    _careful_line = staticmethod(careful_line)

    def event(self, t_s: float, kind: str, **fields: Any) -> None:
        """Append ``{"t_s": t_s, "kind": kind, **fields}`` as one line of ``events.jsonl``.

        numpy values, enums and paths are converted; anything else JSON cannot hold is
        written as its ``repr``. Floats keep full precision (NaN/inf as ``NaN``/``Infinity``).
        """
        record = {"t_s": float(t_s), "kind": str(kind), **fields}
        line = _EVENT_JSON.encode(record)
        _write_all(self._events, (line + "\n").encode("utf-8"))

    def flush(self) -> None:
        """Hand the rows held for their block to the OS (events are written at once)."""
        if self._held and not self._log.closed:
            self._write_held()

    def write_summary(self, rows: Iterable[SummaryRow]) -> Path:
        """Write this run's ``summary.csv`` (:func:`write_summary`). Returns its path."""
        return write_summary(self.path, rows, durable=self.durable)

    # -- closing ----------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._log.closed and self._events.closed

    def close(self) -> None:
        """Write the rows held, close ``log.csv`` and ``events.jsonl`` (idempotent)."""
        try:
            self.flush()
        finally:
            self._close_files()

    def _close_files(self) -> None:
        for f in (self._log, self._events):
            if not f.closed:
                f.close()

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"RunRecorder({str(self.path)!r}, rows_written={self.rows_written})"


# ----------------------------------------------------------------------------- summary.csv


@dataclass(frozen=True)
class SummaryRow:
    """One line of ``summary.csv``: ``value`` of ``metric`` for ``axis``, in ``unit``."""

    axis: str
    metric: str
    value: float
    unit: str


SUMMARY_HEADER = "axis,metric,value,unit"


def write_summary(run_dir: str | Path, rows: Iterable[SummaryRow], *,
                  durable: bool = True) -> Path:
    """Write ``run_dir/summary.csv`` (``axis,metric,value,unit``; values as in ``log.csv``),
    replacing any earlier one atomically. Returns its path. ``durable`` False: not
    ``fsync``-ed before it replaces the earlier one (a simulation's: see
    :meth:`RunRecorder.create`)."""
    lines = [SUMMARY_HEADER]
    for r in rows:
        cells = (str(r.axis), str(r.metric), format_number(r.value), str(r.unit))
        for c in cells:
            if _FORBIDDEN.search(c):
                raise ValueError(f"summary cell {c!r} contains ',', '\"' or a line break")
        lines.append(",".join(cells))
    path = Path(run_dir) / SUMMARY_FILE
    text = "\n".join(lines) + "\n"
    if durable:
        return write_text_atomic(path, text)
    with atomic_path(path) as tmp:
        tmp.write_bytes(text.encode("utf-8"))
    return path


def read_summary(run_dir: str | Path) -> list[SummaryRow]:
    """Read a run's ``summary.csv`` (written by :func:`write_summary`).

    Raises :class:`LogError` (``<file>:<line>: …``) if it is missing or malformed.
    """
    path = Path(run_dir) / SUMMARY_FILE
    lines = read_text(path).splitlines()
    if not lines or lines[0].strip() != SUMMARY_HEADER:
        raise LogError(f"{path}:1: expected the header {SUMMARY_HEADER}")
    out = []
    for i, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = line.split(",")
        if len(cells) != 4:
            raise LogError(f"{path}:{i}: expected 4 cells, got {len(cells)}")
        try:
            value = float(cells[2])
        except ValueError:
            raise LogError(f"{path}:{i}: column value: {cells[2]!r} is not a number") from None
        out.append(SummaryRow(cells[0], cells[1], value, cells[3]))
    return out
