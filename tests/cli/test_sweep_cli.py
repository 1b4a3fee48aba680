"""``ardrone-nmpc sweep`` through typer's CliRunner: local (in-process and pool) and Dask."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from ardrone_nmpc.cli.app import app
from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.runs.summary import read_summary
from ardrone_nmpc.experiments.sweep import read_sweep

runner = CliRunner()
CONFIG = str(Path(__file__).resolve().parents[2] / "configs" / "step_x.yaml")
GRID = ["--grid", "controller.horizon_steps=8,12", "--grid", "controller.dtau_s=0.1"]
SHORT = ["--set", "duration_s=3", "--set", "sim.settle_s=0.5",
         "--set", "reference.target_m=[-0.3, 0, 1]"]
COLUMNS = ["case", "controller.horizon_steps", "controller.dtau_s", "rmse_m", "settling_s",
           "overshoot_pct", "path_deviation_m", "solve_mean_us", "solve_p99_us", "fallbacks",
           "status", "message", "run_dir"]
# Simulated flight is deterministic; solve times are measured wall time and are not.
DETERMINISTIC = [c for c in COLUMNS if c not in ("solve_mean_us", "solve_p99_us")]


def _sweep(out, *extra):
    return runner.invoke(app, ["sweep", CONFIG, *GRID, *SHORT, "-o", str(out), *extra])


def _summary_value(rows, axis, metric):
    (value,) = [r.value for r in rows if (r.axis, r.metric) == (axis, metric)]
    return value


def _same(a: str, b: float) -> bool:
    return (math.isnan(float(a)) and math.isnan(b)) or float(a) == pytest.approx(b, rel=1e-12)


def _check_against_run_dirs(out: Path) -> list[dict[str, str]]:
    """Every sweep.csv row agrees with its run directory's summary.csv and log.csv."""
    rows = read_sweep(out / "sweep.csv").rows
    assert list(rows[0]) == COLUMNS
    for row in rows:
        run_dir = out / row["run_dir"]
        summary = read_summary(run_dir)
        run = read_run(run_dir)
        assert run.config.controller.horizon_steps == int(row["controller.horizon_steps"])
        assert _same(row["settling_s"], _summary_value(summary, "x", "settling_time"))
        assert _same(row["overshoot_pct"], _summary_value(summary, "x", "overshoot"))
        assert _same(row["solve_p99_us"], _summary_value(summary, "solver", "solve_time_p99"))
        assert _same(row["fallbacks"], _summary_value(summary, "loop", "fallbacks"))
        assert row["path_deviation_m"] == "nan"  # a step is not a path experiment
        c = run.columns
        window = c["t_s"] >= 0
        err = np.column_stack([c["x_true_m"] - c["x_ref_m"], c["y_true_m"] - c["y_ref_m"],
                               c["z_true_m"] - c["z_ref_m"]])[window]
        assert _same(row["rmse_m"], float(np.sqrt(np.mean(np.sum(err ** 2, axis=1)))))
        assert row["status"] in ("ok", "unstable")
    return rows


def test_sweep_in_process_writes_runs_csv_and_ranked_table(tmp_path):
    result = _sweep(tmp_path, "--jobs", "1")
    assert result.exit_code == 0, result.output
    rows = _check_against_run_dirs(tmp_path)
    assert [r["controller.horizon_steps"] for r in rows] == ["8", "12"]
    assert {r["controller.dtau_s"] for r in rows} == {"0.1"}
    assert len({r["case"] for r in rows}) == 2
    assert "horizon_steps" in result.stdout and "rmse_m" in result.stdout
    assert "2 cases: 2 flown, 0 resumed" in result.stdout
    assert result.stdout.strip().splitlines()[-1] == f"sweep: {tmp_path / 'sweep.csv'}"
    assert not (tmp_path / ".partial").exists()


def test_sweep_resumes_without_flying_again(tmp_path):
    assert _sweep(tmp_path, "--jobs", "1").exit_code == 0
    before = (tmp_path / "sweep.csv").read_text()
    mtimes = {p: p.stat().st_mtime_ns for p in tmp_path.glob("*/log.csv")}
    result = _sweep(tmp_path, "--jobs", "1")
    assert result.exit_code == 0, result.output
    assert "2 cases: 0 flown, 2 resumed" in result.stdout
    assert {p: p.stat().st_mtime_ns for p in tmp_path.glob("*/log.csv")} == mtimes
    assert (tmp_path / "sweep.csv").read_text() == before


@pytest.mark.timeout(300)
def test_sweep_on_a_process_pool_gives_the_in_process_results(tmp_path):
    assert _sweep(tmp_path / "one", "--jobs", "1").exit_code == 0
    result = _sweep(tmp_path / "two", "--jobs", "2")
    assert result.exit_code == 0, result.output
    rows = _check_against_run_dirs(tmp_path / "two")
    expected = read_sweep(tmp_path / "one" / "sweep.csv").rows
    assert [{c: r[c] for c in DETERMINISTIC} for r in rows] == [
        {c: r[c] for c in DETERMINISTIC} for r in expected]


@pytest.mark.timeout(300)
def test_sweep_on_a_dask_cluster_gives_the_local_results(tmp_path):
    from dask.distributed import LocalCluster

    assert _sweep(tmp_path / "local", "--jobs", "1").exit_code == 0
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                      host="127.0.0.1", dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        result = _sweep(tmp_path / "dask", "--engine", "dask", "--scheduler",
                        cluster.scheduler_address)
    assert result.exit_code == 0, result.output
    assert "(dask, " in result.stdout
    rows = _check_against_run_dirs(tmp_path / "dask")
    expected = read_sweep(tmp_path / "local" / "sweep.csv").rows
    assert [{c: r[c] for c in DETERMINISTIC} for r in rows] == [
        {c: r[c] for c in DETERMINISTIC} for r in expected]


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_sweep_on_the_default_dask_local_cluster(tmp_path):
    result = _sweep(tmp_path, "--engine", "dask", "--jobs", "1")
    assert result.exit_code == 0, result.output
    assert "2 cases: 2 flown" in result.stdout
    _check_against_run_dirs(tmp_path)


@pytest.mark.parametrize("args, message", [
    (["--grid", "controller.horizon_steps"], "error: --grid 'controller.horizon_steps': "
                                             "expected dotted.path=v1,v2,…"),
    (["--grid", "controller.r=[1,2,3,4"], "error: --grid controller.r: unclosed bracket"),
    (["--grid", "controller.horizn_steps=5,6"], "error: controller.horizn_steps: "),
    (["--grid", "controller.horizon_steps=0"], "error: controller.horizon_steps: "),
    (["--grid", "controller.dtau_s=0.1", "--set", "duration_s=-1"], "error: duration_s: "),
    (["--grid", "controller.dtau_s=0.1", "--scheduler", "tcp://127.0.0.1:1"],
     "error: --scheduler: only with --engine dask"),
    ([], "error: --grid: give at least one"),
])
def test_bad_input_is_one_error_line_and_nothing_runs(tmp_path, args, message):
    out = tmp_path / "sweep"
    result = runner.invoke(app, ["sweep", CONFIG, "-o", str(out), *args])
    assert result.exit_code == 1
    assert message in result.output
    assert "Traceback" not in result.output
    assert not out.exists()


@pytest.mark.parametrize("args, message", [
    (["--engine", "ray"], "error: --engine: unknown 'ray'; choose local, dask"),
    (["--rank-by", "speed"], "error: --rank-by: unknown 'speed'; choose rmse, settling, "),
])
def test_a_bad_choice_is_a_command_line_error(tmp_path, args, message):
    out = tmp_path / "sweep"
    result = runner.invoke(app, ["sweep", CONFIG, "-o", str(out),
                                 "--grid", "controller.dtau_s=0.1", *args])
    assert result.exit_code == 2
    assert result.output.startswith(message) and len(result.output.splitlines()) == 1
    assert not out.exists()


def test_a_missing_config_file_is_an_error_line(tmp_path):
    result = runner.invoke(app, ["sweep", str(tmp_path / "nope.yaml"),
                                 "--grid", "controller.dtau_s=0.1", "-o", str(tmp_path / "s")])
    assert result.exit_code == 1
    assert "no such file" in result.output and "Traceback" not in result.output


@pytest.mark.timeout(120)
def test_an_unreachable_scheduler_is_an_error_line(tmp_path):
    import socket

    with socket.socket() as s:  # a free loopback port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    result = _sweep(tmp_path, "--engine", "dask", "--scheduler", f"tcp://127.0.0.1:{port}")
    assert result.exit_code == 1
    assert "error: --engine dask: " in result.output
    assert "Traceback" not in result.output


def test_failed_cases_make_the_exit_code_1(tmp_path, monkeypatch):
    import ardrone_nmpc.runtime.lockstep

    def explode(cfg, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(ardrone_nmpc.runtime.lockstep, "run_lockstep", explode)
    result = _sweep(tmp_path, "--jobs", "1")
    assert result.exit_code == 1
    assert "error: 2 of 2 cases failed" in result.output
    rows = read_sweep(tmp_path / "sweep.csv").rows
    assert [(r["status"], r["message"]) for r in rows] == [("failed", "RuntimeError: boom")] * 2


def test_table_headers_are_the_shortest_distinct_path_tails():
    from ardrone_nmpc.cli.sweep import short_labels

    assert short_labels(["controller.horizon_steps", "controller.dtau_s"]) == [
        "horizon_steps", "dtau_s"]
    assert short_labels(["controller.solver.kmax", "estimator.kind", "duration_s"]) == [
        "kmax", "kind", "duration_s"]
    assert short_labels(["a.x.q", "b.x.q"]) == ["a.x.q", "b.x.q"]
    assert short_labels(["controller.q", "sim.plant.q"]) == ["controller.q", "plant.q"]


# ----------------------------------------------------------------------------- kill -9


def _children() -> dict[int, list[tuple[int, str]]]:
    """parent pid → [(pid, start time in clock ticks)] of every process (Linux /proc)."""
    kids: dict[int, list[tuple[int, str]]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:  # ended meanwhile
                continue
            fields = stat[stat.rindex(")") + 2:].split()
            kids.setdefault(int(fields[1]), []).append((int(entry.name), fields[19]))
    return kids


def _family(pid: int) -> list[tuple[int, str]]:
    kids, found, todo = _children(), [], [pid]
    while todo:
        for child in kids.get(todo.pop(), []):
            found.append(child)
            todo.append(child[0])
    return found


def _alive(process: tuple[int, str]) -> bool:
    """Still running (not a zombie), and the same process (its start time): pids recycle."""
    try:
        stat = Path(f"/proc/{process[0]}/stat").read_text()
    except OSError:
        return False
    fields = stat[stat.rindex(")") + 2:].split()
    return fields[0] != "Z" and fields[19] == process[1]


def _wait_until(done, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


def test_the_processes_of_a_killed_sweep_end_with_it(tmp_path):
    """SIGKILL of the sweep's process (nothing of it runs any more): its pool workers, the
    forkserver (started early by the entry point, cli/launch.py) and the resource tracker
    must end too, not fly their cases on for minutes."""
    out = tmp_path / "killed"
    sweep = subprocess.Popen(
        [sys.executable, "-m", "ardrone_nmpc.cli.launch", "sweep", CONFIG, "--grid",
         "controller.horizon_steps=8,9,10", "--set", "duration_s=3000", "--jobs", "2",
         "-o", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    family: list[tuple[int, str]] = []
    try:
        partial = out / ".partial"
        _wait_until(lambda: partial.is_dir() and len(list(partial.iterdir())) == 2, 180,
                    "two cases never started flying")
        family = _family(sweep.pid)
        assert len(family) >= 3  # the forkserver and two workers (and a resource tracker)
        sweep.kill()
        sweep.wait(timeout=30)
        _wait_until(lambda: not any(_alive(p) for p in family), 30,
                    f"still running 30 s after the sweep was killed: "
                    f"{[p for p in family if _alive(p)]}")
    finally:
        for pid, _ in [p for p in family if _alive(p)] + [(sweep.pid, "")]:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        sweep.wait(timeout=30)
