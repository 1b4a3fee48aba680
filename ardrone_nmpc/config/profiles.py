"""What a plant profile sets outside ``sim.plant``: the rest of an experiment flown "as the
thesis' simulator was" (docs/plant-profiles.md §2).

``sim.plant.profile`` fills the ``sim.plant`` keys a config leaves out
(:data:`~ardrone_nmpc.config.sim.PLANT_PROFILE_DEFAULTS`). The ``thesis_kit`` profile also
stands for how the thesis drove its simulator, the ARDrone Simulink Development Kit: the kit's
command convention, its noise-free outputs, its Baseline Controller's gains, and a supervisor
whose tilt limit fits that plant. :func:`fill_profile_defaults` fills those keys too, only
where the config leaves them out: a key set in the YAML or with ``--set`` always wins.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

__all__ = ["PROFILE_SECTION_DEFAULTS", "fill_profile_defaults"]

#: Per profile, the keys of other sections it fills where the config leaves them out.
PROFILE_SECTION_DEFAULTS: dict[str, dict[str, Any]] = {
    "thesis_kit": {
        # the kit's Baseline Controller wires rad, m/s, rad/s straight into the simulation
        # block's ports, which saturate at ±1 (ARBlocks.slx): the NMPC's bounds are ±1 as
        # thesis eq. 4.17; drone.euler_angle_max_rad & co. still bound a real drone
        "drone": {"command_convention": "kit"},
        # the kit's Baseline Controller (ARBlocks.slx): height 1, lateral 0.4, forward 0.5
        # (−0.5 in the kit's nose-up pitch sign), heading 1.5; position → speed 1 is eq. 4.16's
        "controller": {"p_gains": {"k1_per_s": 1.0, "k2_rad_per_mps": 0.4,
                                   "k3_rad_per_mps": 0.5, "k4_per_s": 1.5}},
        # the kit's simulation block outputs its states without noise or latency
        "sim": {"noise": {"mocap_position_std_m": 0.0, "mocap_angle_std_rad": 0.0,
                          "mocap_latency_ms": 0.0, "navdata_attitude_std_rad": 0.0,
                          "navdata_yaw_std_rad": 0.0, "navdata_altitude_std_m": 0.0,
                          "navdata_velocity_std_mps": 0.0}},
        # commanded tilt is clipped to max_tilt_rad in the command's own units, here the
        # port's: 1 is the port's saturation. The kit cannot tilt beyond 0.86 rad with its
        # ports within ±1 (the L1 norm of ssPitch's impulse response), so the measured-tilt
        # check stays as the catch for a broken plant. Only under the kit's convention
        # (KIT_UNITS): under the SDK's the firmware's 0.52 rad caps it (config/schema.py)
        "safety": {"max_tilt_rad": 1.0},
    },
}


#: Keys a profile fills only where the config flies the kit's command convention: they are in
#: the kit's port units (the schema bounds them by the firmware otherwise).
KIT_UNITS: tuple[tuple[str, str], ...] = (("safety", "max_tilt_rad"),)


def _fill(data: dict, defaults: Mapping) -> None:
    """Set every key of ``defaults`` that ``data`` lacks, recursing into mappings (in place)."""
    for key, value in defaults.items():
        if isinstance(value, Mapping):
            child = data.get(key)
            if child is None:
                data[key] = child = {}
            if isinstance(child, dict):  # anything else is reported by the schema
                _fill(child, value)
        elif key not in data:
            data[key] = copy.deepcopy(value)


def fill_profile_defaults(data: Any) -> Any:
    """``data`` (a raw experiment mapping) with the keys its plant profile sets filled in."""
    if not isinstance(data, Mapping):
        return data
    sim = data.get("sim")
    plant = sim.get("plant") if isinstance(sim, Mapping) else None
    profile = plant.get("profile") if isinstance(plant, Mapping) else None
    defaults = PROFILE_SECTION_DEFAULTS.get(profile) if isinstance(profile, str) else None
    if not defaults:
        return data
    filled = copy.deepcopy(dict(data))
    _fill(filled, defaults)
    drone = filled.get("drone")
    if isinstance(drone, Mapping) and drone.get("command_convention") != "kit":
        for section, key in KIT_UNITS:  # the profile's value, not the config's: dropped
            given = data.get(section)
            if not (isinstance(given, Mapping) and key in given) and isinstance(
                    filled.get(section), dict):
                filled[section].pop(key, None)
    return filled
