"""Checks of option values done while the command line is parsed (exit 2, one line).

click's own ranges let NaN through and say nothing of empty strings; these callbacks make
every number finite and inside its documented range, and refuse an empty host, so that a
typo never silently becomes a default.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Optional

import typer

__all__ = ["MAX_JOBS", "PORT_MAX", "finite", "non_empty", "output_dir", "output_file", "port"]

PORT_MAX = 65535
#: Upper bound of ``sweep --jobs`` (processes started at once).
MAX_JOBS = 256


def finite(low: float, high: float, *, low_open: bool = False
           ) -> Callable[[Optional[float]], Optional[float]]:
    """A callback accepting None or a finite number in [low, high] ((low, high] if
    ``low_open``)."""
    interval = f"{'(' if low_open else '['}{low:g}, {high:g}]"

    def check(value: Optional[float]) -> Optional[float]:
        if value is None:
            return None
        above = value > low if low_open else value >= low
        if not (math.isfinite(value) and above and value <= high):
            raise typer.BadParameter(f"must be a number in {interval}, got {value:g}")
        return value

    return check


def port(*, zero_picks_a_free_one: bool = False) -> Callable[[Optional[int]], Optional[int]]:
    """A callback accepting None or a UDP/TCP port, 1 … 65535 (0 too where it asks the
    operating system for a free port, which is then printed)."""
    low = 0 if zero_picks_a_free_one else 1

    def check(value: Optional[int]) -> Optional[int]:
        if value is not None and not low <= value <= PORT_MAX:
            raise typer.BadParameter(f"{value} is not a port ({low} … {PORT_MAX})")
        return value

    return check


def non_empty(value: Optional[str]) -> Optional[str]:
    """A callback refusing an empty or blank string (None: the option was not given)."""
    if value is not None and not value.strip():
        raise typer.BadParameter("must not be empty")
    return value


def output_file(value: Optional[Path]) -> Optional[Path]:
    """A callback for a report the command will (re)write: not a directory, not inside a run
    directory, not a device, and no file where a parent directory has to be (checked before
    the work, not after it; :func:`~ardrone_nmpc.runs.outputs.check_output_file`)."""
    if value is None:
        return None
    from ardrone_nmpc.runs.outputs import OutputError, check_output_file

    try:
        return check_output_file(value, option="", replace=True)
    except OutputError as err:
        raise typer.BadParameter(str(err).strip()) from None


def output_dir(value: Optional[Path]) -> Optional[Path]:
    """A callback for a folder the command creates things in (``--log-dir``, ``--out``): not
    a run directory nor inside one, not a file, not a link to nowhere
    (:func:`~ardrone_nmpc.runs.outputs.check_output_dir`)."""
    if value is None:
        return None
    from ardrone_nmpc.runs.outputs import OutputError, check_output_dir

    try:
        return check_output_dir(value, option="")
    except OutputError as err:
        raise typer.BadParameter(str(err).strip()) from None
