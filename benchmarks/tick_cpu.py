"""CPU seconds of one lockstep flight and of the simulated drone alone, in this process.

    python benchmarks/tick_cpu.py [--config configs/square.yaml] [--duration-s 60]
                                  [--repeats 5] [--drone-ticks 1000]

prints the best and median CPU seconds (``time.process_time``, which the other agents' load
changes less than the wall time) of ``run_lockstep`` with an in-memory recorder, and the wall
µs per tick of the simulated drone alone (``advance_to``, ``inputs``, ``set_command``,
``truth`` over ``--drone-ticks`` ticks of a flying drone, best of 7). Compare two trees by
running each tree's interpreter (its own virtualenv: an editable install's finder wins over
``PYTHONPATH``) alternately, from outside both trees.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def flight_cpu_s(cfg, repeats: int) -> list[float]:
    from ardrone_nmpc.runs.memory import MemoryRecorder
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    run_lockstep(cfg, recorder=MemoryRecorder())  # kernels loaded, caches warm
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        run_lockstep(cfg, recorder=MemoryRecorder())
        times.append(time.process_time() - t0)
    return times


def drone_us_per_tick(cfg, ticks: int) -> float:
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

    period = cfg.loop.period_s
    drone = LockstepDrone(cfg)
    drone.connect()
    drone.takeoff()
    while drone.truth.mode is not FlightMode.FLYING:
        drone.advance_to(drone.truth.t_s + period)
    t_first = drone.truth.t_s
    drone.start_experiment(t_first)
    t0 = time.perf_counter()
    for k in range(ticks):  # a slow zig-zag: the commands change every 50 ticks
        drone.advance_to(t_first + k * period, k * period)
        drone.take_events()
        drone.inputs(t_first + k * period)
        drone.set_command(0.05 * ((k // 50) % 3 - 1), 0.02, 0.0, 0.01)
        drone.truth
    return (time.perf_counter() - t0) / ticks * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(ROOT / "configs" / "square.yaml"))
    parser.add_argument("--duration-s", type=float, default=60.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--drone-ticks", type=int, default=1000)
    args = parser.parse_args()
    import ardrone_nmpc
    from ardrone_nmpc.config.io import load_config

    cfg = load_config(args.config, [f"duration_s={args.duration_s:g}"])
    times = flight_cpu_s(cfg, args.repeats)
    drone_us_per_tick(cfg, 50)
    drone_us = min(drone_us_per_tick(cfg, args.drone_ticks) for _ in range(7))
    print(f"{Path(ardrone_nmpc.__file__).parents[1]}: flight CPU s best {min(times):.3f} "
          f"median {statistics.median(times):.3f}; drone alone {drone_us:.1f} µs per tick")


if __name__ == "__main__":
    main()
