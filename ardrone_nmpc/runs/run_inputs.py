"""The input files of a run directory (docs/design.md): read and checked before the directory
is made, copied into its ``inputs/`` folder, the configs to record and to fly naming the copies
(:meth:`~ardrone_nmpc.runs.rundir.RunRecorder.create`)."""

from __future__ import annotations

from pathlib import Path

from ardrone_nmpc.config.schema import ExperimentConfig
from ardrone_nmpc.reference.trajectories import input_files

__all__ = ["INPUTS_DIR", "copy_inputs", "read_inputs"]

#: Folder of the copied input files, inside the run directory.
INPUTS_DIR = "inputs"


def read_inputs(cfg: ExperimentConfig) -> dict:
    """The input files ``cfg`` names, read and checked: ``{field: WaypointFile}``."""
    return input_files(cfg.reference)


def copy_inputs(path: Path, cfg: ExperimentConfig, inputs: dict
                ) -> tuple[ExperimentConfig, ExperimentConfig, str]:
    """Write each input into ``path/inputs/``. Returns the config to record (inputs named
    relative to the run directory), the config to fly (the copies' absolute paths) and the
    header lines saying where each copy came from."""
    if not inputs:
        return cfg, cfg, ""
    (path / INPUTS_DIR).mkdir()
    relative, absolute, origins = {}, {}, ""
    for name, source in inputs.items():
        target = path / INPUTS_DIR / source.path.name
        target.write_bytes(source.raw)
        relative[name] = f"{INPUTS_DIR}/{source.path.name}"
        absolute[name] = str(target.resolve())
        origins += f"\nreference.{name}: copied from {source.path}"
    ref = cfg.reference
    recorded = cfg.model_copy(update={"reference": ref.model_copy(update=relative)})
    flown = cfg.model_copy(update={"reference": ref.model_copy(update=absolute)})
    return recorded, flown, origins
