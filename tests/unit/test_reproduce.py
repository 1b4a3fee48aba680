"""The thesis-claim judges of `reproduce`, on hand-made figures (a full run is a CLI job)."""

import math
from pathlib import Path

import pytest

from ardrone_nmpc.experiments.reproduce import Outcome, RunFigures, claims, render_markdown


def fig(metrics=None, unstable=False, input_peak=0.5):
    return RunFigures(metrics or {}, unstable, input_peak, Path("run"))


CLAIMS = {c.experiment: c for c in claims()}


def test_every_thesis_row_has_a_claim_with_existing_configs():
    assert len(CLAIMS) == 12
    for claim in CLAIMS.values():
        for config, _ in claim.runs.values():
            assert (Path("configs") / config).is_file(), config


@pytest.mark.parametrize("overshoot, holds", [(60.0, True), (30.0, False)])
def test_no_estimate_claim_needs_overshoot_above_45(overshoot, holds):
    judge = CLAIMS["NMPC altitude, no ż estimate"].judge
    text, ok = judge({"nmpc": fig({("z", "overshoot"): overshoot,
                                   ("z", "settling_time"): math.nan})})
    assert ok is holds and f"{overshoot:.0f} %" in text


def test_stability_claim_needs_the_unstable_and_the_stable_case():
    judge = CLAIMS["N = 5 vs 6 at Δτ = 0.3"].judge
    assert judge({"N=5": fig(unstable=True), "N=6": fig()})[1] is True
    assert judge({"N=5": fig(), "N=6": fig()})[1] is False
    assert judge({"N=5": fig(unstable=True), "N=6": fig(unstable=True)})[1] is False


def test_r_cases_need_ordered_rise_times_and_more_overshoot_for_case_3():
    judge = CLAIMS["r Case 1 / 2 / 3"].judge

    def case(rise, over):
        return fig({("x", "rise_time"): rise, ("x", "overshoot"): over})

    assert judge({"case1": case(1.3, 1.0), "case2": case(1.2, 2.0), "case3": case(0.9, 4.0)})[1]
    assert not judge({"case1": case(1.0, 1.0), "case2": case(1.2, 2.0),
                      "case3": case(0.9, 4.0)})[1]


def test_inputs_claim_needs_p_well_beyond_the_bound():
    judge = CLAIMS["NMPC inputs vs P"].judge
    runs = {"nmpc_z": fig(input_peak=0.4), "nmpc_psi": fig(input_peak=0.9),
            "p_z": fig(input_peak=0.5), "p_psi": fig(input_peak=1.6)}
    assert judge(runs)[1] is True
    runs["p_psi"] = fig(input_peak=1.0)
    assert judge(runs)[1] is False


def test_markdown_table_has_one_row_per_claim_and_no_broken_cells():
    outcomes = []
    for claim in claims():
        o = Outcome(claim)
        o.ours = {"thesis": ("a | b", False), "ours": ("c", True)}
        o.runs = {"thesis": {}, "ours": {}}
        outcomes.append(o)
    text = render_markdown(outcomes, command="ardrone-nmpc reproduce")
    rows = [line for line in text.splitlines() if line.startswith("| ") and "---" not in line]
    assert len(rows) == 1 + len(outcomes)
    # a bare "|" inside a cell would shift the columns: cells escape it as "\\|"
    separators = [row.replace("\\|", "").count("|") for row in rows]
    assert separators == [separators[0]] * len(rows)
    assert "a \\| b" in text
