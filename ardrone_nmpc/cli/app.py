"""The ``ardrone-nmpc`` command line: a thin typer app over keyword-only functions.

Heavy modules (numpy, numba kernels, pydantic schema, CasADi) are imported inside the
commands, so ``ardrone-nmpc --help`` stays fast. User errors print one ``field.path: message``
line per problem on stderr and exit 1, never a traceback.
"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

app = typer.Typer(
    name="ardrone-nmpc",
    help="Fast nonlinear MPC (C/GMRES) flight experiments for the Parrot AR.Drone 2.0.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

SET_HELP = "Override a config value before validation: dotted.path=value (repeatable)."


def _fail(messages) -> None:
    """Print user-facing error lines on stderr and exit 1."""
    for line in messages:
        typer.echo(f"error: {line}", err=True)
    raise typer.Exit(code=1)


def _load(config: Optional[Path], overrides: List[str]):
    from ardrone_nmpc.config.schema import ConfigError, load_config

    try:
        return load_config(config, overrides)
    except ConfigError as err:
        _fail(err.messages)


@app.command()
def check(
    config: Path = typer.Argument(..., help="Experiment YAML file."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
) -> None:
    """Validate a config and print the resolved values (exit 1 with the errors)."""
    from ardrone_nmpc.config.schema import dump_config

    cfg = _load(config, set_)
    typer.echo(dump_config(cfg), nl=False)


@app.command()
def simulate(
    config: Path = typer.Argument(..., help="Experiment YAML file."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
    log_dir: Path = typer.Option(Path("logs"), "--log-dir", help="Where the run directory is created."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of every random source (default: sim.seed)."),
    quiet: bool = typer.Option(False, "--quiet", help="Only print the run directory."),
) -> None:
    """Fly an experiment against the simulated AR.Drone in lockstep (no sockets, faster than
    real time); writes a run directory and prints its summary. Last line: run: <dir>."""
    from ardrone_nmpc.runs.rundir import LogError
    from ardrone_nmpc.reference.trajectories import ReferenceError
    from ardrone_nmpc.cli.simulate import run_simulate_command

    cfg = _load(config, set_)
    try:
        path = run_simulate_command(cfg=cfg, log_dir=log_dir, seed=seed, quiet=quiet)
    except (ReferenceError, LogError, RuntimeError, OSError) as err:
        _fail([str(err)])
    typer.echo(f"run: {path}")


@app.command()
def fly(
    config: Path = typer.Argument(..., help="Experiment YAML file."),
    sim: bool = typer.Option(False, "--sim", help="Fly the loopback simulators (started in-process on 127.0.0.1) instead of a drone."),
    drone: Optional[str] = typer.Option(None, "--drone", help="Drone address (default: drone.host, 192.168.1.1)."),
    at_port: Optional[int] = typer.Option(None, "--at-port", help="AT command UDP port (default: drone.at_port, 5556)."),
    navdata_port: Optional[int] = typer.Option(None, "--navdata-port", help="Navdata UDP port (default: drone.navdata_port, 5554)."),
    mocap_port: Optional[int] = typer.Option(None, "--mocap-port", help="Mocap UDP port to listen on (default: mocap.port, 51001)."),
    duration_s: Optional[float] = typer.Option(None, "--duration-s", help="Experiment length (s), overriding duration_s."),
    log_dir: Path = typer.Option(Path("logs"), "--log-dir", help="Where the run directory is created."),
    dashboard: bool = typer.Option(True, "--dashboard/--no-dashboard", help="Live status (only on a terminal)."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of the simulators (--sim)."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
) -> None:
    """Fly an experiment over UDP: the AR.Drone (with mocap), or with --sim the loopback
    simulators. Takes off, flies the 65 ms loop, lands at the end, on Ctrl-C, on any error
    and on link loss. Last line: run: <dir>."""
    import sys

    overrides = list(set_)
    if duration_s is not None:
        overrides.append(f"duration_s={duration_s}")
    cfg = _load(config, overrides)
    from rich.console import Console
    from rich.live import Live

    from ardrone_nmpc.viz.dashboard import LiveStatus
    from ardrone_nmpc.runtime.realtime import (EXIT_SIGINT, FlightResult, Terminated,
                                               exit_code_of, run_flight)

    console = Console(stderr=True)
    keys = bool(sys.stdin and sys.stdin.isatty() and sys.stderr.isatty())  # land/cut keys
    view = LiveStatus(f"{cfg.name} — {'loopback simulators' if sim else drone or cfg.drone.host}",
                      **({} if keys else {"keys_help": None}))
    live = Live(view, console=console, refresh_per_second=4, transient=True)
    use_live = dashboard and sys.stderr.isatty()
    result = FlightResult()
    code = 0
    try:
        if use_live:
            live.start()
        run_flight(cfg=cfg, sim=sim, drone_host=drone, at_port=at_port,
                   navdata_port=navdata_port, mocap_port=mocap_port, log_dir=log_dir,
                   seed=seed, status=view.update if use_live else None, result=result,
                   warn=(lambda line: console.print(line, markup=False, highlight=False))
                   if use_live else None,
                   operator_keys=keys)
    except Terminated as err:  # before KeyboardInterrupt: it is one
        code = exit_code_of(err)
    except KeyboardInterrupt:
        code = EXIT_SIGINT
    except Exception as err:  # noqa: BLE001 - one clear line; the session has landed
        code = 1
        typer.echo(f"error: {err}", err=True)
    finally:
        if use_live:
            live.stop()
    if result.landed is False:
        typer.echo("error: landing not confirmed by navdata — check the drone", err=True)
        code = code or 1
    if code == 0 and result.path is not None:
        from ardrone_nmpc.cli.simulate import run_summary_command

        run_summary_command(run_dirs=[result.path])
    if result.path is not None:
        typer.echo(f"run: {result.path}")
    if code:
        raise typer.Exit(code=code)


@app.command()
def summary(
    run_dirs: List[Path] = typer.Argument(..., help="One or more run directories."),
) -> None:
    """Print the summary table of one run, or several side by side."""
    from ardrone_nmpc.runs.rundir import LogError
    from ardrone_nmpc.cli.simulate import run_summary_command

    try:
        run_summary_command(run_dirs=run_dirs)
    except LogError as err:
        _fail([str(err)])


@app.command()
def replay(
    run_dir: Path = typer.Argument(..., help="A run directory (logs/<run>)."),
    rerun: bool = typer.Option(False, "--rerun", help="Feed the logged measurements through the estimator and controller again; report recomputed − logged commands and write a new run directory."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP + " With --rerun: the counterfactual config."),
    log_dir: Optional[Path] = typer.Option(None, "--log-dir", help="Where --rerun creates its run directory (default: logs)."),
    broadcast: bool = typer.Option(False, "--broadcast", help="Re-send the logged mocap poses as the UDP pose stream, with the logged timing."),
    speed: Optional[float] = typer.Option(None, "--speed", help="--broadcast playback speed factor (default 1)."),
    port: Optional[int] = typer.Option(None, "--port", min=1, max=65535, help="--broadcast UDP port (default: the run's mocap.port, 51001)."),
    host: Optional[str] = typer.Option(None, "--host", help="--broadcast target; default 127.0.0.1 (only an explicit --host leaves this machine)."),
) -> None:
    """Re-summarise a run; --rerun recomputes its commands from the logged measurements (last
    line: run: <dir>); --broadcast re-sends its mocap poses over UDP."""
    from ardrone_nmpc.cli.replay import ReplayUsageError, run_replay_command

    try:
        path = run_replay_command(run_dir=run_dir, rerun_=rerun, overrides=set_, log_dir=log_dir,
                                  broadcast_=broadcast, speed=speed, port=port, host=host)
    except ReplayUsageError as err:
        _fail(err.messages)
    if path is not None:
        typer.echo(f"run: {path}")


@app.command()
def sweep(
    config: Path = typer.Argument(..., help="Experiment YAML file."),
    grid: List[str] = typer.Option([], "--grid", help="Swept field and its values: dotted.path=v1,v2,… (repeatable; the Cartesian product is flown). Values parse like --set; commas inside [] separate vector items: controller.r=[4,12,12,24],[1,12,12,24]."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP + " Applied to every case, before the grid."),
    jobs: Optional[int] = typer.Option(None, "--jobs", min=1, help="Parallel workers (default: the CPU count); 1 = in this process."),
    engine: str = typer.Option("local", "--engine", help="'local': a process pool on this machine; 'dask': a Dask cluster."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Dask scheduler address (tcp://host:8786); default: a local cluster of --jobs workers on 127.0.0.1."),
    out: Optional[Path] = typer.Option(None, "--out", help="Sweep directory: one run directory per case and sweep.csv (default: logs/sweeps/<config name>). Finished cases in it are skipped."),
    rank_by: str = typer.Option("rmse", "--rank-by", help="Rank the table by: rmse, settling, overshoot, path_deviation, solve_p99."),
    top: Optional[int] = typer.Option(None, "--top", min=1, help="Show only the best K cases."),
    diverge_m: float = typer.Option(0.5, "--diverge-m", min=0.0, help="A case is 'unstable' if it is farther than this (m) from the reference in the last quarter of the experiment (or leaves the geofence, or is landed by the supervisor)."),
) -> None:
    """Fly the grid of lockstep simulations in parallel; writes one run directory per case
    and sweep.csv (parameters, metrics, status), prints the ranked table. Re-running resumes.
    Last line: sweep: <sweep.csv>."""
    import os

    from ardrone_nmpc.config.schema import ConfigError
    from ardrone_nmpc.cli.sweep import SweepEngineError, run_sweep_command

    out_dir = out if out is not None else Path("logs") / "sweeps" / config.stem
    n_jobs = jobs if jobs is not None else os.cpu_count() or 1
    try:
        outcome = run_sweep_command(config=config, grid=grid, overrides=set_, out_dir=out_dir,
                                    jobs=n_jobs, engine=engine, scheduler=scheduler,
                                    rank_by=rank_by, top=top, diverge_m=diverge_m)
    except ConfigError as err:
        _fail(err.messages)
    except SweepEngineError as err:
        _fail([str(err)])
    except KeyboardInterrupt:
        typer.echo("interrupted: re-run the same command to resume", err=True)
        raise typer.Exit(code=130)
    typer.echo(f"sweep: {outcome.csv_path}")
    if outcome.interrupted:
        typer.echo("interrupted: re-run the same command to resume", err=True)
        raise typer.Exit(code=130)
    if outcome.counts["failed"]:
        _fail([f"{outcome.counts['failed']} of {outcome.total} cases failed (see the message "
               f"column of {outcome.csv_path})"])


@app.command()
def reproduce(
    out: Path = typer.Option(Path("docs/thesis-reproduction.md"), "--out", help="Markdown report to write."),
    log_dir: Path = typer.Option(Path("logs/reproduce"), "--log-dir", help="Where the run directories go."),
    config_dir: Path = typer.Option(Path("configs"), "--config-dir", help="The experiment configs."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every run."),
) -> None:
    """Run every thesis experiment in simulation (thesis formulation and ours) and write the
    claim-by-claim comparison."""
    from ardrone_nmpc.experiments.reproduce import render_markdown, run_claims
    from rich.console import Console
    from rich.progress import Progress

    console = Console()
    with Progress(console=console, transient=True) as progress:
        task = progress.add_task("reproducing", total=None)
        outcomes = run_claims(config_dir=config_dir, log_dir=log_dir, seed=seed,
                              progress=lambda text: progress.update(task, description=text))
    command = f"ardrone-nmpc reproduce --seed {seed}"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render_markdown(outcomes, command=command))
    held = {form: sum(o.ours[form][1] for o in outcomes) for form in ("thesis", "ours")}
    console.print(f"{len(outcomes)} claims: {held['thesis']} hold in the thesis formulation, "
                  f"{held['ours']} delay-compensated")
    typer.echo(f"report: {out}")


@app.command()
def bench(
    config: Optional[Path] = typer.Option(None, "--config", help="Take weights, bounds and solver settings from this config."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
    horizon_steps: Optional[int] = typer.Option(None, "--horizon-steps", min=1, help="N (overrides the config)."),
    kmax: Optional[int] = typer.Option(None, "--kmax", min=1, help="GMRES iterations per solve (overrides the config)."),
    steps: int = typer.Option(300, "--steps", min=10, help="Timed control ticks per solver."),
    repeats: int = typer.Option(5, "--repeats", min=1, help="Identical closed-loop repeats; each tick's best time is kept (strips machine noise)."),
    solvers: str = typer.Option("cgmres,newton", "--solvers", help="Comma-separated: cgmres, newton."),
    compare: Optional[str] = typer.Option(None, "--compare", help="'casadi': also solve the OCP exactly with CasADi/IPOPT."),
    json_path: Optional[Path] = typer.Option(None, "--json", help="Write the rows as JSON to this file."),
) -> None:
    """Time the NMPC solvers in a closed loop (1 m step in x, y, z and 1 rad in ψ)."""
    from ardrone_nmpc.cli.bench import run_bench_command

    overrides = list(set_)
    if horizon_steps is not None:
        overrides.append(f"controller.horizon_steps={horizon_steps}")
    if kmax is not None:
        overrides.append(f"controller.solver.kmax={kmax}")
    cfg = _load(config, overrides)
    names = [s.strip() for s in solvers.split(",") if s.strip()]
    bad = [s for s in names if s not in ("cgmres", "newton")]
    if bad or not names:
        _fail([f"--solvers: unknown solver(s) {', '.join(bad) or '(none)'}; choose cgmres, newton"])
    if compare not in (None, "casadi"):
        _fail([f"--compare: unknown comparison {compare!r}; the only one is 'casadi'"])
    try:
        run_bench_command(cfg=cfg, solvers=names, steps=steps, compare_casadi=compare == "casadi",
                          json_path=json_path, repeats=repeats)
    except RuntimeError as err:
        _fail([str(err)])


@app.command()
def plot(
    path: Path = typer.Argument(..., help="A run directory, or a sweep directory (holding sweep.csv)."),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Image file (default: <dir>/plot-<kind>.png); with --kind all one file per kind: FILE-tracking.png, FILE-inputs.png, …"),
    kind: Optional[str] = typer.Option(None, "--kind", help="Run figure: tracking, inputs, solver, path3d or all (default: all)."),
    metric: Optional[str] = typer.Option(None, "--metric", help="Sweep heat map: metric column of sweep.csv (default: rmse_m)."),
    x: Optional[str] = typer.Option(None, "--x", help="Sweep heat map: swept parameter on the x axis (default: the first)."),
    y: Optional[str] = typer.Option(None, "--y", help="Sweep heat map: swept parameter on the y axis (default: the next); any others are minimised over."),
    dpi: int = typer.Option(100, "--dpi", min=30, max=600, help="Resolution (pixels per inch)."),
) -> None:
    """Draw a run's figures (tracking, inputs, solver, 3-D path), or a sweep's metric heat map,
    as images (needs matplotlib: the 'plot' extra). Prints plot: <file> per file."""
    from ardrone_nmpc.cli.plot import PlotError, run_plot_command
    from ardrone_nmpc.runs.rundir import LogError

    try:
        written = run_plot_command(path=path, output=output, kind=kind, metric=metric, x=x,
                                   y=y, dpi=dpi,
                                   warn=lambda note: typer.echo(f"warning: {note}", err=True))
    except (PlotError, LogError, OSError) as err:
        _fail([str(err)])
    for file in written:
        typer.echo(f"plot: {file}")


@app.command()
def faults(
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the results as JSON to this file."),
    markdown: Optional[Path] = typer.Option(None, "--markdown", help="Write the Markdown report (docs/fault-matrix.md) to this file."),
    experiments: str = typer.Option("hover,step,square", "--experiments", help="Comma-separated experiment kinds: hover, step, square."),
    only: Optional[str] = typer.Option(None, "--faults", help="Comma-separated fault cases (default: all)."),
    config_dir: Path = typer.Option(Path("configs"), "--config-dir", help="Where hover.yaml, step_x.yaml, square.yaml are."),
    log_dir: Optional[Path] = typer.Option(None, "--log-dir", help="Where the case run directories go (default: logs/faults-<time>)."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every case."),
) -> None:
    """Run every injected fault against hover, step and square in lockstep simulation and
    report each case's outcome, deviation, recovery and log completeness (exit 1 if any case
    fails)."""
    from ardrone_nmpc.experiments.faultmatrix import run_faults_command

    try:
        ok = run_faults_command(json_out=json_out, markdown=markdown, experiments=experiments,
                                only=only, config_dir=config_dir, log_dir=log_dir, seed=seed)
    except (ValueError, RuntimeError, OSError) as err:
        _fail([str(err)])
    if not ok:
        raise typer.Exit(code=1)


@app.command("sim-drone")
def sim_drone(
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment YAML (sim, drone, mocap sections); default: all defaults."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
    bind: str = typer.Option("127.0.0.1", "--bind", help="Loopback address the simulated drone listens on."),
    at_port: int = typer.Option(5556, "--at-port", min=0, max=65535, help="AT command UDP port (0 = free port)."),
    navdata_port: int = typer.Option(5554, "--navdata-port", min=0, max=65535, help="Navdata UDP port (0 = free port)."),
    control_port: Optional[int] = typer.Option(None, "--control-port", min=0, max=65535, help="Also serve the TCP configuration port (the drone's 5559); default: not served."),
    mocap_to: str = typer.Option("127.0.0.1:51001", "--mocap-to", help="Loopback host:port the mocap pose stream is sent to."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of the simulation (default: sim.seed)."),
) -> None:
    """Serve a simulated AR.Drone 2.0 (AT commands, navdata) and its mocap stream on loopback
    until Ctrl-C."""
    from ardrone_nmpc.sim.serve import serve

    cfg = _load(config, set_)
    try:
        serve(cfg=cfg, bind=bind, at_port=at_port, navdata_port=navdata_port, mocap_to=mocap_to,
              seed=seed, control_port=control_port, echo=typer.echo)
    except (ValueError, OSError) as err:
        _fail([str(err)])


from ardrone_nmpc.cli.operator import register as register_operator_commands  # noqa: E402

register_operator_commands(app)  # land, emergency, reset, status


def main() -> None:  # console-script entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
