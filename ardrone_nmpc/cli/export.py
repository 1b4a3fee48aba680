"""``ardrone-nmpc export RUN --format mcap|parquet [-o FILE] [--force]``: a run as one file for
Foxglove, PlotJuggler, the ``mcap`` CLI or a data frame (:mod:`ardrone_nmpc.experiments.export`).

The output never lands inside a run directory and never replaces a file unless ``--force``
says so (and then only a regular file); it is written beside its name and renamed into place,
so an export that fails or is interrupted leaves nothing under that name.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ardrone_nmpc.cli.options import choice

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add the ``export`` command to ``app``."""

    @app.command("export")
    def export(
        run_dir: Path = typer.Argument(..., help="A run directory (logs/<run>)."),
        fmt: str = typer.Option("mcap", "--format", **choice(("mcap", "parquet")), help="mcap (the 'mcap' extra): /log, /events, /config, /pose, /reference, /tf channels; parquet (the 'parquet' extra): the log table, events and config in its metadata."),
        output: Optional[Path] = typer.Option(None, "-o", "--output", help="Output file (default: <run dir>.<format> beside the run directory); never inside a run directory."),
        force: bool = typer.Option(False, "--force", help="Replace an existing output file (a previous export)."),
    ) -> None:
        """Export a run directory as MCAP (Foxglove's 3-D panel draws /pose and /reference)
        or Parquet. Last line: export: <file>."""
        from ardrone_nmpc.cli.console import run_notes
        from ardrone_nmpc.experiments.export import default_output, export_run, require_format
        from ardrone_nmpc.runs.outputs import check_output_file
        from ardrone_nmpc.runs.rundir import read_run

        require_format(fmt)
        run = read_run(run_dir)
        out = output if output is not None else default_output(run_dir, fmt)
        check_output_file(out, option="-o", force=force)
        run_notes(run)
        report = export_run(run_dir, fmt, out, run=run)
        typer.echo(report)
        typer.echo(f"export: {out}")
