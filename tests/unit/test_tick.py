"""The control tick, one stage at a time (ardrone_nmpc/runtime/stages.py) and as a whole.

Stages are checked against closed forms written here: backward differences of a known pose
sequence, a hand RK4 of model eq. 3.13 for the delay prediction, the first-order velocity filter
for a moving obstacle, eq. 4.16 for the P controller, and the supervisor's policy table
(docs/design.md) for what a verdict sends.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ardrone_nmpc.config.schema import SafetyConfig

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.diverging import DivergingSolver
from ardrone_nmpc.control.mapping import DroneLimits, map_to_pcmd
from ardrone_nmpc.control.obstacles import OBS_COLS, OBS_X, OBS_Z
from ardrone_nmpc.control.ocp import SolveResult, SolverStatus
from ardrone_nmpc.core.types import (
    IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z, AttitudeCommand, FlightMode, MocapPose,
    NavdataSample, TickInputs,
)
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, REQUIRED_COLUMNS, tick_row
from ardrone_nmpc.runtime import tick as tick_module
from ardrone_nmpc.runtime.lockstep import experiment_trajectory
from ardrone_nmpc.runtime.stages import (
    HOVER, Control, DelayPrediction, Estimation, MovingObstacles, Sent, Solution, Supervision,
)
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action, Decision, Supervisor
from ardrone_nmpc.sim.faults import FaultSchedule

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
PERIOD_S = 0.065
G_MPS2 = 9.81


def config(*overrides: str, name: str = "step_x.yaml"):
    return load_config(CONFIGS / name, list(overrides))


def pose(t_s: float, xyz, psi_rad: float = 0.0) -> MocapPose:
    return MocapPose(t_s, np.asarray(xyz, dtype=float), np.zeros(3), psi_rad)


def nav(vx_body: float = 0.0, vy_body: float = 0.0) -> NavdataSample:
    return NavdataSample(0.0, FlightMode.FLYING, 80.0, 0.0, 0.0, 0.0, 1.0, vx_body, vy_body, 0.0)


def inputs(t_s: float, p: MocapPose | None, *, mocap_age_ms: float = 10.0,
           target: MocapPose | None = None) -> TickInputs:
    return TickInputs(t_s, p, t_s - mocap_age_ms * 1e-3, nav(), t_s - 0.02,
                      target, t_s - 0.01 if target is not None else -math.inf)


# ----------------------------------------------------------------------------- estimation
def test_estimation_velocity_is_the_backward_difference_of_the_poses():
    est = Estimation(config("estimator.kind=difference",
                            "estimator.horizontal_velocity=difference").estimator)
    t = np.arange(6) * PERIOD_S
    path = np.column_stack([t ** 2, -2.0 * t + 0.3, 1.0 + 0.5 * t ** 3])  # Δp/Δt ≠ ṗ
    x = est.update(pose(t[0], path[0], 0.4), None, 0.0)
    assert x[[IX_VX, IX_VY, IX_VZ]] == pytest.approx([0.0, 0.0, 0.0])  # nothing to difference
    for k in range(1, len(t)):
        x = est.update(pose(t[k], path[k], 0.4), None, 0.0)
        expected = (path[k] - path[k - 1]) / (t[k] - t[k - 1])
        if k == 1:  # FiniteDifferenceVz's first update after reset only initialises it
            expected[2] = 0.0
        assert x[[IX_VX, IX_VY, IX_VZ]] == pytest.approx(expected, rel=1e-12)
        assert x[[IX_X, IX_Y, IX_Z, IX_PSI]] == pytest.approx([*path[k], 0.4], rel=1e-15)
    # the same pose again (mocap stale): no new difference, the velocity stays
    again = est.update(pose(t[-1], path[-1], 0.4), None, 0.0)
    assert again[[IX_VX, IX_VY, IX_VZ]] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("psi, fwd, right, world", [
    (0.0, 1.0, 0.0, (1.0, 0.0)),
    (0.0, 0.0, 1.0, (0.0, -1.0)),             # right-positive body y is world −y at ψ = 0
    (math.pi / 2, 1.0, 0.0, (0.0, 1.0)),      # nose along +y
    (math.pi / 2, 0.0, 1.0, (1.0, 0.0)),
])
def test_estimation_takes_navdata_velocity_rotated_to_the_world(psi, fwd, right, world):
    est = Estimation(config("estimator.horizontal_velocity=navdata").estimator)
    x = est.update(pose(0.0, [0.0, 0.0, 1.0], psi), nav(fwd, right), 0.0)
    assert x[[IX_VX, IX_VY]] == pytest.approx(world, abs=1e-15)
    # no navdata yet: the mocap differences (zero on the first pose)
    x = Estimation(config().estimator).update(pose(0.0, [0, 0, 1], psi), None, 0.0)
    assert x[[IX_VX, IX_VY]] == pytest.approx([0.0, 0.0])


def test_estimation_feeds_the_vz_estimator_the_applied_zacc():
    est = Estimation(config("estimator.kind=kalman").estimator)
    calls = []

    class Recording:  # stands in for the Kalman filter: what does the stage hand it?
        vz_mps = 0.25

        def reset(self, z_m):
            calls.append(("reset", z_m))

        def update(self, z_m, zacc_mps2, dt_s):
            calls.append(("update", z_m, zacc_mps2, dt_s))

    est.vz_estimator = Recording()
    est.update(pose(0.0, [0, 0, 1.0]), None, 0.7)
    x = est.update(pose(0.05, [0, 0, 1.1]), None, -0.3)
    assert calls == [("reset", 1.0), ("update", 1.1, -0.3, 0.05)]
    assert x[IX_VZ] == 0.25


# ----------------------------------------------------------------------------- delay
def eq_3_13(x, u):
    """Thesis eq. 3.13, written out again here."""
    _, vx, _, vy, _, vz, psi = x
    zacc, phi, theta, psirate = u
    thrust = zacc + G_MPS2
    tphi, tth, cth = math.tan(phi), math.tan(theta), math.cos(theta)
    ax = (math.sin(psi) * tphi / cth + math.cos(psi) * tth) * thrust
    ay = (-math.cos(psi) * tphi / cth + math.sin(psi) * tth) * thrust
    return np.array([vx, ax, vy, ay, vz, zacc, psirate])


def hand_rk4(x, inputs_, dt):
    x = np.array(x, dtype=float)
    for u in inputs_:
        k1 = eq_3_13(x, u)
        k2 = eq_3_13(x + 0.5 * dt * k1, u)
        k3 = eq_3_13(x + 0.5 * dt * k2, u)
        k4 = eq_3_13(x + dt * k3, u)
        x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def test_delay_prediction_is_an_rk4_rollout_of_the_pending_inputs():
    delay = DelayPrediction(0.2, PERIOD_S)
    assert delay.delay_ticks == 4 and delay.lead_s == pytest.approx(4 * PERIOD_S)
    x = np.array([0.1, 0.2, -0.3, 0.1, 1.0, 0.05, 0.4])
    us = [np.array([0.5, 0.1, -0.05, 0.2]), np.array([-0.2, -0.1, 0.15, -0.3]),
          np.array([0.1, 0.05, 0.05, 0.0]), np.array([0.0, 0.2, 0.0, 0.1]),
          np.array([0.3, 0.0, -0.2, 0.0])]
    zero = np.zeros(4)
    delay.push(us[0])
    delay.push(us[1])  # start-up: the two ticks before the first command are hovers
    np.testing.assert_allclose(delay.predict(x), hand_rk4(x, [zero, zero, us[0], us[1]], PERIOD_S),
                               rtol=1e-12, atol=1e-12)
    for u in us[2:]:
        delay.push(u)  # only the newest four are still on their way
    np.testing.assert_allclose(delay.predict(x), hand_rk4(x, us[1:], PERIOD_S),
                               rtol=1e-12, atol=1e-12)
    assert not np.allclose(delay.predict(x), x)


def test_without_delay_or_pending_inputs_the_estimate_is_solved_from():
    x = np.array([0.1, 0.2, -0.3, 0.1, 1.0, 0.05, 0.4])
    assert DelayPrediction(0.26, PERIOD_S).predict(x) is x  # nothing sent yet
    none = DelayPrediction(0.0, PERIOD_S)
    none.push(np.ones(4))
    assert none.delay_ticks == 0 and none.predict(x) is x


# ----------------------------------------------------------------------------- obstacles
class FakeSolver:
    def __init__(self, n: int) -> None:
        self.obstacles = np.zeros((n, OBS_COLS))
        self.obstacles[:, OBS_X:OBS_Z + 1] = [[2.0, 0.0, 0.0], [5.0, 5.0, 0.0]][:n]
        self.moved = []

    def move_obstacles(self, centres_m):
        self.moved.append(np.array(centres_m))


def test_moving_obstacle_is_placed_ahead_at_its_filtered_velocity():
    solver = FakeSolver(2)
    stage = MovingObstacles(solver, [0], ahead_s=0.5)
    stage.update(pose(0.0, [0.0, 0.0, 0.0]))
    np.testing.assert_allclose(solver.moved[-1], [[0, 0, 0], [5, 5, 0]])  # no velocity yet
    stage.update(pose(0.1, [0.1, 0.2, 0.0]))
    a = 0.1 / (0.1 + 0.2)  # filter gain Δt/(Δt + τ), τ = 0.2 s
    v = a * np.array([0.1, 0.2, 0.0]) / 0.1
    np.testing.assert_allclose(solver.moved[-1][0], np.array([0.1, 0.2, 0.0]) + 0.5 * v, rtol=1e-12)
    np.testing.assert_allclose(solver.moved[-1][1], [5, 5, 0])  # a fixed obstacle stays
    stage.update(pose(0.1, [0.1, 0.2, 0.0]))  # the same frame again: no new difference
    np.testing.assert_allclose(stage.track.velocity_mps, v, rtol=1e-12)


def test_moving_obstacles_exist_only_for_a_configured_mocap_object():
    assert Tick(config(), experiment_trajectory(config())).obstacles is None
    cfg = config(name="moving_obstacle.yaml")
    tick = Tick(cfg, experiment_trajectory(cfg))
    assert tick.obstacles.indices == [0]
    assert tick.obstacles.ahead_s == pytest.approx(
        tick.delay.lead_s + cfg.controller.obstacle_lookahead_s)
    tick.step(inputs(0.0, pose(0.0, [0, 0, 1]), target=pose(0.0, [0.7, -0.4, 0.0])), t_exp_s=0.0)
    assert tick.control.nmpc.obstacles[0, OBS_X:OBS_Z + 1] == pytest.approx([0.7, -0.4, 0.0])


# ----------------------------------------------------------------------------- control
def eq_4_16(x, ref, g):
    """The P controller of thesis eq. 4.16 (body-frame errors), written out again here."""
    ex = ref[IX_X] - x[IX_X] - x[IX_VX]
    ey = ref[IX_Y] - x[IX_Y] - x[IX_VY]
    c, s = math.cos(x[IX_PSI]), math.sin(x[IX_PSI])
    return (g.k1_per_s * (ref[IX_Z] - x[IX_Z]), -g.k2_rad_per_mps * (-s * ex + c * ey),
            g.k3_rad_per_mps * (c * ex + s * ey), g.k4_per_s * (ref[IX_PSI] - x[IX_PSI]))


def state(x=0.2, vx=0.1, y=-0.1, vy=0.0, z=0.9, vz=0.0, psi=0.3):
    return np.array([x, vx, y, vy, z, vz, psi])


def test_p_controller_is_dispatched_without_a_solver():
    cfg = config("controller.kind=p")
    tick = Tick(cfg, experiment_trajectory(cfg))
    assert tick.control.nmpc is None
    x = state()
    sol = tick.control.solve(0.5, x, tick.trajectory)
    assert sol.result is None and sol.status == "" and math.isnan(sol.zacc_mps2)
    ref = tick.trajectory.state_at(0.5)[0]
    cmd = tick.control.command(Action.CONTROL, sol, x, 0.0)
    expected = eq_4_16(x, ref, cfg.controller.p_gains)
    assert (cmd.vz_ref_mps, cmd.phi_rad, cmd.theta_rad, cmd.psirate_radps) == \
        pytest.approx(expected, rel=1e-12)


def test_nmpc_is_dispatched_and_solves_from_the_delay_predicted_state():
    cfg = config()
    tick = Tick(cfg, experiment_trajectory(cfg))
    assert tick.control.nmpc is not None
    x = state()
    u = np.array([0.5, 0.05, -0.05, 0.1])
    tick.delay.push(u)
    sol = tick.control.solve(0.5, x, tick.trajectory)
    assert sol.result is not None and sol.ok  # a cold start may stop at max-iterations
    assert sol.status == sol.result.status.value != SolverStatus.DIVERGED.value
    n_hover = tick.delay.delay_ticks - 1
    np.testing.assert_allclose(sol.x_solve, hand_rk4(x, [np.zeros(4)] * n_hover + [u], PERIOD_S),
                               rtol=1e-12, atol=1e-12)
    assert sol.ref_now == pytest.approx(tick.trajectory.state_at(0.5)[0])


def test_injected_divergence_acts_in_its_window_only_and_the_solver_still_runs():
    cfg = config("faults.solver_diverge.start_s=1.0", "faults.solver_diverge.duration_s=0.5")
    diverges = FaultSchedule(cfg.faults).solver_diverges
    tick = Tick(cfg, experiment_trajectory(cfg),
                wrap_solver=lambda nmpc: DivergingSolver(nmpc, diverges))
    before, inside, after = (tick.control.solve(t, state(), tick.trajectory)
                             for t in (0.935, 1.0, 1.5))
    assert before.ok and after.ok and "diverged" not in (before.status, after.status)
    assert not inside.ok and inside.status == SolverStatus.DIVERGED.value
    assert np.isfinite(inside.result.u).all()  # solved (warm start carries on), not flown
    assert tick.supervisor.check_solution(inside.ok, inside.u_flown).action is Action.HOLD


def test_the_wrapper_marks_the_control_stages_prepared_solve_too():
    """The fast path's ``solve_prepared`` is the wrapper's own, not forwarded past its mark;
    what it solves is the inner solver's, bit for bit."""
    cfg = config()
    plain = Tick(cfg, experiment_trajectory(cfg))
    wrapped = Tick(cfg, experiment_trajectory(cfg),
                   wrap_solver=lambda nmpc: DivergingSolver(nmpc, lambda t_s: t_s >= 1.0))
    for t in (0.5, 0.565, 1.0, 1.065):
        a = plain.control.solve(t, state(), plain.trajectory)
        b = wrapped.control.solve(t, state(), wrapped.trajectory)
        assert a.result.u.tobytes() == b.result.u.tobytes()
        assert a.result.residual_norm == b.result.residual_norm
        assert b.status == (SolverStatus.DIVERGED.value if t >= 1.0 else a.status)
        assert b.ok == (a.ok and t < 1.0)
    x = np.array(state())
    ref = np.tile(x, (plain.control.nmpc.spec.horizon_steps + 1, 1))
    assert wrapped.control.nmpc.solve_prepared(2.0, x, ref).status is SolverStatus.DIVERGED


def test_only_a_wrapper_the_runner_builds_makes_the_solver_diverge():
    cfg = config("faults.solver_diverge.start_s=-100", "faults.solver_diverge.duration_s=1e3")
    plain = Tick(cfg, experiment_trajectory(cfg))  # a faults section alone injects nothing
    wrapped = Tick(cfg, experiment_trajectory(cfg),
                   wrap_solver=lambda nmpc: DivergingSolver(nmpc, lambda t_s: t_s >= 0.0))
    for tick, status in ((plain, "ok"), (wrapped, "diverged")):
        settle = tick.step(inputs(0.0, pose(0.0, [0, 0, 1])), t_exp_s=-0.065, mode="settle")
        track = tick.step(inputs(0.065, pose(0.065, [0, 0, 1])), t_exp_s=0.0)
        assert settle.row["solver_status"] != "diverged" and settle.row["mode"] == "settle"
        assert track.row["solver_status"] in (status, "max-iterations")
    assert track.row["solver_status"] == "diverged" and track.row["mode"] == "hold-solver"


def test_control_command_of_each_verdict():
    cfg = config()
    limits = DroneLimits(0.21, 0.7, 1.745)
    spec = SimpleNamespace(spec=SimpleNamespace(horizon_steps=3))
    control = Control(cfg, limits, spec, DelayPrediction(0.0, PERIOD_S))
    x, ref = state(vz=0.1), state(x=1.0, z=1.0, psi=0.0)
    result = SolveResult(np.array([0.2, 0.1, -0.1, 0.3]), SolverStatus.OK, 0.0, 1, 1.0)
    sol = Solution(ref, x, result, result.u, True, "ok")
    cmd = control.command(Action.CONTROL, sol, x, vz_ref_last_mps=-0.4)
    assert cmd == AttitudeCommand(0.1 + 0.2 * cfg.controller.vz_lead_s, 0.1, -0.1, 0.3)
    fallback = control.command(Action.FALLBACK, sol, x, 0.0)
    assert (fallback.vz_ref_mps, fallback.phi_rad, fallback.theta_rad, fallback.psirate_radps) == \
        pytest.approx(eq_4_16(x, ref, cfg.controller.p_gains), rel=1e-12)
    for action in (Action.HOLD, Action.HOVER, Action.LAND, Action.STOP):
        assert control.command(action, sol, x, 0.0) is None
    big = SolveResult(np.array([5.0, 0.0, 0.0, 0.0]), SolverStatus.OK, 0.0, 1, 1.0)
    clipped = control.command(Action.CONTROL, Solution(ref, x, big, big.u), x, 0.0)
    assert clipped.vz_ref_mps == limits.control_vz_max_mps  # no wind-up past the drone's clip
    # without a ż estimate the z̈ is integrated from the ż reference last sent
    blind = Control(config("estimator.kind=none"), limits, spec, DelayPrediction(0.0, PERIOD_S))
    assert blind.command(Action.CONTROL, sol, x, -0.4).vz_ref_mps == \
        pytest.approx(-0.4 + 0.2 * cfg.controller.vz_lead_s)


def test_effective_controller_plans_within_the_drones_limits():
    cfg = config()
    ctl = tick_module.effective_controller(cfg.controller, DroneLimits(0.21, 0.7, 1.5))
    tilt = 0.21 * cfg.controller.planned_tilt_frac  # the margin below the drone's tilt limit
    assert tilt < 0.21
    assert ctl.u_max == pytest.approx((1.0, tilt, tilt, 1.0))
    assert ctl.u_min == pytest.approx((-1.0, -tilt, -tilt, -1.0))


# ----------------------------------------------------------------------------- supervision
LIMITS = DroneLimits(0.5, 0.7, 1.745)
CMD = AttitudeCommand(0.2, 0.1, -0.05, 0.3)


def supervision() -> Supervision:
    return Supervision(Supervisor(SafetyConfig()), LIMITS)


def test_hold_resends_the_last_command_not_a_level_zero_one():
    sup = supervision()
    first = sup.command(Decision(Action.CONTROL), CMD, 0.4)
    held = sup.command(Decision(Action.HOLD, "stale-mocap"), None, math.nan)
    assert held.progressive and held.decision == Decision(Action.HOLD, "stale-mocap")
    assert held.pcmd == first.pcmd and held.pcmd.roll_frac == pytest.approx(0.1 / 0.5)
    np.testing.assert_array_equal(held.u, [0.4, 0.1, -0.05, 0.3])  # z̈ goes on acting
    assert sup.zacc_mps2 == 0.4 and sup.vz_ref_mps == 0.2
    assert held.flown is None  # nothing new: no vz_ref/cmd_saturated in the row


def test_hold_with_nothing_sent_hovers_and_a_hover_forgets_the_last_command():
    sup = supervision()
    out = sup.command(Decision(Action.HOLD, "solver"), None, math.nan)
    assert out.decision == Decision(Action.HOVER, "solver") and not out.progressive
    assert out.pcmd == HOVER
    sup.command(Decision(Action.CONTROL), CMD, 0.4)
    hover = sup.command(Decision(Action.HOVER, "speed"), None, math.nan)
    assert not hover.progressive and sup.vz_ref_mps == 0.0 and sup.zacc_mps2 == 0.0
    assert sup.command(Decision(Action.HOLD, "stale-mocap"), None, math.nan).decision.action \
        is Action.HOVER


def test_commands_are_tilt_clipped_and_flagged_and_nonfinite_ones_never_sent():
    sup = supervision()  # max_tilt_rad 0.35
    out = sup.command(Decision(Action.CONTROL), AttitudeCommand(0.0, 0.45, -0.1, 0.0), math.nan)
    assert out.flown.phi_rad == 0.35 and out.saturated == "1000"
    assert out.pcmd == map_to_pcmd(AttitudeCommand(0.0, 0.35, -0.1, 0.0), LIMITS)
    assert out.u[0] == 0.0  # the P controller commands no z̈
    bad = sup.command(Decision(Action.CONTROL), AttitudeCommand(0.0, math.nan, 0.0, 0.0), 0.1)
    assert bad.decision == Decision(Action.HOVER, "nonfinite-command") and bad.pcmd == HOVER


def test_fallback_flies_the_p_command_without_the_nmpc_zacc():
    sup = supervision()
    out = sup.command(Decision(Action.FALLBACK, "solver"), CMD, 0.4)
    assert out.progressive and out.u[0] == 0.0 and out.flown == CMD


# ----------------------------------------------------------------------------- the row
def test_row_holds_the_measurements_state_solution_and_command():
    target = pose(0.98, [0.5, 0.6, 0.1], 0.2)
    inp = TickInputs(1.0, pose(0.99, [0.1, 0.2, 1.0], 0.3), 0.99, nav(0.4, -0.1), 0.97,
                     target, 0.995)
    x = state()
    result = SolveResult(np.array([0.2, 0.1, -0.1, 0.3]), SolverStatus.OK, 1e-3, 7, 321.0, 2)
    sol = Solution(state(x=1.0, y=2.0, z=3.0, psi=0.5), x, result, result.u, True, "ok")
    sent = Sent(map_to_pcmd(CMD, LIMITS), np.zeros(4), True, Decision(Action.FALLBACK, "solver"),
                CMD, "0010")
    row = tick_row(t_exp_s=0.5, inputs=inp, ages_ms=(10.0, 30.0), x=x, solution=sol, sent=sent,
                   mode="fallback-solver", compute_us=55.0)
    assert set(REQUIRED_COLUMNS) <= set(row) <= set(LOG_COLUMNS)
    assert row["t_s"] == 0.5 and row["mocap_age_ms"] == 10.0 and row["navdata_age_ms"] == 30.0
    assert (row["x_m"], row["vx_mps"], row["y_m"], row["z_m"], row["psi_rad"]) == \
        (0.2, 0.1, -0.1, 0.9, 0.3)
    assert (row["x_ref_m"], row["y_ref_m"], row["z_ref_m"], row["psi_ref_rad"]) == (1, 2, 3, 0.5)
    # the NMPC's z̈ as solved, the P command actually flown for the rest
    assert row["u_zacc_mps2"] == 0.2
    assert (row["u_phi_rad"], row["u_theta_rad"], row["u_psirate_radps"]) == (0.1, -0.05, 0.3)
    assert row["vz_ref_mps"] == 0.2 and row["cmd_saturated"] == "0010"
    assert row["cmd_roll_frac"] == sent.pcmd.roll_frac and row["cmd_yaw_frac"] == sent.pcmd.yaw_frac
    assert (row["solver_status"], row["solve_us"], row["gmres_iterations"],
            row["newton_iterations"], row["residual_norm"]) == ("ok", 321.0, 7, 2, 1e-3)
    assert row["mocap_t_s"] == 0.99 and row["nav_vy_body_mps"] == -0.1
    assert row["nav_mode"] == "flying"
    assert row["target_x_m"] == 0.5 and row["target_age_ms"] == pytest.approx(5.0)
    assert row["mode"] == "fallback-solver" and row["compute_us"] == 55.0


def test_row_of_a_tick_without_pose_or_solution():
    inp = TickInputs(1.0, None, -math.inf, None, -math.inf)
    sent = Sent(HOVER, np.zeros(4), False, Decision(Action.LAND, "mocap-lost"))
    row = tick_row(t_exp_s=0.5, inputs=inp, ages_ms=(math.inf, math.inf), x=None, solution=None,
                   sent=sent, mode="land-mocap-lost", compute_us=1.0)
    assert row["solver_status"] == "" and row["cmd_saturated"] == "0000"
    assert "x_m" not in row and "u_phi_rad" not in row and "vz_ref_mps" not in row
    assert "target_x_m" not in row and math.isnan(row["mocap_t_s"]) and row["nav_mode"] == ""
    assert row["cmd_pitch_frac"] == 0.0


# ----------------------------------------------------------------------------- the whole tick
def fly(tick: Tick, n: int, xyz=(0.4, 0.0, 1.0), t0: float = 0.0):
    return [tick.step(inputs(t0 + k * PERIOD_S, pose(t0 + k * PERIOD_S, xyz)), t_exp_s=k * PERIOD_S)
            for k in range(n)]


def test_tick_flies_the_nmpc_and_logs_every_required_column():
    cfg = config()
    tick = Tick(cfg, experiment_trajectory(cfg))
    out = fly(tick, 3)[-1]
    assert out.action is Action.CONTROL and out.progressive and out.events == []
    assert set(REQUIRED_COLUMNS) <= set(out.row) <= set(LOG_COLUMNS)
    assert out.row["mode"] == "track" and out.row["solver_status"] == "ok"
    assert out.row["x_m"] == 0.4 and out.row["x_ref_m"] == 0.0
    assert out.row["cmd_pitch_frac"] > 0.0  # 0.4 m ahead of the set point: pitch back (PCMD +)
    assert out.pcmd.pitch_frac == out.row["cmd_pitch_frac"]


def test_tick_holds_then_hovers_on_a_stale_pose():
    cfg = config()
    tick = Tick(cfg, experiment_trajectory(cfg))
    last = fly(tick, 2)[-1]
    p = pose(0.065, [0.4, 0.0, 1.0])  # the pose stops coming
    held = tick.step(inputs(0.2, p, mocap_age_ms=150.0), t_exp_s=0.2)
    assert held.row["mode"] == "hold-stale-mocap" and held.progressive
    assert held.pcmd == last.pcmd and held.pcmd.pitch_frac != 0.0
    assert [e["mode"] for e in held.events] == ["hold-stale-mocap"]
    hover = tick.step(inputs(0.3, p, mocap_age_ms=300.0), t_exp_s=0.3)
    assert hover.row["mode"] == "hover-stale-mocap" and not hover.progressive
    assert hover.pcmd == HOVER


def test_tick_without_a_pose_lands():
    cfg = config()
    out = Tick(cfg, experiment_trajectory(cfg)).step(inputs(0.0, None), t_exp_s=0.0)
    assert out.action is Action.LAND and not out.progressive
    assert out.row["mode"] == "land-mocap-lost" and "x_m" not in out.row


def test_tick_flies_the_p_controller_when_configured():
    cfg = config("controller.kind=p")
    tick = Tick(cfg, experiment_trajectory(cfg))
    row = fly(tick, 1, xyz=(0.2, -0.1, 0.9))[0].row
    assert row["solver_status"] == "" and "solve_us" not in row and math.isnan(row["u_zacc_mps2"])
    x = state(vx=0.0, psi=0.0)  # the first pose: no velocity yet
    expected = eq_4_16(x, tick.trajectory.state_at(0.0)[0], cfg.controller.p_gains)
    assert (row["vz_ref_mps"], row["u_phi_rad"], row["u_theta_rad"]) == \
        pytest.approx(expected[:3], rel=1e-12)


def test_follow_reference_is_fed_the_second_object():
    cfg = config(name="follow_car.yaml")
    tick = Tick(cfg, experiment_trajectory(cfg))
    assert tick.follow is tick.trajectory
    assert Tick(config("controller.kind=p"), experiment_trajectory(config())).follow is None
    out = tick.step(inputs(0.0, pose(0.0, [0, 0, 1]), target=pose(0.0, [0.5, 0.2, 0.0])),
                    t_exp_s=0.0)
    offset = cfg.reference.follow.offset_m
    assert (out.row["x_ref_m"], out.row["y_ref_m"], out.row["z_ref_m"]) == \
        pytest.approx((0.5 + offset[0], 0.2 + offset[1], 0.0 + offset[2]))


def test_tick_inputs_live_in_core_and_sim_does_not_import_runtime():
    assert tick_module.TickInputs is TickInputs
    code = ("import sys, ardrone_nmpc.sim.sensors, ardrone_nmpc.sim.faults; "
            "bad = [m for m in sys.modules if m.startswith('ardrone_nmpc.runtime')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120,
                   env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
