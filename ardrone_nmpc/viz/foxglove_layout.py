"""The Foxglove layout of a flight (``docs/foxglove-layout.json``): the 3-D scene, position
tracking, the commands, the supervisor's modes and the events, on the channels of
:mod:`ardrone_nmpc.runs.channels`.

The file is the layout format Foxglove and Lichtblick import (*Layouts → Import from file*):
``configById`` (one config per panel) and a ``layout`` tree of splits. Regenerate it with
``python -m ardrone_nmpc.viz.foxglove_layout docs/foxglove-layout.json``; a test compares the
committed file with :func:`layout`.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from ardrone_nmpc.runs import channels as ch

__all__ = ["layout", "layout_text", "plotted_fields"]

_POSITION = ("x_m", "x_ref_m", "y_m", "y_ref_m", "z_m", "z_ref_m")
_COMMANDS = ("cmd_roll_frac", "cmd_pitch_frac", "cmd_gaz_frac", "cmd_yaw_frac")
_ATTITUDE = ("nav_roll_deg", "nav_pitch_deg", "psi_rad", "psi_ref_rad")
_HEALTH = ("mocap_age_ms", "navdata_age_ms", "solve_us")


def _plot(title: str, fields: tuple[str, ...]) -> dict[str, Any]:
    return {"title": title,
            "paths": [{"value": f"{ch.TOPIC_LOG}.{name}", "enabled": True,
                       "timestampMethod": "receiveTime"} for name in fields],
            "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True,
            "legendDisplay": "floating", "showPlotValuesInLegend": True, "isSynced": True,
            "xAxisVal": "timestamp", "sidebarDimension": 240}


def _three_d() -> dict[str, Any]:
    line = {"visible": True, "type": "line", "lineWidth": 0.02}
    return {
        "cameraState": {"perspective": True, "distance": 7.0, "phi": 55.0,
                        "thetaOffset": 45.0, "targetOffset": [0, 0, 1.0], "target": [0, 0, 0],
                        "targetOrientation": [0, 0, 0, 1], "fovy": 45, "near": 0.01,
                        "far": 500},
        "followMode": "follow-pose",
        "followTf": ch.WORLD_FRAME,
        "scene": {"transforms": {"labelSize": 0.08, "axisScale": 0.3}},
        "transforms": {f"frame:{ch.DRONE_FRAME}": {"visible": True},
                       f"frame:{ch.REFERENCE_FRAME}": {"visible": True}},
        "topics": {
            ch.TOPIC_FLIGHT_PATH: {**line, "gradient": ["#1f77b4ff", "#1f77b4ff"]},
            ch.TOPIC_REFERENCE_PATH: {**line, "gradient": ["#9e9e9eff", "#9e9e9eff"]},
            ch.TOPIC_POSE: {"visible": False},          # the drone frame (/tf) shows it
            ch.TOPIC_REFERENCE: {"visible": True, "type": "arrow",
                                 "arrowScale": [0.3, 0.05, 0.05], "color": "#9e9e9eff"},
        },
        "layers": {"grid": {"visible": True, "frameLocked": True, "label": "Grid (1 m)",
                            "instanceId": "grid", "layerId": "foxglove.Grid",
                            "frameId": ch.WORLD_FRAME, "size": 10, "divisions": 10,
                            "lineWidth": 1, "color": "#248eff", "position": [0, 0, 0],
                            "rotation": [0, 0, 0], "order": 1}},
    }


def layout() -> dict[str, Any]:
    """The layout as a JSON-ready dict."""
    panels = {
        "3D!flight": _three_d(),
        "Plot!position": _plot("position and reference (m)", _POSITION),
        "Plot!attitude": _plot("navdata roll, pitch (°); heading ψ, ψ_ref (rad)", _ATTITUDE),
        "Plot!commands": _plot("PCMD fractions sent (±1)", _COMMANDS),
        "Plot!health": _plot("mocap / navdata age (ms), solve time (µs)", _HEALTH),
        "StateTransitions!mode": {"isSynced": True, "paths": [
            {"value": f"{ch.TOPIC_LOG}.mode", "timestampMethod": "receiveTime"}]},
        "RawMessages!events": {"topicPath": ch.TOPIC_EVENTS, "diffEnabled": False,
                               "diffMethod": "custom", "diffTopicPath": "",
                               "showFullMessageForDiff": False},
    }
    plots = {"first": "Plot!position",
             "second": {"first": "Plot!attitude", "second": "Plot!commands",
                        "direction": "column"},
             "direction": "column", "splitPercentage": 34}
    bottom = {"first": "StateTransitions!mode",
              "second": {"first": "Plot!health", "second": "RawMessages!events",
                         "direction": "row"},
              "direction": "row", "splitPercentage": 34}
    left = {"first": "3D!flight", "second": bottom, "direction": "column",
            "splitPercentage": 70}
    return {"configById": panels, "globalVariables": {}, "userNodes": {},
            "playbackConfig": {"speed": 1},
            "layout": {"first": left, "second": plots, "direction": "row",
                       "splitPercentage": 55}}


def layout_text() -> str:
    """The layout file's text."""
    return json.dumps(layout(), indent=2, ensure_ascii=False) + "\n"


def plotted_fields() -> set[str]:
    """The ``/log`` fields the layout plots (every one a log column)."""
    return set(_POSITION + _COMMANDS + _ATTITUDE + _HEALTH) | {"mode"}


if __name__ == "__main__":  # python -m ardrone_nmpc.viz.foxglove_layout FILE
    Path(sys.argv[1]).write_text(layout_text(), encoding="utf-8")
