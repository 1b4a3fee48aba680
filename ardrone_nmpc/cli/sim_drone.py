"""``ardrone-nmpc sim-drone``: the loopback drone and mocap streamer until Ctrl-C."""

from __future__ import annotations

from pathlib import Path

import typer

from ardrone_nmpc.errors import UserError


class SimDroneUsageError(UserError):
    """An address that is not loopback, or a malformed ``--mocap-to`` (exit 1)."""


def sim_drone_command(*, config: Path | None, overrides: list[str], bind: str, at_port: int,
                      navdata_port: int, control_port: int | None, mocap_to: str,
                      seed: int | None) -> None:
    """Check the addresses, load the config, serve until Ctrl-C (ports in use: OSError)."""
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.sim.drone_server import require_loopback_host
    from ardrone_nmpc.sim.serve import parse_host_port, serve

    try:  # loopback only: the simulator never answers on a real network
        require_loopback_host(bind, "--bind")
        parse_host_port(mocap_to, what="--mocap-to")
    except ValueError as err:
        raise SimDroneUsageError(str(err)) from None
    cfg = load_config(config, overrides)
    serve(cfg=cfg, bind=bind, at_port=at_port, navdata_port=navdata_port, mocap_to=mocap_to,
          seed=seed, control_port=control_port, echo=typer.echo)
