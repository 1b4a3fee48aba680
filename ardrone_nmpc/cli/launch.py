"""``ardrone-nmpc``'s entry point: a few things start before the command line loads.

The command line framework (typer, and the pydantic it loads) takes most of a second to import
on a busy laptop — a second an operator cutting a drone does not have. So the entry point
first hands the arguments to :func:`~ardrone_nmpc.cli.first_datagram.send_first`, which sends
the operator command's first datagram with nothing but the wire encoder loaded, and only then
loads the command line.

The commands that fly many cases on a local pool (``sweep``, ``tune``, ``robustness``,
``faults --jobs``) spend the same time before they open it, and the pool's forkserver then
spends ~0.7 s more importing numba and loading the kernels before the first case flies: on a
fresh sweep of a couple of seconds, half its wall time, in one process after the other. When the arguments ask for a pool
(:func:`pool_wanted`), the entry point starts that forkserver first
(:func:`~ardrone_nmpc.experiments.parallel.start_forkserver`), so its preload runs on another
core while this process loads the command line, the config and the cases. A guess from the
raw arguments, made before they are parsed: a wrong "yes" (a command that then stops on an
error, or has nothing left to fly) costs a background process that this one ends as it
exits, a wrong "no" only the time saved.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from ardrone_nmpc.cli.raw_options import raw_options

__all__ = ["main", "pool_wanted"]

#: The commands that fly their cases on a local pool of ``--jobs`` workers, and the number of
#: workers when the option is absent (None: the CPU count) — as their options in cli/ say.
POOL_COMMANDS = {"sweep": None, "tune": None, "robustness": None, "faults": 1}


def pool_wanted(args: Sequence[str]) -> bool:
    """Whether a command line asks for a local pool of workers: a command of
    :data:`POOL_COMMANDS` with more than one job on the ``local`` engine. False when it cannot
    be read with certainty (help asked, a value missing or malformed)."""
    if not args or args[0] not in POOL_COMMANDS:
        return False
    # (after "--" the command's arguments: a config file named --jobs, say)
    options = raw_options(args[1:], ("--jobs", "--engine"), stop_at_separator=True)
    if options is None:
        return False
    jobs, engine = POOL_COMMANDS[args[0]], "local"
    for name, value in options:
        if name == "--engine":
            engine = value
        elif value.isdecimal():  # what int() reads (isdigit() passes "²", which it refuses)
            jobs = int(value)
        else:
            return False
    return engine == "local" and (jobs if jobs is not None else os.cpu_count() or 1) > 1


def main() -> None:  # console-script entry point
    from ardrone_nmpc.cli.first_datagram import send_first

    send_first(sys.argv[1:])
    if pool_wanted(sys.argv[1:]):
        from ardrone_nmpc.experiments.parallel import start_forkserver

        try:
            start_forkserver()
        except OSError:  # met again, and reported, when the command opens its pool
            pass
    from ardrone_nmpc.cli.app import main as app_main

    app_main()


if __name__ == "__main__":  # pragma: no cover - ``python -m ardrone_nmpc.cli.launch``
    main()
