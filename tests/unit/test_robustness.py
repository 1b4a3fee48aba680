"""How ``robustness`` judges a flight and lays out its grid: the judge on hand-made logs whose
verdict is known, the grid file, the corners ``tune --robust`` flies, the map."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.experiments.robustness.grid import (DEFAULT_GRID, corner_variants,
                                                      grid_from_data)
from ardrone_nmpc.experiments.robustness.judge import judge_columns
from ardrone_nmpc.experiments.robustness.report import cells, region_lines
from ardrone_nmpc.experiments.robustness.run import RobustnessRow

FENCE = {"geofence_min_m": (-3.0, -3.0, -0.2), "geofence_max_m": (3.0, 3.0, 2.5)}
DT = 0.065


def _log(x_err, *, seconds=30.0, pitch=None, mode="track"):
    """A hover log at (0, 0, 1): x off by ``x_err(t)``, PCMD pitch ``pitch(t)``."""
    t = np.arange(0.0, seconds, DT)
    n = t.size
    cols = {"t_s": t, "x_true_m": x_err(t), "y_true_m": np.zeros(n),
            "z_true_m": np.ones(n), "x_ref_m": np.zeros(n), "y_ref_m": np.zeros(n),
            "z_ref_m": np.ones(n), "cmd_roll_frac": np.zeros(n),
            "cmd_pitch_frac": pitch(t) if pitch else np.zeros(n),
            "mode": np.array([mode] * n, dtype=object)}
    for a in "xyz":
        cols[f"{a}_m"] = cols[f"{a}_true_m"]
    return cols


def test_a_still_flight_settles_clean():
    v = judge_columns(_log(lambda t: 0.002 * np.sin(3 * t)), **FENCE)
    assert (v.verdict, v.clean) == ("settled", True)
    assert v.steady_error_m < 1e-3 and v.saturation_frac == 0.0


def test_a_sustained_oscillation_is_a_limit_cycle_with_its_amplitude_and_period():
    v = judge_columns(_log(lambda t: 0.05 * np.sin(2 * math.pi * t / 2.5)), **FENCE)
    assert v.verdict == "limit cycle" and not v.clean
    assert v.amplitude_m == pytest.approx(0.05, rel=0.05)
    assert v.period_s == pytest.approx(2.5, rel=0.05)


def test_a_decaying_transient_or_an_offset_is_no_cycle_but_an_offset_is_unclean():
    decayed = judge_columns(_log(lambda t: 0.3 * np.exp(-t / 2) * np.sin(3 * t)), **FENCE)
    assert decayed.verdict == "settled" and decayed.clean
    offset = judge_columns(_log(lambda t: np.full_like(t, 0.05)), **FENCE)
    assert offset.verdict == "settled" and not offset.clean
    assert offset.steady_error_m == pytest.approx(0.05) and "steady error" in offset.reason


def test_saturation_over_two_percent_is_unclean():
    bangs = judge_columns(_log(lambda t: np.zeros_like(t),
                               pitch=lambda t: np.where(t < 1.0, 1.0, 0.1)), **FENCE)
    assert bangs.verdict == "settled" and not bangs.clean
    assert bangs.saturation_frac == pytest.approx(1.0 / 30.0, abs=0.01)


def test_the_supervisor_and_a_divergence_are_their_own_classes():
    cols = _log(lambda t: np.zeros_like(t))
    cols["mode"][100:110] = "hover-tilt"
    v = judge_columns(cols, **FENCE)
    assert v.verdict == "supervisor" and v.supervisor_ticks == 10 and "hover-tilt" in v.reason
    away = judge_columns(_log(lambda t: 0.2 * t), **FENCE)
    assert away.verdict == "diverged"
    landed = judge_columns(_log(lambda t: np.zeros_like(t)), **FENCE, ending="land-geofence")
    assert landed.verdict == "diverged"


# ----------------------------------------------------------------------------- grid
def test_the_default_grid_covers_the_region_in_160_flights():
    axes = dict(DEFAULT_GRID.axes)
    assert DEFAULT_GRID.size == 160
    assert (min(axes["sim.plant.command_delay_s"]), max(axes["sim.plant.command_delay_s"])) \
        == (0.0, 0.4)
    assert (min(axes["sim.plant.attitude_gain"]), max(axes["sim.plant.attitude_gain"])) \
        == (0.6, 2.0)
    assert math.hypot(*axes["faults.wind.velocity_mps"][-1][:2]) == pytest.approx(0.4)


def test_tune_robust_flies_a_half_fraction_of_the_corners_and_the_centre():
    variants = corner_variants(DEFAULT_GRID)
    assert len(variants) == 2 ** 5 // 2 + 1
    label, centre = variants[-1]
    assert label == "centre"
    assert "sim.plant.command_delay_s=0.2" in centre and "sim.plant.attitude_gain=1.3" in centre
    assert "faults.wind.velocity_mps=[0.16,0.12,0.0]" in centre
    # every pair of two axes meets in its four corners (resolution V)
    picks = [label for label, _ in variants[:-1]]
    for i in range(5):
        for j in range(i + 1, 5):
            assert {(p[i], p[j]) for p in picks} == {("-", "-"), ("-", "+"), ("+", "-"),
                                                      ("+", "+")}


def test_a_grid_file_names_its_axes_and_map():
    g = grid_from_data({"axes": {"sim.plant.command_delay_s": [0, 0.4],
                                 "sim.plant.attitude_gain": [0.6, 2.0]}})
    assert (g.x, g.y, g.panel, g.size) == ("sim.plant.command_delay_s",
                                           "sim.plant.attitude_gain", "", 4)
    with pytest.raises(ConfigError) as info:
        grid_from_data({"axes": {"a.b": []}, "map": {"x": "c.d"}, "extra": 1})
    text = "\n".join(info.value.messages)
    assert "non-empty list" in text and "unknown keys" in text and "not one of the axes" in text


def test_the_region_names_every_flight_that_is_not_clean():
    ok = judge_columns(_log(lambda t: np.zeros_like(t)), **FENCE)
    cycle = judge_columns(_log(lambda t: 0.05 * np.sin(2.5 * t)), **FENCE)
    grid = grid_from_data({"axes": {"d": [0, 0.4], "k": [1, 2]}})
    rows = [RobustnessRow(f"c{i}", (("d", d), ("k", k)), v, f"c{i}")
            for i, (d, k, v) in enumerate([("0", "1", ok), ("0.4", "1", ok), ("0", "2", ok),
                                           ("0.4", "2", cycle)])]
    lines = region_lines(rows, grid)
    assert lines[0].startswith("3 of 4 flights clean over d 0–0.4, k 1–2")
    assert lines[1].startswith("not clean: d=0.4, k=2: limit cycle")
    cell = cells(rows, grid)[""][("0.4", "2")]
    assert (cell.flights, cell.clean, cell.label) == (1, 0, "limit cycle")


def test_the_map_draws_one_panel_per_wind(tmp_path):
    from ardrone_nmpc.viz.figure import save_figure
    from ardrone_nmpc.viz.robustness_map import figure_robustness_map

    rows = [{"d": d, "k": k, "w": w, "verdict": "settled", "clean": str(d != "0.4").lower()}
            for d in ("0", "0.4") for k in ("1", "2") for w in ("[0,0,0]", "[0.3,0.2,0]")]
    fig = figure_robustness_map(rows, x="d", y="k", panel="w")
    assert len(fig.axes) == 2
    assert save_figure(fig, tmp_path / "map.png").stat().st_size > 1000
