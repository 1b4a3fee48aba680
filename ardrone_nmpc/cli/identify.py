"""``ardrone-nmpc identify RUN [RUN …] -o PLANT.yaml``: fit the drone's channels from logged
flights and write the plant profile the simulator takes (docs/identification.md)."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import List

import typer

from ardrone_nmpc.errors import UserError


class IdentifyFailed(UserError, ValueError):
    """A run that cannot be identified from (one line, exit 1)."""


def identify_command(*, runs: List[Path], output: Path) -> Path:
    from ardrone_nmpc.experiments.identify.data import IdentifyError, read_flight
    from ardrone_nmpc.experiments.identify.profile import identify, write_profile

    try:
        flights = [read_flight(r) for r in runs]
        ident = identify(flights)
    except (IdentifyError, ValueError) as err:
        raise IdentifyFailed(" ".join(str(err).split())) from None
    for line in ident.lines():
        typer.echo(line)
    command = "ardrone-nmpc " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    return write_profile(ident, output, command=command)


def register(app: typer.Typer) -> None:
    """Add the ``identify`` command to ``app``."""
    from ardrone_nmpc.cli.options import output_file

    @app.command()
    def identify(
        runs: List[Path] = typer.Argument(..., help="Run directories of flights to fit (configs/identify.yaml is made for it)."),
        output: Path = typer.Option(..., "-o", "--output", callback=output_file, help="Plant profile to write (YAML): --set sim.plant.profile=FILE flies it."),
    ) -> None:
        """Fit the drone's command delay, attitude response (first-order lag or the kit's
        second order with a zero, by held-out fit), tilt → speed (gain, drag pole), gaz →
        climb rate and yaw rate per unit command from logged PCMD, navdata and mocap; print
        each parameter with its uncertainty and the held-out fit, write the plant profile.
        Last line: profile: <file>."""
        path = identify_command(runs=runs, output=output)
        typer.echo(f"profile: {path}")
