"""docs/thesis-reproduction.md cannot go stale: parts of it are regenerated here and must be in
the committed file verbatim. If this fails, regenerate the report (one command, from the
repository root):

    python -m ardrone_nmpc.cli.app reproduce

and commit docs/thesis-reproduction.md. The claims checked here fly in a few seconds; the
full report takes about a minute (every claim in both formulations).
"""

from pathlib import Path

import pytest

from ardrone_nmpc.experiments.reproduce import COMMAND, run_claims
from ardrone_nmpc.experiments.reproduce import sections as s
from ardrone_nmpc.experiments.reproduce.report import claim_rows

REPORT = Path("docs/thesis-reproduction.md")
CONFIGS = Path("configs")
# one claim per kind of judge that a code change could move: a step pair, the stability pair
QUICK = ["ψ: 0 → 1 rad", "N = 5 vs 6 at Δτ = 0.3", "r Case 1 / 2 / 3"]
STALE = f"docs/thesis-reproduction.md is stale: regenerate it with `{COMMAND}`"


@pytest.fixture(scope="module")
def committed() -> str:
    assert REPORT.is_file(), STALE
    return REPORT.read_text()


@pytest.fixture(scope="module")
def quick_outcomes(tmp_path_factory):
    return run_claims(config_dir=CONFIGS, log_dir=tmp_path_factory.mktemp("reproduce"),
                      only=QUICK)


def test_regenerated_claim_rows_are_the_committed_ones(committed, quick_outcomes):
    assert [o.claim.experiment for o in quick_outcomes] == QUICK
    for row in claim_rows(quick_outcomes):
        assert row in committed, f"{STALE}\nregenerated row not in the report:\n{row}"


def test_regenerated_x_loop_table_and_narrowings_are_the_committed_ones(committed,
                                                                         quick_outcomes):
    flown = {}
    for o in quick_outcomes:
        for form, figs in o.runs.items():
            for label, (name, _) in o.claim.runs.items():
                flown.setdefault(name, {})[form] = figs[label]
    rows, plant, weights = s.x_loop_rows(CONFIGS)
    for line in s.render_x_loop(rows, plant, weights, flown) + s.narrowings(CONFIGS):
        if "not flown" in line:  # a case whose runs this quick subset does not fly
            line = line.split("| not flown")[0]
        assert line in committed, f"{STALE}\nregenerated line not in the report:\n{line}"


def test_the_report_names_the_command_that_regenerates_it(committed):
    assert f"Produced by `{COMMAND}`" in committed
