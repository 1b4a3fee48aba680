"""Physics backends chosen by name: the plant class of a ``sim.plant.profile``
(docs/plant-profiles.md). Apart from the plants so that neither imports the other."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.sim.plant_kit import KitPlant

__all__ = ["Airframe", "make_plant", "plant_backend"]


@runtime_checkable
class Airframe(Protocol):
    """What the simulated drone (its firmware, sensors and faults) reads and drives of a plant:
    any airframe with these members flies behind :class:`~ardrone_nmpc.sim.drone.SimulatedDrone`
    (``run_lockstep(cfg, plant=...)``). Times in s, positions in m, angles in rad."""

    # The limits the firmware holds (euler_angle_max_rad, control_vz_max_mps, …); optional
    # command_delay_s and tau_vz_s: the simulated firmware sits before the plant's command
    # delay (the real one inside it), so its altitude cap leads by them (0 when absent), and
    # integration_step_s: how often a climb near the cap is checked (else 5 ms).
    params: object
    wind_mps: object      # steady wind (x, y[, z]) in the world frame

    @property
    def t_s(self) -> float: ...
    @property
    def mode(self): ...
    @property
    def battery_pct(self) -> float: ...
    @property
    def truth(self): ...
    @property
    def altitude_m_and_rate_mps(self) -> tuple[float, float]: ...

    def command(self, roll, pitch, gaz, yaw, **flags): ...
    def advance(self, dt_s: float) -> None: ...
    def takeoff(self) -> bool: ...
    def land(self) -> bool: ...
    def emergency(self) -> bool: ...
    def mocap_pose(self): ...
    def navdata(self): ...


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
