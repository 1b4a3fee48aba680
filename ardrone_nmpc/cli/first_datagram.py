"""The first datagram of ``land`` and ``emergency``, sent by the entry point before anything else
loads (:mod:`ardrone_nmpc.cli.launch`).

The command line framework (typer, and the pydantic it loads) takes most of a second to import
on a busy laptop — a second an operator cutting a drone does not have. So the entry point
reads just ``--drone`` and ``--at-port`` from the command line and sends the command's first
datagram itself (REF land; for ``emergency``, REF land then REF emergency: the edge of bit 8,
docs/protocol.md §2.4), numbered from 1 like every datagram of
:class:`~ardrone_nmpc.links.operator_link.OperatorLink`, with nothing but the wire encoder
loaded. Then the command runs as usual; :data:`SENT` tells it the datagram went, so it does not
make a second edge. Anything it cannot read with certainty (``--help``, a missing or malformed
value) it leaves to the command line, which then sends the first datagram itself.
"""

from __future__ import annotations

import socket
from collections.abc import Sequence

from ardrone_nmpc.cli.raw_options import raw_options

__all__ = ["SENT", "send_first", "target"]

#: ``(command, drone host, AT port)`` of the first datagram sent here, or None.
SENT: tuple[str, str, int] | None = None

_COMMANDS = ("land", "emergency")
_DEFAULTS = ("192.168.1.1", 5556)  # the options' defaults in cli/operator.py
_LOCAL_AT_PORT = 5556              # the guide's source port; any other works (a busy one)


def target(args: Sequence[str]) -> tuple[str, int] | None:
    """The ``(host, AT port)`` an operator command line names, or None when it cannot be read
    with certainty (help asked, a value missing or malformed)."""
    # (land and emergency take no arguments: read to the end, "--" and all)
    options = raw_options(args, ("--drone", "--at-port"), stop_at_separator=False)
    if options is None:
        return None
    host, port = _DEFAULTS
    for name, value in options:
        if name == "--drone":
            host = value
        elif value.isdecimal() and 1 <= int(value) <= 65535:  # isdigit() passes "²"
            port = int(value)
        else:
            return None
    return (host, port) if host.strip() else None


def send_first(argv: Sequence[str]) -> None:
    """For ``land``/``emergency``: send the first datagram now and note it in :data:`SENT`
    (nothing on any error: the command then sends it itself)."""
    global SENT
    if not argv or argv[0] not in _COMMANDS:
        return
    where = target(argv[1:])
    if where is None:
        return
    from ardrone_nmpc.protocol.at import AtSequencer, Pcmd, Ref

    bodies = [Ref.landing(), *([Ref.emergency()] if argv[0] == "emergency" else []),
              Pcmd.hover()]
    try:
        address = (socket.gethostbyname(where[0]), where[1])
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind(("0.0.0.0", _LOCAL_AT_PORT))
            except OSError:
                pass  # busy: an ephemeral port
            for datagram in AtSequencer().pack(bodies):
                sock.sendto(datagram, address)
    except OSError:
        return
    SENT = (argv[0], where[0], where[1])

