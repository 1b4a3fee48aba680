"""A lockstep flight with its mocap source swapped: the simulator's frames reach the tick
through a MotionCaptureSource whose library is a stand-in (connect / waitForNextFrame /
rigidBodies with quaternions, the libmotioncapture API) instead of the Vicon UDP link. With
occlusion, zero poses, dropouts and a followed second object, the log is the same: every mode,
event and string cell equal, every number equal to within the rounding of the representation
change (Euler angles → quaternion → Euler angles, m → mm → m) as it grows through the
closed loop. Wall-clock columns (solve and compute times, lateness) are this machine's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import ardrone_nmpc.runtime.lockstep as lockstep
import ardrone_nmpc.sim.lockstep_drone as lockstep_drone
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.links.motioncapture_source import MotionCaptureSource
from ardrone_nmpc.protocol.mocap import decode_mocap
from ardrone_nmpc.runs.log_columns import STRING_COLUMNS
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.sim.sensors import LockstepSensors


class _Q:
    def __init__(self, rot: Rotation):
        self.x, self.y, self.z, self.w = rot.as_quat()


class _Body:
    def __init__(self, pose):
        self.position = np.asarray(pose.position_m, dtype=np.float64)
        self.rotation = _Q(Rotation.from_euler("XYZ", pose.rotation_xyz_rad))


class _TrackedSystem:
    """The stand-in of a connected mocap system: the frame handed in is the next one."""

    def __init__(self):
        self.next_bodies: dict = {}
        self.rigidBodies: dict = {}   # noqa: N815 - the library's name

    def waitForNextFrame(self):  # noqa: N802 - the library's name
        self.rigidBodies = self.next_bodies


class _MotionCaptureWire:
    """What the lockstep sensors need of their mocap link (feed, latest, latest_of), served by a
    MotionCaptureSource: each simulated frame becomes the library's next frame."""

    def __init__(self, object_name: str, others: tuple[str, ...]):
        self.now_s = -math.inf
        self.system = _TrackedSystem()
        self.source = MotionCaptureSource("vicon", {"hostname": "sim"}, object_name=object_name,
                                          other_objects=others, clock=lambda: self.now_s,
                                          library=object())
        self.frames = self.source.frames_from(self.system)

    def feed(self, data: bytes, t_s: float) -> None:
        frame = decode_mocap(data)
        self.system.next_bodies = {n: _Body(p) for n, p in frame.poses.items()}
        self.now_s = t_s
        self.source.receive_bodies(*next(self.frames))

    def latest(self):
        return self.source.latest()

    def latest_of(self, name):
        return self.source.latest_of(name)


class _SwappedSensors(LockstepSensors):
    def __init__(self, cfg, drone, on_navdata=None, t_zero_s=math.inf):
        super().__init__(cfg, drone, on_navdata, t_zero_s)
        link = self.mocap
        self.mocap = _MotionCaptureWire(link.object_name, link.other_objects)


def _fly(cfg, path):
    with RunRecorder.create(path, cfg, seed=cfg.sim.seed) as rec:
        lockstep.run_lockstep(cfg, recorder=rec)
    return read_run(rec.path)


POSE_COLUMNS = {"x_m", "y_m", "z_m", "psi_rad", "mocap_t_s", "mocap_age_ms", "target_x_m",
                "target_y_m", "target_z_m", "target_psi_rad", "target_t_s", "target_age_ms"}
WALL_CLOCK_COLUMNS = {"solve_us", "compute_us", "tick_late_ms"}   # this machine's timing
CASES = {
    "step_x": ("configs/step_x.yaml", [
        "duration_s=3", "faults.mocap_occlusion.start_s=0.6", "faults.mocap_occlusion.duration_s=0.3",
        "faults.mocap_occlusion.zero_pose=true", "faults.mocap_dropout.start_s=1.5",
        "faults.mocap_dropout.duration_s=0.4"]),
    "follow_car": ("configs/follow_car.yaml", [
        "duration_s=3", "faults.mocap_occlusion.start_s=1.0",
        "faults.mocap_occlusion.duration_s=0.5"]),
}


@pytest.mark.timeout(300)
@pytest.mark.parametrize("case", sorted(CASES))
def test_swapped_source_gives_the_same_log(case, tmp_path, monkeypatch):
    config, overrides = CASES[case]
    cfg = load_config(config, overrides)
    vicon = _fly(cfg, tmp_path / "vicon")
    monkeypatch.setattr(lockstep_drone, "LockstepSensors", _SwappedSensors)
    swapped = _fly(cfg, tmp_path / "motioncapture")
    assert swapped.n_rows == vicon.n_rows > 40
    assert [(e["t_s"], e["kind"]) for e in swapped.events] == \
        [(e["t_s"], e["kind"]) for e in vicon.events]
    modes = set(vicon.columns["mode"])
    assert modes - {"settle", "track"}, "the faults made the supervisor act"
    for name, a in vicon.columns.items():
        if name in WALL_CLOCK_COLUMNS:
            continue
        b = swapped.columns[name]
        if name in STRING_COLUMNS:
            assert list(a) == list(b), name
            continue
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        ok = ~np.isnan(a)
        # rounding of the representation change (≈ 1e-16) grows through the closed loop:
        # measured on these cases ≤ 8e-11 m in the pose, ≤ 3.2e-9 in a PCMD fraction
        tol = 1e-9 if name in POSE_COLUMNS else 1e-7
        np.testing.assert_allclose(b[ok], a[ok], rtol=1e-6, atol=tol, err_msg=name)
    if case == "follow_car":   # the second object went through the swapped source too
        assert np.isfinite(swapped.columns["target_x_m"]).sum() > 40


@pytest.mark.timeout(120)
def test_fly_reads_a_motioncapture_source(tmp_path):
    """The real-time runner over real UDP to the simulated drone, its poses from the
    libmotioncapture `mock` system (the real library, in its child process)."""
    import threading

    from ardrone_nmpc.experiments.flight import run_flight
    from ardrone_nmpc.sim.loopback import free_udp_port
    from ardrone_nmpc.sim.serve import serve

    at, nav, ctl = free_udp_port(), free_udp_port(), free_udp_port()
    stop = threading.Event()
    server = threading.Thread(target=serve, daemon=True, kwargs=dict(
        cfg=load_config(None, []), at_port=at, navdata_port=nav, control_port=ctl,
        mocap_to=f"127.0.0.1:{free_udp_port()}", echo=lambda *_: None, stop_event=stop))
    server.start()
    c, s = math.cos(0.2), math.sin(0.2)
    cfg = load_config("configs/hover.yaml", [
        "duration_s=1", "sim.settle_s=0.3", "mocap.kind=motioncapture", "mocap.system=mock",
        f"drone.control_port={ctl}",
        # the pose a landed drone has at the start (the pre-flight checks it; the mock's
        # poses do not move)
        f"mocap.options.rigid_bodies=ardrone(0.1,0.2,0.2,{c!r},0,0,{s!r})"])
    try:
        path = run_flight(cfg=cfg, sim=False, drone_host="127.0.0.1", at_port=at,
                          navdata_port=nav, mocap_port=None, log_dir=tmp_path, seed=0)
    finally:
        stop.set()
        server.join(timeout=10)
    run = read_run(path)
    assert run.n_rows >= 15
    np.testing.assert_allclose(run.columns["x_m"], 0.1, atol=1e-6)     # float32 in the library
    np.testing.assert_allclose(run.columns["z_m"], 0.2, atol=1e-6)
    np.testing.assert_allclose(run.columns["psi_rad"], 0.4, atol=1e-6)
    assert np.all(run.columns["mocap_age_ms"] < 100.0)                  # ≈ 100 Hz, fresh
    links = next(e for e in run.events if e["kind"] == "links")
    assert links["mocap"] == "mock@localhost" and links["mocap_port"] is None
