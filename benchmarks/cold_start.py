"""The cold start, side by side: ``simulate configs/hover.yaml`` with an empty numba cache.

    python benchmarks/cold_start.py [--base DIR] [--rounds 2] [--config configs/hover.yaml]

Each round runs ``python -m ardrone_nmpc.cli.app simulate CONFIG`` once on this tree and, with
``--base``, once on another checkout (``git archive main | tar -x -C /tmp/base``: that tree on
``PYTHONPATH``), alternating, each in a fresh process with its own empty ``NUMBA_CACHE_DIR``;
then once more on a filled cache (the warm start). It prints wall and CPU seconds (user +
system of the child, which other load hardly changes) per run and the after/before ratio of
the medians. Exit 1 if a run fails.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _child_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def simulate_once(tree: Path, config: Path, cache_dir: Path) -> tuple[float, float]:
    """Wall and CPU seconds of one ``simulate`` on ``tree`` with the numba cache ``cache_dir``
    — then a background compile it left running (blocks of ticks', ``runtime/precompile``)
    waited for, its seconds after the run printed (it is not the run's: the next run must
    not share the cores with it)."""
    # cwd=tree: ``python -m`` puts the working directory first on sys.path
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(tree))
    with tempfile.TemporaryDirectory(prefix="cold-logs-") as logs:
        cpu0, t0 = _child_cpu_s(), time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "ardrone_nmpc.cli.app", "simulate", str(config), "--quiet",
             "--log-dir", logs], env=env, cwd=tree, capture_output=True, text=True)
        wall, cpu = time.perf_counter() - t0, _child_cpu_s() - cpu0
    if done.returncode != 0:
        sys.exit(f"{tree}: simulate failed ({done.returncode}):\n{done.stderr[-2000:]}")
    t1 = time.perf_counter()
    while any(cache_dir.rglob("lockstep_block.compiling")):
        if time.perf_counter() - t1 > 600.0:
            sys.exit(f"{tree}: the background compile still runs after 600 s")
        time.sleep(0.2)
    if time.perf_counter() - t1 > 0.2:
        print(f"        (a background compile ended {time.perf_counter() - t1:.1f} s after "
              "the run)", flush=True)
    return wall, cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, help="the tree to compare with (e.g. main)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "hover.yaml")
    args = ap.parse_args()
    args.config = args.config.resolve()
    trees = {"after": ROOT} | ({"before": args.base.resolve()} if args.base else {})
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)")
    cold: dict[str, list[tuple[float, float]]] = {name: [] for name in trees}
    caches = {}
    for r in range(args.rounds):
        for name, tree in (trees.items() if r % 2 == 0 else reversed(trees.items())):
            cache = Path(tempfile.mkdtemp(prefix=f"numba-{name}-"))
            wall, cpu = simulate_once(tree, args.config, cache)
            caches[name] = cache
            cold[name].append((wall, cpu))
            print(f"{name:<7} cold  {wall:6.1f} s wall  {cpu:6.1f} s CPU   ({tree})", flush=True)
    warm = {}
    for name, tree in trees.items():
        warm[name] = simulate_once(tree, args.config, caches[name])
        print(f"{name:<7} warm  {warm[name][0]:6.1f} s wall  {warm[name][1]:6.1f} s CPU",
              flush=True)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")
    for name in trees:
        walls, cpus = zip(*cold[name])
        print(f"{name:<7} cold median {statistics.median(walls):6.1f} s wall "
              f"{statistics.median(cpus):6.1f} s CPU")
    if "before" in cold:
        for i, what in enumerate(("wall", "CPU")):
            a = statistics.median(x[i] for x in cold["after"])
            b = statistics.median(x[i] for x in cold["before"])
            print(f"cold {what} after/before: {a / b:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
