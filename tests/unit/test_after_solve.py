"""The nominal tick's stages after the solve in one compiled call (runtime/after_solve.py):
the same command, records and stage state as the Python stages, and nothing written when
the tick is not nominal."""

from __future__ import annotations

import copy
import math
import pickle
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.mapping import UNSATURATED, DroneLimits
from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample, TickInputs
from ardrone_nmpc.runtime import after_solve as after_solve_module
from ardrone_nmpc.runtime.after_solve import NOT_NOMINAL, AfterSolve, after_solve
from ardrone_nmpc.runtime.lockstep import experiment_trajectory
from ardrone_nmpc.runtime.stages import Solution
from ardrone_nmpc.runtime.tick import Tick
from tests.conftest import nan_equal
from tests.tick_flights import fly

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def config(name: str, *overrides: str):
    return load_config(CONFIGS / name, list(overrides))


def _fly(cfg, *, compiled: bool, monkeypatch) -> tuple[list, list, list, int]:
    """The rows and events of a lockstep flight, the stages' state after each tick, and how
    many ticks the compiled call took."""
    taken = [0]

    def use(tick: Tick) -> None:
        tick.control_tick = None  # this half on its own (test_control_tick: the whole)
        if not compiled:
            tick.after_solve = None

    def tally(done) -> None:
        taken[0] += done is not None

    rows, events, states = fly(cfg, monkeypatch, use=use, watch=(AfterSolve, "nominal", tally))
    return rows, events, states, taken[0]


@pytest.mark.parametrize("name, overrides", [
    ("square.yaml", ["duration_s=8"]),  # auto delay and gain, offset-free: every stage
    ("step_x.yaml", ["duration_s=6", "faults.solver_diverge.start_s=2"]),  # holds, fallback
    ("hover.yaml", ["duration_s=6", "faults.mocap_dropout.start_s=3",
                    "faults.mocap_dropout.duration_s=0.2"]),
])
def test_a_flight_gives_the_rows_and_state_of_the_python_stages(name, overrides, monkeypatch):
    cfg = config(name, *overrides)
    python_rows, python_events, python_carried, none = _fly(cfg, compiled=False,
                                                            monkeypatch=monkeypatch)
    compiled_rows, compiled_events, compiled_carried, taken = _fly(cfg, compiled=True,
                                                                   monkeypatch=monkeypatch)
    assert none == 0 and taken > len(python_rows) // 2  # most ticks took the compiled call
    assert compiled_events == python_events  # the fit's and the supervisor's, in order
    assert len(compiled_carried) == len(python_carried)
    for i, (a, b) in enumerate(zip(python_carried, compiled_carried)):  # the stages' state
        assert a == b, f"after tick {i}: {[k for k in range(len(a)) if a[k] != b[k]]}"
    assert len(compiled_rows) == len(python_rows)
    for i, (a, b) in enumerate(zip(python_rows, compiled_rows)):
        bad = [k for k in a if k not in ("solve_us", "compute_us", "tick_late_ms")
               and not nan_equal(a[k], b[k])]
        assert not bad, f"row {i}: {bad}"


# ----------------------------------------------------------------------------- one tick
def _tick() -> Tick:
    cfg = config("square.yaml")
    tick = Tick(cfg, experiment_trajectory(cfg))
    tick.control._states[:] = np.array([0.1, 0.0, -0.2, 0.0, 1.0, 0.0, 0.05])
    return tick


def _inputs(t_s: float, with_navdata: bool = True) -> TickInputs:
    nav = (NavdataSample(0.0, FlightMode.FLYING, 80.0, 1.5, -2.0, 0.0, 1.0, 0.0, 0.0, 0.0)
           if with_navdata else None)
    return TickInputs(t_s, MocapPose(t_s, np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0),
                      t_s - 0.01, nav, t_s - 0.02, None, -math.inf)


def _solution(tick: Tick, x: np.ndarray, u) -> Solution:
    u = np.array(u, dtype=float)
    c = tick.control
    return Solution(c._ref_now, x, SimpleNamespace(u=u), u, True, "ok", None, c._ref_horizon)


def _python_stages(tick: Tick, inputs: TickInputs, x, sol):
    """What Tick.step does after the solve without the compiled call."""
    decision = tick.supervisor.check_solution(sol.ok, sol.u_flown)
    cmd = tick.control.command(decision.action, sol, x, tick.supervision.vz_ref_mps)
    return tick._after(inputs, decision, x, sol, cmd)


def _values(a: np.ndarray) -> list:
    """An array's values, NaN made comparable."""
    return np.where(np.isnan(a), -1e300, a).tolist()


def _state(tick: Tick) -> list:
    """What the stages after the solve carry to the next tick."""
    s, d, integrator = tick.supervision, tick.delay, tick.offset.integrator
    return [d.ring.tolist(), d._next, d.first, d.count, s.zacc_mps2, s.vz_ref_mps,
            (s._last[0], s._last[1].tolist()) if s._last else None,
            tick.supervisor._solver_failures, _values(tick.response.estimator._state),
            _values(integrator._work), integrator._flags.tolist()]


@pytest.mark.parametrize("u, gain", [
    ((0.3, 0.05, -0.08, 0.2), 1.0),     # nothing saturated
    ((0.3, 0.05, -0.08, 0.2), 0.9),     # the gain divides roll and pitch
    ((0.3, 0.15, -0.08, 0.2), 0.6),     # roll beyond E once divided: flagged, x, y frozen
    ((0.3, 0.05, -0.08, 3.0), 1.0),     # the yaw rate beyond control_yaw
    ((40.0, 0.05, -0.08, 0.2), 1.0),    # ż clipped to control_vz_max: z frozen, not flagged
    ((-0.0, 0.0, -0.0, 0.0), 1.0),      # −0.0 sent as 0.0
])
def test_the_compiled_tick_is_the_python_stages(u, gain):
    fast, slow = _tick(), _tick()
    for k in range(4):  # a few ticks: the delay ring, the feed and the integrator move
        t_s = 2.0 + 0.065 * k
        x = np.array([0.05, 0.01, -0.1, 0.0, 1.0, 0.02, 0.04])
        for tick in (fast, slow):
            tick.supervision.attitude_gain = gain
        sent_f, events_f = fast.after_solve.nominal(_inputs(t_s), x, _solution(fast, x, u))
        sent_s, events_s = _python_stages(slow, _inputs(t_s), x, _solution(slow, x, u))
        assert events_f == events_s
        for a, b in zip(sent_f, sent_s):
            assert (a.tolist() == b.tolist() if isinstance(a, np.ndarray) else a == b)
        # (Supervision.command tells an unsaturated command by identity)
        assert (sent_f.pcmd.saturated is UNSATURATED) == (sent_s.pcmd.saturated is UNSATURATED)
        assert _state(fast) == _state(slow)


@pytest.mark.parametrize("u, tick_s, lead_s", [
    ((math.nan, 0.05, -0.08, 0.2), 2.0, None),  # the solver's input not finite: judged
    ((0.3, 0.5, -0.08, 0.2), 2.0, None),        # a tilt beyond the cap: clipped in Python
    ((0.3, 0.05, -0.08, 0.2), 2.0, -0.1),       # a negative ż lead: vz_reference_mps's
    ((0.3, 0.05, -0.08, 0.2), 2e-7, None),      # a time below 1 µs: Python's round
])
def test_a_tick_not_nominal_writes_nothing(u, tick_s, lead_s):
    tick = _tick()
    if lead_s is not None:
        tick.control.vz_lead_s = lead_s
    x = np.array([0.05, 0.01, -0.1, 0.0, 1.0, 0.02, 0.04])
    before = _state(tick)
    assert tick.after_solve.nominal(_inputs(tick_s), x, _solution(tick, x, u)) is None
    assert _state(tick) == before


def test_the_kernel_answers_not_nominal_before_any_write():
    tick = _tick()
    ring = tick.delay.ring
    ring[:] = 7.0
    x = np.zeros(7)
    nothing = after_solve_module._NOTHING
    code = after_solve(0.3, math.inf, 0.0, 0.0, 0.0, 0.065, 0.7, 0.35, 1.0, 0.2, 0.7, 1.7, ring,
                       0, nothing, 0, 0.0, 0.0, 0.0, 1.0, x, x, tick.control._states[1:],
                       nothing, after_solve_module._NO_FLAGS)[0]
    assert code == NOT_NOMINAL
    assert (ring == 7.0).all()


@pytest.mark.parametrize("copier", [copy.deepcopy, lambda t: pickle.loads(pickle.dumps(t))])
def test_a_copied_tick_calls_the_kernel_on_its_own_stages(copier):
    clone = copier(_tick())
    after = clone.after_solve
    assert after._response_state is clone.response.estimator._state
    assert after._offset[0] is clone.offset.integrator._work
    assert after._offset[1] is clone.offset.integrator._flags
    for name in ("supervisor", "control", "supervision", "delay", "response", "offset"):
        assert getattr(after, name) is getattr(clone, name)


# ------------------------------------------------------------------------- the twin, bit for bit
def _typed(v) -> tuple:
    """A number's type and bits (a numpy scalar is not the float it equals)."""
    if isinstance(v, (float, np.floating)):
        return type(v), np.float64(v).tobytes()
    return type(v), v


def _sent_typed(sent) -> tuple:
    p, f = sent.pcmd, sent.flown
    return (tuple(_typed(a) for a in (p.roll_frac, p.pitch_frac, p.gaz_frac, p.yaw_frac)),
            p.saturated, sent.u.dtype, sent.u.tobytes(), sent.u.flags.writeable,
            sent.progressive, sent.decision,
            None if f is None else tuple(_typed(a) for a in (f.vz_ref_mps, f.phi_rad,
                                                               f.theta_rad, f.psirate_radps)),
            sent.saturated)


def _state_typed(tick: Tick) -> list:
    """:func:`_state` with the types of the supervision's numbers, the response's
    Python-side state and the supervisor's whole solver chain."""
    s, r, sup = tick.supervision, tick.response, tick.supervisor
    return _state(tick) + [_typed(s.zacc_mps2), _typed(s.vz_ref_mps), tick.delay._pushed,
                           r.estimator._estimate is None, r._next_fit_s,
                           (sup._solver_failures, sup._solver_good, sup._solver_fallback)]


def _both_paths(fast: Tick, slow: Tick, u, t_s: float, nav: bool = True):
    """One tick after the solve on ``fast`` (the compiled call, or the Python stages where it
    declines, as Tick.step) and on ``slow`` (the Python stages): the same, to the type."""
    x = np.array([0.05, 0.01, -0.1, 0.0, 1.0, 0.02, 0.04])
    inputs = _inputs(t_s, nav)
    done = fast.after_solve.nominal(inputs, x, _solution(fast, x, u))
    compiled = done is not None
    if not compiled:
        done = _python_stages(fast, inputs, x, _solution(fast, x, u))
    want = _python_stages(slow, inputs, x, _solution(slow, x, u))
    assert _sent_typed(done[0]) == _sent_typed(want[0])
    assert done[1] == want[1]
    assert _state_typed(fast) == _state_typed(slow)
    return compiled


@pytest.mark.parametrize("setting", [
    ("gain", np.float32(0.9)),      # Python divides in float32 (NEP 50): other bits
    ("gain", np.float64(0.8)),
    ("gain", 2),                    # an int: the same quotient
    ("lead", np.float64(0.05)),     # a numpy ż: Supervision's general path (a writeable u)
    ("vz_max", np.float64(0.3)),    # the clip makes ż a numpy scalar
    ("limits", (np.float64(0.2094), 0.7, 1.745)),  # numpy fractions
])
def test_numbers_that_are_not_python_floats_give_what_the_python_stages_give(setting):
    fast, slow = _tick(), _tick()
    name, value = setting
    for tick in (fast, slow):
        if name == "gain":
            tick.supervision.attitude_gain = value
        elif name == "lead":
            tick.control.vz_lead_s = value
        elif name == "vz_max":
            tick.control._vz_max_mps = value
        else:
            tick.supervision.limits = DroneLimits(*value)
    for k in range(3):
        _both_paths(fast, slow, (2.5, 0.05, -0.08, 0.2), 2.0 + 0.065 * k)


def test_random_ticks_give_what_the_python_stages_give():
    """The kernel's twins of the Python stages (check_solution's test, Control.command's ż,
    the tilt cap, pcmd_of_floats, frozen_axes, the flags) against them over random
    commands with NaN, ±inf, ±0.0 and values beyond every limit, gains, tilt caps, both ż
    sources, with and without navdata, times the kernel rounds and times it leaves to
    Python."""
    rng = np.random.default_rng(26)
    specials = [math.nan, math.inf, -math.inf, 0.0, -0.0, 0.35, -0.35, 1e308, 5e-324]

    def pick(values):
        return values[int(rng.integers(len(values)))]

    taken = []
    for _ in range(40):
        fast, slow = _tick(), _tick()
        gain, cap, lead = pick([1.0, 0.9, 1.3]), pick([0.05, 0.35, 0.6]), pick([0.0, 0.065, 0.5])
        from_commands = bool(rng.random() < 0.3)
        for tick in (fast, slow):
            tick.supervision.attitude_gain = gain
            tick.supervisor.max_tilt_rad = cap
            tick.control.vz_lead_s = lead
            tick.control.vz_from_commands = from_commands
        for k in range(5):
            u = [float(v) for v in rng.normal(size=4) * pick([0.05, 0.3, 2.0])]
            if rng.random() < 0.3:
                u[int(rng.integers(4))] = pick(specials)
            t_s = pick([2.0 + 0.065 * k, 3.0000005 + 0.065 * k, 2e-7])
            taken.append(_both_paths(fast, slow, u, t_s, nav=bool(rng.random() < 0.8)))
    assert 30 < sum(taken) < len(taken) - 30  # both paths, each many times
