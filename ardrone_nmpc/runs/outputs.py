"""Where a command may write: the checks every output option passes before any work.

A run directory is a record: nothing a command writes may land inside one but what the run's
own recording writes (and ``plot``'s figures, ``plot-*``, beside them). Outputs named by the
user are checked here before anything runs, and written with :mod:`ardrone_nmpc.core.atomic`
(a temporary file renamed into place), so a mistyped ``-o`` cannot destroy a run or a
previous export:

* :func:`check_output_file` — not a directory, not inside a run directory, its folder not a
  file; an existing file only with ``force`` (an export's ``--force``), and then only a regular
  file (never a device node, a pipe or a socket);
* :func:`check_output_dir` — a folder a command creates things in (``--log-dir``, ``--out``):
  not inside (or being) a run directory, not a link to nowhere.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ardrone_nmpc.errors import UserError
from ardrone_nmpc.runs.rundir import CONFIG_FILE, EVENTS_FILE, LOG_FILE

__all__ = ["FIGURE_PREFIX", "OutputError", "check_output_dir", "check_output_file",
           "is_run_dir", "run_dir_holding"]

#: The files ``plot`` writes into a run (or sweep) directory by default.
FIGURE_PREFIX = "plot-"


class OutputError(UserError):
    """An output a command must not write (inside a run directory, an existing file, a
    device…): one line naming the option and the path, exit 1."""


def is_run_dir(path: Path) -> bool:
    """Whether ``path`` is a run directory (``config.yaml`` with ``log.csv`` or
    ``events.jsonl``)."""
    return (path / CONFIG_FILE).is_file() and ((path / LOG_FILE).is_file()
                                               or (path / EVENTS_FILE).is_file())


def _resolved(path: str | Path) -> Path:
    absolute = Path(os.path.abspath(path))
    try:
        return absolute.resolve()
    except (OSError, RuntimeError):  # a link loop: judged by the path as written
        return absolute


def run_dir_holding(path: str | Path) -> Path | None:
    """The run directory ``path`` is (or lies in), following links; None if none."""
    resolved = _resolved(path)
    for folder in (resolved, *resolved.parents):
        if folder.is_dir() and is_run_dir(folder):
            return folder
    return None


def _run_dir_error(option: str, path: Path, run: Path) -> OutputError:
    return OutputError(f"{option} {path}: inside the run directory {run}, which only its "
                       f"recording writes; choose a path outside it (e.g. beside it)")


def check_output_file(path: str | Path, *, option: str, force: bool = False,
                      figures: bool = False, replace: bool = False) -> Path:
    """Refuse an output file ``path`` a command must not write (see the module docstring);
    ``figures``: a ``plot-*`` file directly in a run directory is allowed; ``replace``: an
    existing regular file is replaced without ``force`` (a report a command regenerates).
    Returns it."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{option} {path}: is a directory; give a file name")
    run = run_dir_holding(path)
    figure = figures and path.name.startswith(FIGURE_PREFIX) and _resolved(path.parent) == run
    if run is not None and not figure:
        raise _run_dir_error(option, path, run)
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{option} {path}: {parent} is not a directory")
            break
    if os.path.lexists(path):
        mode = os.lstat(path).st_mode
        if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
            raise OutputError(f"{option} {path}: is not a regular file (a device, a pipe or a "
                              "socket); it is never replaced")
        if not (force or replace):
            raise OutputError(f"{option} {path}: exists; --force replaces it")
    return path


def check_output_dir(path: str | Path, *, option: str) -> Path:
    """Refuse a folder ``path`` a command would create things in when it is (or lies in) a
    run directory, or is a link to nowhere (creating it would fail with a baffling "File
    exists"). Returns it; a file in its place is for the command to refuse."""
    path = Path(path)
    if path.is_symlink() and not path.exists():
        raise OutputError(f"{option} {path}: a symbolic link to {os.readlink(path)}, which "
                          "does not exist")
    run = run_dir_holding(path)
    if run is not None:
        raise _run_dir_error(option, path, run)
    return path
