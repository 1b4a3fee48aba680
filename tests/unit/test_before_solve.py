"""The nominal tick's stages before the solve in one compiled call (runtime/before_solve.py):
the same ages, estimate, solution, rows, events and stage state as the Python stages, and
nothing written when the tick is not nominal."""

from __future__ import annotations

import copy
import dataclasses
import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample, TickInputs
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime.before_solve import BeforeSolve
from ardrone_nmpc.runtime.lockstep import experiment_trajectory, run_lockstep
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.runtime.tick_kernels import E_X, estimate_step
from ardrone_nmpc.safety import NOMINAL, Action, Decision
from tests.conftest import nan_equal

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
_TIMES = ("solve_us", "compute_us", "tick_late_ms")  # the clock's, not the flight's


def config(name: str, *overrides: str):
    return load_config(CONFIGS / name, list(overrides))


def _supervisor(tick: Tick) -> list:
    """What the supervisor carries: counters, latch, mode, pending events."""
    s = tick.supervisor
    return [s._latched, s._solver_failures, s._solver_good, s._solver_fallback, s.label,
            list(s.events)]


def _fly(cfg, *, compiled: bool, monkeypatch) -> tuple[list, list, int, list]:
    """The rows and events of a lockstep flight, how many ticks the compiled call took, and
    the stages' state at the end."""
    taken, ticks = [0], []
    original_init, original_nominal = Tick.__init__, BeforeSolve.nominal

    def init(self, *args, **kwargs):
        original_init(self, *args, **kwargs)
        ticks.append(self)
        self.control_tick = None  # this half on its own (test_control_tick: the whole)
        if not compiled:
            self.before_solve = None

    def nominal(self, *args):
        done = original_nominal(self, *args)
        taken[0] += done is not None
        return done

    with monkeypatch.context() as m:
        m.setattr(Tick, "__init__", init)
        m.setattr(BeforeSolve, "nominal", nominal)
        recorder = MemoryRecorder()
        run_lockstep(cfg, recorder=recorder)
    tick = ticks[-1]
    state = [_supervisor(tick), tick.estimation._state.tolist(), tick.delay.ring.tolist(),
             tick.control._states.tolist()]
    return recorder.rows, recorder.events, taken[0], state


@pytest.mark.parametrize("name, overrides", [
    ("square.yaml", ["duration_s=8"]),  # auto delay and gain, offset-free: every stage
    ("square.yaml", ["duration_s=5", "estimator.horizontal_velocity=navdata"]),
    ("square.yaml", ["duration_s=5", "controller.solver.method=newton"]),
    ("square.yaml", ["duration_s=5", "controller.offset_free.enabled=false"]),  # no shift
    ("square.yaml", ["duration_s=5", "controller.delay_compensation_s=0"]),  # nothing pending
    ("square.yaml", ["duration_s=5", "faults.at_loss.start_s=2",
                     "faults.at_loss.probability=0.7"]),
    ("square.yaml", ["duration_s=6", "faults.solver_diverge.start_s=2"]),  # holds, fallback
    ("square.yaml", ["duration_s=6", "faults.mocap_dropout.start_s=3",
                     "faults.mocap_dropout.duration_s=0.2"]),  # stale mocap: hold, hover
    ("square.yaml", ["duration_s=6", "faults.battery_floor.start_s=3"]),  # land, latched
    ("square.yaml", ["duration_s=6", "faults.emergency.start_s=3"]),  # stop
    ("square.yaml", ["duration_s=6", "faults.navdata_loss.start_s=3"]),  # land, navdata lost
    ("square.yaml", ["duration_s=6", "faults.wind.velocity_mps=[-3.0,0,0]"]),  # speed, fence
])
def test_a_flight_gives_the_rows_of_the_python_stages(name, overrides, monkeypatch):
    cfg = config(name, *overrides)
    python_rows, python_events, none, python_state = _fly(cfg, compiled=False,
                                                          monkeypatch=monkeypatch)
    rows, events, taken, state = _fly(cfg, compiled=True, monkeypatch=monkeypatch)
    assert none == 0 and taken > 20  # the compiled call took the nominal ticks
    assert repr(events) == repr(python_events)  # (repr: a NaN equal to a NaN)
    assert repr(state) == repr(python_state)
    assert len(rows) == len(python_rows)
    for i, (a, b) in enumerate(zip(python_rows, rows)):
        bad = [k for k in a if k not in _TIMES and not nan_equal(a[k], b[k])]
        assert not bad, f"row {i}: {bad}"


# ----------------------------------------------------------------------------- one tick
def _nav(**changes) -> NavdataSample:
    nav = NavdataSample(0.0, FlightMode.FLYING, 80.0, 1.5, -2.0, 0.0, 1.0, 0.1, -0.05, 0.0)
    return dataclasses.replace(nav, **changes)


def _inputs(t_s: float, position=(0.0, 0.0, 1.0), nav=None, pose_t_s=None,
            mocap_age_s=0.01) -> TickInputs:
    pose = MocapPose(t_s if pose_t_s is None else pose_t_s, np.array(position, dtype=float),
                     np.zeros(3), 0.02)
    return TickInputs(t_s, pose, t_s - mocap_age_s, _nav() if nav is None else nav, t_s - 0.02,
                      None, -math.inf)


def _flown_tick(compiled: bool, ticks: int = 4) -> tuple[Tick, list]:
    """A square's tick after ``ticks`` ticks of its start (the first packs the reference in
    Python), and their rows."""
    cfg = config("square.yaml")
    tick = Tick(cfg, experiment_trajectory(cfg))
    tick.control_tick = None  # this half on its own (test_control_tick: the whole)
    if not compiled:
        tick.before_solve = None
    rows = []
    for k in range(ticks):
        t_s = 2.0 + 0.065 * k
        out = tick.step(_inputs(t_s, position=(0.01 * k, -0.02 * k, 1.0 + 0.005 * k)),
                        t_exp_s=t_s - 1.0)
        rows.append(out.row)
    return tick, rows


def _state(tick: Tick) -> list:
    """What the stages before the solve carry or hand on (NaN made comparable)."""
    c = tick.control
    arrays = (tick.estimation._state, c._x_solve, c._states, c._work, tick.delay.ring,
              tick.control.nmpc.memory.U)
    return [np.where(np.isnan(a), -1e300, a).tolist() for a in arrays] + _supervisor(tick)


def test_the_compiled_ticks_are_the_python_stages():
    fast, fast_rows = _flown_tick(True)
    slow, slow_rows = _flown_tick(False)
    for a, b in zip(fast_rows, slow_rows):
        assert not [k for k in a if k not in _TIMES and not nan_equal(a[k], b[k])]
    assert _state(fast) == _state(slow)
    inputs = _inputs(2.3, position=(0.05, -0.1, 1.02))
    ages, x, sol = fast.before_solve.nominal(inputs, 1.3, fast.trajectory)
    assert ages == ((2.3 - inputs.pose_rx_t_s) * 1e3, (2.3 - inputs.navdata_rx_t_s) * 1e3)
    slow_x = slow.estimation.update(inputs.pose, inputs.navdata, slow.supervision.zacc_mps2)
    assert slow.supervisor.check_state(slow_x, inputs.navdata) is NOMINAL
    slow_sol = slow.control.solve(1.3, slow_x, slow.trajectory, slow.offset)
    assert x is fast.estimation._x and x.tolist() == slow_x.tolist()
    assert sol.x_solve.tolist() == slow_sol.x_solve.tolist()
    assert sol.result.u.tolist() == slow_sol.result.u.tolist()
    assert (sol.ok, sol.status) == (slow_sol.ok, slow_sol.status)
    assert sol.ref_horizon.tolist() == slow_sol.ref_horizon.tolist()
    assert _state(fast) == _state(slow)


@pytest.mark.parametrize("inputs", [
    _inputs(2.3, mocap_age_s=0.5),                        # stale mocap: hold, hover, land
    _inputs(2.3, nav=_nav(battery_pct=5.0)),               # the battery floor: land
    _inputs(2.3, nav=_nav(state_bits=1 << 22)),            # a fault bit (CUTOUT): stop
    _inputs(2.3, nav=_nav(state_bits=1 << 15 | 1 << 13)),  # VBAT_LOW (and COM_LOST): land
    _inputs(2.3, nav=_nav(mode=FlightMode.EMERGENCY)),     # emergency: stop
    _inputs(2.3, nav=_nav(roll_deg=60.0)),                 # tilted beyond the cap: hover
    _inputs(2.3, position=(100.0, 0.0, 1.0)),              # outside the geofence
    _inputs(2.3, position=(3.0, 0.0, 1.0)),                # too fast
    _inputs(2.3, position=(math.nan, 0.0, 1.0)),           # not finite: the estimator's own
    _inputs(2.3, pose_t_s=1.0),                            # a pose older than the last
])
def test_a_tick_not_nominal_writes_nothing(inputs):
    tick, _ = _flown_tick(True)
    before = _state(tick)
    assert tick.before_solve.nominal(inputs, 1.3, tick.trajectory) is None
    assert _state(tick) == before


def test_a_latched_supervisor_is_the_python_stages():
    tick, _ = _flown_tick(True)
    tick.supervisor._latch(Decision(Action.LAND, "mocap-lost"))
    before = _state(tick)
    assert tick.before_solve.nominal(_inputs(2.3), 1.3, tick.trajectory) is None
    assert _state(tick) == before


def test_new_safety_limits_are_read():
    tick, _ = _flown_tick(True)
    tick.supervisor.cfg = tick.supervisor.cfg.model_copy(update={"max_speed_mps": 1e-6})
    before = _state(tick)
    assert tick.before_solve.nominal(_inputs(2.3), 1.3, tick.trajectory) is None
    assert _state(tick) == before


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda t: pickle.loads(pickle.dumps(t))])
def test_a_copied_tick_calls_the_kernel_on_its_own_stages(copier):
    clone = copier(_flown_tick(True)[0])
    before = clone.before_solve
    for name in ("supervisor", "estimation", "supervision", "control", "offset"):
        assert getattr(before, name) is getattr(clone, name)
    assert before.delay is clone.delay
    assert before.nominal(_inputs(2.3), 1.3, clone.trajectory) is not None

def test_the_entry_point_is_taken_only_with_the_arrays_it_vetted():
    tick, _ = _flown_tick(True)
    before = tick.before_solve
    assert before.nominal(_inputs(2.3), 1.3, tick.trajectory) is not None
    assert before._entry is not None and before._vetted[0] is tick.estimation._state
    # a new array of another layout (strided): the dispatcher takes it, and no entry point
    strided = np.zeros(2 * tick.control._x_solve.size)[::2]
    strided[:] = tick.control._x_solve
    tick.control._x_solve = strided
    assert before.nominal(_inputs(2.365), 1.365, tick.trajectory) is not None
    assert before._entry is None


# ----------------------------------------------------------------------------- twins' edges
def _step_both(inputs: TickInputs, t_exp_s: float, *, setup=None) -> tuple:
    """The same tick after the same flown ticks, compiled call on and off: their rows
    (repr: value and type) and stage state."""
    out = []
    for compiled in (True, False):
        tick, _ = _flown_tick(True)
        if not compiled:
            tick.before_solve = None
        if setup is not None:
            setup(tick)
        row = tick.step(inputs, t_exp_s=t_exp_s).row
        out.append(([(k, repr(v)) for k, v in row.items() if k not in _TIMES], _state(tick)))
    return out


def test_the_speed_is_squared_as_python_squares():
    """check_state's ``v ** 2`` is the C library's pow, which differs from v · v in the last
    bit for ~0.1 % of v: a speed at its limit must get Python's verdict."""
    tick, _ = _flown_tick(True)
    rng = np.random.default_rng(7)
    for _ in range(200000):  # an estimate whose speeds by pow and by v · v straddle
        position = (0.04 + rng.uniform(-0.05, 0.05), -0.08 + rng.uniform(-0.05, 0.05),
                    1.02 + rng.uniform(-0.01, 0.01))
        inputs = _inputs(2.26, position=position)
        s = tick.estimation._state.copy()  # Estimation.update's step, on a copy
        assert estimate_step(s, *position, 0.02, 2.26, 0.0, False, 0.0, 0.0) == 0
        x = s[E_X:E_X + 7].tolist()
        by_pow = math.sqrt(x[1] ** 2 + x[3] ** 2 + x[5] ** 2)
        by_mul = math.sqrt(x[1] * x[1] + x[3] * x[3] + x[5] * x[5])
        if by_pow > by_mul:
            break
    else:
        pytest.fail("no such estimate found")

    def limit(t: Tick) -> None:
        t.supervision.zacc_mps2 = 0.0
        t.supervisor.cfg = t.supervisor.cfg.model_copy(update={"max_speed_mps": by_mul})

    fast, slow = _step_both(inputs, 1.26, setup=limit)
    assert dict(slow[0])["mode"] == repr("hover-speed")
    assert fast == slow


@pytest.mark.parametrize("name, change", [
    # numpy ages: the row's cells numpy scalars in Python
    ("t_s np.float64", lambda i: dataclasses.replace(i, t_s=np.float64(i.t_s))),
    ("pose_rx float32", lambda i: dataclasses.replace(i, pose_rx_t_s=np.float32(i.pose_rx_t_s))),
    # a float32 pose stamp: the estimators' Δt a float32 difference (the objects' own)
    ("pose stamp float32", lambda i: dataclasses.replace(i, pose=dataclasses.replace(
        i.pose, t_s=np.float32(i.pose.t_s)))),
    # a float32 battery at a floor float32 rounds to: Python compares in float32 (NEP 50)
    ("battery float32", lambda i: dataclasses.replace(i, navdata=dataclasses.replace(
        i.navdata, battery_pct=np.float32(20.1)))),
])
def test_numbers_not_python_floats_are_the_python_stages(name, change):
    inputs = change(_inputs(2.26, position=(0.04, -0.08, 1.02)))

    def floor(t: Tick) -> None:
        t.supervisor.cfg = t.supervisor.cfg.model_copy(update={"battery_floor_pct": 20.1})

    fast, slow = _step_both(inputs, 1.26, setup=floor)
    assert fast == slow


@pytest.mark.parametrize("update", [
    {"battery_floor_pct": np.float32(20.1)},   # battery 20.1 > float32(20.1) in float32: no
    {"max_speed_mps": np.float32(0.1)},
])
def test_limits_not_python_floats_are_the_python_stages(update):
    inputs = _inputs(2.26, position=(0.04, -0.08, 1.02))
    inputs = dataclasses.replace(inputs, navdata=dataclasses.replace(inputs.navdata, battery_pct=20.1000004))

    def limit(t: Tick) -> None:
        t.supervisor.cfg = t.supervisor.cfg.model_copy(update=update)

    fast, slow = _step_both(inputs, 1.26, setup=limit)
    assert fast == slow


@pytest.mark.parametrize("bits", [1 << 63, 1 << 64, 1 << 64 | 1 << 22])
def test_a_state_word_beyond_int64_is_the_python_stages(bits):
    """(The compiled call raised OverflowError where check_feedback masks the word.)"""
    inputs = _inputs(2.26, position=(0.04, -0.08, 1.02), nav=_nav(state_bits=bits))
    fast, slow = _step_both(inputs, 1.26)
    assert fast == slow
