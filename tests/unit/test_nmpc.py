"""NMPC solvers: optimum against scipy, bounds, residual decay, large steps, recovery."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize

from ardrone_nmpc.experiments.bench import HOVER_STATE, closed_loop, plant_step
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.cgmres import CGMRESController
from ardrone_nmpc.control.newton import NewtonGMRESController
from ardrone_nmpc.control.solver import make_nmpc
from ardrone_nmpc.control.ocp import OcpSpec, SolverStatus
from tests.conftest import thesis_cost

SPEC = OcpSpec()  # thesis weights, N = 15, Δτ = 0.1, bounds ±1


def _scipy_optimum(spec, x0, ref):
    """The OCP solved by L-BFGS-B with the box as hard bounds (reference answer)."""
    n = spec.horizon_steps

    def cost(flat):
        return thesis_cost(x0, ref, flat.reshape(n, 4), q=spec.q, r=spec.r,
                           qf=spec.q_terminal, dtau=spec.dtau_s)

    res = minimize(cost, np.zeros(4 * n), method="L-BFGS-B",
                   bounds=[(-1, 1)] * (4 * n), options={"ftol": 1e-15, "gtol": 1e-10,
                                                       "maxiter": 5000})
    return res.x.reshape(n, 4), res.fun


def _ref(target, spec=SPEC):
    return np.tile(np.asarray(target, float), (spec.horizon_steps + 1, 1))


SMALL_TARGET = [0.3, 0, -0.2, 0, 1.1, 0, 0.2]  # bounds inactive at the optimum
BIG_TARGET = [2.0, 0, 2.0, 0, 2.0, 0, 1.5]  # several bounds active


def test_newton_tick_reaches_the_unconstrained_optimum():
    x0 = HOVER_STATE.copy()
    solver = NewtonGMRESController(SPEC, kmax=20, tolerance=1e-8, max_newton_iterations=50)
    result = solver.solve(0.0, x0, _ref(SMALL_TARGET))
    u_opt, _ = _scipy_optimum(SPEC, x0, _ref(SMALL_TARGET))
    assert result.status is SolverStatus.OK
    np.testing.assert_allclose(solver.inputs_horizon, u_opt, atol=2e-4)


def _perturbed_start(seed):
    """Hover with random velocities (±0.5 m/s) and heading (±0.5 rad): another start."""
    rng = np.random.default_rng(seed)
    x0 = HOVER_STATE.copy()
    x0[[1, 3, 5]] = rng.uniform(-0.5, 0.5, 3)
    x0[6] = rng.uniform(-0.5, 0.5)
    return x0


BOX_TARGETS = [BIG_TARGET, [-2.0, 0, 1.0, 0, 0.5, 0, -1.0], [1.5, 0, -1.5, 0, 1.0, 0, -1.2],
               [0.0, 0, 0.0, 0, 2.5, 0, 2.0]]


@pytest.mark.parametrize("target", BOX_TARGETS,
                         ids=["big", "back-left-down", "forward-right-turn", "climb-turn"])
@pytest.mark.parametrize("start", [None, 1, 2], ids=["hover", "moving-1", "moving-2"])
def test_newton_tick_with_active_bounds_matches_the_box_constrained_optimum(target, start):
    """Eq. 3.25: violated bounds imposed as C − ε = 0 give the box optimum (L-BFGS-B with the
    box as hard bounds) up to ε — from several starts and targets, including targets whose
    unconstrained Newton iteration stalls inside the box before any input leaves it."""
    x0 = HOVER_STATE.copy() if start is None else _perturbed_start(start)
    eps = 1e-4
    solver = NewtonGMRESController(SPEC, kmax=30, tolerance=1e-8, max_newton_iterations=50,
                                   bound_epsilon=eps)
    result = solver.solve(0.0, x0, _ref(target))
    u_opt, _ = _scipy_optimum(SPEC, x0, _ref(target))
    assert np.any(np.isclose(np.abs(u_opt), 1.0, atol=1e-6)), "scenario must hit a bound"
    assert result.status is SolverStatus.OK
    # an active bound is the equation u = bound ∓ ε, held to Newton's tolerance
    assert np.all(np.abs(solver.inputs_horizon) <= 1.0 - eps + 1e-6)
    np.testing.assert_allclose(solver.inputs_horizon, u_opt, atol=2e-3)
    np.testing.assert_allclose(result.u, np.clip(u_opt[0], -1, 1), atol=2e-3)


def test_newton_tick_far_outside_the_box_reaches_the_optimal_cost():
    """A target 3 m away in x and y with a 2.5 rad turn: many bounds active at once. The
    optimum is flat there (several input sequences share its cost), so the cost is compared."""
    x0 = HOVER_STATE.copy()
    target = [3.0, 0, -3.0, 0, 2.5, 0, 2.5]
    solver = NewtonGMRESController(SPEC, kmax=60, tolerance=1e-8, max_newton_iterations=50,
                                   bound_epsilon=1e-4)
    result = solver.solve(0.0, x0, _ref(target))
    _, cost_opt = _scipy_optimum(SPEC, x0, _ref(target))
    cost = thesis_cost(x0, _ref(target), solver.inputs_horizon, q=SPEC.q, r=SPEC.r,
                       qf=SPEC.q_terminal, dtau=SPEC.dtau_s)
    assert result.status is SolverStatus.OK
    assert cost == pytest.approx(cost_opt, rel=1e-4)


MODERATE_TARGET = [0.6, 0, -0.6, 0, 1.5, 0, 0.6]  # a bound or two active, no singular region


def test_cgmres_initial_solve_is_near_the_box_optimum():
    """The first tick solves F = 0 by Newton; with a small dummy weight its horizon is the
    box-constrained optimum, a hair inside the bounds."""
    x0 = HOVER_STATE.copy()
    solver = CGMRESController(SPEC, dummy_weight=1e-3, tolerance=1e-9, max_newton_iterations=80)
    solver._t0_s = 0.0
    solver._initial_guess()
    from ardrone_nmpc.control import kernels as K
    # η = 1e-12: exact Krylov solves, so Newton converges quadratically
    _, _, norm = K.newton_solve(solver.U, 4, x0, _ref(MODERATE_TARGET), SPEC.dtau_s,
                                solver.memory.weights, 1e-3, 0.0, np.zeros((1, 1), np.int8),
                                1e-9, 80, 1e-6, 40, 1e-12, solver.memory.workspace_views())
    u_opt, j_opt = _scipy_optimum(SPEC, x0, _ref(MODERATE_TARGET))
    assert norm < 1e-6
    assert np.all(np.abs(solver.inputs_horizon) < 1.0)
    np.testing.assert_allclose(solver.inputs_horizon, u_opt, atol=0.02)
    j = thesis_cost(x0, _ref(MODERATE_TARGET), solver.inputs_horizon, q=SPEC.q, r=SPEC.r,
                    qf=SPEC.q_terminal, dtau=SPEC.dtau_s)
    assert j_opt <= j <= j_opt * 1.001


def _run(solver, target, steps, x0=None):
    log = []

    def solve(t, x, ref):
        r = solver.solve(t, x, ref)
        log.append(r)
        return r.u, r.residual_norm, r.ok, r.solve_time_us

    _, _, _, cost, failures, states = closed_loop(
        solve, solver.spec, steps=steps, period_s=solver.period_s, x0=x0,
        target=np.asarray(target, float))
    return log, states, cost, failures


@pytest.mark.parametrize("condensed", [True, False])
def test_cgmres_residual_falls_along_a_run(condensed):
    kmax = 5 if condensed else 15  # the uncondensed saddle system needs more Krylov room
    solver = CGMRESController(SPEC, kmax=kmax, condensed=condensed)
    log, states, _, failures = _run(solver, SMALL_TARGET, 300)
    norms = np.array([r.residual_norm for r in log])
    assert failures == 0
    assert norms[-20:].max() < 1e-3 * max(norms[:10].max(), 1.0)
    # the thesis weights make z slow (q_z = 5 against q_ż = 10): 20 s to within 2 mm
    np.testing.assert_allclose(states[-1], SMALL_TARGET, atol=2e-3)


def test_cgmres_matches_the_newton_closed_loop_cost_within_one_percent():
    target = [1.0, 0, 1.0, 0, 2.0, 0, 1.0]
    _, _, cost_c, fail_c = _run(CGMRESController(SPEC), target, 200)
    _, _, cost_n, fail_n = _run(NewtonGMRESController(SPEC), target, 200)
    assert fail_c == fail_n == 0
    assert cost_c == pytest.approx(cost_n, rel=0.01)


@pytest.mark.parametrize("target", [
    [5.0, 0, 0.0, 0, 1.0, 0, 0.0],
    [0.0, 0, -5.0, 0, 1.0, 0, 0.0],
    [5.0, 0, 5.0, 0, 3.0, 0, 0.0],
    [-5.0, 0, 5.0, 0, 3.0, 0, 3.0],
])
def test_large_steps_keep_inputs_bounded_and_arrive(target):
    solver = CGMRESController(SPEC)
    log, states, _, _ = _run(solver, target, 400)  # 26 s
    inputs = np.array([r.u for r in log])
    assert np.all(np.isfinite(inputs))
    assert np.all(np.abs(inputs) <= 1.0)
    assert all(r.status is not SolverStatus.NON_FINITE for r in log)
    np.testing.assert_allclose(states[-1][[0, 2, 4, 6]], np.asarray(target)[[0, 2, 4, 6]],
                               atol=0.01)


def test_divergence_is_detected_and_the_solver_reinitialises():
    solver = CGMRESController(SPEC)
    x = HOVER_STATE.copy()
    solver.solve(0.0, x, _ref(x))
    solver.U[:] = 0.9999 * np.sign(np.sin(np.arange(solver.U.size)))  # garbage near bounds
    result = solver.solve(0.065, x, _ref(x))
    assert result.status is SolverStatus.DIVERGED or result.newton_iterations > 0
    assert np.all(np.abs(result.u) <= 1.0) and np.all(np.isfinite(result.u))
    nxt = solver.solve(0.13, plant_step(x, result.u, 0.065), _ref(x))
    assert nxt.status is SolverStatus.OK
    assert nxt.residual_norm < 1.0


def test_forced_divergence_threshold_reports_diverged_and_recovers():
    solver = CGMRESController(SPEC, divergence_residual=1e-12, newton_trigger_residual=1e9)
    x = HOVER_STATE.copy()
    solver.solve(0.0, x, _ref(x))
    result = solver.solve(0.065, x, _ref(SMALL_TARGET))
    assert result.status is SolverStatus.DIVERGED
    assert result.reinitialised
    assert np.all(np.isfinite(result.u)) and np.all(np.abs(result.u) <= 1.0)


@pytest.mark.parametrize("bad", ["state", "reference"])
def test_non_finite_input_is_reported_never_returned(bad):
    solver = CGMRESController(SPEC)
    x = HOVER_STATE.copy()
    good = solver.solve(0.0, x, _ref(SMALL_TARGET))
    ref = _ref(SMALL_TARGET)
    if bad == "state":
        x[2] = np.nan
    else:
        ref[3, 4] = np.inf
    result = solver.solve(0.065, x, ref)
    assert result.status is SolverStatus.NON_FINITE
    assert np.all(np.isfinite(result.u))
    np.testing.assert_array_equal(result.u, good.u)  # the last input, flagged


def test_shape_errors_are_clear():
    solver = CGMRESController(SPEC)
    with pytest.raises(ValueError, match=r"ref \(16, 7\)"):
        solver.solve(0.0, HOVER_STATE, np.zeros((3, 7)))


def test_horizon_ramp_grows_from_zero():
    spec = OcpSpec(horizon_ramp_rate_per_s=2.0)
    solver = CGMRESController(spec)
    assert solver.stage_dtau_s(5.0) == pytest.approx(0.0)  # before the first solve
    solver.solve(1.0, HOVER_STATE, _ref(HOVER_STATE, spec))
    assert solver.stage_dtau_s(1.0) == 0.0
    assert solver.stage_dtau_s(1.5) == pytest.approx(0.1 * (1 - math.exp(-1.0)))
    log, states, _, failures = _run(solver, SMALL_TARGET, 200)
    assert failures == 0
    np.testing.assert_allclose(states[-1], SMALL_TARGET, atol=5e-3)


def test_solvers_build_from_the_config():
    cfg = load_config(None, ["controller.solver.method=newton", "controller.horizon_steps=8",
                             "controller.solver.newton_kmax=7"])
    solver = make_nmpc(cfg.controller, period_s=cfg.loop.period_s)
    assert isinstance(solver, NewtonGMRESController)
    assert solver.spec.horizon_steps == 8 and solver.kmax == 7
    np.testing.assert_array_equal(solver.spec.q, cfg.controller.q)


@pytest.mark.parametrize("kwargs, match", [
    (dict(horizon_steps=0), "horizon_steps"),
    (dict(dtau_s=-0.1), "dtau_s"),
    (dict(q=[1, 2, 3]), "q: expected 7"),
    (dict(u_min=[1, 1, 1, 1]), "u_min"),
    (dict(r=[0, 1, 1, 1]), "weights"),
])
def test_ocp_spec_rejects_bad_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        OcpSpec(**kwargs)


def test_cgmres_call_is_the_memory_step():
    """``SolverMemory.cgmres_call`` (what the solver binds once) is ``cgmres_step``'s call:
    the same tick from the same warm start gives the same bits, and a solve's SolveResult
    (built as its tuple) has the NamedTuple's fields."""
    solver = CGMRESController(SPEC)
    x, ref = np.asarray(HOVER_STATE, float), _ref(SMALL_TARGET)
    result = solver.solve(0.0, x, ref)
    assert result._fields == ("u", "status", "residual_norm", "gmres_iterations",
                              "solve_time_us", "newton_iterations", "reinitialised")
    assert result.reinitialised is False and isinstance(result.status, SolverStatus)
    mem = solver.memory
    warm = mem.snapshot()
    flag = mem.cgmres_step(x, ref, False)
    U, u = mem.U.copy(), mem.u.copy()
    mem.restore(warm)
    kernel, memory, settings = mem.cgmres_call()
    assert kernel(memory, x, ref, settings, False) == flag
    assert np.array_equal(mem.U, U) and np.array_equal(mem.u, u)


@pytest.mark.parametrize("cls", [CGMRESController, NewtonGMRESController])
def test_solve_prepared_is_solve_without_its_checks(cls):
    """The control stage's ``solve_prepared`` (no input checks; C/GMRES' kernel called
    without the ``_tick`` frame) answers as ``solve`` does, bit for bit, along a run with a
    reference step, a non-finite state (flagged, the last input) and a forced divergence
    (the recovery)."""
    runs = []
    for prepared in (False, True):
        solver = cls(SPEC)
        solve = solver.solve_prepared if prepared else solver.solve
        x = np.asarray(HOVER_STATE, float).copy()
        run = []
        for k in range(12):
            target = SMALL_TARGET if k < 6 else BIG_TARGET
            xk = x.copy()
            if k == 8:
                xk[2] = np.nan
            if k == 10:
                solver.divergence_residual = 1e-12
            r = solve(0.065 * k, xk, _ref(target))
            run.append((r.u.tobytes(), r.status, r.residual_norm, r.gmres_iterations,
                        r.newton_iterations, r.reinitialised))
            x = plant_step(x, r.u, 0.065)
        runs.append(run)
    assert runs[0] == runs[1]
    statuses = {status for _, status, *_ in runs[0]}
    assert SolverStatus.NON_FINITE in statuses and SolverStatus.DIVERGED in statuses


def _result_bits(r):
    return (r.u.tobytes(), r.status, r.residual_norm, r.gmres_iterations, r.newton_iterations,
            r.reinitialised)


@pytest.mark.parametrize("copier", ["deepcopy", "pickle"])
@pytest.mark.parametrize("cls", [CGMRESController, NewtonGMRESController])
def test_a_copied_solver_solves_as_the_original(cls, copier):
    """A deep copy or unpickled copy of a solver mid-run is faithful: from the same state it
    answers as the original, bit for bit, on its own memory — its views (the horizon, the
    input, the stats the result reads) are views of its memory, and its solves write nothing
    of the original's."""
    import copy
    import pickle

    solver = cls(SPEC)
    x = np.asarray(HOVER_STATE, float).copy()
    for k in range(4):
        x = plant_step(x, solver.solve(0.065 * k, x, _ref(SMALL_TARGET)).u, 0.065)
    twin = copy.deepcopy(solver) if copier == "deepcopy" else pickle.loads(pickle.dumps(solver))
    views = (twin.U, twin.dU, twin._u, twin.memory.u, twin.memory.stats_array,
             twin._stats_values.__self__)
    for view in views:
        assert np.shares_memory(view, twin.memory._mem)
        assert not np.shares_memory(view, solver.memory._mem)
    original = solver.memory.snapshot()
    ref, answers = _ref(BIG_TARGET), []
    for who in (twin, solver):
        xk, run = x.copy(), []
        for k in range(4, 9):  # a reference step (a Newton re-projection), then continuation
            r = who.solve_prepared(0.065 * k, xk, ref)  # the same arrays: the entry point
            run.append(_result_bits(r))
            xk = plant_step(xk, r.u, 0.065)
        answers.append(run)
        if who is twin:
            assert np.array_equal(solver.memory.snapshot(), original)  # untouched by the copy
    assert answers[0] == answers[1]


def _stub_step(mem, x, ref, iprm, initialise):
    """A kernel of the C/GMRES tick's signature that reads its arrays by their strides."""
    s = 0.0
    for i in range(x.shape[0]):
        s += x[i] * (i + 1)
    for i in range(ref.shape[0]):
        for j in range(ref.shape[1]):
            s += ref[i, j] * (i + 2 * j)
    mem[0] = s
    return 0


def test_solve_prepared_vets_the_arrays_it_sees_again_for_the_entry_point():
    """The bound kernel's compiled entry point (no type look-up, no type check) is taken for
    the same two arrays seen again, and only if they are plain float64 C arrays; arrays of
    another layout stay with the dispatcher, which reads them by their strides."""
    import numba  # a dependency of the package, not an extra: never skipped
    from ardrone_nmpc.core.entry_points import entry_point

    stub = numba.njit(_stub_step)

    class Stubbed(CGMRESController):
        def _kernel_call(self):
            _, mem, iprm = super()._kernel_call()
            return stub, mem, iprm

    solver = Stubbed(SPEC)
    solver._t0_s = 0.0  # no initial guess (the stub solves nothing)
    x, ref = np.arange(7.0), np.arange(16 * 7.0).reshape(16, 7)
    out = np.zeros(1)
    _stub_step(out, x, ref, None, False)
    expected = out[0]
    for k in range(3):
        solver.solve_prepared(0.065, x, ref)
        assert solver.U[0] == expected
        assert (solver._kernel[0] is stub) == (k == 0)  # vetted at the second call
    assert solver._kernel[0] is entry_point(stub, solver.memory._mem, x, ref,
                                            solver.memory._iprm, False)
    wide = np.zeros((7, 2))
    wide[:, 0] = x
    strided, fortran = wide[:, 0], np.asfortranarray(ref)
    for xs, refs in [(strided, ref), (x, fortran), (strided, fortran)]:
        for _ in range(3):
            solver.U[0] = 0.0
            solver.solve_prepared(0.065, xs, refs)
            assert solver.U[0] == expected
            assert solver._kernel[0] is not stub and solver._kernel[3] is x  # not vetted
