"""The consoles every command prints through: results on stdout, progress and notes on stderr.

Results (tables, the ``run: <dir>`` line) go to stdout so they can be piped; progress bars,
warnings and errors go to stderr so a pipe only carries results.
"""

from __future__ import annotations

import sys

from rich.console import Console
from rich.markup import escape

__all__ = ["PIPED_WIDTH", "config_notes", "run_notes", "stderr_console", "stdout_console",
           "stdout_is_terminal", "warn"]

#: Width of the tables when stdout is not a terminal (a file or a pipe has no width).
PIPED_WIDTH = 150


class _Console(Console):
    """rich's Console, except that a broken pipe reaches the central handler (rich would
    exit silently with code 1)."""

    def on_broken_pipe(self) -> None:
        self.quiet = True
        raise BrokenPipeError(32, "Broken pipe")


def stdout_is_terminal() -> bool:
    return sys.stdout is not None and sys.stdout.isatty()


def stdout_console() -> Console:
    """Results: the terminal's width on a TTY; :data:`PIPED_WIDTH` columns when piped."""
    return _Console(width=None if stdout_is_terminal() else PIPED_WIDTH)


def stderr_console() -> Console:
    """Progress, warnings: stderr (never mixed into piped results)."""
    return _Console(stderr=True)


def warn(note: str, console: Console | None = None) -> None:
    """``warning: <note>`` on stderr (or on ``console``)."""
    (console or stderr_console()).print(f"[yellow]warning[/]: {escape(note)}",
                                        highlight=False, soft_wrap=True)


def run_notes(run, *, label: str | None = None) -> str | None:
    """Warn (stderr) about a run read back: its recoverable damage, and how it ended if it did
    not finish (:func:`~ardrone_nmpc.runs.ending.ending_note`); return that ending line."""
    from ardrone_nmpc.runs.ending import ending_note
    from ardrone_nmpc.runs.rundir import SUMMARY_FILE

    for note in run.warnings:
        warn(note)
    ending = ending_note(run.events, summarised=(run.path / SUMMARY_FILE).is_file())
    if ending is not None:
        warn(f"{label or run.path}: {ending}")
    return ending


def config_notes(cfg) -> None:
    """Warn (stderr) about what a config sets and its choices ignore — the same lines from
    ``check`` and from every command that flies it
    (:func:`~ardrone_nmpc.reference.trajectories.ignored_fields`)."""
    from ardrone_nmpc.reference.trajectories import ignored_fields

    for note in ignored_fields(cfg.reference):
        warn(note)
