"""The report's sections beside the claims table: the linearised x loop for the N/Δτ claims,
the thesis' own Newton solver on the ψ step, and where our formulation narrows the thesis'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.mapping import DroneLimits
from ardrone_nmpc.core.types import IU_PSIRATE, IU_THETA, IU_ZACC, IX_VX, IX_X
from ardrone_nmpc.experiments.reproduce.claims import FORMULATIONS, LAB_OVERRIDES, fly
from ardrone_nmpc.experiments.xchannel import XPlant, stability_table, verdict

# (N, Δτ) of the thesis' tuning claims (fig. 4.14–4.17) and the config flying each, if any
STABILITY_CASES = [(5, 0.3, "stability_n5_dtau03.yaml"), (6, 0.3, "stability_n6_dtau03.yaml"),
                   (15, 0.08, "stability_n15_dtau008.yaml"), (15, 0.1, None),
                   (15, 0.15, "stability_n15_dtau015.yaml")]
TILT_GAINS = (1.0, 0.7)  # the plant's g·tanθ as configured, and 0.7× (a weaker drone)


def x_loop_rows(config_dir: Path) -> tuple[list[dict], XPlant, tuple[float, float, float]]:
    """The spectral radius of the linearised x loop (experiments/xchannel.py) per N/Δτ case
    and tilt gain: the thesis' x weights, the configured plant's lag, drag, delay, period."""
    cfg = load_config(config_dir / STABILITY_CASES[0][2], LAB_OVERRIDES)
    ctl, plant = cfg.controller, cfg.sim.plant
    base = XPlant(tau_tilt_s=plant.tau_tilt_s, drag_per_s=plant.drag_per_s,
                  delay_s=plant.command_delay_s, period_s=cfg.loop.period_s)
    plants = {f"{g:g}": XPlant(base.tau_tilt_s, g, base.drag_per_s, base.delay_s, base.period_s)
              for g in TILT_GAINS}
    weights = (ctl.q[IX_X], ctl.q[IX_VX], ctl.r[IU_THETA])
    rows = stability_table([(n, d) for n, d, _ in STABILITY_CASES], q_x=weights[0],
                           q_v=weights[1], r_theta=weights[2], plants=plants)
    for row, (_, _, name) in zip(rows, STABILITY_CASES):
        row["config"] = name
    return rows, base, weights


def render_x_loop(rows, plant: XPlant, weights, flown: dict) -> list[str]:
    """``flown``: config name -> {formulation: RunFigures} of the simulated runs."""
    q_x, q_v, r = weights
    lines = [
        "## N and Δτ: the linearised x loop", "",
        f"The x channel at hover (`experiments/xchannel.py`): the NMPC's first-step gain K₀ of "
        f"the Euler-discretised prediction (q = [{q_x:g}, {q_v:g}], r_θ = {r:g}, no terminal "
        f"weight) against the plant's tilt lag τ = {plant.tau_tilt_s:g} s, drag "
        f"{plant.drag_per_s:g} /s, the {plant.delay_s:g} s command delay and the "
        f"{plant.period_s * 1e3:g} ms period — the thesis formulation (no delay compensation). "
        "ρ is the closed loop's spectral radius (> 1: unstable, within 0.001 of 1: marginal), "
        "at the configured tilt gain g·tanθ and at 0.7 of it.", "",
        "| N | Δτ (s) | K₀ [x, ẋ] | " + " | ".join(f"ρ, tilt gain {g:g}" for g in TILT_GAINS)
        + " | flown, thesis formulation | flown, ours |",
        "|--:|--:|---|" + "---|" * len(TILT_GAINS) + "---|---|",
    ]
    for row in rows:
        rhos = [row[f"rho_{g:g}"] for g in TILT_GAINS]
        figs = flown.get(row["config"], {})
        sims = [figs[f].end("x").describe() if f in figs else "not flown" for f in FORMULATIONS]
        lines.append(f"| {row['N']} | {row['dtau_s']:g} | [{row['k_x']:.3f}, {row['k_v']:.3f}] | "
                     + " | ".join(f"{v:.4f} ({verdict(v)})" for v in rhos)
                     + " | " + " | ".join(sims) + " |")
    lines += ["", *x_loop_conclusion(rows), ""]
    return lines


def x_loop_conclusion(rows) -> list[str]:
    """What the table says about the two claims, from its verdicts."""
    by_case = {(r["N"], r["dtau_s"]): r for r in rows}
    n5, n6 = by_case[(5, 0.3)], by_case[(6, 0.3)]
    gains = [f"{g:g}" for g in TILT_GAINS]
    thesis_like = [g for g in gains if verdict(n5[f"rho_{g}"]) == "unstable"
                   and verdict(n6[f"rho_{g}"]) == "stable"]
    gap = max(abs(n5[f"rho_{g}"] - n6[f"rho_{g}"]) for g in gains)
    out = [f"* N = 5 vs 6 at Δτ = 0.3 s: K₀,x {n5['k_x']:.3f} vs {n6['k_x']:.3f}, ρ within "
           f"{gap:.4f} of each other at every tilt gain; "
           + (f"N = 5 unstable and N = 6 stable at tilt gain {', '.join(thesis_like)}."
              if thesis_like else "at no gain is N = 5 unstable and N = 6 stable — the two are "
              "equally close to the edge, so no plant separates them and a flight cannot either.")]
    for g in gains:
        v = {d: verdict(by_case[(15, d)][f"rho_{g}"]) for d in (0.08, 0.1, 0.15)}
        thesis_like = v[0.08] == "unstable" and v[0.15] == "stable"
        out.append(f"* Δτ at N = 15, tilt gain {g}: 0.08 s {v[0.08]}, 0.1 s {v[0.1]}, 0.15 s "
                   f"{v[0.15]}" + (" — the thesis' boundary." if thesis_like else
                                   " — not the thesis' boundary."))
    return out


@dataclass
class NewtonRun:
    """The thesis' Newton solver flown on the ψ step, with one Krylov dimension."""

    kmax: int
    ticks: int
    at_max_iterations: int
    iterations_mean: float
    iterations_max: float
    residual_p50: float
    residual_max: float
    settling_s: float
    path: Path


NEWTON_KMAX = (5, 30)  # C/GMRES's k_max (the Newton solver's until issue 16), and its own
TRACE_TICKS = (40, 80, 120, 160)  # ticks of the experiment whose Newton iterations are traced
TRACE_CAPS = (1, 2, 3, 5, 10, 20, 40)  # Newton iterations after which ‖F‖ is read


def newton_runs(config_dir: Path, log_dir: Path, seed: int) -> list[NewtonRun]:
    """Fly the ψ step with ``controller.solver.method=newton`` in the thesis formulation."""
    out = []
    for k in NEWTON_KMAX:
        over = ["controller.solver.method=newton", f"controller.solver.newton_kmax={k}"]
        f = fly(config_dir, "step_psi.yaml", over, "thesis", log_dir, seed, tag=f"-newton-k{k}")
        out.append(NewtonRun(k, int(f.get("solver", "solves")), int(f.get("solver", "non_ok")),
                             f.get("solver", "newton_iterations_mean"),
                             f.get("solver", "newton_iterations_max"),
                             f.get("solver", "residual_p50"), f.get("solver", "residual_max"),
                             f.settling("psi"), f.path))
    return out


def newton_traces(path: Path) -> dict[int, dict[int, list[float]]]:
    """‖F‖ after n Newton iterations (:data:`TRACE_CAPS`) at :data:`TRACE_TICKS`, for each
    Krylov dimension of :data:`NEWTON_KMAX`: the run's logged states replayed through a fresh
    Newton solver (thesis formulation: the state solved at is the estimate), the tick's solve
    repeated from the same warm start with each iteration cap."""
    from ardrone_nmpc.control.newton import NewtonGMRESController
    from ardrone_nmpc.reference.trajectories import make_trajectory
    from ardrone_nmpc.runs.rundir import read_run
    from ardrone_nmpc.runtime.tick import effective_controller

    run = read_run(path)
    cfg, cols = run.config, run.columns
    limits = DroneLimits(cfg.drone.euler_angle_max_rad, cfg.drone.control_vz_max_mps,
                         cfg.drone.control_yaw_radps)
    ctl = effective_controller(cfg.controller, limits)
    ctl = ctl.model_copy(update={"solver": ctl.solver.model_copy(
        update={"newton_kmax": max(NEWTON_KMAX)})})  # memory for the largest k_max traced
    solver = NewtonGMRESController.from_config(ctl, period_s=cfg.loop.period_s)
    traj = make_trajectory(cfg.reference, duration_s=cfg.duration_s)
    states = np.column_stack([cols[c] for c in ("x_m", "vx_mps", "y_m", "vy_mps", "z_m",
                                                "vz_mps", "psi_rad")])
    t = np.asarray(cols["t_s"], float)
    solved = np.flatnonzero(np.isfinite(np.asarray(cols["residual_norm"], float)) & (t >= 0))
    stages = np.arange(ctl.horizon_steps + 1) * ctl.dtau_s
    traces: dict[int, dict[int, list[float]]] = {}
    # the solver's private _tick and its memory's snapshot/restore: the trace needs the tick's
    # solve repeated from one warm start with other iteration caps and Krylov dimensions
    memory = solver.memory
    for n, k in enumerate(solved[: max(TRACE_TICKS) + 1]):
        x, ref = states[k], traj.state_at(t[k] + stages)
        if n in TRACE_TICKS:
            saved, active = memory.snapshot(), solver.active.copy()
            cap = memory.max_newton_iterations
            traces[n] = {}
            for kmax in NEWTON_KMAX:
                traces[n][kmax] = []
                for iterations in TRACE_CAPS:
                    memory.restore(saved)
                    solver.active[:] = active
                    memory.kmax, memory.max_newton_iterations = kmax, iterations
                    solver._tick(x, ref, False)
                    traces[n][kmax].append(memory.stats().newton_residual)
            memory.restore(saved)
            solver.active[:] = active
            memory.kmax, memory.max_newton_iterations = cfg.controller.solver.newton_kmax, cap
        solver.solve(float(t[k]), x, ref)
    return traces


def render_newton(runs: list[NewtonRun], traces, tolerance: float,
                  max_iterations: int) -> list[str]:
    lines = [
        "## The thesis' Newton solver on the ψ step", "",
        "`controller.solver.method=newton` (thesis Algorithm 1: Newton steps by fdgmres, "
        f"eq. 3.25 bounds) on `step_psi.yaml` in the thesis formulation; tolerance ‖F‖ ≤ "
        f"{tolerance:g}, at most {max_iterations} Newton iterations per active-set round. "
        "k_max is the Krylov dimension of each Newton step (the thesis gives none).", "",
        "| k_max | solves | ended at max-iterations | Newton iterations mean / max "
        "| ‖F‖ at exit p50 / max | ψ settling |",
        "|--:|--:|--:|---|---|--:|",
    ]
    for r in runs:
        settling = "—" if not math.isfinite(r.settling_s) else f"{r.settling_s:.1f} s"
        lines.append(f"| {r.kmax} | {r.ticks} | {r.at_max_iterations} | "
                     f"{r.iterations_mean:.1f} / {r.iterations_max:.0f} | "
                     f"{r.residual_p50:.1e} / {r.residual_max:.1e} | {settling} |")
    lines += ["", "‖F‖ after n Newton iterations at some ticks of the k_max = "
              f"{runs[-1].kmax} flight (its logged states replayed through the solver, each "
              "tick's solve repeated from the same warm start):", "",
              "| tick | k_max | " + " | ".join(f"n = {c}" for c in TRACE_CAPS) + " |",
              "|--:|--:|" + "--:|" * len(TRACE_CAPS)]
    for tick, by_k in traces.items():
        for kmax, trace in by_k.items():
            lines.append(f"| {tick} | {kmax} | " + " | ".join(f"{v:.1e}" for v in trace) + " |")
    lines += ["", *newton_conclusion(traces, tolerance), ""]
    return lines


def newton_conclusion(traces, tolerance: float) -> list[str]:
    """What the traces say, from their numbers."""
    out = []
    for kmax in NEWTON_KMAX:
        last = [by_k[kmax][-1] for by_k in traces.values()]
        above = sum(v > tolerance for v in last)
        out.append(f"With k_max = {kmax}, {above} of {len(last)} traced ticks are above the "
                   f"tolerance after {TRACE_CAPS[-1]} iterations (‖F‖ {min(last):.0e} – "
                   f"{max(last):.0e}).")
    out.append("Each Newton step is a GMRES solve of the uncondensed system (8 unknowns per "
               "stage); stopped at 5 Krylov vectors it ends far above its relative tolerance η, "
               "the step is a poor Newton direction and the iteration stalls where it stands — "
               "a looser tolerance would not reach the stall, more iterations do not move it. "
               "This is a parameter, not the method: the Newton solver has its own k_max "
               "(`controller.solver.newton_kmax`), no longer C/GMRES's 5.")
    return [" ".join(out)]


def _narrowed(name: str, thesis: float, drone: float, unit: str, field: str) -> str:
    if drone < thesis:
        return f"{name} within ±{drone:.4f} {unit} (`{field}`), not ±{thesis:g}"
    return f"{name} within ±{thesis:g} {unit} as in the thesis (`{field}` = {drone:g})"


def narrowings(config_dir: Path) -> list[str]:
    """Where both formulations depart from the thesis' (bounds, estimator, solver, …)."""
    cfg = load_config(config_dir / "step_x.yaml", [*LAB_OVERRIDES, *FORMULATIONS["thesis"]])
    ctl, drone, est = cfg.controller, cfg.drone, cfg.estimator
    g = ctl.p_gains
    tilt = _narrowed("φ, θ", ctl.u_max[IU_THETA], drone.euler_angle_max_rad, "rad",
                     "drone.euler_angle_max_rad")
    yaw = _narrowed("ψ̇", ctl.u_max[IU_PSIRATE], drone.control_yaw_radps, "rad/s",
                    "drone.control_yaw_radps")
    lines = ["## Where the simulated formulations narrow the thesis'", "",
             f"* **Input bounds.** Eq. 4.17 bounds every input by ±1; the configs keep "
             f"u_min = {list(ctl.u_min)}, u_max = {list(ctl.u_max)}, but the NMPC plans within "
             f"the drone's own limits (`effective_controller`, runtime/tick.py) in both "
             f"formulations: {tilt}; {yaw}. "
             f"u1 is z̈, bounded by ±{ctl.u_max[IU_ZACC]:g} m/s² (the thesis' text calls it a "
             f"velocity in m/s); the ż reference sent is clipped to ±{drone.control_vz_max_mps:g} "
             "m/s (`drone.control_vz_max_mps`).",
             f"* **Estimator.** ż from the estimator each altitude config names "
             f"(`estimator.kind`; the others use {est.kind}): the Kalman filter with the thesis' "
             f"Q = {est.kalman_q:g}, R = {est.kalman_r:g}; the Luenberger observer with its "
             f"double pole at −{est.luenberger_lambda0_per_s:g} /s (K = [2λ0, λ0²]: eq. 4.12 "
             "as printed puts the poles in the right half-plane, eq. 4.15's K = [10, 25] at −5). "
             "ẋ, ẏ from navdata in the thesis formulation (the simulator adds an optical-flow "
             "bias), from differenced mocap positions in ours; x, y, z, ψ from mocap in both.",
             "* **Prediction.** Thesis formulation: delay-free, ż reference = ż + z̈·65 ms. Ours: "
             "the state predicted through the commands in flight over the command delay, "
             "ż reference = ż + z̈·0.5 s (the vertical lag inverted).",
             f"* **Solver.** The claims are flown with `controller.solver.method="
             f"{ctl.solver.method}` in both formulations; the thesis' Newton scheme is shown "
             "on the ψ step above.",
             f"* **P controller (eq. 4.16).** The thesis gives no gains; ours: k1 = "
             f"{g.k1_per_s:g}, k2 = {g.k2_rad_per_mps:g}, k3 = {g.k3_rad_per_mps:g}, "
             f"k4 = {g.k4_per_s:g}, tuned to its P settling times; the velocity error is rotated "
             "into the body frame and φ's sign fixed (as printed the law holds only at ψ = 0).",
             "* **Supervisor.** The geofence is widened (`" + "`, `".join(LAB_OVERRIDES)
             + "`) so that the supervisor does not end a run the controller would fly on.",
             "* **Plant.** The simulator of `docs/plant.md`, not the thesis' Simulink kit.",
             ]
    if "controller.offset_free=false" in FORMULATIONS["thesis"]:
        lines.append("* **Offset-free tracking.** Off in the thesis formulation "
                     "(`controller.offset_free=false`), on in ours.")
    return lines + [""]

