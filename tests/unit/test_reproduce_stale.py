"""docs/thesis-reproduction.md cannot go stale: parts of it are regenerated here and must be in
the committed file verbatim. If this fails, regenerate the report (one command, from the
repository root):

    python -m ardrone_nmpc.cli.app reproduce

and commit docs/thesis-reproduction.md. The claims checked here fly in well under a minute;
the full report takes a few (every claim on its own plant and on `ardrone`, in both
formulations).
"""

from pathlib import Path

import pytest

from ardrone_nmpc.experiments.reproduce import COMMAND, flown_by_config, run_claims
from ardrone_nmpc.experiments.reproduce import sections as s
from ardrone_nmpc.experiments.reproduce.report import beside_rows, claim_rows, failures
from ardrone_nmpc.experiments.reproduce.xloop import x_loop_section

REPORT = Path("docs/thesis-reproduction.md")
CONFIGS = Path("configs")
# one claim per kind of judge that a code change could move: a step pair, the two stability
# pairs (every run the linearised section sets beside), the r cases
QUICK = ["ψ: 0 → 1 rad", "N = 5 vs 6 at Δτ = 0.3", "Δτ at N = 15", "r Case 1 / 2 / 3"]
STALE = f"docs/thesis-reproduction.md is stale: regenerate it with `{COMMAND}`"


@pytest.fixture(scope="module")
def committed() -> str:
    assert REPORT.is_file(), STALE
    return REPORT.read_text()


@pytest.fixture(scope="module")
def log_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("reproduce")


@pytest.fixture(scope="module")
def quick_outcomes(log_dir):
    return run_claims(config_dir=CONFIGS, log_dir=log_dir, only=QUICK)


def test_regenerated_claim_rows_are_the_committed_ones(committed, quick_outcomes):
    assert [o.claim.experiment for o in quick_outcomes] == QUICK
    lines = (claim_rows(quick_outcomes) + beside_rows(quick_outcomes) + failures(quick_outcomes)
             + failures(quick_outcomes, beside=True))
    for line in lines:
        assert line in committed, f"{STALE}\nregenerated line not in the report:\n{line}"


def test_regenerated_x_loop_section_and_narrowings_are_the_committed_ones(committed, log_dir,
                                                                          quick_outcomes):
    section = x_loop_section(CONFIGS, log_dir, 0, flown_by_config(quick_outcomes))
    for line in section + s.narrowings(CONFIGS):
        if "not flown" in line:  # a case whose runs this quick subset does not fly
            line = line.split("| not flown")[0]
        assert line in committed, f"{STALE}\nregenerated line not in the report:\n{line}"


def test_the_report_names_the_command_that_regenerates_it(committed):
    assert f"Produced by `{COMMAND}`" in committed
