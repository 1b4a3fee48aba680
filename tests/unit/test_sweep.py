"""ardrone_nmpc.experiments.sweep: grid parsing, cases and their ids, status and metrics, resume."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.experiments import sweep
from ardrone_nmpc.config.schema import ConfigError, config_from_dict
from ardrone_nmpc.runs.rundir import RunRecorder, read_run
from ardrone_nmpc.runs.summary import summarise
from ardrone_nmpc.experiments import record
from ardrone_nmpc.experiments.sweep import (CaseResult, build_cases, case_id, case_metrics,
                                            classify, parse_grid, rank_rows, read_sweep,
                                            resume_results, run_case, split_values,
                                            sweep_columns, sweep_row, write_sweep_csv)

STEP_X = Path(__file__).resolve().parents[2] / "configs" / "step_x.yaml"
SHORT = ["duration_s=1.0", "sim.settle_s=0.2", "reference.target_m=[-0.3, 0, 1]"]


# ----------------------------------------------------------------------------- grid syntax


@pytest.mark.parametrize("text, items", [
    ("5,6,10", ["5", "6", "10"]),
    (" 0.08 , 0.1 ", ["0.08", "0.1"]),
    ("[4,12,12,24],[1,12,12,24]", ["[4,12,12,24]", "[1,12,12,24]"]),
    ("[-1.5, 0, 1], [-0.5, 0, 1]", ["[-1.5, 0, 1]", "[-0.5, 0, 1]"]),
    ("'a,b',c", ["'a,b'", "c"]),
    ("{k: [1, 2]},x", ["{k: [1, 2]}", "x"]),
])
def test_split_values_splits_on_top_level_commas_only(text, items):
    assert split_values(text) == items


@pytest.mark.parametrize("text", ["[1,2", "1]", "'a,b", "[1,{2]"])
def test_split_values_rejects_unbalanced_text(text):
    with pytest.raises(ValueError, match="unbalanced|unclosed"):
        split_values(text)


def test_parse_grid_parses_values_like_set():
    h, r, k = parse_grid(["controller.horizon_steps=5,6", "controller.r=[4,12,12,24],[1,1,1,1]",
                          "estimator.kind=kalman,luenberger"])
    assert h.path == "controller.horizon_steps" and h.values == (5, 6)
    assert all(type(v) is int for v in h.values)
    assert r.values == ([4, 12, 12, 24], [1, 1, 1, 1])
    assert r.texts == ("[4,12,12,24]", "[1,1,1,1]")
    assert k.values == ("kalman", "luenberger")


@pytest.mark.parametrize("specs, message", [
    ([], r"--grid: give at least one"),
    (["controller.horizon_steps"], r"--grid 'controller.horizon_steps': expected dotted.path="),
    (["=5,6"], r"expected dotted.path=v1,v2"),
    (["controller..dtau_s=0.1"], r"expected dotted.path=v1,v2"),
    (["controller.dtau_s=0.1,,0.3"], r"--grid controller.dtau_s: empty value"),
    (["controller.dtau_s="], r"--grid controller.dtau_s: empty value"),
    (["controller.r=[1,2,3,4"], r"--grid controller.r: unclosed bracket"),
    (["controller.dtau_s=0.1,{a: 1"], r"--grid controller.dtau_s: unclosed bracket"),
    (["controller.dtau_s=0.1,0.10"], r"--grid controller.dtau_s: value '0.10' given twice"),
    (["controller.dtau_s=0.1", "controller.dtau_s=0.3"], r"--grid controller.dtau_s: swept twice"),
    (["name=a: b: c"], r"--grid name: value 'a: b: c' is not valid YAML"),
])
def test_parse_grid_errors_name_the_option(specs, message):
    with pytest.raises(ConfigError, match=message):
        parse_grid(specs)


def test_parse_grid_reports_every_bad_spec():
    with pytest.raises(ConfigError) as info:
        parse_grid(["a.b", "controller.dtau_s=", "controller.kmax=1,1"])
    assert len(info.value.messages) == 3


# ----------------------------------------------------------------------------- cases


def _cases(*grid, overrides=()):
    return build_cases(config_path=STEP_X, overrides=[*SHORT, *overrides], grid=parse_grid(grid))


def test_build_cases_is_the_cartesian_product_first_grid_slowest():
    cases = _cases("controller.horizon_steps=5,10", "controller.dtau_s=0.1,0.2,0.3")
    got = [(c.config.controller.horizon_steps, c.config.controller.dtau_s) for c in cases]
    assert got == [(5, 0.1), (5, 0.2), (5, 0.3), (10, 0.1), (10, 0.2), (10, 0.3)]
    assert [c.index for c in cases] == list(range(6))
    assert cases[4].params == (("controller.horizon_steps", "10"), ("controller.dtau_s", "0.2"))
    assert all(c.config.duration_s == 1.0 for c in cases)  # --set applies to every case


def test_grid_values_win_over_set_and_vectors_apply():
    (case,) = _cases("controller.r=[1,2,3,4]", overrides=["controller.r=[9,9,9,9]"])
    assert case.config.controller.r == (1, 2, 3, 4)
    assert case.params == (("controller.r", "[1,2,3,4]"),)


def test_a_typo_fails_before_anything_runs_with_the_field_path():
    with pytest.raises(ConfigError) as info:
        _cases("controller.horizn_steps=5,6")
    (message,) = info.value.messages  # one line, not one per case
    assert message.startswith("controller.horizn_steps: ")
    assert "(case controller.horizn_steps=5)" in message


def test_an_invalid_value_names_its_field_and_case():
    with pytest.raises(ConfigError, match=r"^controller\.horizon_steps: .*greater than or equal "
                                          r"to 1 \(case controller\.horizon_steps=0\)"):
        _cases("controller.horizon_steps=5,0")


def test_case_ids_are_stable_readable_and_distinct():
    first = _cases("controller.horizon_steps=5,10", "controller.r=[4,12,12,24],[1,1,1,1]")
    again = _cases("controller.horizon_steps=5,10", "controller.r=[4,12,12,24],[1,1,1,1]")
    ids = [c.case_id for c in first]
    assert ids == [c.case_id for c in again]
    assert len(set(ids)) == 4
    assert re.fullmatch(r"horizon_steps=5__r=4_12_12_24__[0-9a-f]{8}", ids[0]), ids[0]
    assert all(re.fullmatch(r"[A-Za-z0-9._+=-]+", i) for i in ids)


def test_case_id_changes_with_the_rest_of_the_config():
    (a,) = _cases("controller.horizon_steps=5")
    (b,) = _cases("controller.horizon_steps=5", overrides=["sim.seed=3"])
    assert a.case_id != b.case_id  # a stale result is never taken for another config
    assert a.case_id.split("__")[0] == b.case_id.split("__")[0]
    assert case_id(params=a.params, cfg=a.config) == a.case_id


# ----------------------------------------------------------------------------- synthetic runs


def _synthetic_run(tmp_path, *, offset=lambda t: np.zeros((t.size, 3)), mode=None,
                   reference=None, duration_s=4.0):
    """A run directory whose drone sits at the reference plus ``offset(t)`` (m)."""
    cfg = config_from_dict({"name": "syn", "duration_s": duration_s,
                            "reference": reference or {"kind": "hover"}})
    t = np.arange(-8, int(duration_s / 0.065) + 1) * 0.065
    ref = np.array([0.0, 0.0, 1.0])
    pos = ref + offset(t)
    with RunRecorder.create(tmp_path, cfg, seed=0) as rec:
        for k, tk in enumerate(t):
            row = {"t_s": tk, "x_ref_m": ref[0], "y_ref_m": ref[1], "z_ref_m": ref[2],
                   "psi_ref_rad": 0.0, "psi_rad": 0.0, "psi_true_rad": 0.0,
                   "solve_us": 10.0 + k % 7, "solver_status": "ok",
                   "mode": (mode(tk) if mode else None) or ("settle" if tk < 0 else "track")}
            for i, axis in enumerate("xyz"):
                row[f"{axis}_m"] = row[f"{axis}_true_m"] = pos[k, i]
            rec.write_row(row)
        run = read_run(rec.path)
        rows = summarise(run)
        rec.write_summary(rows)
    return run, rows


def test_a_run_on_the_reference_is_ok(tmp_path):
    run, rows = _synthetic_run(tmp_path)
    assert classify(run=run) == ("ok", "")
    m = case_metrics(run=run, rows=rows)
    assert m["rmse_m"] == 0.0 and m["fallbacks"] == 0
    assert math.isnan(m["settling_s"]) and math.isnan(m["path_deviation_m"])
    assert 10.0 <= m["solve_mean_us"] <= 16.0


def test_rmse_is_the_3d_distance_from_the_reference(tmp_path):
    run, rows = _synthetic_run(tmp_path, offset=lambda t: np.column_stack(
        [0.3 * np.ones_like(t), 0.4 * np.ones_like(t), np.zeros_like(t)]))
    m = case_metrics(run=run, rows=rows)
    assert m["rmse_m"] == pytest.approx(0.5)
    xyz = [r.value for r in rows if (r.axis, r.metric) == ("xyz", "rmse")]
    assert m["rmse_m"] == pytest.approx(xyz[0])  # the summary's own 3-D RMSE
    assert classify(run=run) == ("ok", "")  # 0.5 m is not above diverge_m


def test_a_large_error_late_in_the_run_is_unstable(tmp_path):
    run, _ = _synthetic_run(tmp_path, offset=lambda t: np.column_stack(
        [np.where(t > 3.5, 0.8, 0.0), np.zeros_like(t), np.zeros_like(t)]))
    status, message = classify(run=run)
    assert status == "unstable"
    assert "0.8 m from the reference in the last 25% (> 0.5 m)" in message
    assert classify(run=run, diverge_m=1.0) == ("ok", "")


def test_a_large_error_early_in_the_run_is_a_transient(tmp_path):
    run, _ = _synthetic_run(tmp_path, offset=lambda t: np.column_stack(
        [np.where(t < 1.0, 1.5, 0.0), np.zeros_like(t), np.zeros_like(t)]))
    assert classify(run=run) == ("ok", "")


def test_non_finite_positions_are_unstable(tmp_path):
    run, _ = _synthetic_run(tmp_path, offset=lambda t: np.column_stack(
        [np.where(t > 2.0, np.nan, 0.0), np.zeros_like(t), np.zeros_like(t)]))
    status, message = classify(run=run)
    assert status == "unstable" and "non-finite position" in message


def test_leaving_the_geofence_is_unstable(tmp_path):
    run, _ = _synthetic_run(tmp_path, offset=lambda t: np.column_stack(
        [np.where((t > 1.0) & (t < 1.2), 3.5, 0.0), np.zeros_like(t), np.zeros_like(t)]))
    status, message = classify(run=run)
    assert status == "unstable" and "left the geofence at t = 1.04 s" in message


@pytest.mark.parametrize("bad_mode", ["landing", "land-geofence", "emergency"])
def test_a_supervisor_landing_is_unstable(tmp_path, bad_mode):
    run, rows = _synthetic_run(tmp_path, mode=lambda t: bad_mode if t > 3.0 else None)
    status, message = classify(run=run)
    assert status == "unstable" and f"aborted (mode {bad_mode})" in message


def test_hover_fallbacks_are_counted_not_unstable(tmp_path):
    run, rows = _synthetic_run(tmp_path, mode=lambda t: "hover-stale-mocap"
                               if 1.0 < t < 1.2 else None)
    assert classify(run=run) == ("ok", "")
    assert case_metrics(run=run, rows=rows)["fallbacks"] == 3


def test_step_metrics_are_the_worst_stepped_axis(tmp_path):
    reference = {"kind": "step", "target_m": [0.0, 0.0, 1.5], "target_psi_rad": 0.0}

    def offset(t):  # z follows a first-order step to 1.5 m; the reference column stays 1
        z = np.where(t < 1.0, 0.0, 0.5 * (1 - np.exp(-(t - 1.0) / 0.4)))
        return np.column_stack([np.zeros_like(t), np.zeros_like(t), z])

    run, rows = _synthetic_run(tmp_path, reference=reference, offset=offset)
    m = case_metrics(run=run, rows=rows)
    settling = [r.value for r in rows if (r.axis, r.metric) == ("z", "settling_time")]
    assert m["settling_s"] == pytest.approx(settling[0]) and m["settling_s"] > 1.0
    assert m["overshoot_pct"] == 0.0


# ----------------------------------------------------------------------------- running, resume


def test_run_case_flies_into_a_complete_run_directory(tmp_path):
    (case,) = _cases("controller.horizon_steps=8")
    result = run_case(case, out_dir=tmp_path)
    run_dir = tmp_path / case.case_id
    assert result.status in ("ok", "unstable") and result.run_dir == case.case_id
    assert {"config.yaml", "log.csv", "events.jsonl", "summary.csv"} <= {
        p.name for p in run_dir.iterdir()}
    assert read_run(run_dir).config.controller.horizon_steps == 8
    assert not any((tmp_path / sweep.PARTIAL_DIR).iterdir())


def test_a_case_is_flown_as_its_staging_directory_and_renamed_into_place(tmp_path,
                                                                         monkeypatch):
    # one rename, no directory inside the staging one to empty and remove (an rmdir cost
    # ~1 ms a case on average on a disk mounted with discard)
    (case,) = _cases("controller.horizon_steps=8")
    staged = []

    def fly(cfg, log_dir, **kwargs):
        recording = inner(cfg, log_dir, **kwargs)
        staged.append((recording.path, sorted(p.name for p in recording.path.iterdir())))
        return recording

    inner = record.record_lockstep
    monkeypatch.setattr(record, "record_lockstep", fly)
    run_case(case, out_dir=tmp_path)
    ((path, names),) = staged
    assert path == tmp_path / sweep.PARTIAL_DIR / case.case_id
    assert {"config.yaml", "log.csv", "events.jsonl", "summary.csv"} <= set(names)
    assert sorted(p.name for p in (tmp_path / case.case_id).iterdir()) == names
    assert not path.exists()


def test_a_failing_case_is_a_result_and_is_kept_for_inspection(tmp_path, monkeypatch):
    import ardrone_nmpc.runtime.lockstep

    def explode(cfg, **kwargs):
        raise RuntimeError("plant exploded\non two lines")

    monkeypatch.setattr(ardrone_nmpc.runtime.lockstep, "run_lockstep", explode)
    (case,) = _cases("controller.horizon_steps=8")
    result = run_case(case, out_dir=tmp_path)
    assert result.status == "failed"
    assert result.message == "RuntimeError: plant exploded on two lines"
    assert all(math.isnan(v) for v in result.metrics.values())
    run_dir = tmp_path / case.case_id
    assert (run_dir / "events.jsonl").read_text().count('"exception"') == 1
    assert not (run_dir / "summary.csv").exists()  # not finished: flown again on resume
    assert resume_results([case], out_dir=tmp_path) == {}


class _CountingFly:
    def __init__(self):
        self.calls = 0
        self.inner = record.record_lockstep

    def __call__(self, cfg, log_dir, **kwargs):
        self.calls += 1
        return self.inner(cfg, log_dir, **kwargs)


def _sweep(cases, out_dir):
    """What the sweep command does with the results: resume, fly the rest, write the CSV."""
    results = resume_results(cases, out_dir=out_dir)
    pending = [c for c in cases if c.case_id not in results]
    for result in sweep.iter_local(pending, out_dir=out_dir, jobs=1):
        results[result.case_id] = result
    columns = sweep_columns([p for p, _ in cases[0].params])
    write_sweep_csv(out_dir / "sweep.csv", columns,
                    [sweep_row(c, results[c.case_id]) for c in cases])
    return results


def test_finished_cases_are_not_flown_again(tmp_path, monkeypatch):
    fly = _CountingFly()
    monkeypatch.setattr(record, "record_lockstep", fly)
    cases = _cases("controller.horizon_steps=8,9")
    first = _sweep(cases, tmp_path)
    assert fly.calls == 2 and not any(r.resumed for r in first.values())
    again = _sweep(cases, tmp_path)
    assert fly.calls == 2  # nothing flown
    assert all(r.resumed for r in again.values())
    for case in cases:
        a, b = first[case.case_id], again[case.case_id]
        assert (a.status, a.message, a.run_dir) == (b.status, b.message, b.run_dir)
        assert a.metrics["rmse_m"] == b.metrics["rmse_m"]  # shortest round-trip text


def test_resume_flies_only_unfinished_cases(tmp_path, monkeypatch):
    fly = _CountingFly()
    monkeypatch.setattr(record, "record_lockstep", fly)
    cases = _cases("controller.horizon_steps=8,9,10")
    _sweep(cases, tmp_path)
    (tmp_path / cases[1].case_id / "summary.csv").unlink()  # a case cut short
    (tmp_path / "sweep.csv").write_text("case,rmse_m\n")  # and a damaged sweep.csv
    results = _sweep(cases, tmp_path)
    assert fly.calls == 4
    assert [results[c.case_id].resumed for c in cases] == [True, False, True]
    rows = read_sweep(tmp_path / "sweep.csv").rows
    assert [r["case"] for r in rows] == [c.case_id for c in cases]


def test_resume_reads_the_run_directory_when_the_csv_row_is_torn(tmp_path, monkeypatch):
    cases = _cases("controller.horizon_steps=8")
    (done,) = _sweep(cases, tmp_path).values()
    text = (tmp_path / "sweep.csv").read_text()
    (tmp_path / "sweep.csv").write_text(text[: text.index(",ok,")])  # cut mid-row
    fly = _CountingFly()
    monkeypatch.setattr(record, "record_lockstep", fly)
    (again,) = resume_results(cases, out_dir=tmp_path).values()
    assert fly.calls == 0 and again.resumed
    assert again.metrics == pytest.approx(done.metrics, nan_ok=True)


# ----------------------------------------------------------------------------- csv, ranking


def test_sweep_columns_are_the_contract():
    assert sweep_columns(["controller.horizon_steps", "controller.dtau_s"]) == [
        "case", "controller.horizon_steps", "controller.dtau_s", "rmse_m", "settling_s",
        "overshoot_pct", "path_deviation_m", "solve_mean_us", "solve_p99_us", "fallbacks",
        "status", "message", "run_dir"]


def _row(case, status, rmse):
    return {"case": case, "status": status, "rmse_m": rmse}


def test_rank_rows_puts_ok_first_then_unstable_then_failed_nan_last():
    rows = [_row("a", "failed", "nan"), _row("b", "unstable", "0.1"), _row("c", "ok", "nan"),
            _row("d", "ok", "0.3"), _row("e", "ok", "0.2"), _row("f", "unstable", "0.05")]
    assert [r["case"] for r in rank_rows(rows, metric="rmse_m")] == ["e", "d", "c", "f", "b",
                                                                     "a"]


def test_sweep_row_writes_numbers_that_read_back_exactly(tmp_path):
    (case,) = _cases("controller.r=[4,12,12,24]")
    metrics = dict.fromkeys(sweep.METRIC_COLUMNS, math.nan)
    metrics.update(rmse_m=0.1 + 0.2, fallbacks=3)
    result = CaseResult(case.case_id, "unstable", "far, away", metrics, case.case_id)
    columns = sweep_columns(["controller.r"])
    write_sweep_csv(tmp_path / "sweep.csv", columns, [sweep_row(case, result)])
    (row,) = read_sweep(tmp_path / "sweep.csv").rows
    assert list(row) == columns
    assert float(row["rmse_m"]) == 0.1 + 0.2 and row["fallbacks"] == "3"
    assert row["settling_s"] == "nan" and row["message"] == "far, away"
    assert row["controller.r"] == "[4,12,12,24]"


def test_a_case_failing_after_its_summary_is_not_taken_as_finished(tmp_path, monkeypatch):
    def broken(**kwargs):
        raise ValueError("metrics bug")

    monkeypatch.setattr(sweep.cases, "case_metrics", broken)
    (case,) = _cases("controller.horizon_steps=8")
    result = run_case(case, out_dir=tmp_path)
    assert (result.status, result.message) == ("failed", "ValueError: metrics bug")
    assert (tmp_path / case.case_id / "log.csv").is_file()
    assert not (tmp_path / case.case_id / "summary.csv").exists()


def test_a_window_made_once_gives_the_same_metrics_and_status(tmp_path):
    from ardrone_nmpc.experiments.sweep.status import case_window

    run, rows = _synthetic_run(tmp_path, offset=lambda t: np.column_stack(
        [np.where(t > 3.5, 0.8, 0.0), np.zeros_like(t), np.zeros_like(t)]))
    window = case_window(run)
    assert classify(run=run, window=window) == classify(run=run)
    shared, alone = case_metrics(run=run, rows=rows, window=window), case_metrics(run=run,
                                                                                   rows=rows)
    assert shared.keys() == alone.keys()
    np.testing.assert_array_equal(list(shared.values()), list(alone.values()))


_WARM_CHECK = """
from ardrone_nmpc.experiments.sweep.cases import warm_up
from ardrone_nmpc.runs.path_kernels import polyline_distances_m
from ardrone_nmpc.core.kernel_cache import warmed
from ardrone_nmpc.runtime import tick_kernels
warm_up()
print(warmed(tick_kernels.estimate_step), warmed(tick_kernels.nmpc_inputs),
      len(polyline_distances_m.overloads))
"""


@pytest.mark.timeout(300)
def test_the_warm_up_loads_a_waypoint_flight_s_kernels_and_the_path_deviation_s():
    """The pool's preload (sweep warm_up): a square's kernels too — nmpc_inputs and the
    summary's path deviation — else every worker loaded them on its first such case."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _WARM_CHECK], capture_output=True,
                          text=True, timeout=240, check=True)
    assert done.stdout.split("\n")[-2] == "True True 1"
