"""Figures of ardrone_nmpc.viz.plots: the data drawn is the logged data, the labels carry units,
and the images render headless with real content."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.viz import plots, run_figures
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.viz.plots import PlotError
from ardrone_nmpc.runs.rundir import RunRecorder, read_run

ROOT = Path(__file__).resolve().parents[2]
SIZES_PX = {"tracking": (1100, 1250), "inputs": (1100, 1250), "solver": (1100, 1100),
            "path3d": (1300, 650)}


# ----------------------------------------------------------------------------- runs


@pytest.fixture(scope="module")
def sim_run(tmp_path_factory):
    """A short lockstep square (0.5 m sides, 1 s legs) with a settle phase: truth logged."""
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    cfg = load_config(ROOT / "configs" / "square.yaml",
                      ["duration_s=5", "sim.settle_s=0.5", "reference.side_m=0.5",
                       "reference.leg_duration_s=1.0"])
    with RunRecorder.create(tmp_path_factory.mktemp("runs"), cfg, seed=0) as rec:
        run_lockstep(cfg, recorder=rec, seed=0)
    return read_run(rec.path)


def _flight_rows(period_s: float = 0.065, n: int = 120):
    """Rows of a real-flight-like run: no truth, a hover fallback with a diverged solve, a
    saturated pitch command, no mocap sample for the first ticks, and a heading reference
    beyond π (the measured heading is wrapped)."""
    rng = np.random.default_rng(3)
    for k in range(n):
        t = (k - 10) * period_s
        psi_ref = min(max(t, 0.0), 4.0)  # rad, continuous past π
        mode = "settle" if t < 0 else ("hover" if 40 <= k < 50 else "track")
        yield dict(
            t_s=t, x_m=0.3 * math.sin(t) + 0.001 * rng.standard_normal(), y_m=0.1 * t,
            z_m=1.0, psi_rad=math.remainder(psi_ref + 0.02, 2 * math.pi), vx_mps=0.0,
            vy_mps=0.1, vz_mps=0.01 * rng.standard_normal(), x_ref_m=0.3 * math.sin(t),
            y_ref_m=0.1 * t, z_ref_m=1.0, psi_ref_rad=psi_ref, u_zacc_mps2=0.1 * math.sin(t),
            u_phi_rad=0.05, u_theta_rad=0.9 if k == 60 else 0.02 * math.cos(t),
            u_psirate_radps=0.5, cmd_roll_frac=0.2, cmd_pitch_frac=-1.0 if k == 60 else -0.1,
            cmd_gaz_frac=0.0, cmd_yaw_frac=-0.3, cmd_saturated="0100" if k == 60 else "0000",
            solve_us=math.nan if mode == "hover" else 40.0 + k % 7, mode=mode,
            solver_status="diverged" if k == 40 else ("" if mode == "hover" else "ok"),
            residual_norm=1e-3 * (1 + k % 5), gmres_iterations=5, newton_iterations=0,
            mocap_age_ms=math.inf if k < 3 else 5.0 + k % 4, navdata_age_ms=30.0 + k % 20,
            battery_pct=90.0, tick_late_ms=0.4 + 0.1 * (k % 3), compute_us=200.0 + k % 11)


@pytest.fixture(scope="module")
def flight_run(tmp_path_factory):
    cfg = load_config(overrides=["name=flight", "duration_s=7", "reference.kind=hover"])
    with RunRecorder.create(tmp_path_factory.mktemp("runs"), cfg, seed=None) as rec:
        for row in _flight_rows():
            rec.write_row(row)
    return read_run(rec.path)


def _line(ax, label):
    lines = [ln for ln in ax.get_lines() if ln.get_label() == label]
    assert len(lines) == 1, [ln.get_label() for ln in ax.get_lines()]
    return lines[0]


def _labels(ax):
    return ax.get_legend_handles_labels()[1]


# ----------------------------------------------------------------------------- tracking


def test_tracking_lines_are_the_logged_columns_from_t0(sim_run):
    fig = plots.figure_tracking(sim_run)
    axes = fig.get_axes()
    c = sim_run.columns
    exp = c["t_s"] >= 0
    assert (c["t_s"] < 0).any(), "the fixture should have a settle phase"
    for ax, (meas, ref, true), unit in zip(
            axes, [("x_m", "x_ref_m", "x_true_m"), ("y_m", "y_ref_m", "y_true_m"),
                   ("z_m", "z_ref_m", "z_true_m")], ["(m)"] * 3):
        measured = _line(ax, "measured")
        np.testing.assert_array_equal(measured.get_xdata(), c["t_s"][exp])
        np.testing.assert_array_equal(measured.get_ydata(), c[meas][exp])
        np.testing.assert_array_equal(_line(ax, "reference").get_ydata(), c[ref][exp])
        np.testing.assert_array_equal(_line(ax, "truth (sim)").get_ydata(), c[true][exp])
        assert unit in ax.get_ylabel()
    assert [ax.get_title(loc="left") for ax in axes] == [
        "x position", "y position", "altitude z", "heading ψ",
        "vertical speed ż: estimator vs truth"]
    assert axes[3].get_ylabel() == "ψ (rad)"
    assert axes[4].get_ylabel() == "ż (m/s)"
    np.testing.assert_array_equal(_line(axes[4], "estimate (kalman)").get_ydata(),
                                  c["vz_mps"][exp])
    np.testing.assert_array_equal(_line(axes[4], "truth (sim)").get_ydata(),
                                  c["vz_true_mps"][exp])
    assert axes[-1].get_xlabel() == "t (s)"
    assert "square" in fig.get_suptitle() and "tracking" in fig.get_suptitle()


def test_tracking_draws_heading_next_to_its_reference(flight_run):
    ax = plots.figure_tracking(flight_run).get_axes()[3]
    c = flight_run.columns
    exp = c["t_s"] >= 0
    drawn = _line(ax, "measured").get_ydata()
    ref = c["psi_ref_rad"][exp]
    assert (np.abs(c["psi_rad"][exp] - ref) > 3).any(), "the fixture should wrap ψ"
    np.testing.assert_allclose(drawn - ref, 0.02, atol=1e-9)  # no 2π jump
    turns = (drawn - c["psi_rad"][exp]) / (2 * math.pi)
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-9)  # whole turns only


def test_tracking_without_truth_and_with_a_fallback(flight_run):
    axes = plots.figure_tracking(flight_run).get_axes()
    assert "truth (sim)" not in _labels(axes[0])
    assert "fallback (hover)" in _labels(axes[0])
    assert axes[4].get_title(loc="left") == "vertical speed ż: estimator"


def test_tracking_keeps_millimetre_noise_from_filling_a_panel(sim_run):
    z_ax = plots.figure_tracking(sim_run).get_axes()[2]
    lo, hi = z_ax.get_ylim()
    assert hi - lo >= 0.05 - 1e-12


# ----------------------------------------------------------------------------- inputs


def test_inputs_lines_and_bounds(sim_run):
    fig = plots.figure_inputs(sim_run)
    axes = fig.get_axes()
    c = sim_run.columns
    exp = c["t_s"] >= 0
    cfg = sim_run.config
    names = ["u_zacc_mps2", "u_phi_rad", "u_theta_rad", "u_psirate_radps"]
    units = ["(m/s²)", "(rad)", "(rad)", "(rad/s)"]
    for i, (ax, name, unit) in enumerate(zip(axes, names, units)):
        np.testing.assert_array_equal(_line(ax, "input").get_ydata(), c[name][exp])
        assert unit in ax.get_ylabel()
        levels = {ln.get_ydata()[0] for ln in ax.get_lines() if ln.get_label() != "input"
                  and len(set(ln.get_ydata())) == 1}
        assert {cfg.controller.u_min[i], cfg.controller.u_max[i]} <= levels
    tilt = cfg.drone.euler_angle_max_rad
    assert any(lab.startswith(f"drone limit ±{tilt:.3g} rad") for lab in _labels(axes[1]))
    # the square's inputs are small: ±1 bounds would flatten them, so they are off scale
    assert any(lab.startswith("bounds ±1 m/s²") and "off scale" in lab
               for lab in _labels(axes[0]))
    assert axes[0].get_ylim()[1] < 1.0
    assert axes[4].get_ylim() == (-1.15, 1.15)
    assert axes[4].get_ylabel() == "command (fraction)"
    np.testing.assert_array_equal(_line(axes[4], "pitch").get_ydata(), c["cmd_pitch_frac"][exp])


def test_inputs_mark_saturated_commands(flight_run):
    axes = plots.figure_inputs(flight_run).get_axes()
    marks = _line(axes[4], "pitch saturated (1 ticks)")
    assert list(marks.get_ydata()) == [-1.0]
    assert "fallback (hover)" in _labels(axes[0])


def test_bound_near_the_data_is_shown_far_bound_is_off_scale():
    data = np.array([-0.1, 0.25])
    (lo, hi), off = run_figures._off_scale_view(data, [-0.5, 0.5, -1.0, 1.0])
    assert off == {-1.0, 1.0}
    assert lo < -0.5 and 0.5 < hi < 1.0


# ----------------------------------------------------------------------------- solver


def test_solver_figure_covers_every_row(sim_run):
    fig = plots.figure_solver(sim_run)
    axes = fig.get_axes()
    c = sim_run.columns
    solve = next(ln for ln in axes[0].get_lines() if ln.get_label().startswith("solve"))
    np.testing.assert_array_equal(solve.get_xdata(), c["t_s"])  # the settle phase too
    np.testing.assert_array_equal(solve.get_ydata(), c["solve_us"])
    assert "settle (t < 0)" in _labels(axes[0])
    assert axes[0].get_ylabel() == "time (µs)"
    assert axes[1].get_yscale() == "log"
    assert axes[2].get_ylabel() == "iterations (count)"
    assert axes[3].get_ylabel() == "age (ms)"
    np.testing.assert_array_equal(_line(axes[3], "navdata age").get_ydata(),
                                  c["navdata_age_ms"])


def test_solver_figure_marks_bad_status_and_missing_link_data(flight_run):
    axes = plots.figure_solver(flight_run).get_axes()
    assert "status ≠ ok (1 ticks)" in _labels(axes[0])
    assert "mocap age (3 ticks without data)" in _labels(axes[3])
    assert "tick lateness" in _labels(axes[3])
    assert "mocap hover 250 ms (off scale)" in _labels(axes[3])


# ----------------------------------------------------------------------------- path


def test_path_figure_draws_the_flown_truth_and_the_polyline(sim_run):
    from ardrone_nmpc.reference.trajectories import make_trajectory
    from ardrone_nmpc.runs.summary import summarise

    fig = plots.figure_path3d(sim_run)
    ax3, ax2 = fig.get_axes()
    c = sim_run.columns
    exp = c["t_s"] >= 0
    flown = _line(ax2, "flown (sim truth)")
    np.testing.assert_array_equal(flown.get_xdata(), c["x_true_m"][exp])
    np.testing.assert_array_equal(flown.get_ydata(), c["y_true_m"][exp])
    poly = make_trajectory(sim_run.config.reference).polyline_m()
    np.testing.assert_array_equal(_line(ax2, "reference (square)").get_xdata(), poly[:, 0])
    assert ax2.get_xlabel() == "x (m)" and ax2.get_ylabel() == "y (m)"
    assert ax3.get_zlabel() == "z (m)"
    mean = {(r.axis, r.metric): r.value for r in summarise(sim_run)}[("path", "mean_deviation")]
    assert f"mean {mean:.3f} m" in fig.get_suptitle()


def test_empty_log_is_a_plot_error(tmp_path):
    cfg = load_config(overrides=["name=empty"])
    with RunRecorder.create(tmp_path, cfg, seed=None) as rec:
        pass
    run = read_run(rec.path)
    for kind in plots.KINDS:
        with pytest.raises(PlotError, match="no rows"):
            getattr(plots, f"figure_{kind}")(run)


# ----------------------------------------------------------------------------- images


def _image_stats(path: Path) -> tuple[tuple[int, int], float, int]:
    """(width, height) px, pixel standard deviation (0–255) and distinct colours."""
    from matplotlib.image import imread

    img = imread(path)  # float RGBA in [0, 1]
    rgb = (img[..., :3] * 255).round().astype(np.uint8)
    colours = np.unique(rgb.reshape(-1, 3), axis=0).shape[0]
    return (img.shape[1], img.shape[0]), float(rgb.std()), colours


@pytest.mark.parametrize("kind", plots.KINDS)
def test_each_kind_renders_a_png_with_content(sim_run, tmp_path, kind):
    before = "matplotlib.pyplot" in sys.modules
    fig = getattr(plots, f"figure_{kind}")(sim_run)
    path = plots.save_figure(fig, tmp_path / "sub" / f"{kind}.png", dpi=100)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    size, std, colours = _image_stats(path)
    assert size == SIZES_PX[kind]
    assert std > 10.0  # not a blank page: white background with dark lines and text
    assert colours > 50  # lines in several colours, anti-aliased text
    if not before:
        assert "matplotlib.pyplot" not in sys.modules  # the OO API only, no global state


def test_importing_plots_does_not_import_matplotlib():
    code = "import sys, ardrone_nmpc.viz.plots; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


# ----------------------------------------------------------------------------- sweeps

SWEEP_HEADER = ["case", "controller.horizon_steps", "controller.dtau_s", "rmse_m", "settling_s",
                "overshoot_pct", "path_deviation_m", "solve_mean_us", "solve_p99_us",
                "fallbacks", "status", "message", "run_dir"]


def write_sweep(path: Path, rows, header=SWEEP_HEADER) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    with open(path / "sweep.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def _case(i, n, dtau, rmse, status="ok", message=""):
    return [f"c{i}", n, dtau, rmse, 2.5, 1.0, "nan", 30 + n, 60 + n, 0, status, message,
            f"c{i}"]


@pytest.fixture
def sweep_dir(tmp_path):
    rows = []
    rmse = {}
    for i, (n, dtau) in enumerate([(n, d) for n in (5, 10, 15) for d in (0.08, 0.1, 0.3)]):
        value = round(0.01 * n * dtau + 0.001 * i, 6)
        status = {(5, 0.3): "unstable", (15, 0.08): "failed"}.get((n, dtau), "ok")
        rows.append(_case(i, n, dtau, value if status != "failed" else "nan", status,
                          "solver, diverged" if status == "failed" else ""))
        rmse[(n, dtau)] = value
    return write_sweep(tmp_path / "sweep", rows), rmse


def test_read_sweep_finds_parameters_and_metrics(sweep_dir):
    path, _ = sweep_dir
    table = plots.read_sweep(path)
    assert table.params == ("controller.horizon_steps", "controller.dtau_s")
    assert table.metrics[0] == "rmse_m" and "fallbacks" in table.metrics
    assert len(table.rows) == 9
    failed = [r for r in table.rows if r["status"] == "failed"]
    assert [r["message"] for r in failed] == ["solver, diverged"]  # a quoted comma survives


def test_heatmap_cells_are_the_sweep_metric(sweep_dir):
    path, rmse = sweep_dir
    fig = plots.figure_sweep_heatmap(plots.read_sweep(path), metric="rmse_m")
    ax = fig.get_axes()[0]
    cells = ax.get_images()[0].get_array()
    assert [t.get_text() for t in ax.get_xticklabels()] == ["5", "10", "15"]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["0.08", "0.1", "0.3"]
    for i, dtau in enumerate((0.08, 0.1, 0.3)):
        for j, n in enumerate((5, 10, 15)):
            if (n, dtau) in ((5, 0.3), (15, 0.08)):
                assert cells.mask[i, j]  # no number drawn for unstable/failed
            else:
                assert cells[i, j] == rmse[(n, dtau)]
    texts = [t.get_text() for t in ax.texts]
    assert "unstable" in texts and "failed" in texts
    assert f"{rmse[(10, 0.1)]:.3g}" in texts
    assert ax.get_xlabel() == "controller.horizon_steps"
    assert ax.get_ylabel() == "controller.dtau_s (s)"
    assert fig.get_axes()[1].get_ylabel() == "RMSE (m)"  # the colour bar
    assert "RMSE over controller.horizon_steps × controller.dtau_s" in ax.get_title()


def test_heatmap_of_three_parameters_takes_the_minimum_over_the_third(tmp_path):
    header = SWEEP_HEADER[:3] + ["controller.solver.kmax"] + SWEEP_HEADER[3:]
    rows = []
    for i, (n, d, k) in enumerate([(n, d, k) for n in (5, 10) for d in (0.1, 0.3)
                                   for k in (3, 5)]):
        row = _case(i, n, d, 0.01 * n * d + 0.001 * k, "unstable" if (n, k) == (5, 3) else "ok")
        rows.append(row[:3] + [k] + row[3:])
    table = plots.read_sweep(write_sweep(tmp_path / "s3", rows, header))
    grid = plots.sweep_grid(table, metric="rmse_m")
    assert grid.aggregated == ("controller.solver.kmax",)
    expected = [[0.01 * 5 * 0.1 + 0.005, 0.01 * 10 * 0.1 + 0.003],  # (5, 3) was unstable
                [0.01 * 5 * 0.3 + 0.005, 0.01 * 10 * 0.3 + 0.003]]
    np.testing.assert_allclose(grid.values, expected, rtol=1e-12)
    assert grid.n_bad.tolist() == [[1, 0], [1, 0]]
    fig = plots.figure_sweep_heatmap(table, metric="rmse_m")
    assert "minimum) over controller.solver.kmax" in fig.get_axes()[0].get_title()
    chosen = plots.sweep_grid(table, metric="rmse_m", x="controller.solver.kmax",
                              y="controller.dtau_s")
    assert chosen.aggregated == ("controller.horizon_steps",)
    assert chosen.x_labels == ("3", "5") and chosen.y_labels == ("0.1", "0.3")


def test_sweep_errors_are_plot_errors(sweep_dir, tmp_path):
    path, _ = sweep_dir
    table = plots.read_sweep(path)
    with pytest.raises(PlotError, match="--metric: 'bogus'"):
        plots.sweep_grid(table, metric="bogus")
    with pytest.raises(PlotError, match="--x: 'controller.kmax' was not swept"):
        plots.sweep_grid(table, x="controller.kmax")
    with pytest.raises(PlotError, match="different"):
        plots.sweep_grid(table, x="controller.dtau_s", y="controller.dtau_s")
    bare = write_sweep(tmp_path / "bare", [["c0", 1.0, 1.0, 1.0, 1.0, 0, 0, 0, "ok", "", ""]],
                       ["case"] + SWEEP_HEADER[3:])
    with pytest.raises(PlotError, match="no swept parameter"):
        plots.read_sweep(bare)
    with pytest.raises(PlotError, match="no such file|cannot read"):
        plots.read_sweep(tmp_path / "nowhere")


def test_a_torn_last_sweep_row_is_dropped_with_a_warning(sweep_dir):
    path, _ = sweep_dir
    text = (path / "sweep.csv").read_text()
    (path / "sweep.csv").write_text(text + "c9,20,0.1,0.0")
    table = plots.read_sweep(path)
    assert len(table.rows) == 9
    assert "incomplete last row" in table.warnings[0]


def test_heatmap_renders_a_png_with_content(sweep_dir, tmp_path):
    path, _ = sweep_dir
    fig = plots.figure_sweep_heatmap(plots.read_sweep(path), metric="solve_p99_us")
    out = plots.save_figure(fig, tmp_path / "heat.png", dpi=100)
    size, std, colours = _image_stats(out)
    w, h = fig.get_size_inches() * 100
    assert size == (round(w), round(h))
    assert std > 20.0 and colours > 50
