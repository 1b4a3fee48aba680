"""How reliably ``tune`` finds a good controller: docs/tuning.md §4's reliability table.

``python benchmarks/tune_reliability.py [CONFIG] [--runs 10] [--trials 40] [--jobs 2]
[--held-out 100,101,102,103,104] [--out DIR]``
runs ``ardrone-nmpc tune CONFIG --trials N --jobs J --seed k`` for k = 0 … runs − 1 (each into
``DIR/seed<k>``, kept: a second call re-evaluates the ``best.yaml`` files without tuning
again), then flies each ``best.yaml`` as it is (its own plant) on the held-out seeds, which no
trial flew (a trial flies ``sim.seed`` … ``sim.seed + 2``), and prints one row per tuning run:
the stepped axis' settling time (2 % band) and overshoot, worst over the held-out seeds, and
whether both meet the target (settling ≤ 3 s, overshoot ≤ 5 %).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from tune_heldout import _flight, _load  # noqa: E402 - the held-out flights of §4's tables

SETTLE_MAX_S = 3.0
OVERSHOOT_MAX_PCT = 5.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="configs/step_z.yaml")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--trials", type=int, default=40)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--held-out", default="100,101,102,103,104")
    parser.add_argument("--out", default="/tmp/tune_reliability")
    args = parser.parse_args()
    held_out = [int(s) for s in args.held_out.split(",")]
    good = 0
    print(f"| --seed | wall s | best trial | settling s (worst of {len(held_out)}) | "
          "overshoot % (worst) | ≤ 3 s and ≤ 5 % |")
    print("|--:|--:|:--|--:|--:|:--:|")
    for k in range(args.runs):
        out = Path(args.out) / f"seed{k}"
        wall_s = float("nan")
        if not (out / "best.yaml").is_file():
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "ardrone_nmpc.cli.app", "tune", args.config,
                            "--trials", str(args.trials), "--jobs", str(args.jobs), "--seed",
                            str(k), "-o", str(out)], check=True, stdout=subprocess.DEVNULL)
            wall_s = time.perf_counter() - t0
        cfg = _load(str(out / "best.yaml"), [], None)
        axis = cfg.reference.stepped_axes[0]
        flights = [_flight(cfg, s) for s in held_out]
        settle = max(f[(axis, "settling_time")] for f in flights)   # NaN: never settled
        over = max(f[(axis, "overshoot")] for f in flights)
        ok = settle <= SETTLE_MAX_S and over <= OVERSHOOT_MAX_PCT
        good += ok
        header = (out / "best.yaml").read_text().splitlines()[1].strip("# ")
        print(f"| {k} | {wall_s:.0f} | {header.split(',')[1].strip()} | {settle:.2f} | "
              f"{over:.1f} | {'yes' if ok else 'no'} |")
    print(f"\n{good} of {args.runs} tuning runs meet the target.")


if __name__ == "__main__":
    main()
