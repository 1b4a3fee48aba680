"""Every command with hostile arguments: one ``error:`` line, exit ≠ 0, no traceback, no work.

Bad numbers (out of range, NaN, 1e308, 1e-300), empty hosts, ports outside 1–65535, outputs
that are directories or sit under a file, inputs that do not exist or exceed the limits. Each
must fail before anything is flown, sent or written (no run directory is left), with the
exit code of :mod:`ardrone_nmpc.errors`: 2 for the command line itself, 1 for the rest.

Issue 24's reproductions are here too: outputs aimed into a run directory, onto an existing
file or a device; times MCAP cannot hold; a corrupt study; space files the sampler cannot
draw from; a Dask scheduler that is garbage or never answers; a port in use; the interrupts
(Ctrl-C, SIGTERM) of simulate, export and tune; and a test that every output option of every
command is refused inside a run directory.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import RunRecorder
from ardrone_nmpc.runs.summary import write_run_summary

ROOT = Path(__file__).resolve().parents[2]
HOVER = str(ROOT / "configs" / "hover.yaml")
FAR_PATH = "t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n2,100000000,0,1,0\n"
SHORT = ["--set", "duration_s=0.3", "--set", "sim.settle_s=0.1"]

runner = CliRunner()


SPACES = {"space_inf": "params:\n  controller.dtau_s: {low: -.inf, high: 0.2}\n",
          "space_factor_inf": "factor: .inf\n",
          "space_no_int": "default: false\nparams:\n  controller.horizon_steps: "
                          "{low: 10.2, high: 10.8, type: int}\n"}


def _run(parent: Path, name: str, *t_s: float) -> Path:
    cfg = load_config(overrides=[f"name={name}"])
    with RunRecorder.create(parent, cfg, seed=0) as rec:
        for t in t_s:
            rec.write_row({"t_s": t, "x_m": 0.0, "y_m": 0.0, "z_m": 1.0, "psi_rad": 0.0,
                           "mode": "track", "solver_status": "ok"})
    write_run_summary(rec.path)  # a finished run
    return rec.path


@pytest.fixture
def files(tmp_path) -> dict[str, str]:
    """A plain file, an existing directory, a far path CSV, a run directory; and issue 24's
    inputs: runs with times MCAP cannot hold, a corrupt study, a folder holding a sweep and a
    tune, space files, a non-UTF-8 file, a dangling link, a TCP port in use (closed by the
    test's teardown)."""
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    (tmp_path / "far.csv").write_text(FAR_PATH)
    run = _run(tmp_path / "runs", "r", 0.0)
    paths = {"file": tmp_path / "afile", "dir": tmp_path / "adir", "far": tmp_path / "far.csv",
             "run": run, "logs": tmp_path / "logs", "tmp": tmp_path,
             "huge": _run(tmp_path / "odd", "huge", 0.0, 1e308),
             "big": _run(tmp_path / "odd", "big", 0.0, 1e11)}
    (tmp_path / "corrupt").mkdir()
    (tmp_path / "corrupt" / "study.db").write_bytes(bytes(range(256)) * 20)
    (tmp_path / "shared").mkdir()
    (tmp_path / "shared" / "sweep.csv").write_text("case,status\n")
    (tmp_path / "shared" / "study.db").write_bytes(b"")
    for name, text in SPACES.items():
        paths[name] = tmp_path / f"{name}.yaml"
        paths[name].write_text(text)
    paths["binary"] = tmp_path / "binary.yaml"
    paths["binary"].write_bytes(b"params:\n  \xff\xfe: {}\n")
    paths["dangling"] = tmp_path / "dangling"
    os.symlink(tmp_path / "gone", paths["dangling"])
    paths.update(corrupt=tmp_path / "corrupt", shared=tmp_path / "shared")
    out = {k: str(v) for k, v in paths.items()}
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    out["busy_port"] = str(busy.getsockname()[1])
    yield out
    busy.close()


# (id, arguments with {placeholders} from `files`, exit code, pattern of the error line)
CASES = [
    ("check-missing", ["check", "{tmp}/nope.yaml"], 1, r"nope\.yaml: no such file"),
    ("check-unknown-option", ["check", HOVER, "--bogus"], 2, r"No such option: --bogus"),
    ("check-long-name", ["check", HOVER, "--set", "name=" + "n" * 300], 1,
     r"^error: name: String should have at most 200 characters$"),
    ("check-far-path", ["check", HOVER, "--set", "reference.kind=path",
                        "--set", "reference.path_file={far}"], 1,
     r"^error: reference\.path_file: .*far\.csv:3: column 'x_m': 100000000 is outside ±1000 m$"),
    ("check-config-ids-digits", ["check", HOVER, "--set", "drone.config_ids=[1,2,3]"], 1,
     r"^error: drone\.config_ids: quote ids made of digits only"),
    ("simulate-duration-1e308", ["simulate", HOVER, "--set", "duration_s=1e308"], 1,
     r"^error: duration_s: Input should be less than or equal to 3600$"),
    ("simulate-settle-1e308", ["simulate", HOVER, "--set", "sim.settle_s=1e308"], 1,
     r"^error: sim\.settle_s: Input should be less than or equal to 3600$"),
    ("simulate-leg-1e308", ["simulate", HOVER, "--set", "reference.kind=square",
                            "--set", "reference.leg_duration_s=1e308"], 1,
     r"^error: reference\.leg_duration_s: Input should be less than or equal to 3600$"),
    ("simulate-far-path", ["simulate", HOVER, "--set", "reference.kind=path",
                           "--set", "reference.path_file={far}"], 1, r"far\.csv:3: column 'x_m'"),
    ("simulate-negative-seed", ["simulate", HOVER, "--seed", "-1"], 2, r"^error: --seed: "),
    ("simulate-log-dir-under-a-file", ["simulate", HOVER, *SHORT, "--log-dir", "{file}/logs"],
     1, r"afile/logs: Not a directory$"),
    ("fly-at-port-70000", ["fly", HOVER, "--sim", "--at-port", "70000"], 2,
     r"^error: --at-port: 70000 is not a port \(1 … 65535\)$"),
    ("fly-navdata-port-negative", ["fly", HOVER, "--sim", "--navdata-port", "-1"], 2,
     r"^error: --navdata-port: -1 is not a port \(1 … 65535\)$"),
    ("fly-mocap-port-0", ["fly", HOVER, "--sim", "--mocap-port", "0"], 2,
     r"^error: --mocap-port: 0 is not a port \(1 … 65535\)$"),
    ("fly-empty-drone", ["fly", HOVER, "--drone", ""], 2, r"^error: --drone: must not be empty$"),
    ("fly-duration-1e308", ["fly", HOVER, "--sim", "--duration-s", "1e308"], 1,
     r"^error: duration_s: Input should be less than or equal to 3600$"),
    ("fly-duration-nan", ["fly", HOVER, "--sim", "--duration-s", "nan"], 1,
     r"^error: duration_s: Input should be a finite number$"),
    ("summary-missing", ["summary", "{tmp}/nope"], 1, r"nope: no such run directory$"),
    ("summary-not-a-run", ["summary", "{dir}"], 1, r"adir/config\.yaml: no such file$"),
    ("replay-speed-1e-300", ["replay", "{run}", "--broadcast", "--speed", "1e-300"], 2,
     r"^error: --speed: must be a number in \[0\.001, 1000\], got 1e-300$"),
    ("replay-speed-nan", ["replay", "{run}", "--broadcast", "--speed", "nan"], 2,
     r"^error: --speed: must be a number"),
    ("replay-port-0", ["replay", "{run}", "--broadcast", "--port", "0"], 2,
     r"^error: --port: 0 is not a port \(1 … 65535\)$"),
    ("replay-empty-host", ["replay", "{run}", "--broadcast", "--host", ""], 2,
     r"^error: --host: must not be empty$"),
    ("replay-both-modes", ["replay", "{run}", "--rerun", "--broadcast"], 1, r"choose one"),
    ("sweep-out-under-a-file", ["sweep", HOVER, "--grid", "duration_s=0.3", "-o",
                                "{file}/sweep"], 1,
     r"^error: --output .*afile/sweep: cannot create the directory: Not a directory$"),
    ("sweep-out-a-file", ["sweep", HOVER, "--grid", "duration_s=0.3", "-o", "{file}"], 1,
     r"^error: --output .*afile: exists and is not a directory$"),
    ("sweep-jobs-0", ["sweep", HOVER, "--jobs", "0"], 2, r"^error: --jobs: .*\b1\b"),
    ("sweep-jobs-huge", ["sweep", HOVER, "--jobs", "100000"], 2, r"^error: --jobs: .*\b256\b"),
    ("sweep-diverge-nan", ["sweep", HOVER, "--diverge-m", "nan"], 2, r"^error: --diverge-m: "),
    ("sweep-far-path", ["sweep", HOVER, "--grid", "duration_s=0.3,0.4", "--set",
                        "reference.kind=path", "--set", "reference.path_file={far}",
                        "-o", "{tmp}/sw"], 1, r"far\.csv:3: column 'x_m'"),
    ("reproduce-out-a-dir", ["reproduce", "-o", "{dir}"], 2,
     r"^error: -o / --output: .*adir: is a directory; give a file name$"),
    ("bench-json-a-dir", ["bench", "--json", "{dir}"], 2,
     r"^error: --json: .*adir: is a directory; give a file name$"),
    ("bench-json-under-a-file", ["bench", "--json", "{file}/b.json"], 2,
     r"^error: --json: .*afile is not a directory$"),
    ("bench-steps-huge", ["bench", "--steps", "1000000000"], 2, r"^error: --steps: "),
    ("bench-steps-float", ["bench", "--steps", "1e9"], 2, r"^error: --steps: "),
    ("bench-unknown-solver", ["bench", "--solvers", "fast"], 2, r"--solvers: unknown 'fast'"),
    ("plot-missing", ["plot", "{tmp}/nope"], 1, r"nope: no such directory$"),
    ("plot-dpi-0", ["plot", "{run}", "--dpi", "0"], 2, r"^error: --dpi: .*\b30\b"),
    ("faults-unknown-experiment", ["faults", "--experiments", "bogus"], 2,
     r"^error: --experiments: unknown 'bogus'; choose from hover, step, square$"),
    ("faults-empty-list", ["faults", "--faults", ","], 2, r"^error: --faults: unknown \(empty\)"),
    ("faults-json-a-dir", ["faults", "--json", "{dir}"], 2, r"^error: --json: "),
    ("sim-drone-port-70000", ["sim-drone", "--at-port", "70000"], 2,
     r"^error: --at-port: 70000 is not a port \(0 … 65535\)$"),
    ("sim-drone-empty-bind", ["sim-drone", "--bind", ""], 2, r"^error: --bind: must not be empty"),
    ("sim-drone-remote-bind", ["sim-drone", "--bind", "198.51.100.7"], 1,
     r"--bind '198\.51\.100\.7' is not a loopback address"),
    ("sim-drone-mocap-to", ["sim-drone", "--mocap-to", "nohost"], 1,
     r"--mocap-to 'nohost': expected host:port"),
    ("export-missing", ["export", "{tmp}/nope", "--format", "mcap", "-o", "{tmp}/x.mcap"], 1,
     r"^error: .*nope: no such run directory$"),
    ("export-bogus-format", ["export", "{run}", "--format", "bogus", "-o", "{tmp}/x.mcap"], 2,
     r"^error: --format: unknown 'bogus'; choose mcap, parquet$"),
    ("mocap-check-missing", ["mocap-check", "{tmp}/nope.yaml"], 1, r"nope\.yaml: no such file$"),
    ("mocap-check-negative-seconds", ["mocap-check", HOVER, "--seconds", "-1"], 2,
     r"^error: --seconds: "),
    ("land-at-port-0", ["land", "--at-port", "0"], 2,
     r"^error: --at-port: 0 is not a port \(1 … 65535\)$"),
    ("emergency-empty-drone", ["emergency", "--drone", ""], 2,
     r"^error: --drone: must not be empty$"),
    ("reset-navdata-port-70000", ["reset", "--navdata-port", "70000"], 2,
     r"^error: --navdata-port: 70000 is not a port \(1 … 65535\)$"),
    ("status-control-port-negative", ["status", "--control-port", "-1"], 2,
     r"^error: --control-port: -1 is not a port \(1 … 65535\)$"),
    ("tune-missing", ["tune", "{tmp}/nope.yaml"], 1, r"nope\.yaml: no such file$"),
    ("robustness-missing", ["robustness", "{tmp}/nope.yaml", "-o", "{tmp}/rob"], 1,
     r"nope\.yaml: no such file"),
    ("robustness-zero-jobs", ["robustness", HOVER, "--jobs", "0"], 2, r"^error: --jobs: "),
    ("identify-missing", ["identify", "{tmp}/nope", "-o", "{tmp}/p.yaml"], 1,
     r"nope: no such run directory$"),
    ("identify-too-short", ["identify", "{run}", "-o", "{tmp}/p.yaml"], 1,
     r"too little flown with navdata and mocap"),
    ("tune-zero-trials", ["tune", HOVER, "--trials", "0"], 2, r"^error: --trials: "),
    # issue 24: data loss
    ("export-mcap-onto-the-log", ["export", "{run}", "--format", "mcap", "-o", "{run}/log.csv"],
     1, r"^error: -o .*/log\.csv: inside the run directory .*-r, which only its recording"),
    ("export-parquet-onto-the-config", ["export", "{run}", "--format", "parquet", "-o",
                                        "{run}/config.yaml"], 1,
     r"^error: -o .*/config\.yaml: inside the run directory"),
    ("export-onto-an-existing-file", ["export", "{run}", "-o", "{file}"], 1,
     r"^error: -o .*afile: exists; --force replaces it$"),
    ("export-onto-a-device", ["export", "{run}", "-o", "/dev/null", "--force"], 1,
     r"^error: -o /dev/null: is not a regular file \(a device, a pipe or a socket\); it is "
     r"never replaced$"),
    # issue 24: tracebacks
    ("export-t-1e308", ["export", "{huge}", "-o", "{tmp}/h.mcap"], 1,
     r"^error: .*-huge/log\.csv:3: t_s = 1e\+308 s is beyond what an MCAP log time holds"),
    ("export-t-1e11", ["export", "{big}", "-o", "{tmp}/b.mcap"], 1,
     r"^error: .*-big/log\.csv:3: t_s = 100000000000\.0 s is beyond what an MCAP log time"),
    ("export-a-config-file", ["export", HOVER], 1,
     r"^error: .*hover\.yaml: a file, not a run directory$"),
    ("tune-resume-a-corrupt-study", ["tune", HOVER, "--resume", "-o", "{corrupt}"], 1,
     r"^error: .*corrupt/study\.db: file is not a database$"),
    ("plot-a-corrupt-study", ["plot", "{corrupt}"], 1,
     r"^error: .*corrupt/study\.db: file is not a database$"),
    ("tune-space-inf", ["tune", HOVER, "--space", "{space_inf}", "-o", "{tmp}/t"], 1,
     r"^error: --space .*space_inf\.yaml: params\.controller\.dtau_s: needs finite numbers"),
    ("tune-space-factor-inf", ["tune", HOVER, "--space", "{space_factor_inf}", "-o",
                               "{tmp}/t"], 1,
     r"^error: --space .*: factor: inf must be a finite number > 1$"),
    ("tune-space-int-without-an-integer", ["tune", HOVER, "--space", "{space_no_int}", "-o",
                                           "{tmp}/t"], 1,
     r"^error: --space .*: type int: no integer lies in 10\.2 … 10\.8$"),
    ("tune-space-not-utf8", ["tune", HOVER, "--space", "{binary}", "-o", "{tmp}/t"], 1,
     r"^error: --space .*binary\.yaml: not UTF-8 text"),
    ("tune-storage-garbage", ["tune", HOVER, "--storage", "garbage", "-o", "{tmp}/t"], 1,
     r"^error: --storage garbage: Could not parse SQLAlchemy URL"),
    ("tune-dask-garbage-scheduler", ["tune", HOVER, "--engine", "dask", "--scheduler",
                                     "garbage://x", "-o", "{tmp}/t"], 1,
     r"^error: --engine dask: .*garbage://x.*unknown address scheme 'garbage'"),
    ("simulate-foxglove-port-in-use", ["simulate", HOVER, "--foxglove", "--foxglove-port",
                                       "{busy_port}", "--log-dir", "{logs}"], 1,
     r"^error: --foxglove-port \d+: Failed to bind port: Address already in use"),
    ("check-profile-as-a-list", ["check", HOVER, "--set", "sim.plant.profile=[ardrone]"], 1,
     r"^error: sim\.plant\.profile: Input should be a valid string$"),
    ("fly-blank-host", ["fly", HOVER, "--set", 'drone.host=" "', "--log-dir", "{logs}"], 1,
     r"^error: drone\.host: must be an address or host name, without spaces$"),
    ("check-blank-host", ["check", HOVER, "--set", 'drone.host=" "'], 1,
     r"^error: drone\.host: must be an address or host name, without spaces$"),
    # issue 24: a hang and the misleading messages
    ("check-connect-timeout-1e9", ["check", HOVER, "--set", "mocap.connect_timeout_s=1e9"], 1,
     r"^error: mocap\.connect_timeout_s: Input should be less than or equal to 60$"),
    ("check-missing-path-file-of-a-step", ["check", HOVER, "--set",
                                           "reference.path_file={tmp}/nope.csv"], 1,
     r"^error: reference\.path_file: no such file: .*nope\.csv$"),
    ("simulate-missing-path-file-of-a-step", ["simulate", HOVER, "--set",
                                              "reference.path_file={tmp}/nope.csv",
                                              "--log-dir", "{logs}"], 1,
     r"^error: reference\.path_file: no such file: .*nope\.csv$"),
    ("fly-sim-mocap-port", ["fly", HOVER, "--sim", "--mocap-port", "5000", "--log-dir",
                            "{logs}"], 1,
     r"^error: --mocap-port: not with --sim \(the loopback simulators listen on free ports"),
    ("plot-a-folder-of-a-sweep-and-a-tune", ["plot", "{shared}"], 1,
     r"^error: .*shared: holds a sweep \(sweep\.csv\) and a tune study \(study\.db\); plot "),
    ("summary-without-a-run", ["summary"], 2, r"^error: Missing argument 'run_dirs'"),
    ("simulate-log-dir-a-dangling-link", ["simulate", HOVER, "--log-dir", "{dangling}"], 2,
     r"^error: --log-dir: .*dangling: a symbolic link to .*gone, which does not exist$"),
    ("simulate-log-dir-in-a-run", ["simulate", HOVER, "--log-dir", "{run}/inputs"], 2,
     r"^error: --log-dir: .*inputs: inside the run directory .*-r, which only its recording"),
]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("args, code, pattern", [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_every_command_refuses_hostile_arguments_in_one_line(files, args, code, pattern):
    before = sorted(p.name for p in Path(files["tmp"]).iterdir())
    result = runner.invoke(app, [a.format(**files) for a in args])
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), \
        repr(result.exception)
    errors = [line for line in result.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, result.output
    assert errors[0] == " ".join(errors[0].split())  # one line, no box
    assert re.search(pattern, errors[0]), (pattern, errors[0])
    assert "error:" not in result.stdout  # errors go to stderr only
    # nothing was flown, written or created
    assert sorted(p.name for p in Path(files["tmp"]).iterdir()) == before
    assert len(list(Path(files["run"]).parent.iterdir())) == 1


def test_every_command_is_covered():
    commands = {c[1][0] for c in CASES}
    registered = {c.name or c.callback.__name__.replace("_", "-") for c in
                  app.registered_commands}
    assert commands == registered


def test_sweep_out_on_a_read_only_file_system_is_one_line(files, monkeypatch):
    def read_only(self, *args, **kwargs):
        raise OSError(30, "Read-only file system", str(self))

    monkeypatch.setattr(Path, "mkdir", read_only)
    result = runner.invoke(app, ["sweep", HOVER, "--grid", "duration_s=0.3", "-o",
                                 f"{files['tmp']}/ro/sweep"])
    assert result.exit_code == 1, result.output
    assert result.stderr.strip().splitlines() == [
        f"error: --output {files['tmp']}/ro/sweep: cannot create the directory: "
        "Read-only file system"]


# ----------------------------------------------------------------------------- closed output


def _cli(*args: str, **kwargs) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "ardrone_nmpc.cli.app", *args], env=env,
                          stderr=subprocess.PIPE, text=True, timeout=120, **kwargs)


@pytest.mark.timeout(150)
@pytest.mark.parametrize("args", [["check", HOVER],
                                  ["fly", HOVER, "--sim", "--no-dashboard", *SHORT]])
def test_a_closed_stdout_is_one_line_before_anything_runs(tmp_path, args):
    log_dir = ["--log-dir", str(tmp_path / "logs")] if args[0] == "fly" else []
    result = _cli(*args, *log_dir, preexec_fn=lambda: os.close(1))
    assert result.returncode == 1
    assert result.stderr.splitlines() == [
        "error: standard output is closed; redirect it (> FILE, > /dev/null) instead of "
        "closing it"]
    assert not (tmp_path / "logs").exists()  # nothing flew


@pytest.mark.timeout(150)
def test_a_broken_pipe_is_one_line(files):
    read_end, write_end = os.pipe()
    os.close(read_end)  # nobody will ever read: the first write fails with EPIPE
    try:
        result = _cli("summary", files["run"], stdout=write_end)
    finally:
        os.close(write_end)
    assert result.returncode == 1
    assert result.stderr.splitlines() == [
        "error: standard output was closed before everything was written (broken pipe)"]


# ----------------------------------------------------------------------------- run directories

#: Path options that name inputs; every other Path option of every command is an output.
INPUT_OPTIONS = {"--config", "--config-dir", "--space", "--grid-file"}
#: The rest of a command line that would do work, per command with an output option.
WORK = {"simulate": [HOVER, *SHORT], "fly": [HOVER, "--sim", "--no-dashboard", *SHORT],
        "replay": ["{run}", "--rerun"], "sweep": [HOVER, "--grid", "duration_s=0.3"],
        "reproduce": [], "bench": ["--steps", "10", "--repeats", "1"], "plot": ["{run}"],
        "faults": ["--experiments", "hover", "--faults", "battery_floor"],
        "export": ["{run}"], "tune": [HOVER, "--trials", "1", "--seeds", "1", *SHORT],
        "robustness": [HOVER, "--jobs", "1"], "identify": ["{run}"]}


def _output_options() -> list[tuple[str, str]]:
    """(command, option) for every Path-valued option of every command that is not an input."""
    import inspect
    import typing

    from typer.models import OptionInfo

    found = []
    for info in app.registered_commands:
        name = info.name or info.callback.__name__.replace("_", "-")
        hints = typing.get_type_hints(info.callback)
        for param in inspect.signature(info.callback).parameters.values():
            default = param.default
            if not isinstance(default, OptionInfo) or Path not in (
                    hints[param.name], *typing.get_args(hints[param.name])):
                continue
            option = next(d for d in default.param_decls if d.startswith("--"))
            if option not in INPUT_OPTIONS:
                found.append((name, option))
    return found


def _snapshot(run: Path) -> dict[str, bytes]:
    return {str(p.relative_to(run)): p.read_bytes() for p in sorted(run.rglob("*"))
            if p.is_file()}


def test_the_output_options_found_are_the_known_ones():
    found = set(_output_options())
    assert {c for c, _ in found} <= set(WORK), "a new output option: add its command to WORK"
    assert {("export", "--output"), ("plot", "--output"), ("simulate", "--log-dir"),
            ("fly", "--log-dir"), ("replay", "--log-dir"), ("sweep", "--output"),
            ("tune", "--output"), ("reproduce", "--output"), ("reproduce", "--log-dir"),
            ("faults", "--json"), ("faults", "--markdown"), ("faults", "--log-dir"),
            ("bench", "--json")} <= found


@pytest.mark.timeout(300)
@pytest.mark.parametrize("command, option", _output_options())
@pytest.mark.parametrize("target", ["{run}", "{run}/log.csv", "{run}/config.yaml",
                                    "{run}/inputs/new"])
def test_no_output_option_reaches_a_file_inside_a_run_directory(files, command, option,
                                                                target):
    run = Path(files["run"])
    before = _snapshot(run)
    args = [command, *(a.format(**files) for a in WORK[command]), option, target.format(**files)]
    result = runner.invoke(app, args)
    assert "Traceback" not in result.output
    if not (command == "plot" and result.exit_code == 0):  # plot's figures go beside the run
        assert result.exit_code != 0, (args, result.output)
        assert re.search(r"^error: .+", result.output, re.M), result.output
    after = _snapshot(run)
    assert {k: v for k, v in after.items() if k in before} == before, "a run file changed"
    assert all(k.startswith("plot-") for k in set(after) - set(before)), sorted(after)


# ----------------------------------------------------------------------------- interrupts


def _start(*args: str, cwd: Path = ROOT) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "ardrone_nmpc.cli.app", *args], env=env,
                            cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(predicate, what: str, proc: subprocess.Popen, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert proc.poll() is None, f"ended before {what}: {proc.communicate()}"
        assert time.monotonic() < deadline, f"never {what}"
        time.sleep(0.05)


def _rows(path: Path) -> int:
    try:
        return path.read_text().count("\n") - 1
    except OSError:
        return -1


@pytest.mark.timeout(300)
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_an_interrupted_hour_long_simulate_says_where_it_stopped(tmp_path, sig, code):
    proc = _start("simulate", str(ROOT / "configs" / "square.yaml"), "--set", "duration_s=3600",
                  "--log-dir", str(tmp_path), "--quiet")
    try:
        _wait_for(lambda: any(_rows(p / "log.csv") > 200 for p in tmp_path.iterdir()),
                  "flying", proc)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    (run,) = tmp_path.iterdir()
    assert proc.returncode == code
    assert err.splitlines()[-1] == f"error: interrupted by {sig.name}; the run so far is in {run}"
    last = json.loads((run / "events.jsonl").read_text().splitlines()[-1])
    assert last["kind"] == "interrupted" and last["signal"] == sig.name
    assert 0 < last["t_s"] < 3600 and not (run / "summary.csv").exists()
    said = f"interrupted at t = {last['t_s']:.2f} s ({sig.name})"
    for command in (["summary", str(run)], ["replay", str(run)],
                    ["export", str(run), "-o", str(tmp_path / "x.parquet"), "--format",
                     "parquet"]):
        result = runner.invoke(app, command)
        assert result.exit_code == 0, result.output
        assert said in result.stderr, (command, result.stderr)
    assert said in " ".join(runner.invoke(app, ["summary", str(run)]).stdout.split())


def test_export_of_the_current_directory_inside_a_run_writes_beside_it(files, monkeypatch):
    run = Path(files["run"])
    before = _snapshot(run)
    monkeypatch.chdir(run)
    result = runner.invoke(app, ["export", ".", "--format", "parquet"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[-1] == f"export: {run.parent / (run.name + '.parquet')}"
    assert (run.parent / f"{run.name}.parquet").stat().st_size > 0
    assert _snapshot(run) == before


@pytest.mark.timeout(300)
def test_an_interrupted_mcap_export_leaves_nothing_and_keeps_the_earlier_export(tmp_path):
    cfg = load_config(overrides=["name=big"])
    with RunRecorder.create(tmp_path / "runs", cfg, seed=0) as rec:
        for k in range(60_000):
            rec.write_row({"t_s": 0.065 * k, "x_m": 0.001 * k, "y_m": 0.0, "z_m": 1.0,
                           "psi_rad": 0.0, "x_ref_m": 1.0, "y_ref_m": 0.0, "z_ref_m": 1.0,
                           "psi_ref_rad": 0.0, "mode": "track", "solver_status": "ok"})
    write_run_summary(rec.path)
    out = tmp_path / "big.mcap"
    assert runner.invoke(app, ["export", str(rec.path), "-o", str(out)]).exit_code == 0
    earlier = out.read_bytes()
    proc = _start("export", str(rec.path), "-o", str(out), "--force")
    try:
        _wait_for(lambda: any(p.name.endswith(".part") for p in tmp_path.iterdir()),
                  "writing", proc)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130
    assert err.splitlines() == ["error: interrupted by SIGINT"]
    assert out.read_bytes() == earlier                       # the earlier export is intact
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.mcap", "runs"]  # no remnant


def test_a_failed_parquet_write_never_hands_pyarrow_a_path_and_keeps_the_earlier_file(
        files, tmp_path, monkeypatch):
    import pyarrow.parquet as pq
    out = tmp_path / "r.parquet"
    out.write_bytes(b"an earlier export")
    given = []

    def failing(table, where, **kwargs):
        given.append(where)
        where.write(b"PAR1 half a file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pq, "write_table", failing)
    result = runner.invoke(app, ["export", files["run"], "--format", "parquet", "-o", str(out),
                                 "--force"])
    assert result.exit_code == 1 and "No space left on device" in result.stderr
    assert len(given) == 1 and not isinstance(given[0], (str, Path))  # a stream, not a path
    assert out.read_bytes() == b"an earlier export"
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".part")]


# ----------------------------------------------------------------------------- tune

TUNE_SHORT = ["--seeds", "1", "--set", "duration_s=0.3", "--set", "sim.settle_s=0.1"]


def _trials_csv(out: Path) -> list[dict[str, str]]:
    import csv

    with open(out / "trials.csv", newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _study_alone(out: Path, tmp_path: Path):
    """The study read from a copy of ``study.db`` alone (no -wal, no -shm beside it)."""
    import shutil

    import optuna

    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(out / "study.db", alone / "study.db")
    return optuna.load_study(study_name="hover", storage=f"sqlite:///{alone / 'study.db'}")


@pytest.mark.timeout(600)
@pytest.mark.parametrize("sig, code, jobs", [(signal.SIGTERM, 143, "1"),
                                             (signal.SIGINT, 130, "2")])
def test_a_signalled_tune_leaves_its_files_consistent_with_the_study(tmp_path, sig, code,
                                                                     jobs):
    from optuna.trial import TrialState

    out = tmp_path / "study"
    proc = _start("tune", HOVER, "--trials", "500", "--jobs", jobs, *TUNE_SHORT, "-o",
                  str(out))
    try:
        _wait_for(lambda: _rows(out / "trials.csv") >= 3, "three trials stored", proc, 300)
        proc.send_signal(sig)
        stdout, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == code, err
    assert f"interrupted ({sig.name})" in err and "Traceback" not in err
    assert not (out / "study.db-wal").exists()  # checkpointed: study.db stands alone
    study = _study_alone(out, tmp_path)
    done = [t for t in study.trials if t.state is TrialState.COMPLETE]
    rows = _trials_csv(out)
    assert [(int(r["trial"]), float(r["score"])) for r in rows] == \
        [(t.number, t.value) for t in done]
    assert [t.number for t in study.trials] == list(range(len(study.trials)))
    best = min(done, key=lambda t: t.value)
    assert f"trial {best.number} of {len(done)}" in (out / "best.yaml").read_text()
    assert f"{len(done)} trials ({len(done)} flown now, 0 before)" in " ".join(stdout.split())


def _kept_tune(tmp_path: Path, *args: str) -> Path:
    """A short ``tune --keep-runs`` of hover into ``tmp_path/study``; its directory."""
    out = tmp_path / "study"
    result = runner.invoke(app, ["tune", HOVER, "--keep-runs", *TUNE_SHORT, *args, "-o",
                                 str(out)])
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.timeout(600)
def test_kept_run_folders_are_named_by_the_trial_number_of_trials_csv(tmp_path):
    out = _kept_tune(tmp_path, "--trials", "5", "--jobs", "2", "--variant",
                     "one:sim.plant.tau_vz_s=0.5")
    rows = _trials_csv(out)
    assert sorted(int(r["trial"]) for r in rows) == list(range(5))
    for row in rows:
        (run,) = (out / "runs" / f"trial-{int(row['trial']):05d}").iterdir()
        q = load_config(run / "config.yaml").controller.q
        assert [float(row[f"controller.q[{i}]"]) for i in range(7) if q[i]] == \
            [v for v in q if v]


@pytest.mark.timeout(300)
def test_a_set_plant_profile_is_the_one_flown_and_written(tmp_path):
    out = _kept_tune(tmp_path, "--trials", "1", "--jobs", "1", "--set",
                     "sim.plant.profile=thesis_kit")
    labels = {c.split(":")[0] for c in _trials_csv(out)[0] if ":" in c}
    assert labels == {"seed0"}  # not every profile: the one set
    (run,) = (out / "runs" / "trial-00000").iterdir()
    assert load_config(run / "config.yaml").sim.plant.profile == "thesis_kit"
    assert load_config(out / "best.yaml").sim.plant.profile == "thesis_kit"
    clash = runner.invoke(app, ["tune", HOVER, "--set", "sim.plant.profile=thesis_kit",
                                "--variant", "lab:sim.plant.profile=ardrone_lab", "-o",
                                str(tmp_path / "other")])
    assert clash.exit_code == 1
    assert clash.stderr.startswith("error: --set sim.plant.profile: --variant "
                                   "'lab:sim.plant.profile=ardrone_lab' sets it per scenario")
    assert not (tmp_path / "other").exists()


@pytest.mark.timeout(120)
@pytest.mark.parametrize("command", [["tune", HOVER, *TUNE_SHORT],
                                     ["sweep", HOVER, "--grid", "duration_s=0.3"]])
def test_a_dask_scheduler_that_never_answers_is_an_error_not_a_hang(tmp_path, monkeypatch,
                                                                    command):
    from ardrone_nmpc.experiments import parallel

    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 1.0)
    with socket.socket() as silent:  # accepts connections and never says a word
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        result = runner.invoke(app, [*command, "--engine", "dask", "--scheduler", address,
                                     "-o", str(tmp_path / "out")])
    assert result.exit_code == 1, result.output
    assert result.stderr.splitlines()[-1] == (f"error: --engine dask: no Dask scheduler "
                                              f"answers at {address}: no answer within 1 s")


# ----------------------------------------------------------------------------- check = simulate


@pytest.mark.timeout(120)
def test_check_and_simulate_warn_of_the_same_ignored_fields(files, tmp_path):
    path = tmp_path / "wp.csv"
    path.write_text("t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n5,1,0,1,0\n")
    extra = ["--set", f"reference.path_file={path}", "--set", "reference.side_m=2"]
    check = runner.invoke(app, ["check", HOVER, *extra])
    flown = runner.invoke(app, ["simulate", HOVER, *extra, *SHORT, "--quiet", "--log-dir",
                                str(tmp_path / "logs")])
    assert check.exit_code == 0 and flown.exit_code == 0, (check.output, flown.output)
    warnings = [line for line in check.stderr.splitlines() if line.startswith("warning: ")]
    assert warnings == [
        "warning: reference.side_m: ignored by reference.kind 'hover' (read by: square, "
        "square_altitudes)",
        "warning: reference.path_file: ignored by reference.kind 'hover' (read by: path)"]
    assert [line for line in flown.stderr.splitlines() if line.startswith("warning: ")] == \
        warnings


def test_the_reproduce_report_names_the_options_that_made_it():
    from ardrone_nmpc.experiments.reproduce import COMMAND, command_line

    assert command_line(config_dir=Path("configs"), seed=0) == COMMAND
    assert command_line(config_dir=Path("my configs"), seed=3) == \
        f"{COMMAND} --config-dir 'my configs' --seed 3"


@pytest.mark.timeout(300)
def test_resuming_a_read_only_study_is_one_line_before_anything_flies(tmp_path, monkeypatch):
    """A study.db SQLite may read but not write (a read-only file or mount; root ignores the
    file mode, so the test opens it read-only the way SQLite does for such a file)."""
    import sqlite3

    import optuna

    from ardrone_nmpc.runs import tune_record

    out = tmp_path / "study"
    first = runner.invoke(app, ["tune", HOVER, "--trials", "1", "--jobs", "1", *TUNE_SHORT,
                                "--variant", "one:sim.plant.tau_vz_s=0.5", "-o", str(out)])
    assert first.exit_code == 0, first.output
    before = (out / "study.db").read_bytes()

    def read_only(db, *, read_only=False):
        uri = f"file:{Path(db).resolve()}?mode=ro"
        return optuna.storages.RDBStorage(f"sqlite:///{Path(db).resolve()}", engine_kwargs={
            "creator": lambda: sqlite3.connect(uri, uri=True, check_same_thread=False)})

    monkeypatch.setattr(tune_record, "storage", read_only)
    monkeypatch.setattr("ardrone_nmpc.experiments.tune.study.record_storage", read_only)
    result = runner.invoke(app, ["tune", HOVER, "--trials", "3", "--jobs", "1", *TUNE_SHORT,
                                 "--variant", "one:sim.plant.tau_vz_s=0.5", "--resume",
                                 "-o", str(out)])
    assert result.exit_code == 1, (result.output, result.exception)
    assert result.stderr.splitlines() == [
        f"error: {out / 'study.db'}: attempt to write a readonly database"], \
        (result.output, result.exception)
    assert (out / "study.db").read_bytes() == before
