"""runtime/p_tick.p_tick against the Python P tick it replaces: ``HoldStartThen.state_at``
then ``p_control``, the same bits for every reference cell and command field — before,
at and after t = 0, after the lap, headings on both sides of ±π and beyond a turn."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ardrone_nmpc.control.proportional import PGains, p_control
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.reference.trajectories import Square, Waypoints
from ardrone_nmpc.runtime.p_tick import p_tick, p_work

_GAINS = PGains(0.7, 0.2, 0.3, 1.1)


def _bits(a) -> bytes:
    return np.asarray(a, dtype=np.float64).tobytes()


def _trajectories():
    yield HoldStartThen(Square((0.5, -0.3, 1.0), side_m=1.5, leg_duration_s=4.0,
                               psi_rad=3.0))
    yield HoldStartThen(Waypoints([0.0, 1.0, 2.5], [[0, 0, 1], [1, 2, 1.5], [-1, 0, 0.8]],
                                  [0.0, 3.1, -3.1]))


@pytest.mark.parametrize("traj", list(_trajectories()))
def test_p_tick_is_the_python_p_tick_bit_for_bit(traj):
    rng = np.random.default_rng(7)
    work, rows = p_work(0.01, traj.waypoint_args)
    times = [-1.0, -0.0, 0.0, 1e-12, 0.01, 0.999, 1.0, 2.5, 4.0, 7.77, 16.0, 40.0]
    times += list(rng.uniform(-2.0, 20.0, 200))
    for t in times:
        x = rng.normal(0.0, 2.0, 7)
        x[6] = rng.choice([rng.uniform(-math.pi, math.pi), math.pi, -math.pi, 3.14159,
                           rng.uniform(-20.0, 20.0)])
        ref = np.empty((1, 7))
        got = p_tick(x, float(t), _GAINS.k1_per_s, _GAINS.k2_rad_per_mps,
                     _GAINS.k3_rad_per_mps, _GAINS.k4_per_s, ref, work, rows)
        want_ref = traj.state_at(float(t))[0]
        want = p_control(x, want_ref, _GAINS)
        assert _bits(ref[0]) == _bits(want_ref), t
        assert _bits(got) == _bits([want.vz_ref_mps, want.phi_rad, want.theta_rad,
                                    want.psirate_radps]), (t, x)


def test_a_table_keeps_the_python_path():
    args = (np.zeros(0),) * 5 + (np.zeros(7),)
    assert p_work(0.01, args) is None


@pytest.mark.parametrize("psi", [math.nan, math.inf, -math.inf])
def test_a_nonfinite_heading_gets_the_python_answer(psi):
    """``Control._p_solve`` with a heading that is not finite: what ``p_control`` gives (the
    sign of its NaN) or raises (``math.cos(inf)``), as before p_tick — the kernel would give
    a NaN of the other sign, or NaN for inf. (A stand-in for the stage's own attributes.)"""
    from types import SimpleNamespace

    from ardrone_nmpc.runtime.stages import Control

    traj = next(_trajectories())
    stage = SimpleNamespace(p_gains=_GAINS, delay=SimpleNamespace(period_s=0.065),
                            _p_args=None, _p_work=None)
    x = np.array([0.1, -0.2, 0.3, 0.0, 1.0, -0.0, psi])
    ref = traj.state_at(0.0)[0]
    try:
        want = p_control(x, ref, _GAINS)
    except ValueError:
        with pytest.raises(ValueError):
            Control._p_solve(stage, 0.0, x, traj)
        return
    got = Control._p_solve(stage, 0.0, x, traj).p_command
    fields = ("vz_ref_mps", "phi_rad", "theta_rad", "psirate_radps")
    assert _bits([getattr(got, f) for f in fields]) == _bits([getattr(want, f) for f in fields])
