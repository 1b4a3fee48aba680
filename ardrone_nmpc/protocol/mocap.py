"""Motion-capture pose datagrams (Vicon Tracker "UDP object stream" layout): encoder and decoder.

docs/mocap-stream.md. A datagram is ``u32 frame number, u8 item count`` followed by items
``u8 id, u16 size, data[size]`` (size excludes the 3-byte item header). A pose item (id 0,
size 72) is ``char[24]`` NUL-padded ASCII name, translation x, y, z (float64, **mm**, world
frame) and rotation x, y, z (float64, **rad**, R = Rx(rx)·Ry(ry)·Rz(rz), intrinsic X→Y→Z).
Little-endian and packed: always the ``<`` prefix (native alignment shifts the second item).

The decoder trusts the item count and sizes, not the datagram length: zero padding to
256/512/1024 bytes (or none) is accepted and ignored, items of unknown id are stepped over by
their size, and an item that overruns the datagram (or a pose item shorter than 72 bytes, or a
name repeated within one datagram) raises :class:`MocapError`, the only exception it raises.
Non-ASCII name bytes never raise; they are kept as ``\\xNN`` escapes.

Records hold the wire values and the boundary conversions: ``position_m`` (metres),
``psi_rad`` = atan2(R[1,0], R[0,0]) wrapped to (−π, π] (≈ rz only for small roll and pitch),
and ``fresh`` — False for the all-zero pose a tracker sends for an occluded object (and for
non-finite values), which must never reach the controller. The other "no fresh pose" forms of
the spec (object missing, bit-identical pose repeated) need history and belong to the link.
"""

from __future__ import annotations

import math
import struct
import types
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

__all__ = [
    "MOCAP_DEFAULT_PORT", "HEADER_FORMAT", "HEADER_BYTES", "ITEM_HEADER_FORMAT",
    "ITEM_HEADER_BYTES", "POSE_ITEM_ID", "POSE_FORMAT", "POSE_DATA_BYTES", "POSE_ITEM_BYTES",
    "OBJECT_NAME_BYTES", "MOCAP_MAX_DATAGRAM_BYTES", "MOCAP_PAD_BYTES", "MOCAP_MAX_OBJECTS",
    "MocapError", "MocapObjectPose", "MocapFrame", "rotation_heading_rad", "encode_mocap",
    "decode_mocap",
]

MOCAP_DEFAULT_PORT = 51001
HEADER_FORMAT = "<IB"                  # frame number, item count
HEADER_BYTES = struct.calcsize(HEADER_FORMAT)             # 5
ITEM_HEADER_FORMAT = "<BH"             # item id, data size (excluding these 3 bytes)
ITEM_HEADER_BYTES = struct.calcsize(ITEM_HEADER_FORMAT)   # 3
POSE_ITEM_ID = 0
POSE_FORMAT = "<24s6d"                 # name, tx, ty, tz (mm), rx, ry, rz (rad)
POSE_DATA_BYTES = struct.calcsize(POSE_FORMAT)            # 72
POSE_ITEM_BYTES = ITEM_HEADER_BYTES + POSE_DATA_BYTES     # 75
OBJECT_NAME_BYTES = 24
MOCAP_MAX_DATAGRAM_BYTES = 1024
MOCAP_PAD_BYTES = (256, 1024)          # the encoder pads to the first size that fits
MOCAP_MAX_OBJECTS = (MOCAP_MAX_DATAGRAM_BYTES - HEADER_BYTES) // POSE_ITEM_BYTES   # 13

_HEADER = struct.Struct(HEADER_FORMAT)
_ITEM_HEADER = struct.Struct(ITEM_HEADER_FORMAT)
_POSE = struct.Struct(POSE_FORMAT)
_MM_PER_M = 1000.0


class MocapError(ValueError):
    """A malformed mocap datagram (the only exception the decoder raises)."""


def rotation_heading_rad(rx: float, ry: float, rz: float) -> float:
    """Heading ψ = atan2(R[1,0], R[0,0]) of R = Rx(rx)·Ry(ry)·Rz(rz), wrapped to (−π, π].

    R[1,0] = cos rx · sin rz + sin rx · sin ry · cos rz,  R[0,0] = cos ry · cos rz.
    NaN if an angle is not finite (``math.sin(inf)`` would raise).
    """
    if not (math.isfinite(rx) and math.isfinite(ry) and math.isfinite(rz)):
        return math.nan
    r10 = math.cos(rx) * math.sin(rz) + math.sin(rx) * math.sin(ry) * math.cos(rz)
    r00 = math.cos(ry) * math.cos(rz)
    psi = math.atan2(r10, r00)
    return math.pi if psi <= -math.pi else psi


def _triple(name: str, v) -> tuple[float, float, float]:
    t = tuple(float(x) for x in v)
    if len(t) != 3:
        raise ValueError(f"{name} needs 3 values, got {len(t)}")
    return t  # type: ignore[return-value]


@dataclass(frozen=True, slots=True)
class MocapObjectPose:
    """One rigid-body pose as on the wire, with the boundary conversions.

    Attributes
    ----------
    name : object name (≤ 24 ASCII characters on the wire).
    translation_mm : (x, y, z) in millimetres, world frame (x forward, y left, z up).
    rotation_xyz_rad : (rx, ry, rz) in radians, R = Rx(rx)·Ry(ry)·Rz(rz), body → world.
    position_m : translation in metres (computed).
    psi_rad : heading atan2(R[1,0], R[0,0]) in (−π, π], counter-clockwise (computed).
    fresh : False for the all-zero pose (occluded object) or any non-finite value (computed).
    """

    name: str
    translation_mm: tuple[float, float, float]
    rotation_xyz_rad: tuple[float, float, float]
    position_m: tuple[float, float, float] = field(init=False)
    psi_rad: float = field(init=False)
    fresh: bool = field(init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise TypeError(f"name must be a str, got {type(self.name).__name__}")
        t = _triple("translation_mm", self.translation_mm)
        r = _triple("rotation_xyz_rad", self.rotation_xyz_rad)
        s = object.__setattr__
        s(self, "translation_mm", t)
        s(self, "rotation_xyz_rad", r)
        s(self, "position_m", (t[0] / _MM_PER_M, t[1] / _MM_PER_M, t[2] / _MM_PER_M))
        s(self, "psi_rad", rotation_heading_rad(*r))
        values = t + r
        s(self, "fresh", any(values) and all(math.isfinite(v) for v in values))

    @classmethod
    def from_si(cls, name: str, position_m, rotation_xyz_rad) -> MocapObjectPose:
        """The wire pose of an object at ``position_m`` (3,) m with ``rotation_xyz_rad`` (3,)."""
        return cls(name, tuple(float(v) * _MM_PER_M for v in position_m),
                   tuple(float(v) for v in rotation_xyz_rad))


@dataclass(frozen=True, slots=True)
class MocapFrame:
    """One datagram: the frame number and the poses keyed by object name (datagram order).

    Attributes
    ----------
    frame_number : u32, +1 per mocap frame (gaps = dropped frames).
    poses : read-only mapping name → :class:`MocapObjectPose`; each key equals its pose's name.
    """

    frame_number: int
    poses: Mapping[str, MocapObjectPose] = field(default_factory=dict)

    def __post_init__(self) -> None:
        fn = self.frame_number
        if isinstance(fn, bool) or not isinstance(fn, int) or not 0 <= fn <= 0xFFFFFFFF:
            raise ValueError(f"frame_number must be a u32, got {fn!r}")
        poses = dict(self.poses)
        for key, pose in poses.items():
            if not isinstance(pose, MocapObjectPose) or pose.name != key:
                raise ValueError(f"poses[{key!r}] must be a MocapObjectPose named {key!r}")
        object.__setattr__(self, "poses", types.MappingProxyType(poses))

    @classmethod
    def of(cls, frame_number: int, poses: Iterable[MocapObjectPose]) -> MocapFrame:
        """A frame from a sequence of poses (names must be distinct)."""
        d: dict[str, MocapObjectPose] = {}
        for p in poses:
            if p.name in d:
                raise ValueError(f"duplicate object name {p.name!r}")
            d[p.name] = p
        return cls(frame_number, d)


def _name_bytes(name: str) -> bytes:
    try:
        raw = name.encode("ascii")
    except UnicodeEncodeError as exc:
        raise ValueError(f"object name {name!r} is not ASCII") from exc
    if not 0 < len(raw) <= OBJECT_NAME_BYTES or b"\0" in raw:
        raise ValueError(f"object name {name!r} must be 1..{OBJECT_NAME_BYTES} ASCII characters "
                         "without NUL")
    return raw


def encode_mocap(frame: MocapFrame, *, pad: bool = True) -> bytes:
    """The datagram of ``frame``: header and one pose item per object, in order.

    With ``pad`` (the streamer default) the datagram is zero-padded to 256 bytes, or to 1024
    when it does not fit 256 (more than 3 objects). Raises ValueError for names that are not
    1–24 ASCII characters, or more than :data:`MOCAP_MAX_OBJECTS` objects (1024 bytes).
    """
    if len(frame.poses) > MOCAP_MAX_OBJECTS:
        raise ValueError(f"{len(frame.poses)} objects do not fit a "
                         f"{MOCAP_MAX_DATAGRAM_BYTES}-byte datagram (max {MOCAP_MAX_OBJECTS})")
    parts = [_HEADER.pack(frame.frame_number, len(frame.poses))]
    for p in frame.poses.values():
        parts.append(_ITEM_HEADER.pack(POSE_ITEM_ID, POSE_DATA_BYTES))
        parts.append(_POSE.pack(_name_bytes(p.name), *p.translation_mm, *p.rotation_xyz_rad))
    out = b"".join(parts)
    if pad:
        size = next(s for s in MOCAP_PAD_BYTES if s >= len(out))
        out += bytes(size - len(out))
    return out


def decode_mocap(data: bytes) -> MocapFrame:
    """Decode one datagram, padded or not; raises only :class:`MocapError`."""
    buf = bytes(data)
    n = len(buf)
    if n < HEADER_BYTES:
        raise MocapError(f"datagram of {n} bytes is shorter than the {HEADER_BYTES}-byte header")
    frame_number, count = _HEADER.unpack_from(buf, 0)
    off = HEADER_BYTES
    poses: dict[str, MocapObjectPose] = {}
    for i in range(count):
        if off + ITEM_HEADER_BYTES > n:
            raise MocapError(f"item {i} of {count} header at byte {off} overruns the "
                             f"{n}-byte datagram")
        item_id, size = _ITEM_HEADER.unpack_from(buf, off)
        off += ITEM_HEADER_BYTES
        if off + size > n:
            raise MocapError(f"item {i} (id {item_id}, size {size}) overruns the "
                             f"{n}-byte datagram")
        if item_id == POSE_ITEM_ID:
            if size < POSE_DATA_BYTES:
                raise MocapError(f"pose item {i} has size {size} < {POSE_DATA_BYTES}")
            raw_name, tx, ty, tz, rx, ry, rz = _POSE.unpack_from(buf, off)
            name = raw_name.split(b"\0", 1)[0].decode("ascii", errors="backslashreplace")
            if name in poses:
                raise MocapError(f"object {name!r} appears twice in frame {frame_number}")
            poses[name] = MocapObjectPose(name, (tx, ty, tz), (rx, ry, rz))
        off += size
    return MocapFrame(frame_number, poses)
