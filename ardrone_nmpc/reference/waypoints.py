"""Waypoint files: the CSV of reference kind 'path', read and checked against the limits.

Format: a header row naming the columns ``t_s,x_m,y_m,z_m,psi_rad`` (any order; other
columns are ignored), then one waypoint per row: time (s, strictly increasing), position
(m), heading (rad). Blank lines and lines starting with ``#`` are skipped. At least two
waypoints.

Limits (:mod:`ardrone_nmpc.config.limits`), so that a file that passes ``check`` cannot make a
run crash later: at most 16 MiB and 10 000 waypoints, coordinates within ±1000 m (the cap of
the built-in paths), consecutive times at least 1 ms apart, a path at most 10 km long.

Every error is a :class:`ReferenceError` reading ``<file>:<line>: <message>`` (1-based line).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ardrone_nmpc.config.limits import (MAX_COORDINATE_M, MAX_PATH_FILE_BYTES,
                                        MAX_PATH_LENGTH_M, MAX_WAYPOINTS, MIN_WAYPOINT_STEP_S)
from ardrone_nmpc.errors import UserError

__all__ = ["ReferenceError", "WAYPOINT_COLUMNS", "WaypointFile", "parse_waypoints",
           "read_waypoint_file"]

#: Columns of a waypoint CSV file, in the order they are written.
WAYPOINT_COLUMNS = ("t_s", "x_m", "y_m", "z_m", "psi_rad")


class ReferenceError(UserError, ValueError):  # noqa: A001 - shadows the builtin here only
    """A reference that cannot be built, e.g. a malformed waypoint file (exit code 1).

    File errors read ``<file>:<line>: <message>`` with a 1-based line number.
    """


@dataclass(frozen=True)
class WaypointFile:
    """A waypoint file read and checked: its bytes (copied into run directories as they
    are) and its waypoints."""

    path: Path
    raw: bytes
    t_s: np.ndarray           # (K,) strictly increasing
    positions_m: np.ndarray   # (K, 3)
    psi_rad: np.ndarray       # (K,)


def _error(source: object, line: int, message: str) -> ReferenceError:
    return ReferenceError(f"{source}:{line}: {message}")


def _rows(text: str) -> Iterator[tuple[int, list[str]]]:
    """``(line number, cells)`` of the data-bearing lines, lazily (a huge file stops at the
    row beyond the limit instead of being split whole)."""
    for lineno, fields in enumerate(csv.reader(io.StringIO(text)), start=1):
        cells = [c.strip() for c in fields]
        if any(cells) and not cells[0].startswith("#"):
            yield lineno, cells


def _columns(source: object, line: int, header: list[str]) -> list[int]:
    for name in WAYPOINT_COLUMNS:
        if header.count(name) > 1:
            raise _error(source, line, f"column '{name}' appears more than once")
    missing = [name for name in WAYPOINT_COLUMNS if name not in header]
    if missing:
        raise _error(source, line,
                     f"missing column{'s' if len(missing) > 1 else ''} "
                     f"{', '.join(repr(m) for m in missing)} (header: {','.join(header)}; "
                     f"expected {','.join(WAYPOINT_COLUMNS)})")
    return [header.index(name) for name in WAYPOINT_COLUMNS]


def _cell(source: object, line: int, name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _error(source, line, f"column '{name}': {text!r} is not a number") from None
    if not math.isfinite(value):
        raise _error(source, line, f"column '{name}': {text!r} is not a finite number")
    if name in ("x_m", "y_m", "z_m") and abs(value) > MAX_COORDINATE_M:
        raise _error(source, line, f"column '{name}': {text} is outside "
                                   f"±{MAX_COORDINATE_M:g} m")
    return value


def parse_waypoints(text: str, source: object = "<waypoints>"
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t_s (K,), positions_m (K, 3), psi_rad (K,))`` of a waypoint file's text; errors
    name ``source`` and the line."""
    rows = _rows(text)
    header_line, header = next(rows, (1, None))
    if header is None:
        raise _error(source, 1, "empty file: expected a header row " + ",".join(WAYPOINT_COLUMNS))
    index = _columns(source, header_line, header)
    values: list[list[float]] = []
    lineno = header_line
    for count, (lineno, cells) in enumerate(rows, start=1):
        if count > MAX_WAYPOINTS:
            raise _error(source, lineno, f"more than {MAX_WAYPOINTS} waypoints")
        if len(cells) != len(header):
            raise _error(source, lineno, f"expected {len(header)} values, got {len(cells)}")
        row = [_cell(source, lineno, name, cells[i]) for name, i in zip(WAYPOINT_COLUMNS, index)]
        if values and not row[0] > values[-1][0]:
            raise _error(source, lineno, f"time {row[0]} is not after the previous "
                                         f"{values[-1][0]}")
        if values and row[0] - values[-1][0] < MIN_WAYPOINT_STEP_S:
            raise _error(source, lineno, f"time {row[0]} is less than "
                                         f"{MIN_WAYPOINT_STEP_S * 1e3:g} ms after the "
                                         f"previous {values[-1][0]}")
        values.append(row)
    if len(values) < 2:
        raise _error(source, lineno, f"at least 2 waypoints are needed, got {len(values)}")
    data = np.asarray(values, dtype=np.float64)
    length_m = float(np.linalg.norm(np.diff(data[:, 1:4], axis=0), axis=1).sum())
    if length_m > MAX_PATH_LENGTH_M:
        raise _error(source, lineno, f"the path is {length_m:.6g} m long; at most "
                                     f"{MAX_PATH_LENGTH_M:g} m")
    return data[:, 0], data[:, 1:4], data[:, 4]


def read_waypoint_file(path: str | Path) -> WaypointFile:
    """Read and check a waypoint file (see the module docstring).

    Raises :class:`ReferenceError`: ``no such file: <path>``, ``<path>: cannot read: …``, a
    file above 16 MiB, or ``<path>:<line>: …`` for its contents.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        if not path.is_file():
            raise ReferenceError(f"{path}: not a file")
        if size > MAX_PATH_FILE_BYTES:
            raise ReferenceError(f"{path}: {size} bytes; a waypoint file may hold at most "
                                 f"{MAX_PATH_FILE_BYTES // 2**20} MiB")
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ReferenceError(f"no such file: {path}") from None
    except OSError as exc:
        raise ReferenceError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise _error(path, line, "not UTF-8 text") from None
    t_s, positions_m, psi_rad = parse_waypoints(text, path)
    return WaypointFile(path, raw, t_s, positions_m, psi_rad)
