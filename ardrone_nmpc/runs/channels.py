"""A run as Foxglove channels: topics, what each message holds, and the JSON encoding of the
run's own records — for the MCAP export, ``fly --mcap`` and the live view alike
(docs/live-view.md; the foxglove-sdk side is :mod:`ardrone_nmpc.runs.foxglove_channels`).

* ``/log`` — one message per log row; its fields are the log's columns (JSON).
* ``/events`` — one message per event, the object of ``events.jsonl`` (JSON).
* ``/config`` — the resolved configuration (``{"seed", "version", "config"}``, JSON).
* ``/pose`` — ``foxglove.PoseInFrame`` in frame ``world``: the measured position (mocap) and
  the full attitude — heading ψ from the mocap, roll and pitch from the drone's navdata
  (yaw-only where a row has no navdata attitude); rows without a finite position publish none.
* ``/reference`` — ``foxglove.PoseInFrame``: the reference position and heading.
* ``/tf`` — ``foxglove.FrameTransform`` ``world → drone`` (the ``/pose``) and
  ``world → reference`` per row, so Foxglove's 3-D panel has a drone frame to follow and to
  attach a model to.
* ``/flight_path``, ``/reference_path`` — ``foxglove.PosesInFrame``: those poses as paths (the
  export writes each once, whole, at the first row's time; the live view re-sends them as they
  grow).

JSON has no NaN or infinity: NaN is written as ``null``, ±inf as ``±1e999`` — a number every
JSON parser reads back as ±infinity (Python's ``json``, JavaScript's ``JSON.parse``). Other
floats are written as ``repr`` (the shortest decimal that reads back to the same double,
−0.0 included), so every float of a row round-trips bit for bit.

Frames (docs/design.md §4): ``world`` is the mocap frame, x forward, y left, z up. The drone
frame is its body with the same axes (x forward, y left, z up); its attitude is
``Rz(ψ) · Ry(θ) · Rx(φ)`` with φ = navdata roll (> 0 right wing down) and θ = −navdata pitch
(navdata pitch > 0 is nose up; about +y, > 0 is nose down).
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Callable, Mapping
from pathlib import PurePath
from typing import Any, NamedTuple

import numpy as np

from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS

__all__ = ["TOPIC_LOG", "TOPIC_EVENTS", "TOPIC_CONFIG", "TOPIC_POSE", "TOPIC_REFERENCE",
           "TOPIC_TF", "TOPIC_FLIGHT_PATH", "TOPIC_REFERENCE_PATH", "WORLD_FRAME",
           "DRONE_FRAME", "REFERENCE_FRAME", "JSON_SCHEMAS", "TOPICS", "Pose", "Transform",
           "PathBuilder", "attitude_quaternion", "json_bytes", "row_messages",
           "event_message", "config_message", "time_ns", "decode_row"]

TOPIC_LOG = "/log"
TOPIC_EVENTS = "/events"
TOPIC_CONFIG = "/config"
TOPIC_POSE = "/pose"
TOPIC_REFERENCE = "/reference"
TOPIC_TF = "/tf"
TOPIC_FLIGHT_PATH = "/flight_path"
TOPIC_REFERENCE_PATH = "/reference_path"
WORLD_FRAME = "world"
DRONE_FRAME = "drone"
REFERENCE_FRAME = "reference"

_LOG_SCHEMA = {"title": "ardrone_nmpc.LogRow", "type": "object",
               "properties": {c: {"type": "string"} if c in STRING_COLUMNS
                              else {"type": ["number", "null"]} for c in LOG_COLUMNS}}
_EVENT_SCHEMA = {"title": "ardrone_nmpc.Event", "type": "object",
                 "properties": {"t_s": {"type": "number"}, "kind": {"type": "string"}},
                 "required": ["t_s", "kind"]}
_CONFIG_SCHEMA = {"title": "ardrone_nmpc.Config", "type": "object"}

#: topic → (schema name, JSON schema text) of the JSON channels (the run's own records).
JSON_SCHEMAS: dict[str, tuple[str, bytes]] = {
    topic: (schema["title"], json.dumps(schema, separators=(",", ":")).encode())
    for topic, schema in ((TOPIC_LOG, _LOG_SCHEMA), (TOPIC_EVENTS, _EVENT_SCHEMA),
                          (TOPIC_CONFIG, _CONFIG_SCHEMA))}

#: topic → schema name of every channel (the JSON ones and foxglove-sdk's typed ones).
TOPICS: dict[str, str] = {
    **{topic: name for topic, (name, _) in JSON_SCHEMAS.items()},
    TOPIC_POSE: "foxglove.PoseInFrame", TOPIC_REFERENCE: "foxglove.PoseInFrame",
    TOPIC_TF: "foxglove.FrameTransform",
    TOPIC_FLIGHT_PATH: "foxglove.PosesInFrame", TOPIC_REFERENCE_PATH: "foxglove.PosesInFrame",
}


class Pose(NamedTuple):
    """A position (m, frame ``world``) and an attitude quaternion (x, y, z, w)."""

    x_m: float
    y_m: float
    z_m: float
    qx: float
    qy: float
    qz: float
    qw: float


class Transform(NamedTuple):
    """``parent → child`` placed at ``pose`` (a ``foxglove.FrameTransform``)."""

    parent: str
    child: str
    pose: Pose


def attitude_quaternion(roll_rad: float, pitch_rad: float, yaw_rad: float
                        ) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of ``Rz(yaw) · Ry(pitch) · Rx(roll)`` (intrinsic
    z-y'-x'' angles: the heading, then the pitch about the new y, then the roll about the
    new x)."""
    cr, sr = math.cos(0.5 * roll_rad), math.sin(0.5 * roll_rad)
    cp, sp = math.cos(0.5 * pitch_rad), math.sin(0.5 * pitch_rad)
    cy, sy = math.cos(0.5 * yaw_rad), math.sin(0.5 * yaw_rad)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def _float_text(v: float) -> str:
    if v != v:
        return "null"
    if v in (math.inf, -math.inf):
        return "1e999" if v > 0 else "-1e999"
    return float.__repr__(v)   # numpy's float64 is a float whose repr is "np.float64(…)"


def _text(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return "null" if v is None else ("true" if v else "false")
    if isinstance(v, float):
        return _float_text(v)
    if isinstance(v, int):
        return int.__repr__(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, np.generic):
        return _text(v.item())
    if isinstance(v, enum.Enum):
        return _text(v.value)
    if isinstance(v, Mapping):
        return "{" + ",".join(f"{json.dumps(str(k))}:{_text(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ",".join(_text(x) for x in v) + "]"
    if isinstance(v, PurePath):
        return json.dumps(str(v))
    return json.dumps(repr(v))


def json_bytes(value: Any) -> bytes:
    """``value`` as JSON text (UTF-8), NaN → ``null``, ±inf → ``±1e999``."""
    return _text(value).encode("utf-8")


def time_ns(origin_ns: int, t_s: float) -> int:
    """The log time (ns since the epoch) of run time ``t_s`` on a run whose ``t_s = 0`` is
    ``origin_ns``; a non-finite ``t_s`` maps to the origin. Never negative."""
    if not math.isfinite(t_s):
        return max(origin_ns, 0)
    return max(origin_ns + round(t_s * 1e9), 0)


def _number(row: Mapping[str, Any], key: str) -> float:
    v = row.get(key)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _pose(row: Mapping[str, Any], keys: tuple[str, str, str, str],
          tilt: tuple[str, str] | None) -> Pose | None:
    """The pose of a row's position, heading and (``tilt``: navdata roll and pitch columns,
    degrees) attitude; None without a finite position. A missing angle counts as 0."""
    x, y, z, psi = (_number(row, k) for k in keys)
    if not all(math.isfinite(v) for v in (x, y, z)):
        return None
    roll = pitch = 0.0
    if tilt is not None:
        nav_roll, nav_pitch = (_number(row, k) for k in tilt)
        if math.isfinite(nav_roll) and math.isfinite(nav_pitch):
            roll, pitch = math.radians(nav_roll), -math.radians(nav_pitch)
    return Pose(x, y, z, *attitude_quaternion(roll, pitch, psi if math.isfinite(psi) else 0.0))


def drone_pose(row: Mapping[str, Any]) -> Pose | None:
    """The measured pose of a row: mocap position and ψ, navdata roll and pitch."""
    return _pose(row, ("x_m", "y_m", "z_m", "psi_rad"), ("nav_roll_deg", "nav_pitch_deg"))


def reference_pose(row: Mapping[str, Any]) -> Pose | None:
    """The reference of a row: its position and heading (a reference has no tilt)."""
    return _pose(row, ("x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad"), None)


_POSES = ((TOPIC_POSE, drone_pose, DRONE_FRAME, TOPIC_FLIGHT_PATH),
          (TOPIC_REFERENCE, reference_pose, REFERENCE_FRAME, TOPIC_REFERENCE_PATH))


def row_messages(row: Mapping[str, Any],
                 paths: PathBuilder | None = None) -> list[tuple[str, Any]]:
    """``(topic, payload)`` of one log row: ``/log`` always (JSON bytes); ``/pose`` and
    ``/reference`` (a :class:`Pose`) and their ``/tf`` (a :class:`Transform`) when the position
    is finite. Their poses are added to ``paths`` too."""
    out: list[tuple[str, Any]] = [(TOPIC_LOG, json_bytes(row))]
    for topic, pose_of, frame, path_topic in _POSES:
        pose = pose_of(row)
        if pose is not None:
            out.append((topic, pose))
            out.append((TOPIC_TF, Transform(WORLD_FRAME, frame, pose)))
            if paths is not None:
                paths.add(path_topic, pose)
    return out


class PathBuilder:
    """The poses of ``/pose`` and ``/reference`` so far, as ``(topic, [pose, …])`` for
    ``/flight_path`` and ``/reference_path`` (the 3-D panel draws them as lines).

    ``every`` keeps one pose in so many (a live view re-sends the whole path); ``convert``
    turns each :class:`Pose` into what the writer logs, once, as it is added (a live view
    re-sends thousands of poses a second: converting them again each time would cost tens of
    milliseconds)."""

    def __init__(self, every: int = 1, convert: Callable[[Pose], Any] | None = None):
        self.every = max(int(every), 1)
        self.convert = convert
        self.poses: dict[str, list[Any]] = {TOPIC_FLIGHT_PATH: [], TOPIC_REFERENCE_PATH: []}

    def add(self, topic: str, pose: Pose) -> None:
        self.poses[topic].append(pose if self.convert is None else self.convert(pose))

    def messages(self) -> list[tuple[str, list[Pose]]]:
        return [(topic, poses[::self.every]) for topic, poses in self.poses.items() if poses]


def event_message(event: Mapping[str, Any]) -> bytes:
    """The ``/events`` message of one event (``{"t_s", "kind", …}``)."""
    return json_bytes(event)


def config_message(config: Mapping[str, Any], *, seed: Any = None, version: Any = None) -> bytes:
    """The ``/config`` message: the resolved configuration as a mapping."""
    return json_bytes({"seed": seed, "version": version, "config": config})


def decode_row(message: bytes) -> dict[str, Any]:
    """A ``/log`` message read back: ``null`` in a numeric column is NaN again."""
    row = json.loads(message)
    return {k: (math.nan if v is None and k not in STRING_COLUMNS else v)
            for k, v in row.items()}
