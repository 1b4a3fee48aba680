"""Closed-loop solver benchmark: the NMPC inside its loop, timed as the loop calls it.

Scenario: hovering at (0, 0, 1) m, ψ = 0, the reference steps by 1 m in x, y, z and 1 rad in
ψ together; the plant is the control model (eq. 3.13) integrated by RK4 in 5 ms steps with
the input held over each control period, so every solver faces the same exact-model problem
and the closed-loop costs compare optimisers, not models. Each solver first runs a few
untimed hover ticks (JIT warm-up, initial solve), then the timed step response.

Closed-loop cost: ``Σ_k [½ e_kᵀ q e_k + ½ u_kᵀ r u_k] Δt`` over the timed ticks.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from ardrone_nmpc import model
from ardrone_nmpc.control.ocp import OcpSpec, SolverStatus

STEP_M = 1.0
STEP_PSI_RAD = 1.0
HOVER_STATE = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
WARMUP_TICKS = 20
PLANT_SUBSTEP_S = 0.005


@dataclass
class BenchRow:
    """One solver's figures (the JSON contract of ``bench --json``)."""

    solver: str
    horizon_steps: int
    kmax: int
    steps: int
    mean_us: float
    p50_us: float
    p99_us: float
    max_us: float
    call_mean_us: float
    call_p99_us: float
    residual_mean: float
    residual_max: float
    closed_loop_cost: float
    failures: int

    def to_json(self) -> dict:
        return asdict(self)


def step_target() -> np.ndarray:
    """(7,) state reference after the step."""
    target = HOVER_STATE.copy()
    target[[0, 2, 4]] += STEP_M
    target[6] += STEP_PSI_RAD
    return target


def plant_step(x: np.ndarray, u: np.ndarray, period_s: float) -> np.ndarray:
    """Integrate the model over one control period with ``u`` held (RK4, ≤ 5 ms steps)."""
    n_sub = max(1, math.ceil(period_s / PLANT_SUBSTEP_S - 1e-9))
    for _ in range(n_sub):
        x = model.rk4_step(x, u, period_s / n_sub)
    return x


def closed_loop(solve, spec: OcpSpec, *, steps: int, period_s: float,
                x0: np.ndarray | None = None, target: np.ndarray | None = None):
    """Run ``solve(t_s, x, ref) -> (u, residual, ok, update_us)`` for ``steps`` timed ticks.

    Returns ``(call_us, update_us, residuals, cost, failures, states)``: ``call_us`` is wall
    time around each ``solve`` call as the control loop pays it, ``update_us`` the solver's
    own figure for its update (kernel and dispatch, without packaging the result).
    """
    x = HOVER_STATE.copy() if x0 is None else np.asarray(x0, float).copy()
    hover_ref = np.tile(x, (spec.horizon_steps + 1, 1))
    for k in range(WARMUP_TICKS):  # untimed: JIT, initial solve, settle at hover
        solve(k * period_s, x, hover_ref)
    target = step_target() if target is None else target
    ref = np.tile(target, (spec.horizon_steps + 1, 1))
    times = np.empty(steps)
    updates = np.empty(steps)
    residuals = np.empty(steps)
    states = np.empty((steps + 1, x.size))
    states[0] = x
    cost = 0.0
    failures = 0
    t_base = WARMUP_TICKS * period_s
    for k in range(steps):
        t0 = time.perf_counter_ns()
        u, res, ok, update_us = solve(t_base + k * period_s, x, ref)
        times[k] = (time.perf_counter_ns() - t0) * 1e-3
        updates[k] = update_us
        residuals[k] = res
        failures += not ok
        cost += spec.stage_cost(x, target, u) * period_s
        x = plant_step(x, u, period_s)
        states[k + 1] = x
    return times, updates, residuals, cost, failures, states


def _row(name, spec, kmax, calls, updates, residuals, cost, failures) -> BenchRow:
    finite = residuals[np.isfinite(residuals)]  # IPOPT reports no residual: NaN
    return BenchRow(
        solver=name, horizon_steps=spec.horizon_steps, kmax=kmax, steps=int(updates.size),
        mean_us=float(updates.mean()), p50_us=float(np.percentile(updates, 50)),
        p99_us=float(np.percentile(updates, 99)), max_us=float(updates.max()),
        call_mean_us=float(calls.mean()), call_p99_us=float(np.percentile(calls, 99)),
        residual_mean=float(finite.mean()) if finite.size else math.nan,
        residual_max=float(finite.max()) if finite.size else math.nan,
        closed_loop_cost=float(cost), failures=int(failures))


def bench_nmpc(make_solver, *, steps: int, repeats: int = 1) -> BenchRow:
    """Benchmark a solver: ``make_solver()`` builds a fresh one per repeat.

    The closed loop is deterministic, so every repeat computes the same ticks; taking each
    tick's minimum time over the repeats strips the interference of other processes on a
    shared machine (the figures of one run are what a single flight would see).
    """
    all_calls, all_updates = [], []
    for _ in range(max(1, repeats)):
        solver = make_solver()

        def solve(t_s, x, ref):
            r = solver.solve(t_s, x, ref)
            return r.u, r.residual_norm, r.status is SolverStatus.OK, r.solve_time_us

        calls, updates, residuals, cost, failures, _ = closed_loop(
            solve, solver.spec, steps=steps, period_s=solver.period_s)
        all_calls.append(calls)
        all_updates.append(updates)
    return _row(solver.method, solver.spec, solver.kmax, np.min(all_calls, axis=0),
                np.min(all_updates, axis=0), residuals, cost, failures)


def bench_ipopt(spec: OcpSpec, *, steps: int, period_s: float) -> BenchRow:  # one repeat: slow
    """The same OCP solved to optimality by CasADi/IPOPT each tick (warm-started)."""
    from ardrone_nmpc.control.exact import IpoptController

    solver = IpoptController(spec)

    def solve(t_s, x, ref):
        t0 = time.perf_counter_ns()
        u, ok = solver.solve(x, ref)
        return u, math.nan, ok, (time.perf_counter_ns() - t0) * 1e-3

    calls, updates, residuals, cost, failures, _ = closed_loop(solve, spec, steps=steps,
                                                               period_s=period_s)
    return _row("ipopt", spec, 0, calls, updates, residuals, cost, failures)
