"""Obstacle avoidance: the penalty and its gradients against finite differences, the residual
and merit cost with obstacles, the tie-break geometry, config validation, the summary metrics,
and closed-loop lockstep flights past a cylinder on the straight path."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from ardrone_nmpc import model
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control import kernels as K
from ardrone_nmpc.control import obstacles as O
from ardrone_nmpc.control.cgmres import CGMRESController
from ardrone_nmpc.control.ocp import OcpSpec
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.runs.summary import CLEARANCE_TOLERANCE_M, clearance_stats, summarise
from tests.conftest import thesis_cost

CONFIG = "configs/obstacle.yaml"
N = 8
DTAU = 0.1
RHO = 0.05
WEIGHT = 500.0


def _obstacle(kind, centre, radius=0.3, margin=0.3):
    return SimpleNamespace(kind=kind, center_m=tuple(centre), radius_m=radius, margin_m=margin)


def _table(obstacles, weight=WEIGHT, shift=0.0):
    return O.obstacle_table(obstacles, weight, shift)


def _fd_grad(fun, x, eps=1e-6):
    g = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        up, um = x.copy(), x.copy()
        up[idx] += eps
        um[idx] -= eps
        g[idx] = (fun(up) - fun(um)) / (2 * eps)
    return g


# ----------------------------------------------------------------------------- penalty


@pytest.mark.parametrize("penalty, gradient", [
    (O.penalty, O.penalty_gradient),  # the plain-Python definitions
    (K.penalty, K.penalty_gradient),  # as the kernels compile them
], ids=["python", "compiled"])
@pytest.mark.parametrize("point", [
    (0.95, 0.2, 1.3),  # near the sphere's boundary
    (0.65, 0.1, 1.05),  # deep in the sphere
    (1.1, 0.1, 1.0),  # in both
    (2.1, 0.3, 0.2),  # in the cylinder only (its height is unbounded)
])
def test_penalty_gradient_is_the_derivative_of_the_penalty(penalty, gradient, point):
    table = _table([_obstacle("sphere", (0.6, 0.0, 1.0)), _obstacle("cylinder", (1.6, 0.0, 9.0))])
    p = np.array(point)
    fd = _fd_grad(lambda q: penalty(table, *q), p)
    assert np.linalg.norm(fd) > 1.0  # the point is inside: there is a gradient to check
    np.testing.assert_allclose(gradient(table, *p, *p), fd, rtol=1e-6, atol=1e-6)


def test_penalty_is_zero_outside_and_a_cylinder_ignores_height():
    table = _table([_obstacle("sphere", (0.0, 0.0, 1.0)), _obstacle("cylinder", (3.0, 0.0, 1.0))])
    assert O.penalty(table, 0.0, 0.0, 1.61) == 0.0  # just beyond d = 0.6 above the sphere
    assert O.penalty_gradient(table, 0.0, 0.0, 1.61, 0.0, 0.0, 1.61) == (0.0, 0.0, 0.0)
    low, high = O.penalty(table, 3.1, 0.0, -5.0), O.penalty(table, 3.1, 0.0, 50.0)
    assert low == high > 0.0
    assert O.penalty_gradient(table, 3.1, 0.0, 7.0, 3.1, 0.0, 7.0)[2] == 0.0


def test_penalty_value():
    """½ w (d² − r²)² inside, for a sphere of d = 0.6 at distances r from its centre."""
    table = _table([_obstacle("sphere", (0.0, 0.0, 0.0))])
    for r in (0.59, 0.45, 0.3, 0.0):
        assert O.penalty(table, 0.0, r, 0.0) == pytest.approx(0.5 * WEIGHT * (0.36 - r * r) ** 2,
                                                              rel=1e-12)


def test_frozen_direction_gives_the_gauss_newton_curvature():
    """With f fixed, ∂g/∂p = 4 w (f − c)(f − c)ᵀ: the exact Hessian less its negative part
    −2 w e I (e = d² − ‖p − c‖²)."""
    c = np.array([0.0, 0.0, 1.0])
    table = _table([_obstacle("sphere", c)])
    f = np.array([0.3, 0.2, 1.1])  # e = 0.36 − 0.14 = 0.22
    jac = np.vstack([_fd_grad(lambda p: K.penalty_gradient(table, *p, *f)[j], f)
                     for j in range(3)])
    np.testing.assert_allclose(jac, 4 * WEIGHT * np.outer(f - c, f - c), rtol=1e-6, atol=1e-6)
    exact = np.vstack([_fd_grad(lambda p: K.penalty_gradient(table, *p, *p)[j], f)
                       for j in range(3)])
    e = 0.36 - np.sum((f - c) ** 2)
    np.testing.assert_allclose(exact - jac, -2 * WEIGHT * e * np.eye(3), rtol=1e-5, atol=1e-5)


def test_tie_break_moves_the_centre_left_of_the_line_of_sight_and_covers_the_obstacle(rng):
    c = (1.0, 2.0, 1.0)
    table = _table([_obstacle("cylinder", c)], shift=0.05)
    x = np.zeros(7)
    x[0], x[2] = 1.0, 0.0  # the drone due −y of the obstacle: its line of sight is +y
    K.aim_obstacles(table, x)
    # +y turned 90° counter-clockwise is −x: the penalised region moved to the drone's left
    np.testing.assert_allclose(table[0, [O.OBS_EX, O.OBS_EY]], [0.95, 2.0])
    assert table[0, O.OBS_EDIST] == pytest.approx(0.65)
    # every point within d of the true centre is within d + s of the moved one, and the point
    # d to the right of the true centre is on both boundaries
    pts = np.array(c[:2]) + rng.uniform(-0.6, 0.6, (500, 2))
    inside = np.hypot(*(pts - c[:2]).T) < 0.6
    assert inside.sum() > 100
    assert np.all(np.hypot(pts[inside, 0] - 0.95, pts[inside, 1] - 2.0) < 0.65)
    assert O.penalty(table, 1.601, 2.0, 0.0) == 0.0
    assert O.penalty(table, 1.599, 2.0, 0.0) > 0.0
    # no line of sight (right above the axis): no shift
    x[0], x[2] = 1.0, 2.0
    K.aim_obstacles(table, x)
    np.testing.assert_allclose(table[0, [O.OBS_EX, O.OBS_EY, O.OBS_EDIST]], [1.0, 2.0, 0.6])


# ----------------------------------------------------------------------------- residual


@pytest.fixture
def problem(rng):
    """A horizon whose predicted positions run through a sphere and a cylinder."""
    q = rng.uniform(1, 5, 7)
    qf = rng.uniform(0, 3, 7)
    r = rng.uniform(1, 5, 4)
    W = np.zeros((5, 7))
    W[0], W[1], W[2, :4], W[3, :4], W[4, :4] = q, qf, r, -1.0, 1.0
    x0 = np.array([0.0, 1.5, 0.1, 0.0, 1.0, 0.1, 0.2])
    ref = rng.normal(size=(N + 1, 7))
    u = rng.uniform(-0.5, 0.5, (N, 4))
    xs = _rollout(x0, u)
    table = _table([_obstacle("sphere", xs[3, [0, 2, 4]] + [0.1, 0.25, 0.05]),
                    _obstacle("cylinder", xs[6, [0, 2, 4]] + [0.05, -0.35, 4.0])])
    p = dict(q=q, qf=qf, r=r, W=W, x0=x0, ref=ref, u=u, obs=table)
    intrusions = _intrusions(xs, table)
    assert np.sum(intrusions > 0) >= 4, "the scenario must put stages inside the obstacles"
    return p


def _rollout(x0, u):
    return _rollout_dt(x0, u, DTAU)


def _rollout_dt(x0, u, dtau):
    """The solver's prediction: forward Euler of eq. 3.13 through the inputs (N, 4)."""
    xs = [np.array(x0, float)]
    for ui in u:
        xs.append(xs[-1] + model.f(xs[-1], ui) * dtau)
    return np.array(xs)


def _intrusions(xs, table):
    out = []
    for x in xs:
        for row in table:
            off = x[[0, 2, 4]] - row[[O.OBS_EX, O.OBS_EY, O.OBS_EZ]]
            if row[O.OBS_KIND] == O.KIND_CYLINDER:
                off[2] = 0.0
            out.append(row[O.OBS_EDIST] ** 2 - off @ off)
    return np.array(out)


def _penalised_cost(p, u):
    """J − ρΔτ Σ v + Δτ Σ_{i=0..N} P(x_i): the cost the condensed residual is the gradient of."""
    v = np.sqrt(1.0 - u ** 2)  # box ±1: the dummy inputs
    xs = _rollout(p["x0"], u)
    pen = sum(O.penalty(p["obs"], x[0], x[2], x[4]) for x in xs)
    return (thesis_cost(p["x0"], p["ref"], u, q=p["q"], r=p["r"], qf=p["qf"], dtau=DTAU)
            - RHO * DTAU * v.sum() + DTAU * pen)


def _residual(p, U, **kwargs):
    out = np.zeros(U.size)
    xs = np.zeros((N + 1, 7))
    norm = K.residual(U, K.STAGE_CONDENSED, p["x0"], p["ref"], DTAU, p["W"], RHO, 0.0,
                      K.NO_ACTIVE, xs, np.zeros((N + 1, 5)), out, False, p["obs"], **kwargs)
    return out, norm, xs


def test_residual_with_obstacles_is_the_gradient_of_the_penalised_cost(problem):
    """The penalty's gradient enters the costates (λ̇ = −H_x): F = ∇_U J / Δτ still."""
    p = problem
    F, norm, _ = _residual(p, p["u"].reshape(-1).copy())
    expected = _fd_grad(lambda u: _penalised_cost(p, u), p["u"]) / DTAU
    scale = np.abs(expected).max()
    np.testing.assert_allclose(F.reshape(N, 4), expected, rtol=1e-6, atol=1e-6 * scale)
    # and the obstacles matter: without them F is a different vector
    F_free = np.zeros_like(F)
    K.residual(p["u"].reshape(-1).copy(), K.STAGE_CONDENSED, p["x0"], p["ref"], DTAU, p["W"],
               RHO, 0.0, K.NO_ACTIVE, np.zeros((N + 1, 7)), np.zeros((N + 1, 5)), F_free)
    assert np.abs(F - F_free).max() > 0.1 * scale


def test_frozen_directions_at_the_base_rollout_give_the_exact_residual(problem):
    """The Gauss–Newton products start from the exact F: at U itself the frozen directions
    are the exact ones."""
    p = problem
    U = p["u"].reshape(-1).copy()
    F, _, xs = _residual(p, U)
    base = np.ascontiguousarray(xs[:, [0, 2, 4]])
    F_gn, _, _ = _residual(p, U, base=base, gauss_newton=True)
    np.testing.assert_allclose(F_gn, F, rtol=1e-14, atol=1e-12)


def _merit(p, U):
    _, _, xs = _residual(p, U)
    return K.condensed_cost(U, xs, p["ref"], DTAU, p["W"], RHO, p["obs"])


def test_merit_cost_is_the_penalised_cost(problem):
    """condensed_cost, the Newton line search's merit with obstacles, is the cost whose
    gradient the residual is (the eliminated dummy inputs' −ρΔτΣv included)."""
    p = problem
    assert _merit(p, p["u"].reshape(-1).copy()) == pytest.approx(_penalised_cost(p, p["u"]),
                                                                 rel=1e-12)


def test_merit_cost_gradient_is_the_residual_beyond_s_max(problem):
    """∇J = Δτ F also where the input barrier continues along its tangent (|s| > S_MAX)."""
    p = problem
    U = p["u"].reshape(-1).copy()
    U[5] = 0.9995
    F, _, _ = _residual(p, U)
    grad = _fd_grad(lambda u: _merit(p, u), U, eps=1e-7)
    np.testing.assert_allclose(grad, DTAU * F, rtol=1e-5, atol=1e-5 * np.abs(DTAU * F).max())


def test_an_obstacle_away_from_the_horizon_changes_nothing(problem):
    p = problem
    U = p["u"].reshape(-1).copy()
    far = dict(p, obs=_table([_obstacle("sphere", (50.0, 50.0, 1.0))]))
    F_far, _, _ = _residual(far, U)
    F_free = np.zeros_like(F_far)
    K.residual(U, K.STAGE_CONDENSED, p["x0"], p["ref"], DTAU, p["W"], RHO, 0.0, K.NO_ACTIVE,
               np.zeros((N + 1, 7)), np.zeros((N + 1, 5)), F_free)
    np.testing.assert_allclose(F_far, F_free, rtol=1e-13, atol=1e-13)


# ----------------------------------------------------------------------------- solver


def _hover_run(solver, ticks=40):
    """A small step from hover, exact model, no Newton re-projection: the inputs applied."""
    from ardrone_nmpc.experiments.bench import HOVER_STATE, plant_step

    x = HOVER_STATE.copy()
    target = x.copy()
    target[[0, 2]] = 0.2, -0.1
    ref = np.tile(target, (solver.spec.horizon_steps + 1, 1))
    inputs = []
    for k in range(ticks):
        result = solver.solve(k * 0.065, x, ref)
        assert result.newton_iterations == 0 or k == 0
        inputs.append(result.u)
        x = plant_step(x, result.u, 0.065)
    return np.array(inputs)


def test_solver_with_a_far_obstacle_flies_like_the_obstacle_free_one():
    """The penalty is exactly inactive away from the obstacle; what remains is the other
    compiled code (the kernels with an obstacle table) and the other line-search merit of the
    initial Newton solve, both converged tight here."""
    far = OcpSpec(obstacles=_table([_obstacle("cylinder", (40.0, 0.0, 0.0))]))
    tight = dict(tolerance=1e-10, max_newton_iterations=60)
    with_far = _hover_run(CGMRESController(far, **tight))
    free = _hover_run(CGMRESController(OcpSpec(), **tight))
    np.testing.assert_allclose(with_far, free, atol=1e-8)


def test_obstacle_free_config_builds_an_obstacle_free_solver():
    from ardrone_nmpc.control.solver import make_nmpc

    cfg = load_config(CONFIG, ["controller.obstacles=[]"])
    solver = make_nmpc(cfg.controller, period_s=0.065)
    assert solver.obstacles.shape == (0, O.OBS_COLS)
    assert solver.memory.n_obstacles == 0  # the kernels' specialisation without obstacles
    solver = make_nmpc(load_config(CONFIG).controller, period_s=0.065)
    np.testing.assert_allclose(solver.obstacles[0, [O.OBS_X, O.OBS_Y, O.OBS_DIST]],
                               [1.25, 0.0, 0.6])


def test_moving_an_obstacle_onto_the_path_makes_the_drone_go_round():
    """The centre is a runtime parameter: the solver told that the sphere moved onto its path
    flies round it (exact model, the loop's 0.21 rad tilt box); the other flies through."""
    from ardrone_nmpc.experiments.bench import closed_loop

    centre = np.array([0.9, 0.0, 1.0])
    spec = OcpSpec(u_min=[-1, -0.21, -0.21, -1], u_max=[1, 0.21, 0.21, 1],
                   obstacles=_table([_obstacle("sphere", (40.0, 0.0, 1.0))], weight=2000.0,
                                    shift=0.05))
    target = np.array([1.8, 0, 0, 0, 1.0, 0, 0])

    def fly(solver):
        def solve(t, x, ref):
            r = solver.solve(t, x, ref)
            return r.u, r.residual_norm, r.ok, r.solve_time_us

        *_, failures, states = closed_loop(solve, spec, steps=120, period_s=0.065,
                                           target=target)
        assert failures == 0
        np.testing.assert_allclose(states[-1][[0, 2, 4]], target[[0, 2, 4]], atol=0.02)
        return np.linalg.norm(states[:, [0, 2, 4]] - centre, axis=1).min()

    moved, still = CGMRESController(spec), CGMRESController(spec)
    moved.move_obstacles([centre])
    assert fly(still) < 0.1
    assert fly(moved) > 0.6 - CLEARANCE_TOLERANCE_M
    with pytest.raises(ValueError, match=r"move_obstacles: expected 1×3 finite centres"):
        moved.move_obstacles([[0.5, 0.0]])
    with pytest.raises(ValueError, match=r"move_obstacles"):
        moved.move_obstacles([[0.5, np.nan, 1.0]])


# ----------------------------------------------------------------------------- config


@pytest.mark.parametrize("override, message", [
    ("controller.obstacles=[{kind: box, center_m: [0, 0, 1], radius_m: 0.3}]",
     r"controller\.obstacles\.0\.kind: Input should be 'sphere' or 'cylinder'"),
    ("controller.obstacles=[{kind: sphere, center_m: [0, 0], radius_m: 0.3}]",
     r"controller\.obstacles\.0\.center_m: expected 3 values, got 2"),
    ("controller.obstacles=[{kind: sphere, center_m: [3, 0, 1], radius_m: 0}]",
     r"controller\.obstacles\.0\.radius_m: Input should be greater than 0"),
    ("controller.obstacles=[{kind: sphere, center_m: [3, 0, 1], radius_m: 0.2, margin_m: -0.1}]",
     r"controller\.obstacles\.0\.margin_m: Input should be greater than or equal to 0"),
    ("controller.obstacles=[{kind: sphere, center_m: [3, 0, .nan], radius_m: 0.2}]",
     r"controller\.obstacles\.0\.center_m\.2: Input should be a finite number"),
    ("controller.obstacles=[{kind: sphere, center_m: [3, 0, 1], radius_m: 0.2, height_m: 1}]",
     r"controller\.obstacles\.0\.height_m: Extra inputs are not permitted"),
    ("controller.obstacles=[{center_m: [3, 0, 1], radius_m: 0.2}]",
     r"controller\.obstacles\.0\.kind: Field required"),
    ("controller.obstacle_weight=0",
     r"controller\.obstacle_weight: Input should be greater than 0"),
    ("controller.obstacle_tie_break_m=-0.01",
     r"controller\.obstacle_tie_break_m: Input should be greater than or equal to 0"),
    ("controller.obstacle_curvature=hessian",
     r"controller\.obstacle_curvature: Input should be 'gauss-newton' or 'exact'"),
    ("reference.start_m=[1.0, 0.3, 5.0]",  # a cylinder has no top: 0.3 m from its axis
     r"reference: start_m \[1\.0, 0\.3, 5\.0\] is 0\.391 m from controller\.obstacles\.0, "
     r"inside its radius \+ margin \(0\.6 m\)"),
])
def test_bad_obstacle_config_is_reported_at_its_path(override, message):
    with pytest.raises(ConfigError, match=message):
        load_config(CONFIG, [override])


def test_obstacle_config_defaults():
    cfg = load_config(CONFIG)
    (obs,) = cfg.controller.obstacles
    assert (obs.kind, obs.center_m, obs.radius_m, obs.margin_m) == (
        "cylinder", (1.25, 0.0, 1.0), 0.3, 0.3)
    assert load_config(None).controller.obstacles == ()  # none unless configured
    margin = load_config(None, ["controller.obstacles=[{kind: sphere, center_m: [3, 0, 1], "
                                "radius_m: 0.2}]"]).controller.obstacles[0].margin_m
    assert margin == 0.3


# ----------------------------------------------------------------------------- summary


def test_clearance_stats_sphere_and_cylinder():
    sphere = _obstacle("sphere", (0.0, 0.0, 1.0), radius=0.3, margin=0.3)
    cylinder = _obstacle("cylinder", (0.0, 0.0, 1.0), radius=0.3, margin=0.3)
    p = np.array([[0.56, 0.0, 1.0],  # 0.26 from the surface: 4 cm inside d, tolerated
                  [0.54, 0.0, 1.0],  # 6 cm inside d: a violation
                  [0.0, 0.0, 1.8],  # above: clear of the sphere, inside the cylinder
                  [np.nan, 0.0, 1.0]])  # ignored
    s = clearance_stats(p, sphere)
    assert s["min_clearance_m"] == pytest.approx(0.24)
    assert s["violations"] == 1
    c = clearance_stats(p, cylinder)
    assert c["min_clearance_m"] == pytest.approx(-0.3)
    assert c["violations"] == 2
    assert math.isnan(clearance_stats(p[3:], sphere)["min_clearance_m"])


# ----------------------------------------------------------------------------- closed loop


@pytest.mark.parametrize("seed", [0, 7])
def test_the_drone_goes_round_a_cylinder_on_the_straight_path(tmp_path, seed):
    """configs/obstacle.yaml, shortened: the x step runs through a cylinder; the drone passes
    it, its truth never closer than d − 5 cm, and the summary says so."""
    cfg = load_config(CONFIG, ["duration_s=6.0"])
    (obs,) = cfg.controller.obstacles
    d = obs.radius_m + obs.margin_m
    with RunRecorder.create(tmp_path, cfg, seed=seed) as rec:
        run_lockstep(cfg, recorder=rec, seed=seed)
        rec.flush()
        run = read_run(rec.path)
    cols = run.columns
    p = np.column_stack([cols["x_true_m"], cols["y_true_m"], cols["z_true_m"]])
    distance = np.hypot(p[:, 0] - obs.center_m[0], p[:, 1] - obs.center_m[1])
    assert distance.min() >= d - CLEARANCE_TOLERANCE_M
    # it went round, not stopped in front: it came abreast of the axis (at the clearance
    # above, so to one side) and ended near the target
    assert p[:, 0].max() > obs.center_m[0] + d
    assert abs(p[-1, 0] - 2.5) < 0.1 and abs(p[-1, 1]) < 0.1
    assert all(s in ("ok", "") for s in cols["solver_status"])
    rows = {(r.axis, r.metric): r.value for r in summarise(run)}
    assert rows[("obstacle0", "min_clearance")] == pytest.approx(distance.min() - obs.radius_m)
    assert rows[("obstacle0", "clearance_violations")] == 0
