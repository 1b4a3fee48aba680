"""``ardrone-nmpc replay``: re-summarise a run, re-run its controller, or re-send its poses.

The work is in :mod:`ardrone_nmpc.experiments.replay`; this module checks the option combinations, runs
it with progress and prints the tables. Bad option combinations are a
:class:`ReplayUsageError` (one line per problem); like every other user error it reaches the
command line's one handler (``error: …`` lines, exit code 1).
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn
from rich.table import Table

from ardrone_nmpc.cli.console import run_notes, stdout_console
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.limits import MAX_NAME_CHARS, RERUN_SUFFIX
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.experiments.record import record
from ardrone_nmpc.runs.rundir import CONFIG_FILE, RunData, RunRecorder, read_run
from ardrone_nmpc.experiments.replay import (
    COMPARED_COLUMNS, RERUN_FILE, RerunResult, broadcast, missing_rerun_columns,
    require_rerun_columns, rerun, write_rerun_csv,
)
from ardrone_nmpc.cli.tables import render_summary
from ardrone_nmpc.runs.summary import summarise

#: ``--rerun`` on an unchanged config must reproduce every command within this (issue target).
REPRODUCE_TOLERANCE = 1e-9


class ReplayUsageError(UserError):
    """Options that do not go together: ``messages`` for the user, one per line (exit 1)."""

    def __init__(self, messages: list[str] | str) -> None:
        self.messages = [messages] if isinstance(messages, str) else list(messages)
        super().__init__("; ".join(self.messages))


def _check_options(*, rerun_: bool, overrides: list[str], log_dir: Path | None,
                   broadcast_: bool, speed: float | None, port: int | None,
                   host: str | None) -> None:
    """Options that belong to a mode need that mode; the two modes exclude each other."""
    errors = []
    if rerun_ and broadcast_:
        errors.append("--rerun and --broadcast: choose one")
    for given, flag in ((overrides, "--set"), (log_dir is not None, "--log-dir")):
        if given and not rerun_:
            errors.append(f"{flag} applies to --rerun only")
    for value, flag in ((speed, "--speed"), (port, "--port"), (host, "--host")):
        if value is not None and not broadcast_:
            errors.append(f"{flag} applies to --broadcast only")
    if errors:
        raise ReplayUsageError(errors)


def run_replay_command(*, run_dir: Path, rerun_: bool = False, overrides: list[str] = (),
                       log_dir: Path | None = None, broadcast_: bool = False,
                       speed: float | None = None, port: int | None = None,
                       host: str | None = None, console: Console | None = None) -> Path | None:
    """The ``replay`` command; returns the new run directory of ``--rerun`` (else None).

    Raises :class:`ReplayUsageError` for options that do not go together; the errors of
    reading the run, its config and re-running it (LogError, ConfigError, ReplayError, …)
    as they are.
    """
    overrides = list(overrides)
    _check_options(rerun_=rerun_, overrides=overrides, log_dir=log_dir, broadcast_=broadcast_,
                   speed=speed, port=port, host=host)
    console = console or stdout_console()
    run = read_run(run_dir)
    run_notes(run)
    if rerun_:
        return _rerun(run=run, overrides=overrides, log_dir=log_dir or Path("logs"),
                      console=console)
    if broadcast_:
        _broadcast(run=run, host=host, port=port, speed=speed or 1.0, console=console)
        return None
    _resummarise(run=run, console=console)
    return None


# ----------------------------------------------------------------------------- modes


def _resummarise(*, run: RunData, console: Console) -> None:
    """The summary recomputed from ``log.csv`` by this version (the run dir is not touched)."""
    console.print(render_summary(summarise(run), title=f"{run.path.name} (re-summarised)"))
    missing = missing_rerun_columns(run=run)
    made_by = f"ardrone-nmpc {run.version}" if run.version else "an unknown version"
    note = (f"--rerun not possible: log.csv lacks {', '.join(missing)}" if missing
            else "--rerun possible")
    console.print(f"{run.n_rows} ticks, written by {made_by}, seed {run.seed}; {note}")


def _rerun(*, run: RunData, overrides: list[str], log_dir: Path, console: Console) -> Path:
    """Recompute every command into a new run directory linked to the original."""
    cfg = load_config(run.path / CONFIG_FILE, overrides, allow_retired=True)
    if not cfg.name.endswith(RERUN_SUFFIX):  # cut a long name: the result must still load
        name = cfg.name[:MAX_NAME_CHARS - len(RERUN_SUFFIX)] + RERUN_SUFFIX
        cfg = cfg.model_copy(update={"name": name})
    require_rerun_columns(run=run)  # before a run directory is created for nothing
    columns = [TextColumn("{task.description}"), BarColumn(),
               TextColumn("{task.percentage:>3.0f}%")]

    def fly(recorder: RunRecorder) -> RerunResult:
        recorder.event(0.0, "replay", source=str(run.path.resolve()), overrides=overrides,
                       source_version=run.version)
        with Progress(*columns, console=console, transient=True) as progress:
            task = progress.add_task("re-running", total=1.0)
            result = rerun(run=run, cfg=recorder.config, recorder=recorder,
                           progress=lambda f: progress.update(task, completed=f))
        write_rerun_csv(result=result, path=recorder.path / RERUN_FILE)
        return result

    recording = record(cfg, log_dir, seed=run.seed, fly=fly)
    result = recording.result
    console.print(_diff_table(result, title=f"{run.path.name}: recomputed − logged"))
    console.print(_cost_table(result))
    console.print("cost = Σ ½(eᵀQe + uᵀRu)·Δt over the experiment (t ≥ 0); q, r of the rerun "
                  "config; e = logged state − reference")
    console.print("open-loop counterfactual: the logged states did not respond to the "
                  "recomputed inputs, so only the input part differs")
    _verdict(result=result, changed=bool(overrides), console=console)
    return recording.path


def _broadcast(*, run: RunData, host: str | None, port: int | None, speed: float,
               console: Console) -> None:
    """Re-send the logged poses; an explicit ``--host`` may leave the machine."""
    target_port = port if port is not None else run.config.mocap.port
    target_host = host if host is not None else "127.0.0.1"
    console.print(f"broadcasting the poses of {run.path.name} to {target_host}:{target_port} "
                  f"as {run.config.mocap.object_name!r} at {speed:g}× …")
    try:
        with Progress(console=console, transient=True) as progress:
            task = progress.add_task("sending", total=1.0)
            sent = broadcast(run=run, host=target_host, port=target_port, speed=speed,
                             allow_remote=host is not None,
                             progress=lambda f: progress.update(task, completed=f))
    except ValueError as err:  # a non-loopback default, a bad port or name
        raise ReplayUsageError(str(err)) from None
    skipped = f" ({sent.skipped} without a logged position skipped)" if sent.skipped else ""
    console.print(f"sent {sent.frames} poses spanning {sent.span_s:.2f} s of flight to "
                  f"{sent.target[0]}:{sent.target[1]}{skipped}")


# ----------------------------------------------------------------------------- output


def _diff_table(result: RerunResult, *, title: str) -> Table:
    """max |Δ| per command column, with the tick where it happens and how many differ."""
    table = Table(title=title)
    for name, justify in (("column", "left"), ("max |Δ|", "right"), ("at t_s", "right"),
                          (f"ticks |Δ| > {REPRODUCE_TOLERANCE:g}", "right")):
        table.add_column(name, justify=justify)
    for c in COMPARED_COLUMNS:
        d = abs(result.diff[c])
        worst = int(d.argmax()) if d.size else 0
        at = f"{result.t_s[worst]:.3f}" if d.size and d[worst] > 0 else "—"
        table.add_row(c, f"{result.max_abs_diff[c]:.3g}", at,
                      str(int((d > REPRODUCE_TOLERANCE).sum())))
    return table


def _cost_table(result: RerunResult) -> Table:
    cost = result.cost
    table = Table(title=f"stage cost, {cost.rows} ticks", min_width=48)
    table.add_column("part")
    table.add_column("logged u", justify="right")
    table.add_column("recomputed u", justify="right")
    table.add_row("state (shared)", f"{cost.state:.6g}", f"{cost.state:.6g}")
    table.add_row("input", f"{cost.input_logged:.6g}", f"{cost.input_rerun:.6g}")
    table.add_row("total", f"{cost.logged:.6g}", f"{cost.rerun:.6g}")
    return table


def _verdict(*, result: RerunResult, changed: bool, console: Console) -> None:
    worst = result.max_abs_diff_overall
    modes = result.mode_mismatches
    if changed:
        console.print(f"counterfactual (--set): max |Δ| {worst:.3g}, {modes} ticks in another "
                      f"mode; the logged states did not respond to these commands")
    elif worst <= REPRODUCE_TOLERANCE and modes == 0:
        console.print(f"[green]reproduced[/]: max |Δ| {worst:.3g} ≤ {REPRODUCE_TOLERANCE:g}")
    else:
        console.print(f"[yellow]not reproduced[/]: max |Δ| {worst:.3g} (tolerance "
                      f"{REPRODUCE_TOLERANCE:g}), {modes} ticks in another mode")
    if result.unlogged_pose_rows:
        console.print(f"{result.unlogged_pose_rows} ticks saw a pose whose position was not "
                      f"logged (stale-mocap hover): replayed without it")
