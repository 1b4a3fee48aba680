"""Checks of option values done while the command line is parsed (exit 2, one line).

click's own ranges let NaN through and say nothing of empty strings; these callbacks make
every number finite and inside its documented range, and refuse an empty host, so that a
typo never silently becomes a default.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Optional, Union

import typer

__all__ = ["DEPRECATED_SPELLINGS", "MAX_JOBS", "PORT_MAX", "choice", "finite",
           "modern_spellings", "new_output_file", "non_empty", "output_file", "port"]

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
    """A callback for a file the command will write: not a directory, and no file where a
    parent directory has to be (checked before the work, not after it)."""
    if value is None:
        return None
    if value.is_dir():
        raise typer.BadParameter(f"{value} is a directory; give a file name")
    for parent in value.parents:
        if parent.exists():
            if not parent.is_dir():
                raise typer.BadParameter(f"{parent} is not a directory")
            break
    return value


def new_output_file(value: Optional[Path]) -> Optional[Path]:
    """:func:`output_file` that must not exist yet (a recording never replaces a file)."""
    value = output_file(value)
    if value is not None and value.exists():
        raise typer.BadParameter(f"{value} exists; give a new file name")
    return value


Values = Union[Iterable[str], Callable[[], Iterable[str]]]


def choice(values: Values, *, many: bool = False) -> dict[str, Any]:
    """``typer.Option`` keywords for a closed set of values: a callback refusing any other
    (exit 2, naming the choices) and shell completion of them. ``many``: a comma-separated
    list of them. ``values`` may be a function (called when the option is used: a list that
    lives in a module too heavy to import at start-up)."""

    def known() -> list[str]:
        return list(values() if callable(values) else values)

    def check(value: Optional[str]) -> Optional[str]:
        if value is None:
            return None
        names = [n.strip() for n in value.split(",") if n.strip()] if many else [value]
        bad = [n for n in names if n not in known()]
        if bad or not names:
            what = ", ".join(repr(n) for n in bad) or "(empty)"
            raise typer.BadParameter(f"unknown {what}; choose {'from ' if many else ''}"
                                     f"{', '.join(known())}")
        return value

    def complete(incomplete: str) -> list[str]:
        head, _, last = incomplete.rpartition(",") if many else ("", "", incomplete)
        prefix = head + "," if head else ""
        return [prefix + v for v in known() if v.startswith(last)]

    return {"callback": check, "autocompletion": complete}


#: Old spellings of options, per command, still accepted (with a warning on stderr): what a
#: command writes is ``-o/--output`` everywhere (a file, or the folder it fills); where new
#: run directories are created is ``--log-dir``.
DEPRECATED_SPELLINGS: dict[str, dict[str, str]] = {
    "reproduce": {"--out": "--output"},
    "robustness": {"--out": "--output"},
    "sweep": {"--out": "--output"},
    "tune": {"--out": "--output"},
}


def modern_spellings(command: str, args: list[str], warn: Callable[[str], None]) -> list[str]:
    """``args`` of ``command`` with each deprecated option spelling (``--out DIR``,
    ``--out=DIR``) replaced by the current one, and ``warn(line)`` once per spelling used.
    Nothing after ``--`` is touched."""
    table = DEPRECATED_SPELLINGS.get(command, {})
    out: list[str] = []
    warned: set[str] = set()
    for k, arg in enumerate(args):
        if arg == "--":
            return out + args[k:]
        name, eq, value = arg.partition("=")
        if name in table:
            if name not in warned:
                warned.add(name)
                new = table[name]
                warn(f"warning: {name} is deprecated; use "
                     f"{'-o/--output' if new == '--output' else new}")
            arg = table[name] + eq + value
        out.append(arg)
    return out
