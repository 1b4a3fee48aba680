"""Every command with hostile arguments: one ``error:`` line, exit ≠ 0, no traceback, no work.

Bad numbers (out of range, NaN, 1e308, 1e-300), empty hosts, ports outside 1–65535, outputs
that are directories or sit under a file, inputs that do not exist or exceed the limits. Each
must fail before anything is flown, sent or written (no run directory is left), with the
exit code of :mod:`ardrone_nmpc.errors`: 2 for the command line itself, 1 for the rest.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import RunRecorder

ROOT = Path(__file__).resolve().parents[2]
HOVER = str(ROOT / "configs" / "hover.yaml")
FAR_PATH = "t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n2,100000000,0,1,0\n"
SHORT = ["--set", "duration_s=0.3", "--set", "sim.settle_s=0.1"]

runner = CliRunner()


@pytest.fixture
def files(tmp_path) -> dict[str, str]:
    """A plain file, an existing directory, a far path CSV, a run directory."""
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    (tmp_path / "far.csv").write_text(FAR_PATH)
    cfg = load_config(overrides=["name=r"])
    with RunRecorder.create(tmp_path / "runs", cfg, seed=0) as rec:
        rec.write_row({"t_s": 0.0, "x_m": 0.0, "y_m": 0.0, "z_m": 1.0, "psi_rad": 0.0,
                       "mode": "track", "solver_status": "ok"})
    return {"file": str(tmp_path / "afile"), "dir": str(tmp_path / "adir"),
            "far": str(tmp_path / "far.csv"), "run": str(rec.path),
            "logs": str(tmp_path / "logs"), "tmp": str(tmp_path)}


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
     r"^error: -o / --output: .*adir is a directory; give a file name$"),
    ("bench-json-a-dir", ["bench", "--json", "{dir}"], 2,
     r"^error: --json: .*adir is a directory; give a file name$"),
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
    ("robustness-missing", ["robustness", "{tmp}/nope.yaml", "--out", "{tmp}/rob"], 1,
     r"nope\.yaml: no such file"),
    ("robustness-zero-jobs", ["robustness", HOVER, "--jobs", "0"], 2, r"^error: --jobs: "),
    ("identify-missing", ["identify", "{tmp}/nope", "-o", "{tmp}/p.yaml"], 1,
     r"nope: no such run directory$"),
    ("identify-too-short", ["identify", "{run}", "-o", "{tmp}/p.yaml"], 1,
     r"too little flown with navdata and mocap"),
    ("tune-zero-trials", ["tune", HOVER, "--trials", "0"], 2, r"^error: --trials: "),
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
