"""The thesis-claim judges of `reproduce` on hand-made figures, and the end-of-run classifier
on closed-form signals (a full run is the staleness test's job: test_reproduce_stale.py)."""

import math
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.experiments.reproduce import (Motion, Outcome, RunFigures, Verdict,
                                                classify_motion, claims, render_markdown)
from ardrone_nmpc.experiments.reproduce.judges import swing_period_s
from ardrone_nmpc.experiments.reproduce.report import run_name

T = np.arange(0.0, 20.0, 0.065)
BAND = 0.03  # 2 % of a 1.5 m step


def fig(metrics=None, motion=None, input_peak=0.5, bad_solves=0.0):
    return RunFigures(metrics or {}, motion or {}, bad_solves, input_peak, Path("run"))


def settled(axis, settling_s, overshoot_pct):
    return fig({(axis, "settling_time"): settling_s, (axis, "overshoot"): overshoot_pct},
               {axis: Motion("settled")})


def cycling(axis="x", overshoot_pct=25.0):
    return fig({(axis, "settling_time"): math.nan, (axis, "overshoot"): overshoot_pct},
               {axis: Motion("limit cycle", 0.5, 2.0)})


CLAIMS = {c.experiment: c for c in claims()}


# ----------------------------------------------------------------------------- classifier


@pytest.mark.parametrize("period_s, amp", [(2.1, 0.3), (1.3, 0.05), (3.7, 1.0)])
def test_limit_cycle_period_and_peak_to_peak_of_a_sinusoid(period_s, amp):
    rng = np.random.default_rng(1)
    e = amp * np.sin(2 * np.pi * T / period_s) + rng.normal(0, 0.05 * amp, T.size)
    m = classify_motion(T, e, t_step_s=1.0, band=BAND * amp / 0.3, settled=False)
    assert m.kind == "limit cycle" and m.unstable
    assert m.period_s == pytest.approx(period_s, rel=0.03)
    assert m.ptp == pytest.approx(2 * amp, rel=0.15)


def test_growing_oscillation_diverges_and_decaying_one_converges():
    grow = 0.05 * np.exp(0.15 * T) * np.sin(2 * np.pi * T / 2.0)
    assert classify_motion(T, grow, t_step_s=1.0, band=BAND, settled=False).kind == "diverging"
    decay = 0.5 * np.exp(-0.2 * T) * np.sin(2 * np.pi * T / 2.0)
    m = classify_motion(T, decay, t_step_s=1.0, band=BAND, settled=False)
    assert m.kind == "converging" and not m.unstable


def test_offset_without_swing_is_unsettled_and_the_summary_verdict_wins():
    offset = 0.1 + 0.002 * np.sin(T)
    assert classify_motion(T, offset, t_step_s=1.0, band=BAND, settled=False).kind == "unsettled"
    assert classify_motion(T, offset, t_step_s=1.0, band=BAND, settled=True).kind == "settled"
    assert classify_motion(T, offset, t_step_s=1.0, band=BAND, settled=True,
                           ended_early=True).kind == "ended early"


@pytest.mark.parametrize("ptp_bands, kind", [(0.4, "unsettled"), (1.5, "unsettled"),
                                             (2.5, "limit cycle")])
def test_a_swing_is_a_limit_cycle_only_beyond_twice_the_band(ptp_bands, kind):
    """A steady swing counts once its peak-to-peak leaves the band on both sides (> 2 band)."""
    swing = 0.5 * ptp_bands * BAND * np.sin(2 * np.pi * T / 2.0)
    assert classify_motion(T, swing, t_step_s=1.0, band=BAND, settled=False).kind == kind


def test_a_growing_swing_inside_twice_the_band_is_not_diverging():
    grow = 0.5 * 1.5 * BAND * np.exp(0.1 * (T - T[-1])) * np.sin(2 * np.pi * T / 2.0)
    assert classify_motion(T, grow, t_step_s=1.0, band=BAND, settled=False).kind != "diverging"


def test_square_wave_period_and_no_period_without_a_swing():
    """Hysteresis: crossings count only past a quarter of the swing, both ways."""
    square = np.where((T // 1.5) % 2 == 0, 1.0, -1.0)
    period, periods = swing_period_s(T, square)
    assert period == pytest.approx(3.0, abs=0.07) and periods >= 5
    assert math.isnan(swing_period_s(T, np.zeros_like(T))[0])
    rng = np.random.default_rng(2)
    drift = np.linspace(0.0, 1.0, T.size) + rng.normal(0, 0.01, T.size)
    assert math.isnan(swing_period_s(T, drift)[0])  # one crossing of its mean: no swing


def test_excursions_inside_a_quarter_of_the_swing_are_no_crossings():
    """A ±1 square wave of period 3 s with a blip to ∓0.35 in each half (inside the ±0.5
    hysteresis, a quarter of its 2 peak-to-peak): still period 3 s."""
    square = np.where((T // 1.5) % 2 == 0, 1.0, -1.0)
    middle = (T % 1.5 > 0.7) & (T % 1.5 < 0.8)
    blipped = np.where(middle, -0.35 * square, square)
    assert np.ptp(blipped) == 2.0
    period, periods = swing_period_s(T, blipped)
    assert period == pytest.approx(3.0, abs=0.07)
    assert periods == swing_period_s(T, square)[1]


# ----------------------------------------------------------------------------- judges


def holds(verdict) -> bool:
    assert verdict.holds is (not verdict.failed)
    return verdict.holds


def test_every_thesis_row_has_a_claim_with_existing_configs_and_its_plant():
    assert len(CLAIMS) == 12
    for claim in CLAIMS.values():
        for config, _ in claim.runs.values():
            assert (Path("configs") / config).is_file(), config
    experimental = {c.experiment for c in CLAIMS.values() if c.setting == "experiment"}
    assert experimental == {"square path", "square, altitude per corner (KF)"}
    assert {c.plants for c in CLAIMS.values()} == {("thesis_kit", "ardrone"),
                                                   ("ardrone_lab", "ardrone")}


@pytest.mark.parametrize("overshoot, end, ok", [
    (60.0, "settled", True), (60.0, "converging", True), (30.0, "settled", False),
    (60.0, "limit cycle", False), (60.0, "unsettled", False)])
def test_no_estimate_claim_needs_overshoot_above_45_and_convergence(overshoot, end, ok):
    judge = CLAIMS["NMPC altitude, no ż estimate"].judge
    v = judge({"nmpc": fig({("z", "overshoot"): overshoot,
                            ("z", "settling_time"): math.nan}, {"z": Motion(end, 0.4)})})
    assert holds(v) is ok and f"{overshoot:.0f} %" in v.text


def test_step_claims_compare_settling_times_with_the_thesis_within_40_percent():
    z = CLAIMS["z: take-off to 1 m"].judge  # thesis: P 2 s, NMPC 5 s
    assert holds(z({"nmpc": settled("z", 5.0, 0.0), "p": settled("z", 2.0, 0.0)}))
    assert holds(z({"nmpc": settled("z", 6.9, 0.0), "p": settled("z", 1.3, 0.0)}))
    slow = z({"nmpc": settled("z", 8.9, 0.0), "p": settled("z", 2.0, 0.0)})
    assert not holds(slow) and slow.failed == ("NMPC settles in 8.9 s, not 5 s ± 40%",)
    fast = z({"nmpc": settled("z", 5.0, 0.0), "p": settled("z", 1.1, 0.0)})  # too fast fails
    assert not holds(fast) and "P settles in 1.1 s" in fast.failed[0]
    never = fig({("z", "settling_time"): math.nan, ("z", "overshoot"): 30.0},
                {"z": Motion("converging", 0.05)})
    v = z({"nmpc": never, "p": settled("z", 2.0, 0.0)})
    assert not holds(v) and "NMPC does not settle (converging (0.05 m p-p))" in v.failed


@pytest.mark.parametrize("axis, thesis_s", [("x", 4.0), ("psi", 5.0)])
def test_without_overshoot_means_settled_inside_the_band(axis, thesis_s):
    judge = CLAIMS["x: 0 → −1.5 m" if axis == "x" else "ψ: 0 → 1 rad"].judge
    p = settled(axis, 4.0 if axis == "x" else 2.5, 1.0)
    assert holds(judge({"nmpc": settled(axis, thesis_s, 1.5), "p": p}))
    v = judge({"nmpc": settled(axis, thesis_s, 3.0), "p": p})
    assert not holds(v) and v.failed == ("NMPC overshoots 3.0 % (≥ 2 %)",)
    assert not holds(judge({"nmpc": cycling(axis, 0.0), "p": p}))


def test_y_claim_needs_both_near_the_thesis_and_less_nmpc_overshoot():
    judge = CLAIMS["y: 1 m step"].judge  # thesis: P 4.5 s, NMPC 5.5 s
    assert holds(judge({"nmpc": settled("y", 5.5, 0.1), "p": settled("y", 4.5, 1.2)}))
    more = judge({"nmpc": settled("y", 5.5, 2.0), "p": settled("y", 4.5, 1.2)})
    assert more.failed == ("NMPC overshoots 2.0 %, more than P's 1.2 %",)
    assert not holds(judge({"nmpc": cycling("y", 0.0), "p": settled("y", 4.5, 1.2)}))


def test_estimator_claim_needs_both_to_settle_alike_without_overshoot():
    judge = CLAIMS["NMPC altitude with KF / Luenberger"].judge
    assert holds(judge({"kalman": settled("z", 8.9, 0.0), "luenberger": settled("z", 8.9, 0.0)}))
    assert not holds(judge({"kalman": settled("z", 8.9, 0.0),
                            "luenberger": cycling("z", 0.0)}))
    unlike = judge({"kalman": settled("z", 4.0, 0.0), "luenberger": settled("z", 8.9, 0.0)})
    assert not holds(unlike) and "not alike" in unlike.failed[0]


def test_stability_claim_needs_a_limit_cycle_or_divergence_against_a_settled_run():
    judge = CLAIMS["N = 5 vs 6 at Δτ = 0.3"].judge
    stable = settled("x", 3.0, 0.5)
    assert holds(judge({"N=5": cycling(), "N=6": stable}))
    diverging = fig({("x", "settling_time"): math.nan}, {"x": Motion("diverging", 2.0)})
    assert holds(judge({"N=5": diverging, "N=6": stable}))
    assert not holds(judge({"N=5": stable, "N=6": stable}))
    assert not holds(judge({"N=5": cycling(), "N=6": cycling()}))
    converging = fig({("x", "settling_time"): math.nan}, {"x": Motion("converging", 0.1)})
    assert not holds(judge({"N=5": converging, "N=6": stable}))  # not unstable
    text = judge({"N=5": cycling(), "N=6": stable}).text
    assert "limit cycle 0.50 m p-p, period 2.0 s" in text


def test_a_claim_fails_when_the_supervisor_flew_any_experiment_tick():
    """A settled run whose settling the supervisor's hover produced is not the controller's."""
    judge = CLAIMS["ψ: 0 → 1 rad"].judge
    nmpc, p = settled("psi", 5.0, 0.0), settled("psi", 2.5, 0.0)
    assert holds(judge({"nmpc": nmpc, "p": p}))
    nmpc.supervised, nmpc.ticks = {"hover-tilt": 1}, 232
    v = judge({"nmpc": nmpc, "p": p})
    assert v.failed == ("nmpc: the supervisor flew 1 of 232 experiment ticks (hover-tilt 1)",)
    nmpc.supervised = {}
    p.ended_early = True
    assert judge({"nmpc": nmpc, "p": p}).failed == ("p: ended early",)


def test_many_failed_solves_make_a_run_unstable():
    assert fig(bad_solves=0.2).unstable and not fig(bad_solves=0.05).unstable


def _case(rise, over, settles=True):
    return fig({("x", "rise_time"): rise, ("x", "overshoot"): over,
                ("x", "settling_time"): 3.0 if settles else math.nan},
               {"x": Motion("settled" if settles else "limit cycle", 0.1, 2.0)})


def test_r_cases_need_rise_gaps_of_a_tick_case_2_clean_and_case_3_a_small_overshoot():
    judge = CLAIMS["r Case 1 / 2 / 3"].judge
    assert holds(judge({"case1": _case(1.3, 0.1), "case2": _case(1.2, 0.1),
                        "case3": _case(0.9, 4.0)}))
    one_tick_short = judge({"case1": _case(1.3, 0.1), "case2": _case(1.25, 0.1),
                            "case3": _case(0.9, 4.0)})  # 50 ms: inside one 65 ms tick
    assert one_tick_short.failed == ("Case 1 rises 50 ms after Case 2 (≥ one 65 ms tick "
                                     "needed)",)
    assert not holds(judge({"case1": _case(1.0, 0.1), "case2": _case(1.2, 0.1),
                            "case3": _case(0.9, 4.0)}))
    assert not holds(judge({"case1": _case(1.3, 0.1), "case2": _case(1.2, 3.0),
                            "case3": _case(0.9, 4.0)}))  # Case 2 overshoots: not tuned
    big = judge({"case1": _case(1.3, 0.1), "case2": _case(1.2, 0.1), "case3": _case(0.9, 20)})
    assert "not a small overshoot" in big.failed[0]
    clean = judge({"case1": _case(1.3, 0.1), "case2": _case(1.2, 0.1), "case3": _case(0.9, 0.5)})
    assert not holds(clean)  # "with a small overshoot": none is not one
    cycling3 = judge({"case1": _case(1.3, 0.1), "case2": _case(1.2, 0.1),
                      "case3": _case(0.9, 4.0, settles=False)})
    assert "Case 3 does not settle" in cycling3.failed[0]


def _inputs(nmpc: dict, p: dict, worst: float | None = None) -> dict:
    runs = {}
    for axis in ("x", "y", "z", "psi"):
        runs[f"nmpc_{axis}"] = fig(input_peak=nmpc[axis] if worst is None else worst)
        runs[f"nmpc_{axis}"].input_peaks = {axis: nmpc[axis]}
        runs[f"p_{axis}"] = fig(input_peak=p[axis])
        runs[f"p_{axis}"].input_peaks = {axis: p[axis]}
    return runs


def test_inputs_claim_can_fail_both_ways_axis_by_axis():
    claim = CLAIMS["NMPC inputs vs P"]
    assert {c for c, _ in claim.runs.values()} == {"step_x.yaml", "step_y.yaml", "step_z.yaml",
                                                   "step_psi.yaml"}
    nmpc = {"x": 0.3, "y": 0.3, "z": 0.2, "psi": 0.4}
    assert holds(claim.judge(_inputs(nmpc, {"x": 0.75, "y": 0.6, "z": 0.7, "psi": 1.5})))
    # P not twice the NMPC's on y: the NMPC asked for as much tilt as P did
    v = claim.judge(_inputs(nmpc, {"x": 0.75, "y": 0.4, "z": 0.7, "psi": 1.5}))
    assert v.failed == ("y: P's peak 0.40 is 1.33× the NMPC's 0.30 (< 2×)",)
    # an NMPC input beyond ±1 on a run fails though P's are far larger
    v = claim.judge(_inputs(nmpc, {"x": 3.0, "y": 3.0, "z": 3.0, "psi": 3.0}, worst=1.2))
    assert len(v.failed) == 4 and "NMPC's input reaches 1.200" in v.failed[0]


@pytest.mark.parametrize("deviation_m, ok", [(0.1045, True), (0.075, True), (0.135, True),
                                             (0.008, False), (0.22, False)])
def test_path_claims_are_two_sided_within_30_percent(deviation_m, ok):
    judge = CLAIMS["square path"].judge
    v = judge({"nmpc": fig({("path", "mean_deviation"): deviation_m})})
    assert holds(v) is ok


# ----------------------------------------------------------------------------- figures_of


def _synthetic_run(cfg_overrides, cols, duration_s=10.0, period_s=0.065):
    from types import SimpleNamespace

    from ardrone_nmpc.config.io import load_config
    cfg = load_config(None, [f"duration_s={duration_s}", *cfg_overrides])
    n = len(cols["t_s"])
    base = {"solver_status": np.array(["ok"] * n, dtype=object),
            "mode": np.array(["track"] * n, dtype=object),
            "navdata_age_ms": np.full(n, 30.0)}
    for c in ("x_true_m", "y_true_m", "z_true_m", "psi_true_rad", "u_phi_rad", "u_theta_rad",
              "u_psirate_radps", "u_zacc_mps2", "vz_ref_mps"):
        base[c] = np.zeros(n)
    base.update(cols)
    return SimpleNamespace(config=cfg, columns=base, path=Path("/runs/20260101-000000-synthetic"))


@pytest.mark.parametrize("decay_per_s, kind", [(0.2, "converging"), (0.0, "limit cycle")])
def test_figures_of_wraps_the_heading_error_across_pi(decay_per_s, kind):
    """ψ steps to 3.1 rad and swings across ±π to the end of the run (0.3 rad, decaying or
    not): the error is the wrapped one — a swing of 0.6 rad p-p, not 2π jumps."""
    from ardrone_nmpc.core.angles import wrap_angle_rad
    from ardrone_nmpc.experiments.reproduce.judges import figures_of

    t = np.arange(-1.0, 10.0, 0.065)
    swing = 0.3 * np.exp(-decay_per_s * np.clip(t - 1.0, 0, None)) * np.sin(2 * np.pi * t / 1.5)
    psi = np.asarray(wrap_angle_rad(3.1 + np.where(t >= 1.0, swing, -3.1)), float)
    assert np.ptp(psi[t >= 7.0]) > 6.0  # the truth jumps across ±π in the last third
    run = _synthetic_run(["reference.kind=step", "reference.target_psi_rad=3.1"],
                         {"t_s": t, "psi_true_rad": psi, "z_true_m": np.ones_like(t)})
    f = figures_of(run, [])
    m = f.end("psi")
    assert m.kind == kind and m.unit == "rad"
    assert m.ptp == pytest.approx(np.ptp(swing[t >= 7.0]), rel=0.05)
    if kind == "limit cycle":
        assert m.period_s == pytest.approx(1.5, rel=0.05) and f.unstable
    else:
        assert not f.unstable
    assert f.supervised == {} and not f.ended_early and f.ticks == int(np.sum(t >= 0))


@pytest.mark.parametrize("statuses", [
    ["", "ok"],                      # the P controller logs no solver status
    ["ok"] * 7 + ["maxiter"] * 3,
    ["", "nan", "", "ok"],
])
def test_figures_of_counts_failed_solves_of_the_experiment_ticks(statuses):
    from ardrone_nmpc.experiments.reproduce.judges import BAD_SOLVES, figures_of

    t = np.arange(-1.0, 10.0, 0.065)
    status = np.array([statuses[k % len(statuses)] for k in range(t.size)], dtype=object)
    status[t < 0] = "maxiter"  # the settle phase is not judged
    run = _synthetic_run(["reference.kind=hover"], {"t_s": t, "solver_status": status})
    f = figures_of(run, [])
    failed = [s in ("maxiter", "nan") for s in status[t >= 0]]
    assert f.bad_solves == pytest.approx(sum(failed) / len(failed), abs=1e-12)
    assert f.unstable is (f.bad_solves > BAD_SOLVES)


def test_figures_of_counts_the_supervisors_experiment_ticks_not_the_settle_phase():
    from ardrone_nmpc.experiments.reproduce.judges import figures_of

    t = np.arange(-2.0, 10.0, 0.065)
    mode = np.where(t < 0, "settle", "track").astype(object)
    mode[(t > 3.0) & (t < 3.5)] = "hover-tilt"
    mode[(t > 6.0) & (t < 6.2)] = "fallback-solver"
    run = _synthetic_run(["reference.kind=hover"], {"t_s": t, "mode": mode,
                                                    "u_theta_rad": 0.4 * np.sin(t),
                                                    "u_phi_rad": np.full_like(t, -0.7),
                                                    "navdata_age_ms": np.full_like(t, 40.0)})
    f = figures_of(run, [])
    assert f.supervised == {"hover-tilt": int(np.sum((t > 3.0) & (t < 3.5))),
                            "fallback-solver": int(np.sum((t > 6.0) & (t < 6.2)))}
    assert f.supervised_ticks == 11 and f.ticks == int(np.sum(t >= 0))
    assert f.input_peaks["y"] == pytest.approx(0.7) and f.input_peaks["x"] < 0.41
    assert f.input_peak == pytest.approx(0.7) and f.navdata_age_s == pytest.approx(0.04)


def test_figures_of_marks_a_run_that_ended_early():
    from ardrone_nmpc.experiments.reproduce.judges import figures_of

    t = np.arange(-1.0, 6.0, 0.065)  # a 20 s experiment that stopped after 6 s
    x = np.where(t >= 1.0, -1.5, 0.0)
    run = _synthetic_run(["reference.kind=step", "reference.target_m=[-1.5,0,1]"],
                         {"t_s": t, "x_true_m": x, "z_true_m": np.ones_like(t)}, duration_s=20)
    f = figures_of(run, [])
    assert f.ended_early and f.end("x").kind == "ended early" and f.unstable
    v = CLAIMS["x: 0 → −1.5 m"].judge({"nmpc": f, "p": settled("x", 4.0, 0.0)})
    assert "nmpc: ended early" in v.failed


# ----------------------------------------------------------------------------- report


def _outcomes(thesis_holds: bool):
    outcomes = []
    for claim in claims():
        o = Outcome(claim)
        for plant in claim.plants:
            o.verdicts[(plant, "thesis")] = Verdict("a | b", () if thesis_holds else ("bad",))
            o.verdicts[(plant, "ours")] = Verdict("c")
            o.runs[(plant, "thesis")] = {}
            o.runs[(plant, "ours")] = {}
        outcomes.append(o)
    return outcomes


def test_markdown_tables_have_one_row_per_claim_and_no_broken_cells():
    outcomes = _outcomes(thesis_holds=False)
    text = render_markdown(outcomes)
    for header in ("| experiment | thesis | judged on |", "| experiment | thesis formulation |"):
        table = text.split(header)[1].split("\n\n")[0]
        rows = [line for line in (header + table).splitlines()
                if line.startswith("| ") and "---" not in line]
        assert len(rows) == 1 + len(outcomes)
        # a bare "|" inside a cell would shift the columns: cells escape it as "\\|"
        separators = [row.replace("\\|", "").count("|") for row in rows]
        assert separators == [separators[0]] * len(rows)
    assert "a \\| b" in text
    assert "* thesis formulation: 0 of 10 simulation claims on `thesis_kit` and 0 of 2 experimental" in text
    assert "* delay-compensated: 10 of 10 simulation claims on `thesis_kit` and 2 of 2 experimental" in text
    # every ✘ of the thesis formulation on a claim's own plant lists its failures and its why
    why = [line for line in text.splitlines() if line.startswith("* **") and "*Why:*" in line]
    assert len(why) == sum(1 for c in claims() if c.note)


def test_run_names_drop_the_time_stamp():
    assert run_name(Path("/x/20261123-193338-step_x-p-thesis_kit-thesis")) == \
        "step_x-p-thesis_kit-thesis"
    assert run_name(Path("step_x-ours")) == "step_x-ours"
