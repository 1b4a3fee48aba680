"""``ardrone-nmpc reproduce``: every thesis experiment in simulation, judged against its claim.

Each claim of the thesis' results table (docs/thesis.md) names the runs it needs and where it
was made: simulation claims are judged on ``thesis_kit`` (the thesis' own simulator), the
experimental ones on ``ardrone_lab``, and every claim is shown on ``ardrone`` beside. Every run
is flown twice — in the thesis' own formulation (a delay-free prediction model, the ż
reference integrated over one period, navdata ẋ, ẏ) and in this tool's default — and the
claim is judged on each (``claims``, ``judges``). Beside the tables the report shows the
linearised x loop for the N/Δτ claims (``xloop``), the thesis' Newton solver on the ψ step,
and where the formulations narrow the thesis' (``sections``). :func:`reproduce` writes the report
(``report``) to ``docs/thesis-reproduction.md``; it is deterministic, and
tests/unit/test_reproduce_stale.py checks the committed file against a regenerated part.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from ardrone_nmpc.experiments.reproduce.claims import (
    BESIDE, FORMULATIONS, HOME_PLANTS, LAB_OVERRIDES, Claim, Outcome, claims, run_claims)
from ardrone_nmpc.experiments.reproduce.judges import (Motion, RunFigures, Verdict,
                                                       classify_motion)
from ardrone_nmpc.experiments.reproduce.report import COMMAND, render_markdown

__all__ = ["BESIDE", "COMMAND", "FORMULATIONS", "HOME_PLANTS", "LAB_OVERRIDES", "Claim",
           "Motion", "Outcome", "RunFigures", "Verdict", "classify_motion", "claims",
           "flown_by_config", "render_markdown", "reproduce", "run_claims", "report_sections"]


def flown_by_config(outcomes: list[Outcome]) -> dict:
    """config name -> {(plant, formulation): RunFigures} of the claims' runs."""
    flown: dict = {}
    for o in outcomes:
        for key, figs in o.runs.items():
            for label, (name, overrides) in o.claim.runs.items():
                if not overrides:
                    flown.setdefault(name, {})[key] = figs[label]
    return flown


def report_sections(outcomes: list[Outcome], *, config_dir: Path, log_dir: Path, seed: int,
                    progress: Callable[[str], None] | None = None) -> list[str]:
    """The sections beside the claims table (flies the Newton runs)."""
    from ardrone_nmpc.experiments.reproduce import sections as s
    from ardrone_nmpc.experiments.reproduce.xloop import x_loop_section

    if progress:
        progress("linearised x loop — Newton flights and the small-step check")
    lines = x_loop_section(config_dir, log_dir, seed, flown_by_config(outcomes))
    if progress:
        progress("thesis Newton solver — ψ step")
    runs = s.newton_runs(config_dir, log_dir, seed)
    solver = s.load_config(config_dir / "step_psi.yaml").controller.solver
    lines += s.render_newton(runs, s.newton_traces(runs[-1].path), solver.tolerance,
                             solver.max_newton_iterations)
    return lines + s.narrowings(config_dir)


def reproduce(*, config_dir: Path, log_dir: Path, seed: int = 0,
              progress: Callable[[str], None] | None = None) -> tuple[str, list[Outcome]]:
    """Fly every claim and the sections' runs; the report's text and the outcomes."""
    outcomes = run_claims(config_dir=config_dir, log_dir=log_dir, seed=seed, progress=progress)
    sections = report_sections(outcomes, config_dir=config_dir, log_dir=log_dir, seed=seed,
                               progress=progress)
    command = COMMAND if seed == 0 else f"{COMMAND} --seed {seed}"
    return render_markdown(outcomes, command=command, sections=sections), outcomes
