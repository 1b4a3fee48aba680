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
# a square's flight: the child compiles its tick before the solve too
_START_AND_JOIN = ("from ardrone_nmpc.config.schema import config_from_dict\n"
                   "from ardrone_nmpc.runtime import precompile\n"
                   "cfg = config_from_dict({'name': 's', 'reference': {'kind': 'square'}})\n"
                   "child = precompile.start_if_cold(cfg)\n"
                   "precompile.join_child(timeout_s=600.0)\n"
                   "print('none' if child is None else f'started {child.returncode}')")
# a child that outlives the wait is stopped (a Python start-up alone outlasts a zero wait)
_START_AND_STOP = ("from ardrone_nmpc.runtime import precompile\n"
                   "child = precompile.start_if_cold()\n"
                   "precompile.join_child(timeout_s=0.0)\n"
                   "print('none' if child is None else f'stopped {child.returncode}')")
#: Kernels the child must leave cached (module.kernel of numba's file names).
EXPECTED = ("sensor_step.lockstep_run", "plant_step.flying_advance", "plant_step.auto_steps",
            "airframe.airframe_rk4",
            "response_kernels.feed", "response_kernels.fit_grid",
            "response_kernels.fit_estimate")
#: and those of a waypoint flight's tick before the solve
WAYPOINT_EXPECTED = ("tick_kernels.nmpc_inputs", "before_solve.before_solve")


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
    assert set(EXPECTED + WAYPOINT_EXPECTED) <= _cached(cache), sorted(_cached(cache))
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
    # (the step-by-step path's airframe_rk4 only if a take-off's last leg flew on after it)
    assert set(EXPECTED) - {"airframe.airframe_rk4"} <= _cached(cache)
    assert _python(_COLD, cache) == "False"


def test_a_child_that_outlives_the_wait_is_stopped(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    assert _python(_START_AND_STOP, cache, ARDRONE_NMPC_PRECOMPILE="1") == "stopped -9"


def test_the_child_compiles_the_waypoint_tick_before_the_solve_for_a_flight_that_takes_it(
        monkeypatch):
    """A flight whose nominal tick before the solve is compiled (an NMPC, the Kalman filter,
    a waypoint reference) has the child compile it, its callee nmpc_inputs first; any other
    flight's child leaves both to the runner (they would only lengthen its wait)."""
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.runtime import before_solve, precompile, tick_kernels

    root = Path(__file__).resolve().parents[2] / "configs"
    square, hover = load_config(root / "square.yaml"), load_config(root / "hover.yaml")
    p_square = load_config(root / "square.yaml", ["controller.kind=p"])
    luenberger = load_config(root / "square.yaml", ["estimator.kind=luenberger"])
    assert precompile.takes_before_solve(square)
    for cfg in (hover, p_square, luenberger, None):
        assert not precompile.takes_before_solve(cfg)
    # the child's argument
    started = []
    monkeypatch.setenv(precompile.ENV_SWITCH, "1")
    monkeypatch.setattr(precompile, "cache_is_cold", lambda: True)
    monkeypatch.setattr(precompile.subprocess, "Popen", lambda argv, **kw: started.append(argv))
    for cfg in (square, hover):
        monkeypatch.setattr(precompile, "_started", False)
        precompile.start_if_cold(cfg)
    assert started[0][-1] == precompile.BEFORE_SOLVE_ARG
    assert precompile.BEFORE_SOLVE_ARG not in started[1]
    # what the child compiles for it, in the runner's order, before the drone's kernels
    calls = []

    class Stop(Exception):
        pass

    def drone(cfg):
        calls.append("drone")
        raise Stop

    monkeypatch.setattr(tick_kernels, "warm_up_kernels",
                        lambda **which: calls.append(("tick", which)))
    monkeypatch.setattr(before_solve, "warm_up_kernels", lambda: calls.append("before_solve"))
    monkeypatch.setattr("ardrone_nmpc.runtime.after_solve.warm_up_kernels",
                        lambda: calls.append("after_solve"))
    monkeypatch.setattr("ardrone_nmpc.estimation.attitude_response.warm_up_kernels",
                        lambda: calls.append("response"))
    monkeypatch.setattr("ardrone_nmpc.sim.lockstep_drone.LockstepDrone", drone)
    for argv, expected in (([precompile.BEFORE_SOLVE_ARG],
                            [("tick", {"estimate": True, "nmpc": False}), "response",
                             "after_solve", ("tick", {"estimate": False, "nmpc": True}),
                             "before_solve", "drone"]),
                           ([], [("tick", {"estimate": True, "nmpc": False}), "response",
                                 "after_solve", "drone"])):
        calls.clear()
        try:
            precompile.main(argv)
        except Stop:
            pass
        assert calls == expected, argv
