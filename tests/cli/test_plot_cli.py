"""``ardrone-nmpc plot`` through typer's CliRunner: files written, exit codes, error lines."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.rundir import RunRecorder

runner = CliRunner()
KINDS = ("tracking", "inputs", "solver", "path3d")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A small hand-written run directory (a real-flight log: no truth columns)."""
    cfg = load_config(overrides=["name=cli_plot", "duration_s=3", "reference.kind=step",
                                 "reference.target_m=[0.5, 0, 1]"])
    with RunRecorder.create(tmp_path_factory.mktemp("runs"), cfg, seed=None) as rec:
        for k in range(60):
            t = (k - 10) * 0.065
            x = 0.5 * (1 - np.exp(-max(t - 1.0, 0.0) / 0.5))
            rec.write_row(dict(
                t_s=t, x_m=x, y_m=0.0, z_m=1.0, psi_rad=0.0, vx_mps=0.0, vy_mps=0.0,
                vz_mps=0.0, x_ref_m=0.5 if t >= 1.0 else 0.0, y_ref_m=0.0, z_ref_m=1.0,
                psi_ref_rad=0.0, u_zacc_mps2=0.0, u_phi_rad=0.0, u_theta_rad=0.1 * (0.5 - x),
                u_psirate_radps=0.0, cmd_roll_frac=0.0, cmd_pitch_frac=-0.2 * (0.5 - x),
                cmd_gaz_frac=0.0, cmd_yaw_frac=0.0, cmd_saturated="0000", solve_us=50.0 + k,
                solver_status="ok", residual_norm=1e-3, mode="settle" if t < 0 else "track",
                mocap_age_ms=4.0, navdata_age_ms=30.0, battery_pct=90.0))
    return rec.path


@pytest.fixture
def sweep_dir(tmp_path) -> Path:
    header = ["case", "controller.horizon_steps", "controller.dtau_s", "rmse_m", "settling_s",
              "overshoot_pct", "path_deviation_m", "solve_mean_us", "solve_p99_us",
              "fallbacks", "status", "message", "run_dir"]
    path = tmp_path / "sweep"
    path.mkdir()
    with open(path / "sweep.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for i, (n, d) in enumerate([(n, d) for n in (5, 10) for d in (0.1, 0.3)]):
            status = "unstable" if (n, d) == (5, 0.3) else "ok"
            writer.writerow([f"c{i}", n, d, 0.01 * n * d, 2.0, 1.0, "nan", 30, 60, 0, status,
                             "", f"c{i}"])
    return path


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def _one_error_line(result) -> str:
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    return lines[0]


# ----------------------------------------------------------------------------- runs


def test_plot_run_writes_one_png_per_kind_into_the_run_dir(run_dir):
    result = runner.invoke(app, ["plot", str(run_dir)])
    assert result.exit_code == 0, result.output
    expected = [run_dir / f"plot-{k}.png" for k in KINDS]
    assert result.output.splitlines() == [f"plot: {p}" for p in expected]
    assert _png_size(expected[0]) == (1100, 1250)
    assert _png_size(expected[3]) == (1300, 650)


def test_plot_all_with_output_names_one_file_per_kind(run_dir, tmp_path):
    result = runner.invoke(app, ["plot", str(run_dir), "-o", str(tmp_path / "out" / "run.png"),
                                 "--kind", "all", "--dpi", "50"])
    assert result.exit_code == 0, result.output
    for k in KINDS:
        assert (tmp_path / "out" / f"run-{k}.png").is_file()
    assert _png_size(tmp_path / "out" / "run-solver.png") == (550, 550)


def test_plot_one_kind_writes_exactly_the_output_file(run_dir, tmp_path):
    result = runner.invoke(app, ["plot", str(run_dir), "--kind", "inputs", "-o",
                                 str(tmp_path / "inputs")])
    assert result.exit_code == 0, result.output
    assert result.output.strip() == f"plot: {tmp_path / 'inputs.png'}"  # suffix added
    assert _png_size(tmp_path / "inputs.png") == (1100, 1250)
    assert list(tmp_path.iterdir()) == [tmp_path / "inputs.png"]


# ----------------------------------------------------------------------------- sweeps


def test_plot_sweep_dir_draws_the_heat_map(sweep_dir):
    result = runner.invoke(app, ["plot", str(sweep_dir)])
    assert result.exit_code == 0, result.output
    out = sweep_dir / "plot-heatmap-rmse_m.png"
    assert result.output.strip() == f"plot: {out}"
    width, height = _png_size(out)
    assert width >= 700 and height >= 450


def test_plot_sweep_metric_and_axes(sweep_dir, tmp_path):
    out = tmp_path / "heat.png"
    result = runner.invoke(app, ["plot", str(sweep_dir / "sweep.csv"), "--metric",
                                 "solve_p99_us", "--x", "controller.dtau_s", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.is_file()


# ----------------------------------------------------------------------------- errors


def test_an_unknown_kind_is_a_command_line_error(run_dir):
    result = runner.invoke(app, ["plot", str(run_dir), "--kind", "bode"])
    assert result.exit_code == 2
    assert result.output == ("error: --kind: unknown 'bode'; choose tracking, inputs, solver, "
                             "path3d, all\n")


@pytest.mark.parametrize("args, message", [
    (["--metric", "rmse_m"], "--metric: only for sweep directories"),
    (["--kind", "tracking", "-o", "x.docx"], "-o: cannot write '.docx' images"),
])
def test_plot_run_usage_errors(run_dir, args, message):
    line = _one_error_line(runner.invoke(app, ["plot", str(run_dir), *args]))
    assert message in line


@pytest.mark.parametrize("args, message", [
    (["--metric", "speed"], "--metric: 'speed' is not a metric"),
    (["--x", "controller.kmax"], "--x: 'controller.kmax' was not swept"),
    (["--kind", "tracking"], "is a sweep directory"),
])
def test_plot_sweep_usage_errors(sweep_dir, args, message):
    line = _one_error_line(runner.invoke(app, ["plot", str(sweep_dir), *args]))
    assert message in line


def test_plot_missing_and_non_run_directories(tmp_path):
    line = _one_error_line(runner.invoke(app, ["plot", str(tmp_path / "nope")]))
    assert line == f"error: {tmp_path / 'nope'}: no such directory"
    line = _one_error_line(runner.invoke(app, ["plot", str(tmp_path)]))
    assert "not a run directory (no log.csv) nor a sweep directory" in line


def test_plot_corrupt_log_is_one_error_line(run_dir, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    for name in ("config.yaml", "events.jsonl"):
        (bad / name).write_bytes((run_dir / name).read_bytes())
    lines = (run_dir / "log.csv").read_text().splitlines()
    cells = lines[5].split(",")
    cells[1] = "oops"  # x_m
    lines[5] = ",".join(cells)
    (bad / "log.csv").write_text("\n".join(lines) + "\n")
    line = _one_error_line(runner.invoke(app, ["plot", str(bad)]))
    assert line == f"error: {bad / 'log.csv'}:6: column x_m: 'oops' is not a number"


def test_plot_without_matplotlib_says_how_to_install_it(run_dir, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # `import matplotlib` now fails
    line = _one_error_line(runner.invoke(app, ["plot", str(run_dir)]))
    assert line == "error: plotting needs matplotlib: pip install -e '.[plot]'"


def test_help_does_not_import_matplotlib():
    code = "\n".join([
        "import sys",
        "from typer.testing import CliRunner",
        "from ardrone_nmpc.cli.app import app",
        "r = CliRunner().invoke(app, ['--help'])",
        "assert r.exit_code == 0 and 'plot' in r.output",
        "print(sorted(m for m in sys.modules if m.startswith('matplotlib')))"])
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"


def test_plot_into_an_existing_directory_writes_the_default_names_there(run_dir, tmp_path):
    out = tmp_path / "figures"
    out.mkdir()
    result = runner.invoke(app, ["plot", str(run_dir), "-o", str(out), "--kind", "tracking"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines() == [f"plot: {out / 'plot-tracking.png'}"]
    assert _png_size(out / "plot-tracking.png")[0] > 100
    assert not (tmp_path / "figures.png").exists()  # not beside the directory


def test_plot_a_sweep_into_an_existing_directory(sweep_dir, tmp_path):
    result = runner.invoke(app, ["plot", str(sweep_dir), "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines() == [f"plot: {tmp_path / 'plot-heatmap-rmse_m.png'}"]
