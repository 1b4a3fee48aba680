"""One sender per mocap stream, end to end: a stale ``replay --broadcast``-like sender (frames
numbered from 1, the object at x = 0.8 m) streams into a ``fly --sim`` hover for 3 s. The pose
must never move (no logged x beyond 0.3 m), an event must name the sender, and the flight
must go on. In-process (typer's CliRunner), 127.0.0.1 only."""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

import ardrone_nmpc.links.mocap_link as mocap_link_module
from ardrone_nmpc.cli.app import app
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap
from ardrone_nmpc.runs.rundir import read_run

HOVER = str(Path(__file__).parents[2] / "configs" / "hover.yaml")


@pytest.mark.timeout(90)
def test_a_second_sender_never_moves_the_pose_and_is_named(tmp_path, monkeypatch):
    links = []

    class Captured(mocap_link_module.MocapLink):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            links.append(self)

    monkeypatch.setattr(mocap_link_module, "MocapLink", Captured)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    stale = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stale.bind(("127.0.0.1", 0))
    sent = []

    def hovering_in_the_experiment():  # 20 rows: past the 0.5 s settle, ~0.8 s in
        logs = list(tmp_path.glob("*-hover/log.csv"))
        return logs and len(logs[0].read_bytes().splitlines()) > 20

    def replay():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not hovering_in_the_experiment():
            time.sleep(0.02)
        t_end = time.monotonic() + 3.0
        k = 1
        while time.monotonic() < t_end:
            frame = MocapFrame.of(k, [MocapObjectPose("ardrone", (800.0 + k % 3, 0.0, 1000.0),
                                                      (0.0, 0.0, 0.0))])
            stale.sendto(encode_mocap(frame), ("127.0.0.1", links[0].port))
            sent.append(k)
            k += 1
            time.sleep(0.01)

    sender = threading.Thread(target=replay, daemon=True)
    sender.start()
    try:
        result = CliRunner().invoke(app, ["fly", HOVER, "--sim", "--no-dashboard", "--log-dir",
                                          str(tmp_path), "--duration-s", "6", "--set",
                                          "sim.settle_s=0.5"])
    finally:
        sender.join(timeout=10)
        name = f"127.0.0.1:{stale.getsockname()[1]}"
        stale.close()
    assert result.exit_code == 0, result.stderr
    assert len(sent) > 200  # the stale stream really ran during the flight
    run = Path([l for l in result.stdout.splitlines() if l.startswith("run: ")][-1][5:])
    x = read_run(run).columns["x_m"]
    assert abs(x).max() < 0.3
    events = [json.loads(l) for l in (run / "events.jsonl").read_text().splitlines()]
    foreign = [e for e in events if e["kind"] == "mocap_foreign_sender"]
    assert [e["sender"] for e in foreign] == [name]
    assert foreign[0]["t_s"] > 0.5  # mid-hover, in the experiment (its clock, as every event)
    assert foreign[0]["carries_object"] is True and foreign[0]["frame"] == 1
    assert links[0].foreign_senders[name] == len(sent)
    assert links[0].stats.foreign == len(sent)
