"""The report's sections beside the claims table: the thesis' own Newton solver on the ψ step,
and where the simulated formulations narrow the thesis' (the linearised x loop for the N/Δτ
claims is :mod:`.xloop`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.mapping import command_scales
from ardrone_nmpc.core.types import IU_PSIRATE, IU_THETA, IU_ZACC
from ardrone_nmpc.experiments.reproduce.claims import (BESIDE, FORMULATIONS, HOME_PLANTS,
                                                       LAB_OVERRIDES, fly)

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
    limits = command_scales(cfg.drone)
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
        f"eq. 3.25 bounds) on `step_psi.yaml` in the thesis formulation on `{BESIDE}`; "
        f"tolerance ‖F‖ ≤ "
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
    return f"{name} within ±{thesis:g} {unit} as in the thesis"


def _bounds(cfg) -> str:
    """What the NMPC plans within on one plant, and why."""
    ctl, scales = cfg.controller, command_scales(cfg.drone)
    convention = cfg.drone.command_convention
    field = ("drone.euler_angle_max_rad" if convention == "sdk"
             else "the port's ±1, `drone.command_convention: kit`")
    tilt = _narrowed("φ, θ", ctl.u_max[IU_THETA], scales.euler_angle_max_rad, "rad", field)
    yaw = _narrowed("ψ̇", ctl.u_max[IU_PSIRATE], scales.control_yaw_radps, "rad/s",
                    "drone.control_yaw_radps" if convention == "sdk" else field)
    return (f"`{cfg.sim.plant.profile}` ({convention} convention): {tilt}; {yaw}; the ż "
            f"reference sent clipped to ±{scales.control_vz_max_mps:g} m/s")


def narrowings(config_dir: Path) -> list[str]:
    """Where both formulations depart from the thesis' (bounds, estimator, solver, …)."""
    over = [*LAB_OVERRIDES, *FORMULATIONS["thesis"]]
    kit, lab = HOME_PLANTS["simulation"], HOME_PLANTS["experiment"]
    cfgs = {plant: load_config(config_dir / "step_x.yaml", [*over, f"sim.plant.profile={plant}"])
            for plant in (kit, lab, BESIDE)}
    cfg = cfgs[BESIDE]
    ours = load_config(config_dir / "step_x.yaml", LAB_OVERRIDES)
    ctl, est = cfg.controller, cfg.estimator
    gains = {plant: c.controller.p_gains for plant, c in cfgs.items()}
    noise = cfgs[kit].sim.noise
    quiet = all(v == 0.0 for v in noise.model_dump().values())
    lines = ["## Where the simulated formulations narrow the thesis'", "",
             "* **Plants.** The simulation claims on `" + kit + "`: the ARDrone Simulink "
             "Development Kit the thesis simulated with, driven as its Baseline Controller "
             "drives it (docs/plant-profiles.md §2). The experimental claims on `" + lab + "`, "
             "calibrated on the thesis' experimental square (§3). Every claim also on `"
             + BESIDE + "` (the tum_ardrone airframe with the thesis simulator's 0.26 s delay).",
             f"* **Input bounds.** Eq. 4.17 bounds every input by ±1; the configs keep "
             f"u_min = {list(ctl.u_min)}, u_max = {list(ctl.u_max)}, and the NMPC plans within "
             "what a PCMD ±1 commands (`effective_controller`, runtime/tick.py): "
             + "; ".join(_bounds(cfgs[p]) for p in (kit, BESIDE)) + ". "
             f"u1 is z̈, bounded by ±{ctl.u_max[IU_ZACC]:g} m/s² (the thesis' text calls it a "
             "velocity in m/s).",
             f"* **Estimator.** ż from the estimator each altitude config names "
             f"(`estimator.kind`; the others use {est.kind}): the Kalman filter with the thesis' "
             f"Q = {est.kalman_q:g}, R = {est.kalman_r:g}; the Luenberger observer with its "
             f"double pole at −{est.luenberger_lambda0_per_s:g} /s (K = [2λ0, λ0²]: eq. 4.12 "
             "as printed puts the poles in the right half-plane, eq. 4.15's K = [10, 25] at −5). "
             "ẋ, ẏ from navdata in the thesis formulation, from differenced mocap positions in "
             "ours; x, y, z, ψ from mocap in both. "
             + (f"On `{kit}` the sensors are noise-free, as the kit's outputs; "
                if quiet else f"On `{kit}` the sensors carry `sim.noise`; ")
             + "on the others they carry the noise and navdata biases of docs/plant.md §3.",
             f"* **Prediction.** Thesis formulation: delay-free, ż reference = ż + "
             f"z̈·{cfg.loop.period_s * 1e3:g} ms. Ours: the state predicted through the commands "
             f"in flight over {_delay(ours.controller)}, ż reference = ż + "
             f"z̈·{_lead(ours.controller.vz_lead_s)} (the `{BESIDE}` plant's vertical lag "
             f"inverted); the NMPC plans φ, θ within {ours.controller.planned_tilt_frac:g} of the "
             f"tilt limit and its tilt is divided by {_gain(ours.controller)}.",
             f"* **Solver.** The claims are flown with `controller.solver.method="
             f"{ctl.solver.method}` in both formulations; the thesis' Newton scheme flies the "
             "stability cases beside the linearised x loop and the ψ step below.",
             "* **P controller (eq. 4.16).** On `" + kit + "` the kit's Baseline Controller "
             "gains: " + _gains(gains[kit]) + " (ARBlocks.slx); on `" + BESIDE + "` and `" + lab
             + "` ours, tuned to the thesis' P settling times on `" + BESIDE + "`: "
             + _gains(gains[BESIDE]) + ". The velocity error is rotated into the body frame "
             "and φ's sign fixed (as printed the law holds only at ψ = 0), as the kit does.",
             "* **Supervisor.** The geofence is widened (`" + "`, `".join(LAB_OVERRIDES)
             + "`) so that the supervisor does not end a run the controller would fly on; "
             f"on `{kit}` its tilt limit is {cfgs[kit].safety.max_tilt_rad:g} (the port's "
             "saturation in the kit's convention; the kit cannot tilt beyond 0.86 rad with its "
             "ports within ±1), elsewhere "
             f"{cfg.safety.max_tilt_rad:g} rad. A claim fails if the supervisor flew any tick "
             "of its experiments.",
             ]
    if "controller.offset_free=false" in FORMULATIONS["thesis"]:
        lines.append("* **Offset-free tracking.** Off in the thesis formulation "
                     "(`controller.offset_free=false`), on in ours.")
    return lines + [""]


def _gains(g) -> str:
    return (f"k1 = {g.k1_per_s:g}, k2 = {g.k2_rad_per_mps:g}, k3 = {g.k3_rad_per_mps:g}, "
            f"k4 = {g.k4_per_s:g}")


def _lead(seconds) -> str:
    return "one period" if seconds is None else f"{seconds:g} s"


def _delay(ctl) -> str:
    """The delay the prediction compensates: configured, or measured in flight (auto)."""
    if ctl.delay_compensation_s == "auto":
        return (f"the command delay the flight measures (`delay_compensation_s: auto`, "
                f"{ctl.adaptation.delay_prior_s:g} s until its estimate is confident)")
    return _lead(ctl.delay_compensation_s)


def _gain(ctl) -> str:
    """What the NMPC's tilt is divided by: a configured gain, or the measured one (auto)."""
    if ctl.attitude_gain == "auto":
        return ("the drone's attitude gain the flight measures (`attitude_gain: auto`, "
                f"{ctl.adaptation.gain_prior:g} until confident, within "
                f"{ctl.adaptation.gain_min:g}–{ctl.adaptation.gain_max:g})")
    return f"{ctl.attitude_gain:g}"
