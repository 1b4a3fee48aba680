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
    assert _python(_START_AND_JOIN, cache, ARDRONE_NMPC_PRECOMPILE="1") == "started 0"
    assert set(EXPECTED) <= _cached(cache), sorted(_cached(cache))
    assert _python(_COLD, cache) == "False"
    assert _python(_START, cache, ARDRONE_NMPC_PRECOMPILE="1") == "False"  # warm: no child


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
