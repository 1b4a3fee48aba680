"""How much of each kind of lockstep flight blocks of ticks fly (``runtime/lockstep_block``):
the loop's ticks, those flown in blocks, and the wall time a tick, per config and overrides.

    python benchmarks/block_coverage.py [--rounds N] [ROW ...]

A flight no block takes shows 0 %; the rest fly all but their first ticks (the first input
unsent, a fit's or a fault's tick) in blocks. The first flight also loads or compiles the
kernels: its wall time is not the tick's. ``ROW``: only the rows of these names (e.g.
``"square, mocap dropout"``); ``--rounds N``: each flown N times, the least µs a tick shown
(the side-by-side figures of docs/benchmarks.md: one tree, then the other, alternating).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime import lockstep_block as lb

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
WIND = "faults.wind.velocity_mps=[0.32,0.24,0.0]"
CASES = [
    ("square", "square", []),
    ("hover", "hover", []),
    ("step_z", "step_z", []),
    ("ellipse", "ellipse", []),
    ("lorenz", "lorenz", []),
    ("identify", "identify", []),
    ("square, thesis_kit", "square", ["sim.plant.profile=thesis_kit"]),
    ("hover, thesis_kit", "hover", ["sim.plant.profile=thesis_kit"]),
    ("square, navdata speeds", "square", ["estimator.horizontal_velocity=navdata"]),
    ("square, Luenberger", "square", ["estimator.kind=luenberger"]),
    ("altitude_luenberger", "altitude_luenberger", []),
    ("square, difference ż", "square", ["estimator.kind=difference"]),
    ("altitude_none", "altitude_none", []),
    ("square, wind, delay 0.4 s, gain 2", "square",
     [WIND, "sim.plant.command_delay_s=0.4", "sim.plant.attitude_gain=2.0"]),
    ("square, delay 0.2 s, gain 0.6, lag 0.2 s", "square",
     ["sim.plant.command_delay_s=0.2", "sim.plant.attitude_gain=0.6",
      "sim.plant.tau_tilt_s=0.2"]),
    ("square, gust and AT loss", "square",
     ["faults.wind_gust.start_s=5", "faults.at_loss.start_s=10",
      "faults.at_loss.duration_s=0.5", "faults.at_loss.probability=0.5"]),
    ("square, mocap dropout", "square",
     ["faults.mocap_dropout.start_s=5", "faults.mocap_dropout.duration_s=0.3"]),
    ("square, navdata loss", "square", ["faults.navdata_loss.start_s=5"]),
    ("square, 0.1 s dropout every 2 s", "square",
     ["faults.mocap_dropout.start_s=3", "faults.mocap_dropout.duration_s=0.1",
      "faults.mocap_dropout.repeat_every_s=2"]),
    ("square, mocap disorder 2 s", "square",
     ["faults.disorder.start_s=5", "faults.disorder.duration_s=2"]),
    ("square, solver made to diverge", "square",
     ["faults.solver_diverge.start_s=10", "faults.solver_diverge.duration_s=1"]),
    ("square, Newton", "square", ["controller.solver.method=newton"]),
    ("hover, Newton, thesis_kit", "hover",
     ["controller.solver.method=newton", "sim.plant.profile=thesis_kit"]),
    ("square, P", "square", ["controller.kind=p"]),
    ("obstacle", "obstacle", []),
    ("moving_obstacle", "moving_obstacle", []),
    ("follow_car", "follow_car", []),
    ("hover, a second object logged", "hover",
     ["sim.target.object_name=car", "sim.target.path=circle"]),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rows", nargs="*", help="only these rows (their names)")
    parser.add_argument("--rounds", type=int, default=1, help="flights of each row (least µs)")
    args = parser.parse_args()
    unknown = set(args.rows) - {name for name, _, _ in CASES}
    if unknown or args.rounds < 1:
        parser.error(f"no such rows: {sorted(unknown)}" if unknown else "--rounds must be ≥ 1")
    lockstep.warm_up_blocks()
    flown = [0]
    fly = lb.TickBlocks.fly

    def counted(self, k, mode, n_max):
        answer = fly(self, k, mode, n_max)
        flown[0] += answer[0]
        return answer

    lb.TickBlocks.fly = counted
    for name, config, overrides in CASES:
        if args.rows and name not in args.rows:
            continue
        cfg = load_config(CONFIGS / f"{config}.yaml", overrides)
        best_us = float("inf")
        for _ in range(args.rounds):
            flown[0] = 0
            t0 = time.perf_counter()
            result = lockstep.run_lockstep(cfg, recorder=MemoryRecorder())
            ticks = max(result.ticks, 1)
            best_us = min(best_us, (time.perf_counter() - t0) * 1e6 / ticks)
        print(f"{name:42s} ticks {result.ticks:5d}  in blocks {flown[0]:5d} "
              f"({100 * flown[0] / ticks:5.1f} %)  {best_us:6.1f} µs a tick  "
              f"{result.ending}", flush=True)


if __name__ == "__main__":
    main()
