"""A run as Foxglove channels: topics, schemas and JSON messages, for the MCAP export and the
live view alike (docs/live-view.md).

* ``/log`` — one message per log row; its fields are the log's columns.
* ``/events`` — one message per event, the object of ``events.jsonl``.
* ``/config`` — the resolved configuration (``{"seed", "version", "config"}``).
* ``/pose``, ``/reference`` — ``foxglove.PoseInFrame`` in frame ``world``: the measured pose
  and the reference (ψ as a yaw quaternion), so Foxglove's 3-D panel draws the flight and its
  path. Rows without a finite position publish none.

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

from ardrone_nmpc.runs.rundir import LOG_COLUMNS, STRING_COLUMNS

__all__ = ["TOPIC_LOG", "TOPIC_EVENTS", "TOPIC_CONFIG", "TOPIC_POSE", "TOPIC_REFERENCE",
           "WORLD_FRAME", "SCHEMAS", "json_bytes", "row_messages", "event_message",
           "config_message", "time_ns", "decode_row"]

TOPIC_LOG = "/log"
TOPIC_EVENTS = "/events"
TOPIC_CONFIG = "/config"
TOPIC_POSE = "/pose"
TOPIC_REFERENCE = "/reference"
WORLD_FRAME = "world"
_POSE_FIELDS = {TOPIC_POSE: ("x_m", "y_m", "z_m", "psi_rad"),
                TOPIC_REFERENCE: ("x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad")}

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
                          (TOPIC_REFERENCE, _POSE_IN_FRAME))}


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


def _pose_message(log_ns: int, x: float, y: float, z: float, psi: float) -> bytes | None:
    if not all(math.isfinite(v) for v in (x, y, z)):
        return None
    half = 0.5 * psi if math.isfinite(psi) else 0.0
    sec, nsec = divmod(log_ns, 1_000_000_000)
    return json_bytes({"timestamp": {"sec": sec, "nsec": nsec}, "frame_id": WORLD_FRAME,
                       "pose": {"position": {"x": x, "y": y, "z": z},
                                "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(half),
                                                "w": math.cos(half)}}})


def _number(row: Mapping[str, Any], key: str) -> float:
    v = row.get(key)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def row_messages(row: Mapping[str, Any], log_ns: int) -> list[tuple[str, bytes]]:
    """``(topic, message)`` of one log row: ``/log`` always, ``/pose`` and ``/reference`` when
    their position is finite."""
    out = [(TOPIC_LOG, json_bytes(row))]
    for topic, keys in _POSE_FIELDS.items():
        msg = _pose_message(log_ns, *(_number(row, k) for k in keys))
        if msg is not None:
            out.append((topic, msg))
    return out


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
