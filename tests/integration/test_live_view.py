"""Live view (`fly --foxglove`): a Foxglove WebSocket client written from the protocol
(foxglove_client.py, on tornado) receives the flight's rows; the control thread never waits
for the publisher; the server listens on 127.0.0.1 only."""

from __future__ import annotations

import json
import math
import threading

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs import channels as ch
from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.viz.live import LiveView
from foxglove_client import FoxgloveClient


def _listening_addresses(port: int) -> set[str]:
    """Local addresses of the TCP sockets listening on ``port`` (from /proc, no packets)."""
    found = set()
    for table, width in (("/proc/net/tcp", 8), ("/proc/net/tcp6", 32)):
        try:
            lines = open(table).read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            addr, p = local.split(":")
            if int(p, 16) == port and state == "0A":   # LISTEN
                found.add(addr if width == 32 else ".".join(
                    str(int(addr[i:i + 2], 16)) for i in (6, 4, 2, 0)))
    return found


@pytest.mark.timeout(120)
def test_a_client_receives_the_ticks_of_a_fly_sim_run(tmp_path):
    from ardrone_nmpc.experiments.flight import run_flight

    cfg = load_config("configs/hover.yaml", ["duration_s=2", "sim.settle_s=0.5"])
    with LiveView(0, config=cfg, seed=1) as view:
        assert _listening_addresses(view.port) == {"127.0.0.1"}
        with FoxgloveClient(view.port) as client:
            assert client.subscribed.wait(10) and client.error is None
            assert {c["topic"] for c in client.channels.values()} == set(ch.TOPICS)
            path = run_flight(cfg=cfg, sim=True, drone_host=None, at_port=None,
                              navdata_port=None, mocap_port=None, log_dir=tmp_path, seed=1,
                              sink=view)
            view.close()              # publishes what is queued
            run = read_run(path)
            n_rows = run.n_rows
            n_poses = int(np.isfinite(run.columns["x_m"]).sum())

            def complete():           # every published row and the final whole path arrived
                paths = client.topic_messages("/flight_path")
                return len(client.topic_messages("/log")) >= view.published and paths and \
                    len(client.decode("/flight_path", paths[-1][1]).poses) == n_poses

            for _ in range(200):      # wait for the state, not for a time
                if complete():
                    break
                threading.Event().wait(0.05)
            rows = [ch.decode_row(data) for _, data in client.topic_messages("/log")]
            poses = client.topic_messages("/pose")
            events = [json.loads(data) for _, data in client.topic_messages("/events")]
    assert view.rows_in == n_rows and view.dropped == 0
    assert len(rows) >= 0.9 * n_rows
    # what arrived is the log: the same t_s and positions, bit for bit
    by_t = {float(t): i for i, t in enumerate(run.columns["t_s"])}
    for row in rows:
        i = by_t[row["t_s"]]
        for col in ("x_m", "z_ref_m", "cmd_gaz_frac"):
            want = float(run.columns[col][i])
            assert row[col] == want or (math.isnan(row[col]) and math.isnan(want))
    assert len(poses) >= 0.9 * n_rows
    assert "takeoff" in {e["kind"] for e in events} and "landed" in {e["kind"] for e in events}
    assert len(client.topic_messages("/config")) >= 1   # sent again on subscription
    assert complete()                 # the whole flight path arrived last


class _StuckChannels:
    def __init__(self, gate: threading.Event):
        self.gate = gate

    def log(self, topic, data, log_ns):
        self.gate.wait()


@pytest.mark.timeout(30)
def test_rows_are_dropped_never_waited_for():
    gate = threading.Event()
    view = LiveView(0, queue_size=8)
    view.start()
    try:
        view._channels = _StuckChannels(gate)   # a publisher that hangs
        for k in range(500):
            view.row({"t_s": 0.065 * k, "x_m": 1.0, "y_m": 0.0, "z_m": 1.0, "psi_rad": 0.0})
        # the publisher holds at most one row; the queue at most 8; the rest were dropped
        assert view.rows_in == 500
        assert 500 - 8 - 1 <= view.dropped <= 500 - 8
    finally:
        gate.set()
        view.close()


def test_port_range_is_checked():
    with pytest.raises(ValueError, match="--foxglove-port 70000"):
        LiveView(70000)


@pytest.mark.timeout(120)
def test_simulate_foxglove_serves_the_lockstep_run_at_real_time(tmp_path):
    import socket
    import subprocess
    import sys
    import time
    from pathlib import Path

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "ardrone_nmpc.cli.app", "simulate", "configs/hover.yaml",
         "--quiet", "--log-dir", str(tmp_path), "--set", "duration_s=1.5",
         "--set", "sim.settle_s=0.5", "--foxglove", "--foxglove-port", str(port)],
        cwd=Path(__file__).parents[2], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with FoxgloveClient(port, connect_timeout_s=60) as client:
        assert client.subscribed.wait(60) and client.error is None
        t0 = time.monotonic()
        out, err = proc.communicate(timeout=100)
        paced_s = time.monotonic() - t0
    assert proc.returncode == 0, err
    assert f"live view: ws://127.0.0.1:{port}" in err
    run = read_run(out.strip().splitlines()[-1][len("run: "):])
    assert len(client.topic_messages("/log")) >= 0.9 * run.n_rows
    assert paced_s >= 1.0      # 2 s of flight at real time (unpaced it takes ≈ 0.05 s)


def _wait_for(predicate, timeout_s: float = 10.0) -> bool:
    """Poll ``predicate`` until it holds (a state, not a time) or ``timeout_s`` passes."""
    gate = threading.Event()
    for _ in range(int(timeout_s / 0.02)):
        if predicate():
            return True
        gate.wait(0.02)
    return predicate()


@pytest.mark.timeout(60)
def test_a_refused_client_is_one_event_and_nothing_on_the_terminal(tmp_path, capfd):
    """The SDK speaks only foxglove.sdk.v1: an older client (foxglove.websocket.v1) is
    refused at the handshake. Each refusal used to print a line on stderr; now the first is
    one event of the run, the others are counted, and a current client still connects."""
    from ardrone_nmpc.runs.rundir import RunRecorder

    cfg = load_config(None, ["name=refused"])
    with LiveView(0, config=cfg, seed=0) as view, \
            RunRecorder.create(tmp_path, cfg, seed=0) as recorder:
        sink = view.tee(recorder)
        for _ in range(3):
            old = FoxgloveClient(view.port, subprotocol="foxglove.websocket.v1").start()
            old._thread.join(10)
            assert old.error is not None and "400" in str(old.error)
        assert _wait_for(lambda: view.notices.refused == 3)
        with FoxgloveClient(view.port) as client:
            assert client.subscribed.wait(10) and client.error is None
            # /config went out before this client came: it is sent again on subscription
            assert _wait_for(lambda: client.topic_messages("/config"))
            for k in range(3):
                sink.write_row({"t_s": 0.065 * k, "x_m": 0.0, "y_m": 0.0, "z_m": 1.0,
                                "psi_rad": 0.0, "nav_roll_deg": 2.0, "nav_pitch_deg": -1.0})
            assert _wait_for(lambda: len(client.topic_messages("/tf")) >= 3)
            tf = client.decode("/tf", client.topic_messages("/tf")[0][1])
            assert (tf.parent_frame_id, tf.child_frame_id) == ("world", "drone")
            assert tf.rotation.x != 0.0 and tf.rotation.y != 0.0   # roll and pitch
        sink.event(1.0, "landed")
    events = read_run(recorder.path).events
    refused = [e for e in events if e["kind"] == "foxglove_refused"]
    assert len(refused) == 1 and "foxglove.sdk.v1" in refused[0]["hint"]
    assert refused[0]["client"].startswith("127.0.0.1:")
    assert {"action": "connected"}.items() <= next(
        e for e in events if e["kind"] == "foxglove_client").items()
    out, err = capfd.readouterr()
    assert "handshake" not in out + err and "Dropping client" not in out + err


@pytest.mark.timeout(120)
def test_fly_records_an_mcap_file_as_it_flies(tmp_path):
    """`fly --mcap` (with `--foxglove`: one context, two sinks): the file holds every row,
    a /tf transform per pose, /config once and each whole path once — not the live view's
    re-sent paths."""
    from ardrone_nmpc.experiments.export import read_mcap
    from ardrone_nmpc.experiments.flight import run_flight

    cfg = load_config("configs/hover.yaml", ["duration_s=2", "sim.settle_s=0.5"])
    recording = tmp_path / "flight.mcap"
    with LiveView(0, config=cfg, seed=1, mcap=recording) as view:
        path = run_flight(cfg=cfg, sim=True, drone_host=None, at_port=None, navdata_port=None,
                          mocap_port=None, log_dir=tmp_path, seed=1, sink=view)
    run = read_run(path)
    back = read_mcap(recording)
    assert view.dropped == 0 and len(back.rows) == run.n_rows
    for got, t in zip(back.rows, run.columns["t_s"]):
        assert got["t_s"] == float(t)
    n_poses = int(np.isfinite(run.columns["x_m"]).sum())
    assert len(back.poses["/pose"]) == n_poses
    assert sum(m["child_frame_id"] == "drone" for m in back.poses["/tf"]) == n_poses
    (flight_path,) = back.poses["/flight_path"]
    assert len(flight_path["poses"]) == n_poses
    assert len(back.poses["/reference_path"]) == 1
    assert back.config is not None and back.config["seed"] == 1 and back.n_configs == 1
    assert {"takeoff", "landed"} <= {e["kind"] for e in back.events}


def test_a_recording_that_cannot_be_written_is_one_user_error(tmp_path):
    from ardrone_nmpc.errors import UserError

    nested = tmp_path / "new" / "folder" / "f.mcap"
    with LiveView(0, serve=False, mcap=nested):
        pass
    assert nested.is_file()                      # its folder was made
    with pytest.raises(UserError, match=r"^--mcap /proc/none/f\.mcap: cannot write it: "):
        LiveView(0, serve=False, mcap="/proc/none/f.mcap").start()
