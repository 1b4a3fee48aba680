"""`mocap-check` end to end: through the real libmotioncapture `mock` system (its child
process), through the Vicon UDP stream of the loopback simulator `sim-drone` serves, and the
hand-carry axis test. Only 127.0.0.1 is used."""

from __future__ import annotations

import math
import re
import threading
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.cli.mocap_check import AxisTest, final_line
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.links.mocap_factory import open_mocap_source
from ardrone_nmpc.sim.loopback import free_udp_port

LINE = re.compile(r"^(?P<name>\S+): x=(?P<x>-?\d+\.\d{3}) y=(?P<y>-?\d+\.\d{3}) "
                  r"z=(?P<z>-?\d+\.\d{3}) psi=(?P<psi>-?\d+\.\d{3}) rate=(?P<rate>\d+\.\d{3})$")


def _lines(output: str) -> dict[str, dict[str, float]]:
    out = {}
    for line in output.splitlines():
        m = LINE.match(line)
        if m:
            out[m["name"]] = {k: float(m[k]) for k in ("x", "y", "z", "psi", "rate")}
    return out


def _mock_body(name, xyz, yaw_rad):
    c, s = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return f"{name}({xyz[0]},{xyz[1]},{xyz[2]},{c!r},0,0,{s!r})"


@pytest.mark.timeout(60)
def test_mocap_check_through_the_motioncapture_mock_prints_its_pose():
    bodies = ";".join([_mock_body("ardrone", (1.234, -0.567, 0.891), math.pi / 4),
                       _mock_body("car", (-2.5, 0.25, 0.0), -2.0)])
    result = CliRunner().invoke(app, [
        "mocap-check", "configs/follow_car.yaml", "--seconds", "1.5", "--no-live",
        "--set", "mocap.kind=motioncapture", "--set", "mocap.system=mock",
        "--set", f"mocap.options.rigid_bodies={bodies}"])
    assert result.exit_code == 0, result.output
    got = _lines(result.output)
    assert set(got) == {"ardrone", "car"}
    drone, car = got["ardrone"], got["car"]
    assert (drone["x"], drone["y"], drone["z"]) == (1.234, -0.567, 0.891)
    assert abs(drone["psi"] - math.pi / 4) <= 1e-3          # 45° yaw, within 1 mrad
    assert (car["x"], car["y"], car["z"]) == (-2.5, 0.25, 0.0)
    assert abs(car["psi"] - -2.0) <= 1e-3
    assert drone["rate"] > 50.0                              # the mock streams ≈ 100 Hz
    assert "axis test: +x ·  +y ·  +z ·  yaw CCW ·" in result.output


@pytest.mark.timeout(60)
def test_y_up_systems_are_turned_into_z_up_end_to_end():
    cfg = load_config(None, ["mocap.kind=motioncapture", "mocap.system=mock",
                             "mocap.up_axis=y",
                             f"mocap.options.rigid_bodies={_mock_body('ardrone', (1, 2, 3), 0)}"])
    with open_mocap_source(cfg.mocap) as src:
        for _ in range(500):
            if src.poses:
                break
            threading.Event().wait(0.01)
        pose, _ = src.latest()
    assert pose.position_m.tolist() == pytest.approx([1.0, -3.0, 2.0], abs=1e-6)
    assert src._child.poll() is not None            # the library process is gone


@pytest.mark.timeout(60)
def test_mocap_check_reads_the_sim_drone_stream():
    port = free_udp_port()
    overrides = ["sim.plant.initial_position_m=[0.8,-0.3,0.0]", "sim.plant.initial_psi_rad=0.6",
                 "sim.noise.mocap_angle_std_rad=0.0", "sim.noise.mocap_position_std_m=0.0002"]
    from ardrone_nmpc.sim.serve import serve

    stop = threading.Event()
    server = threading.Thread(target=serve, kwargs=dict(
        cfg=load_config(None, overrides), at_port=0, navdata_port=0,
        mocap_to=f"127.0.0.1:{port}", echo=lambda *_: None, stop_event=stop), daemon=True)
    server.start()
    try:
        result = CliRunner().invoke(app, [
            "mocap-check", "configs/hover.yaml", "--seconds", "1", "--no-live",
            "--set", "mocap.bind_host=127.0.0.1", "--set", f"mocap.port={port}"])
    finally:
        stop.set()
        server.join(timeout=10)
    assert result.exit_code == 0, result.output
    drone = _lines(result.output)["ardrone"]
    assert abs(drone["x"] - 0.8) <= 1e-3 and abs(drone["y"] + 0.3) <= 1e-3
    assert abs(drone["z"]) <= 1e-3 and abs(drone["psi"] - 0.6) <= 1e-3
    assert drone["rate"] > 50.0                              # 100 Hz stream


@pytest.mark.timeout(30)
def test_mocap_check_without_the_object_fails_in_one_line():
    port = free_udp_port()
    result = CliRunner().invoke(app, [
        "mocap-check", "configs/hover.yaml", "--seconds", "0.3", "--no-live",
        "--set", "mocap.bind_host=127.0.0.1", "--set", f"mocap.port={port}"])
    assert result.exit_code == 1
    assert "ardrone: not seen" in result.output
    assert "error: object 'ardrone' not seen from udp 127.0.0.1:" in result.output


def test_mocap_check_reports_a_missing_extra_in_one_line(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "motioncapture", None)
    result = CliRunner().invoke(app, ["mocap-check", "configs/hover.yaml", "--no-live",
                                      "--set", "mocap.kind=motioncapture"])
    assert result.exit_code == 1
    assert result.output.strip() == ("error: mocap.kind 'motioncapture' needs the "
                                     "'motioncapture' library: pip install 'ardrone-nmpc[mocap]'")


# ----------------------------------------------------------------------------- axis test


def test_axis_test_marks_each_sign():
    t = AxisTest()
    t.update((1.0, 1.0, 0.0), 0.0)
    t.update((1.05, 1.0, 0.0), 0.0)          # too small: nothing yet
    assert t.line() == "axis test: +x ·  +y ·  +z ·  yaw CCW ·"
    t.update((1.12, 1.03, 0.0), 0.0)         # carried forward
    t.update((1.0, 0.85, 0.0), 0.0)          # carried right: a mirrored y would show this
    t.update((1.0, 1.0, 0.3), 0.0)           # lifted
    t.update((1.0, 1.0, 0.0), 0.5)           # turned CCW
    assert [t.mark(a) for a in ("+x", "+y", "+z", "yaw CCW")] == ["✔", "✘", "✔", "✔"]
    t.update((1.0, 1.2, 0.0), 0.0)           # now left: the sign is right
    assert t.mark("+y") == "✔"


def test_axis_test_counts_only_the_dominant_axis_and_wraps_yaw():
    t = AxisTest()
    t.update((0.0, 0.0, 0.0), 3.0)
    t.update((0.12, 0.2, 0.0), 3.0)          # mostly +y: x not credited
    assert (t.mark("+x"), t.mark("+y")) == ("·", "✔")
    t.update((0.0, 0.0, 0.0), -2.9)          # 3.0 → −2.9 across ±π is +0.38 rad: CCW
    assert t.mark("yaw CCW") == "✔"


def test_final_line_format():
    track = SimpleNamespace(name="ardrone", pose=SimpleNamespace(
        position_m=(1.2344, -0.0001, 0.8916), psi_rad=-0.0004), rate_hz=lambda: 99.5)
    assert final_line(track) == "ardrone: x=1.234 y=0.000 z=0.892 psi=0.000 rate=99.500"


def test_run_check_renders_the_live_table_and_runs_the_axis_test():
    from rich.console import Console

    from ardrone_nmpc.cli.mocap_check import run_check

    class Source:   # a source whose drone is carried 20 cm forward during the check
        where, names_seen, missing, zero_poses, repeats = "test", ("ardrone", "wand"), 2, 0, 0
        max_gap_s = 0.01

        def __init__(self):
            self.n = 0

        def latest(self):
            self.n += 1
            x = 0.2 if self.n > 3 else 0.0
            return SimpleNamespace(position_m=(x, 0.0, 1.0), psi_rad=0.0), 0.0

        def fresh_count(self, name):
            return 10 * self.n

    tables = []
    result = run_check(Source(), ["ardrone"], 0.3, live=tables.append)
    text = Console(width=120, record=True)
    text.print(tables[-1])
    shown = text.export_text()
    assert "ardrone" in shown and "stream objects: ardrone, wand" in shown and "2/0/0" in shown
    assert result.axes.mark("+x") == "✔" and result.tracks[0].rate_hz() > 0


@pytest.mark.timeout(60)
def test_mocap_check_json_through_the_motioncapture_mock():
    import json

    body = _mock_body("ardrone", (0.5, 0.25, 1.0), 0.3)
    result = CliRunner().invoke(app, [
        "mocap-check", "configs/hover.yaml", "--seconds", "1.5", "--no-live", "--json",
        "--set", "mocap.kind=motioncapture", "--set", "mocap.system=mock",
        "--set", f"mocap.options.rigid_bodies={body}"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    (drone,) = doc["objects"]
    assert drone["name"] == "ardrone" and drone["seen"]
    assert (drone["x_m"], drone["y_m"], drone["z_m"]) == pytest.approx((0.5, 0.25, 1.0),
                                                                       abs=1e-6)
    assert drone["psi_rad"] == pytest.approx(0.3, abs=1e-3)
    assert drone["rate_hz"] > 50.0 and drone["fresh_poses"] > 50
    # a ≈ 100 Hz stream read every 50 ms: a reader never saw it older than a few samples
    assert 0.0 <= drone["max_age_ms"] < 1000.0
    assert 0.0 < doc["max_gap_ms"] < 1000.0
    assert (doc["missing_frames"], doc["zero_frames"], doc["frozen_frames"]) == (0, 0, 0)
    assert doc["stream_objects"] == ["ardrone"]
    assert doc["axis_test"] == {"+x": "not done", "+y": "not done", "+z": "not done",
                                "yaw CCW": "not done"}


@pytest.mark.timeout(60)
def test_piped_mocap_check_prints_the_streams_counts():
    """Piped (no live table), the counts are a line of their own: a streaming object, then
    one the mock streams as the all-zero pose (what Vicon sends for an occluded object)."""
    def check(xyz):
        return CliRunner().invoke(app, [
            "mocap-check", "configs/hover.yaml", "--seconds", "1.0", "--no-live",
            "--set", "mocap.kind=motioncapture", "--set", "mocap.system=mock",
            "--set", f"mocap.options.rigid_bodies={_mock_body('ardrone', xyz, 0)}"])

    pattern = (r"stream: missing=(\d+) zero=(\d+) frozen=(\d+) max_age_ms=(\d+|—) "
               r"max_gap_ms=(\d+|—)")
    seen = check((0, 0, 1))
    assert seen.exit_code == 0, seen.output
    (line,) = [ln for ln in seen.stdout.splitlines() if ln.startswith("stream: ")]
    m = re.fullmatch(pattern, line)
    assert m and m.groups()[:3] == ("0", "0", "0") and int(m[5]) > 0, line
    occluded = check((0, 0, 0))
    assert occluded.exit_code == 1
    (line,) = [ln for ln in occluded.stdout.splitlines() if ln.startswith("stream: ")]
    m = re.fullmatch(pattern, line)
    assert m and int(m[2]) > 10 and (m[4], m[5]) == ("—", "—"), line


def test_the_largest_gap_between_fresh_poses_is_measured_at_receipt():
    """docs/mocap-stream.md: missing, all-zero and repeated frames are not fresh; the gap is
    the time from one fresh pose to the next (receipt stamps)."""
    from ardrone_nmpc.links.mocap_source import MocapSource
    from ardrone_nmpc.protocol.mocap import MocapObjectPose

    class Fed(MocapSource):   # the base class's rules, fed by hand
        def start(self): pass
        def close(self): pass
        where = "hand"

    src = Fed(object_name="ardrone")
    pose = lambda x: {"ardrone": MocapObjectPose("ardrone", (x, 0.0, 1000.0), (0.0, 0.0, 0.0))}
    zero = {"ardrone": MocapObjectPose("ardrone", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))}
    frames = [(0.00, pose(1.0)), (0.01, pose(2.0)), (0.02, {}), (0.03, zero), (0.04, zero),
              (0.05, pose(3.0)), (0.06, pose(3.0)), (0.07, pose(3.0)), (0.08, pose(3.0)),
              (0.09, pose(4.0))]
    for t, frame in frames:
        src.accept_frame(frame, t)
    assert (src.missing, src.zero_poses, src.repeats) == (1, 2, 2)   # 3rd and 4th repeat
    assert src.max_gap_s == pytest.approx(0.04)   # 0.01 → 0.05, longer than 0.06 → 0.09
