"""Reference kind 'follow' (issue 8): the live object reference, the scripted object, the link
that tracks it, and the closed loop following it."""

import math
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.reference.live import LiveTarget
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.sim.target import target_state
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.runs.summary import read_summary, summarise
from ardrone_nmpc.core.types import MocapPose

CONFIGS = Path(__file__).parents[2] / "configs"


def pose(t_s, xyz, psi=0.0):
    return MocapPose(t_s=t_s, position_m=np.array(xyz, float), rotation_xyz_rad=np.zeros(3),
                     psi_rad=psi)


def live(**follow):
    overrides = ["reference.kind=follow", "reference.start_m=[1,2,1]"]
    overrides += [f"reference.follow.{k}={v}" for k, v in follow.items()]
    return LiveTarget(load_config(None, overrides).reference)


def test_before_the_object_is_seen_the_reference_holds_start():
    ref = live()
    np.testing.assert_array_equal(ref.state_at([0.0, 5.0])[:, [0, 2, 4]], [[1, 2, 1]] * 2)
    assert not ref.seen


def test_constant_velocity_object_is_extrapolated_over_the_horizon():
    ref = live(velocity_filter_s=1e-9)  # the last difference, unfiltered
    v = np.array([0.3, -0.1, 0.0])
    for k in range(5):
        t = 0.01 * k
        ref.observe(pose(t, v * t), t_pose_s=t, age_ms=0.0)
    t_last = 0.04
    got = ref.state_at([t_last, t_last + 1.0, t_last + 10.0])
    expected = v * t_last + np.array([0, 0, 1.0])  # default offset: 1 m above
    np.testing.assert_allclose(got[0, [0, 2, 4]], expected, atol=1e-12)
    np.testing.assert_allclose(got[1, [0, 2, 4]], expected + v * 1.0, atol=1e-9)
    np.testing.assert_allclose(got[2, [0, 2, 4]], expected + v * 3.0, atol=1e-9)  # capped 3 s
    np.testing.assert_allclose(got[1, [1, 3, 5]], v, atol=1e-9)


def test_velocity_filter_is_first_order():
    ref = live(velocity_filter_s=0.2)
    ref.observe(pose(0.0, [0, 0, 0]), t_pose_s=0.0, age_ms=0.0)
    ref.observe(pose(0.1, [0.1, 0, 0]), t_pose_s=0.1, age_ms=0.0)  # 1 m/s difference
    a = 0.1 / (0.1 + 0.2)
    assert ref.state_at(0.1)[0, 1] == pytest.approx(a * 1.0)


def test_stale_object_is_held_not_extrapolated():
    ref = live(velocity_filter_s=1e-9, max_age_ms=100)
    ref.observe(pose(0.0, [0, 0, 0]), t_pose_s=0.0, age_ms=0.0)
    ref.observe(pose(0.1, [0.1, 0, 0]), t_pose_s=0.1, age_ms=0.0)
    ref.observe(pose(0.1, [0.1, 0, 0]), t_pose_s=0.1, age_ms=150.0)  # same pose, now stale
    np.testing.assert_allclose(ref.state_at([0.2, 1.0])[:, 0], [0.1, 0.1])


def test_offset_in_the_object_frame_and_object_heading():
    ref = live(offset_frame="object", offset_m="[1,0,0.5]", heading="object")
    ref.observe(pose(0.0, [2, 0, 0], psi=math.pi / 2), t_pose_s=0.0, age_ms=0.0)
    s = ref.state_at(0.0)[0]
    np.testing.assert_allclose(s[[0, 2, 4]], [2.0, 1.0, 0.5], atol=1e-12)
    assert s[6] == pytest.approx(math.pi / 2)
    with pytest.raises(ConfigError, match=r"reference\.follow\.offset_frame"):
        load_config(None, ["reference.follow.offset_frame=body"])


@pytest.mark.parametrize("path", ["circle", "figure8"])
def test_scripted_object_moves_at_its_velocity(path):
    cfg = load_config(None, [f"sim.target.path={path}", "sim.target.radius_m=1.5",
                             "sim.target.speed_mps=0.4", "sim.target.center_m=[1,0,0.2]"]).sim.target
    h = 1e-6
    for t in (0.0, 1.3, 7.9):
        p0, psi, vel = target_state(cfg, t)
        p1, _, _ = target_state(cfg, t + h)
        np.testing.assert_allclose((p1 - p0) / h, vel, atol=1e-5)  # velocity = dp/dt
        assert psi == pytest.approx(math.atan2(vel[1], vel[0]))
        assert p0[2] == 0.2
    if path == "circle":
        assert np.linalg.norm(vel) == pytest.approx(0.4)
        assert np.linalg.norm(p0[:2] - [1, 0]) == pytest.approx(1.5)


def test_mocap_link_tracks_a_second_object():
    link = MocapLink("127.0.0.1", 0, object_name="ardrone", other_objects=("car",))
    frame = MocapFrame.of(1, [MocapObjectPose("ardrone", (0.0, 0.0, 1000.0), (0.0, 0.0, 0.0)),
                              MocapObjectPose("car", (500.0, -250.0, 0.0), (0.0, 0.0, 0.3))])
    link.feed(encode_mocap(frame), 2.0)
    car, rx = link.latest_of("car")
    np.testing.assert_allclose(car.position_m, [0.5, -0.25, 0.0])
    assert car.psi_rad == pytest.approx(0.3) and rx == 2.0
    assert link.latest()[0].position_m[2] == 1.0
    assert link.latest_of("truck") == (None, -math.inf)


def fly(tmp_path, *overrides):
    cfg = load_config(CONFIGS / "follow_car.yaml", ["duration_s=12", *overrides])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        run_lockstep(cfg, recorder=rec)
    rec.write_summary(summarise(read_run(rec.path)))
    return read_run(rec.path), {(r.axis, r.metric): r.value for r in read_summary(rec.path)}


def test_closed_loop_follows_the_car_and_prediction_helps(tmp_path):
    run, figures = fly(tmp_path)
    c = run.columns
    t = c["t_s"]
    late = t > 5
    # the drone stays 1 m above the car (true positions), within the lag of a 0.3 m/s car
    gap = np.sqrt((c["x_true_m"] - c["target_x_m"]) ** 2 + (c["y_true_m"] - c["target_y_m"]) ** 2)
    assert np.max(gap[late]) < 0.2
    np.testing.assert_allclose(c["z_true_m"][late] - c["target_z_m"][late], 1.0, atol=0.05)
    # 0.155 m with the robust default weights (0.097 m with the thesis', which fly only a
    # drone like the simulator's: docs/robustness.md)
    assert figures[("xyz", "rmse")] < 0.2
    _, blind = fly(tmp_path, "reference.follow.predict=false")
    assert blind[("xyz", "rmse")] > 2 * figures[("xyz", "rmse")]


def test_rerun_of_a_follow_flight_is_exact(tmp_path):
    from ardrone_nmpc.experiments.replay import rerun

    run, _ = fly(tmp_path, "duration_s=4")
    result = rerun(run=run, cfg=run.config)
    assert max(result.max_abs_diff.values()) == 0.0


def test_path_plot_draws_the_followed_object(tmp_path):
    from ardrone_nmpc.viz.plots import figure_path3d

    run, _ = fly(tmp_path, "duration_s=3")
    fig = figure_path3d(run)
    top = fig.axes[1]
    lines = {line.get_label(): line for line in top.get_lines()}
    assert "followed object" in lines and "reference (follow, logged)" in lines
    shown = lines["followed object"].get_xdata()
    logged = run.columns["target_x_m"][(run.columns["t_s"] >= 0)]
    np.testing.assert_array_equal(shown, logged[np.isfinite(logged)])


# ----------------------------------------------------------------------------- moving obstacle
def test_one_second_object_per_experiment():
    with pytest.raises(ConfigError, match="one second mocap object per experiment"):
        load_config(CONFIGS / "moving_obstacle.yaml",
                    ["reference.kind=follow", "reference.follow.object_name=car",
                     "reference.start_m=[0,2,1]"])


def test_moving_obstacle_is_avoided_and_measured_where_it_was(tmp_path):
    from ardrone_nmpc.control.obstacles import clearance_m

    cfg = load_config(CONFIGS / "moving_obstacle.yaml", ["duration_s=14"])
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        run_lockstep(cfg, recorder=rec)
    rec.write_summary(summarise(read_run(rec.path)))
    run = read_run(rec.path)
    c = run.columns
    figures = {(r.axis, r.metric): r.value for r in read_summary(rec.path)}
    obstacle = cfg.controller.obstacles[0]
    # the summary measures from the cart's logged position on each tick
    seen = np.isfinite(c["target_x_m"]) & (c["mode"] != "landing")
    rel = np.column_stack([c["x_true_m"] - c["target_x_m"], c["y_true_m"] - c["target_y_m"],
                           c["z_true_m"]])[seen] + np.array(obstacle.center_m) * [1, 1, 0]
    assert figures[("obstacle0", "min_clearance")] == pytest.approx(
        clearance_m(rel, obstacle).min(), abs=1e-12)
    # the cart drove through the set point, and the drone kept its margin (less 5 cm)
    gap = np.hypot(c["target_x_m"][seen], c["target_y_m"][seen])
    assert gap.min() < 0.1
    assert figures[("obstacle0", "clearance_violations")] == 0
    assert figures[("obstacle0", "min_clearance")] > obstacle.margin_m - 0.05
    # without the look-ahead the same cart gets closer than that
    cfg0 = load_config(CONFIGS / "moving_obstacle.yaml",
                       ["duration_s=14", "controller.obstacle_lookahead_s=0"])
    with RunRecorder.create(tmp_path, cfg0, seed=0) as rec0:
        run_lockstep(cfg0, recorder=rec0)
    worse = {(r.axis, r.metric): r.value for r in summarise(read_run(rec0.path))}
    assert worse[("obstacle0", "min_clearance")] < figures[("obstacle0", "min_clearance")]
