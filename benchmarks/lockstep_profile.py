"""Where a lockstep tick's time goes, and the aggregate throughput of many flights.

``python benchmarks/lockstep_profile.py profile [--config configs/step_x.yaml] [--repeats 3]``
flies one config in lockstep with ``time.perf_counter_ns`` accumulators wrapped around the
stages (monkeypatched here, nothing in the package changes) and prints the cost per tick:

* plant — the simulated drone (the airframe, its firmware and sensors, which it alone
  calls): the lockstep drone's ``advance_to`` and ``set_command`` and its sensors'
  ``inputs`` (``LockstepSensors.inputs``: the loop calls it bound, not the drone's);
* estimator — ``Estimation.update``;
* solver — ``Control.solve`` (delay prediction, reference lookup, the NMPC);
* supervisor — the supervisor's checks and verdict bookkeeping, the command mapping
  (``Control.command``, ``Supervision.command``, ``DelayPrediction.push``);
* controller — the NMPC tick's compiled calls, which do the three above on the nominal tick
  (``ControlTick.answer``: the whole controller in one call, ``runtime/control_tick``, then
  the Python stages' state written from its answer — ``ControlTick.finish``, or
  ``Tick._nominal_cells`` for a row of cells; ``BeforeSolve.nominal``: the estimate and the
  solve, on the ticks it does not take): the three above count only the ticks the Python
  stages take;
* logging — building the row (``tick_row``, ``put_truth``; ``tick_cells``,
  ``nominal_cells`` — the nominal tick's, from the compiled call's answer — and the drone's
  ``truth_cells`` for a recorder of cells) and the recorder's ``write_row`` or
  ``write_cells``, for a run directory (``log.csv``) and for an in-memory recorder;
* rest — the runner's loop and everything not wrapped.

Each bucket has its calls' own time: a wrapped call's wrapped callees count in theirs (a
run directory's ``write_cells`` calls its ``write_row`` on some rows: counted once).
The wrappers add ~0.3 µs per wrapped call; the total is measured without them too.

``python benchmarks/lockstep_profile.py throughput [--jobs 2] [--rounds 2] [--flights
step_x|square]`` flies the same 24 configs (step_x, 20 s: horizon 10/15/20 × Δτ 0.08/0.1 ×
four r; ``square``: issue 26's 24 × 60 s squares, seeds 0–23) the sweep's way (run
directories, ``experiments/sweep`` ``iter_local``) and ``tune``'s way (in-memory recorder,
``experiments/parallel``'s pool), alternating, and prints simulated seconds per wall
second of each: the ratio holds on a loaded machine, the absolute figures do not.

``python benchmarks/lockstep_profile.py cpu --way sweep|tune [--rounds 3] [--flights …]``
flies the same 24 flights in this process and prints their CPU seconds
(``time.process_time``), which other load hardly changes: run ``--way sweep`` from another tree
(``PYTHONPATH=...``, from outside this tree: ``python -m`` and ``-c`` put the working
directory first on ``sys.path``) to compare commits.
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_NESTED = [0]  # ns spent in wrapped calls under the wrapped call running now


def _wrap(owner, name: str, bucket: str, acc: dict) -> None:
    """``owner.name`` timed into ``acc[bucket]``, less the time of the wrapped calls it makes
    (theirs go to their own buckets: a call nested in another is counted once)."""
    original = getattr(owner, name)

    def timed(*args, **kwargs):
        outer = _NESTED[0]
        _NESTED[0] = 0
        t0 = time.perf_counter_ns()
        try:
            return original(*args, **kwargs)
        finally:
            dt = time.perf_counter_ns() - t0
            acc[bucket] += dt - _NESTED[0]
            _NESTED[0] = outer + dt

    setattr(owner, name, timed)


def _instrument(acc: dict) -> None:
    from ardrone_nmpc import safety
    from ardrone_nmpc.runtime import (after_solve, before_solve, control_tick, lockstep, stages,
                                      tick)
    from ardrone_nmpc.sim.lockstep_drone import LockstepDrone
    from ardrone_nmpc.sim.sensors import LockstepSensors

    for name in ("advance_to", "set_command"):
        _wrap(LockstepDrone, name, "plant", acc)
    # the loop binds the sensors' inputs (LockstepDrone.inputs forwards to it)
    _wrap(LockstepSensors, "inputs", "plant", acc)
    _wrap(LockstepDrone, "truth_cells", "logging", acc)
    _wrap(stages.Estimation, "update", "estimator", acc)
    _wrap(stages.Control, "solve", "solver", acc)
    for name in ("check_feedback", "check_state", "check_solution", "record", "take_events"):
        _wrap(safety.Supervisor, name, "supervisor", acc)
    _wrap(stages.Control, "command", "supervisor", acc)
    _wrap(stages.Supervision, "command", "supervisor", acc)
    _wrap(stages.DelayPrediction, "push", "supervisor", acc)
    # the nominal tick's stages after the solve in one call: the four above, with the response
    # feed and the integrator's step (unwrapped, in "rest", on the other ticks)
    _wrap(after_solve.AfterSolve, "nominal", "supervisor", acc)
    # the nominal tick's controller in one compiled call (the stages above unwrapped in it):
    # its answer, then the Python stages' state written from it — by finish (the records a
    # dict row reads) or by Tick._nominal_cells (a row of cells built from the answer's
    # numbers: nominal_cells, logging, and the supervisor's calls counted apart)
    _wrap(control_tick.ControlTick, "answer", "controller", acc)
    _wrap(control_tick.ControlTick, "finish", "controller", acc)
    _wrap(tick.Tick, "_nominal_cells", "controller", acc)
    _wrap(before_solve.BeforeSolve, "nominal", "controller", acc)
    _wrap(tick, "tick_row", "logging", acc)
    _wrap(tick, "tick_cells", "logging", acc)
    _wrap(tick, "nominal_cells", "logging", acc)
    _wrap(lockstep, "put_truth", "logging", acc)


def _fly(cfg, kind: str, acc: dict | None) -> tuple[float, int]:
    """(wall s of run_lockstep, ticks) with a run-directory or in-memory recorder."""
    from ardrone_nmpc.runs.memory import MemoryRecorder
    from ardrone_nmpc.runs.rundir import RunRecorder
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    with tempfile.TemporaryDirectory() as tmp:
        recorder = RunRecorder.create(tmp, cfg, seed=0) if kind == "rundir" else MemoryRecorder()
        if acc is not None:
            _wrap(recorder, "write_row", "logging", acc)
            _wrap(recorder, "write_cells", "logging", acc)
        t0 = time.perf_counter()
        result = run_lockstep(cfg, recorder=recorder)
        wall = time.perf_counter() - t0
        recorder.close()
    return wall, result.ticks


def profile(config: str, repeats: int) -> None:
    from ardrone_nmpc.config.io import load_config

    cfg = load_config(config)
    _fly(cfg, "memory", None)  # load the kernels
    plain = {k: min(_fly(cfg, k, None)[0] for _ in range(repeats)) for k in ("rundir", "memory")}
    acc: dict = defaultdict(int)
    _instrument(acc)
    print(f"{config}: {cfg.duration_s:g} s + settle {cfg.sim.settle_s:g} s; best of {repeats}")
    for kind in ("rundir", "memory"):
        best = None
        for _ in range(repeats):
            acc.clear()
            wall, ticks = _fly(cfg, kind, acc)
            if best is None or wall < best[0]:
                best = (wall, ticks, dict(acc))
        wall, ticks, parts = best
        parts["rest"] = wall * 1e9 - sum(parts.values())
        print(f"\nrecorder {kind}: {ticks} ticks (plus landing), {wall:.3f} s instrumented, "
              f"{plain[kind]:.3f} s plain → {ticks * cfg.loop.period_s / plain[kind]:.0f}× "
              "real time")
        print(f"{'stage':<12}{'µs/tick':>10}{'share':>8}")
        for name in ("plant", "estimator", "solver", "supervisor", "controller", "logging",
                     "rest"):
            ns = parts.get(name, 0)
            print(f"{name:<12}{ns / ticks / 1e3:>10.1f}{ns / (wall * 1e9):>8.1%}")
    print(f"\nrun directory / in-memory wall: {plain['rundir'] / plain['memory']:.2f}")


def _configs(flights: str = "step_x"):
    from ardrone_nmpc.config.io import load_config

    if flights == "square":  # issue 26's target set: 24 × 60 s squares, seeds 0–23
        return [load_config(ROOT / "configs" / "square.yaml",
                            ["duration_s=60", f"sim.seed={seed}"]) for seed in range(24)]
    rs = ("[4,12,12,24]", "[1,12,12,24]", "[2,12,12,24]", "[4,6,6,24]")
    return [load_config(ROOT / "configs" / "step_x.yaml",
                        ["duration_s=20", f"controller.horizon_steps={n}",
                         f"controller.dtau_s={d}", f"controller.r={r}"])
            for n, d, r in itertools.product((10, 15, 20), (0.08, 0.1), rs)]


def _sweep_way(cfgs, jobs: int) -> float:
    from ardrone_nmpc.experiments.sweep import Case, case_id, iter_local

    cases = [Case(i, case_id(params=(("i", str(i)),), cfg=c), (("i", str(i)),), c)
             for i, c in enumerate(cfgs)]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        results = list(iter_local(cases, out_dir=tmp, jobs=jobs))
        wall = time.perf_counter() - t0
    assert all(r.status != "failed" for r in results), [r.message for r in results]
    return wall


def _values(done) -> list:
    """The values of finished cases (``experiments.parallel.Done``); an error is raised."""
    out = []
    for d in done:
        if d.error is not None:
            raise d.error
        out.append(d.value)
    return out


def _tune_way(cfgs, jobs: int) -> float:
    from ardrone_nmpc.config.io import config_to_dict
    from ardrone_nmpc.experiments.parallel import open_executor
    from ardrone_nmpc.experiments.tune.engine import Scenario, TrialSpec, run_trial
    from ardrone_nmpc.experiments.tune.objective import parse_objective

    obj = parse_objective(None)
    specs = [TrialSpec(i, {}, config_to_dict(c), {}, (Scenario("seed0", 0),), obj)
             for i, c in enumerate(cfgs)]
    t0 = time.perf_counter()
    with open_executor("local", jobs=jobs) as executor:  # tune's executor
        results = _values(executor.map(run_trial, specs, key=id))
    wall = time.perf_counter() - t0
    assert all(r.status != "failed" for r in results), [r.message for r in results]
    return wall


def _warm_pool(cfgs, jobs: int, rounds: int) -> dict:
    """Walls of the per-flight work alone: one warm pool runs the sweep's ``run_case`` and
    tune's ``run_trial`` on the same configs, alternating."""
    from ardrone_nmpc.config.io import config_to_dict
    from ardrone_nmpc.experiments.parallel import open_executor
    from ardrone_nmpc.experiments.sweep import Case, case_id, run_case
    from ardrone_nmpc.experiments.tune.engine import Scenario, TrialSpec, run_trial
    from ardrone_nmpc.experiments.tune.objective import parse_objective

    cases = [Case(i, case_id(params=(("i", str(i)),), cfg=c), (("i", str(i)),), c)
             for i, c in enumerate(cfgs)]
    obj = parse_objective(None)
    specs = [TrialSpec(i, {}, config_to_dict(c), {}, (Scenario("seed0", 0),), obj)
             for i, c in enumerate(cfgs)]
    walls = defaultdict(list)
    with open_executor("local", jobs=jobs) as executor:
        _values(executor.map(run_trial, specs[:jobs], key=id))  # every worker started and warm
        for _ in range(rounds):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                _values(executor.map(run_case, cases, key=id, out_dir=tmp))
                walls["sweep run_case (run dirs)"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            _values(executor.map(run_trial, specs, key=id))
            walls["tune run_trial (memory)"].append(time.perf_counter() - t0)
    return walls


def _report(title: str, walls: dict, sim_s: float) -> None:
    print(title)
    for name, w in walls.items():
        print(f"  {name:<28} walls {', '.join(f'{x:.2f}' for x in w)} s → best "
              f"{sim_s / min(w):.0f}× real time")
    a, b = (min(w) for w in walls.values())
    print(f"  ratio of throughputs (second / first): {a / b:.2f}")


def throughput(jobs: int, rounds: int, flights: str = "step_x") -> None:
    cfgs = _configs(flights)
    sim_s = sum(c.duration_s + c.sim.settle_s for c in cfgs)
    print(f"{len(cfgs)} flights, {sim_s:.0f} s simulated (settle + experiment), {jobs} jobs")
    walls = defaultdict(list)
    for _ in range(rounds):  # alternate, so both see the same load
        walls["sweep (run dirs)"].append(_sweep_way(cfgs, jobs))
        walls["tune (memory)"].append(_tune_way(cfgs, jobs))
    _report("end to end, pool start-up included:", walls, sim_s)
    _report("per-flight work on one warm pool:", _warm_pool(cfgs, jobs, rounds), sim_s)


def cpu(way: str, rounds: int, flights: str = "step_x") -> None:
    """CPU seconds (``time.process_time``: little affected by other load, unlike wall time)
    and wall seconds of the 24 flights in this process, the sweep's way or tune's, this
    process made ready as a pool worker is (``warm_worker``: kernels loaded, the garbage
    collector set)."""
    from ardrone_nmpc.config.io import config_to_dict
    from ardrone_nmpc.experiments.sweep import Case, case_id, run_case

    try:
        from ardrone_nmpc.experiments.sweep import warm_worker
    except ImportError:  # a tree from before it: no collector settings
        from ardrone_nmpc.experiments.sweep import warm_up as warm_worker
    cfgs = _configs(flights)
    sim_s = sum(c.duration_s + c.sim.settle_s for c in cfgs)
    warm_worker()
    if way == "tune":
        from ardrone_nmpc.experiments.tune.engine import Scenario, TrialSpec, run_trial
        from ardrone_nmpc.experiments.tune.objective import parse_objective

        obj = parse_objective(None)
        work = [TrialSpec(i, {}, config_to_dict(c), {}, (Scenario("seed0", 0),), obj)
                for i, c in enumerate(cfgs)]
    else:
        work = [Case(i, case_id(params=(("i", str(i)),), cfg=c), (("i", str(i)),), c)
                for i, c in enumerate(cfgs)]
    cpu_s, wall_s = [], []
    for _ in range(rounds):
        with tempfile.TemporaryDirectory() as tmp:
            c0, w0 = time.process_time(), time.perf_counter()
            for w in work:
                run_trial(w) if way == "tune" else run_case(w, out_dir=tmp)
            cpu_s.append(time.process_time() - c0)
            wall_s.append(time.perf_counter() - w0)
    print(f"{way}: {len(work)} flights, {sim_s:.0f} s simulated: best {min(cpu_s):.2f} CPU s "
          f"({sim_s / min(cpu_s):.0f} simulated s per CPU s), best wall {min(wall_s):.2f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    p = sub.add_parser("profile")
    p.add_argument("--config", default=str(ROOT / "configs" / "step_x.yaml"))
    p.add_argument("--repeats", type=int, default=3)
    t = sub.add_parser("throughput")
    t.add_argument("--jobs", type=int, default=2)
    t.add_argument("--rounds", type=int, default=2)
    t.add_argument("--flights", choices=("step_x", "square"), default="step_x")
    c = sub.add_parser("cpu")
    c.add_argument("--way", choices=("sweep", "tune"), required=True)
    c.add_argument("--rounds", type=int, default=3)
    c.add_argument("--flights", choices=("step_x", "square"), default="step_x")
    args = parser.parse_args()
    if args.what == "profile":
        profile(args.config, args.repeats)
    elif args.what == "cpu":
        cpu(args.way, args.rounds, args.flights)
    else:
        throughput(args.jobs, args.rounds, args.flights)


if __name__ == "__main__":
    main()
