"""Model eq. 3.13: hand-computed values, Jacobians against finite differences, integrators."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from ardrone_nmpc import model

G = 9.81


def test_pitch_at_zero_yaw_accelerates_forward():
    # θ = 0.2 rad, ψ = 0: ẍ = tan(0.2)·g, ÿ = 0
    xdot = model.f([0, 0, 0, 0, 1, 0, 0], [0, 0, 0.2, 0])
    assert xdot[1] == pytest.approx(math.tan(0.2) * G, rel=1e-12)
    assert xdot[3] == pytest.approx(0.0, abs=1e-15)


def test_roll_at_zero_yaw_accelerates_towards_minus_y():
    # φ = 0.1 rad, θ = 0, ψ = 0: ÿ = −tan(0.1)·g (docs/design.md §4: φ > 0 towards −y)
    xdot = model.f([0, 0, 0, 0, 1, 0, 0], [0, 0.1, 0, 0])
    assert xdot[3] == pytest.approx(-math.tan(0.1) * G, rel=1e-12)
    assert xdot[1] == pytest.approx(0.0, abs=1e-15)


def test_hand_computed_general_point():
    x = [1.0, 0.5, -2.0, 0.3, 1.2, -0.1, 0.7]
    u = [0.4, 0.15, -0.25, 0.6]
    tphi, tth, cth = math.tan(0.15), math.tan(-0.25), math.cos(-0.25)
    s, c = math.sin(0.7), math.cos(0.7)
    expected = [0.5, (s * tphi / cth + c * tth) * (0.4 + G), 0.3,
                (-c * tphi / cth + s * tth) * (0.4 + G), -0.1, 0.4, 0.6]
    np.testing.assert_allclose(model.f(x, u), expected, rtol=1e-13, atol=1e-15)


vec7 = st.lists(st.floats(-2, 2), min_size=7, max_size=7)
vec4 = st.lists(st.floats(-0.9, 0.9), min_size=4, max_size=4)


def _fd_jacobian(fun, z, eps=1e-6):
    z = np.asarray(z, float)
    cols = []
    for k in range(z.size):
        dz = np.zeros_like(z)
        dz[k] = eps
        cols.append((fun(z + dz) - fun(z - dz)) / (2 * eps))
    return np.column_stack(cols)


@settings(max_examples=60, deadline=None)
@given(vec7, vec4)
def test_jacobian_x_matches_central_differences(x, u):
    fd = _fd_jacobian(lambda z: model.f(z, u), x)
    np.testing.assert_allclose(model.jacobian_x(x, u), fd, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(vec7, vec4)
def test_jacobian_u_matches_central_differences(x, u):
    fd = _fd_jacobian(lambda z: model.f(x, z), u)
    np.testing.assert_allclose(model.jacobian_u(x, u), fd, atol=1e-5, rtol=1e-6)


def test_euler_step_is_thesis_eq_3_16():
    x = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    u = np.array([0.1, -0.2, 0.3, -0.4])
    np.testing.assert_array_equal(model.euler_step(x, u, 0.1), x + model.f(x, u) * 0.1)


def test_rk4_matches_scipy_reference_solution():
    x0 = np.array([0.0, 0.5, 0.0, -0.2, 1.0, 0.1, 0.3])
    u = np.array([0.2, 0.1, -0.15, 0.5])
    x = x0.copy()
    for _ in range(100):  # 1 s in 10 ms steps
        x = model.rk4_step(x, u, 0.01)
    sol = solve_ivp(lambda t, z: model.f(z, u), (0, 1.0), x0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(x, sol.y[:, -1], atol=1e-8)
