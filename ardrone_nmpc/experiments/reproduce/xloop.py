"""The report's section on the N/Δτ claims: the linearised x loop (experiments/xchannel.py) on
the kit's plant and on ``ardrone``, beside the flights, and checked against a flight.

The loop is linearised with the navdata velocity as old as it was in the flights (its mean
age at the experiment ticks); the kit's table also shows the stability runs flown with the
thesis' own solver (Newton to a tolerance each tick), which is what the linearisation
describes: C/GMRES's one continuation step per tick is not the converged law. The small-step
check flies a step too small to saturate and compares it with the linear loop's response.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import IU_THETA, IX_VX, IX_X
from ardrone_nmpc.experiments.record import record_lockstep
from ardrone_nmpc.experiments.reproduce.claims import (FORMULATIONS, HOME_PLANTS, LAB_OVERRIDES,
                                                       fly)
from ardrone_nmpc.experiments.xchannel import (KitXPlant, XPlant, first_step_law,
                                               stability_table, step_response, verdict)

# (N, Δτ) of the thesis' tuning claims (fig. 4.14–4.17) and the config flying each, if any
STABILITY_CASES = [(5, 0.3, "stability_n5_dtau03.yaml"), (6, 0.3, "stability_n6_dtau03.yaml"),
                   (15, 0.08, "stability_n15_dtau008.yaml"), (15, 0.1, None),
                   (15, 0.15, "stability_n15_dtau015.yaml")]
TILT_GAINS = (1.0, 0.7)  # the ardrone plant's g·tanθ as configured, and 0.7× (a weaker drone)
KIT = HOME_PLANTS["simulation"]
NEWTON = ["controller.solver.method=newton"]  # the thesis' solver (Algorithm 1)
CHECK_STEP_M = 0.1  # small enough that the tilt command stays far inside its ±1 bound
CHECK_SOLVERS = ("newton", "cgmres")
AMPLITUDE_CONFIG = "stability_n15_dtau008.yaml"  # the case the Newton flight cycles on
AMPLITUDES_M = (0.1, 0.5, 1.0, 1.5)  # x step sizes, the last the claim's


def _weights(config_dir: Path) -> tuple[float, float, float, float]:
    cfg = load_config(config_dir / STABILITY_CASES[0][2], LAB_OVERRIDES)
    ctl = cfg.controller
    return ctl.q[IX_X], ctl.q[IX_VX], ctl.r[IU_THETA], cfg.loop.period_s


def flight_age_s(flown: dict, plant: str) -> float:
    """The mean navdata age of the thesis formulation's stability flights on ``plant``."""
    ages = [flown[name][(plant, "thesis")].navdata_age_s for _, _, name in STABILITY_CASES
            if name in flown and (plant, "thesis") in flown[name]]
    ages = [a for a in ages if math.isfinite(a)]
    return float(np.mean(ages)) if ages else 0.0


def x_loop_rows(config_dir: Path, plant: str, age_s: float) -> list[dict]:
    """ρ per N/Δτ case on ``plant``'s linearised x channel, with a fresh and an ``age_s`` old
    velocity (columns ``rho_<name>``); the ``ardrone`` plant also at 0.7× its tilt gain."""
    q_x, q_v, r, period_s = _weights(config_dir)
    cfg = load_config(config_dir / STABILITY_CASES[0][2], [*LAB_OVERRIDES,
                                                           f"sim.plant.profile={plant}"])
    delay_s = cfg.sim.plant.command_delay_s
    if plant == KIT:
        plants = {name: KitXPlant(delay_s=delay_s, period_s=period_s, velocity_age_s=age)
                  for name, age in (("fresh", 0.0), ("aged", age_s))}
    else:
        p = cfg.sim.plant
        plants = {f"{g:g}_{name}": XPlant(p.tau_tilt_s, g, p.drag_per_s, delay_s, period_s, age)
                  for g in TILT_GAINS for name, age in (("fresh", 0.0), ("aged", age_s))}
    rows = stability_table([(n, d) for n, d, _ in STABILITY_CASES], q_x=q_x, q_v=q_v,
                           r_theta=r, plants=plants)
    for row, (_, _, name) in zip(rows, STABILITY_CASES):
        row["config"] = name
    return rows


def newton_flights(config_dir: Path, log_dir: Path, seed: int) -> dict:
    """The stability configs flown on the kit in the thesis formulation with the thesis'
    Newton solver: config name -> RunFigures."""
    return {name: fly(config_dir, name, NEWTON, "thesis", log_dir, seed, tag="-newton",
                      plant=KIT)
            for _, _, name in STABILITY_CASES if name}


def amplitude_flights(config_dir: Path, log_dir: Path, seed: int) -> dict:
    """:data:`AMPLITUDE_CONFIG` flown on the kit (thesis formulation, Newton solver) with x
    steps of :data:`AMPLITUDES_M`: step (m) -> RunFigures. Small steps follow the linear loop;
    the claim's 1.5 m saturates the tilt command."""
    return {a: fly(config_dir, AMPLITUDE_CONFIG, [*NEWTON, f"reference.target_m=[{-a},0,1]"],
                   "thesis", log_dir, seed, tag=f"-newton-{a:g}m", plant=KIT)
            for a in AMPLITUDES_M}


@dataclass(frozen=True)
class StepCheck:
    """A small x step flown on the kit (thesis formulation) against the linear loop."""

    solver: str
    max_error_frac: float  # max |x_flown − x_linear| over the step size
    rms_error_frac: float
    theta_peak_rad: float
    age_s: float


def small_step_checks(config_dir: Path, log_dir: Path, seed: int) -> list[StepCheck]:
    """Fly :data:`CHECK_STEP_M` in x on the kit with each solver and compare with the linear
    loop at the flight's mean navdata age."""
    out = []
    for solver in CHECK_SOLVERS:
        over = [*LAB_OVERRIDES, *FORMULATIONS["thesis"], f"sim.plant.profile={KIT}",
                f"controller.solver.method={solver}",
                f"reference.target_m=[{-CHECK_STEP_M},0,1]"]
        cfg = load_config(config_dir / "step_x.yaml", over)
        cfg = cfg.model_copy(update={"name": f"{cfg.name}-small-{KIT}-thesis-{solver}"})
        cols = record_lockstep(cfg, log_dir, seed=seed).run.columns
        t = np.asarray(cols["t_s"], float)
        window = np.isfinite(t) & (t >= 0)
        age_s = float(np.nanmean(np.asarray(cols["navdata_age_ms"], float)[window])) * 1e-3
        ctl = cfg.controller
        law = first_step_law(horizon_steps=ctl.horizon_steps, dtau_s=ctl.dtau_s,
                             q_x=ctl.q[IX_X], q_v=ctl.q[IX_VX], r_theta=ctl.r[IU_THETA])
        plant = KitXPlant(delay_s=cfg.sim.plant.command_delay_s, period_s=cfg.loop.period_s,
                          velocity_age_s=age_s)
        flown = np.asarray(cols["x_true_m"], float)[window]
        linear = step_response(law, plant, dtau_s=ctl.dtau_s, step_m=-CHECK_STEP_M,
                               step_s=cfg.reference.step_time_s, ticks=flown.size - 1)
        err = np.abs(flown - linear) / CHECK_STEP_M
        theta = np.asarray(cols["u_theta_rad"], float)[window]
        out.append(StepCheck(solver, float(err.max()), float(np.sqrt(np.mean(err ** 2))),
                             float(np.nanmax(np.abs(theta))), age_s))
    return out


def _flown(figs: dict | None, key) -> str:
    return figs[key].end("x").describe() if figs and key in figs else "not flown"


def render_amplitudes(flights: dict) -> list[str]:
    if not flights:
        return []
    return [f"By step size (`{AMPLITUDE_CONFIG}`, Newton solver, thesis formulation): "
            + "; ".join(f"{a:g} m — {f.end('x').describe()}, tilt command peak "
                        f"{f.input_peaks.get('x', math.nan):.2f}" for a, f in flights.items())
            + ". The loop the linearisation calls stable cycles once the tilt command "
            "saturates.", ""]


def render_kit(rows, age_s: float, flown: dict, newton: dict, checks) -> list[str]:
    lines = [
        f"### On `{KIT}`, the claims' own plant", "",
        "The kit's x channel under its command convention: θ = ssPitch(θ_cmd) (second order, "
        "0.41 rad of tilt per rad commanded at steady state), v̇ = −0.665 v + 6.15 θ — per rad "
        "commanded, 2.5 m/s² where the NMPC predicts g = 9.81 m/s².", "",
        f"| N | Δτ (s) | K₀ [x, ẋ] | ρ, fresh ẋ | ρ, ẋ {age_s * 1e3:.0f} ms old | flown, thesis "
        "formulation | flown, thesis formulation, Newton solver | flown, ours |",
        "|--:|--:|---|---|---|---|---|---|",
    ]
    for row in rows:
        figs = flown.get(row["config"])
        lines.append(
            f"| {row['N']} | {row['dtau_s']:g} | [{row['k_x']:.3f}, {row['k_v']:.3f}] | "
            + " | ".join(f"{row[f'rho_{k}']:.4f} ({verdict(row[f'rho_{k}'])})"
                         for k in ("fresh", "aged"))
            + f" | {_flown(figs, (KIT, 'thesis'))} | "
            + (newton[row["config"]].end("x").describe() if row["config"] in newton
               else "not flown")
            + f" | {_flown(figs, (KIT, 'ours'))} |")
    lines += ["", *kit_conclusion(rows, newton), ""]
    by = {c.solver: c for c in checks}
    if by:
        lines += [f"Small-signal check: a {CHECK_STEP_M:g} m x step flown on `{KIT}` in the "
                  "thesis formulation (tilt command peak "
                  f"{max(c.theta_peak_rad for c in checks):.3f} rad, far inside ±1) against "
                  "the linear loop at the flight's mean navdata age: "
                  + "; ".join(f"{c.solver} {c.max_error_frac:.1%} of the step at most, "
                              f"{c.rms_error_frac:.1%} rms" for c in checks)
                  + ". The linearisation is the converged NMPC's law; C/GMRES, one "
                  "continuation step per tick, follows it only approximately.", ""]
    return lines


def kit_conclusion(rows, newton: dict) -> list[str]:
    by_case = {(r["N"], r["dtau_s"]): r for r in rows}
    out = []
    for key in ("fresh", "aged"):
        v = {case: verdict(r[f"rho_{key}"]) for case, r in by_case.items()}
        unstable = [f"N = {n}, Δτ = {d:g}" for (n, d), x in v.items() if x != "stable"]
        out.append(f"* Linearised, {'fresh' if key == 'fresh' else 'aged'} ẋ: "
                   + (f"{', '.join(unstable)} not stable." if unstable else
                      "every case stable — neither N = 5 nor Δτ = 0.08 s is unstable at "
                      "small signals on the kit (ρ "
                      f"{min(r[f'rho_{key}'] for r in rows):.3f}–"
                      f"{max(r[f'rho_{key}'] for r in rows):.3f})."))
    unstable = [n for n, f in newton.items() if f.unstable]
    if newton:
        out.append("* Flown with the Newton solver (1.5 m step, the tilt command saturating at "
                   "±1): " + (", ".join(f"`{n}` {newton[n].end('x').describe()}"
                                        for n in unstable) or "every case settles")
                   + ("; the others settle." if unstable and len(unstable) < len(newton)
                      else "."))
    return out


def render_ardrone(rows, age_s: float, flown: dict) -> list[str]:
    keys = [(g, name) for g in TILT_GAINS for name in ("fresh", "aged")]
    lines = [
        "### On `ardrone`, beside", "",
        "The tum_ardrone airframe's x channel (docs/plant.md): the first-order tilt lag "
        "τ = 0.1 s, drag 0.58 /s, at the configured tilt gain g·tanθ and at 0.7 of it.", "",
        "| N | Δτ (s) | K₀ [x, ẋ] | "
        + " | ".join(f"ρ, tilt gain {g:g}, {'fresh ẋ' if n == 'fresh' else f'ẋ {age_s * 1e3:.0f} ms old'}"
                     for g, n in keys)
        + " | flown, thesis formulation | flown, ours |",
        "|--:|--:|---|" + "---|" * len(keys) + "---|---|",
    ]
    for row in rows:
        figs = flown.get(row["config"])
        lines.append(f"| {row['N']} | {row['dtau_s']:g} | [{row['k_x']:.3f}, {row['k_v']:.3f}] | "
                     + " | ".join(f"{row[f'rho_{g:g}_{n}']:.4f} "
                                  f"({verdict(row[f'rho_{g:g}_{n}'])})" for g, n in keys)
                     + f" | {_flown(figs, ('ardrone', 'thesis'))} | "
                       f"{_flown(figs, ('ardrone', 'ours'))} |")
    lines += ["", *ardrone_conclusion(rows, keys), ""]
    return lines


def ardrone_conclusion(rows, keys) -> list[str]:
    """What the table says about the two claims, from its verdicts."""
    by_case = {(r["N"], r["dtau_s"]): r for r in rows}
    n5, n6 = by_case[(5, 0.3)], by_case[(6, 0.3)]
    names = [f"{g:g}_{n}" for g, n in keys]
    gap = max(abs(n5[f"rho_{k}"] - n6[f"rho_{k}"]) for k in names)
    thesis_like = [k for k in names if verdict(n5[f"rho_{k}"]) == "unstable"
                   and verdict(n6[f"rho_{k}"]) == "stable"]
    out = [f"* N = 5 vs 6 at Δτ = 0.3 s: K₀,x {n5['k_x']:.3f} vs {n6['k_x']:.3f}, ρ within "
           f"{gap:.4f} of each other in every column; "
           + (f"N = 5 unstable and N = 6 stable in {', '.join(thesis_like)}."
              if thesis_like else "in no column is N = 5 unstable and N = 6 stable — the two "
              "are equally close to the edge, so no plant separates them and a flight cannot "
              "either.")]
    for (g, n), k in zip(keys, names):
        v = {d: verdict(by_case[(15, d)][f"rho_{k}"]) for d in (0.08, 0.1, 0.15)}
        like = v[0.08] == "unstable" and v[0.15] == "stable"
        out.append(f"* Δτ at N = 15, tilt gain {g:g}, {'fresh' if n == 'fresh' else 'aged'} "
                   f"ẋ: 0.08 s {v[0.08]}, 0.1 s {v[0.1]}, 0.15 s {v[0.15]}"
                   + (" — the thesis' boundary." if like else " — not the thesis' boundary."))
    return out


def x_loop_section(config_dir: Path, log_dir: Path, seed: int, flown: dict,
                   checks: bool = True) -> list[str]:
    """The whole section; ``flown``: config name -> {(plant, formulation): RunFigures}."""
    q_x, q_v, r, period_s = _weights(config_dir)
    kit_age = flight_age_s(flown, KIT)
    ard_age = flight_age_s(flown, "ardrone")
    lines = [
        "## N and Δτ: the linearised x loop", "",
        "The x channel at hover (`experiments/xchannel.py`): the NMPC's first-step law — the "
        f"gain K₀ on [x, ẋ] of its Euler-discretised prediction (q = [{q_x:g}, {q_v:g}], "
        f"r_θ = {r:g}, no terminal weight) and its preview of the reference over the horizon "
        "— against each plant's x channel, the command delay in whole "
        f"{period_s * 1e3:g} ms periods, and ẋ from navdata either fresh or as old as in the "
        "thesis formulation's flights on that plant (its mean age; x, from mocap, fresh). The "
        "thesis formulation: no delay compensation. ρ is the closed loop's spectral radius "
        "(> 1: unstable, within 0.001 of 1: marginal); a flight that saturates its tilt "
        "command can cycle where the linear loop is stable.", "",
    ]
    newton = newton_flights(config_dir, log_dir, seed)
    runs = small_step_checks(config_dir, log_dir, seed) if checks else []
    lines += render_kit(x_loop_rows(config_dir, KIT, kit_age), kit_age, flown, newton, runs)
    lines += render_amplitudes(amplitude_flights(config_dir, log_dir, seed) if checks else {})
    lines += render_ardrone(x_loop_rows(config_dir, "ardrone", ard_age), ard_age, flown)
    return lines
