"""The drone's configuration as text: the ``section:key = value`` dump it sends on the control
port (TCP 5559, after ``AT*CTRL=<seq>,4,0``) and the ranges of the keys the tool writes
(docs/protocol.md §3). The client reads this text and the loopback drone writes it: one home,
so the two cannot drift apart."""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["CONTROL_PORT", "EULER_ANGLE_MAX_LIMIT_RAD", "format_config_text",
           "parse_config_text"]

CONTROL_PORT = 5559  # TCP: the configuration dump after AT*CTRL=<seq>,4,0 (docs/protocol.md §1.3)
EULER_ANGLE_MAX_LIMIT_RAD = 0.52  # control:euler_angle_max range 0 … 0.52 rad (30°), §3.1


def parse_config_text(text: str) -> dict[str, str]:
    """The configuration dump (``section:key = value`` lines) as a dict; lines without ``=``
    or without a key are skipped, values are stripped."""
    out: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        key = key.strip()
        if sep and key:
            out[key] = value.strip()
    return out


def format_config_text(values: Mapping[str, str]) -> str:
    """The dump of ``values``, one ``section:key = value`` line each (the drone's layout)."""
    return "".join(f"{k} = {v}\n" for k, v in values.items())
