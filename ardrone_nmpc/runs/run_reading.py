"""A run directory read back (:mod:`ardrone_nmpc.runs.rundir` writes it; its docstring
describes the files): :func:`read_run` gives its configuration, log columns and events as a
:class:`RunData`, or raises :class:`LogError` naming the file and line it cannot read.

Its own module for size (the run directory's module stays under the architecture test's
cap); :mod:`~ardrone_nmpc.runs.rundir` re-exports :class:`LogError`, :class:`RunData`,
:func:`read_run` and the file names, so imports from there keep working.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ardrone_nmpc.config.io import load_run_config
from ardrone_nmpc.config.schema import ConfigError, ExperimentConfig
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, REQUIRED_COLUMNS, STRING_COLUMNS

__all__ = ["CONFIG_FILE", "EVENTS_FILE", "LOG_FILE", "SUMMARY_FILE", "LogError", "RunData",
           "read_run", "read_text"]

CONFIG_FILE = "config.yaml"
LOG_FILE = "log.csv"
EVENTS_FILE = "events.jsonl"
SUMMARY_FILE = "summary.csv"

_COLUMN_SET = frozenset(LOG_COLUMNS)


class LogError(UserError, ValueError):
    """A run directory that cannot be read: ``<file>:<line>: <message>`` (1-based line;
    exit code 1)."""


@dataclass
class RunData:
    """A run directory read back by :func:`read_run`.

    Attributes
    ----------
    path : the run directory.
    config : the experiment configuration of ``config.yaml``.
    columns : every column of ``log.csv`` (and every :data:`LOG_COLUMNS` name, filled when
        absent) → array over the rows: float64 for numeric columns (empty cell → NaN), object
        arrays of str for :data:`STRING_COLUMNS` (empty cell → ``""``).
    events : the ``events.jsonl`` objects in order.
    seed : the seed recorded in ``config.yaml``'s header (None if absent or ``None``).
    version : the tool version recorded in the header (None if absent).
    warnings : notes about recoverable damage (a torn last line dropped).
    """

    path: Path
    config: ExperimentConfig
    columns: dict[str, np.ndarray]
    events: list[dict[str, Any]]
    seed: int | None = None
    version: str | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def n_rows(self) -> int:
        """Number of logged ticks."""
        return int(self.columns["t_s"].size)

    def __len__(self) -> int:
        return self.n_rows


def read_text(path: Path) -> str:
    """A run directory's file as text; :class:`LogError` if it is missing, unreadable or not
    UTF-8."""
    if not path.is_file():
        raise LogError(f"{path}: no such file")
    try:
        return path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise LogError(f"{path}: cannot read: {exc}") from None
    except UnicodeDecodeError as exc:
        line = path.read_bytes()[: exc.start].count(b"\n") + 1
        raise LogError(f"{path}:{line}: not UTF-8 text") from None


def _split_lines(path: Path, text: str, warnings: list[str]) -> list[str]:
    """Complete lines of ``text``; a final line without its newline (torn by a crash) is
    dropped with a note in ``warnings``."""
    if "\r" in text:
        text = text.replace("\r\n", "\n")
    parts = text.split("\n")
    torn = parts.pop()  # "" when the text ends with a newline
    if torn:
        warnings.append(f"{path}:{len(parts) + 1}: incomplete last line dropped "
                        f"(the run was probably cut short): {torn[:60]!r}")
    return parts


def _parse_header_comments(text: str) -> tuple[int | None, str | None]:
    seed: int | None = None
    version: str | None = None
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        body = line[1:].strip()
        if body.startswith("seed:"):
            value = body[5:].strip()
            try:
                seed = int(value)
            except ValueError:
                seed = None
        elif body.startswith("ardrone-nmpc "):
            version = body.split(None, 1)[1].strip()
    return seed, version


def _float_column(path: Path, name: str, cells: list[str]) -> np.ndarray:
    """Parse one numeric column; ``cells[i]`` is on line ``i + 2`` of the file."""
    n = len(cells)
    try:
        return np.fromiter(map(float, cells), dtype=np.float64, count=n)
    except ValueError:
        pass
    if cells.count("") == n:  # a column no row filled (tick_late_ms in simulation, target_*)
        return np.full(n, math.nan)
    out = np.empty(n, dtype=np.float64)
    for i, cell in enumerate(cells):
        if cell == "":
            out[i] = math.nan
            continue
        try:
            out[i] = float(cell)
        except ValueError:
            raise LogError(f"{path}:{i + 2}: column {name}: {cell!r} is not a number") from None
    return out


def _read_log(path: Path, warnings: list[str]) -> dict[str, np.ndarray]:
    lines = _split_lines(path, read_text(path), warnings)
    if not lines or not lines[0].strip():
        if warnings and not lines:
            raise LogError(f"{path}:1: incomplete header row")
        raise LogError(f"{path}:1: empty file: expected a header row")
    header = [c.strip() for c in lines[0].split(",")]
    seen: set[str] = set()
    for name in header:
        if name in seen:
            raise LogError(f"{path}:1: column {name!r} appears more than once")
        seen.add(name)
    missing = [c for c in REQUIRED_COLUMNS if c not in seen]
    if missing:
        raise LogError(f"{path}:1: missing column{'s' if len(missing) > 1 else ''} "
                       f"{', '.join(missing)}")
    width = len(header)
    rows = [line.split(",") for line in lines[1:]]
    for i, cells in enumerate(rows):
        if len(cells) != width:
            raise LogError(f"{path}:{i + 2}: expected {width} cells, got {len(cells)} "
                           f"(a torn or corrupted row)")
    n = len(rows)
    transposed = list(zip(*rows)) if n else [()] * width
    columns: dict[str, np.ndarray] = {}
    for name, cells in zip(header, transposed):
        if name in STRING_COLUMNS:
            arr = np.empty(n, dtype=object)
            arr[:] = list(cells)
            columns[name] = arr
        elif name in _COLUMN_SET:
            columns[name] = _float_column(path, name, list(cells))
        else:  # an extra column: numbers if they all parse, strings otherwise
            try:
                columns[name] = _float_column(path, name, list(cells))
            except LogError:
                arr = np.empty(n, dtype=object)
                arr[:] = list(cells)
                columns[name] = arr
    for name in LOG_COLUMNS:
        if name not in columns:
            if name in STRING_COLUMNS:
                arr = np.empty(n, dtype=object)
                arr[:] = [""] * n
                columns[name] = arr
            else:
                columns[name] = np.full(n, math.nan)
    return columns


def _read_events(path: Path, warnings: list[str]) -> list[dict[str, Any]]:
    events = []
    for i, line in enumerate(_split_lines(path, read_text(path), warnings), start=1):
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError as exc:
            raise LogError(f"{path}:{i}: invalid JSON: {exc.msg}") from None
        if not isinstance(obj, dict):
            raise LogError(f"{path}:{i}: expected a JSON object, got {type(obj).__name__}")
        events.append(obj)
    return _on_experiment_clock(events)


def _on_experiment_clock(events: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The events of a real-time run written before every runner stamped ``t_s`` with
    experiment time (``fly`` wrote its session's wall time there, and experiment time into
    ``t_exp_s``): ``t_s`` becomes experiment time and the old stamp ``wall_s``. The clocks'
    offset comes from the events that carry both; without any, ``t_s`` is NaN."""
    old = (any(e.get("kind") == "links" for e in events)
           and not any("wall_s" in e for e in events))
    if not old:
        return events
    offsets = [e["t_s"] - e["t_exp_s"] for e in events
               if isinstance(e.get("t_s"), (int, float)) and isinstance(e.get("t_exp_s"),
                                                                       (int, float))]
    offset = float(np.median(offsets)) if offsets else math.nan
    out = []
    for e in events:
        e = dict(e)
        wall = e.pop("t_s", math.nan)
        t_exp = e.pop("t_exp_s", None)
        wall = float(wall) if isinstance(wall, (int, float)) else math.nan
        t_s = float(t_exp) if isinstance(t_exp, (int, float)) else wall - offset
        out.append({"t_s": t_s, **e, "wall_s": wall})
    return out


def read_run(run_dir: str | Path, *, columns: dict[str, np.ndarray] | None = None,
             config: ExperimentConfig | None = None) -> RunData:
    """Read a run directory written by :class:`~ardrone_nmpc.runs.rundir.RunRecorder`;
    ``columns`` (its :meth:`~ardrone_nmpc.runs.rundir.RunRecorder.kept_columns`) stand for
    ``log.csv``, which is then not parsed again, and ``config`` (its
    :attr:`~ardrone_nmpc.runs.rundir.RunRecorder.config`: what ``config.yaml`` loads back as —
    ``tests/unit/test_read_run_config.py``) for ``config.yaml``'s settings, which are then
    not parsed and validated again (its header comments still are).

    Raises
    ------
    LogError
        ``<file>:<line>: <message>`` for a missing directory or file, an invalid
        ``config.yaml``, a ``log.csv`` header without a required column (or with a repeated
        one), a row with the wrong number of cells (a torn line anywhere but at the end), a
        non-numeric cell in a numeric column, or an ``events.jsonl`` line that is not a JSON
        object. A torn *last* line of ``log.csv`` or ``events.jsonl`` is dropped with a note
        in :attr:`RunData.warnings`.
    """
    path = Path(run_dir)
    if not path.is_dir():
        raise LogError(f"{path}: " + ("a file, not a run directory" if path.exists()
                                      else "no such run directory"))
    cfg_path = path / CONFIG_FILE
    cfg_text = read_text(cfg_path)
    try:
        if config is None:
            config = load_run_config(cfg_path)
    except ConfigError as exc:
        detail = "; ".join(exc.messages)
        prefix = "" if detail.startswith(str(cfg_path)) else f"{cfg_path}: "
        raise LogError(f"{prefix}{detail}") from None
    seed, version = _parse_header_comments(cfg_text)
    warnings: list[str] = []
    missing = config.reference.path_file
    if missing is not None and not Path(missing).is_file():  # an older run: no copy
        warnings.append(f"{cfg_path}: reference.path_file {missing} is gone: path metrics "
                        "and the reference path cannot be shown")
    if columns is None:
        columns = _read_log(path / LOG_FILE, warnings)
    events = _read_events(path / EVENTS_FILE, warnings)
    return RunData(path=path, config=config, columns=columns, events=events, seed=seed,
                   version=version, warnings=warnings)
