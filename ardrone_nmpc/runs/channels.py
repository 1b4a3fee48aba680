"""A run as Foxglove channels: topics, schemas and JSON messages, for the MCAP export and the
live view alike (docs/live-view.md).

* ``/log`` — one message per log row; its fields are the log's columns.
* ``/events`` — one message per event, the object of ``events.jsonl``.
* ``/config`` — the resolved configuration (``{"seed", "version", "config"}``).
* ``/pose``, ``/reference`` — ``foxglove.PoseInFrame`` in frame ``world``: the measured pose
  and the reference at each row (ψ as a yaw quaternion; rows without a finite position
  publish none);
* ``/flight_path``, ``/reference_path`` — ``foxglove.PosesInFrame``: those poses as paths, so
  Foxglove's 3-D panel draws the flight and the path it follows (the export writes each once,
  whole, at the first row's time; the live view re-sends them as they grow).

JSON has no NaN or infinity: NaN is written as ``null``, ±inf as ``±1e999`` — a number every
JSON parser reads back as ±infinity (Python's ``json``, JavaScript's ``JSON.parse``). Other
floats are written as ``repr`` (the shortest decimal that reads back to the same double,
−0.0 included), so every float of a row round-trips bit for bit.
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Mapping
from pathlib import PurePath
from typing import Any

import numpy as np

from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS

__all__ = ["TOPIC_LOG", "TOPIC_EVENTS", "TOPIC_CONFIG", "TOPIC_POSE", "TOPIC_REFERENCE",
           "TOPIC_FLIGHT_PATH", "TOPIC_REFERENCE_PATH", "WORLD_FRAME", "SCHEMAS", "PathBuilder",
           "json_bytes", "row_messages", "event_message", "config_message", "time_ns",
           "decode_row"]

TOPIC_LOG = "/log"
TOPIC_EVENTS = "/events"
TOPIC_CONFIG = "/config"
TOPIC_POSE = "/pose"
TOPIC_REFERENCE = "/reference"
TOPIC_FLIGHT_PATH = "/flight_path"
TOPIC_REFERENCE_PATH = "/reference_path"
WORLD_FRAME = "world"
_POSE_FIELDS = {TOPIC_POSE: ("x_m", "y_m", "z_m", "psi_rad"),
                TOPIC_REFERENCE: ("x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad")}
_PATH_OF = {TOPIC_POSE: TOPIC_FLIGHT_PATH, TOPIC_REFERENCE: TOPIC_REFERENCE_PATH}

_NUMBER = {"type": ["number", "null"]}
_XYZ = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_POSE_IN_FRAME = {  # foxglove.PoseInFrame, JSON form (docs.foxglove.dev message schemas)
    "title": "foxglove.PoseInFrame", "type": "object",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"},
                                                        "nsec": {"type": "integer"}}},
        "frame_id": {"type": "string"},
        "pose": {"type": "object", "properties": {
            "position": _XYZ,
            "orientation": {"type": "object",
                            "properties": {k: {"type": "number"} for k in "xyzw"}}}},
    },
}
_POSES_IN_FRAME = {  # foxglove.PosesInFrame, JSON form
    "title": "foxglove.PosesInFrame", "type": "object",
    "properties": {"timestamp": _POSE_IN_FRAME["properties"]["timestamp"],
                   "frame_id": {"type": "string"},
                   "poses": {"type": "array",
                             "items": _POSE_IN_FRAME["properties"]["pose"]}},
}
_LOG_SCHEMA = {"title": "ardrone_nmpc.LogRow", "type": "object",
               "properties": {c: {"type": "string"} if c in STRING_COLUMNS else _NUMBER
                              for c in LOG_COLUMNS}}
_EVENT_SCHEMA = {"title": "ardrone_nmpc.Event", "type": "object",
                 "properties": {"t_s": {"type": "number"}, "kind": {"type": "string"}},
                 "required": ["t_s", "kind"]}
_CONFIG_SCHEMA = {"title": "ardrone_nmpc.Config", "type": "object"}

#: topic → (schema name, JSON schema text); every channel's messages are JSON.
SCHEMAS: dict[str, tuple[str, bytes]] = {
    topic: (schema["title"], json.dumps(schema, separators=(",", ":")).encode())
    for topic, schema in ((TOPIC_LOG, _LOG_SCHEMA), (TOPIC_EVENTS, _EVENT_SCHEMA),
                          (TOPIC_CONFIG, _CONFIG_SCHEMA), (TOPIC_POSE, _POSE_IN_FRAME),
                          (TOPIC_REFERENCE, _POSE_IN_FRAME),
                          (TOPIC_FLIGHT_PATH, _POSES_IN_FRAME),
                          (TOPIC_REFERENCE_PATH, _POSES_IN_FRAME))}


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


def _stamp(log_ns: int) -> str:
    sec, nsec = divmod(log_ns, 1_000_000_000)
    return f'"timestamp":{{"sec":{sec},"nsec":{nsec}}},"frame_id":"{WORLD_FRAME}"'


def _number(row: Mapping[str, Any], key: str) -> float:
    v = row.get(key)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _pose_text(row: Mapping[str, Any], keys: tuple[str, ...]) -> str | None:
    """The ``foxglove.Pose`` JSON of a row's position and heading; None without a position."""
    x, y, z, psi = (_number(row, k) for k in keys)
    if not all(math.isfinite(v) for v in (x, y, z)):
        return None
    half = 0.5 * psi if math.isfinite(psi) else 0.0
    return (f'{{"position":{{"x":{_text(x)},"y":{_text(y)},"z":{_text(z)}}},'
            f'"orientation":{{"x":0.0,"y":0.0,"z":{_text(math.sin(half))},'
            f'"w":{_text(math.cos(half))}}}}}')


def row_messages(row: Mapping[str, Any], log_ns: int,
                 paths: PathBuilder | None = None) -> list[tuple[str, bytes]]:
    """``(topic, message)`` of one log row: ``/log`` always, ``/pose`` and ``/reference`` when
    their position is finite; their poses are added to ``paths`` too."""
    out = [(TOPIC_LOG, json_bytes(row))]
    for topic, keys in _POSE_FIELDS.items():
        pose = _pose_text(row, keys)
        if pose is not None:
            out.append((topic, f'{{{_stamp(log_ns)},"pose":{pose}}}'.encode()))
            if paths is not None:
                paths.poses[_PATH_OF[topic]].append(pose)
    return out


class PathBuilder:
    """The poses of ``/pose`` and ``/reference`` so far, as ``foxglove.PosesInFrame``
    messages on ``/flight_path`` and ``/reference_path`` (the 3-D panel draws them as lines).

    ``every`` keeps one pose in so many (a live view re-sends the whole path)."""

    def __init__(self, every: int = 1):
        self.every = max(int(every), 1)
        self.poses: dict[str, list[str]] = {TOPIC_FLIGHT_PATH: [], TOPIC_REFERENCE_PATH: []}

    def messages(self, log_ns: int) -> list[tuple[str, bytes]]:
        return [(topic, f'{{{_stamp(log_ns)},"poses":[{",".join(poses[::self.every])}]}}'
                 .encode()) for topic, poses in self.poses.items() if poses]


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
