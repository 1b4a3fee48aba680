"""Soak test: ``fly --sim`` (real UDP on 127.0.0.1, 15 Hz navdata, 100 Hz mocap, 65 ms loop) for
N simulated minutes; reports the process RSS at the start and end of the loop, its peak, the
ticks flown vs expected, overruns and wake-up jitter.

    python benchmarks/soak.py --minutes 10 [--config configs/hover.yaml]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.experiments.flight import run_flight
from ardrone_nmpc.runs.rundir import read_run

PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--config", type=Path, default=Path("configs/hover.yaml"))
    args = ap.parse_args()
    cfg = load_config(args.config, [f"duration_s={args.minutes * 60}"])
    samples = []  # (tick progress, rss MiB)

    def status(row):
        k = len(samples)
        if k % 150 == 0:
            samples.append((time.monotonic(), rss_mib()))
        else:
            samples.append(None)

    with tempfile.TemporaryDirectory() as tmp:
        path = run_flight(cfg=cfg, sim=True, drone_host=None, at_port=None, navdata_port=None,
                          mocap_port=None, log_dir=Path(tmp), seed=0, status=status)
        run = read_run(path)
        timing = next(e for e in run.events if e["kind"] == "loop_timing")
        n_settle = round(cfg.sim.settle_s / cfg.loop.period_s)
        expected = n_settle + round(cfg.duration_s / cfg.loop.period_s) + 1
    rss = [s[1] for s in samples if s is not None]
    report = {"minutes": args.minutes, "ticks": run.n_rows, "ticks_expected": expected,
              "overruns": timing["overruns"], "jitter_p99_ms": timing["jitter_p99_ms"],
              "jitter_max_ms": timing["jitter_max_ms"], "rss_start_mib": round(rss[1], 1),
              "rss_end_mib": round(rss[-1], 1), "rss_peak_mib": round(max(rss), 1)}
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
