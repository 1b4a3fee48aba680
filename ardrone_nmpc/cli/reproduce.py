"""``ardrone-nmpc reproduce``: every thesis claim flown in simulation, written as Markdown."""

from __future__ import annotations

from pathlib import Path

import typer


def reproduce_command(*, out: Path, log_dir: Path, config_dir: Path, seed: int) -> None:
    """Run the claims (progress on stderr), write the report to ``out``, print a verdict."""
    from rich.progress import Progress

    from ardrone_nmpc.cli.console import stderr_console, stdout_console
    from ardrone_nmpc.experiments.reproduce import FORMULATIONS, reproduce

    with Progress(console=stderr_console(), transient=True) as progress:
        task = progress.add_task("reproducing", total=None)
        text, outcomes = reproduce(
            config_dir=config_dir, log_dir=log_dir, seed=seed,
            progress=lambda text: progress.update(task, description=text))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    held = {form: sum(o.verdict(o.claim.plants[0], form).holds for o in outcomes)
            for form in FORMULATIONS}
    stdout_console().print(f"{len(outcomes)} claims on their own plants: {held['thesis']} hold "
                           f"in the thesis formulation, {held['ours']} delay-compensated")
    typer.echo(f"report: {out}")
