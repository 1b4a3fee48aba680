"""Mutation testing, one module at a time (docs/testing.md): ``python tests/mutation.py MODULE``.

mutmut reads one ``[tool.mutmut]`` table, which pyproject.toml keeps for the safety modules.
For any other target this copies the tree to a scratch directory, writes that table with the
target's files and its narrow test selection there, and runs ``mutmut run --max-children 1``
in it (2 shared cores: one child); the counts are printed per file. ``pip install mutmut`` —
it is not a test dependency.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: target → (files mutated, tests run against them). The tests are the ones that exercise the
#: module directly: every mutant runs only the tests mutmut saw calling its function.
TARGETS: dict[str, tuple[list[str], list[str]]] = {
    "disturbance": (["estimation/disturbance.py"], ["tests/unit/test_disturbance.py"]),
    "plant_kit": (["sim/plant_kit.py"],
                  ["tests/unit/test_plant_profiles.py", "tests/unit/test_kit_closed_loop.py",
                   "tests/unit/test_plant_disturbances.py"]),
    "config_text": (["protocol/config_text.py"], ["tests/unit/test_protocol_config_text.py"]),
    # the sources' own tests, the UDP link's socket tests (receiver thread, 127.0.0.1) and the
    # one follow test that reads the link; not the flights that merely use a source (each
    # mutant would fly for 2–45 s, and a cold first flight compiles for minutes)
    "mocap": (["links/mocap_source.py", "links/mocap_link.py", "links/motioncapture_source.py",
               "links/mocap_factory.py"],
              ["tests/unit/test_mocap_sources.py", "tests/unit/test_mocap_senders.py",
               "tests/unit/test_motioncapture_child_lines.py",
               "tests/integration/test_mocap_receiver.py",
               "tests/unit/test_follow.py::test_mocap_link_tracks_a_second_object",
               *(f"tests/integration/test_links.py::test_mocap_{name}" for name in (
                   "latest_pose_converted_and_stamped", "age_grows_when_object_disappears",
                   "all_zero_pose_ignored", "repeated_identical_pose_stops_being_fresh",
                   "frame_gaps_reordering_and_malformed")),
               "tests/integration/test_hostile_datagrams.py::"
               "test_mocap_link_counts_garbage_and_keeps_the_latest_good_pose"]),
    "schedule": (["runtime/schedule.py"],
                 ["tests/unit/test_schedule.py", "tests/unit/test_realtime_schedule.py"]),
    "judges": (["experiments/reproduce/judges.py"],
               ["tests/unit/test_reproduce.py", "tests/unit/test_judges.py"]),
    "xchannel": (["experiments/xchannel.py"],
                 ["tests/unit/test_xchannel.py", "tests/unit/test_xchannel_loops.py"]),
    "drone_config": (["links/drone_config.py"],
                     ["tests/unit/test_drone_config.py", "tests/unit/test_drone_config_verify.py",
                      "tests/integration/test_drone_config_standin.py",
                      "tests/integration/test_links.py",
                      "tests/integration/test_backend_conformance.py"]),
    "tune": (["experiments/tune/objective.py", "experiments/tune/space.py"],
             ["tests/unit/test_tune.py", "tests/unit/test_tune_objective.py",
              "tests/unit/test_tune_space.py"]),
    "export": (["experiments/export.py"],
               ["tests/unit/test_export.py", "tests/unit/test_export_edges.py",
                "tests/unit/test_export_limits.py"]),
    # the operator commands run in-process (typer's CliRunner) against the SDK stand-in; the
    # alarms file holds the operator's `emergency` against a running `fly` (issue 21)
    "operator": (["cli/operator.py"],
                 ["tests/integration/test_operator_standin.py",
                  "tests/integration/test_alarms_standin.py",
                  "tests/integration/test_fly_standin.py", "tests/cli/test_hostile_args.py"]),
}

@dataclass(frozen=True)
class HandMutant:
    """A bug a developer writes: ``old`` (once in ``path``) replaced by ``new``; the suite
    must fail on it — ``tests`` are the test files expected to catch it."""

    name: str
    path: str
    old: str
    new: str
    tests: tuple[str, ...]


_DIST = ("tests/unit/test_disturbance.py",)
_KIT = ("tests/unit/test_plant_profiles.py", "tests/unit/test_kit_closed_loop.py",
        "tests/unit/test_plant_disturbances.py")
_AIR = ("tests/unit/test_plant.py", "tests/unit/test_plant_disturbances.py")
_OFFSET = ("tests/integration/test_offset_free.py::test_constant_disturbances_leave_at_most_3_cm",)
_MOCAP = ("tests/unit/test_mocap_sources.py", "tests/unit/test_follow.py",
          "tests/unit/test_mocap_senders.py")
_LOOP = ("tests/unit/test_schedule.py", "tests/unit/test_realtime_schedule.py")
_JUDGES = ("tests/unit/test_reproduce.py",)
_EXPORT = ("tests/unit/test_export.py", "tests/unit/test_export_edges.py",
           "tests/unit/test_export_limits.py")
_TUNE = ("tests/unit/test_tune.py", "tests/unit/test_tune_objective.py",
         "tests/unit/test_tune_space.py")
_CONFIG = ("tests/unit/test_drone_config_verify.py",)

#: The hand-mutation audit's survivors (issue 25) and their neighbours: each must be killed.
HAND_MUTANTS: tuple[HandMutant, ...] = (
    HandMutant("disturbance: integral never clamped (windup)", "estimation/disturbance.py",
               "carry[_INTEGRAL, k] = _clip(carry[_INTEGRAL, k] - ki * ek * period, lim)",
               "carry[_INTEGRAL, k] = carry[_INTEGRAL, k] - ki * ek * period", _DIST),
    HandMutant("disturbance: release check without abs", "estimation/disturbance.py",
               "abs(rate[k]) > release:", "rate[k] > release:", _DIST),
    HandMutant("disturbance: ẏ taken from ẋ", "estimation/disturbance.py",
               "_VEL = (IX_VX, IX_VY, IX_VZ)", "_VEL = (IX_VX, IX_VX, IX_VZ)", _DIST),
    HandMutant("disturbance: ψ rate per tick, not per second", "estimation/disturbance.py",
               "rate[3] = wrap_half_turn(e[3] - psi[0], math.pi) / period",
               "rate[3] = wrap_half_turn(e[3] - psi[0], math.pi)", _DIST),
    HandMutant("kit: heading rotation sign", "sim/plant_kit.py",
               "    s = math.sin(psi)\n", "    s = math.sin(-psi)\n", _KIT),
    HandMutant("kit: lateral wind sign", "sim/plant_kit.py",
               "w_v = s * w[0] - c * w[1]", "w_v = s * w[0] + c * w[1]", _KIT),
    HandMutant("kit: hold damping on v dropped", "sim/plant_kit.py",
               "out[9] -= hold_v * v", "pass", _KIT),
    HandMutant("kit: battery sag ignored", "sim/plant_kit.py",
               "gaz = float(gaz) * self.params.vertical_gain(self._battery)",
               "gaz = float(gaz)", _KIT),
    HandMutant("airframe: vertical wind dropped", "sim/airframe.py",
               "out[5] = gaz * vz_gain - vz * inv_tau_vz + kd * w[2]",
               "out[5] = gaz * vz_gain - vz * inv_tau_vz", (*_AIR, *_OFFSET)),
    HandMutant("airframe: heading rotation sign", "sim/airframe.py",
               "    s = math.sin(psi)\n", "    s = math.sin(-psi)\n", _AIR),
    HandMutant("airframe: lateral wind sign", "sim/airframe.py",
               "kd * (vy - w[1])", "kd * (vy + w[1])", _AIR),
    HandMutant("airframe: hold damping on v dropped", "sim/airframe.py",
               "ay -= hold_damping * vy", "pass", _AIR),
    HandMutant("airframe: battery sag ignored", "sim/plant_params.py",
               "if self.battery_sag_frac == 0.0:\n            return k",
               "if True:\n            return k", _AIR),
    HandMutant("drone_config: held-limit tolerance 10 %", "links/drone_config.py",
               "_REL_TOLERANCE = 1e-3", "_REL_TOLERANCE = 0.1", _CONFIG),
    HandMutant("drone_config: held-limit tolerance 50 %", "links/drone_config.py",
               "_REL_TOLERANCE = 1e-3", "_REL_TOLERANCE = 0.5", _CONFIG),
    HandMutant("drone_config: tolerance on the written value only", "links/drone_config.py",
               "max(abs(a), abs(b), 1e-9)", "max(abs(a), 1e-9)", _CONFIG),
    HandMutant("config_text: a value holding '=' cut at its last '='",
               "protocol/config_text.py", 'line.partition("=")', 'line.rpartition("=")',
               ("tests/unit/test_protocol_config_text.py",)),
    HandMutant("mocap: followed object accepted without .fresh", "links/mocap_source.py",
               "if other is not None and other.fresh:", "if other is not None:", _MOCAP),
    HandMutant("real-time loop: one extra tick", "runtime/realtime.py",
               "if k >= schedule.n_ticks:", "if k > schedule.n_ticks:", _LOOP),
    HandMutant("real-time loop: fault clock started at settle start", "runtime/realtime.py",
               "t0 = now + schedule.settle_span_s", "t0 = now", _LOOP),
    HandMutant("lockstep: one extra tick", "runtime/lockstep.py",
               "for k in range(schedule.n_ticks):", "for k in range(schedule.n_ticks + 1):",
               _LOOP),
    HandMutant("export: the MCAP origin's sign", "experiments/export.py",
               "return _created_ns(run) - round(min(first, 0.0) * 1e9)",
               "return _created_ns(run) + round(min(first, 0.0) * 1e9)", _EXPORT),
    HandMutant("export: an event's time ignored", "experiments/export.py",
               "float(t) if isinstance(t, (int, float)) else math.nan,", "math.nan,", _EXPORT),
    HandMutant("export: an older run's event t_exp_s ignored", "runs/run_reading.py",
               "t_s = float(t_exp) if isinstance(t_exp, (int, float)) else wall - offset",
               "t_s = wall - offset", _EXPORT),
    HandMutant("export: the yaw quaternion's sign", "runs/channels.py",
               "psi if math.isfinite(psi) else 0.0", "-psi if math.isfinite(psi) else 0.0",
               _EXPORT),
    HandMutant("export: /reference from the measured positions", "runs/channels.py",
               '("x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad")',
               '("x_m", "y_m", "z_m", "psi_ref_rad")', _EXPORT),
    HandMutant("export: navdata pitch's sign", "runs/channels.py",
               "roll, pitch = math.radians(nav_roll), -math.radians(nav_pitch)",
               "roll, pitch = math.radians(nav_roll), math.radians(nav_pitch)", _EXPORT),
    HandMutant("tune: a non-finite term scores 0", "experiments/tune/objective.py",
               '(value if math.isfinite(value) else self.weights["abort"])',
               "(value if math.isfinite(value) else 0.0)", _TUNE),
    HandMutant("tune: tracking always RMSE", "experiments/tune/objective.py",
               '"tracking_m": path_dev if not math.isnan(path_dev) else sweep["rmse_m"],',
               '"tracking_m": sweep["rmse_m"],', _TUNE),
    HandMutant("tune: the sampler ignores log (float)", "experiments/tune/study.py",
               "trial.suggest_float(name, p.low, p.high, log=p.log)",
               "trial.suggest_float(name, p.low, p.high, log=False)", _TUNE),
    HandMutant("tune: the sampler ignores log (int)", "experiments/tune/study.py",
               "int(math.floor(p.high)),\n                                             log=p.log)",
               "int(math.floor(p.high)),\n                                             log=False)",
               _TUNE),
    HandMutant("judges: swing threshold halved", "experiments/reproduce/judges.py",
               "swinging = ptp_tail > 2.0 * band", "swinging = ptp_tail > 1.0 * band", _JUDGES),
    HandMutant("judges: crossing hysteresis halved", "experiments/reproduce/judges.py",
               "h = 0.25 * float(np.ptp(e))", "h = 0.125 * float(np.ptp(e))", _JUDGES),
    HandMutant("judges: ψ wrap dropped", "experiments/reproduce/judges.py",
               "e = np.asarray(wrap_angle_rad(e), float)", "e = np.asarray(e, float)", _JUDGES),
    HandMutant("judges: an empty solver status counted as bad",
               "experiments/reproduce/judges.py",
               'bad = float(np.mean([s not in ("", "ok") for s in status]))',
               'bad = float(np.mean([s != "ok" for s in status]))', _JUDGES),
    HandMutant("judges: the ended-early check dropped", "experiments/reproduce/judges.py",
               "ended = not np.any(window) or float(np.nanmax(t)) < cfg.duration_s - 1.0",
               "ended = not np.any(window)", _JUDGES),
)


def _mutmut_table(files: list[str], tests: list[str]) -> str:
    only = ", ".join(json.dumps(f"*ardrone_nmpc/{f}") for f in files)
    sel = ", ".join(json.dumps(t) for t in tests)
    return ("[tool.mutmut]\n"
            'source_paths = ["ardrone_nmpc"]\n'
            f"only_mutate = [{only}]\n"
            'also_copy = ["configs/", "trajectories/", "docs/", "README.md"]\n'
            # no per-test limit: the first run compiles the numba kernels in mutants/ (minutes
            # under load); a mutant that hangs is mutmut's own timeout
            'pytest_add_cli_args = ["-p", "no:cacheprovider", "-p", "tests.mutmut_plugin", '
            '"--timeout=0"]\n'
            f"pytest_add_cli_args_test_selection = [{sel}]\n")


def _with_table(pyproject: str, table: str) -> str:
    """pyproject.toml with its [tool.mutmut] table replaced by ``table``."""
    start = pyproject.index("[tool.mutmut]")
    nxt = re.search(r"^\[", pyproject[start + 1:], flags=re.M)
    end = len(pyproject) if nxt is None else start + 1 + nxt.start()
    return pyproject[:start] + table + pyproject[end:]


def _copy_tree(dest: Path) -> None:
    """The tree into ``dest``, over an earlier copy: files keep their times, so the numba
    caches there stay valid (a recompile under load can time a test out)."""
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "mutants", ".git",
                                    ".hypothesis", ".pytest_cache", "*.nbi", "*.nbc")
    dest.mkdir(parents=True, exist_ok=True)
    for item in ROOT.iterdir():
        if item.name in {".git", "mutants", "logs"} or item.name.endswith(".egg-info"):
            continue
        if item.is_dir():
            shutil.copytree(item, dest / item.name, ignore=ignore, dirs_exist_ok=True)
        else:
            shutil.copy2(item, dest / item.name)
    (dest / "logs").mkdir(exist_ok=True)


def counts(workdir: Path) -> dict[str, Counter]:
    """Outcome counts per mutated file, from mutmut's ``.meta`` files."""
    from mutmut.stats import status_by_exit_code

    out: dict[str, Counter] = {}
    for meta in sorted((workdir / "mutants").rglob("*.py.meta")):
        data = json.loads(meta.read_text())
        rel = str(meta.relative_to(workdir / "mutants")).removesuffix(".meta")
        c = out.setdefault(rel, Counter())
        for code in data.get("exit_code_by_key", {}).values():
            c[status_by_exit_code[code]] += 1
    return out


def run_hand(workdir: Path, only: str | None) -> int:
    """Apply each hand mutant in a copy of the tree, run its tests; 0 if all are killed."""
    _copy_tree(workdir)
    env = {**os.environ, "PYTHONPATH": str(workdir)}
    pytest = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider"]
    mutants = [m for m in HAND_MUTANTS if not only or only in m.name]
    # the unmutated tree first: every selection passes (and the numba caches are warm, so a
    # compile under load cannot time a test out and pass for a kill)
    for tests in dict.fromkeys(m.tests for m in mutants):
        res = subprocess.run([*pytest, "--timeout=0", *tests], cwd=workdir, env=env,
                             capture_output=True, text=True)
        if res.returncode != 0:
            print(f"the unmutated tree fails {' '.join(tests)}:\n{res.stdout[-2000:]}")
            return 2
    survivors = 0
    for m in mutants:
        src = workdir / "ardrone_nmpc" / m.path
        text = src.read_text()
        if text.count(m.old) != 1:
            print(f"STALE  {m.name}: the original text is not in {m.path} exactly once")
            survivors += 1
            continue
        stamp = src.stat()
        src.write_text(text.replace(m.old, m.new))
        try:
            res = subprocess.run([*pytest, *m.tests], cwd=workdir, env=env,
                                 capture_output=True, text=True)
        finally:
            src.write_text(text)
            os.utime(src, ns=(stamp.st_atime_ns, stamp.st_mtime_ns))  # its cache is valid
        failed = [ln.split(" - ")[0] for ln in res.stdout.splitlines()
                  if ln.startswith(("FAILED", "ERROR"))]
        timed_out = "Timeout" in res.stdout  # a compile under load is no kill
        killed = res.returncode == 1 and failed and not timed_out
        survivors += not killed
        verdict = "killed" if killed else ("TIMEOUT" if timed_out else "SURVIVED")
        print(f"{verdict}  {m.name}"
              + (f"  ({failed[0].split(' ', 1)[1]})" if killed else f"  (exit {res.returncode})"),
              flush=True)
    return 1 if survivors else 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("target", choices=[*sorted(TARGETS), "hand"],
                   help="a module to run mutmut on, or 'hand': the hand mutants")
    p.add_argument("--workdir", type=Path, default=None,
                   help="scratch directory (default /tmp/mutmut-TARGET); reused when it exists")
    p.add_argument("--fresh", action="store_true", help="discard earlier results in the workdir")
    p.add_argument("--only", default=None, help="hand: the mutants whose name contains this")
    p.add_argument("--survivors", action="store_true", help="print each survivor's diff")
    p.add_argument("--rerun", action="store_true",
                   help="keep the workdir's results and re-run only its survivors (and the "
                        "mutants it did not check) against the tree as it is now")
    p.add_argument("--also", action="append", default=[], metavar="PATTERN",
                   help="with --rerun: mutants matching this too (e.g. 'MODULE.x_FUNC__mutmut_*' "
                        "for a function changed since)")
    args = p.parse_args(argv)
    if args.rerun and args.fresh:
        p.error("--rerun keeps the earlier results: not with --fresh")
    workdir = args.workdir or Path(f"/tmp/mutmut-{args.target}")
    if args.fresh:
        shutil.rmtree(workdir, ignore_errors=True)
    if args.target == "hand":
        return run_hand(workdir, args.only)
    files, tests = TARGETS[args.target]
    _copy_tree(workdir)
    pyproject = workdir / "pyproject.toml"
    pyproject.write_text(_with_table(pyproject.read_text(), _mutmut_table(files, tests)))
    mutmut = [sys.executable, "-m", "mutmut"]
    names: list[str] = []
    if args.rerun:  # the earlier run's survivors (and what it did not check) against new tests
        res = subprocess.run([*mutmut, "results", "--all", "true"], cwd=workdir,
                             capture_output=True, text=True)
        names = re.findall(r"^\s*(\S+): (?:survived|not checked|no tests)", res.stdout,
                           flags=re.M)
        names += args.also  # functions whose source changed since: all their mutants
        if not names:
            print("nothing to re-run")
    with open(workdir / "mutmut-run.log", "a" if args.rerun else "w") as log:
        if names or not args.rerun:
            subprocess.run([*mutmut, "run", "--max-children", "1", *names], cwd=workdir,
                           check=False, stdout=log, stderr=subprocess.STDOUT)
    total = Counter()
    for rel, c in counts(workdir).items():
        total += c
        killed = c["killed"] + c["timeout"]
        n = sum(c.values())
        print(f"{rel}: {n} mutants, {killed} killed ({c['timeout']} by timeout), "
              f"{c['survived']} survived, score {100.0 * killed / max(n, 1):.1f} %"
              + "".join(f", {v} {k}" for k, v in c.items()
                        if k not in {"killed", "timeout", "survived"}))
    if args.survivors:
        res = subprocess.run([*mutmut, "results"], cwd=workdir, capture_output=True, text=True)
        for name in re.findall(r"^\s*(\S+): survived", res.stdout, flags=re.M):
            diff = subprocess.run([*mutmut, "show", name], cwd=workdir, capture_output=True,
                                  text=True).stdout
            print(f"== {name}")
            print("\n".join(ln for ln in diff.splitlines()
                            if ln[:1] in "+-" and ln[:3] not in ("+++", "---")))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
