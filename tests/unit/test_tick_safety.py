"""The tick obeys the supervisor: HOLD resends the last command sent (not a level zero), and
``safety.solver_accept_max_iterations`` decides whether a max-iterations solve flies."""

import math

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.ocp import SolveResult, SolverStatus
from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample
from ardrone_nmpc.runtime.lockstep import experiment_trajectory
from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action


def pose(t, x=0.0):
    return MocapPose(t, np.array([x, 0.0, 1.0]), np.zeros(3), 0.0)


def nav(t):
    return NavdataSample(t, FlightMode.FLYING, 80.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


def step(tick, t, pose_rx, x=0.0, t_exp=None):
    inputs = TickInputs(t, pose(pose_rx, x), pose_rx, nav(t), t)
    return tick.step(inputs, t_exp_s=t if t_exp is None else t_exp)


@pytest.mark.parametrize("kind", ["p", "nmpc"])
def test_hold_resends_the_last_command_sent(kind):
    cfg = load_config(None, [f"controller.kind={kind}"])
    tick = Tick(cfg, experiment_trajectory(cfg))
    first = step(tick, 0.0, 0.0, x=-0.4)     # 0.4 m behind the reference: pitch forward
    assert first.action is Action.CONTROL and first.progressive
    assert abs(first.pcmd.pitch_frac) > 0.05
    hold_s = (cfg.safety.mocap_hold_ms + 20) * 1e-3
    held = step(tick, hold_s, 0.0, x=-0.4)    # the same pose, now stale
    assert held.action is Action.HOLD and held.row["mode"] == "hold-stale-mocap"
    assert held.progressive and held.pcmd == first.pcmd
    assert held.row["cmd_pitch_frac"] == first.row["cmd_pitch_frac"] != 0.0
    hover = step(tick, (cfg.safety.mocap_hover_ms + 20) * 1e-3, 0.0, x=-0.4)
    assert hover.action is Action.HOVER and not hover.progressive
    assert hover.row["cmd_pitch_frac"] == 0.0
    # after a hover nothing is held any more: a hold hovers
    again = step(tick, 0.5 + hold_s, 0.5, x=-0.4)
    assert not again.progressive and again.row["mode"] == "hover-stale-mocap"


class _Answering:
    """``inner`` whose every solve answers ``answer`` (set it to change the answer) — on either
    of the control stage's paths; every other attribute is the inner solver's."""

    def __init__(self, inner, answer: SolveResult) -> None:
        self._inner = inner
        self.answer = answer

    def solve(self, t_s, x, ref) -> SolveResult:
        return self.answer

    solve_prepared = solve

    def __getattr__(self, name: str):
        return getattr(self._inner, name)


def _tick_with_solver_status(accept: bool, status: SolverStatus):
    cfg = load_config(None, [f"safety.solver_accept_max_iterations={str(accept).lower()}"])
    answer = SolveResult(np.array([0.0, 0.05, -0.04, 0.0]), status, 1e-3, 5, 30.0, 3)
    return Tick(cfg, experiment_trajectory(cfg),
                wrap_solver=lambda nmpc: _Answering(nmpc, answer))


@pytest.mark.parametrize("accept, mode, progressive", [(True, "track", True),
                                                       (False, "hover-solver", False)])
def test_accept_max_iterations_switch(accept, mode, progressive):
    tick = _tick_with_solver_status(accept, SolverStatus.MAX_ITERATIONS)
    out = step(tick, 0.0, 0.0)
    assert out.row["mode"] == mode and out.progressive is progressive
    assert out.row["solver_status"] == "max-iterations"
    if accept:
        assert out.row["cmd_roll_frac"] == pytest.approx(
            0.05 / tick.limits.euler_angle_max_rad, abs=1e-9)


def test_a_rejected_max_iterations_solve_holds_the_last_good_command():
    tick = _tick_with_solver_status(False, SolverStatus.OK)
    good = step(tick, 0.0, 0.0)
    assert good.row["mode"] == "track" and good.progressive
    rejected = SolveResult(np.array([0.0, 0.2, 0.2, 0.0]), SolverStatus.MAX_ITERATIONS, 1.0, 5,
                           30.0, 3)
    tick.control.nmpc.answer = rejected
    held = step(tick, 0.065, 0.065)
    assert held.row["mode"] == "hold-solver" and held.pcmd == good.pcmd
    assert math.isclose(held.row["cmd_roll_frac"], good.row["cmd_roll_frac"])
