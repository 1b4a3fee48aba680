"""The controller's nominal tick in one compiled call (runtime/control_tick.py): the same rows,
events and stage state as the two-call path and as the Python stages, the solver's verdicts
it leaves to Python, and every precondition that leaves the tick to them with nothing
written."""

from __future__ import annotations

import copy
import dataclasses
import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.diverging import DivergingSolver
from ardrone_nmpc.control.newton import NewtonGMRESController
from ardrone_nmpc.core.entry_points import VettedCall
from ardrone_nmpc.core.monotonic import SAME_CLOCK
from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample, TickInputs
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.trajectories import Ellipse
from ardrone_nmpc.runtime import control_tick as control_tick_module
from ardrone_nmpc.control.kernels import FLAG_BAD_INPUT, FLAG_NON_FINITE, FLAG_OK, cgmres_step
from ardrone_nmpc.control.kernels.steps import (cgmres_step_obstacles, newton_step,
                                                newton_step_obstacles)
from ardrone_nmpc.runtime.control_tick import (
    FLAG_ABOVE_TOLERANCE, KERNELS, NOT_NOMINAL, SOLVED, ControlTick, control_tick,
    control_tick_newton, control_tick_newton_obstacles, control_tick_obstacles,
    newton_step_judged, newton_step_judged_obstacles)
from ardrone_nmpc.runtime.lockstep import experiment_trajectory
from ardrone_nmpc.runs.log_columns import tick_cells
from ardrone_nmpc.runtime.tick import Tick, TickOutput
from tests.conftest import nan_equal
from tests.tick_flights import carried, fly

# the call is built only where its clock is read (core/monotonic: 64-bit Linux); elsewhere
# the two calls around the solve take its ticks (test_before_solve, test_after_solve)
pytestmark = pytest.mark.skipif(not SAME_CLOCK, reason="ControlTick is built on Linux only")
CONFIGS = Path(__file__).resolve().parents[2] / "configs"
_TIMES = ("solve_us", "compute_us", "tick_late_ms")  # the clock's, not the flight's
_PATHS = ("whole", "halves", "python")
NEWTON = "controller.solver.method=newton"
# Newton ticks that stop at their iterations above the tolerance (a share of them)
TIGHT = ["controller.solver.tolerance=2e-6", "controller.solver.max_newton_iterations=2"]


def config(name: str, *overrides: str):
    return load_config(CONFIGS / name, list(overrides))


def _use(tick: Tick, path: str) -> None:
    """``tick`` on one path: the whole call (as built), the two calls around the solve, or
    the Python stages alone."""
    if path != "whole":
        tick.control_tick = None
    if path == "python":
        tick.before_solve = tick.after_solve = None


def _fly(cfg, path: str, monkeypatch, lane=None) -> tuple:
    """A lockstep flight on ``path``: its rows, events, the stages' state after each tick,
    and the compiled call's answers (all done, solved and left to Python, declined);
    ``lane`` in ``Tick._nominal_cells``' place (default: itself)."""
    answers = {"done": 0, "solved": 0, "none": 0}

    def tally(code) -> None:
        answers["none" if code is None or code[0] == NOT_NOMINAL
                else "solved" if code[0] == SOLVED else "done"] += 1

    rows, events, states = fly(cfg, monkeypatch, use=lambda tick: _use(tick, path),
                               watch=(ControlTick, "answer", tally), lane=lane)
    return rows, events, states, answers


def _same_flights(a: tuple, b: tuple) -> None:
    rows_a, events_a, carried_a, _ = a
    rows_b, events_b, carried_b, _ = b
    assert repr(events_a) == repr(events_b)  # (repr: a NaN equal to a NaN)
    assert len(carried_a) == len(carried_b) and len(rows_a) == len(rows_b)
    for i, (p, q) in enumerate(zip(carried_a, carried_b)):
        assert p == q, f"after tick {i}: {[k for k in range(len(p)) if p[k] != q[k]]}"
    for i, (p, q) in enumerate(zip(rows_a, rows_b)):
        bad = [k for k in p if k not in _TIMES and not nan_equal(p[k], q[k])]
        assert not bad, f"row {i}: {bad}"


@pytest.mark.parametrize("name, overrides, whole", [
    ("square.yaml", ["duration_s=8"], True),  # auto delay and gain, offset-free: every stage
    ("square.yaml", ["duration_s=5", "estimator.horizontal_velocity=navdata"], True),
    ("square.yaml", ["duration_s=5", "controller.offset_free.enabled=false"], True),
    ("square.yaml", ["duration_s=5", "controller.delay_compensation_s=0"], True),
    ("square.yaml", ["duration_s=5", "faults.at_loss.start_s=2",
                     "faults.at_loss.probability=0.7"], True),
    ("square.yaml", ["duration_s=6", "faults.mocap_dropout.start_s=3",
                     "faults.mocap_dropout.duration_s=0.2"], True),  # stale: hold, hover
    ("square.yaml", ["duration_s=6", "faults.battery_floor.start_s=3"], True),  # latched
    ("square.yaml", ["duration_s=6", "faults.wind.velocity_mps=[-3.0,0,0]"], True),  # fence
    # a diverging solver (wrapped): the call outside its window, Python inside
    ("step_x.yaml", ["duration_s=6", "faults.solver_diverge.start_s=2"], True),
    ("square.yaml", ["duration_s=8", "faults.solver_diverge.start_s=3",
                     "faults.solver_diverge.duration_s=0.5"], True),
    ("hover.yaml", ["duration_s=5"], True),  # a set point: the one-call lookup's too
    ("step_x.yaml", ["duration_s=5", "reference.step_time_s=0.5"], True),
    ("step_psi.yaml", ["duration_s=5"], True),
    ("ellipse.yaml", ["duration_s=5"], True),  # curves: a table of their states
    ("lorenz.yaml", ["duration_s=5"], True),
    ("identify.yaml", ["duration_s=5"], True),
    # the thesis' Newton scheme (control_tick_newton): its ticks to tolerance, ticks stopped
    # above it (SOLVED: Python's verdict, accepted or the P fallback's), a diverging
    # solver's window, an obstacle's table
    ("square.yaml", ["duration_s=6", NEWTON], True),
    ("square.yaml", ["duration_s=6", NEWTON, *TIGHT], True),
    ("square.yaml", ["duration_s=6", NEWTON, *TIGHT,
                     "safety.solver_accept_max_iterations=false"], True),
    ("square.yaml", ["duration_s=8", NEWTON, "faults.solver_diverge.start_s=3",
                     "faults.solver_diverge.duration_s=0.5"], True),
    ("obstacle.yaml", ["duration_s=6", NEWTON], True),
    # obstacles: the call solving with the obstacle table (control_tick_obstacles); a
    # moving one's centre fed between ticks
    ("obstacle.yaml", ["duration_s=6"], True),
    ("moving_obstacle.yaml", ["duration_s=6"], True),
])
def test_a_flight_gives_the_rows_and_state_of_the_other_paths(name, overrides, whole,
                                                              monkeypatch):
    cfg = config(name, *overrides)
    flights = {path: _fly(cfg, path, monkeypatch) for path in _PATHS}
    answers = flights["whole"][3]
    if whole:  # the compiled call took the nominal ticks
        assert answers["done"] > 20
        if TIGHT[0] in overrides:  # … and left those above the tolerance to Python
            assert answers["solved"] > 5
    else:  # another solver: the call is not built
        assert answers == {"done": 0, "solved": 0, "none": 0}
    _same_flights(flights["whole"], flights["halves"])
    _same_flights(flights["whole"], flights["python"])


def _via_records(self, inputs, t_exp_s, mode, answer, t0):
    """``Tick._nominal_cells``' tick the long way: the records ``ControlTick.finish`` makes
    and ``tick_cells`` of them, as ``Tick.step`` builds a row that reads them."""
    ages_ms, x, sol, (sent, adapted) = self.control_tick.finish(inputs, t_exp_s, answer)
    sup = self.supervisor
    label = sup.record(sent.decision, mode)
    events = sup.take_events() if sup.events else []
    cells = tick_cells(t_exp_s, inputs, ages_ms, x, sol, sent, label, 0.0)
    return TickOutput.make(sent.pcmd, sent.progressive, None, sent.decision.action,
                           events + adapted, cells)


@pytest.mark.parametrize("overrides", [
    ["duration_s=8"],  # auto delay and gain (their events), offset-free
    ["duration_s=5", "estimator.horizontal_velocity=navdata",
     "controller.offset_free.enabled=false"],
    ["duration_s=6", "faults.wind.velocity_mps=[-3.0,0,0]"],  # the fence: a landing
    # a low attitude gain: most ticks of the lane saturate (their cmd_saturated text)
    ["duration_s=20", "sim.settle_s=1", "controller.attitude_gain=0.3"],
])
def test_a_row_built_from_the_answer_is_the_row_of_its_records(overrides, monkeypatch):
    """The cells of a tick done whole (``Tick._nominal_cells``: from the answer's numbers)
    are, bit for bit and of the same types, the cells ``tick_cells`` makes of the records
    (the clocks aside), and the stages carry the same state on."""
    cfg = config("square.yaml", *overrides)
    rows_a, events_a, carried_a, answers = _fly(cfg, "whole", monkeypatch)
    rows_b, events_b, carried_b, _ = _fly(cfg, "whole", monkeypatch, lane=_via_records)
    assert answers["done"] > 20  # (the lane taken: the fence lands the third flight early)
    if "controller.attitude_gain=0.3" in overrides:  # (the flight for the saturation text)
        assert sum(r["cmd_saturated"] != "0000" for r in rows_a) > 100
    assert repr(events_a) == repr(events_b) and carried_a == carried_b
    assert len(rows_a) == len(rows_b)
    for i, (p, q) in enumerate(zip(rows_a, rows_b)):
        assert list(p) == list(q), i
        bad = [k for k in p if k not in _TIMES and (repr(p[k]), type(p[k])) != (repr(q[k]),
                                                                                 type(q[k]))]
        assert not bad, f"row {i}: {bad}"
        assert all(type(p[k]) is type(q[k]) for k in _TIMES if k in p), i


# ----------------------------------------------------------------------------- one tick
def _nav(**changes) -> NavdataSample:
    nav = NavdataSample(0.0, FlightMode.FLYING, 80.0, 1.5, -2.0, 0.0, 1.0, 0.1, -0.05, 0.0)
    return dataclasses.replace(nav, **changes)


def _inputs(t_s: float, position=(0.0, 0.0, 1.0), nav=None, mocap_age_s=0.01) -> TickInputs:
    pose = MocapPose(t_s, np.array(position, dtype=float), np.zeros(3), 0.02)
    return TickInputs(t_s, pose, t_s - mocap_age_s, _nav() if nav is None else nav, t_s - 0.02,
                      None, -math.inf)


def _flown(path: str, ticks: int = 4, name: str = "square.yaml",
           *overrides: str) -> tuple[Tick, list]:
    """A flight's tick after ``ticks`` ticks of its start (the first solves in Python), on
    ``path``, and their rows."""
    cfg = config(name, *overrides)
    tick = Tick(cfg, experiment_trajectory(cfg))
    _use(tick, path)
    rows = [_step(tick, k) for k in range(ticks)]
    return tick, rows


def _step(tick: Tick, k: int, **changes) -> dict:
    t_s = 2.0 + 0.065 * k
    position = (0.01 * k, -0.02 * k, 1.0 + 0.005 * k)
    return tick.step(_inputs(t_s, position=position, **changes), t_exp_s=t_s - 1.0).row


def _same_ticks(rows_a: list, rows_b: list) -> None:
    assert len(rows_a) == len(rows_b)
    for a, b in zip(rows_a, rows_b):
        assert [k for k in a if k not in _TIMES and not nan_equal(a[k], b[k])] == []
        assert list(a) == list(b)


def test_the_compiled_ticks_are_the_python_stages():
    (whole, rows), (python, python_rows) = _flown("whole", 8), _flown("python", 8)
    _same_ticks(rows, python_rows)
    assert carried(whole) == carried(python)
    assert rows[-1]["solver_status"] == "ok"
    assert 0.0 < rows[-1]["solve_us"] < rows[-1]["compute_us"]  # the solve alone


@pytest.mark.parametrize("setup", [
    # the solver's answer above divergence_residual: solve_prepared's recovery, in Python
    lambda tick: setattr(tick.control.nmpc, "divergence_residual", 1e-12),
    # a tilt beyond the cap: the after-stages decline, Python clips and flags
    lambda tick: setattr(tick.supervisor, "max_tilt_rad", 1e-4),
])
def test_a_solve_left_to_python_is_the_python_stages(setup, monkeypatch):
    codes = []
    kernel = control_tick_module.control_tick

    def spy(*args):
        answer = kernel(*args)
        codes.append(answer[0])
        return answer

    (whole, _), (python, _) = _flown("whole"), _flown("python")
    # through the call's kernel, the spy, every tick: no entry point vetted for it
    whole.control_tick.kernel = spy
    whole.control_tick._call = VettedCall(spy, *control_tick_module._KINDS)
    whole.control_tick._entry = None
    asked = []  # the after-stages' own compiled call: not asked after a SOLVED (it would
    # decline), asked on the ticks the whole call does not take (a solver recovered afresh)
    whole.after_solve.nominal = lambda *args: asked.append(args)
    rows, python_rows = [], []
    for tick, out in ((whole, rows), (python, python_rows)):
        setup(tick)
        out += [_step(tick, k) for k in range(4, 8)]
    assert codes and set(codes) == {SOLVED} and len(codes) + len(asked) == 4
    _same_ticks(rows, python_rows)
    assert carried(whole) == carried(python)


@pytest.mark.parametrize("setup", [
    lambda tick: setattr(tick.control.nmpc, "_t0_s", None),  # the first solve: initialises
    lambda tick: setattr(tick.control.nmpc, "_ramped", True),  # a horizon ramp: Δτ asked
    lambda tick: setattr(tick.supervisor, "_solver_fallback", True),  # distrusted solver
    lambda tick: setattr(tick.supervision, "attitude_gain", np.float32(0.9)),
    lambda tick: setattr(tick.control, "vz_lead_s", np.float64(0.065)),
    lambda tick: setattr(tick.supervisor, "max_tilt_rad", np.float32(0.35)),  # float32 clip
    lambda tick: setattr(tick.supervisor, "_latched", "land"),
])
def test_a_precondition_not_held_leaves_the_tick_with_nothing_written(setup):
    tick, _ = _flown("whole")
    setup(tick)
    before = carried(tick)
    assert tick.control_tick.nominal(_inputs(2.3), 1.3, tick.trajectory) is None
    assert carried(tick) == before


@pytest.mark.parametrize("inputs, answer", [
    (_inputs(2.3, mocap_age_s=0.5), False),                  # stale mocap
    (_inputs(2.3, nav=_nav(battery_pct=5.0)), False),         # the battery floor
    (_inputs(2.3, nav=_nav(state_bits=1 << 22)), False),      # a fault bit
    (_inputs(2.3, nav=_nav(roll_deg=60.0)), False),           # tilted beyond the cap
    (_inputs(2.3, position=(100.0, 0.0, 1.0)), False),        # outside the geofence
    (_inputs(2.3, position=(math.nan, 0.0, 1.0)), False),     # not finite
    (_inputs(np.float64(2.3)), None),                  # a numpy time: Python's ages (no call)
])
def test_a_tick_not_nominal_before_the_solve_writes_nothing(inputs, answer):
    """False: the kernel declined (and before_solve's call would: the tick skips it); None:
    the Python side did, before any call."""
    tick, _ = _flown("whole")
    before = carried(tick)
    assert tick.control_tick.nominal(inputs, 1.3, tick.trajectory) is answer
    assert carried(tick) == before
    if answer is False:
        assert tick.before_solve.nominal(inputs, 1.3, tick.trajectory) is None


def test_the_kernel_answers_not_nominal_before_any_write():
    tick, _ = _flown("whole")
    ct = tick.control_tick
    args = list(ct.before.arguments(_inputs(2.3), 1.3, tick.trajectory))
    args[4] = -math.inf  # the battery: below any floor
    before = carried(tick)
    nmpc, control, after = tick.control.nmpc, tick.control, ct.after
    _, mem, iprm = nmpc._step
    offset, flags = after._offset
    answer = control_tick_module.control_tick(
        *args, 0.0, tick.delay._next, mem, iprm, control._horizon, False,
        nmpc.divergence_residual, False, control.vz_lead_s, control._vz_max_mps,
        tick.supervisor.max_tilt_rad, 1.0, *tick.supervision._scales, after._response_state, 1,
        offset, flags)
    assert answer[0] == NOT_NOMINAL
    assert carried(tick) == before


@pytest.mark.parametrize("name", ["hover.yaml", "step_x.yaml", "step_z.yaml", "step_psi.yaml",
                                  "r_case1.yaml", "stability_n5_dtau03.yaml", "square.yaml",
                                  "ellipse.yaml", "lorenz.yaml", "identify.yaml"])
def test_the_set_points_and_waypoints_take_the_call(name):
    """Hover and step references are looked up by the waypoint kernel
    (``reference/experiment.lookup_args``), curves read from a table of their states
    (``reference/experiment.tabulated``): their nominal ticks are the one call's."""
    cfg = config(name)
    assert Tick(cfg, experiment_trajectory(cfg)).control_tick is not None


class _OwnEllipse(Ellipse):
    def state_at(self, t_s):
        return super().state_at(t_s)


class _OwnNewton(NewtonGMRESController):
    def _tick(self, x, ref, initialise: bool) -> int:
        return super()._tick(x, ref, initialise)


@pytest.mark.parametrize("build", [
    # the P controller against a curve's table (runtime/control_tick_p: waypoints only)
    lambda cfg: Tick(config("ellipse.yaml", "controller.kind=p"),
                     experiment_trajectory(config("ellipse.yaml"))),
    # a Newton solver's subclass (its own tick)
    lambda cfg: Tick(config("square.yaml", NEWTON), experiment_trajectory(cfg),
                     wrap_solver=lambda nmpc: _OwnNewton.from_config(
                         config("square.yaml", NEWTON).controller, period_s=0.065)),
    # a reference neither looked up nor tabulated (a curve's subclass: its own state_at)
    lambda cfg: Tick(config("ellipse.yaml"), HoldStartThen(_OwnEllipse())),
])
def test_a_solver_the_kernel_is_not_is_not_taken(build):
    """(A reference the compiled calls do not take, too.)"""
    assert build(config("square.yaml")).control_tick is None


def test_a_wrapped_solver_s_marked_ticks_are_its_own_solve_s(monkeypatch):
    """A :class:`DivergingSolver` around the plain solver (marking 1.2 s ≤ t < 1.4 s): the
    call is built on the inner solver's memory and takes the unmarked ticks; a marked tick
    it leaves to the wrapper's solve with nothing done — the rows and state of the Python
    stages, the marked ticks' solves diverged."""
    answered = []
    answer = ControlTick.answer

    def watched(self, inputs, t_exp_s, traj):
        got = answer(self, inputs, t_exp_s, traj)
        answered.append((t_exp_s, got is not None))
        return got

    monkeypatch.setattr(ControlTick, "answer", watched)
    cfg = config("square.yaml")
    flown = {}
    for path in ("whole", "python"):
        tick = Tick(cfg, experiment_trajectory(cfg), wrap_solver=lambda nmpc: DivergingSolver(
            nmpc, lambda t_s: 1.2 <= t_s < 1.4))
        _use(tick, path)
        flown[path] = tick, [_step(tick, k) for k in range(12)]
    (whole, rows), (python, python_rows) = flown["whole"], flown["python"]
    assert whole.control_tick.nmpc is whole.control.nmpc.inner
    _same_ticks(rows, python_rows)
    assert carried(whole) == carried(python)
    assert [r["solver_status"] == "diverged" for r in rows[4:7]] == [True] * 3
    assert {t for t, took in answered if 1.2 <= t < 1.4} and not any(
        took for t, took in answered if 1.2 <= t < 1.4)
    # (tick 0 solves first: Python; ticks 1–3 the call)
    assert [took for t, took in answered if t < 1.2] == [False, True, True, True]


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda t: pickle.loads(pickle.dumps(t))])
def test_a_copied_tick_calls_the_kernel_on_its_own_stages(copier):
    original, _ = _flown("whole")
    clone = copier(original)
    ct = clone.control_tick
    assert ct.before is clone.before_solve and ct.after is clone.after_solve
    assert ct.control is clone.control and ct.nmpc is clone.control.nmpc
    assert ct.delay is clone.delay and ct._entry is None
    state = carried(original)
    python, _ = _flown("python")
    _same_ticks([_step(clone, k) for k in range(4, 6)], [_step(python, k) for k in range(4, 6)])
    assert carried(original) == state  # the original's stages untouched


def test_the_entry_point_is_taken_only_with_the_arrays_it_vetted():
    tick, _ = _flown("whole")
    ct = tick.control_tick
    assert ct._entry is not None and ct._vetted[0] is tick.estimation._state
    fresh = tick.control._x_solve.copy()  # a new array of the same kind
    tick.control._x_solve = fresh
    _step(tick, 4)
    assert ct._entry is not None and ct._vetted[2] is fresh


@pytest.mark.parametrize("setup", [
    lambda tick: setattr(tick.supervision, "attitude_gain", 1.25),  # as the response fit
    lambda tick: setattr(tick.control, "vz_lead_s", 0.04),
    lambda tick: setattr(tick.supervision, "_scales", (0.3, 0.8, 1.5)),
])
def test_a_setting_a_writer_replaces_is_the_next_call_s(setup):
    """The call's tail (ControlTick._prepare) is made again when a writer replaces what it
    was made of: the next tick computes with the new value, as the Python stages do."""
    (whole, _), (python, _) = _flown("whole"), _flown("python")
    ct = whole.control_tick
    tail, entry = ct._tail, ct._entry
    assert tail and entry is not None
    for tick in (whole, python):
        setup(tick)
    _same_ticks([_step(whole, k) for k in range(4, 7)], [_step(python, k) for k in range(4, 7)])
    assert carried(whole) == carried(python)
    assert ct._tail != tail and ct._entry is not None  # made again, and vetted again
    kept = ct._tail
    _step(whole, 7)
    assert ct._tail is kept  # nothing replaced: the same tail


def test_a_platform_whose_clock_the_kernel_does_not_read_takes_the_two_calls(monkeypatch):
    """Not Linux (``core/monotonic.SAME_CLOCK`` False): the call is not built, so it is never
    compiled — its clock_gettime would not link on Windows, nor time on macOS —, and the
    two calls around the solve take the ticks."""
    from ardrone_nmpc.core import monotonic

    monkeypatch.setattr(monotonic, "SAME_CLOCK", False)
    (tick, rows), (python, python_rows) = _flown("whole", 6), _flown("python", 6)
    assert tick.control_tick is None and tick.before_solve is not None
    _same_ticks(rows, python_rows)
    assert 0.0 < rows[-1]["solve_us"]  # timed in Python


def _heading_step(tick: Tick, k: int, psi_rad) -> dict:
    t_s = 2.0 + 0.065 * k
    pose = MocapPose(t_s, np.array((0.01 * k, -0.02 * k, 1.0)), np.zeros(3), psi_rad)
    return tick.step(TickInputs(t_s, pose, t_s - 0.01, _nav(), t_s - 0.02, None, -math.inf),
                     t_exp_s=t_s - 1.0).row


def test_an_int_number_on_the_vetting_tick_does_not_make_later_floats_ints():
    """The entry point kept after a dispatcher's call is the floats' (as the warm-up's call):
    one kept for an int heading (``MocapPose(…, 0)``) would unbox the next ticks' headings by
    ``int()`` — 0.3 read as 0 — and fly another flight than the Python stages."""
    (whole, _), (python, _) = _flown("whole"), _flown("python")
    whole.control_tick._entry = None  # the next tick through the dispatcher, then vetted
    headings = (0, 0.3, 0.3, -0.2)
    rows = [_heading_step(whole, 4 + k, psi) for k, psi in enumerate(headings)]
    python_rows = [_heading_step(python, 4 + k, psi) for k, psi in enumerate(headings)]
    assert whole.control_tick._entry is not None  # (the entry point took the later ticks)
    _same_ticks(rows, python_rows)
    assert carried(whole) == carried(python)


def test_a_solve_bound_after_the_tick_was_built_is_called_as_the_two_calls_call_it():
    """``Control._solve_prepared`` rebound after ``Tick`` was built (a wrapper: a recorder,
    an injected fault): the two calls around the solve call it every tick, so the whole call
    takes no tick while it is not the solver's own — and takes them again once it is."""
    tick, _ = _flown("whole")
    control, ct = tick.control, tick.control_tick
    own, solved = control._solve_prepared, []

    def recorded(t_s, x, ref):
        solved.append(t_s)
        return own(t_s, x, ref)

    control._solve_prepared = recorded
    assert ct.nominal(_inputs(2.3), 1.3, tick.trajectory) is None  # nothing done
    _step(tick, 4)
    assert solved == [2.0 + 0.065 * 4 - 1.0]
    control._solve_prepared = own
    assert ct.nominal(_inputs(2.0 + 0.065 * 5), 1.0 + 0.065 * 5, tick.trajectory)
    assert solved == [2.0 + 0.065 * 4 - 1.0]


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda t: pickle.loads(pickle.dumps(t))])
def test_a_copied_tick_keeps_its_call(copier):
    clone = copier(_flown("whole")[0])
    assert clone.control_tick._solve is clone.control._solve_prepared  # (taken: not None)
    assert clone.control_tick.nominal(_inputs(2.3), 1.3, clone.trajectory)


@pytest.mark.parametrize("name, kernel", [("square.yaml", control_tick),
                                          ("obstacle.yaml", control_tick_obstacles),
                                          ("moving_obstacle.yaml", control_tick_obstacles)])
def test_the_call_solves_with_the_solvers_kernel(name, kernel):
    """An obstacle flight's call is the twin calling ``cgmres_step_obstacles``; the others'
    the obstacle-free one (whose specialisation an obstacle flight does not change)."""
    tick, _ = _flown("whole", 2, name)
    assert tick.control_tick.kernel is kernel
    assert KERNELS[tick.control.nmpc._step[0]] is kernel
    clone = pickle.loads(pickle.dumps(tick))  # (kept by the kernel's name)
    assert clone.control_tick.kernel is kernel
    python, _ = _flown("python", 2, name)
    _same_ticks([_step(clone, k) for k in range(2, 6)], [_step(python, k) for k in range(2, 6)])
    assert clone.control_tick._entry is not None  # (the compiled call took them)
    assert control_tick_obstacles.py_func.__globals__["cgmres_step"] is cgmres_step_obstacles
    assert control_tick.py_func.__globals__["cgmres_step"] is cgmres_step


@pytest.mark.parametrize("name, kernel, step, judged", [
    ("square.yaml", control_tick_newton, newton_step, newton_step_judged),
    ("obstacle.yaml", control_tick_newton_obstacles, newton_step_obstacles,
     newton_step_judged_obstacles)])
def test_a_newton_flight_s_call_solves_with_the_newton_kernel(name, kernel, step, judged):
    """The thesis' Newton scheme's call is the twin whose solve is the solver's own Newton
    kernel (with or without the obstacle table), its active set passed in: the rows of the
    Python stages, the copy's too."""
    tick, _ = _flown("whole", 2, name, NEWTON)
    assert tick.control_tick.kernel is kernel and KERNELS[step] is kernel
    assert tick.control.nmpc.newton_call[0] is step
    assert kernel.py_func.__globals__["cgmres_step"] is judged
    assert judged.py_func.__globals__["newton_step"] is step
    clone = pickle.loads(pickle.dumps(tick))  # (kept by the kernel's name)
    assert clone.control_tick.kernel is kernel
    assert clone.control.nmpc.newton_call[3] is clone.control.nmpc.active  # (its own)
    python, _ = _flown("python", 2, name, NEWTON)
    _same_ticks([_step(clone, k) for k in range(2, 8)], [_step(python, k) for k in range(2, 8)])
    assert clone.control_tick._entry is not None  # (the compiled call took them)
    np.testing.assert_array_equal(clone.control.nmpc.active, python.control.nmpc.active)


def test_a_newton_tick_above_its_tolerance_is_judged_in_python():
    """A Newton tick that stops at its iterations above the tolerance answers SOLVED with
    :data:`FLAG_ABOVE_TOLERANCE` (no flag of the kernels'), and is judged as
    ``solve_prepared`` judges it: ``max-iterations``, its ‖F‖ above the tolerance."""
    assert FLAG_ABOVE_TOLERANCE not in (FLAG_OK, FLAG_BAD_INPUT, FLAG_NON_FINITE)
    tick, _ = _flown("whole", 2, "square.yaml", NEWTON, "controller.solver.tolerance=1e-12",
                     "controller.solver.max_newton_iterations=1")
    ct = tick.control_tick
    inputs, t_exp_s = _inputs(2.2, position=(0.02, -0.04, 1.01)), 1.2
    answer = ct.answer(inputs, t_exp_s, tick.trajectory)
    assert answer[0] == SOLVED and answer[3] == FLAG_ABOVE_TOLERANCE
    assert answer[5] > 1e-12 and answer[7] == 1  # (‖F‖, Newton iterations)
    _, _, solution, done = ct.finish(inputs, t_exp_s, answer)
    assert done is False
    assert solution.status == "max-iterations" and not solution.result.reinitialised
