"""The simulated drone's configuration: what ``AT*CONFIG`` writes, what the drone applies to
the plant, and the text it sends on the control port (docs/protocol.md, configuration).

Applied keys: ``control:euler_angle_max`` (rad, clamped to 0.52), ``control:control_vz_max``
(mm/s, clamped to 200–2000), ``control:control_yaw`` (rad/s, clamped to 0.7–6.11) replace the
plant's params; ``control:altitude_max`` (mm) sets the altitude cap; ``general:navdata_demo``
leaves bootstrap (TRUE demo packets, FALSE full rate); ``general:navdata_options`` selects the
options. Any other key, and a value that does not parse, is stored but changes nothing. The
clamps keep a hostile value ("1e300") from driving the plant where no navdata int32 reaches.

Indoor and outdoor profiles (config_keys.h: ``control:outdoor`` and the ``indoor_*`` /
``outdoor_*`` triples): the drone keeps one stored triple of the three limits per profile;
``control:outdoor`` selects which one it flies (writing it loads that triple), and a write of
a limit key stores it into the active profile. A drone last flown outdoors
(:class:`OutdoorProfiles`) starts with ``outdoor`` TRUE — so limits written before
``control:outdoor FALSE`` land in (and overwrite) its outdoor profile, and the indoor triple
loaded afterwards is not what was written.

Multiconfiguration: a drone left in another application's session (:class:`HeldSession`)
acknowledges every ``AT*CONFIG`` (unless the session ignores plain CONFIG: then a write without
the session's ids is not acknowledged at all — ARDroneLib's ``ardrone_at_mutex.c`` as
docs/protocol.md §3.3 reads it; the SDK stand-in of the tests does the same). Keys every session shares (ARDroneLib ``config_keys.h``
category CAT_COMMON: ``general:navdata_demo``, ``control:altitude_max``, ``control:outdoor`` …)
apply; a per-session key (CAT_APPLI, CAT_USER, CAT_SESSION: the three command limits,
``general:navdata_options``, ``control:flying_mode`` …) applies only when the ``AT*CONFIG_IDS``
right before it (same datagram, as the SDK sends them) carries that session's three ids.
``custom:session_id`` / ``profile_id`` / ``application_id`` switch ids and always apply (the SDK
sends them with the ids it switches to). The exact firmware rule is not documented; this is
the reading of docs/protocol.md (multiconfiguration). The dump reports what the drone holds:
the plant's limits, the active ids.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ardrone_nmpc.protocol.config_text import EULER_ANGLE_MAX_LIMIT_RAD, format_config_text
from ardrone_nmpc.protocol.navdata import DEFAULT_NAVDATA_OPTIONS

__all__ = ["ConfigStore", "HeldSession", "OutdoorProfiles", "apply_limits", "limit_change",
           "EULER_ANGLE_MAX_LIMIT_RAD", "DEFAULT_CONFIG_ID"]

CONTROL_VZ_MAX_RANGE_MMPS = (200.0, 2000.0)   # recommended ranges of the other two limits
CONTROL_YAW_RANGE_RADPS = (0.7, 6.11)
DEFAULT_CONFIG_ID = "00000000"            # the default session, profile and application
_LIMIT_KEYS = ("control:euler_angle_max", "control:control_vz_max", "control:control_yaw")
_ID_KEYS = ("custom:session_id", "custom:profile_id", "custom:application_id")
#: config_keys.h defaults of the outdoor triple (20°, 1000 mm/s, 200°/s).
OUTDOOR_DEFAULTS = ("0.3491", "1000", "3.491")
#: Keys of the per-session categories (CAT_APPLI, CAT_USER, CAT_SESSION in config_keys.h).
SESSION_KEYS = frozenset({
    "general:navdata_options", "control:control_level", "control:euler_angle_max",
    "control:control_iphone_tilt", "control:control_vz_max", "control:control_yaw",
    "control:manual_trim", "control:indoor_euler_angle_max", "control:indoor_control_vz_max",
    "control:indoor_control_yaw", "control:outdoor_euler_angle_max",
    "control:outdoor_control_vz_max", "control:outdoor_control_yaw", "control:flying_mode",
    "control:hovering_range", "video:codec_fps", "video:video_codec", "video:video_slices",
    "video:video_live_socket", "video:bitrate", "video:max_bitrate", "video:bitrate_ctrl_mode",
    "video:bitrate_storage", "video:video_channel", "detect:groundstripe_colors",
    "detect:detect_type", "detect:detections_select_h", "detect:detections_select_v_hsync",
    "detect:detections_select_v", "userbox:userbox_cmd", "gps:latitude", "gps:longitude",
    "gps:altitude", "custom:application_desc", "custom:profile_desc", "custom:session_desc"})


def _triple(euler_angle_max_rad: float, control_vz_max_mps: float,
            control_yaw_radps: float) -> dict[str, str]:
    """The three limit keys as wire texts (rad, mm/s, rad/s)."""
    return dict(zip(_LIMIT_KEYS, (repr(euler_angle_max_rad), repr(control_vz_max_mps * 1000.0),
                                  repr(control_yaw_radps))))


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


def apply_limits(plant, values: dict[str, str]) -> None:
    """Apply the limit keys among ``values`` (key → value text) to ``plant``'s params."""
    for key, value in values.items():
        change = limit_change(key, value)
        if change is None:
            continue
        try:
            plant.params = plant.params.replace(**change)
        except (ValueError, TypeError, AttributeError):   # keep the old params
            pass


@dataclass(frozen=True)
class HeldSession:
    """A multiconfig session the drone is in (not the client's) and the limits it holds there.

    ``ids`` are (session, profile, application), 8 hex digits each, not all "00000000".
    """

    ids: tuple[str, str, str]
    euler_angle_max_rad: float = EULER_ANGLE_MAX_LIMIT_RAD
    control_vz_max_mps: float = CONTROL_VZ_MAX_RANGE_MMPS[1] / 1000.0
    control_yaw_radps: float = CONTROL_YAW_RANGE_RADPS[1]
    ignores_plain_config: bool = False  # no ACK for a CONFIG without the session's ids

    def __post_init__(self) -> None:
        ids = tuple(str(i) for i in self.ids)
        if len(ids) != 3 or ids == (DEFAULT_CONFIG_ID,) * 3:
            raise ValueError(f"a held session needs 3 ids, not all {DEFAULT_CONFIG_ID}: {ids}")
        object.__setattr__(self, "ids", ids)

    @classmethod
    def of_fault(cls, fault) -> HeldSession:
        """From a :class:`~ardrone_nmpc.config.faults.ForeignSessionFault`."""
        return cls((fault.session_id, fault.profile_id, fault.application_id),
                   fault.euler_angle_max_rad, fault.control_vz_max_mps, fault.control_yaw_radps,
                   fault.ignores_plain_config)

    def limits(self) -> dict[str, str]:
        """The held limits as config key → value text (the wire's units: rad, mm/s, rad/s)."""
        return _triple(self.euler_angle_max_rad, self.control_vz_max_mps,
                       self.control_yaw_radps)


@dataclass(frozen=True)
class OutdoorProfiles:
    """The stored profiles of a drone last flown outdoors (``control:outdoor`` TRUE): each a
    (tilt rad, climb m/s, yaw rate rad/s) triple."""

    indoor: tuple[float, float, float]
    outdoor: tuple[float, float, float]

    @classmethod
    def of_fault(cls, fault) -> OutdoorProfiles:
        """From an :class:`~ardrone_nmpc.config.faults.OutdoorProfileFault`."""
        return cls((fault.indoor_euler_angle_max_rad, fault.indoor_control_vz_max_mps,
                    fault.indoor_control_yaw_radps),
                   (fault.euler_angle_max_rad, fault.control_vz_max_mps,
                    fault.control_yaw_radps))


class ConfigStore:
    """The configuration of one simulated drone (use under the drone's lock).

    Attributes
    ----------
    written : key → value text of every applied ``AT*CONFIG``.
    config_ids : the last ``AT*CONFIG_IDS`` (session, profile, application).
    active_ids : the session, profile and application the drone is in.
    ignored : key → value text of the writes acknowledged but not applied (another session).
    outdoor : the active profile is the outdoor one (``control:outdoor``).
    profiles : the stored limit triple (key → value text) of each profile, by ``outdoor``.
    bootstrap : True until ``general:navdata_demo`` is written (again after a link loss).
    demo : demo packets (False: full rate).
    navdata_options : the ``general:navdata_options`` mask.
    altitude_max_m : the altitude cap (m).
    """

    def __init__(self, plant, *, altitude_max_m: float, session: HeldSession | None = None,
                 outdoor: OutdoorProfiles | None = None) -> None:
        self.plant = plant
        self.written: dict[str, str] = {}
        self.ignored: dict[str, str] = {}
        self.config_ids: tuple[str, str, str] = (DEFAULT_CONFIG_ID,) * 3
        self.active_ids: tuple[str, str, str] = (DEFAULT_CONFIG_ID,) * 3
        self.session = session
        if session is not None:
            self.active_ids = session.ids
            self.apply_limits(session.limits())
        p = plant.params
        self.outdoor = outdoor is not None
        self.profiles = {False: _triple(p.euler_angle_max_rad, p.control_vz_max_mps,
                                        p.control_yaw_radps),
                         True: dict(zip(_LIMIT_KEYS, OUTDOOR_DEFAULTS))}
        if outdoor is not None:
            self.profiles = {False: _triple(*outdoor.indoor), True: _triple(*outdoor.outdoor)}
            self.apply_limits(self.profiles[True])
        self.bootstrap = True
        self.demo = True
        self.navdata_options = DEFAULT_NAVDATA_OPTIONS
        self.altitude_max_m = float(altitude_max_m)

    @property
    def multiconfig(self) -> bool:
        """The drone is in a session other than the default one."""
        return self.active_ids != (DEFAULT_CONFIG_ID,) * 3

    def acknowledges(self, key: str, ids: tuple[str, str, str] | None) -> bool:
        """Whether an ``AT*CONFIG`` of ``key`` (``ids``: those of the ``AT*CONFIG_IDS`` right
        before it) is acknowledged at all: not by a session that ignores plain CONFIG, unless
        it carries the session's ids (the id keys themselves always are)."""
        return not (self.session is not None and self.session.ignores_plain_config
                    and self.multiconfig and key not in _ID_KEYS and ids != self.active_ids)

    def write(self, key: str, value: str, ids: tuple[str, str, str] | None = None) -> bool:
        """One ``AT*CONFIG``; ``ids`` those of the ``AT*CONFIG_IDS`` right before it, if any.
        Returns whether it was applied (either way the drone acknowledges it)."""
        if key in _ID_KEYS:
            if not value.startswith("-"):   # "-<id>" / "-all" delete sessions: not modelled
                i = _ID_KEYS.index(key)
                self.active_ids = (*self.active_ids[:i], value, *self.active_ids[i + 1:])
        elif key in SESSION_KEYS and self.multiconfig and ids != self.active_ids:
            self.ignored[key] = value
            return False
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
        elif key == "control:outdoor":
            self._select_profile(_parse_bool(value))
        else:
            self._store_in_profile(key, value)
        return True

    def _select_profile(self, outdoor: bool) -> None:
        """``control:outdoor``: fly the stored triple of that profile."""
        if outdoor != self.outdoor:
            self.outdoor = outdoor
            self.apply_limits(self.profiles[outdoor])

    def _store_in_profile(self, key: str, value: str) -> None:
        """A limit key goes into the active profile (and flies); an ``indoor_*`` /
        ``outdoor_*`` key into its own profile (flying only if that one is active)."""
        profile, base = self.outdoor, key
        for outdoor, prefix in ((False, "control:indoor_"), (True, "control:outdoor_")):
            if key.startswith(prefix):
                profile, base = outdoor, "control:" + key[len(prefix):]
        if base not in _LIMIT_KEYS:
            return
        self.profiles[profile][base] = value
        if profile == self.outdoor:
            self.apply_limits({base: value})

    def apply_limits(self, values: dict[str, str]) -> None:
        """Apply the limit keys among ``values`` to the plant (others are ignored)."""
        apply_limits(self.plant, values)

    def held(self) -> dict[str, str]:
        """The values the drone flies with, as the dump reports them whatever text was
        written (clamped limits, writes of another session)."""
        p = self.plant.params
        return {
            "general:navdata_demo": "TRUE" if self.demo else "FALSE",
            "general:navdata_options": str(self.navdata_options),
            "control:euler_angle_max": f"{p.euler_angle_max_rad:.4f}",
            "control:altitude_max": str(int(round(self.altitude_max_m * 1000))),
            "control:control_vz_max": f"{p.control_vz_max_mps * 1000:.1f}",
            "control:control_yaw": f"{p.control_yaw_radps:.4f}",
            "custom:session_id": self.active_ids[0],
            "custom:profile_id": self.active_ids[1],
            "custom:application_id": self.active_ids[2],
            "control:outdoor": "TRUE" if self.outdoor else "FALSE",
            **{f"control:{prefix}{key[8:]}": text
               for outdoor, prefix in ((False, "indoor_"), (True, "outdoor_"))
               for key, text in self.profiles[outdoor].items()},
        }

    def text(self) -> str:
        """The configuration dump: ``section:key = value`` lines (the NUL is the port's)."""
        values = {
            "general:num_version_soft": "2.4.8",
            "general:com_watchdog": "2",
            "general:vbat_min": "9000",
            "control:altitude_min": "50",
            "control:outdoor": "FALSE",
            "control:flight_without_shell": "FALSE",
            "control:flying_mode": "0",
            "video:video_codec": "129",
            "video:video_channel": "0",
        }
        values.update(self.written)
        values.update(self.held())
        return format_config_text(values)
