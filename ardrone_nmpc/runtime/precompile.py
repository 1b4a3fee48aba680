"""Cold start on two cores: the kernels a lockstep flight needs besides the solver's, compiled
into numba's on-disk cache by a background child while the runner compiles the solver.

On an empty cache a flight compiles everything in one process, serially (~13 s on 2 cores):
the solver first (``Tick``'s warm-up), then the attitude estimate's ``feed``, then the simulated
drone's kernels (``lockstep_run``, ``flying_advance``, ``airframe_rk4`` …), which are needed
only after the take-off. :func:`start_if_cold` starts ``python -m
ardrone_nmpc.runtime.precompile`` once per process when the cache is cold; the child compiles
those kernels (:func:`main`) and the runner finds them cached when it gets there.

Never harmful: the child is best-effort (its output goes nowhere; the runner compiles whatever
is not cached yet), numba writes each cache file to a temporary name and renames it (two writers
are safe), and the cached code a process loads is the code it would compile (no fast-math;
``core/kernel_cache.load_cached_callees``). No child when the cache is warm or when
``ARDRONE_NMPC_PRECOMPILE=0``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

#: The environment switch: ``0`` starts no background compile.
ENV_SWITCH = "ARDRONE_NMPC_PRECOMPILE"
_started = False


def cache_is_cold() -> bool:
    """True when numba's cache holds no machine code of the simulated drone's step
    (``sim/sensor_step.lockstep_run``'s index is absent, empty, stale or of another numba): the
    first flight of this machine, or of these sources. Reads one small index file."""
    from ardrone_nmpc.sim.sensor_step import lockstep_run

    cache_file = getattr(getattr(lockstep_run, "_cache", None), "_cache_file", None)
    if cache_file is None:  # caching off (no writable cache dir): nothing to precompile into
        return False
    try:
        return not cache_file._load_index()
    except Exception:  # an unreadable index: numba recompiles anyway
        return True


def start_if_cold() -> subprocess.Popen | None:
    """Start the background compile (module docstring) when the cache is cold, once per
    process; returns the child (None if none started). Any failure is silent."""
    global _started
    if _started or os.environ.get(ENV_SWITCH, "1") == "0":
        return None
    _started = True
    try:
        if not cache_is_cold():
            return None
        # this process's package first on the child's path: it compiles these very sources
        root = str(Path(__file__).resolve().parents[2])
        path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)
        return subprocess.Popen([sys.executable, "-m", __name__],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL,
                                env={**os.environ, ENV_SWITCH: "0", "PYTHONPATH": path})
    except Exception:  # best-effort: the runner compiles what it needs itself
        return None


def compile_kernels() -> None:
    """Compile (or load) the attitude estimate's kernels, then the simulated drone's: connect,
    take off, fly a second holding a small command — the calls a lockstep flight makes."""
    from ardrone_nmpc.config.schema import config_from_dict
    from ardrone_nmpc.core.types import FlightMode
    from ardrone_nmpc.estimation.attitude_response import warm_up_kernels
    from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

    warm_up_kernels()  # the runner needs these first: right after the solver's compile
    cfg = config_from_dict({"name": "precompile", "duration_s": 1.0})
    drone = LockstepDrone(cfg)
    period = cfg.loop.period_s
    drone.connect()
    drone.takeoff()
    truth = drone.truth
    while truth.mode is not FlightMode.FLYING and truth.t_s < 30.0:
        drone.advance_to(truth.t_s + period)
        truth = drone.truth
    t0 = truth.t_s
    drone.start_experiment(t0)
    for k in range(round(1.0 / period)):
        t = t0 + k * period
        drone.advance_to(t, t - t0)
        drone.take_events()
        drone.inputs(t)
        drone.set_command(0.01, -0.01, 0.02, 0.01, progressive=True)
        drone.truth_cells()


def main() -> int:
    """The child's entry point (``python -m ardrone_nmpc.runtime.precompile``)."""
    compile_kernels()
    return 0


if __name__ == "__main__":
    sys.exit(main())
