"""The tick's one-call NMPC inputs (``runtime/tick_kernels.nmpc_inputs``, issue 26) give the bits
of the Python they replace: ``DelayPrediction.predict``, the horizon's times,
``HoldStartThen.state_at`` of a waypoint trajectory and ``ReferenceIntegrator.shifted`` — and
``Control.solve`` answers the same through either path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.config.schema import ReferenceConfig
from ardrone_nmpc.control.mapping import command_scales
from ardrone_nmpc.control.solver import make_nmpc
from ardrone_nmpc.core.types import STATE_DIM
from ardrone_nmpc.estimation.disturbance import ReferenceIntegrator
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.trajectories import Waypoints, make_trajectory
from ardrone_nmpc.runtime.stages import Control, DelayPrediction, OffsetFree
from ardrone_nmpc.runtime.tick import effective_controller
from ardrone_nmpc.runtime.tick_kernels import nmpc_inputs

PERIOD_S = 0.065
ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def _waypoint_references():
    square = make_trajectory(ReferenceConfig(kind="square"), duration_s=25.0)
    altitudes = make_trajectory(ReferenceConfig(kind="square_altitudes"), duration_s=25.0)
    path = Waypoints([0.0, 2.0, 3.5, 4.0], [[0, 0, 1], [1, 0, 1], [1, -1, 1.2], [0.5, -1, 1.2]],
                     [0.0, 0.5, 3.0, -3.0])
    return [HoldStartThen(t) for t in (square, altitudes, path)]


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
        for t_s in (-2.0, -0.3, -0.07, 0.0, 1e-9, 2.5, 4.99, 12.3, 30.0, math.nan):
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
                horizon = np.full((n + 1, STATE_DIM), np.nan)
                nmpc_inputs(x, sent, first, count, delay.period_s, x_k, *traj.waypoint_args,
                            t_s, delay.lead_s, offsets, np.zeros(0) if shift is None else shift,
                            np.zeros(n + 2), np.zeros(n + 2), states, horizon)
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


@pytest.mark.parametrize("shifted", [False, True])
def test_control_solves_the_same_through_either_path(shifted):
    cfg = load_config(str(ROOT / "configs" / "square.yaml"))
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
