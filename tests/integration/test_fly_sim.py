"""`fly --sim` end to end: the real loop over UDP on 127.0.0.1 against the loopback drone.

Subprocesses with timeouts; only loopback addresses are ever used.
"""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.runs.rundir import read_run
from ardrone_nmpc.runtime.schedule import Schedule

FLY = [sys.executable, "-m", "ardrone_nmpc.cli.app", "fly", "configs/hover.yaml", "--sim",
       "--no-dashboard"]


def _events(run_dir):
    return [json.loads(line) for line in (Path(run_dir) / "events.jsonl").read_text().splitlines()]


def _run_line(text):
    lines = [l for l in text.splitlines() if l.startswith("run: ")]
    assert lines, text
    return lines[-1][len("run: "):]


@pytest.mark.timeout(120)
def test_fly_sim_flies_and_lands(tmp_path):
    proc = subprocess.run([*FLY, "--log-dir", str(tmp_path), "--duration-s", "3",
                           "--set", "sim.settle_s=1"], capture_output=True, text=True,
                          timeout=110, cwd=Path(__file__).parents[2])
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1].startswith("run: ")
    run = read_run(_run_line(proc.stdout))
    events = _events(run.path)
    kinds = [e["kind"] for e in events]
    assert kinds.index("takeoff") < kinds.index("landed")
    overruns = [e["overruns"] for e in events if e["kind"] == "loop_timing"]
    assert len(overruns) == 1
    # the schedule's ticks and no more: every row at a tick time of the schedule, none past
    # t = 3 s; a deadline the loaded machine skipped is counted, not made up for
    schedule = Schedule.of(settle_s=1.0, duration_s=3.0, period_s=0.065)
    t = run.columns["t_s"]
    ticks = [schedule.t_exp_s(k) for k in range(schedule.n_ticks)]
    assert set(t.tolist()) <= set(ticks) and np.all(np.diff(t) > 0)
    assert run.n_rows + overruns[0] <= schedule.n_ticks and run.n_rows >= 55
    assert t[-1] >= ticks[-1] - 0.065 * overruns[0]
    # settle and track — or a hold where the pose was older than the hold's age (a late
    # datagram on a loaded machine: the supervisor's to hold, not a fault of the flight)
    modes, age_ms = run.columns["mode"], run.columns["mocap_age_ms"]
    held = modes == "hold-stale-mocap"
    assert set(modes[~held]) <= {"settle", "track"}
    assert np.all(age_ms[held] > run.config.safety.mocap_hold_ms) and held.mean() < 0.1
    z = run.columns["z_m"][t > 0]
    assert abs(z.mean() - 1.0) < 0.3  # hovering near the reference over UDP
    _assert_one_clock(run, tmp_path)


def _assert_one_clock(run, tmp_path):
    """events.jsonl's t_s is the rows' experiment time: the take-off before the first row
    (negative, as the settle rows), the landing at the last; the wall time apart; and the
    MCAP export places each event at its t_s on the rows' time line."""
    from ardrone_nmpc.experiments.export import read_mcap, write_mcap

    raw = {e["kind"]: e for e in reversed(_events(run.path))}  # the first of each kind
    t = run.columns["t_s"]
    assert raw["takeoff"]["t_s"] <= t[0] < 0
    assert 0.0 <= raw["landing"]["t_s"] - t[-1] <= 2.0
    assert raw["landed"]["t_s"] >= raw["landing"]["t_s"]
    assert all(isinstance(e["wall_s"], float) for e in raw.values())
    assert raw["landing"]["wall_s"] - raw["takeoff"]["wall_s"] == pytest.approx(
        raw["landing"]["t_s"] - raw["takeoff"]["t_s"], abs=1e-6)
    write_mcap(run, tmp_path / "run.mcap")
    mcap = read_mcap(tmp_path / "run.mcap")
    rows_ns = mcap.row_log_times_ns
    for event, t_ns in zip(mcap.events, mcap.event_log_times_ns):
        expected_ns = rows_ns[0] + (event["t_s"] - t[0]) * 1e9
        assert abs(t_ns - expected_ns) < 1e3, event     # on the rows' time line
        if t[0] <= event["t_s"] <= t[-1]:
            assert rows_ns[0] <= t_ns <= rows_ns[-1], event


@pytest.mark.timeout(120)
@pytest.mark.parametrize("sig, code, rows", [
    (signal.SIGINT, 130, 20), (signal.SIGTERM, 143, 20),
    (signal.SIGHUP, 129, 4.0 / 0.065),      # the terminal closed 4 s into the experiment
    (signal.SIGQUIT, 131, 20), (signal.SIGUSR1, 138, 20), (signal.SIGUSR2, 140, 20),
    (signal.SIGPIPE, 141, 20)])
def test_every_terminating_signal_lands_and_exits_with_its_code(tmp_path, sig, code, rows):
    proc = subprocess.Popen([*FLY, "--log-dir", str(tmp_path), "--duration-s", "60",
                             "--set", "sim.settle_s=0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=Path(__file__).parents[2])
    try:
        deadline = time.monotonic() + 60
        run_dir = None
        while time.monotonic() < deadline:  # wait until it is flying the loop
            dirs = list(Path(tmp_path).glob("*-hover"))
            if dirs and (dirs[0] / "log.csv").exists() and \
                    len((dirs[0] / "log.csv").read_text().splitlines()) > rows:
                run_dir = dirs[0]
                break
            time.sleep(0.1)
        assert run_dir is not None, "the flight never started"
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=40)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == code, err
    kinds = [e["kind"] for e in _events(run_dir)]
    assert "landed" in kinds, kinds
    landing = [e for e in _events(run_dir) if e["kind"] == "landing"]
    assert landing[0]["reason"] == sig.name  # SIGHUP lands with reason SIGHUP
    if sig == signal.SIGUSR2:   # the operator's `emergency`: the cut is held, not a landing
        assert any(e["kind"] == "emergency" for e in _events(run_dir))
    assert "Traceback" not in err
    assert _run_line(out) == str(run_dir)
    read_run(run_dir)  # complete and readable
    assert (run_dir / "summary.csv").read_text().startswith("axis,metric,value,unit")


def _wait_for_rows(run_glob, n_rows, timeout_s=60):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        dirs = list(run_glob())
        if dirs and (dirs[0] / "log.csv").exists() and \
                len((dirs[0] / "log.csv").read_bytes().splitlines()) > n_rows:
            return dirs[0]
        time.sleep(0.1)
    return None


@pytest.mark.timeout(120)
def test_sigkill_mid_flight_leaves_a_readable_run(tmp_path):
    """No landing is possible after SIGKILL (the drone's own watchdog hovers it); what the
    tool owes is its log: config.yaml from before take-off, log.csv readable, at most the
    row being written lost."""
    from ardrone_nmpc.config.io import load_config

    proc = subprocess.Popen([*FLY, "--log-dir", str(tmp_path), "--duration-s", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=Path(__file__).parents[2])
    try:
        run_dir = _wait_for_rows(lambda: Path(tmp_path).glob("*-hover"), 30)
        assert run_dir is not None, "the flight never started"
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == -signal.SIGKILL
    cfg = load_config(run_dir / "config.yaml")
    assert cfg.name == "hover" and cfg.duration_s == 60
    lines = (run_dir / "log.csv").read_bytes().splitlines(keepends=True)
    run = read_run(run_dir)
    complete = sum(1 for line in lines[1:] if line.endswith(b"\n"))
    assert run.n_rows == complete >= 30  # every finished row, at most a torn last one lost
    assert len(lines) - 1 - complete <= 1
    assert "takeoff" in [e["kind"] for e in _events(run_dir)]


@pytest.mark.timeout(120)
def test_fly_sim_follows_the_streamed_car(tmp_path):
    """The loopback mocap stream carries the scripted car; the link tracks it; the tick
    follows it — the same path as lockstep, over UDP."""
    proc = subprocess.run([sys.executable, "-m", "ardrone_nmpc.cli.app", "fly",
                           "configs/follow_car.yaml", "--sim", "--no-dashboard", "--log-dir",
                           str(tmp_path), "--duration-s", "6", "--set", "sim.settle_s=2"],
                          capture_output=True, text=True, timeout=110,
                          cwd=Path(__file__).parents[2])
    assert proc.returncode == 0, proc.stderr
    run = read_run(_run_line(proc.stdout))
    c = run.columns
    seen = np.isfinite(c["target_x_m"])
    assert seen.mean() > 0.9
    # the reference is the car plus 1 m up (the car moves on a 1 m circle at 0.3 m/s) — on
    # the ticks that have one: a tick whose own pose went stale holds (a loaded machine's
    # late datagram), with the car seen and no reference
    ref = seen & np.isfinite(c["z_ref_m"])
    assert ref.sum() > 0.9 * seen.sum()
    assert all(m.startswith("hold") for m in c["mode"][seen & ~ref]), set(c["mode"][seen & ~ref])
    np.testing.assert_allclose(c["z_ref_m"][ref], c["target_z_m"][ref] + 1.0, atol=1e-9)
    radius = np.hypot(c["target_x_m"][seen], c["target_y_m"][seen])
    np.testing.assert_allclose(radius, 1.0, atol=0.01)
    late = c["t_s"] > 2
    gap = np.hypot(c["x_m"][late] - c["target_x_m"][late], c["y_m"][late] - c["target_y_m"][late])
    assert np.median(gap) < 0.25
