"""The cold start's background compile (runtime/precompile.py): the cold-cache test is right
(an empty ``NUMBA_CACHE_DIR`` is cold, one after a flight is warm), the child fills an empty
cache with the simulated drone's and the attitude fit's kernels, and no child is started when
the cache is warm or the switch is off. Each case in its own process (its own cache dir)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

_COLD = "from ardrone_nmpc.runtime.precompile import cache_is_cold; print(cache_is_cold())"
_START = ("from ardrone_nmpc.runtime.precompile import start_if_cold; "
          "print(start_if_cold() is not None)")
_START_AND_JOIN = ("from ardrone_nmpc.runtime import precompile\n"
                   "child = precompile.start_if_cold()\n"
                   "precompile.join_child(timeout_s=600.0)\n"
                   "print('none' if child is None else f'started {child.returncode}')")
# a child that outlives the wait is stopped (a Python start-up alone outlasts a zero wait)
_START_AND_STOP = ("from ardrone_nmpc.runtime import precompile\n"
                   "child = precompile.start_if_cold()\n"
                   "precompile.join_child(timeout_s=0.0)\n"
                   "print('none' if child is None else f'stopped {child.returncode}')")
#: The plant's own steps (its Python path's: sim/plant.py), which the child compiles too.
PLANT_STEPS = ("plant_step.flying_advance", "plant_step.auto_steps", "airframe.airframe_rk4")
#: Kernels the child must leave cached (module.kernel of numba's file names).
EXPECTED = ("sensor_step.lockstep_run", "plant_step.flying_advance", "plant_step.auto_steps",
            "airframe.airframe_rk4",
            "response_kernels.feed", "response_kernels.fit_grid",
            "response_kernels.fit_estimate")


def _python(code: str, cache: Path, **env) -> str:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, env={**os.environ, "NUMBA_CACHE_DIR": str(cache), **env})
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout.strip().splitlines()[-1]


def _cached(cache: Path) -> set[str]:
    """module.kernel of every compiled kernel's data file in ``cache``."""
    return {p.name.split("-")[0] for p in cache.rglob("*.nbc")}


def test_a_cold_cache_starts_the_child_and_it_fills_the_cache(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    assert _python(_COLD, cache) == "True"
    # the switch on (conftest turns it off for every other test): a child starts, and once it
    # has ended (waited for here) the cache holds the drone's and the attitude fit's kernels
    assert _python(_START_AND_JOIN, cache, ARDRONE_NMPC_PRECOMPILE="1",
                   ARDRONE_NMPC_PRECOMPILE_BLOCKS="0") == "started 0"  # (blocks: below)
    assert set(EXPECTED) <= _cached(cache), sorted(_cached(cache))
    assert _python(_COLD, cache) == "False"
    assert _python(_START, cache, ARDRONE_NMPC_PRECOMPILE="1",
                   ARDRONE_NMPC_PRECOMPILE_BLOCKS="0") == "False"  # warm: no child


def test_a_flight_leaves_the_cache_warm_and_the_switch_starts_no_child(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    assert _python(_START, cache, ARDRONE_NMPC_PRECOMPILE="0") == "False"
    fly = ("from ardrone_nmpc.config.schema import config_from_dict\n"
           "from ardrone_nmpc.runtime.lockstep import run_lockstep\n"
           "run_lockstep(config_from_dict({'name': 't', 'duration_s': 0.2}))\n"
           "print('flown')")
    # the switch off: the flight compiles every kernel itself, and leaves the cache warm
    assert _python(fly, cache, ARDRONE_NMPC_PRECOMPILE="0") == "flown"
    # (the plant's own steps only if a leg the compiled legs cannot fly took them: none in a
    # clean flight, whose take-off and landing they fly to their ends)
    assert set(EXPECTED) - set(PLANT_STEPS) <= _cached(cache)
    assert _python(_COLD, cache) == "False"


def test_a_child_that_outlives_the_wait_is_stopped(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    assert _python(_START_AND_STOP, cache, ARDRONE_NMPC_PRECOMPILE="1") == "stopped -9"


def test_one_block_compile_runs_at_a_time_and_a_dead_ones_lock_is_taken_over(tmp_path,
                                                                               monkeypatch):
    """The block compile (precompile.start_block_compile) starts when the cache lacks blocks
    of ticks' kernel and no other started one less than BLOCK_LOCK_S ago — its lock beside
    the kernel's cache; an older lock (a process that died) is taken over; none when the
    cache holds it. (The process itself is not started here: Popen is recorded.)"""
    import time

    from ardrone_nmpc.runtime import precompile

    started = []
    monkeypatch.setattr(precompile.subprocess, "Popen",
                        lambda args, **kw: started.append(args) or "process")
    lock = tmp_path / "lockstep_block.compiling"
    monkeypatch.setattr(precompile, "_block_lock", lambda kernel: lock)
    cached = {"tick_block": False}
    monkeypatch.setattr(precompile, "_in_cache", lambda kernel: cached["tick_block"])
    assert precompile.start_block_compile() == "process" and lock.exists()
    assert "warm_up_blocks" in started[0][-1]  # (the code it runs)
    assert precompile.start_block_compile() is None  # one runs: none more
    old = time.time() - precompile.BLOCK_LOCK_S - 1.0
    os.utime(lock, (old, old))
    assert precompile.start_block_compile() == "process" and len(started) == 2
    assert lock.stat().st_mtime > old  # taken over: fresh again
    lock.unlink()
    cached["tick_block"] = True
    assert precompile.start_block_compile() is None and len(started) == 2


def test_no_block_compile_where_blocks_never_fly(tmp_path, monkeypatch):
    """Where blocks of ticks are never flown (``TickBlocks.takes``: a platform whose clock
    the kernel does not read, ``core/monotonic.SAME_CLOCK`` False) the kernel is never
    compiled by ``warm_up_blocks``' flight either: no process is started for it (else every
    flight's process would start one, whose warm-up flight compiles nothing and releases
    its lock for the next)."""
    from ardrone_nmpc.core import monotonic
    from ardrone_nmpc.runtime import precompile

    started = []
    monkeypatch.setattr(precompile.subprocess, "Popen",
                        lambda args, **kw: started.append(args) or "process")
    lock = tmp_path / "lockstep_block.compiling"
    monkeypatch.setattr(precompile, "_block_lock", lambda kernel: lock)
    monkeypatch.setattr(precompile, "_in_cache", lambda kernel: False)
    monkeypatch.setattr(monotonic, "SAME_CLOCK", False)
    assert precompile.start_block_compile() is None
    assert not started and not lock.exists()


def test_a_cold_first_flight_flies_tick_by_tick_and_leaves_blocks_compiled_behind(tmp_path):
    """On an empty cache the first flight does not wait for blocks of ticks' kernel: it
    flies every tick its own way while a process of its own compiles the kernel (after the
    flight's controller kernels are cached); then the cache holds it, its lock is gone, and
    the next process's flight flies its usual ticks in blocks."""
    import time

    cache = tmp_path / "cache"
    cache.mkdir()
    fly = ("from ardrone_nmpc.config.schema import config_from_dict\n"
           "from ardrone_nmpc.runtime import lockstep_block\n"
           "from ardrone_nmpc.runtime.lockstep import run_lockstep\n"
           "n = []\n"
           "fly = lockstep_block.TickBlocks.fly\n"
           "def counted(self, *args):\n"
           "    answer = fly(self, *args)\n"
           "    n.append(answer[0])\n"
           "    return answer\n"
           "lockstep_block.TickBlocks.fly = counted\n"
           "run_lockstep(config_from_dict({'name': 't', 'duration_s': 2.0,\n"
           "                               'reference': {'kind': 'square'}}))\n"
           "print(sum(n))")
    assert _python(fly, cache, ARDRONE_NMPC_PRECOMPILE="1") == "0"  # no block: not compiled
    deadline = time.monotonic() + 300.0  # (the block compile: ~10 s on two idle cores)
    while not any(cache.rglob("lockstep_block.tick_block-*.nbc")) or any(
            cache.rglob("lockstep_block.compiling")):
        assert time.monotonic() < deadline, sorted(p.name for p in cache.rglob("*"))
        time.sleep(0.5)
    assert int(_python(fly, cache, ARDRONE_NMPC_PRECOMPILE="1")) > 20


def test_warm_up_blocks_starts_no_second_block_compile(tmp_path, monkeypatch):
    """``warm_up_blocks`` (``bench --tick``, the gates' record) compiles blocks of ticks'
    kernel in its own flight: that flight's ``start_if_cold`` must not start the block
    compile's process too — a second ~7 s compile of the same kernel on the same cores,
    overlapping the flights timed after the warm-up. (The machine code is in this tree's
    cache: the flight loads it; the cache's answers are made to say it is not.)"""
    from ardrone_nmpc.runtime import lockstep, precompile

    started = []
    monkeypatch.setattr(precompile.subprocess, "Popen",
                        lambda args, **kw: started.append(args) or "process")
    lock = tmp_path / "lockstep_block.compiling"
    monkeypatch.setattr(precompile, "_block_lock", lambda kernel: lock)
    monkeypatch.setattr(precompile, "_started", False)  # (this process's first flight)
    monkeypatch.setenv("ARDRONE_NMPC_PRECOMPILE", "1")
    monkeypatch.setattr(precompile, "cache_is_cold", lambda: False)  # the drone's: cached
    monkeypatch.setattr(precompile, "_in_cache", lambda kernel: False)  # … the blocks': not
    monkeypatch.setattr(lockstep, "load_cached", lambda kernel: False)
    lockstep.warm_up_blocks()
    assert not started
    assert not lock.exists()  # (nothing left locked)
