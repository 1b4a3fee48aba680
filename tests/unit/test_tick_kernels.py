"""The tick's one-call NMPC inputs (``runtime/tick_kernels.nmpc_inputs``, issue 26) give the bits
of the Python they replace: ``DelayPrediction.predict``, the horizon's times,
``HoldStartThen.state_at`` of a waypoint trajectory or a set point (hover, step) and
``ReferenceIntegrator.shifted`` — and ``Control.solve`` answers the same through either path."""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.schema import ReferenceConfig
from ardrone_nmpc.control.mapping import command_scales
from ardrone_nmpc.control.solver import make_nmpc
from ardrone_nmpc.core.types import STATE_DIM
from ardrone_nmpc.estimation.disturbance import ReferenceIntegrator
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.trajectories import Step, Waypoints, make_trajectory
from ardrone_nmpc.runtime.stages import Control, DelayPrediction, OffsetFree
from ardrone_nmpc.runtime.tick import effective_controller
from ardrone_nmpc.runtime.tick_kernels import W_HEAD, nmpc_inputs, nmpc_work, nmpc_work_views

PERIOD_S = 0.065
ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def _waypoint_references():
    square = make_trajectory(ReferenceConfig(kind="square"), duration_s=25.0)
    altitudes = make_trajectory(ReferenceConfig(kind="square_altitudes"), duration_s=25.0)
    path = Waypoints([0.0, 2.0, 3.5, 4.0], [[0, 0, 1], [1, 0, 1], [1, -1, 1.2], [0.5, -1, 1.2]],
                     [0.0, 0.5, 3.0, -3.0])
    hover = make_trajectory(ReferenceConfig(kind="hover", start_m=(0.3, -0.2, 1.1)))
    step = Step([0.0, 0.0, 1.0], 0.0, [-1.5, 0.5, 1.2], 1.0, step_time_s=1.0)
    settle_step = Step([0.2, 0.0, 1.0], -0.5, [0.2, 0.0, 1.0], 2.0, step_time_s=-0.2)
    return [HoldStartThen(t) for t in (square, altitudes, path, hover, step, settle_step)]


def _delay(pending: int) -> DelayPrediction:
    delay = DelayPrediction(0.3, PERIOD_S, max_delay_s=0.6)
    rng = np.random.default_rng(pending)
    for _ in range(pending):
        delay.push(rng.uniform(-0.3, 0.3, 4))
    return delay


@pytest.mark.parametrize("pending", [0, 1, 7, 12])
@pytest.mark.parametrize("shift", [None, np.array([0.02, -0.01, 0.005, 0.03])])
def test_nmpc_inputs_is_the_python_it_replaces_bit_for_bit(pending, shift):
    x = np.array([0.1, 0.3, -0.2, 0.1, 1.05, -0.02, 0.2])
    n = 16
    for traj in _waypoint_references():
        assert traj.waypoint_args is not None
        delay = _delay(pending)
        for t_s in (-2.0, -0.3, -0.07, 0.0, 1e-9, 0.94, 1.0, 2.5, 4.99, 12.3, 30.0, math.nan):
            for dtau in (0.08, 0.1):
                offsets = np.zeros(n + 2)
                np.multiply(dtau, np.arange(n + 1, dtype=np.float64), out=offsets[1:])
                # the Python path (runtime/stages.py before issue 26's fusion)
                x_py = delay.predict(x)
                times = np.add(t_s + delay.lead_s, offsets)
                times[0] = t_s
                states_py = traj.state_at(times)
                horizon_py = (states_py[1:] if shift is None
                              else _integrator(shift).shifted(states_py[1:]))
                # the one call
                sent, first, count = delay.pending()
                x_k = np.full(STATE_DIM, np.nan) if count else x
                states = np.full((n + 2, STATE_DIM), np.nan)
                work, rows = nmpc_work(delay.period_s, n + 2, traj.waypoint_args)
                work_offsets, _, _, horizon = nmpc_work_views(work)
                work_offsets[:] = offsets
                horizon[:] = np.nan
                # the rollout's scratch after the horizon, any contents: the same bits
                scratch = work[W_HEAD + 3 * (n + 2) + (n + 1) * STATE_DIM:]
                scratch[:5 * STATE_DIM] = np.nan
                nmpc_inputs(x, sent, first, count, x_k, t_s, delay.lead_s,
                            np.zeros(0) if shift is None else shift, states, work, rows)
                assert (count > 0) == (x_py is not x)
                assert x_k.tobytes() == x_py.tobytes()
                assert states.tobytes() == states_py.tobytes(), (t_s, dtau)
                if shift is not None:
                    assert horizon.tobytes() == horizon_py.tobytes()


def _integrator(shift: np.ndarray) -> ReferenceIntegrator:
    ones = (1.0,) * 4
    integrator = ReferenceIntegrator(ones, ones, ones, ones, ones, PERIOD_S)
    integrator.shift[:] = shift
    return integrator


class _NotHeld(HoldStartThen):
    """The same reference through the general path (only HoldStartThen itself takes the
    one-call path)."""


@pytest.mark.parametrize("name", ["square.yaml", "hover.yaml", "step_x.yaml", "ellipse.yaml",
                                  "lorenz.yaml", "identify.yaml"])  # (curves: a table's)
@pytest.mark.parametrize("shifted", [False, True])
def test_control_solves_the_same_through_either_path(shifted, name):
    step_within = ["reference.step_time_s=0.5"] if name.startswith("step") else []
    cfg = load_config(str(ROOT / "configs" / name), step_within)
    limits = command_scales(cfg.drone)
    solutions = []
    for wrap in (HoldStartThen, _NotHeld):
        traj = wrap(make_trajectory(cfg.reference, duration_s=cfg.duration_s))
        delay = DelayPrediction(0.26, PERIOD_S)
        nmpc = make_nmpc(effective_controller(cfg.controller, limits), period_s=PERIOD_S)
        control = Control(cfg, limits, nmpc, delay)
        offset = OffsetFree(cfg.controller.offset_free, PERIOD_S) if shifted else None
        x = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
        run = []
        for k in range(40):
            t = -1.0 + k * PERIOD_S
            if offset is not None:  # an offset-free shift that changes every tick
                offset.integrator.shift[:] = 0.01 * np.cos(np.arange(4) + k)
            sol = control.solve(t, x, traj, offset)
            delay.push(sol.result.u)
            x = x + 0.01 * np.sin(np.arange(STATE_DIM) + k)
            run.append((sol.ref_now.tobytes(), sol.x_solve.tobytes(), sol.result.u.tobytes(),
                        sol.ref_horizon.tobytes(), sol.status, sol.ok))
        solutions.append(run)
    assert solutions[0] == solutions[1]



def test_the_fast_paths_answer_is_the_stages_own_and_its_result_the_answers_own():
    """Against a waypoint reference ``Control.solve`` writes its answer's ``ref_now``,
    ``x_solve`` and ``ref_horizon`` into the stage's own arrays (the next solve overwrites
    them, as the estimate's): what the tick reads within the tick is this solve's; the
    solver's ``result`` (its ``u``) stays each answer's own."""
    cfg = load_config(str(ROOT / "configs" / "square.yaml"))
    limits = command_scales(cfg.drone)
    traj = HoldStartThen(make_trajectory(cfg.reference, duration_s=cfg.duration_s))
    delay = DelayPrediction(0.26, PERIOD_S)
    nmpc = make_nmpc(effective_controller(cfg.controller, limits), period_s=PERIOD_S)
    control = Control(cfg, limits, nmpc, delay)
    x = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    delay.push(np.array([0.1, 0.0, 0.0, 0.0]))  # a pending input: x_solve is not x
    first = control.solve(2.0, x, traj)
    kept = (first.ref_now.copy(), first.x_solve.copy(), first.ref_horizon.copy(),
            first.result.u.copy())
    np.testing.assert_array_equal(kept[0], traj.state_at(2.0)[0])
    delay.push(first.result.u)
    second = control.solve(2.0 + PERIOD_S, x, traj)
    assert second.ref_now is first.ref_now and second.x_solve is first.x_solve
    assert second.ref_horizon is first.ref_horizon
    np.testing.assert_array_equal(second.ref_now, traj.state_at(2.0 + PERIOD_S)[0])
    assert first.ref_now.tobytes() != kept[0].tobytes()  # overwritten, as documented
    assert second.result.u is not first.result.u
    assert first.result.u.tobytes() == kept[3].tobytes()


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
@pytest.mark.parametrize("shifted", [False, True])
def test_a_copied_control_stage_solves_from_its_own_arrays(how, shifted):
    """A deep copy or a pickle of the control stage after its first fast-path solve: its
    views (the reference now and over the horizon, the shifted horizon, the offsets) are
    views of its own copied arrays again — the reference it logs and the horizon it hands
    the solver are this tick's, as the original's, not a stale copy made at the copy. (The
    copied solver's answer and delay pushes are not: theirs are their classes' matter.)"""
    import copy
    import pickle

    cfg = load_config(str(ROOT / "configs" / "square.yaml"))
    limits = command_scales(cfg.drone)
    traj = HoldStartThen(make_trajectory(cfg.reference, duration_s=cfg.duration_s))
    nmpc = make_nmpc(effective_controller(cfg.controller, limits), period_s=PERIOD_S)
    control = Control(cfg, limits, nmpc, DelayPrediction(0.26, PERIOD_S))
    offset = OffsetFree(cfg.controller.offset_free, PERIOD_S) if shifted else None
    x = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    control.solve(1.0, x, traj, offset)
    control.delay.push(np.array([0.1, 0.02, -0.01, 0.0]))  # pending: x_solve is not x
    clone = (copy.deepcopy(control) if how == "deepcopy"
             else pickle.loads(pickle.dumps(control)))
    runs = []
    for stage in (control, clone):
        horizons = []
        solve = stage._solve_prepared  # the horizon each solve gets, recorded

        def recorded(t_s, x_solve, horizon, solve=solve, horizons=horizons):
            horizons.append(horizon.tobytes())
            return solve(t_s, x_solve, horizon)

        stage._solve_prepared = recorded
        run = []
        for k in range(1, 4):
            if offset is not None:  # a shift that changes every tick
                offset.integrator.shift[:] = 0.01 * np.cos(np.arange(4) + k)
            sol = stage.solve(1.0 + k * PERIOD_S, x, traj, offset)
            run.append((sol.ref_now.tobytes(), sol.ref_horizon.tobytes(),
                        sol.x_solve.tobytes(), horizons[-1]))
        runs.append(run)
    assert runs[0] == runs[1]
    np.testing.assert_array_equal(np.frombuffer(runs[1][-1][0]),
                                  traj.state_at(1.0 + 3 * PERIOD_S)[0])


# ----------------------------------------------------------------------------- estimation
def _poses(seed: int):
    """A flight's poses: steps of 65 ms with jitter, a pose seen again (stale mocap), a gap."""
    from ardrone_nmpc.core.types import MocapPose

    rng = np.random.default_rng(seed)
    t, out = 0.0, []
    for k in range(60):
        t += 0.0 if k in (7, 8, 30) else (0.4 if k == 20 else rng.uniform(0.05, 0.08))
        p = rng.normal([0.0, 0.0, 1.0], 0.3)
        out.append((MocapPose(t, p, np.zeros(3), float(rng.uniform(-3.0, 3.0))),
                    float(rng.normal(0.0, 1.0))))
    return out


def _nav(k: int):
    from ardrone_nmpc.core.types import FlightMode, NavdataSample

    return NavdataSample(0.0, FlightMode.FLYING, 80.0, 1.0, 2.0, 0.0, 1.0, 0.1 * k, -0.05 * k, 0.0)


def _estimations(*overrides: str):
    from ardrone_nmpc.config.io import config_from_dict

    from ardrone_nmpc.runtime.stages import Estimation

    est = {"kind": "kalman"}
    for o in overrides:
        key, value = o.split("=")
        est[key] = value
    cfg = config_from_dict({"name": "t", "estimator": est}).estimator
    compiled, python = Estimation(cfg), Estimation(cfg)
    python._leave_compiled()  # the estimator objects from the start
    return compiled, python


@pytest.mark.parametrize("kind", ["kalman", "luenberger", "difference", "none"])
@pytest.mark.parametrize("horizontal", ["difference", "navdata"])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_compiled_estimate_is_the_python_one_bit_for_bit(horizontal, seed, kind):
    """Each ż estimator: the compiled step's estimate is the objects' own, bit for bit, over
    poses of ~60 distinct Δt (more than the observer's table holds: entries replaced), a
    pose seen again and a gap; then the objects carry on from the state it reached."""
    compiled, python = _estimations(f"horizontal_velocity={horizontal}", f"kind={kind}")
    assert compiled._compiled and not python._compiled
    for k, (p, zacc) in enumerate(_poses(seed)):
        nav = _nav(k) if k % 3 else None
        a = compiled.update(p, nav, zacc).copy()
        b = python.update(p, nav, zacc).copy()
        assert a.tobytes() == b.tobytes(), k
    assert compiled._compiled
    # the objects, asked for, hold the state the compiled step reached: the same from here on
    kf, kp = compiled.vz_estimator, python.vz_estimator
    assert not compiled._compiled
    assert kf.state() == kp.state() and kf.vz_mps == kp.vz_mps
    assert compiled.xy_difference.velocity_mps == python.xy_difference.velocity_mps
    for p, zacc in _poses(seed + 10):
        shifted = type(p)(p.t_s + 100.0, p.position_m, p.rotation_xyz_rad, p.psi_rad)
        assert (compiled.update(shifted, None, zacc).tobytes()
                == python.update(shifted, None, zacc).tobytes())


def test_the_observer_s_step_asks_for_a_missing_interval_and_writes_nothing(monkeypatch):
    """The compiled step of a Luenberger observer meets a Δt its table lacks: it answers
    NO_COEFFICIENTS with its state untouched; the stage adds the Δt's coefficients (the
    object's own) and steps; the next pose at the same Δt finds them (no entry added)."""
    from ardrone_nmpc.core.types import MocapPose
    from ardrone_nmpc.estimation import luenberger

    monkeypatch.setattr(luenberger, "_SHARED_CACHES", OrderedDict())  # no Δt known in this process
    from ardrone_nmpc.runtime.tick_kernels import (E_TABLE, LU_ENTRY, NO_COEFFICIENTS,
                                                   estimate_step)

    def pose(t_s):  # times on a binary grid: every Δt is exactly 1/16 s
        return MocapPose(t_s, np.array([0.0, 0.0, 1.0 + t_s]), np.zeros(3), 0.0)

    est, _ = _estimations("kind=luenberger")
    keys = est._state[E_TABLE:E_TABLE + 3 * LU_ENTRY:LU_ENTRY]  # (a view)
    est.update(pose(0.0), None, 0.5)  # resets
    est.update(pose(0.0625), None, 0.5)  # anchors ẑ: no coefficients asked
    assert np.isnan(keys).all()
    state = est._state.copy()
    assert estimate_step(state, 0.0, 0.0, 1.125, 0.0, 0.125, 0.5, False, 0.0, 0.0) == (
        NO_COEFFICIENTS)
    assert state.tobytes() == est._state.tobytes()  # nothing written
    est.update(pose(0.125), None, 0.5)
    assert est._compiled and keys[0] == 0.0625 and np.isnan(keys[1:]).all()
    assert est._state[E_TABLE + 1:E_TABLE + LU_ENTRY].tolist() == list(
        est._vz_estimator.coefficients(0.0625))
    est._compiled = True  # (the property above left it: back, the state unchanged)
    est.update(pose(0.1875), None, 0.5)
    assert np.isnan(keys[1:]).all()  # found: no new entry
    est.update(pose(0.3125), None, 0.5)
    assert keys[1] == 0.125


def test_an_observer_s_table_starts_with_the_intervals_its_process_knows(monkeypatch):
    """A Luenberger observer's compiled step starts with the coefficients of the Δt the
    process' observers of its gain met (a sweep's next flight): a second flight of the same
    poses asks for none, and its estimates are still the Python objects' bit for bit."""
    from ardrone_nmpc.estimation import luenberger
    from ardrone_nmpc.runtime.tick_kernels import E_TABLE, LU_ENTRIES, LU_ENTRY

    monkeypatch.setattr(luenberger, "_SHARED_CACHES", OrderedDict())
    poses = [(p, zacc) for p, zacc in _poses(3) if p.t_s < 1.0]  # (fewer Δt than entries)
    first, _ = _estimations("kind=luenberger")
    assert np.isnan(first._state[E_TABLE::LU_ENTRY]).all()
    for p, zacc in poses:
        first.update(p, None, zacc)
    met = first._state[E_TABLE::LU_ENTRY]
    met = set(met[~np.isnan(met)].tolist())
    assert 3 < len(met) < LU_ENTRIES
    second, python = _estimations("kind=luenberger")
    assert met <= set(second._state[E_TABLE::LU_ENTRY].tolist())
    added = []
    monkeypatch.setattr(type(second), "_add_coefficients",
                        lambda self, dt_s, coefficients: added.append(dt_s))  # (asked: fails)
    for p, zacc in poses:
        assert second.update(p, None, zacc).tobytes() == python.update(p, None, zacc).tobytes()
    assert second._compiled and added == []


def test_the_estimate_by_the_entry_point_takes_any_number_as_the_dispatcher_does():
    """The compiled step is called by its entry point once known (no look-up of the
    arguments' types): numbers of other types than float — ints, numpy scalars — give the
    bits the dispatcher's own specialisation for them gives."""
    from ardrone_nmpc.core.types import MocapPose
    from ardrone_nmpc.runtime.tick_kernels import E_X, estimate_step

    est, _ = _estimations()
    kinds = (np.float32, int, np.float64, np.int64, float)
    stamps = (float, int, np.float64)  # (others are the objects': the next test)
    for k, (p, zacc) in enumerate(_poses(4)):
        kind = kinds[k % len(kinds)]  # (the times' int parts do not decrease)
        odd = MocapPose(stamps[k % 3](0.5 * k), p.position_m.astype(np.float32),
                        p.rotation_xyz_rad, kind(p.psi_rad))
        state = est._state.copy()
        estimate = est.update(odd, None, kind(zacc)).copy()
        assert estimate_step(state, *odd.position_m.tolist(), odd.psi_rad, odd.t_s,
                               kind(zacc), False, 0.0, 0.0) == 0
        assert estimate.tobytes() == state[E_X:E_X + 7].tobytes() and est._state.tobytes() == (
            state.tobytes()), k
    from ardrone_nmpc.runtime.estimate import _STEP
    entry = _STEP.entry_for(est._state)
    assert entry is not None and est._step is entry  # the entry point


@pytest.mark.parametrize("stamp", [np.float32, np.int64])
@pytest.mark.parametrize("kind", ["kalman", "luenberger", "difference", "none"])
def test_a_stamp_of_another_type_is_the_objects_own(kind, stamp):
    """A pose stamp the Python path subtracts in its own type (a float32: a float32 Δt)
    hands the estimate to the estimator objects: the same bits as theirs (a review's find:
    the step's float64 Δt gave ẋ 0.62499998196 where they give 0.62499999069)."""
    from ardrone_nmpc.core.types import MocapPose

    compiled, python = _estimations(f"kind={kind}")
    for k, (p, zacc) in enumerate(_poses(5)):
        odd = MocapPose(stamp(0.5 * k + 0.1), p.position_m, p.rotation_xyz_rad, p.psi_rad)
        assert (compiled.update(odd, None, zacc).tobytes()
                == python.update(odd, None, zacc).tobytes()), k
    assert not compiled._compiled


@pytest.mark.parametrize("copier", ["deepcopy", "pickle"])
@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("kind", ["kalman", "luenberger", "difference", "none"])
def test_a_copied_estimation_estimates_as_the_original(copier, compiled, kind):
    """A deep or pickled copy of the estimation stage mid-flight answers as the original, bit
    for bit, in its own array (a view of its own state while the compiled step holds it),
    and its updates leave the original's state alone."""
    import copy
    import pickle

    est, _ = _estimations(f"kind={kind}")
    if not compiled:
        est._leave_compiled()
    poses = _poses(3)
    for p, zacc in poses[:20]:
        est.update(p, None, zacc)
    twin = copy.deepcopy(est) if copier == "deepcopy" else pickle.loads(pickle.dumps(est))
    assert twin.compiled == compiled
    before = est._state.tobytes()
    answers = []
    for who in (twin, est):
        answers.append([who.update(p, _nav(k) if k % 2 else None, zacc).tobytes()
                        for k, (p, zacc) in enumerate(poses[20:])])
        if who is twin:
            assert est._state.tobytes() == before
            assert np.shares_memory(twin._x, twin._state)
    assert answers[0] == answers[1]


# the first pose only resets the estimators: a bad z̈ or interval needs a pose before it
@pytest.mark.parametrize("first,bad", [(True, "z"), (True, "x"), (True, "t_nan")]
                         + [(False, b) for b in ("z", "x", "zacc", "dt", "t_nan")])
@pytest.mark.parametrize("kind", ["kalman", "luenberger", "difference", "none"])
def test_the_compiled_estimate_refuses_what_the_estimators_refuse(bad, first, kind):
    from ardrone_nmpc.core.types import MocapPose
    from ardrone_nmpc.estimation.base import EstimatorError

    compiled, python = _estimations(f"kind={kind}")
    if not first:
        for est in (compiled, python):
            est.update(MocapPose(1.0, np.array([0.0, 0.0, 1.0]), np.zeros(3), 0.0), None, 0.0)
            est.update(MocapPose(1.065, np.array([0.01, 0.0, 1.01]), np.zeros(3), 0.0), None, 0.1)
    t = {"dt": 1.0 if not first else 2.0, "t_nan": math.nan}.get(bad, 1.2)
    pos = np.array([math.nan if bad == "x" else 0.02, 0.0, math.inf if bad == "z" else 1.0])
    zacc = math.nan if bad == "zacc" else 0.0
    def outcome(est, pose, zacc_mps2):
        try:
            return est.update(pose, None, zacc_mps2).tobytes()
        except EstimatorError as err:
            return str(err)

    bad_pose = MocapPose(t, pos, np.zeros(3), 0.0)
    first_outcome = outcome(compiled, bad_pose, zacc)
    assert first_outcome == outcome(python, bad_pose, zacc)
    assert not compiled._compiled or isinstance(first_outcome, bytes)
    # and what each holds afterwards is the same
    good = MocapPose(5.0, np.array([0.1, 0.1, 1.1]), np.zeros(3), 0.1)
    assert outcome(compiled, good, 0.2) == outcome(python, good, 0.2)


@pytest.mark.parametrize("coordinate", ["x", "psi"])
def test_nmpc_inputs_clamps_a_negative_zero_time_as_numpy_does(coordinate):
    """At t = −0.0 the lookup runs at np.maximum(−0.0, 0.0) = +0.0, not −0.0: with a first
    waypoint at t = 0 holding a −0.0 coordinate, the two give that coordinate opposite signs."""
    position, psi = ([-0.0, 0.0, 1.0], 0.0) if coordinate == "x" else ([0.0, 0.0, 1.0], -0.0)
    traj = HoldStartThen(Waypoints([0.0, 2.0], [position, [1.0, 0.5, 1.0]], [psi, 0.5]))
    n, t_s = 4, -0.0
    offsets = np.zeros(n + 2)
    np.multiply(0.1, np.arange(n + 1, dtype=np.float64), out=offsets[1:])
    times = np.add(t_s + 0.0, offsets)
    times[0] = t_s
    want = traj.state_at(times)  # the Python path: HoldStartThen.state_at
    x = np.zeros(STATE_DIM)
    states = np.full((n + 2, STATE_DIM), np.nan)
    work, rows = nmpc_work(PERIOD_S, n + 2, traj.waypoint_args)
    nmpc_work_views(work)[0][:] = offsets
    nmpc_inputs(x, np.zeros((2, 4)), 0, 0, x, t_s, 0.0, np.zeros(0), states, work, rows)
    assert states.tobytes() == want.tobytes()
