"""`fly --sim` with injected faults: the real-time loop over UDP on 127.0.0.1 against the
loopback servers, which inject the faults of the config's ``faults`` section.

Each test flies a short experiment (settle 0.5 s, fault windows from t = 0.5 s) through the CLI
in-process (typer's CliRunner) and checks how the run ended: the supervisor's modes in log.csv,
the events, the exit code and error line. The loopback and the drone link are captured (by
wrapping their factories) to read the servers' fault counters and the link's statistics.
Only loopback addresses are used; every test has a timeout.
"""

from __future__ import annotations

import heapq
import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

import ardrone_nmpc.links.drone_link as drone_link_module
import ardrone_nmpc.sim.loopback as loopback_module
from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.sim.faults import FaultSchedule
from ardrone_nmpc.protocol.at import REF_BASE, REF_TAKEOFF_BIT, AtCommand, Ref
from ardrone_nmpc.protocol.mocap import decode_mocap
from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.sim.drone_server import DroneServer
from ardrone_nmpc.sim.fault_injection import ServerFaults
from ardrone_nmpc.sim.mocap_server import MocapServer
from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.core.types import FlightMode

ROOT = Path(__file__).parents[2]
HOVER = str(ROOT / "configs" / "hover.yaml")
T0 = 0.5  # fault start (s, experiment time)
LOCALHOST = "127.0.0.1"
NOW = 1000.0  # a monotonic time (s) taken as experiment time 0 by the hand-driven servers


@pytest.fixture
def captured(monkeypatch):
    """The Loopback and DroneLink the flight builds (``captured["loop"]``, ``["link"]``)."""
    got: dict = {}
    real_start = loopback_module.start_loopback

    def start_loopback(*args, **kwargs):
        got["loop"] = real_start(*args, **kwargs)
        return got["loop"]

    class DroneLink(drone_link_module.DroneLink):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            got["link"] = self

    monkeypatch.setattr(loopback_module, "start_loopback", start_loopback)
    monkeypatch.setattr(drone_link_module, "DroneLink", DroneLink)
    return got


def _fly(tmp_path, *sets: str, duration_s: float = 2.0):
    """Run ``fly --sim`` in-process; returns (CLI result, run directory)."""
    args = ["fly", HOVER, "--sim", "--no-dashboard", "--log-dir", str(tmp_path),
            "--set", f"duration_s={duration_s}", "--set", "sim.settle_s=0.5"]
    for s in sets:
        args += ["--set", s]
    result = CliRunner().invoke(app, args)
    lines = [l for l in result.stdout.splitlines() if l.startswith("run: ")]
    assert lines, (result.stdout, result.stderr, result.exception)
    return result, Path(lines[-1][len("run: "):])


def _events(run_dir: Path) -> list[dict]:
    return [json.loads(l) for l in (run_dir / "events.jsonl").read_text().splitlines()]


def _modes(run_dir: Path) -> list[str]:
    return list(read_run(run_dir).columns["mode"])


def _landed_by_navdata(run_dir: Path) -> bool:
    ends = [e for e in _events(run_dir) if e["kind"] == "session_end"]
    return bool(ends) and ends[-1]["landed"] is True


@pytest.mark.timeout(60)
def test_mocap_dropout_hovers_then_tracks_again(tmp_path, captured):
    result, run = _fly(tmp_path, f"faults.mocap_dropout.start_s={T0}",
                       "faults.mocap_dropout.duration_s=0.6", duration_s=2.0)
    assert result.exit_code == 0, result.stderr
    modes = _modes(run)
    assert "hover-stale-mocap" in modes, sorted(set(modes))
    last_hover = len(modes) - 1 - modes[::-1].index("hover-stale-mocap")
    assert "track" in modes[last_hover:]  # recovered once the frames came back
    assert captured["loop"].fault_counters.mocap_dropped > 0
    assert _landed_by_navdata(run)


@pytest.mark.timeout(60)
def test_navdata_loss_lands_with_exit_code_1(tmp_path, captured):
    result, run = _fly(tmp_path, f"faults.navdata_loss.start_s={T0}",
                       "faults.navdata_loss.duration_s=1.0", duration_s=3.0)
    assert result.exit_code == 1
    assert "error: navdata silent" in result.stderr
    assert _modes(run)[-1] == "land-navdata-lost"
    kinds = [(e["kind"], e.get("reason")) for e in _events(run)]
    assert ("landing", "LinkLost") in kinds and ("landed", None) in kinds
    assert captured["loop"].fault_counters.navdata_lost > 0


@pytest.mark.timeout(60)
def test_battery_floor_lands_the_drone(tmp_path, captured):
    result, run = _fly(tmp_path, f"faults.battery_floor.start_s={T0}",
                       "faults.battery_floor.level_pct=19", duration_s=3.0)
    assert result.exit_code == 1
    assert "error: the supervisor landed the drone: land-battery" in result.stderr
    log = read_run(run)
    assert log.columns["mode"][-1] == "land-battery"
    assert log.columns["battery_pct"][-1] == pytest.approx(19.0, abs=1.0)
    assert _landed_by_navdata(run)
    assert captured["link"].navdata.mode.value == "landed"
    assert [ev["fault"] for _, ev in captured["loop"].fault_events] == ["battery_floor"]


@pytest.mark.timeout(60)
def test_emergency_stops_with_a_nonzero_exit(tmp_path, captured):
    result, run = _fly(tmp_path, f"faults.emergency.start_s={T0}", duration_s=3.0)
    assert result.exit_code != 0
    assert "emergency" in result.stderr
    assert _modes(run)[-1] == "stop-emergency"
    assert captured["link"].navdata.mode.value == "emergency"
    t_fault, ev = captured["loop"].fault_events[0]
    assert ev["fault"] == "emergency" and t_fault >= T0


@pytest.mark.timeout(60)
def test_corrupted_navdata_is_counted_as_malformed(tmp_path, captured):
    # 0.2 s of bad checksums: shorter than safety.navdata_land_ms (500 ms), so the flight goes on
    result, run = _fly(tmp_path, f"faults.navdata_corrupt.start_s={T0}",
                       "faults.navdata_corrupt.duration_s=0.2",
                       "faults.navdata_corrupt.kind=checksum", duration_s=1.5)
    assert result.exit_code == 0, result.stderr
    assert captured["loop"].fault_counters.navdata_corrupted > 0
    assert captured["link"].stats.malformed > 0
    assert "land-navdata-lost" not in _modes(run)


@pytest.mark.timeout(60)
def test_at_loss_is_survived(tmp_path, captured):
    result, run = _fly(tmp_path, f"faults.at_loss.start_s={T0}",
                       "faults.at_loss.duration_s=0.5", duration_s=1.5)
    assert result.exit_code == 0, result.stderr
    assert captured["loop"].drone.counters.at_datagrams_lost > 0
    assert captured["loop"].fault_counters.at_lost == \
        captured["loop"].drone.counters.at_datagrams_lost
    assert _landed_by_navdata(run)


@pytest.mark.timeout(60)
def test_wind_gust_pushes_the_drone_and_the_flight_completes(tmp_path, captured):
    result, run = _fly(tmp_path, f"faults.wind_gust.start_s={T0}",
                       "faults.wind_gust.duration_s=0.8",
                       "faults.wind_gust.velocity_mps=[1.5,0,0]", duration_s=2.0)
    assert result.exit_code == 0, result.stderr
    log = read_run(run)
    t, x = log.columns["t_s"], log.columns["x_m"]  # mocap: fly logs no truth
    before, during = x[(t >= 0) & (t < T0)], x[(t >= T0 + 0.2) & (t < T0 + 0.8)]
    assert during.max() > before.max() + 0.02  # drag towards +x
    gust = [ev["on"] for _, ev in captured["loop"].fault_events if ev["fault"] == "wind_gust"]
    assert gust == [True, False]



# ----------------------------------------------------------------------------- the servers
# Server objects driven by hand (never started): their sockets are bound on 127.0.0.1 but
# carry no traffic.

def _server_faults(cfg, plant) -> ServerFaults:
    faults = ServerFaults(FaultSchedule(cfg.faults, 0), plant)
    faults.set_clock(NOW)
    return faults


@pytest.mark.timeout(30)
def test_mocap_frames_delayed_by_a_spike_are_overtaken_and_occluded_ones_lack_the_object():
    cfg = load_config(None, ["faults.mocap_latency.start_s=0.095",
                             "faults.mocap_latency.duration_s=0.03",
                             "faults.mocap_latency.extra_latency_ms=35",
                             "faults.mocap_occlusion.start_s=0.195",
                             "faults.mocap_occlusion.duration_s=0.02"])
    plant = AirframePlant.from_config(cfg.sim, cfg.drone)
    server = MocapServer(plant, target=(LOCALHOST, 9), latency_ms=2.0,
                         faults=_server_faults(cfg, plant))
    try:
        queue: list = []
        for k in range(25):  # frames 0..24 sampled every 10 ms from experiment time 0
            server._sample(k, NOW + 0.01 * k, queue)
        sent = [heapq.heappop(queue) for _ in range(len(queue))]
    finally:
        server.stop()
    frames = [decode_mocap(data) for _, _, data in sent]
    order = [f.frame_number for f in frames]
    # frames 10..12 (spike) are due 35 ms late: 13..15 go out before them
    assert order[:10] == list(range(10))
    assert order.index(13) < order.index(10) < order.index(12) < order.index(17)
    assert sorted(order) == list(range(25))
    assert [due for due, _, _ in sent] == sorted(due for due, _, _ in sent)
    missing = [f.frame_number for f in frames if "ardrone" not in f.poses]
    assert missing == [20, 21]


@pytest.mark.timeout(30)
def test_drone_server_discards_lost_at_datagrams():
    cfg = load_config(None, ["faults.at_loss.start_s=0", "faults.at_loss.duration_s=1"])
    plant = AirframePlant.from_config(cfg.sim, cfg.drone)
    clock = [NOW + 0.5]
    server = DroneServer(plant, clock=lambda: clock[0], faults=_server_faults(cfg, plant))
    takeoff = AtCommand(1, Ref(REF_BASE | REF_TAKEOFF_BIT)).encode()
    try:
        server.handle_at_datagram(takeoff)  # in the window: never reaches the drone
        c = server.counters
        assert (c.at_datagrams_lost, c.at_datagrams_in) == (1, 0)
        assert plant.mode is FlightMode.LANDED
        clock[0] = NOW + 1.0  # window over
        server.handle_at_datagram(takeoff)
        c = server.counters
        assert (c.at_datagrams_lost, c.at_datagrams_in, c.at_commands_applied) == (1, 1, 1)
        assert plant.mode is FlightMode.TAKING_OFF
    finally:
        server.stop()


@pytest.mark.timeout(30)
def test_start_loopback_shares_one_fault_clock_between_the_servers(tmp_path):
    cfg = load_config(None, ["faults.navdata_loss.start_s=1"])
    with loopback_module.start_loopback(cfg, seed=1) as loop:
        assert loop.faults is not None and loop.mocap._faults is loop.faults
        assert loop.drone._drone is loop.simulated and loop.simulated.faults is loop.faults
        assert loop.faults.t_exp(NOW) == -math.inf
        loop.set_fault_clock(NOW)
        assert loop.faults.t_exp(NOW + 2.0) == pytest.approx(2.0)
    with loopback_module.start_loopback(load_config(None), seed=1) as loop:
        assert loop.faults is None and loop.fault_events == []
        loop.set_fault_clock(NOW)  # harmless without faults
