"""``ardrone-nmpc check``: validate a config and the files it names; print the resolved values.

It rejects what a run would: the reference is built, so a waypoint file is read and checked
exactly as ``simulate`` and ``fly`` read it before they create a run directory, and a
reference that leaves the geofence is refused as they refuse it.
"""

from __future__ import annotations

from pathlib import Path

import typer


def run_check(*, config: Path, overrides: list[str]) -> None:
    """Print the resolved config as YAML; a ConfigError or ReferenceError otherwise."""
    from ardrone_nmpc.config.io import dump_config, load_config
    from ardrone_nmpc.reference.experiment import experiment_trajectory

    cfg = load_config(config, overrides)
    experiment_trajectory(cfg)
    typer.echo(dump_config(cfg), nl=False)
