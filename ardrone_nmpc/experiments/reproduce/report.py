"""``docs/thesis-reproduction.md``: the claims tables and the sections beside them.

Deterministic: nothing in it depends on wall time or the machine's clock (run directories are
named without their time stamp), so a regenerated report equals the committed one.
"""

from __future__ import annotations

import re

from ardrone_nmpc.experiments.reproduce.claims import (BESIDE, FORMULATIONS, HOME_PLANTS,
                                                       MUCH_LARGER, PATH_TOLERANCE,
                                                       SMALL_OVERSHOOT_PCT, Outcome)
from ardrone_nmpc.experiments.reproduce.judges import (BAD_SOLVES, GROWING, MIN_PERIODS,
                                                       NO_OVERSHOOT_PCT, SETTLING_TOLERANCE,
                                                       SHRINKING, Verdict)

COMMAND = "python -m ardrone_nmpc.cli.app reproduce"  # regenerates the committed report
FORM_NAMES = {"thesis": "thesis formulation", "ours": "delay-compensated"}
SETTING_NAMES = {"simulation": "simulation", "experiment": "experimental"}
TABLE_HEADER = ("| experiment | thesis | judged on | thesis formulation | holds | "
                "delay-compensated | holds | on `ardrone`: thesis / delay-comp. |")
BESIDE_HEADER = ("| experiment | thesis formulation | holds | delay-compensated | holds | "
                 "why |")


def run_name(path) -> str:
    """A run directory's name without its time stamp (``20261123-193338-`` prefix)."""
    return re.sub(r"^\d{8}-\d{6}-", "", path.name)


def _mark(v: Verdict) -> str:
    return "✔" if v.holds else "✘"


def _row(cells) -> str:
    return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"


def claim_rows(outcomes: list[Outcome]) -> list[str]:
    """The main table's rows: each claim on its own plant, ``ardrone``'s verdicts beside."""
    rows = []
    for o in outcomes:
        home, beside = o.claim.plants
        t, c = o.verdict(home, "thesis"), o.verdict(home, "ours")
        bt, bc = o.verdict(beside, "thesis"), o.verdict(beside, "ours")
        rows.append(_row([o.claim.experiment, o.claim.thesis, f"`{home}`", t.text, _mark(t),
                          c.text, _mark(c), f"{_mark(bt)} / {_mark(bc)}"]))
    return rows


def beside_rows(outcomes: list[Outcome]) -> list[str]:
    """The ``ardrone`` table's rows."""
    rows = []
    for o in outcomes:
        t, c = o.verdict(BESIDE, "thesis"), o.verdict(BESIDE, "ours")
        rows.append(_row([o.claim.experiment, t.text, _mark(t), c.text, _mark(c),
                          o.claim.beside_note]))
    return rows


def failures(outcomes: list[Outcome], *, beside: bool = False) -> list[str]:
    """One item per claim with a ✘: each failed condition, and (for the thesis formulation on
    the claim's own plant) why."""
    lines = []
    for o in outcomes:
        plant = BESIDE if beside else o.claim.plants[0]
        parts = [f"{FORM_NAMES[f]}: " + "; ".join(o.verdict(plant, f).failed)
                 for f in FORMULATIONS if not o.verdict(plant, f).holds]
        if not parts:
            continue
        why = "" if beside or o.verdict(plant, "thesis").holds else o.claim.note
        lines.append(f"* **{o.claim.experiment}** (`{plant}`) — " + " — ".join(parts)
                     + (f". *Why:* {why}" if why else "."))
    return lines


def _counts(outcomes: list[Outcome]) -> list[str]:
    out = []
    for form in FORMULATIONS:
        per = []
        for setting, plant in HOME_PLANTS.items():
            mine = [o for o in outcomes if o.claim.setting == setting]
            held = sum(o.verdict(plant, form).holds for o in mine)
            per.append(f"{held} of {len(mine)} {SETTING_NAMES[setting]} claims on `{plant}`")
        beside = sum(o.verdict(BESIDE, form).holds for o in outcomes)
        out.append(f"* {FORM_NAMES[form]}: {' and '.join(per)}; on `{BESIDE}` {beside} of "
                   f"{len(outcomes)}.")
    return out


def _judging() -> list[str]:
    return [
        "How a claim is judged:", "",
        "* every run of a claim must fly its whole experiment under the controller: a claim "
        "fails if the supervisor flew any tick of it (a mode other than `track`) or a run "
        "ended early;",
        "* *settles* — the summary's settling time exists: the 2 % band of the step entered and "
        "held to the end of the run, at least 1 s (runs/summary.py `step_metrics`); a step "
        f"claim's settling times must be within ±{SETTLING_TOLERANCE:.0%} of the thesis' "
        "figures (it reads them off its plots without naming a band: a first-order response "
        "enters a 2 % band 30 % later than a 5 % one, and a plot reads to about ±0.5 s);",
        f"* *without overshoot* — settles with an overshoot below {NO_OVERSHOOT_PCT:g} % of "
        "the step (inside the settling band); *similar* estimators — settling times within "
        f"±{SETTLING_TOLERANCE:.0%} of each other;",
        "* the end of a run that does not settle is measured on its last third: *limit cycle* "
        f"(a swing of at least {MIN_PERIODS} full periods, peak-to-peak beyond twice the band; "
        "period from its zero crossings), *diverging* (its peak-to-peak more than "
        f"{GROWING:g}× the middle third's), *converging* (less than {SHRINKING:g}×), "
        "*unsettled* (none of these: an offset, a wander, or a swing too slow to show a period "
        "in the last third);",
        "* *unstable* — a limit cycle, diverging, ended early, or more than "
        f"{BAD_SOLVES:.0%} failed solves; *stable* — settles;",
        "* inputs — each controller's input on the stepped axis (θ, φ, u1, ψ̇; u1 is z̈ for the "
        "NMPC, the ż reference for P): the NMPC's within ±1 on every input, and P's peak at "
        f"least {MUCH_LARGER:g}× the NMPC's on every axis (either can fail);",
        "* r cases — rise times ordered Case 1 > 2 > 3 with each gap at least one control tick; "
        f"all settle; Case 2 without overshoot; Case 3 with a small one ({NO_OVERSHOOT_PCT:g}–"
        f"{SMALL_OVERSHOOT_PCT:g} %);",
        f"* paths — the mean deviation within ±{PATH_TOLERANCE:.0%} of the thesis' experimental "
        "figure (too good fails as too bad does);",
        "* overshoot in % of the step; ψ in rad.", "",
    ]


def render_markdown(outcomes: list[Outcome], *, command: str = COMMAND,
                    sections: list[str] = ()) -> str:
    kit, lab = HOME_PLANTS["simulation"], HOME_PLANTS["experiment"]
    lines = [
        "# Thesis results reproduced in simulation",
        "",
        f"Produced by `{command}` (lockstep simulation). Each claim is judged where the thesis "
        f"made it: its simulation claims on `{kit}` — the ARDrone Simulink Development Kit it "
        "simulated with, driven as the kit's Baseline Controller drives it (its command "
        "convention, noise-free outputs, its P gains; docs/plant-profiles.md §2) — and its "
        f"experimental claims, the square paths, on `{lab}`, the AR.Drone plant calibrated on "
        f"the thesis' experimental square (§3). The default `{BESIDE}` plant is shown beside. "
        "Each in two formulations: **thesis formulation** — the thesis' delay-free prediction "
        "model, ż reference and navdata velocities (`" + "`, `".join(FORMULATIONS["thesis"])
        + "`); **delay-compensated** — this tool's default, which predicts the state through "
        "the commands already sent, inverts the `ardrone` plant's vertical lag and "
        "differentiates the mocap position for ẋ, ẏ. Run directories are listed at the end; `ardrone-nmpc summary DIR` "
        "shows any in full.",
        "",
        f"Of the {len(outcomes)} claims, on their own plants (and on `{BESIDE}`):",
        "",
        *_counts(outcomes),
        "",
        TABLE_HEADER,
        "|---|---|---|---|:-:|---|:-:|:-:|",
        *claim_rows(outcomes),
        "",
        "What fails, condition by condition (the thesis formulation's with why; the "
        "delay-compensated column is this tool's default, tuned on `ardrone`: its ż lead "
        "inverts that plant's vertical lag, not the kit's, and it predicts through the delay "
        "with the NMPC's model, whose tilt gain is four times the kit's):",
        "",
        *failures(outcomes),
        "",
        *_judging(),
        f"## Beside: the same claims on `{BESIDE}`",
        "",
        f"The tum_ardrone airframe (docs/plant.md) with the thesis simulator's 0.26 s delay, "
        "the SDK's command convention (the NMPC's tilt bound is the drone's 0.21 rad) and our "
        "P gains.",
        "",
        BESIDE_HEADER,
        "|---|---|:-:|---|:-:|---|",
        *beside_rows(outcomes),
        "",
        *failures(outcomes, beside=True),
        "",
        *sections,
        "## Run directories",
        "",
        "Under `--log-dir` (default `logs/reproduce`), each name preceded by its time stamp:",
        "",
    ]
    for o in outcomes:
        for (plant, form), figs in o.runs.items():
            for label, fig in figs.items():
                lines.append(f"* {o.claim.experiment} — {label} ({plant}, {form}): "
                             f"`{run_name(fig.path)}`")
    return "\n".join(lines) + "\n"
