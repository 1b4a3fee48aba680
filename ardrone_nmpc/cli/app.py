"""The ``ardrone-nmpc`` command line: the typer app, its commands and their options.

Each command's work is in its own module (``cli/<command>.py``), imported when the command
runs, so ``ardrone-nmpc --help`` stays fast (no numpy, numba, pydantic or CasADi). Errors
are turned into ``error: …`` lines and exit codes in one place, :mod:`ardrone_nmpc.cli.handler`
(codes: :mod:`ardrone_nmpc.errors`).
"""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from ardrone_nmpc.cli.handler import CommandGroup
from ardrone_nmpc.cli.options import (MAX_JOBS, choice, finite, new_output_file, non_empty,
                                      output_file, port)

app = typer.Typer(
    name="ardrone-nmpc",
    help="Fast nonlinear MPC (C/GMRES) flight experiments for the Parrot AR.Drone 2.0.\n\n"
    "Exit codes: 0 success; 1 an error in a config, a file, a run directory or a flight; "
    "2 a bad command line (unknown option, value out of range); 130 Ctrl-C; 143 SIGTERM.",
    cls=CommandGroup,
    no_args_is_help=True,
    add_completion=True,  # --install-completion / --show-completion [bash|zsh|fish|powershell]
    pretty_exceptions_enable=False,
)


def _print_version(value: bool) -> None:
    if value:
        from ardrone_nmpc import __version__

        typer.echo(f"ardrone-nmpc {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Fast nonlinear MPC (C/GMRES) flight experiments for the Parrot AR.Drone 2.0."""

def _sweep_engines():  # the closed sets of values, read where they live when an option is used
    from ardrone_nmpc.cli.sweep import ENGINES

    return ENGINES


def _rank_metrics():
    from ardrone_nmpc.runs.sweep_table import RANK_METRICS

    return RANK_METRICS


def _figure_kinds():
    from ardrone_nmpc.viz.run_figures import KINDS

    return (*KINDS, "all")


def _fault_cases():
    from ardrone_nmpc.experiments.faultmatrix import FAULT_CASES

    return FAULT_CASES


SET_HELP = "Override a config value before validation: dotted.path=value (repeatable)."
CONFIG_ARG = typer.Argument(..., help="Experiment YAML file.")


@app.command()
def check(
    config: Path = CONFIG_ARG,
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
) -> None:
    """Validate a config (and the files it names) and print the resolved values."""
    from ardrone_nmpc.cli.check import run_check

    run_check(config=config, overrides=set_)


@app.command()
def simulate(
    config: Path = CONFIG_ARG,
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
    log_dir: Path = typer.Option(Path("logs"), "--log-dir", help="Where the run directory is created."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of every random source (default: sim.seed)."),
    quiet: bool = typer.Option(False, "--quiet", help="Only print the run directory."),
    foxglove: bool = typer.Option(False, "--foxglove", help="Serve the run live on a Foxglove WebSocket (127.0.0.1), flown at real time (the 'foxglove' extra; docs/live-view.md)."),
    foxglove_port: int = typer.Option(8765, "--foxglove-port", min=0, max=65535, help="--foxglove port (0: a free one)."),
) -> None:
    """Fly an experiment against the simulated AR.Drone in lockstep (no sockets, faster than
    real time); writes a run directory and prints its summary. Last line: run: <dir>."""
    from ardrone_nmpc.cli.simulate import simulate_command

    simulate_command(config=config, overrides=set_, log_dir=log_dir, seed=seed, quiet=quiet,
                     foxglove=foxglove, foxglove_port=foxglove_port)


@app.command()
def fly(
    config: Path = CONFIG_ARG,
    sim: bool = typer.Option(False, "--sim", help="Fly the loopback simulators (started in-process on 127.0.0.1) instead of a drone: --drone sim://loopback."),
    drone: Optional[str] = typer.Option(None, "--drone", callback=non_empty, help="Drone address or URI: 192.168.1.1 or udp://HOST (an AR.Drone 2.0), sim://loopback (the simulated drone over UDP), sim://lockstep (the simulated drone in lockstep, as simulate) (default: drone.host, 192.168.1.1)."),
    at_port: Optional[int] = typer.Option(None, "--at-port", callback=port(), help="AT command UDP port (default: drone.at_port, 5556)."),
    navdata_port: Optional[int] = typer.Option(None, "--navdata-port", callback=port(), help="Navdata UDP port (default: drone.navdata_port, 5554)."),
    mocap_port: Optional[int] = typer.Option(None, "--mocap-port", callback=port(), help="Mocap UDP port to listen on (default: mocap.port, 51001)."),
    duration_s: Optional[float] = typer.Option(None, "--duration-s", help="Experiment length (s), overriding duration_s."),
    log_dir: Path = typer.Option(Path("logs"), "--log-dir", help="Where the run directory is created."),
    dashboard: bool = typer.Option(True, "--dashboard/--no-dashboard", help="Live status (only on a terminal)."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of the simulators (--sim)."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
    foxglove: bool = typer.Option(False, "--foxglove", help="Serve the flight live on a Foxglove WebSocket (127.0.0.1; the 'foxglove' extra; docs/live-view.md)."),
    foxglove_port: int = typer.Option(8765, "--foxglove-port", min=0, max=65535, help="--foxglove port (0: a free one)."),
    mcap: Optional[Path] = typer.Option(None, "--mcap", callback=new_output_file, help="Record the flight's Foxglove channels to this new MCAP file as it flies (the 'foxglove' extra; the same channels as --foxglove and export)."),
) -> None:
    """Fly an experiment over UDP: the AR.Drone (with mocap), or with --sim the loopback
    simulators. Takes off, flies the 65 ms loop, lands at the end, on Ctrl-C, on any error
    and on link loss. Last line: run: <dir>."""
    from ardrone_nmpc.cli.fly import fly_command

    fly_command(config=config, overrides=set_, sim=sim, drone=drone, at_port=at_port,
                navdata_port=navdata_port, mocap_port=mocap_port, duration_s=duration_s,
                log_dir=log_dir, dashboard=dashboard, seed=seed, foxglove=foxglove,
                foxglove_port=foxglove_port, mcap=mcap)


@app.command()
def summary(
    run_dirs: List[Path] = typer.Argument(..., help="One or more run directories."),
    csv: bool = typer.Option(False, "--csv", help="Print run,axis,metric,value,unit rows (one per run and metric) instead of tables."),
) -> None:
    """Print the summary of one run, or of several: side by side while they fit, else one
    line per metric and run (full run names); --csv for scripts."""
    from ardrone_nmpc.cli.summary import summary_command

    summary_command(run_dirs=run_dirs, csv=csv)


@app.command()
def replay(
    run_dir: Path = typer.Argument(..., help="A run directory (logs/<run>)."),
    rerun: bool = typer.Option(False, "--rerun", help="Feed the logged measurements through the estimator and controller again; report recomputed − logged commands and write a new run directory."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP + " With --rerun: the counterfactual config."),
    log_dir: Optional[Path] = typer.Option(None, "--log-dir", help="Where --rerun creates its run directory (default: logs)."),
    broadcast: bool = typer.Option(False, "--broadcast", help="Re-send the logged mocap poses as the UDP pose stream, with the logged timing."),
    speed: Optional[float] = typer.Option(None, "--speed", callback=finite(0.001, 1000.0), help="--broadcast playback speed factor, 0.001 … 1000 (default 1)."),
    port: Optional[int] = typer.Option(None, "--port", callback=port(), help="--broadcast UDP port (default: the run's mocap.port, 51001)."),
    host: Optional[str] = typer.Option(None, "--host", callback=non_empty, help="--broadcast target; default 127.0.0.1 (only an explicit --host leaves this machine)."),
) -> None:
    """Re-summarise a run; --rerun recomputes its commands from the logged measurements (last
    line: run: <dir>); --broadcast re-sends its mocap poses over UDP."""
    from ardrone_nmpc.cli.replay import run_replay_command

    path = run_replay_command(run_dir=run_dir, rerun_=rerun, overrides=set_, log_dir=log_dir,
                              broadcast_=broadcast, speed=speed, port=port, host=host)
    if path is not None:
        typer.echo(f"run: {path}")


@app.command()
def sweep(
    config: Path = CONFIG_ARG,
    grid: List[str] = typer.Option([], "--grid", help="Swept field and its values: dotted.path=v1,v2,… (repeatable; the Cartesian product is flown). Values parse like --set; commas inside [] separate vector items: controller.r=[4,12,12,24],[1,12,12,24]."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP + " Applied to every case, before the grid."),
    jobs: Optional[int] = typer.Option(None, "--jobs", min=1, max=MAX_JOBS, help="Parallel workers (default: the CPU count); 1 = in this process."),
    engine: str = typer.Option("local", "--engine", **choice(_sweep_engines), help="'local': a process pool on this machine; 'dask': a Dask cluster."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", callback=non_empty, help="Dask scheduler address (tcp://host:8786); default: a local cluster of --jobs workers on 127.0.0.1."),
    out: Optional[Path] = typer.Option(None, "-o", "--output", help="Sweep directory: one run directory per case and sweep.csv (default: logs/sweeps/<config name>). Finished cases in it are skipped."),
    rank_by: str = typer.Option("rmse", "--rank-by", **choice(_rank_metrics), help="Rank the table by: rmse, settling, overshoot, path_deviation, solve_p99."),
    top: Optional[int] = typer.Option(None, "--top", min=1, help="Show only the best K cases."),
    diverge_m: float = typer.Option(0.5, "--diverge-m", callback=finite(0.0, 1000.0), help="A case is 'unstable' if it is farther than this (m) from the reference in the last quarter of the experiment (or leaves the geofence, or is landed by the supervisor)."),
) -> None:
    """Fly the grid of lockstep simulations in parallel; writes one run directory per case
    and sweep.csv (parameters, metrics, status), prints the ranked table. Re-running resumes.
    Last line: sweep: <sweep.csv>."""
    from ardrone_nmpc.cli.sweep import sweep_command

    sweep_command(config=config, grid=grid, overrides=set_, out=out, jobs=jobs, engine=engine,
                  scheduler=scheduler, rank_by=rank_by, top=top, diverge_m=diverge_m)


@app.command()
def reproduce(
    out: Path = typer.Option(Path("docs/thesis-reproduction.md"), "-o", "--output", callback=output_file, help="Markdown report to write."),
    log_dir: Path = typer.Option(Path("logs/reproduce"), "--log-dir", help="Where the run directories go."),
    config_dir: Path = typer.Option(Path("configs"), "--config-dir", help="The experiment configs."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every run."),
) -> None:
    """Run every thesis experiment in simulation (thesis formulation and ours) and write the
    claim-by-claim comparison."""
    from ardrone_nmpc.cli.reproduce import reproduce_command

    reproduce_command(out=out, log_dir=log_dir, config_dir=config_dir, seed=seed)


@app.command()
def bench(
    config: Optional[Path] = typer.Option(None, "--config", help="Take weights, bounds and solver settings from this config."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
    horizon_steps: Optional[int] = typer.Option(None, "--horizon-steps", min=1, max=1000, help="N (overrides the config)."),
    kmax: Optional[int] = typer.Option(None, "--kmax", min=1, max=1000, help="GMRES iterations per solve (overrides the config)."),
    steps: int = typer.Option(300, "--steps", min=10, max=100_000, help="Timed control ticks per solver."),
    repeats: int = typer.Option(5, "--repeats", min=1, max=100, help="Identical closed-loop repeats; each tick's best time is kept (strips machine noise)."),
    solvers: str = typer.Option("cgmres,newton", "--solvers", **choice(("cgmres", "newton"), many=True), help="Comma-separated: cgmres, newton."),
    compare: Optional[str] = typer.Option(None, "--compare", **choice(("casadi",)), help="'casadi': also solve the OCP exactly with CasADi/IPOPT."),
    json_path: Optional[Path] = typer.Option(None, "--json", callback=output_file, help="Write the rows as JSON to this file."),
) -> None:
    """Time the NMPC solvers in a closed loop (1 m step in x, y, z and 1 rad in ψ)."""
    from ardrone_nmpc.cli.bench import bench_command

    bench_command(config=config, overrides=set_, horizon_steps=horizon_steps, kmax=kmax,
                  steps=steps, repeats=repeats, solvers=solvers, compare=compare,
                  json_path=json_path)


@app.command()
def plot(
    path: Path = typer.Argument(..., help="A run directory, or a sweep directory (holding sweep.csv)."),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Image file (default: <dir>/plot-<kind>.png), or a directory to write the default file names into; with --kind all one file per kind: FILE-tracking.png, FILE-inputs.png, …"),
    kind: Optional[str] = typer.Option(None, "--kind", **choice(_figure_kinds), help="Run figure: tracking, inputs, solver, path3d or all (default: all)."),
    metric: Optional[str] = typer.Option(None, "--metric", help="Sweep heat map: metric column of sweep.csv (default: rmse_m)."),
    x: Optional[str] = typer.Option(None, "--x", help="Sweep heat map: swept parameter on the x axis (default: the first)."),
    y: Optional[str] = typer.Option(None, "--y", help="Sweep heat map: swept parameter on the y axis (default: the next); any others are minimised over."),
    dpi: int = typer.Option(100, "--dpi", min=30, max=600, help="Resolution (pixels per inch)."),
) -> None:
    """Draw a run's figures (tracking, inputs, solver, 3-D path), or a sweep's metric heat map,
    as images (needs matplotlib: the 'plot' extra). Prints plot: <file> per file."""
    from ardrone_nmpc.cli.plot import plot_command

    plot_command(path=path, output=output, kind=kind, metric=metric, x=x, y=y, dpi=dpi)


@app.command()
def faults(
    json_out: Optional[Path] = typer.Option(None, "--json", callback=output_file, help="Write the results as JSON to this file."),
    markdown: Optional[Path] = typer.Option(None, "--markdown", callback=output_file, help="Write the Markdown report (docs/fault-matrix.md) to this file."),
    experiments: str = typer.Option("hover,step,square", "--experiments", **choice(("hover", "step", "square"), many=True), help="Comma-separated experiment kinds: hover, step, square."),
    only: Optional[str] = typer.Option(None, "--faults", **choice(_fault_cases, many=True), help="Comma-separated fault cases (default: all)."),
    config_dir: Path = typer.Option(Path("configs"), "--config-dir", help="Where hover.yaml, step_x.yaml, square.yaml are."),
    log_dir: Optional[Path] = typer.Option(None, "--log-dir", help="Where the case run directories go (default: logs/faults-<time>)."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every case."),
) -> None:
    """Run every injected fault against hover, step and square in lockstep simulation and
    report each case's outcome, deviation, recovery and log completeness (exit 1 if any case
    fails)."""
    from ardrone_nmpc.cli.faults import faults_command

    faults_command(json_out=json_out, markdown=markdown, experiments=experiments, only=only,
                   config_dir=config_dir, log_dir=log_dir, seed=seed)


@app.command("sim-drone")
def sim_drone(
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment YAML (sim, drone, mocap sections); default: all defaults."),
    set_: List[str] = typer.Option([], "--set", help=SET_HELP),
    bind: str = typer.Option("127.0.0.1", "--bind", callback=non_empty, help="Loopback address the simulated drone listens on."),
    at_port: int = typer.Option(5556, "--at-port", callback=port(zero_picks_a_free_one=True), help="AT command UDP port (0 = a free port, printed)."),
    navdata_port: int = typer.Option(5554, "--navdata-port", callback=port(zero_picks_a_free_one=True), help="Navdata UDP port (0 = a free port, printed)."),
    control_port: int = typer.Option(5559, "--control-port", callback=port(zero_picks_a_free_one=True), help="TCP configuration port (the drone's 5559; 0 = a free port, printed)."),
    mocap_to: str = typer.Option("127.0.0.1:51001", "--mocap-to", callback=non_empty, help="Loopback host:port the mocap pose stream is sent to."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of the simulation (default: sim.seed)."),
) -> None:
    """Serve a simulated AR.Drone 2.0 (AT commands, navdata) and its mocap stream on loopback
    until Ctrl-C."""
    from ardrone_nmpc.cli.sim_drone import sim_drone_command

    sim_drone_command(config=config, overrides=set_, bind=bind, at_port=at_port,
                      navdata_port=navdata_port, control_port=control_port,
                      mocap_to=mocap_to, seed=seed)


from ardrone_nmpc.cli import export as _export, mocap_check as _mocap_check, tune as _tune  # noqa: E402
from ardrone_nmpc.cli import identify as _identify, robustness as _robustness  # noqa: E402
_mocap_check.register(app)  # commands that live in their own modules
_export.register(app)
_tune.register(app)
_robustness.register(app)
_identify.register(app)


from ardrone_nmpc.cli.operator import register as register_operator_commands  # noqa: E402

register_operator_commands(app)  # land, emergency, reset, status


def main() -> None:  # console-script entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
