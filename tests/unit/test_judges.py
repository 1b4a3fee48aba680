"""The judges' arithmetic at its edges (experiments/reproduce/judges.py): which samples make
the middle and last thirds, the thresholds taken exactly, the crossings' hysteresis, and
``figures_of`` on synthetic runs — each figure against the rule docs/thesis-reproduction.md
states, computed here from the samples."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.reproduce.judges import (
    GROWING, SETTLING_BAND, SHRINKING, Conditions, Motion, RunFigures, classify_motion,
    figures_of, swing_period_s, within)

# ----------------------------------------------------------------------------- thirds


def _third(t: np.ndarray, j: int) -> str:
    """The documented split of the samples after the step: middle third
    [t₀ + span/3, t₀ + 2·span/3), last third [t₀ + 2·span/3, end]."""
    t0, span = t[0], t[-1] - t[0]
    if t[j] >= t0 + 2.0 * span / 3.0:
        return "last"
    return "middle" if t[j] >= t0 + span / 3.0 else "first"


@pytest.mark.parametrize("n", [10, 11, 12])
def test_the_middle_and_last_thirds_hold_the_documented_samples(n):
    """One spike at sample j on a zero error: in the middle third the end converges (the last
    third is flat, the middle is not); in the last third the end is unsettled with the
    spike's peak-to-peak; in the first third it counts nowhere. n = 10 puts the thirds
    exactly on samples 3 and 6."""
    t = np.arange(n, dtype=float)
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1.0
        m = classify_motion(t, e, t_step_s=0.0, band=10.0, settled=False, unit="rad")
        want = {"middle": ("converging", 0.0), "last": ("unsettled", 1.0),
                "first": ("unsettled", 0.0)}[_third(t, j)]
        assert (m.kind, m.ptp, m.unit) == (*want, "rad"), (n, j)


def test_a_sample_exactly_at_two_thirds_is_in_the_last_third_only():
    """t = 0 … 9: the last third starts exactly at t = 6. A step of the error there leaves the
    middle third flat, so a tail that swings at all is diverging (it would not be if the
    middle third also held t = 6)."""
    t = np.arange(10, dtype=float)
    e = np.zeros(10)
    e[6:] = [1.0, 0.0, 1.0, 0.0]
    m = classify_motion(t, e, t_step_s=0.0, band=0.01, settled=False, unit="rad")
    assert (m.kind, m.ptp) == ("diverging", 1.0)


def test_samples_before_the_step_and_non_finite_ones_are_not_judged():
    t = np.arange(30, dtype=float)
    e = np.where(t < 10, 5.0, 0.1 * np.exp(-0.3 * (t - 10)) * np.cos(np.pi * t))
    e[25] = math.nan
    m = classify_motion(t, e, t_step_s=10.0, band=0.001, settled=False)
    kept = (t >= 10) & np.isfinite(e)
    tail = kept & (t >= 10 + 2.0 * (29 - 10) / 3.0)
    assert m.kind == "converging" and m.ptp == pytest.approx(np.ptp(e[tail]), abs=1e-15)


def test_six_samples_after_the_step_are_judged_five_are_not():
    t = np.arange(12, dtype=float)
    e = np.ones(12)
    six = classify_motion(t, e, t_step_s=6.0, band=1.0, settled=True, unit="rad")
    assert six.kind == "settled" and six.ptp == 0.0 and six.unit == "rad"
    five = classify_motion(t, e, t_step_s=7.0, band=1.0, settled=True, unit="rad")
    assert (five.kind, five.unit) == ("ended early", "rad")
    early = classify_motion(t, e, t_step_s=0.0, band=1.0, settled=True, ended_early=True,
                            unit="rad")
    assert (early.kind, early.unit) == ("ended early", "rad")
    assert classify_motion(t, e, t_step_s=0.0, band=1.0, settled=True).unit == "m"


# ----------------------------------------------------------------------------- thresholds


def _halves(*amplitudes: float, per_half: int = 10) -> np.ndarray:
    """A square swing: each amplitude for two halves (+a then −a) of ``per_half`` samples."""
    return np.concatenate([np.r_[np.full(per_half, a), np.full(per_half, -a)]
                           for a in amplitudes])


def test_a_swing_exactly_twice_the_band_is_not_swinging():
    e = _halves(*[0.5] * 9)                  # peak-to-peak 1.0 = 2 · band exactly
    t = np.arange(e.size, dtype=float)
    assert classify_motion(t, e, t_step_s=0.0, band=0.5, settled=False).kind == "unsettled"
    assert classify_motion(t, e, t_step_s=0.0, band=0.49, settled=False).kind == "limit cycle"


def test_growing_and_shrinking_are_strict_ratios_of_the_thirds():
    """Last third over middle third exactly GROWING (3 : 2) is not diverging; exactly
    SHRINKING (67 : 100) is not converging: both are limit cycles."""
    assert GROWING * 2.0 == 3.0 and SHRINKING * 100.0 == 67.0
    for mid, tail, kind_above in ((1.0, 1.5, "diverging"), (50.0, 33.5, "converging")):
        e = _halves(*[mid] * 3, *[mid] * 3, *[tail] * 3)   # thirds of 60 samples each
        t = np.arange(e.size, dtype=float)
        m = classify_motion(t, e, t_step_s=0.0, band=0.01, settled=False, unit="rad")
        assert (m.kind, m.ptp, m.unit) == ("limit cycle", 2.0 * tail, "rad")
        nudged = _halves(*[mid] * 6, *[tail * (1.01 if kind_above == "diverging" else 0.99)] * 3)
        m = classify_motion(t, nudged, t_step_s=0.0, band=0.01, settled=False, unit="rad")
        assert (m.kind, m.unit) == (kind_above, "rad")
        assert m.ptp == pytest.approx(2.0 * tail, rel=0.02)


def test_crossings_need_to_pass_a_quarter_of_the_swing_strictly():
    """±1 halves of 30 samples with one sample exactly at ∓0.5 inside each (the hysteresis is
    a quarter of the 2.0 peak-to-peak: 0.5): no extra crossings; 16 halves are 15 crossings,
    7 full periods of 60 samples."""
    e = _halves(*[1.0] * 8, per_half=30)
    e[15::30] = -0.5 * e[15::30]
    assert e.mean() == 0.0
    t = np.arange(e.size, dtype=float)
    assert swing_period_s(t, e) == (60.0, 7.0)
    assert swing_period_s(t, e + 5.0) == (60.0, 7.0)   # about its mean, wherever that is
    assert swing_period_s(t, np.zeros(e.size))[1] == 0.0
    square = _halves(1.0, 1.0, per_half=30)
    assert swing_period_s(t[:75], square[:75])[1] == 0.0  # two crossings: no period yet


def test_within_includes_its_edge():
    assert within(3.0, 2.0, 0.5) and within(1.0, 2.0, 0.5)
    assert not within(3.0 + 1e-12, 2.0, 0.5) and not within(math.nan, 2.0)


def test_descriptions():
    assert Motion("settled", 0.05).describe() == "settled"
    assert Motion("ended early", 0.3).describe() == "ended early"
    assert Motion("converging", 0.123, unit="rad").describe() == "converging (0.12 rad p-p)"
    assert Motion("unsettled").describe() == "unsettled"
    assert Motion("limit cycle", 0.5, 2.04).describe() == "limit cycle 0.50 m p-p, period 2.0 s"


def test_flown_names_every_supervisor_mode_with_its_ticks():
    c = Conditions()
    f = RunFigures({}, supervised={"hover-tilt": 8, "fallback-solver": 3}, ticks=200)
    c.flown({"nmpc": f})
    assert c.failed == ["nmpc: the supervisor flew 11 of 200 experiment ticks "
                        "(fallback-solver 3, hover-tilt 8)"]


# ----------------------------------------------------------------------------- figures_of


def _run(overrides, cols, *, duration_s=10.0, kind="nmpc"):
    cfg = load_config(None, [f"duration_s={duration_s}", f"controller.kind={kind}", *overrides])
    n = len(cols["t_s"])
    base = {"solver_status": np.array(["ok"] * n, dtype=object),
            "mode": np.array(["track"] * n, dtype=object), "navdata_age_ms": np.full(n, 30.0)}
    for c in ("x_true_m", "y_true_m", "z_true_m", "psi_true_rad", "u_phi_rad", "u_theta_rad",
              "u_psirate_radps", "u_zacc_mps2", "vz_ref_mps"):
        base[c] = np.zeros(n)
    base.update({k: np.asarray(v) for k, v in cols.items()})
    return SimpleNamespace(config=cfg, columns=base, path=Path("/runs/20260101-000000-synth"))


TICK = 0.0625  # exact in binary: experiment time 0 and the run's end fall on samples


def _times(settle_s=1.0, end_s=10.0):
    return np.arange(-round(settle_s / TICK), round(end_s / TICK) + 1) * TICK


@pytest.mark.parametrize("kind, z_column", [("p", "vz_ref_mps"), ("nmpc", "u_zacc_mps2")])
def test_input_peaks_per_axis_and_the_vertical_input_of_each_controller(kind, z_column):
    t = _times()
    cols = {"t_s": t, "u_theta_rad": -0.3 * np.sin(t), "u_phi_rad": np.full(t.size, 0.2),
            "u_psirate_radps": np.full(t.size, math.nan), "vz_ref_mps": np.full(t.size, 0.7),
            "u_zacc_mps2": np.full(t.size, -0.9)}
    cols["u_phi_rad"][t < 0] = 5.0  # the settle phase is not judged
    f = figures_of(_run(["reference.kind=hover"], cols, kind=kind), [])
    assert f.input_peaks["x"] == pytest.approx(np.max(np.abs(0.3 * np.sin(t[t >= 0]))))
    assert f.input_peaks["y"] == 0.2 and math.isnan(f.input_peaks["psi"])
    assert f.input_peaks["z"] == abs(cols[z_column][0])
    assert f.input_peak == max(f.input_peaks["x"], 0.2, abs(cols[z_column][0]))
    assert f.end("x").kind == "unsettled" and f.motion == {}  # a hover judges no step
    assert f.path == Path("/runs/20260101-000000-synth")
    assert f.period_s == load_config(None, []).loop.period_s


def test_an_empty_run_has_no_figures_but_is_not_unstable_by_its_solves():
    f = figures_of(_run(["reference.kind=step", "reference.target_m=[1,0,1]"],
                        {"t_s": np.array([])}), [])
    assert f.bad_solves == 0.0 and f.ticks == 0 and f.ended_early
    assert math.isnan(f.input_peak) and math.isnan(f.navdata_age_s)
    assert f.end("x").kind == "ended early"


def test_experiment_ticks_start_at_t_0_and_a_run_ends_early_a_second_short():
    t = _times(end_s=9.0)                           # exactly 1 s short of 10 s: not early
    mode = np.array(["settle" if v < 0 else "track" for v in t], dtype=object)
    mode[t == 0.0] = "hover-tilt"
    f = figures_of(_run(["reference.kind=hover"], {"t_s": t, "mode": mode}), [])
    assert f.ticks == int(np.sum(t >= 0)) and f.supervised == {"hover-tilt": 1}
    assert not f.ended_early
    assert figures_of(_run(["reference.kind=hover"], {"t_s": _times(end_s=8.5)}),
                      []).ended_early


def test_the_summary_settling_time_makes_an_axis_settled():
    t = _times()
    x = np.where(t >= 1.0, -1.5 + 0.05 * np.sin(3 * t), 0.0)
    run = _run(["reference.kind=step", "reference.target_m=[-1.5,0,1]"], {"t_s": t,
                                                                            "x_true_m": x})
    rows = [SimpleNamespace(axis="x", metric="settling_time", value=2.5)]
    assert figures_of(run, rows).end("x").kind == "settled"
    assert figures_of(run, []).end("x").kind != "settled"


def test_the_band_is_two_percent_of_the_step_from_its_start():
    """x steps from 1.0 to −0.5 (1.5 m: band 3 cm); a steady swing of 5 cm p-p stays inside
    twice the band (unsettled), 7 cm leaves it (a limit cycle)."""
    t = _times(end_s=20.0)
    for ptp, kind in ((0.05, "unsettled"), (0.07, "limit cycle")):
        x = np.where(t >= 1.0, -0.5 + 0.5 * ptp * np.sign(np.sin(2 * np.pi * t / 2.0)), 1.0)
        run = _run(["reference.kind=step", "reference.start_m=[1,0,1]",
                    "reference.target_m=[-0.5,0,1]"], {"t_s": t, "x_true_m": x}, duration_s=20)
        m = figures_of(run, []).end("x")
        assert m.kind == kind and m.ptp == pytest.approx(ptp)
        assert SETTLING_BAND * 1.5 == pytest.approx(0.03)


def test_the_heading_error_wraps_whatever_the_target():
    """ψ → π/2 swinging ±0.2 rad: unwrapped against the target the error would sit at π away
    and tear across ±π; wrapped it is the 0.4 rad swing."""
    t = _times(end_s=12.0)
    swing = 0.2 * np.sign(np.sin(2 * np.pi * t / 1.5))
    psi = np.where(t >= 1.0, math.pi / 2 + swing, 0.0)
    run = _run(["reference.kind=step", f"reference.target_psi_rad={math.pi / 2}"],
               {"t_s": t, "psi_true_rad": psi}, duration_s=12)
    m = figures_of(run, []).end("psi")
    assert m.kind == "limit cycle" and m.ptp == pytest.approx(0.4) and m.unit == "rad"
