"""``ardrone-nmpc check``: validate a config and the files it names; print the resolved values.

It applies the rules a run applies, in the same functions: the files the config names are
read and checked (a missing one is an error, whatever the reference kind) and the reference
is built, exactly as ``simulate`` and ``fly`` do before they create a run directory; a field
the chosen kind ignores is a warning naming it, from both; a reference that leaves the
geofence is refused as they refuse it.
"""

from __future__ import annotations

from pathlib import Path

import typer


def run_check(*, config: Path, overrides: list[str]) -> None:
    """Print the resolved config as YAML; a ConfigError or ReferenceError otherwise."""
    from ardrone_nmpc.cli.console import config_notes
    from ardrone_nmpc.config.io import dump_config, load_config
    from ardrone_nmpc.reference.experiment import experiment_trajectory
    from ardrone_nmpc.reference.trajectories import input_files

    cfg = load_config(config, overrides)
    config_notes(cfg)
    input_files(cfg.reference)
    experiment_trajectory(cfg)
    typer.echo(dump_config(cfg), nl=False)
