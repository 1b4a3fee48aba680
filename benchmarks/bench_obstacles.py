"""Obstacle avoidance over seeded lockstep runs: clearance, and solve time with and without.

    python benchmarks/bench_obstacles.py [--config configs/obstacle.yaml] [--seeds 20]
                                         [--repeats 3] [--set dotted.path=value …]
                                         [--json docs/bench-obstacles.json]

Per seed it flies the config twice in the lockstep simulation (``simulate.run_lockstep``): as
written, and with ``controller.obstacles=[]`` (the obstacle-free solve of the same
experiment, same seed). Clearance comes from the plant's truth positions over every tick
(``summary.clearance_stats``: ``min_clearance`` = min ``‖p − c‖ − radius``, a violation = a
tick closer than ``d − 0.05 m``). Solve times are the solver's own ``solve_us`` per tick;
a seed's run is deterministic, so it is repeated and each tick's minimum kept, which strips
the interference of other processes on a shared machine (as ``ardrone-nmpc bench`` does).
Not part of the test suite: timings never are.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runtime.lockstep import run_lockstep
from ardrone_nmpc.runs.metrics import CLEARANCE_TOLERANCE_M, clearance_stats

ROOT = Path(__file__).resolve().parents[1]


class _Rows:
    """Recorder stand-in: keeps the columns the benchmark needs."""

    path = None

    def __init__(self):
        self.positions, self.solve_us, self.status = [], [], []

    def write_row(self, row):
        self.positions.append((row["x_true_m"], row["y_true_m"], row["z_true_m"]))
        self.solve_us.append(row.get("solve_us", np.nan))
        self.status.append(row.get("solver_status", ""))

    def event(self, *args, **kwargs):
        pass


def fly(cfg, seed: int, repeats: int):
    """One seed, ``repeats`` identical runs: (positions (K, 3), per-tick min solve µs (K,),
    non-ok solver ticks)."""
    runs = []
    for _ in range(repeats):
        rows = _Rows()
        run_lockstep(cfg, recorder=rows, seed=seed)
        runs.append(rows)
    positions = np.array(runs[0].positions)
    for other in runs[1:]:  # the per-tick minimum needs the same ticks in every repeat
        if not np.array_equal(np.array(other.positions), positions):
            raise RuntimeError(f"seed {seed}: repeats differ; the run is not deterministic")
    solve = np.nanmin(np.array([r.solve_us for r in runs], dtype=float), axis=0)
    non_ok = sum(1 for s in runs[0].status if s not in ("", "ok"))
    return positions, solve, non_ok


def _stats(us: np.ndarray) -> dict:
    us = us[np.isfinite(us)]
    return {"mean_us": float(us.mean()), "p50_us": float(np.percentile(us, 50)),
            "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max())}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "configs" / "obstacle.yaml")
    parser.add_argument("--seeds", type=int, default=20, help="seeds 0 … n−1")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    cfg = load_config(args.config, args.overrides)
    free = load_config(args.config, [*args.overrides, "controller.obstacles=[]"])
    if not cfg.controller.obstacles:
        parser.error("the config has no obstacles")
    run_lockstep(cfg, seed=0)  # JIT warm-up of both specialisations, untimed
    run_lockstep(free, seed=0)

    seeds, all_with, all_without = [], [], []
    print(f"{'seed':>4} {'min clearance m':>16} {'violations':>10} {'non-ok':>6} "
          f"{'mean µs with':>12} {'without':>8} {'p99 µs with':>11} {'without':>8}")
    for seed in range(args.seeds):
        pos, with_us, non_ok = fly(cfg, seed, args.repeats)
        _, without_us, non_ok_free = fly(free, seed, args.repeats)
        per_obstacle = [clearance_stats(pos, ob) for ob in cfg.controller.obstacles]
        row = {"seed": seed,
               "min_clearance_m": min(c["min_clearance_m"] for c in per_obstacle),
               "violations": sum(c["violations"] for c in per_obstacle),
               "non_ok": non_ok, "non_ok_without": non_ok_free,
               "with": _stats(with_us), "without": _stats(without_us)}
        seeds.append(row)
        all_with.append(with_us)
        all_without.append(without_us)
        print(f"{seed:>4} {row['min_clearance_m']:>16.3f} {row['violations']:>10} {non_ok:>6} "
              f"{row['with']['mean_us']:>12.1f} {row['without']['mean_us']:>8.1f} "
              f"{row['with']['p99_us']:>11.1f} {row['without']['p99_us']:>8.1f}")
    w = _stats(np.concatenate(all_with))
    wo = _stats(np.concatenate(all_without))
    d = [ob.radius_m + ob.margin_m for ob in cfg.controller.obstacles]
    print(f"all ticks, with obstacles:    mean {w['mean_us']:.1f}  p50 {w['p50_us']:.1f}  "
          f"p99 {w['p99_us']:.1f}  max {w['max_us']:.0f} µs")
    print(f"all ticks, without obstacles: mean {wo['mean_us']:.1f}  p50 {wo['p50_us']:.1f}  "
          f"p99 {wo['p99_us']:.1f}  max {wo['max_us']:.0f} µs")
    print(f"ratio with/without: mean {w['mean_us'] / wo['mean_us']:.2f}  "
          f"p50 {w['p50_us'] / wo['p50_us']:.2f}  p99 {w['p99_us'] / wo['p99_us']:.2f}")
    worst = min(r["min_clearance_m"] for r in seeds)
    violations = sum(r["violations"] for r in seeds)
    print(f"min clearance over {args.seeds} seeds {worst:.3f} m (d = {d} m); "
          f"ticks closer than d − {CLEARANCE_TOLERANCE_M} m: {violations}")
    if args.json is not None:
        payload = {"config": str(args.config), "overrides": args.overrides,
                   "repeats": args.repeats, "machine": platform.machine(),
                   "python": platform.python_version(),
                   "timing": "per-tick minimum over identical repeats", "seeds": seeds,
                   "all_ticks": {"with": w, "without": wo}}
        args.json.write_text(json.dumps(payload, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
