"""``ardrone-nmpc faults``: the fault matrix (every injected fault × hover, step, square)."""

from __future__ import annotations

from pathlib import Path

from ardrone_nmpc.errors import UserError


class FaultsUsageError(UserError):
    """An unknown experiment or fault name, or a missing config (exit 1)."""


class FaultCasesFailed(UserError):
    """At least one case of the matrix does not pass (exit 1)."""


def _names(text: str | None, known, option: str) -> None:
    if text is None:
        return
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise FaultsUsageError(f"{option}: unknown {', '.join(unknown) or '(empty)'}; "
                               f"choose from {', '.join(known)}")


def faults_command(*, json_out: Path | None, markdown: Path | None, experiments: str,
                   only: str | None, config_dir: Path, log_dir: Path | None,
                   seed: int, jobs: int = 1) -> None:
    """Check the options, run the matrix, write the reports; FaultCasesFailed if a case
    does not pass."""
    from ardrone_nmpc.experiments.faultmatrix import (EXPERIMENTS, FAULT_CASES,
                                                      run_faults_command)

    _names(experiments, EXPERIMENTS, "--experiments")
    _names(only, FAULT_CASES, "--faults")
    for kind in (n.strip() for n in experiments.split(",") if n.strip()):
        if not (config_dir / EXPERIMENTS[kind][0]).is_file():
            raise FaultsUsageError(f"--config-dir: {config_dir / EXPERIMENTS[kind][0]} not found")
    for report in (json_out, markdown):  # written at the end: make their folders now
        if report is not None:
            report.parent.mkdir(parents=True, exist_ok=True)
    ok = run_faults_command(json_out=json_out, markdown=markdown, experiments=experiments,
                            only=only, config_dir=config_dir, log_dir=log_dir, seed=seed,
                            jobs=jobs)
    if not ok:
        raise FaultCasesFailed("not every fault case passes (see the table)")
