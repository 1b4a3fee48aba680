"""The command line's one error handler: every user error becomes ``error: …`` and an exit code.

:class:`CommandGroup` is the click group behind the typer app. Whatever a command raises
passes through :meth:`CommandGroup.invoke`:

* :class:`~ardrone_nmpc.errors.UserError` — its lines, its exit code (1 unless it says);
* a command-line problem (unknown option, bad or out-of-range value) — one line, exit 2;
* an ``OSError`` of the file system or the network (a directory that is a file, a read-only
  disk, a port in use) — one line naming the file, exit 1;
* a closed or broken standard output — one line on stderr (if it is open), exit 1.

Anything else is a bug and keeps its traceback. The exit codes are listed in
:mod:`ardrone_nmpc.errors`.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable

import typer
from typer.core import TyperGroup

from ardrone_nmpc.errors import EXIT_ERROR, UserError

__all__ = ["CommandGroup", "report"]

# Recent typer versions carry their own copy of click, older ones use click itself: take the
# command-line error classes from where typer's own BadParameter comes from.
_CLICK_ERRORS = {cls.__name__: cls for cls in typer.BadParameter.__mro__}
UsageError = _CLICK_ERRORS["UsageError"]
ClickException = _CLICK_ERRORS["ClickException"]
NoArgsIsHelpError = getattr(sys.modules[UsageError.__module__], "NoArgsIsHelpError", ())
_PASS_THROUGH = (typer.Exit, typer.Abort, NoArgsIsHelpError)

STDOUT_CLOSED = ("standard output is closed; redirect it (> FILE, > /dev/null) instead of "
                 "closing it")


def report(lines: Iterable[str]) -> None:
    """Print ``error: <line>`` on stderr for each line (nothing if stderr is closed too)."""
    for line in lines:
        typer.echo(f"error: {' '.join(str(line).split())}", err=True)


def _usage_line(err: ClickException) -> str:
    """One line for a command-line error: ``--option: message`` rather than click's box."""
    if isinstance(err, typer.BadParameter) and (err.param is not None or err.param_hint):
        hint = err.param_hint or getattr(err.param, "opts", None) or [err.param.name]
        if not isinstance(hint, str):
            hint = " / ".join(hint)
        return f"{hint.strip(chr(39) + chr(34))}: {err.message}"
    ctx = getattr(err, "ctx", None)
    see = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    return f"{err.format_message()}{see}"


def _os_line(err: OSError) -> str:
    what = err.strerror or str(err)
    name = err.filename
    return f"{name}: {what}" if name else what


def _silence_stdout() -> None:
    """After a broken pipe: point fd 1 at /dev/null so the interpreter's final flush does not
    print a second complaint."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, AttributeError, ValueError):  # no real fd (a test runner's buffer)
        pass


class CommandGroup(TyperGroup):
    """The typer group with the one error handler (see the module docstring)."""

    def make_context(self, info_name, args, parent=None, **extra):
        try:  # the group's own arguments: `ardrone-nmpc --bogus`
            return super().make_context(info_name, args, parent=parent, **extra)
        except _PASS_THROUGH:
            raise
        except ClickException as err:
            report([_usage_line(err)])
            raise typer.Exit(err.exit_code) from None

    def resolve_command(self, ctx, args):
        """The command, with its deprecated option spellings replaced (and warned about)."""
        from ardrone_nmpc.cli.options import modern_spellings

        name, cmd, rest = super().resolve_command(ctx, args)
        if name is not None:
            rest = modern_spellings(name, list(rest), lambda line: typer.echo(line, err=True))
        return name, cmd, rest

    def invoke(self, ctx: typer.Context):
        if sys.stdout is None:  # started with `>&-`: there is nowhere to print the results
            report([STDOUT_CLOSED])
            raise typer.Exit(EXIT_ERROR)
        try:
            return super().invoke(ctx)
        except _PASS_THROUGH:
            raise
        except ClickException as err:
            report([_usage_line(err)])
            raise typer.Exit(err.exit_code) from None
        except UserError as err:
            report(err.messages)
            raise typer.Exit(err.exit_code) from None
        except BrokenPipeError:
            _silence_stdout()
            report(["standard output was closed before everything was written (broken pipe)"])
            raise typer.Exit(EXIT_ERROR) from None
        except OSError as err:
            report([_os_line(err)])
            raise typer.Exit(EXIT_ERROR) from None
