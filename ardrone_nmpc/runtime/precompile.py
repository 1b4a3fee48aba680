"""Cold start on two cores: the kernels a lockstep flight needs besides the solver's, compiled
into numba's on-disk cache by a background child while the runner compiles the solver.

On an empty cache a flight compiles everything in one process, serially (~13 s on 2 cores):
the solver first (``Tick``'s warm-up), then the estimation stage's step, the attitude
estimate's ``feed`` and the NMPC's nominal tick after the solve (``after_solve``), then the
simulated drone's kernels (``lockstep_run``, ``wire_run``, ``flying_advance``,
``airframe_rk4`` …), which are needed only after the take-off. :func:`start_if_cold` starts
``python -m ardrone_nmpc.runtime.precompile`` once per process when the cache is cold; the
child compiles those kernels (:func:`main`) and the runner finds them cached when it gets there.

Never harmful: the child is best-effort (its output goes nowhere; the runner compiles whatever
is not cached yet), and the cached code a process loads is the code it would compile (no
fast-math; ``core/kernel_cache.load_cached_callees``). The runner waits for the child
(:func:`join_child`) before its first call of a kernel the child compiles — the take-off —:
numba writes each cache file under a temporary name and renames it, but two processes adding
*different* signatures of one kernel at once could both claim the same data file name.
No child when the cache is warm or when ``ARDRONE_NMPC_PRECOMPILE=0``.

Blocks of ticks' kernels (``runtime/lockstep_block.tick_block``, ~7 s to compile, the
controller's and the drone's kernels inside, and its twins — obstacles, Newton, Newton with
obstacles, the P controller's: ``BLOCK_KERNELS``) are compiled last, by a process of its own
that the child starts and nobody waits for: a flight flies its ticks one by one until the
cache holds its kernel (the same rows), the next flights load it. One such compile at a time
(a lock file beside the kernel's cache, held by ``runtime/lockstep.warm_up_blocks`` too
while it compiles the kernels itself); none where blocks are never flown (``core/monotonic.SAME_CLOCK`` False).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

#: The environment switch: ``0`` starts no background compile.
ENV_SWITCH = "ARDRONE_NMPC_PRECOMPILE"
#: … and the block compile's own: ``0`` starts the drone's child alone.
BLOCKS_SWITCH = "ARDRONE_NMPC_PRECOMPILE_BLOCKS"
#: How long :func:`join_child` waits before it stops a child that hangs (its own compile on a
#: busy machine takes ~10 s)
JOIN_TIMEOUT_S = 120.0
#: How long the block compile waits for the runner's controller kernels to be cached (s)
BLOCK_WAIT_S = 60.0
#: How long a block compile's lock keeps others from starting one (s)
BLOCK_LOCK_S = 600.0
_started = False
_child: subprocess.Popen | None = None


def cache_is_cold() -> bool:
    """True when numba's cache holds no machine code of the simulated drone's step
    (``sim/sensor_step.lockstep_run``'s index is absent, empty, stale or of another numba): the
    first flight of this machine, or of these sources. Reads one small index file."""
    from ardrone_nmpc.sim.sensor_step import lockstep_run

    return _in_cache(lockstep_run) is False


def background_compiles() -> bool:
    """Whether kernels are compiled in the background (:data:`ENV_SWITCH` not ``0``): a
    runner then does not compile blocks of ticks' kernel itself."""
    return os.environ.get(ENV_SWITCH, "1") != "0"


def _in_cache(kernel) -> bool | None:
    """Whether ``kernel``'s cache index lists machine code (None: caching is off — no
    writable cache dir: nothing to precompile into)."""
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    if cache_file is None:
        return None
    try:
        return bool(cache_file._load_index())
    except Exception:  # an unreadable index: numba recompiles anyway
        return False


def start_if_cold() -> subprocess.Popen | None:
    """Start the background compile (module docstring) when the cache is cold, once per
    process; returns the child (None if none started). Any failure is silent. A cache
    that lacks only blocks of ticks' kernel gets the block compile alone (no child to wait
    for)."""
    global _started, _child
    if _started or not background_compiles():
        return None
    _started = True
    try:
        if not cache_is_cold():
            start_block_compile()
            return None
        # this process's package first on the child's path (not the working directory's, as
        # ``-m`` would put first, nor on PYTHONPATH, ahead of the standard library): it
        # compiles these very sources
        root = str(Path(__file__).resolve().parents[2])
        code = (f"import sys; sys.path.insert(0, {root!r}); "
                f"from {__name__} import main; sys.exit(main())")
        _child = subprocess.Popen([sys.executable, "-c", code],
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, env={**os.environ, ENV_SWITCH: "0"})
        return _child
    except Exception:  # best-effort: the runner compiles what it needs itself
        return None


def join_child(timeout_s: float = JOIN_TIMEOUT_S) -> None:
    """Wait for the background compile, if one runs (module docstring); a child still running
    after ``timeout_s`` is stopped — the runner then compiles what is missing itself."""
    global _child
    child, _child = _child, None
    if child is None:
        return
    try:
        child.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        child.kill()
        child.wait()


def compile_kernels() -> None:
    """Compile (or load) the estimation stage's and the attitude estimate's kernels, then the
    simulated drone's: connect, take off, fly a second holding a small command, land — the
    calls a lockstep flight makes — then the plant's own steps, flying and landing."""
    from ardrone_nmpc.config.schema import config_from_dict
    from ardrone_nmpc.estimation.attitude_response import warm_up_kernels
    from ardrone_nmpc.runtime.after_solve import warm_up_kernels as warm_up_after_solve
    from ardrone_nmpc.runtime.tick_kernels import warm_up_kernels as warm_up_tick_kernels
    from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

    # the runner needs these first: right after the solver's compile (the estimate's: every
    # flight with the default ż filter; nmpc_inputs only a waypoint reference's, left to it)
    warm_up_tick_kernels(estimate=True, nmpc=False)
    warm_up_kernels()
    warm_up_after_solve()  # the NMPC's nominal tick (runtime/after_solve): feed is cached now
    cfg = config_from_dict({"name": "precompile", "duration_s": 1.0})
    drone = LockstepDrone(cfg)
    period = cfg.loop.period_s
    drone.connect()
    drone.takeoff()
    _, t0 = drone.climb_out(period, 30.0)  # (as the runner: drone_ascent)
    plant = drone.sim.plant  # its step-by-step path: a take-off end the legs hand back
    plant._motors_on_step(plant._current, plant.params.integration_step_s, (0.0, 0.0, 0.0))
    drone.start_experiment(t0)
    for k in range(round(1.0 / period)):
        t = t0 + k * period
        drone.advance_to(t, t - t0)
        drone.take_events()
        drone.inputs(t)
        drone.set_command(0.01, -0.01, 0.02, 0.01, progressive=True)
        drone.truth_cells()
    # the plant's own compiled steps, which the compiled legs fly in a clean flight's place
    # but a flight they cannot fly takes (sensor faults through the wire, an emptying battery)
    plant.advance(period)  # FLYING: flying_advance
    plant.land()
    plant.advance(period)  # the automatic landing: auto_steps
    _land(drone, plant.t_s, 0, period)  # (the drone's landing, from the plant's time on)
    # the wire path's quiet ticks (sensor faults: sim/quiet_wire) on the legs' own arrays
    import math

    import numpy as np

    from ardrone_nmpc.sim.wire_step import EV_WIDTH, navdata_packets, wire_run

    legs = drone.sensors._legs
    if legs is not None and legs._args:  # (this drone is done with: a run changes nothing
        wire_run(*legs._args, np.zeros((1, EV_WIDTH)))  # that is read again)
    navdata_packets(np.zeros((1, EV_WIDTH)), 1, 0, math.inf, 0.05, 20.0)  # (quiet packets)


def start_block_compile() -> subprocess.Popen | None:
    """Start the compile of blocks of ticks' kernels in a process of its own, which nobody
    waits for (module docstring) — unless the cache holds them all, :data:`BLOCKS_SWITCH` is
    ``0``, or another such process started less than :data:`BLOCK_LOCK_S` ago (its lock
    file is beside the kernel's cache):
    it waits for the runner's controller kernels to be cached (:data:`BLOCK_WAIT_S` at most:
    not compiled twice at once on two cores), then compiles the block kernels the cache
    lacks (``runtime/lockstep.warm_up_blocks``) and removes the lock."""
    from ardrone_nmpc.core import monotonic
    from ardrone_nmpc.runtime.lockstep_block import BLOCK_KERNELS

    # (no blocks flown where the kernel does not read Python's clock: TickBlocks.takes —
    # warm_up_blocks' flight would compile nothing, and each process would start one);
    # any block kernel not cached (the P controller's, the Newton scheme's with obstacles:
    # not a flight's foreground compile either)
    if (os.environ.get(BLOCKS_SWITCH, "1") == "0" or not monotonic.SAME_CLOCK
            or all(_in_cache(k) is not False for k in BLOCK_KERNELS.values())):
        return None
    if not take_block_lock():
        return None  # another compiles it
    code = _BLOCK_COMPILE.format(root=str(Path(__file__).resolve().parents[2]),
                                 module=__name__)
    return subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, ENV_SWITCH: "0"}, start_new_session=True)


def take_block_lock() -> bool:
    """The block compile's lock taken (:func:`start_block_compile`'s; also
    ``runtime/lockstep.warm_up_blocks``' while its flight compiles the kernel, so that no
    process is started to compile it a second time meanwhile): False when another process
    took it less than :data:`BLOCK_LOCK_S` ago, or it cannot be made (no cache)."""
    from ardrone_nmpc.runtime.lockstep_block import tick_block

    if _in_cache(tick_block) is None:  # caching off: no cache directory to lock in
        return False
    lock = _block_lock(tick_block)
    try:
        os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        try:
            if time.time() - lock.stat().st_mtime < BLOCK_LOCK_S:
                return False  # another compiles it
            lock.touch()  # a lock left by a process that died: taken over
        except OSError:
            return False
    except OSError:
        return False
    return True


def _block_lock(tick_block) -> Path:
    return Path(tick_block._cache.cache_path) / "lockstep_block.compiling"


def wait_for_controller() -> None:
    """The block compile's wait (:func:`start_block_compile`): until the controller's
    nominal tick is cached, :data:`BLOCK_WAIT_S` at most."""
    from ardrone_nmpc.runtime.control_tick import control_tick

    deadline = time.monotonic() + BLOCK_WAIT_S
    while _in_cache(control_tick) is False and time.monotonic() < deadline:
        time.sleep(0.5)


def release_block_lock() -> None:
    """The block compile's lock removed (its process ends)."""
    from ardrone_nmpc.runtime.lockstep_block import tick_block

    _block_lock(tick_block).unlink(missing_ok=True)


#: The block compile's process (:func:`start_block_compile`; the runner's module is not
#: this one's import: it imports this one)
_BLOCK_COMPILE = """
import sys
sys.path.insert(0, {root!r})
from {module} import release_block_lock, wait_for_controller
try:
    wait_for_controller()
    from ardrone_nmpc.runtime.lockstep import warm_up_blocks
    warm_up_blocks()
finally:
    release_block_lock()
"""


def _land(drone, t0: float, k: int, period: float) -> None:
    """A landing as the runner waits one out (``LockstepDrone.touch_down``: the descent's
    usual ticks in one compiled call, ``sim/drone_block.drone_descent``); ~1 s of compile a
    first flight's landing would wait for."""
    drone.land()
    drone.touch_down(t0, k, period, t0 + 60.0, t0)


def main() -> int:
    """The child's entry point (``python -m ardrone_nmpc.runtime.precompile``): the drone's
    kernels, then the block compile started (it goes on after this child's exit)."""
    compile_kernels()
    start_block_compile()
    return 0


if __name__ == "__main__":
    sys.exit(main())
