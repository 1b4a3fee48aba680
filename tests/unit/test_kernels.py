"""Optimality residual F of the thesis OCP against finite differences of the cost itself."""

import math

import numpy as np
import pytest

from ardrone_nmpc.control import kernels as K
from tests.conftest import thesis_cost

N = 6
DTAU = 0.1


@pytest.fixture
def problem(rng):
    q = rng.uniform(1, 5, 7)
    qf = rng.uniform(0, 3, 7)
    r = rng.uniform(1, 5, 4)
    W = np.zeros((5, 7))
    W[0], W[1], W[2, :4], W[3, :4], W[4, :4] = q, qf, r, -1.0, 1.0
    x0 = rng.normal(size=7)
    ref = rng.normal(size=(N + 1, 7))
    u = rng.uniform(-0.6, 0.6, (N, 4))
    return dict(q=q, qf=qf, r=r, W=W, x0=x0, ref=ref, u=u)


def _residual(U, m, p, rho=0.01, eps=0.0, active=None):
    out = np.zeros(U.size)
    if active is None:
        active = np.zeros((N, 4), dtype=np.int8)
    norm = K.residual(U, m, p["x0"], p["ref"], DTAU, p["W"], rho, eps, active,
                      np.zeros((N + 1, 7)), np.zeros((N + 1, 5)), out)
    return out, norm


def _grad(fun, u, eps=1e-6):
    g = np.zeros_like(u)
    for idx in np.ndindex(u.shape):
        up, um = u.copy(), u.copy()
        up[idx] += eps
        um[idx] -= eps
        g[idx] = (fun(up) - fun(um)) / (2 * eps)
    return g


def test_stationarity_rows_are_the_cost_gradient(problem):
    """H_u of eq. 3.19 (no active bounds) is ∂J/∂u_i / Δτ of eq. 3.14."""
    p = problem
    U = np.zeros(N * K.STAGE_ACTIVE)
    U.reshape(N, 8)[:, :4] = p["u"]
    F, norm = _residual(U, K.STAGE_ACTIVE, p)
    cost = lambda u: thesis_cost(p["x0"], p["ref"], u, q=p["q"], r=p["r"], qf=p["qf"], dtau=DTAU)
    expected = _grad(cost, p["u"]) / DTAU
    np.testing.assert_allclose(F.reshape(N, 8)[:, :4], expected, atol=1e-6, rtol=1e-6)
    assert norm == pytest.approx(np.linalg.norm(F), rel=1e-12)


def test_condensed_residual_is_the_gradient_of_the_dummy_penalised_cost(problem):
    """m = 4: F = ∇_U [J − ρ Δτ Σ v(u)] / Δτ with v = √(w² − (u − c)²)."""
    p, rho = problem, 0.05
    F, _ = _residual(p["u"].reshape(-1).copy(), K.STAGE_CONDENSED, p, rho=rho)

    def penalised(u):
        v = np.sqrt(1.0 - u ** 2)  # box ±1: c = 0, w = 1
        return thesis_cost(p["x0"], p["ref"], u, q=p["q"], r=p["r"], qf=p["qf"],
                           dtau=DTAU) - rho * DTAU * v.sum()

    np.testing.assert_allclose(F.reshape(N, 4), _grad(penalised, p["u"]) / DTAU, atol=1e-6)


def test_condensed_equals_full_dummy_form_on_its_manifold(problem):
    """With v, μ from C = 0 and H_v = 0, the m = 12 rows reduce to the m = 4 rows."""
    p, rho = problem, 0.02
    u = p["u"]
    v = np.sqrt(1.0 - u ** 2)
    mu = rho / (2 * v)
    U12 = np.concatenate([u, v, mu], axis=1).reshape(-1)
    F12, _ = _residual(U12, K.STAGE_DUMMY, p, rho=rho)
    F4, _ = _residual(u.reshape(-1).copy(), K.STAGE_CONDENSED, p, rho=rho)
    F12 = F12.reshape(N, 12)
    np.testing.assert_allclose(F12[:, :4], F4.reshape(N, 4), atol=1e-12)
    np.testing.assert_allclose(F12[:, 4:], 0.0, atol=1e-12)  # H_v and C rows vanish


def test_condensed_bound_term_stays_finite_and_pulls_back_outside_the_box(problem):
    p = problem
    U = p["u"].reshape(-1).copy()
    U[0] = 1.5  # outside the box: the tangent continuation, not a NaN
    F, norm = _residual(U, K.STAGE_CONDENSED, p)
    assert math.isfinite(norm)
    U[0] = 1.6
    F_further, _ = _residual(U, K.STAGE_CONDENSED, p)
    assert F_further[0] > F[0]  # steeper the further out: Newton steps inward


def test_active_bound_rows_impose_the_eq_3_25_constraint(problem):
    p = problem
    active = np.zeros((N, 4), dtype=np.int8)
    active[2, 1] = 1
    active[3, 0] = -1
    U = np.zeros(N * 8)
    Us = U.reshape(N, 8)
    Us[:, :4] = p["u"]
    Us[2, 5] = 0.7  # ν of the active upper bound
    eps = 1e-3
    F, _ = _residual(U, K.STAGE_ACTIVE, p, eps=eps, active=active)
    Fs = F.reshape(N, 8)
    assert Fs[2, 5] == pytest.approx(p["u"][2, 1] - (1.0 - eps))
    assert Fs[3, 4] == pytest.approx((-1.0 + eps) - p["u"][3, 0])
    assert Fs[0, 4] == 0.0  # inactive: the row is ν itself
    # the multiplier enters H_u with the constraint's sign
    Us[2, 5] = 0.0
    F0, _ = _residual(U, K.STAGE_ACTIVE, p, eps=eps, active=active)
    assert Fs[2, 1] - F0.reshape(N, 8)[2, 1] == pytest.approx(0.7)


def test_fdgmres_matches_a_dense_solve_with_the_fd_jacobian(problem):
    p = problem
    U = p["u"].reshape(-1).copy()
    n = U.size
    F, _ = _residual(U, K.STAGE_CONDENSED, p)
    h = 1e-6
    J = np.column_stack([(_residual(U + h * e, K.STAGE_CONDENSED, p)[0] - F) / h
                         for e in np.eye(n)])
    buf = np.zeros(K.workspace_size(N, 4, n))
    views = K.carve_workspace(buf, N, 4, n)
    out = np.zeros(n)
    k, _ = K.fdgmres(U, 4, p["x0"], p["ref"], DTAU, p["W"], 0.01, 0.0,
                     np.zeros((1, 1), np.int8), F, -F, np.zeros(n), h, n, 1e-12, views, out)
    # Both sides use forward differences with h = 1e-6: O(h·‖F''‖) apart, so compare normwise.
    exact = np.linalg.solve(J, -F)
    assert np.linalg.norm(out - exact) <= 1e-5 * np.linalg.norm(exact)
    assert k <= n


@pytest.mark.parametrize("psi_ref", [3.0, -3.0, 6.5, -9.0])
def test_reference_psi_is_unwrapped_near_the_state(psi_ref):
    x = np.zeros(7)
    x[6] = -3.0
    ref = np.zeros((4, 7))
    ref[:, 6] = psi_ref + np.array([0.0, 0.1, 0.2, 0.3])
    out = np.zeros_like(ref)
    assert K.prepare_reference(x, ref, out)
    assert abs(out[0, 6] - x[6]) <= math.pi
    np.testing.assert_allclose(np.diff(out[:, 6]), 0.1, atol=1e-12)
    np.testing.assert_allclose(np.sin(out[:, 6]), np.sin(ref[:, 6]), atol=1e-12)


def test_non_finite_reference_is_refused():
    ref = np.zeros((3, 7))
    ref[1, 2] = np.nan
    assert not K.prepare_reference(np.zeros(7), ref, np.zeros_like(ref))


@pytest.mark.parametrize("a", [0.0, 1e-8, 0.1, -0.3, 0.5, 0.7, -2.0])
def test_sincos_small_is_exact_to_rounding(a):
    s, c = K.sincos_small(a)
    assert s == pytest.approx(math.sin(a), abs=2e-16)
    assert c == pytest.approx(math.cos(a), abs=2e-16)


def test_rollout_rk4_matches_the_model_integrator(rng):
    from ardrone_nmpc import model

    x = rng.normal(size=7)
    inputs = rng.uniform(-0.5, 0.5, (4, 4))
    expected = x.copy()
    for u in inputs:
        expected = model.rk4_step(expected, u, 0.065)
    out = np.zeros(7)
    K.rollout_rk4(x, inputs, 0.065, out)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n_stages, m, n_obs", [(10, 4, 0), (20, 8, 3), (1, 12, 0)])
def test_the_answer_is_read_where_unpack_puts_u_out_and_stats(n_stages, m, n_obs):
    from ardrone_nmpc.control.kernels import layout

    mem = np.zeros(layout.memory_size(n_stages, m, 5, n_obs))
    _, _, u_out, stats, *_ = layout.unpack(mem, n_stages, m, n_obs)
    at = layout.u_out_at.py_func(n_stages, m)
    base = mem.__array_interface__["data"][0]
    assert u_out.__array_interface__["data"][0] - base == at * mem.itemsize
    assert stats.__array_interface__["data"][0] - base == (at + layout.NU) * mem.itemsize
