"""Options read from the raw command line before it is parsed (the entry point's early work:
:mod:`ardrone_nmpc.cli.launch`, :mod:`ardrone_nmpc.cli.first_datagram`), with nothing loaded.

Only what can be read with certainty: the caller gives up on anything else and leaves it to
the command line, which then does the work itself.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

__all__ = ["raw_options"]

_HELP = ("--help", "-h")


def raw_options(args: Sequence[str], names: Collection[str], *,
                stop_at_separator: bool) -> list[tuple[str, str]] | None:
    """The ``(name, value)`` of each ``--name value`` or ``--name=value`` in ``args`` whose
    name is one of ``names``, in their order; None when the line cannot be read with
    certainty: help asked (``--help``, ``-h``) or a value missing at the end.

    A value taken from the next argument is not read as an option itself. With
    ``stop_at_separator`` a ``--`` ends the options (the rest are arguments, as the parser
    reads them); without, a command whose options may follow its arguments is read to its
    end. The values are not checked: the caller refuses what it cannot use.
    """
    found = []
    values = iter(args)
    for arg in values:
        if stop_at_separator and arg == "--":
            break
        name, eq, value = arg.partition("=")
        if name in _HELP:
            return None
        if name not in names:
            continue
        if not eq:
            value = next(values, None)
            if value is None:
                return None
        found.append((name, value))
    return found
