"""``ardrone-nmpc tune``: search controller weights (and more) by optimisation, not by grid.

The parts are in :mod:`ardrone_nmpc.experiments.tune` (space, objective, engines, study);
this module drives them: options, the progress bar (stderr), the ranked table (stdout),
``trials.csv`` and ``best.yaml`` in ``-o/--output``. :func:`register` adds the command to the app.
"""

from __future__ import annotations

import math
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional

import typer

__all__ = ["TuneOutcome", "register", "run_tune_command"]

SAVE_EVERY_S = 5.0


@dataclass
class TuneOutcome:
    """Where the study's files are, how many trials it holds and how many were flown now,
    the best score, the wall time (s), the simulated time flown (s), and the interrupt (Ctrl-C,
    a signal) that stopped it, if any."""

    out_dir: Path
    total: int
    flown: int
    best_score: float
    best_path: Path | None
    wall_s: float
    sim_s: float
    interrupt: BaseException | None = None  # the Ctrl-C or signal that stopped it

    @property
    def interrupted(self) -> bool:
        return self.interrupt is not None


def _check_options(*, engine: str, scheduler: str | None) -> None:
    import importlib.util

    from ardrone_nmpc.config.schema import ConfigError
    from ardrone_nmpc.experiments.parallel import engine_errors

    errors = engine_errors(engine=engine, scheduler=scheduler)
    if importlib.util.find_spec("optuna") is None:
        errors.append("tune needs Optuna: pip install 'ardrone-nmpc[tune]'")
    if errors:
        raise ConfigError(errors)


def _set_paths(overrides) -> set[str]:
    return {o.partition("=")[0].strip() for o in overrides if "=" in o}


def _named(data, path: str) -> bool:
    """Whether the config mapping ``data`` (as written) names the dotted ``path``."""
    node = data
    for key in path.split("."):
        if not isinstance(node, dict) or key not in node:
            return False
        node = node[key]
    return True


def _variants(texts, *, written, overrides) -> list[tuple[str, tuple[str, ...]]]:
    """``--variant`` texts (``label:path=v;path=v`` or ``path=v;…``) → (label, overrides);
    none given: the plant profiles, if the schema has them and the config (or ``--set``) does
    not name one — a named profile is flown, alone. A ``--set`` of a path a variant sets per
    scenario is refused: it would be overridden on every flight."""
    from ardrone_nmpc.config.schema import ConfigError
    from ardrone_nmpc.experiments.tune.engine import plant_variants

    if not texts:
        return [] if _named(written, "sim.plant.profile") else plant_variants()
    out, errors = [], []
    for i, text in enumerate(texts):
        label, sep, rest = text.partition(":")
        if not sep or "=" in label:
            label, rest = f"v{i}", text
        items = tuple(s.strip() for s in rest.split(";") if s.strip())
        if not items or any("=" not in o for o in items):
            errors.append(f"--variant {text!r}: expected [label:]path=value;path=value…")
        clash = sorted(_set_paths(items) & _set_paths(overrides))
        if clash:
            errors.append(f"--set {', '.join(clash)}: --variant {text!r} sets it per scenario; "
                          "give it in the variants only")
        out.append((label.strip(), items))
    if errors:
        raise ConfigError(errors)
    return out


def _cell(value: float) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.4g}"


def _ranked_table(study, *, space, scenarios, top: int):
    from rich.markup import escape
    from rich.table import Table

    from ardrone_nmpc.experiments.tune.study import finished_trials, result_of

    trials = sorted(finished_trials(study), key=lambda t: (t.value, t.number))[:top]
    table = Table(title=f"best {len(trials)} of {len(finished_trials(study))} trials "
                        f"(score: lower is better; metrics: mean over {len(scenarios)} "
                        "scenarios)")
    for head in ("#", "trial", "score", "status"):
        table.add_column(head, justify="right" if head != "status" else "left")
    labels = [n.split(".")[-1] for n in space]
    for label in labels:
        table.add_column(label, justify="right")
    means = {"tracking_m": "track_m", "settling_s": "settle_s", "overshoot_pct": "over_%",
             "supervisor_ticks": "superv"}
    for head in means.values():
        table.add_column(head, justify="right")
    style = {"ok": "green", "aborted": "yellow", "failed": "red"}
    for i, t in enumerate(trials, start=1):
        metrics = result_of(t).get("metrics", {})
        row = [str(i), str(t.number), _cell(t.value)]
        status = result_of(t).get("status", "")
        row.append(f"[{style.get(status, 'white')}]{escape(status)}[/]")
        row += [_cell(t.params.get(n)) for n in space]
        for m in means:
            vals = [s.get(m, math.nan) for s in metrics.values()]
            vals = [v for v in vals if v is not None and math.isfinite(v)]
            row.append(_cell(sum(vals) / len(vals)) if vals else "—")
        table.add_row(*row)
    return table


def _trials_writer(out_dir: Path, study, *, cfg, space, scen, obj, command: str):
    """``(rewrite, append)``: rewrite ``trials.csv`` and ``best.yaml`` from the record, or add
    one stored trial (its ``trials.csv`` row at once; ``best.yaml`` when it is the best), so
    both files match the study whenever the process stops; ``study.db`` is checkpointed at
    least every :data:`SAVE_EVERY_S` meanwhile (a copy of it alone misses no more)."""
    from ardrone_nmpc.experiments.tune import study as st
    from ardrone_nmpc.runs.sweep_table import SweepCsvAppender

    columns = st.trials_columns(list(space), scen)
    best = [min((t.value for t in st.finished_trials(study.record)), default=math.inf)]
    checkpointed = [time.perf_counter()]

    def write_best() -> None:
        st.write_best(out_dir / st.BEST_FILE, study.record, cfg=cfg, space=space,
                      command=command, objective=obj, scenarios=scen)

    def rewrite() -> None:
        st.write_trials_csv(out_dir / st.TRIALS_FILE, columns,
                            st.trial_rows(study.record, list(space), scen))
        write_best()
        study.checkpoint()
        checkpointed[0] = time.perf_counter()

    def append(trial) -> None:
        from optuna.trial import TrialState

        if trial.state is not TrialState.COMPLETE:
            return
        appender = SweepCsvAppender(out_dir / st.TRIALS_FILE, columns)
        try:
            appender.append(st.trial_row(trial, list(space), scen))
        finally:
            appender.close()
        if trial.value < best[0]:
            best[0] = trial.value
            write_best()
        if time.perf_counter() - checkpointed[0] >= SAVE_EVERY_S:
            study.checkpoint()
            checkpointed[0] = time.perf_counter()

    return rewrite, append


def run_tune_command(*, config: Path, overrides=(), trials: int = 40, jobs: int = 1,
                     engine: str = "local", scheduler: str | None = None,
                     out_dir: Path, seed: int = 0, n_seeds: int = 3, variants=(),
                     space_file: Path | None = None, objective: str | None = None,
                     resume: bool = False, keep_runs: bool = False, top: int = 10,
                     robust: bool = False, grid_file: Path | None = None,
                     study_name: str | None = None, storage_url: str | None = None,
                     command: str = "ardrone-nmpc tune", console=None,
                     err_console=None) -> TuneOutcome:
    """Run (or resume) the study; see the module docstring. Raises ConfigError for bad
    input, before anything is created or flies. A signal (Ctrl-C, SIGTERM…) stops it with
    ``interrupted`` set: the trials in flight finish and are stored (Ctrl-C again stops
    waiting), ``trials.csv`` and ``best.yaml`` match the study, ``study.db`` stands alone."""
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    from ardrone_nmpc.cli.console import config_notes
    from ardrone_nmpc.cli.narrow import fit
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.config.schema import ConfigError
    from ardrone_nmpc.experiments.parallel import open_executor
    from ardrone_nmpc.experiments.tune import engine as eng
    from ardrone_nmpc.experiments.tune import study as st
    from ardrone_nmpc.experiments.tune.objective import parse_objective
    from ardrone_nmpc.experiments.tune.space import load_space, written_config
    from ardrone_nmpc.runs.tune_record import load_record, stored_trials

    wall0 = time.perf_counter()  # start-up included: the wall time a user waits
    _check_options(engine=engine, scheduler=scheduler)
    cfg = load_config(config, overrides)
    config_notes(cfg)
    space = load_space(space_file, cfg)
    if robust:  # the grid's corners and centre; scored by the worst of them
        from ardrone_nmpc.experiments.robustness.grid import corner_variants, load_grid

        if variants:
            raise ConfigError("--variant: not with --robust (its plants are the grid's)")
        variants = corner_variants(load_grid(grid_file))
        objective = objective or "robust"
    elif grid_file is not None:
        raise ConfigError("--grid-file: only with --robust")
    obj = parse_objective(objective)
    written = written_config(config, overrides)
    scen = eng.scenarios(base_seed=cfg.sim.seed, n_seeds=n_seeds,
                         variants=variants if robust else
                         _variants(variants, written=written, overrides=overrides))
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"--output {out_dir}: exists and is not a directory")
    if not resume and stored_trials(out_dir):  # before any start-up
        raise ConfigError(f"--output {out_dir}: holds a study already ({st.STUDY_FILE}); "
                          "--resume continues it, or choose another --output")
    base_values = {n: p.base for n, p in space.items() if p.contains(p.base)}
    sig = st.signature(cfg=cfg, space=space, scenarios=scen, objective=obj)
    console = console or Console(width=None if sys.stdout.isatty() else 160)
    err_console = err_console or Console(stderr=True)
    make_spec = st.spec_factory(cfg=cfg, written=written, space=space, scenarios=scen,
                                objective=obj,
                                keep_dir=out_dir / "runs" if keep_runs else None)
    interrupted, best_score = None, math.inf
    before: set[int] = set()  # the numbers of the trials finished before this run
    # the engine warms up (a pool: its forkserver loads the kernels) while the study opens
    with open_executor(engine, jobs=max(1, min(jobs, trials)), scheduler=scheduler) as ex:
        created = not out_dir.exists()
        out_dir.mkdir(parents=True, exist_ok=True)
        try:
            study = st.open_study(out_dir, resume=resume, seed=seed, sig=sig,
                                  base_values=base_values, name=study_name or cfg.name,
                                  storage_url=storage_url)
        except BaseException:
            if created and not any(out_dir.iterdir()):  # nothing of ours left behind
                out_dir.rmdir()
            raise
        rewrite, append = _trials_writer(out_dir, study, cfg=cfg, space=space, scen=scen,
                                         obj=obj, command=command)
        try:
            rewrite()
            before = {t.number for t in st.finished_trials(study.record)}
            best_score = min((t.value for t in st.finished_trials(study.record)),
                             default=math.inf)
            todo = max(0, trials - len(st.finished_trials(study.record)))
            progress = Progress(TextColumn("{task.description}"), BarColumn(),
                                MofNCompleteColumn(), TimeElapsedColumn(),
                                TimeRemainingColumn(), console=err_console, transient=True)
            with progress:
                task = progress.add_task("tune", total=todo)

                def on_result(result) -> None:  # the bar only: the record counts
                    nonlocal best_score
                    best_score = min(best_score, result.score)
                    progress.update(task, advance=1, description=f"tune · best {best_score:.4g}")

                try:
                    st.run_study(study, n_trials=trials, executor=ex, make_spec=make_spec,
                                 space=space, on_result=on_result, on_record=append)
                except KeyboardInterrupt as err:
                    interrupted = err
        finally:
            try:
                rewrite()
            finally:
                study.close()
    wall_s = time.perf_counter() - wall0
    record = load_record(out_dir)
    done = st.finished_trials(record)
    # what this run flew, from the record: a signal between a trial's result and its
    # storing must not make the two counts disagree
    now = [t for t in done if t.number not in before]
    flown, sim_s = len(now), sum(_sim_s(t) for t in now)
    if done:
        console.print(fit(_ranked_table(record, space=space, scenarios=scen, top=top), console))
    console.print(f"{len(done)} trials ({flown} flown now, {len(done) - flown} before) × "
                  f"{len(scen)} scenarios; {wall_s:.1f} s wall, {sim_s:.0f} s simulated "
                  f"({sim_s / wall_s if wall_s > 0 else math.nan:.0f}× real time; {engine}, "
                  f"{jobs} jobs){' (interrupted)' if interrupted else ''}")
    best = out_dir / st.BEST_FILE
    return TuneOutcome(out_dir, len(done), flown, record.best_value if done else math.nan,
                       best if done else None, wall_s, sim_s, interrupted)


def _sim_s(trial) -> float:
    """The simulated time (s) a stored trial flew (0 where the record holds none)."""
    from ardrone_nmpc.runs.tune_record import result_of

    sim_s = result_of(trial).get("sim_s")
    return float(sim_s) if isinstance(sim_s, (int, float)) and math.isfinite(sim_s) else 0.0


def register(app: typer.Typer) -> None:
    """Add the ``tune`` command to ``app`` (errors go to the app's one handler,
    :mod:`ardrone_nmpc.cli.handler`)."""
    from ardrone_nmpc.cli.options import MAX_JOBS, choice, non_empty, output_dir
    from ardrone_nmpc.experiments.parallel import ENGINES as engines

    @app.command()
    def tune(
        config: Path = typer.Argument(..., help="Experiment YAML file (its values are the search's centre)."),
        trials: int = typer.Option(40, "--trials", min=1, help="Trials the study should hold when done (with --resume: in total)."),
        jobs: Optional[int] = typer.Option(None, "--jobs", min=1, max=MAX_JOBS, help="Trials flown at once (default: the CPU count); 1 = in this process."),
        engine: str = typer.Option("local", "--engine", **choice(engines), help="'local': a process pool on this machine; 'dask': a Dask cluster."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", callback=non_empty, help="Dask scheduler address (tcp://host:8786); default: a local cluster of --jobs workers on 127.0.0.1."),
        out: Optional[Path] = typer.Option(None, "-o", "--output", callback=output_dir, help="Study directory: study.db, trials.csv, best.yaml (default: logs/tune/<config name>)."),
        seed: int = typer.Option(0, "--seed", min=0, help="Seed of the sampler."),
        seeds: Optional[int] = typer.Option(None, "--seeds", min=1, help="Flight seeds per trial: sim.seed, sim.seed + 1, … (default 3; 1 with --robust)."),
        variant: List[str] = typer.Option([], "--variant", help="A scenario override set, [label:]path=value;path=value (repeatable; each is flown on every seed). Default: each plant profile, if the config has sim.plant.profile."),
        space: Optional[Path] = typer.Option(None, "--space", help="Search-space YAML (default: q and r log-uniform ×0.1…×10 of the config's)."),
        objective: Optional[str] = typer.Option(None, "--objective", help="Preset (default, step, tracking) and/or term=weight items: tracking, settling, overshoot, effort, solver, supervisor, abort, worst."),
        resume: bool = typer.Option(False, "--resume", help="Continue the study in --output (finished trials are not flown again)."),
        keep_runs: bool = typer.Option(False, "--keep-runs", help="Write every flight's run directory under DIR/runs/ (default: metrics only)."),
        top: int = typer.Option(10, "--top", min=1, help="Rows of the ranked table."),
        robust: bool = typer.Option(False, "--robust", help="Fly every trial on the robustness grid's corners and centre (plant deviations: delay, attitude gain and lag, vertical gain, wind) and score it by the worst (objective preset 'robust'); docs/robustness.md."),
        grid_file: Optional[Path] = typer.Option(None, "--grid-file", help="With --robust: the grid whose corners are flown (the format of robustness --grid-file)."),
        study: Optional[str] = typer.Option(None, "--study", callback=non_empty, help="The Optuna study's name (default: the config's name)."),
        storage: Optional[str] = typer.Option(None, "--storage", callback=non_empty, help="Also store every trial in this Optuna storage URL (sqlite:///dash.db, postgresql://…), e.g. a database optuna-dashboard serves for several studies; DIR/study.db stays the record --resume and plot read."),
        set_: List[str] = typer.Option([], "--set", help="Override a config value before tuning: dotted.path=value (repeatable)."),
    ) -> None:
        """Tune the controller by optimisation (Optuna TPE): each trial flies the config
        in lockstep on several seeds (and plant variants) and is scored; writes trials.csv
        and best.yaml, prints the ranked table. Last line: best: <best.yaml>."""
        import os

        out_dir = out if out is not None else Path("logs") / "tune" / config.stem
        n_jobs = jobs if jobs is not None else os.cpu_count() or 1
        command = "ardrone-nmpc " + " ".join(shlex.quote(a) for a in sys.argv[1:]) \
            if sys.argv[1:2] == ["tune"] else f"ardrone-nmpc tune {config}"
        outcome = run_tune_command(config=config, overrides=set_, trials=trials, jobs=n_jobs,
                                   engine=engine, scheduler=scheduler, out_dir=out_dir,
                                   seed=seed, n_seeds=seeds or (1 if robust else 3),
                                   variants=variant, robust=robust, grid_file=grid_file,
                                   space_file=space, objective=objective, resume=resume,
                                   keep_runs=keep_runs, top=top, study_name=study,
                                   storage_url=storage, command=command)
        if outcome.best_path is not None:
            typer.echo(f"best: {outcome.best_path}")
        if outcome.interrupted:
            from ardrone_nmpc.runtime.signals import exit_code_of, signal_name

            typer.echo(f"interrupted ({signal_name(outcome.interrupt)}): the trials that "
                       f"finished are in {outcome.out_dir}; --resume continues the study",
                       err=True)
            raise typer.Exit(code=exit_code_of(outcome.interrupt))
