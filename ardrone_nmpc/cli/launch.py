"""``ardrone-nmpc``'s entry point: ``land`` and ``emergency`` act before anything else loads.

The command line framework (typer, and the pydantic it loads) takes most of a second to import
on a busy laptop — a second an operator cutting a drone does not have. So the entry point first
hands the arguments to :func:`~ardrone_nmpc.cli.first_datagram.send_first`, which sends the
operator command's first datagram with nothing but the wire encoder loaded, and only then loads
the command line.
"""

from __future__ import annotations

import sys

__all__ = ["main"]


def main() -> None:  # console-script entry point
    from ardrone_nmpc.cli.first_datagram import send_first

    send_first(sys.argv[1:])
    from ardrone_nmpc.cli.app import main as app_main

    app_main()


if __name__ == "__main__":  # pragma: no cover - ``python -m ardrone_nmpc.cli.launch``
    main()
