"""GMRES pieces against numpy.linalg.solve and scipy.sparse.linalg.gmres."""

import numpy as np
import pytest
from scipy.sparse.linalg import gmres as scipy_gmres

from ardrone_nmpc.control.gmres import gmres_dense


@pytest.mark.parametrize("n", [1, 5, 12, 40])
def test_full_krylov_space_solves_exactly(rng, n):
    A = rng.normal(size=(n, n)) + n * np.eye(n)
    b = rng.normal(size=n)
    x, k, res = gmres_dense(A, b, np.zeros(n), n, 1e-14)
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=1e-9, atol=1e-12)
    assert k <= n
    assert res == pytest.approx(np.linalg.norm(b - A @ x), abs=1e-9)


def test_nonsymmetric_indefinite_system(rng):
    n = 20
    A = rng.normal(size=(n, n))  # generic: non-symmetric, indefinite
    b = rng.normal(size=n)
    x, _, _ = gmres_dense(A, b, np.zeros(n), n, 1e-14)
    np.testing.assert_allclose(A @ x, b, atol=1e-8)


@pytest.mark.parametrize("kmax", [1, 3, 5])
def test_partial_krylov_matches_scipy_gmres_one_cycle(rng, kmax):
    n = 30
    A = rng.normal(size=(n, n)) + 4 * np.eye(n)
    b = rng.normal(size=n)
    x0 = rng.normal(size=n) * 0.1
    ours, k, res = gmres_dense(A, b, x0, kmax, 0.0)
    theirs, _ = scipy_gmres(A, b, x0=x0, restart=kmax, maxiter=1, rtol=0.0, atol=0.0)
    assert k == kmax
    np.testing.assert_allclose(ours, theirs, rtol=1e-8, atol=1e-10)
    # the Givens residual estimate is the true residual of the returned iterate
    assert res == pytest.approx(np.linalg.norm(b - A @ ours), rel=1e-8)


def test_stops_at_relative_tolerance(rng):
    n = 50
    A = np.diag(np.linspace(1, 2, n))
    b = rng.normal(size=n)
    x, k, res = gmres_dense(A, b, np.zeros(n), n, 1e-6)
    assert res <= 1e-6 * np.linalg.norm(b)
    assert k < n  # well-clustered spectrum: converges long before n


def test_zero_rhs_returns_the_guess_without_iterating():
    A = np.eye(3)
    x, k, res = gmres_dense(A, np.zeros(3), np.zeros(3), 3, 1e-10)
    assert k == 0 and res == 0.0
    np.testing.assert_array_equal(x, np.zeros(3))
