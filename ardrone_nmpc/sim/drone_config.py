"""The simulated drone's configuration: what ``AT*CONFIG`` writes, what the drone applies to
the plant, and the text it sends on the control port (docs/protocol.md, configuration).

Applied keys: ``control:euler_angle_max`` (rad, clamped to 0.52), ``control:control_vz_max``
(mm/s, clamped to 200–2000), ``control:control_yaw`` (rad/s, clamped to 0.7–6.11) replace the
plant's params; ``control:altitude_max`` (mm) sets the altitude cap; ``general:navdata_demo``
leaves bootstrap (TRUE demo packets, FALSE full rate); ``general:navdata_options`` selects the
options. Any other key, and a value that does not parse, is stored but changes nothing. The
clamps keep a hostile value ("1e300") from driving the plant where no navdata int32 reaches.
"""

from __future__ import annotations

import math

from ardrone_nmpc.protocol.navdata import DEFAULT_NAVDATA_OPTIONS

__all__ = ["ConfigStore", "EULER_ANGLE_MAX_LIMIT_RAD", "DEFAULT_CONFIG_ID"]

EULER_ANGLE_MAX_LIMIT_RAD = 0.52          # dev guide range of control:euler_angle_max
CONTROL_VZ_MAX_RANGE_MMPS = (200.0, 2000.0)   # recommended ranges of the other two limits
CONTROL_YAW_RANGE_RADPS = (0.7, 6.11)
DEFAULT_CONFIG_ID = "00000000"            # the default session, profile and application
_LIMIT_KEYS = ("control:euler_angle_max", "control:control_vz_max", "control:control_yaw")


def _parse_bool(text: str) -> bool:
    return text.strip().upper() in ("TRUE", "1", "YES", "ON")


def _parse_float(text: str) -> float | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def limit_change(key: str, value: str) -> dict | None:
    """The :class:`~ardrone_nmpc.sim.plant.PlantParams` change one limit key asks for (the
    value clamped to its range), or None if the key is no limit or the value does not parse."""
    v = _parse_float(value) if key in _LIMIT_KEYS else None
    if v is None or v <= 0:
        return None
    if key == "control:euler_angle_max":
        return {"euler_angle_max_rad": min(v, EULER_ANGLE_MAX_LIMIT_RAD)}
    if key == "control:control_vz_max":
        lo, hi = CONTROL_VZ_MAX_RANGE_MMPS
        return {"control_vz_max_mps": min(max(v, lo), hi) / 1000.0}
    lo, hi = CONTROL_YAW_RANGE_RADPS
    return {"control_yaw_radps": min(max(v, lo), hi)}


class ConfigStore:
    """The configuration of one simulated drone (use under the drone's lock).

    Attributes
    ----------
    written : key → value text of every applied ``AT*CONFIG``.
    config_ids : the last ``AT*CONFIG_IDS`` (session, profile, application).
    bootstrap : True until ``general:navdata_demo`` is written.
    demo : demo packets (False: full rate).
    navdata_options : the ``general:navdata_options`` mask.
    altitude_max_m : the altitude cap (m).
    """

    def __init__(self, plant, *, altitude_max_m: float) -> None:
        self.plant = plant
        self.written: dict[str, str] = {}
        self.config_ids: tuple[str, str, str] = (DEFAULT_CONFIG_ID,) * 3
        self.bootstrap = True
        self.demo = True
        self.navdata_options = DEFAULT_NAVDATA_OPTIONS
        self.altitude_max_m = float(altitude_max_m)

    def write(self, key: str, value: str) -> None:
        """Store and apply one ``AT*CONFIG``."""
        self.written[key] = value
        if key == "general:navdata_demo":
            self.bootstrap = False
            self.demo = _parse_bool(value)
        elif key == "general:navdata_options":
            try:
                self.navdata_options = int(value) & 0xFFFFFFFF
            except ValueError:
                pass
        elif key == "control:altitude_max":
            v = _parse_float(value)
            if v is not None and v > 0:
                self.altitude_max_m = v / 1000.0
        else:
            self.apply_limits({key: value})

    def apply_limits(self, values: dict[str, str]) -> None:
        """Apply the limit keys among ``values`` to the plant (others are ignored)."""
        plant = self.plant
        for key, value in values.items():
            change = limit_change(key, value)
            if change is None:
                continue
            try:
                plant.params = plant.params.replace(**change)
            except (ValueError, TypeError, AttributeError):   # keep the old params
                pass

    def text(self) -> str:
        """The configuration dump: ``section:key = value`` lines (the NUL is the port's)."""
        p = self.plant.params
        values = {
            "general:num_version_soft": "2.4.8",
            "general:navdata_demo": "TRUE" if self.demo else "FALSE",
            "general:navdata_options": str(self.navdata_options),
            "general:com_watchdog": "2",
            "general:vbat_min": "9000",
            "control:euler_angle_max": f"{p.euler_angle_max_rad:.4f}",
            "control:altitude_max": str(int(round(self.altitude_max_m * 1000))),
            "control:altitude_min": "50",
            "control:control_vz_max": f"{p.control_vz_max_mps * 1000:.1f}",
            "control:control_yaw": f"{p.control_yaw_radps:.4f}",
            "control:outdoor": "FALSE",
            "control:flight_without_shell": "FALSE",
            "control:flying_mode": "0",
            "video:video_codec": "129",
            "video:video_channel": "0",
            "custom:session_id": self.config_ids[0],
            "custom:profile_id": self.config_ids[1],
            "custom:application_id": self.config_ids[2],
        }
        values.update(self.written)
        values["general:navdata_demo"] = "TRUE" if self.demo else "FALSE"
        return "".join(f"{k} = {v}\n" for k, v in values.items())
