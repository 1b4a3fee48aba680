"""``docs/thesis-reproduction.md``: the claims table and the sections beside it.

Deterministic: nothing in it depends on wall time or the machine's clock (run directories are
named without their time stamp), so a regenerated report equals the committed one.
"""

from __future__ import annotations

import re

from ardrone_nmpc.experiments.reproduce.claims import FORMULATIONS, Outcome
from ardrone_nmpc.experiments.reproduce.judges import (BAD_SOLVES, GROWING, MIN_PERIODS,
                                                       NO_OVERSHOOT_PCT, SHRINKING)

COMMAND = "python -m ardrone_nmpc.cli.app reproduce"  # regenerates the committed report
TABLE_HEADER = ("| experiment | thesis | ours, thesis formulation | holds | "
                "ours, delay-compensated | holds | why ours differs |")


def run_name(path) -> str:
    """A run directory's name without its time stamp (``20261123-193338-`` prefix)."""
    return re.sub(r"^\d{8}-\d{6}-", "", path.name)


def claim_rows(outcomes: list[Outcome]) -> list[str]:
    """The claims table's rows, one per outcome."""
    rows = []
    for o in outcomes:
        t_text, t_ok = o.ours["thesis"]
        c_text, c_ok = o.ours["ours"]
        cells = [o.claim.experiment, o.claim.thesis, t_text, "✔" if t_ok else "✘", c_text,
                 "✔" if c_ok else "✘", o.claim.note]
        rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return rows


def render_markdown(outcomes: list[Outcome], *, command: str = COMMAND,
                    sections: list[str] = ()) -> str:
    held = {f: sum(o.ours[f][1] for o in outcomes) for f in FORMULATIONS}
    lines = [
        "# Thesis results reproduced in simulation",
        "",
        f"Produced by `{command}` (lockstep simulation of the AR.Drone closed loop of",
        "`docs/plant.md`: tilt/vertical/yaw inner loops, drag, noise, the thesis' 0.26 s command",
        "delay). Each experiment runs in two formulations: **thesis** — the thesis' delay-free",
        "prediction model, ż reference and navdata velocities (`"
        + "`, `".join(FORMULATIONS["thesis"]) + "`); **ours** — this",
        "tool's default, which predicts the state through the commands already sent, inverts the",
        "drone's 0.5 s vertical lag and differentiates the mocap position for ẋ, ẏ. Run",
        "directories are listed at the end; `ardrone-nmpc summary DIR` shows any in full.",
        "",
        f"{len(outcomes)} claims: {held['thesis']} hold in the thesis formulation, "
        f"{held['ours']} delay-compensated.",
        "",
        TABLE_HEADER,
        "|---|---|---|:-:|---|:-:|---|",
        *claim_rows(outcomes),
        "",
        "How a claim is judged:",
        "",
        "* *settles* — the summary's settling time exists: the 2 % band of the step entered and "
        "held to the end of the run, at least 1 s (runs/summary.py `step_metrics`);",
        f"* *without overshoot* — settles with an overshoot below {NO_OVERSHOOT_PCT:g} % of "
        "the step (inside the settling band);",
        "* the end of a run that does not settle is measured on its last third: *limit cycle* "
        f"(a swing of at least {MIN_PERIODS} full periods, peak-to-peak beyond twice the band; "
        "period from its zero crossings), *diverging* (its peak-to-peak more than "
        f"{GROWING:g}× the middle third's), *converging* (less than {SHRINKING:g}×), "
        "*unsettled* (none of these: an offset, a wander, or a swing too slow to show a period "
        "in the last third);",
        "* *unstable* — a limit cycle, diverging, ended early, or more than "
        f"{BAD_SOLVES:.0%} failed solves; *stable* — settles;",
        "* overshoot in % of the step; ψ in rad.",
        "",
        *sections,
        "## Run directories",
        "",
        "Under `--log-dir` (default `logs/reproduce`), each name preceded by its time stamp:",
        "",
    ]
    for o in outcomes:
        for form, figs in o.runs.items():
            for label, fig in figs.items():
                lines.append(f"* {o.claim.experiment} — {label} ({form}): `{run_name(fig.path)}`")
    return "\n".join(lines) + "\n"
