"""Physics backends chosen by name: the plant class of a ``sim.plant.profile``
(docs/plant-profiles.md). Apart from the plants so that neither imports the other."""

from __future__ import annotations

from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.sim.plant_kit import KitPlant

__all__ = ["make_plant", "plant_backend"]


def plant_backend(profile: str) -> type[AirframePlant]:
    """The kit's linear identified channels for ``thesis_kit``, :class:`AirframePlant` for the
    ``ardrone`` profiles and a profile file (its values are in the config already:
    :mod:`ardrone_nmpc.config.io` fills them in)."""
    if profile == "thesis_kit":
        return KitPlant
    if profile.startswith("ardrone") or profile.lower().endswith((".yaml", ".yml")):
        return AirframePlant
    raise ValueError(f"unknown plant profile {profile!r}")


def make_plant(sim_cfg, drone_cfg, *, seed: int | None = None) -> AirframePlant:
    """The plant of an experiment's ``sim`` and ``drone`` sections (seeded by ``seed``,
    default ``sim.seed``), of the backend ``sim.plant.profile`` names."""
    backend = plant_backend(sim_cfg.plant.profile)
    return backend.from_config(sim_cfg, drone_cfg, seed=seed)
