"""replay: logged measurements back through the tick (determinism), and the pose re-broadcast.

Runs are short lockstep simulations (3.5 s + 0.5 s settle). The inputs the simulator handed
the tick are captured on the way, so the replay's reconstruction is checked against the real
thing, not against itself. Network: 127.0.0.1 only.
"""

from __future__ import annotations

import copy
import math
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.runtime import tick as loop
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.ocp import OcpSpec
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.runs.rundir import LOG_FILE, RunRecorder, read_run
from ardrone_nmpc.reference.trajectories import make_trajectory
from ardrone_nmpc.experiments.replay import (
    CMD_COLUMNS, COMPARED_COLUMNS, RERUN_COLUMNS, ReplayError, broadcast, logged_poses,
    missing_rerun_columns, rerun, rows_to_inputs,
)
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime.lockstep import run_lockstep

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
SHORT = ["duration_s=3.5", "sim.settle_s=0.5"]


def simulate_captured(log_dir: Path, config: str, overrides: list[str], monkeypatch):
    """Simulate into a run directory; return (run, [(inputs, t_exp_s), …] the tick saw) —
    every tick its own step (``BLOCK_TICKS`` 0: a block of ticks makes no step call)."""
    cfg = load_config(CONFIGS / config, SHORT + overrides)
    seen = []
    step = loop.Tick.step

    def capture(self, inputs, *, t_exp_s, **kwargs):
        seen.append((inputs, t_exp_s))
        return step(self, inputs, t_exp_s=t_exp_s, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(lockstep, "BLOCK_TICKS", 0)
        m.setattr(loop.Tick, "step", capture)
        with RunRecorder.create(log_dir, cfg, seed=cfg.sim.seed) as recorder:
            run_lockstep(cfg, recorder=recorder)
    return read_run(recorder.path), seen


def feed_directly(cfg, seen) -> dict[str, np.ndarray]:
    """The commands of a fresh Tick fed the simulator's own inputs (the flight's clock)."""
    tick = loop.Tick(cfg, HoldStartThen(make_trajectory(cfg.reference, duration_s=cfg.duration_s)))
    rows = [tick.step(inputs, t_exp_s=t, mode="settle" if t < 0 else "track").row
            for inputs, t in seen]
    return {c: np.array([r.get(c, math.nan) for r in rows], float) for c in COMPARED_COLUMNS}


CASES = {
    # config, overrides: NMPC + Kalman ż (altitude step), NMPC with navdata ẋ/ẏ and the
    # raw-difference ż (x step), the P controller (ψ step)
    "nmpc-kalman": ("step_z.yaml", ["estimator.kind=kalman"]),
    "nmpc-navdata": ("step_x.yaml", ["estimator.kind=difference",
                                     "estimator.horizontal_velocity=navdata"]),
    "p": ("step_psi.yaml", ["controller.kind=p"]),
    # the supervisor's path: the mocap object occluded from t = 1 s — one pose seen on many
    # ticks, hold, hover, then land (mocap lost) and the runner's logged descent
    "supervisor": ("step_x.yaml", ["faults.mocap_occlusion.start_s=1.0",
                                   "faults.mocap_occlusion.duration_s=1.5"]),
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Each case simulated once: name → (run, captured inputs)."""
    out = {}
    with pytest.MonkeyPatch.context() as mp:
        for name, (config, overrides) in CASES.items():
            out[name] = simulate_captured(tmp_path_factory.mktemp(name), config, overrides, mp)
    return out


# ----------------------------------------------------------------------------- inputs


def test_rows_to_inputs_rebuild_what_the_tick_saw(runs):
    run, seen = runs["nmpc-navdata"]
    inputs = rows_to_inputs(run=run)
    assert len(inputs) == len(seen) == run.n_rows
    for k, (rebuilt, (orig, t_exp)) in enumerate(zip(inputs, seen)):
        assert rebuilt.t_s == t_exp
        np.testing.assert_array_equal(rebuilt.pose.position_m, orig.pose.position_m)
        assert rebuilt.pose.psi_rad == orig.pose.psi_rad
        # ages on the replay clock equal the flight's (to the ms → s round trip)
        assert rebuilt.t_s - rebuilt.pose_rx_t_s == pytest.approx(orig.t_s - orig.pose_rx_t_s,
                                                                  abs=1e-12)
        assert rebuilt.t_s - rebuilt.navdata_rx_t_s == pytest.approx(
            orig.t_s - orig.navdata_rx_t_s, abs=1e-12)
        nav, nav0 = rebuilt.navdata, orig.navdata
        assert (nav.mode, nav.battery_pct, nav.vx_body_mps, nav.vy_body_mps) == (
            nav0.mode, nav0.battery_pct, nav0.vx_body_mps, nav0.vy_body_mps)
        if k:  # the estimators' sample intervals, and "same pose" exactly when it was
            dt = rebuilt.pose.t_s - inputs[k - 1].pose.t_s
            assert dt == pytest.approx(orig.pose.t_s - seen[k - 1][0].pose.t_s, abs=1e-12)
            assert (rebuilt.pose is inputs[k - 1].pose) == (orig.pose is seen[k - 1][0].pose)


# ----------------------------------------------------------------------------- determinism


def test_the_tick_on_the_flights_own_inputs_reproduces_the_log_bit_for_bit(runs):
    """The tick itself is deterministic: whatever a rerun misses, the log lost."""
    run, seen = runs["nmpc-navdata"]
    direct = feed_directly(run.config, seen)
    for c in COMPARED_COLUMNS:
        np.testing.assert_array_equal(direct[c], run.columns[c], err_msg=c)


@pytest.mark.parametrize("case", ["nmpc-kalman", "nmpc-navdata", "p", "supervisor"])
def test_rerun_with_the_logged_config_reproduces_every_command(runs, case):
    run, _ = runs[case]
    result = rerun(run=run, cfg=run.config)
    for c in COMPARED_COLUMNS:
        # the log keeps every bit the tick saw (the raw pose stamp included): exact
        assert result.max_abs_diff[c] == 0.0, (c, result.max_abs_diff[c])
    assert result.mode_mismatches == 0
    # not vacuous: the run did command something
    assert max(np.max(np.abs(run.columns[c])) for c in CMD_COLUMNS) > 0.01
    assert result.cost.rows > 0
    assert result.cost.rerun == pytest.approx(result.cost.logged, rel=1e-9)


def test_rerun_of_a_log_whose_tick_ran_late(runs, tmp_path):
    """As in ``fly``: the tick's clock (wall time) is up to 2 ms past its deadline, which is
    the experiment time it is told. The rerun's clock is the deadline itself."""
    run, seen = runs["nmpc-navdata"]
    cfg = run.config
    tick = loop.Tick(cfg, HoldStartThen(make_trajectory(cfg.reference, duration_s=cfg.duration_s)))
    late = np.random.default_rng(7).uniform(0.0, 2e-3, len(seen))
    with RunRecorder.create(tmp_path, cfg, seed=run.seed) as recorder:
        for (inputs, t), late_s in zip(seen, late):
            on_wall = TickInputs(inputs.t_s + late_s, inputs.pose, inputs.pose_rx_t_s,
                                      inputs.navdata, inputs.navdata_rx_t_s)
            recorder.write_row(tick.step(on_wall, t_exp_s=t,
                                         mode="settle" if t < 0 else "track").row)
    result = rerun(run=read_run(recorder.path), cfg=cfg)
    assert result.max_abs_diff_overall <= 1e-9


def test_the_supervisor_case_went_through_stale_feedback_and_landing(runs):
    run, _ = runs["supervisor"]
    modes = set(run.columns["mode"])
    assert {"hold-stale-mocap", "hover-stale-mocap", "land-mocap-lost", "landing"} <= modes
    result = rerun(run=run, cfg=run.config)
    assert list(result.mode) == list(run.columns["mode"])


def test_rerun_is_deterministic(runs):
    run, _ = runs["nmpc-kalman"]
    a, b = rerun(run=run, cfg=run.config), rerun(run=run, cfg=run.config)
    for c in COMPARED_COLUMNS:
        np.testing.assert_array_equal(a.recomputed[c], b.recomputed[c])


def test_changed_config_gives_the_commands_of_a_tick_fed_directly(runs):
    run, seen = runs["nmpc-kalman"]
    cfg = load_config(run.path / "config.yaml", ["controller.q=[30, 2, 7, 2, 20, 10, 13]"])
    result = rerun(run=run, cfg=cfg)
    assert max(result.max_abs_diff[c] for c in COMPARED_COLUMNS) > 1e-3
    direct = feed_directly(cfg, seen)
    for c in COMPARED_COLUMNS:
        np.testing.assert_allclose(result.recomputed[c], direct[c], rtol=0, atol=1e-9,
                                   err_msg=c)


def test_cost_is_the_ocp_stage_cost_on_the_logged_states(runs):
    run, _ = runs["nmpc-kalman"]
    cfg = load_config(run.path / "config.yaml", ["controller.r=[8, 12, 12, 24]"])
    result = rerun(run=run, cfg=cfg)
    spec = OcpSpec.from_config(cfg.controller)
    traj = HoldStartThen(make_trajectory(cfg.reference, duration_s=cfg.duration_s))
    cols = run.columns
    logged = rerun_cost = 0.0
    for i in np.nonzero(cols["t_s"] >= 0)[0]:
        x = np.array([cols[c][i] for c in ("x_m", "vx_mps", "y_m", "vy_mps", "z_m", "vz_mps",
                                           "psi_rad")])
        ref = traj.state_at(cols["t_s"][i])[0]
        u_log = np.array([cols[c][i] for c in COMPARED_COLUMNS[4:]])
        u_new = np.array([result.recomputed[c][i] for c in COMPARED_COLUMNS[4:]])
        logged += spec.stage_cost(x, ref, u_log) * cfg.loop.period_s
        rerun_cost += spec.stage_cost(x, ref, u_new) * cfg.loop.period_s
    assert result.cost.logged == pytest.approx(logged, rel=1e-12)
    assert result.cost.rerun == pytest.approx(rerun_cost, rel=1e-12)
    assert abs(result.cost.input_rerun - result.cost.input_logged) > 1e-6


def test_rerun_writes_the_recomputed_rows(runs, tmp_path):
    run, _ = runs["p"]
    with RunRecorder.create(tmp_path, run.config, seed=run.seed) as recorder:
        result = rerun(run=run, cfg=run.config, recorder=recorder)
    again = read_run(recorder.path)
    assert again.n_rows == run.n_rows
    for c in COMPARED_COLUMNS:  # bit for bit what the result holds (NaN where none)
        np.testing.assert_array_equal(again.columns[c], result.recomputed[c])
    np.testing.assert_array_equal(again.columns["mocap_t_s"], run.columns["mocap_t_s"])
    assert list(again.columns["mode"]) == list(run.columns["mode"])


# ----------------------------------------------------------------------------- odd logs


def edited_copy(run, tmp_path, edit):
    """A copy of ``run``'s directory whose log.csv went through ``edit(header, rows)``."""
    target = tmp_path / "edited"
    shutil.copytree(run.path, target)
    lines = (target / LOG_FILE).read_text().splitlines()
    header, rows = lines[0].split(","), [line.split(",") for line in lines[1:]]
    header, rows = edit(header, rows)
    (target / LOG_FILE).write_text("\n".join(",".join(r) for r in [header, *rows]) + "\n")
    return read_run(target)


def test_old_log_without_the_measurement_columns_is_refused_by_name(runs, tmp_path):
    run, _ = runs["p"]

    def drop(header, rows):
        keep = [i for i, c in enumerate(header) if c not in RERUN_COLUMNS]
        return [header[i] for i in keep], [[r[i] for i in keep] for r in rows]

    old = edited_copy(run, tmp_path, drop)
    assert missing_rerun_columns(run=old) == list(RERUN_COLUMNS)
    with pytest.raises(ReplayError, match="mocap_t_s, nav_vx_body_mps, nav_vy_body_mps, "
                                          "nav_mode columns"):
        rerun(run=old, cfg=old.config)
    with pytest.raises(ReplayError, match="mocap_t_s"):
        logged_poses(run=old)


def test_a_stale_pose_is_one_pose_and_an_unlogged_one_never_reaches_the_estimator(runs):
    """Rows 20–27 see the pose of row 19 again, ageing past mocap_hover_ms (the tick's
    offset moves mocap_t_s by a few ulps); row 28 brings a new pose whose position was not
    logged (a stale hover), row 29 a fresh pose again."""
    run, _ = runs["nmpc-kalman"]
    cols = copy.deepcopy(run.columns)
    t19 = cols["mocap_t_s"][19]
    for k in range(20, 29):
        cols["mocap_t_s"][k] = t19 + (4e-16 if k % 2 else 0.0)
        cols["mocap_age_ms"][k] = cols["mocap_age_ms"][19] + 65.0 * (k - 19)
    for c in ("x_m", "y_m", "z_m", "psi_rad"):
        cols[c][21:29] = math.nan
    cols["mocap_t_s"][28] = t19 + 0.5  # new, not logged (age says stale)
    stale = copy.copy(run)
    stale.columns = cols
    inputs = rows_to_inputs(run=stale)
    # one pose object: the estimators see no new sample; the ages still grow
    assert all(inputs[k].pose is inputs[19].pose for k in range(20, 29))
    assert inputs[28].t_s - inputs[28].pose_rx_t_s == pytest.approx(
        cols["mocap_age_ms"][28] * 1e-3, abs=1e-12)
    result = rerun(run=stale, cfg=run.config)
    assert result.unlogged_pose_rows == 1
    assert all(str(m).startswith(("hold", "hover", "land")) for m in result.mode[21:29])
    assert np.all(np.isfinite(result.recomputed["cmd_roll_frac"]))
    poses, skipped = logged_poses(run=stale)
    assert skipped == 1
    assert len(poses) == len({float(t) for t in cols["mocap_t_s"]}) - 2  # 20–27 = 19, 28


# ----------------------------------------------------------------------------- broadcast


class RecordingLink(MocapLink):
    """A MocapLink that also keeps every pose it accepted (the real receive path)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.received = []
        self.got_all = threading.Event()
        self.expected = math.inf

    def _handle(self, data, t_s, *sender):
        super()._handle(data, t_s, *sender)
        pose, _ = self.latest()
        if pose is not None and (not self.received or pose is not self.received[-1]):
            self.received.append(pose)
            if len(self.received) >= self.expected:
                self.got_all.set()


@pytest.mark.timeout(30)
def test_broadcast_resends_the_logged_poses_to_a_mocap_link(runs):
    run, _ = runs["nmpc-navdata"]
    poses, skipped = logged_poses(run=run)
    assert skipped == 0 and len(poses) > 50
    with RecordingLink("127.0.0.1", 0, object_name=run.config.mocap.object_name) as link:
        link.expected = len(poses)
        sent = broadcast(run=run, host="127.0.0.1", port=link.port, speed=10.0)
        assert link.got_all.wait(5.0), f"received {len(link.received)} of {len(poses)}"
    assert sent.frames == len(poses)
    assert sent.span_s == pytest.approx(poses[-1].t_s - poses[0].t_s)
    got = np.array([[*p.position_m, p.psi_rad] for p in link.received])
    want = np.array([[*p.position_m, p.psi_rad] for p in poses])
    # metres → millimetres on the wire → metres, ψ → rotation z → atan2: a few ulps
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(want[:, :3], np.column_stack(
        [run.columns[c] for c in ("x_m", "y_m", "z_m")])[:len(want)], atol=0)  # one per tick


def test_broadcast_refuses_other_hosts_unless_allowed_and_bad_speeds(runs):
    run, _ = runs["p"]
    # RFC 5737 documentation address: refused before any socket exists
    with pytest.raises(ValueError, match="not a loopback address"):
        broadcast(run=run, host="192.0.2.1", port=51001, speed=1.0)
    for speed in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ReplayError, match="--speed"):
            broadcast(run=run, port=51001, speed=speed)


def test_broadcast_keeps_the_logged_timing(runs):
    """Deadlines at mocap_t_s spacing / speed, from a fake clock (no real sleeping)."""
    run, _ = runs["p"]
    now = [100.0]
    waits = []

    def sleep(s):
        waits.append(s)
        now[0] += s

    poses, _ = logged_poses(run=run)
    with RecordingLink("127.0.0.1", 0) as link:
        broadcast(run=run, port=link.port, speed=4.0, clock=lambda: now[0], sleep=sleep)
    assert now[0] - 100.0 == pytest.approx((poses[-1].t_s - poses[0].t_s) / 4.0)
    np.testing.assert_allclose(np.cumsum(waits),
                               [(p.t_s - poses[0].t_s) / 4.0 for p in poses[1:]], atol=1e-12)
