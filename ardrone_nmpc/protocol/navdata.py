"""AR.Drone 2.0 navdata (UDP 5554, drone → client): encoder (simulator) and decoder (client).

docs/protocol.md (navdata). A packet is a 16-byte header (magic, state bits, sequence, vision
flag), then options ``u16 tag, u16 size, payload`` (``size`` includes the 4-byte head) in
ascending tag order, then the checksum option (tag 0xFFFF, size 8, ``u32`` = unsigned 32-bit
sum of every byte before it). Little-endian throughout; at most 4096 bytes.

Decoding walks the options by their size: the demo option (tag 0) is decoded into
:class:`DemoOption`, any other option is kept raw as :class:`NavdataOption` (so unknown tags of
newer firmware are skipped, not rejected), and the walk stops at the checksum option, which is
required and verified. Size 0 (or < 4), overrunning options, a second demo option, a bad magic
and a bad or missing checksum raise :class:`NavdataError`, the only exception the decoder
raises. Bytes after the checksum option are ignored.

Sign conventions of the demo option (inferred from ardrone_autonomy, which negates
theta, psi, vy and vz to get ROS frames): body frame x forward, y right, z down; theta > 0 nose
up, phi > 0 right wing down, psi > 0 **clockwise** seen from above; vx, vy, vz are body-frame
speeds (vy > 0 to the right, vz > 0 down). The records keep the wire units in their raw fields
(``theta_mdeg``, ``altitude_mm`` …) and convert at the boundary in properties (``pitch_deg``,
``altitude_m`` …); signs are never changed here.

Every simulated drone builds its packets with :func:`encode_drone_navdata` from a
:class:`DroneStatus` (what the drone knows about itself: flight phase, command, link), so the
state bits and the ctrl_state codes of a flight state are written in one place;
:func:`drone_navdata` builds a lockstep tick's packet without the per-field checks (theirs).
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass, fields

__all__ = [
    "NAVDATA_PORT", "NAVDATA_WAKEUP", "NAVDATA_MAGIC", "NAVDATA_MAGIC_ALT", "NAVDATA_MAX_BYTES",
    "HEADER_FORMAT", "HEADER_BYTES", "OPTION_HEAD_FORMAT", "OPTION_HEAD_BYTES",
    "CHECKSUM_TAG", "CHECKSUM_FORMAT", "CHECKSUM_SIZE", "DEMO_TAG", "DEMO_FORMAT", "DEMO_SIZE",
    "VISION_DETECT_TAG", "VISION_DETECT_SIZE", "NavdataError", "DroneState", "OptionTag",
    "CtrlMajor", "ctrl_state_value", "DemoOption", "NavdataOption", "Navdata",
    "navdata_checksum", "empty_vision_detect_option", "encode_navdata", "decode_navdata",
    "CtrlCodes", "DRONE_PHASES", "DroneStatus", "ALWAYS_ON_STATE", "DEFAULT_NAVDATA_OPTIONS",
    "time_option", "encode_drone_navdata", "drone_navdata",
]

NAVDATA_PORT = 5554
NAVDATA_WAKEUP = b"\x01\x00\x00\x00"       # int32 1: "start streaming, unicast"
NAVDATA_MAGIC = 0x55667788
NAVDATA_MAGIC_ALT = 0x55667789             # accepted by node-ar-drone/afParrotSdk2; meaning unknown
NAVDATA_MAX_BYTES = 4096

HEADER_FORMAT = "<IIIi"                    # magic, state, sequence, vision_defined
HEADER_BYTES = struct.calcsize(HEADER_FORMAT)             # 16
OPTION_HEAD_FORMAT = "<HH"                 # tag, size (size includes these 4 bytes)
OPTION_HEAD_BYTES = struct.calcsize(OPTION_HEAD_FORMAT)   # 4
CHECKSUM_TAG = 0xFFFF
CHECKSUM_FORMAT = "<HHI"                   # tag, size, cks
CHECKSUM_SIZE = struct.calcsize(CHECKSUM_FORMAT)          # 8
DEMO_TAG = 0
DEMO_FORMAT = "<HHIIfffifffI9f3fII9f3f"
DEMO_SIZE = struct.calcsize(DEMO_FORMAT)                  # 148
VISION_DETECT_TAG = 16
VISION_DETECT_SIZE = 328

_U32_MAX = 2**32 - 1
_I32_MIN, _I32_MAX = -(2**31), 2**31 - 1
_HEADER = struct.Struct(HEADER_FORMAT)
_OPTION_HEAD = struct.Struct(OPTION_HEAD_FORMAT)
_CHECKSUM = struct.Struct(CHECKSUM_FORMAT)
_DEMO = struct.Struct(DEMO_FORMAT)
_F32 = struct.Struct("<f")
_F32X6 = struct.Struct("<6f")  # DemoOption.of_sample's six floats, rounded in one go


class NavdataError(ValueError):
    """A malformed navdata packet (the only exception the decoder raises)."""


class DroneState(enum.IntFlag):
    """Drone state bits of the header (``def_ardrone_state_mask_t``)."""

    FLY = 1 << 0                   # flying (0 = landed)
    VIDEO = 1 << 1
    VISION = 1 << 2
    CONTROL = 1 << 3               # 0 euler-angle control, 1 angular-speed control
    ALTITUDE = 1 << 4              # altitude control active
    USER_FEEDBACK_START = 1 << 5   # REF bit 9 (start button) state
    COMMAND = 1 << 6               # control-command ACK (config ACK)
    CAMERA = 1 << 7
    TRAVELLING = 1 << 8
    USB = 1 << 9
    NAVDATA_DEMO = 1 << 10         # only demo navdata is sent
    NAVDATA_BOOTSTRAP = 1 << 11    # no options sent (bootstrap)
    MOTORS = 1 << 12               # motor problem
    COM_LOST = 1 << 13
    SOFTWARE_FAULT = 1 << 14
    VBAT_LOW = 1 << 15
    USER_EL = 1 << 16              # user emergency landing
    TIMER_ELAPSED = 1 << 17
    MAGNETO_NEEDS_CALIB = 1 << 18
    ANGLES_OUT_OF_RANGE = 1 << 19
    WIND = 1 << 20
    ULTRASOUND = 1 << 21           # ultrasound sensor deaf
    CUTOUT = 1 << 22               # motor cut-out detected
    PIC_VERSION = 1 << 23
    ATCODEC_THREAD_ON = 1 << 24
    NAVDATA_THREAD_ON = 1 << 25
    VIDEO_THREAD_ON = 1 << 26
    ACQ_THREAD_ON = 1 << 27
    CTRL_WATCHDOG = 1 << 28        # control loop late
    ADC_WATCHDOG = 1 << 29         # nav-board UART late
    COM_WATCHDOG = 1 << 30         # no client traffic recently
    EMERGENCY = 1 << 31
    # Aliases with descriptive names.
    FLYING = FLY
    COMMAND_ACK = COMMAND
    LOW_BATTERY = VBAT_LOW


class OptionTag(enum.IntEnum):
    """Option tags (``navdata_keys.h``); 27 is GPS on firmware 2.4.x."""

    DEMO = 0
    TIME = 1
    RAW_MEASURES = 2
    PHYS_MEASURES = 3
    GYROS_OFFSETS = 4
    EULER_ANGLES = 5
    REFERENCES = 6
    TRIMS = 7
    RC_REFERENCES = 8
    PWM = 9
    ALTITUDE = 10
    VISION_RAW = 11
    VISION_OF = 12
    VISION = 13
    VISION_PERF = 14
    TRACKERS_SEND = 15
    VISION_DETECT = 16
    WATCHDOG = 17
    ADC_DATA_FRAME = 18
    VIDEO_STREAM = 19
    GAMES = 20
    PRESSURE_RAW = 21
    MAGNETO = 22
    WIND_SPEED = 23
    KALMAN_PRESSURE = 24
    HDVIDEO_STREAM = 25
    WIFI = 26
    ZIMMU_3000_OR_GPS = 27
    CHECKSUM = 0xFFFF


class CtrlMajor(enum.IntEnum):
    """Major ctrl_state (upper 16 bits, ``control_states.h``). Real 2.x firmware reports
    7 during take-off and 9 during landing; rely on state bit 0 for airborne/landed."""

    DEFAULT = 0
    INIT = 1
    LANDED = 2
    FLYING = 3
    HOVERING = 4
    TEST = 5
    TRANS_TAKEOFF = 6
    TRANS_GOTOFIX = 7
    TRANS_LANDING = 8
    TRANS_LOOPING = 9


def ctrl_state_value(major: int, minor: int = 0) -> int:
    """``major << 16 | minor`` (both 0 … 65535)."""
    if not (0 <= major <= 0xFFFF and 0 <= minor <= 0xFFFF):
        raise ValueError(f"major/minor must be u16, got {major}/{minor}")
    return (int(major) << 16) | int(minor)


# Minor ctrl_states a simulated drone reports (control_states.h FLYING_STATES, HOVERING_STATES).
FLYING_ALT_OUT_ZONE = 3
HOVERING_ALT_OUT_ZONE = 4
HOVERING_LOST_COM = 8


class CtrlCodes(enum.Enum):
    """The major codes a drone reports during its two automatic transitions.

    ``SDK``: ``control_states.h`` — take-off 6 (CTRL_TRANS_TAKEOFF), landing 8
    (CTRL_TRANS_LANDING). ``FIRMWARE_2_4``: what 2.4.x firmware is reported to send — take-off
    7, landing 9 (the header's GOTOFIX and LOOPING; ardrone_autonomy #186, node-ar-drone #132).
    A client must read both (docs/protocol.md, ctrl_state).
    """

    SDK = "sdk"
    FIRMWARE_2_4 = "fw2.4"

    @property
    def takeoff_major(self) -> int:
        return 6 if self is CtrlCodes.SDK else 7

    @property
    def landing_major(self) -> int:
        return 8 if self is CtrlCodes.SDK else 9


def _uint(name: str, v, hi: int = _U32_MAX) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise TypeError(f"{name} must be an int, got {type(v).__name__}")
    if not 0 <= v <= hi:
        raise ValueError(f"{name}={v} outside 0..{hi}")
    return int(v)


def _f32(name: str, v) -> float:
    try:
        return _F32.unpack(_F32.pack(float(v)))[0]
    except OverflowError as exc:
        raise ValueError(f"{name}={v!r} does not fit a float32") from exc


def _f32s(name: str, v, n: int) -> tuple[float, ...]:
    t = tuple(_f32(name, x) for x in v)
    if len(t) != n:
        raise ValueError(f"{name} needs {n} values, got {len(t)}")
    return t


@dataclass(frozen=True, slots=True)
class DemoOption:
    """The demo option (tag 0, 148 bytes), raw wire values with unit-named fields.

    Floats are stored rounded to float32 (the wire type). Converted views: :attr:`pitch_deg`,
    :attr:`roll_deg`, :attr:`yaw_deg`, :attr:`altitude_m`, :attr:`vx_body_mps`,
    :attr:`vy_body_mps`, :attr:`vz_mps`, :attr:`ctrl_major`, :attr:`ctrl_minor`.

    Attributes
    ----------
    ctrl_state : ``major << 16 | minor`` (:class:`CtrlMajor`).
    battery_pct : ``vbat_flying_percentage``, 0–100 %.
    theta_mdeg : pitch (millidegrees), > 0 nose up.
    phi_mdeg : roll (millidegrees), > 0 right wing down.
    psi_mdeg : yaw (millidegrees), −180000…180000, > 0 clockwise seen from above.
    altitude_mm : ultrasound altitude (mm; the SDK header's "cm" is wrong).
    vx_mmps, vy_mmps, vz_mmps : body-frame speeds (mm/s): x forward, y right, z down.
    num_frames : streamed frame index (unused).
    detection_camera_rot, detection_camera_trans, detection_tag_index : deprecated (9, 3, 1).
    detection_camera_type : tag type searched (3 = none).
    drone_camera_rot, drone_camera_trans : 3×3 (row-major) and 3 floats.
    """

    ctrl_state: int = 0
    battery_pct: int = 0
    theta_mdeg: float = 0.0
    phi_mdeg: float = 0.0
    psi_mdeg: float = 0.0
    altitude_mm: int = 0
    vx_mmps: float = 0.0
    vy_mmps: float = 0.0
    vz_mmps: float = 0.0
    num_frames: int = 0
    detection_camera_rot: tuple[float, ...] = (0.0,) * 9
    detection_camera_trans: tuple[float, ...] = (0.0,) * 3
    detection_tag_index: int = 0
    detection_camera_type: int = 3
    drone_camera_rot: tuple[float, ...] = (0.0,) * 9
    drone_camera_trans: tuple[float, ...] = (0.0,) * 3

    def __post_init__(self) -> None:
        s = object.__setattr__
        for name in ("ctrl_state", "battery_pct", "num_frames", "detection_tag_index",
                     "detection_camera_type"):
            s(self, name, _uint(name, getattr(self, name)))
        alt = self.altitude_mm
        if isinstance(alt, bool) or not isinstance(alt, int) or not _I32_MIN <= alt <= _I32_MAX:
            raise ValueError(f"altitude_mm must be an int32, got {alt!r}")
        for name in ("theta_mdeg", "phi_mdeg", "psi_mdeg", "vx_mmps", "vy_mmps", "vz_mmps"):
            s(self, name, _f32(name, getattr(self, name)))
        for name, n in (("detection_camera_rot", 9), ("detection_camera_trans", 3),
                        ("drone_camera_rot", 9), ("drone_camera_trans", 3)):
            s(self, name, _f32s(name, getattr(self, name), n))

    @classmethod
    def from_si(cls, *, ctrl_state: int, battery_pct: int, pitch_deg: float, roll_deg: float,
                yaw_deg: float, altitude_m: float, vx_body_mps: float, vy_body_mps: float,
                vz_mps: float, num_frames: int = 0) -> DemoOption:
        """Build from converted values (same signs; altitude rounded to whole mm)."""
        if not math.isfinite(altitude_m):
            raise ValueError(f"altitude_m must be finite, got {altitude_m!r}")
        return cls(ctrl_state=ctrl_state, battery_pct=battery_pct,
                   theta_mdeg=pitch_deg * 1000.0, phi_mdeg=roll_deg * 1000.0,
                   psi_mdeg=yaw_deg * 1000.0, altitude_mm=round(altitude_m * 1000.0),
                   vx_mmps=vx_body_mps * 1000.0, vy_mmps=vy_body_mps * 1000.0,
                   vz_mmps=vz_mps * 1000.0, num_frames=num_frames)

    @classmethod
    def of_sample(cls, sample, ctrl_state: int) -> DemoOption:
        """The demo option a drone sends for a :class:`~ardrone_nmpc.core.types.NavdataSample`
        (the inverse of reading one): the battery as a whole percent clamped to 0–100, the
        rest as :meth:`from_si`.

        Built without :meth:`__post_init__`'s per-field checks (a simulated drone builds one
        per packet): the six floats rounded to float32 by one pack, as the wire does; any value
        a check would refuse goes through :meth:`from_si`, which raises as it always has."""
        battery_pct = int(round(min(100.0, max(0.0, sample.battery_pct))))
        altitude_m = sample.altitude_m
        try:
            floats = _F32X6.unpack(_F32X6.pack(
                sample.pitch_deg * 1000.0, sample.roll_deg * 1000.0, sample.yaw_deg * 1000.0,
                sample.vx_body_mps * 1000.0, sample.vy_body_mps * 1000.0,
                sample.vz_mps * 1000.0))
            altitude_mm = round(altitude_m * 1000.0) if math.isfinite(altitude_m) else None
        except (OverflowError, TypeError, ValueError, struct.error):
            floats = altitude_mm = None
        if (floats is None or type(altitude_mm) is not int
                or not _I32_MIN <= altitude_mm <= _I32_MAX
                or type(ctrl_state) is not int or not 0 <= ctrl_state <= _U32_MAX):
            return cls.from_si(
                ctrl_state=ctrl_state, battery_pct=battery_pct, pitch_deg=sample.pitch_deg,
                roll_deg=sample.roll_deg, yaw_deg=sample.yaw_deg, altitude_m=altitude_m,
                vx_body_mps=sample.vx_body_mps, vy_body_mps=sample.vy_body_mps,
                vz_mps=sample.vz_mps)
        demo = object.__new__(cls)
        s = object.__setattr__
        theta, phi, psi, vx, vy, vz = floats
        for name, value in zip(_DEMO_SAMPLE_FIELDS, (ctrl_state, battery_pct, theta, phi, psi,
                                                     altitude_mm, vx, vy, vz)):
            s(demo, name, value)
        for name, value in _DEMO_CONSTANT_FIELDS:
            s(demo, name, value)
        return demo

    @property
    def ctrl_major(self) -> int:
        """Upper 16 bits of ctrl_state (:class:`CtrlMajor` value; 10 is seen in the field)."""
        return self.ctrl_state >> 16

    @property
    def ctrl_minor(self) -> int:
        """Lower 16 bits of ctrl_state (meaning depends on the major state)."""
        return self.ctrl_state & 0xFFFF

    @property
    def pitch_deg(self) -> float:
        """theta in degrees, > 0 nose up."""
        return self.theta_mdeg / 1000.0

    @property
    def roll_deg(self) -> float:
        """phi in degrees, > 0 right wing down."""
        return self.phi_mdeg / 1000.0

    @property
    def yaw_deg(self) -> float:
        """psi in degrees, > 0 clockwise seen from above (not wrapped)."""
        return self.psi_mdeg / 1000.0

    @property
    def altitude_m(self) -> float:
        """Altitude in metres."""
        return self.altitude_mm / 1000.0

    @property
    def vx_body_mps(self) -> float:
        """Body-frame forward speed (m/s)."""
        return self.vx_mmps / 1000.0

    @property
    def vy_body_mps(self) -> float:
        """Body-frame speed to the right (m/s)."""
        return self.vy_mmps / 1000.0

    @property
    def vz_mps(self) -> float:
        """Body-frame vertical speed (m/s), **down positive**."""
        return self.vz_mmps / 1000.0


_DEMO_SAMPLE_FIELDS = ("ctrl_state", "battery_pct", "theta_mdeg", "phi_mdeg", "psi_mdeg",
                       "altitude_mm", "vx_mmps", "vy_mmps", "vz_mmps")
#: The demo option's fields a sample leaves at their defaults (as checked: of_sample's)
_DEMO_CONSTANT_FIELDS = tuple((f.name, getattr(DemoOption(), f.name))
                              for f in fields(DemoOption) if f.name not in _DEMO_SAMPLE_FIELDS)


@dataclass(frozen=True, slots=True)
class NavdataOption:
    """An option kept raw: ``tag`` and the ``payload`` after the 4-byte head."""

    tag: int
    payload: bytes = b""

    def __post_init__(self) -> None:
        _uint("tag", self.tag, 0xFFFF)
        payload = bytes(self.payload)
        if len(payload) + OPTION_HEAD_BYTES > 0xFFFF:
            raise ValueError(f"option payload of {len(payload)} bytes too long")
        object.__setattr__(self, "payload", payload)

    @property
    def size(self) -> int:
        """The wire size field: payload + 4."""
        return len(self.payload) + OPTION_HEAD_BYTES


@dataclass(frozen=True, slots=True)
class Navdata:
    """One navdata packet.

    Attributes
    ----------
    state : header state bits.
    sequence : packet sequence (u32; starts at 1, +1 per packet).
    vision_flag : ``vision_defined`` (i32).
    demo : the demo option, or None (bootstrap packets have none).
    options : every other option except the checksum, raw, in wire order. The encoder writes
        the demo option and these in ascending tag order (stable) and appends the checksum.
    magic : :data:`NAVDATA_MAGIC` or :data:`NAVDATA_MAGIC_ALT`.
    """

    state: DroneState
    sequence: int
    vision_flag: int = 0
    demo: DemoOption | None = None
    options: tuple[NavdataOption, ...] = ()
    magic: int = NAVDATA_MAGIC

    def __post_init__(self) -> None:
        object.__setattr__(self, "state", DroneState(_uint("state", int(self.state))))
        _uint("sequence", self.sequence)
        vf = self.vision_flag
        if isinstance(vf, bool) or not isinstance(vf, int) or not _I32_MIN <= vf <= _I32_MAX:
            raise ValueError(f"vision_flag must be an int32, got {vf!r}")
        if self.magic not in (NAVDATA_MAGIC, NAVDATA_MAGIC_ALT):
            raise ValueError(f"magic must be 0x55667788 or 0x55667789, got {self.magic!r}")
        if self.demo is not None and not isinstance(self.demo, DemoOption):
            raise TypeError("demo must be a DemoOption or None")
        options = tuple(self.options)
        for o in options:
            if not isinstance(o, NavdataOption):
                raise TypeError(f"options must be NavdataOption, got {type(o).__name__}")
            if o.tag in (DEMO_TAG, CHECKSUM_TAG):
                raise ValueError(f"option tag {o.tag:#x} is reserved (use demo=; checksum is "
                                 "computed)")
        object.__setattr__(self, "options", options)

    def option(self, tag: int) -> NavdataOption | None:
        """The first raw option with ``tag``, or None."""
        return next((o for o in self.options if o.tag == tag), None)


def navdata_checksum(data: bytes) -> int:
    """Unsigned 32-bit sum of the bytes (of everything before the checksum option)."""
    return sum(data) & _U32_MAX


def empty_vision_detect_option() -> NavdataOption:
    """vision_detect (tag 16, 328 bytes) with nb_detected = 0, as in default demo packets."""
    return NavdataOption(VISION_DETECT_TAG, bytes(VISION_DETECT_SIZE - OPTION_HEAD_BYTES))


_EMPTY_VISION_DETECT = empty_vision_detect_option()  # (frozen: shared by every packet)


def _encode_demo(d: DemoOption) -> bytes:
    return _DEMO.pack(DEMO_TAG, DEMO_SIZE, d.ctrl_state, d.battery_pct, d.theta_mdeg,
                      d.phi_mdeg, d.psi_mdeg, d.altitude_mm, d.vx_mmps, d.vy_mmps, d.vz_mmps,
                      d.num_frames, *d.detection_camera_rot, *d.detection_camera_trans,
                      d.detection_tag_index, d.detection_camera_type, *d.drone_camera_rot,
                      *d.drone_camera_trans)


def _decode_demo(buf: bytes, off: int) -> DemoOption:
    v = _DEMO.unpack_from(buf, off)
    return DemoOption(ctrl_state=v[2], battery_pct=v[3], theta_mdeg=v[4], phi_mdeg=v[5],
                      psi_mdeg=v[6], altitude_mm=v[7], vx_mmps=v[8], vy_mmps=v[9],
                      vz_mmps=v[10], num_frames=v[11], detection_camera_rot=v[12:21],
                      detection_camera_trans=v[21:24], detection_tag_index=v[24],
                      detection_camera_type=v[25], drone_camera_rot=v[26:35],
                      drone_camera_trans=v[35:38])


def encode_navdata(packet: Navdata) -> bytes:
    """The packet's bytes: header, demo and options in ascending tag order, checksum.

    Raises ValueError if the result would exceed :data:`NAVDATA_MAX_BYTES`.
    """
    parts = [_HEADER.pack(packet.magic, int(packet.state), packet.sequence, packet.vision_flag)]
    if packet.demo is not None:
        parts.append(_encode_demo(packet.demo))
    for o in sorted(packet.options, key=lambda o: o.tag):
        parts.append(_OPTION_HEAD.pack(o.tag, o.size) + o.payload)
    body = b"".join(parts)
    if len(body) + CHECKSUM_SIZE > NAVDATA_MAX_BYTES:
        raise ValueError(f"navdata packet of {len(body) + CHECKSUM_SIZE} bytes exceeds "
                         f"{NAVDATA_MAX_BYTES}")
    return body + _CHECKSUM.pack(CHECKSUM_TAG, CHECKSUM_SIZE, navdata_checksum(body))


def decode_navdata(data: bytes) -> Navdata:
    """Decode one packet (see the module docstring); raises only :class:`NavdataError`."""
    buf = bytes(data)
    n = len(buf)
    if n < HEADER_BYTES + CHECKSUM_SIZE:
        raise NavdataError(f"packet of {n} bytes is shorter than header + checksum")
    if n > NAVDATA_MAX_BYTES:
        raise NavdataError(f"packet of {n} bytes exceeds {NAVDATA_MAX_BYTES}")
    magic, state, sequence, vision_flag = _HEADER.unpack_from(buf, 0)
    if magic not in (NAVDATA_MAGIC, NAVDATA_MAGIC_ALT):
        raise NavdataError(f"bad magic {magic:#010x}")
    off = HEADER_BYTES
    demo: DemoOption | None = None
    options: list[NavdataOption] = []
    while True:
        if off + OPTION_HEAD_BYTES > n:
            raise NavdataError(f"no checksum option (options end at byte {off} of {n})")
        tag, size = _OPTION_HEAD.unpack_from(buf, off)
        if size < OPTION_HEAD_BYTES:
            raise NavdataError(f"option tag {tag} at byte {off} has invalid size {size}")
        if off + size > n:
            raise NavdataError(f"option tag {tag} at byte {off} (size {size}) overruns the "
                               f"{n}-byte packet")
        if tag == CHECKSUM_TAG:
            if size != CHECKSUM_SIZE:
                raise NavdataError(f"checksum option has size {size}, expected {CHECKSUM_SIZE}")
            (cks,) = struct.unpack_from("<I", buf, off + OPTION_HEAD_BYTES)
            expected = navdata_checksum(buf[:off])
            if cks != expected:
                raise NavdataError(f"checksum mismatch: packet says {cks:#x}, bytes sum to "
                                   f"{expected:#x}")
            break
        if tag == DEMO_TAG:
            if demo is not None:
                raise NavdataError("second demo option")
            if size < DEMO_SIZE:
                raise NavdataError(f"demo option of size {size} < {DEMO_SIZE}")
            demo = _decode_demo(buf, off)
        else:
            options.append(NavdataOption(tag, buf[off + OPTION_HEAD_BYTES:off + size]))
        off += size
    return Navdata(DroneState(state), sequence, vision_flag, demo, tuple(options), magic)


# ----------------------------------------------------------------------------- the drone's side

#: Flight phases a :class:`DroneStatus` names (the values of the tool's flight modes).
DRONE_PHASES = ("landed", "taking_off", "flying", "landing", "emergency")
_AIRBORNE_PHASES = ("taking_off", "flying", "landing")

#: State bits a running drone always shows (the captured bootstrap packet 0x4F800C10).
ALWAYS_ON_STATE = (DroneState.ALTITUDE | DroneState.PIC_VERSION | DroneState.ATCODEC_THREAD_ON
                   | DroneState.NAVDATA_THREAD_ON | DroneState.VIDEO_THREAD_ON
                   | DroneState.ACQ_THREAD_ON)
# state_bits' flags as ints (a flag's ``|`` builds a member each time)
_ALWAYS_ON_BITS = int(ALWAYS_ON_STATE)
_BIT_FLY, _BIT_EMERGENCY, _BIT_USER_EL, _BIT_START, _BIT_COMMAND = (
    int(DroneState.FLY), int(DroneState.EMERGENCY), int(DroneState.USER_EL),
    int(DroneState.USER_FEEDBACK_START), int(DroneState.COMMAND))
_BIT_BOOTSTRAP, _BIT_DEMO, _BIT_COM_WATCHDOG, _BIT_COM_LOST, _BIT_VBAT_LOW = (
    int(DroneState.NAVDATA_BOOTSTRAP), int(DroneState.NAVDATA_DEMO),
    int(DroneState.COM_WATCHDOG), int(DroneState.COM_LOST), int(DroneState.VBAT_LOW))
#: ``general:navdata_options`` default: demo + vision_detect (65537).
DEFAULT_NAVDATA_OPTIONS = (1 << OptionTag.DEMO) | (1 << OptionTag.VISION_DETECT)


@dataclass(frozen=True, slots=True)
class DroneStatus:
    """What a drone knows about itself when it sends a packet (the simulators' side).

    Attributes
    ----------
    phase : one of :data:`DRONE_PHASES`.
    moving : a progressive PCMD with a non-zero value is being flown (FLYING, else HOVERING).
    alt_out_zone : the altitude cap holds the climb (minor ALT_OUT_ZONE).
    lost_com : hovering because the client went silent (minor HOVERING_LOST_COM).
    user_emergency : the emergency came from the client's REF (state bit 16).
    start_button : REF bit 9 as last received (state bit 5).
    ack : the command-ACK bit 6.
    bootstrap : no ``general:navdata_demo`` written yet (bits 10 + 11, no options).
    demo : demo packets (bit 10); False = full-rate packets with every option.
    com_watchdog, com_lost, battery_low : state bits 30, 13, 15.
    faults : further state bits the drone reports about itself (MOTORS, SOFTWARE_FAULT,
        ULTRASOUND, CUTOUT, …), OR-ed into the state word as they are.
    """

    phase: str
    moving: bool = False
    alt_out_zone: bool = False
    lost_com: bool = False
    user_emergency: bool = False
    start_button: bool = False
    ack: bool = False
    bootstrap: bool = False
    demo: bool = True
    com_watchdog: bool = False
    com_lost: bool = False
    battery_low: bool = False
    faults: int = 0

    def __post_init__(self) -> None:
        if self.phase not in DRONE_PHASES:
            raise ValueError(f"phase must be one of {DRONE_PHASES}, got {self.phase!r}")

    def state_bits(self) -> DroneState:
        """The header's state bits (OR-ed as ints, then made one flag)."""
        s = _ALWAYS_ON_BITS | (self.faults & 0xFFFFFFFF)
        flags = ((self.phase in _AIRBORNE_PHASES, _BIT_FLY),
                 (self.phase == "emergency", _BIT_EMERGENCY),
                 (self.phase == "emergency" and self.user_emergency, _BIT_USER_EL),
                 (self.start_button, _BIT_START),
                 (self.ack, _BIT_COMMAND),
                 (self.bootstrap, _BIT_BOOTSTRAP | _BIT_DEMO),
                 (not self.bootstrap and self.demo, _BIT_DEMO),
                 (self.com_watchdog, _BIT_COM_WATCHDOG),
                 (self.com_lost, _BIT_COM_LOST),
                 (self.battery_low, _BIT_VBAT_LOW))
        for on, bits in flags:
            if on:
                s |= bits
        return DroneState(s)

    def ctrl_state(self, codes: CtrlCodes = CtrlCodes.SDK) -> int:
        """``major << 16 | minor``: LANDED 2, emergency DEFAULT 0 (as node-ar-drone's docs
        show a drone in emergency), the transitions by ``codes``, airborne HOVERING 4 (minor
        LOST_COM or ALT_OUT_ZONE) or FLYING 3 while moving (minor ALT_OUT_ZONE)."""
        phase = self.phase
        if phase == "landed":
            return ctrl_state_value(CtrlMajor.LANDED)
        if phase == "emergency":
            return ctrl_state_value(CtrlMajor.DEFAULT)
        if phase == "taking_off":
            return ctrl_state_value(codes.takeoff_major)
        if phase == "landing":
            return ctrl_state_value(codes.landing_major)
        if self.lost_com:
            return ctrl_state_value(CtrlMajor.HOVERING, HOVERING_LOST_COM)
        if self.moving:
            return ctrl_state_value(CtrlMajor.FLYING,
                                    FLYING_ALT_OUT_ZONE if self.alt_out_zone else 0)
        return ctrl_state_value(CtrlMajor.HOVERING,
                                HOVERING_ALT_OUT_ZONE if self.alt_out_zone else 0)


_TIME = struct.Struct("<I")


def time_option(t_s: float) -> NavdataOption:
    """The time option (tag 1): ``u32`` with 11 bits of seconds over 21 bits of microseconds."""
    if not (math.isfinite(t_s) and t_s >= 0.0):
        raise ValueError(f"t_s must be finite and >= 0, got {t_s!r}")
    sec = int(t_s)
    usec = int((t_s - sec) * 1e6)
    option = object.__new__(NavdataOption)  # (its tag and 4-byte payload need no check)
    object.__setattr__(option, "tag", OptionTag.TIME)
    object.__setattr__(option, "payload", _TIME.pack(((sec & 0x7FF) << 21) | (usec & 0x1FFFFF)))
    return option


def encode_drone_navdata(status: DroneStatus, sequence: int, sample=None, *,
                         codes: CtrlCodes = CtrlCodes.SDK,
                         options_mask: int = DEFAULT_NAVDATA_OPTIONS, t_s: float = 0.0) -> bytes:
    """The packet a drone in ``status`` sends: the one navdata encoder of every simulated drone.

    Bootstrap: header and checksum only. Otherwise the options ``options_mask`` selects
    (``general:navdata_options``; every one in full mode, ``status.demo`` False) among those a
    simulator produces: demo (bit 0) from ``sample`` (a
    :class:`~ardrone_nmpc.core.types.NavdataSample`, see :meth:`DemoOption.of_sample`; None =
    no demo option), time (bit 1) from ``t_s`` and an empty vision_detect (bit 16).
    """
    return encode_navdata(drone_navdata(status, sequence, sample, codes=codes,
                                        options_mask=options_mask, t_s=t_s))


def drone_navdata(status: DroneStatus, sequence: int, sample=None, *,
                  codes: CtrlCodes = CtrlCodes.SDK, options_mask: int = DEFAULT_NAVDATA_OPTIONS,
                  t_s: float = 0.0) -> Navdata:
    """:func:`encode_drone_navdata`'s packet before its encoding — what
    :func:`decode_navdata` gives back of its bytes but for the raw options' payloads (the
    header's state and sequence; the demo option, whose floats are stored as float32). Built
    without :class:`Navdata`'s checks but the sequence's (the rest hold by construction); the
    empty vision_detect option shared by every packet (frozen)."""
    state = status.state_bits()
    if status.bootstrap:
        return Navdata(state, sequence)
    full = not status.demo
    demo = None
    options: list[NavdataOption] = []
    if sample is not None and (full or options_mask & (1 << OptionTag.DEMO)):
        demo = DemoOption.of_sample(sample, status.ctrl_state(codes))
    if full or options_mask & (1 << OptionTag.TIME):
        options.append(time_option(t_s))
    if full or options_mask & (1 << OptionTag.VISION_DETECT):
        options.append(_EMPTY_VISION_DETECT)
    _uint("sequence", sequence)
    # the rest of Navdata's checks hold by construction: built without them (one a packet)
    packet = object.__new__(Navdata)
    s = object.__setattr__
    for name, value in (("state", state), ("sequence", sequence), ("vision_flag", 0),
                        ("demo", demo), ("options", tuple(options)),
                        ("magic", NAVDATA_MAGIC)):
        s(packet, name, value)
    return packet
