"""``ardrone-nmpc export RUN --format mcap|parquet [-o FILE]``: a run as one file for Foxglove,
PlotJuggler, the ``mcap`` CLI or a data frame (:mod:`ardrone_nmpc.experiments.export`)."""

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
        fmt: str = typer.Option("mcap", "--format", **choice(("mcap", "parquet")), help="mcap (the 'mcap' extra): /log, /events, /config, /pose, /reference channels; parquet (the 'parquet' extra): the log table, events and config in its metadata."),
        output: Optional[Path] = typer.Option(None, "-o", "--output", help="Output file (default: <run dir>.<format> beside the run directory)."),
    ) -> None:
        """Export a run directory as MCAP (Foxglove's 3-D panel draws /pose and /reference)
        or Parquet. Last line: export: <file>."""
        from ardrone_nmpc.core.extras import MissingExtra
        from ardrone_nmpc.experiments.export import ExportError, export_run
        from ardrone_nmpc.runs.rundir import LogError

        out = output if output is not None else run_dir.with_name(f"{run_dir.name}.{fmt}")
        try:
            report = export_run(run_dir, fmt, out)
        except (ExportError, MissingExtra, LogError, OSError) as err:
            typer.echo(f"error: {err}", err=True)
            raise typer.Exit(code=1)
        typer.echo(report)
        typer.echo(f"export: {out}")
