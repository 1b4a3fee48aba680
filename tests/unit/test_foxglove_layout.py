"""docs/foxglove-layout.json: regenerated, it is the committed file; every panel it lays out
exists, and every topic, field and frame it names is one the run's channels publish."""

from __future__ import annotations

import json
from pathlib import Path

from ardrone_nmpc.runs import channels as ch
from ardrone_nmpc.runs.rundir import LOG_COLUMNS
from ardrone_nmpc.viz.foxglove_layout import layout, layout_text, plotted_fields

COMMITTED = Path(__file__).parents[2] / "docs" / "foxglove-layout.json"


def test_the_committed_layout_is_the_generated_one():
    assert COMMITTED.read_text(encoding="utf-8") == layout_text(), (
        "regenerate: python -m ardrone_nmpc.viz.foxglove_layout docs/foxglove-layout.json")


def _leaves(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    return _leaves(node["first"]) + _leaves(node["second"])


def test_every_panel_is_laid_out_once_and_names_what_the_channels_publish():
    doc = json.loads(COMMITTED.read_text(encoding="utf-8"))
    leaves = _leaves(doc["layout"])
    assert sorted(leaves) == sorted(doc["configById"]) and len(set(leaves)) == len(leaves)
    paths = [p["value"] for cfg in doc["configById"].values() for p in cfg.get("paths", [])]
    assert paths and all(p.startswith(ch.TOPIC_LOG + ".") for p in paths)
    fields = {p.split(".", 1)[1] for p in paths}
    assert fields == plotted_fields() and fields <= set(LOG_COLUMNS)
    three_d = doc["configById"]["3D!flight"]
    assert set(three_d["topics"]) <= set(ch.TOPICS)
    assert three_d["followTf"] == ch.WORLD_FRAME
    assert {k.split(":", 1)[1] for k in three_d["transforms"]} == {ch.DRONE_FRAME,
                                                                   ch.REFERENCE_FRAME}
    assert doc["configById"]["RawMessages!events"]["topicPath"] == ch.TOPIC_EVENTS
    assert layout() == doc
