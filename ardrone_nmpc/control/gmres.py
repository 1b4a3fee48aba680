"""Restart-free GMRES (Saad & Schultz) as small numba kernels.

The Arnoldi/Givens pieces are shared by two drivers:

* :func:`gmres_dense` — ``A x = b`` with an explicit matrix (used to test the pieces against
  ``numpy.linalg.solve`` and ``scipy.sparse.linalg.gmres``);
* ``fdgmres`` in :mod:`ardrone_nmpc.control.kernels` — the matrix-free solve of thesis
  Algorithm 1, where ``A w`` is a forward difference of the optimality residual.

Arrays: ``V`` (kmax+1, n) Krylov basis, ``H`` (kmax+1, kmax) Hessenberg matrix after the
Givens rotations (upper triangular in its leading k×k block), ``cs``/``sn`` (kmax,) the
rotations, ``g`` (kmax+1,) the rotated right-hand side ``β e1``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL

# LLVM fast-math without 'nnan'/'ninf': the kernels must still see NaN and inf to report them.
FAST_MATH = {"contract", "reassoc", "arcp", "nsz", "afn"}


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def gmres_start(r0, V, g):
    """Set ``V[0] = r0/‖r0‖`` and ``g = ‖r0‖ e1``; return ``β = ‖r0‖``."""
    beta = 0.0
    for i in range(r0.shape[0]):
        beta += r0[i] * r0[i]
    beta = math.sqrt(beta)
    g[:] = 0.0
    g[0] = beta
    if beta > 0.0:
        inv = 1.0 / beta
        v0 = V[0]
        for i in range(r0.shape[0]):
            v0[i] = r0[i] * inv
    return beta


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def gmres_iterate(k, w, V, H, cs, sn, g):
    """Arnoldi step ``k`` on ``w = A V[k]`` (overwritten); return the new residual ``|g[k+1]|``.

    Modified Gram–Schmidt orthogonalises ``w`` against ``V[0..k]``; the previous Givens
    rotations are applied to the new Hessenberg column and a new one zeroes ``H[k+1, k]``.
    """
    n = w.shape[0]
    for j in range(k + 1):
        vj = V[j]
        hjk = 0.0
        for i in range(n):
            hjk += w[i] * vj[i]
        H[j, k] = hjk
        for i in range(n):
            w[i] -= hjk * vj[i]
    hnext = 0.0
    for i in range(n):
        hnext += w[i] * w[i]
    hnext = math.sqrt(hnext)
    H[k + 1, k] = hnext
    vk1 = V[k + 1]
    if hnext > 0.0:
        inv = 1.0 / hnext
        for i in range(n):
            vk1[i] = w[i] * inv
    else:  # happy breakdown: the Krylov space already holds the solution
        vk1[:] = 0.0
    for j in range(k):
        a = H[j, k]
        b = H[j + 1, k]
        H[j, k] = cs[j] * a + sn[j] * b
        H[j + 1, k] = -sn[j] * a + cs[j] * b
    a = H[k, k]
    b = H[k + 1, k]
    denom = math.sqrt(a * a + b * b)
    if denom == 0.0:
        cs[k] = 1.0
        sn[k] = 0.0
    else:
        cs[k] = a / denom
        sn[k] = b / denom
    H[k, k] = denom
    H[k + 1, k] = 0.0
    g[k + 1] = -sn[k] * g[k]
    g[k] = cs[k] * g[k]
    return abs(g[k + 1])


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def gmres_finish(k, V, H, g, x0, out):
    """``out = x0 + V[:k]ᵀ y`` with ``y`` from ``H[:k,:k] y = g[:k]``; ``out`` may be ``x0``.

    ``g`` is overwritten by ``y``.
    """
    # back-substitution in place of g (g is not needed afterwards)
    for i in range(k - 1, -1, -1):
        acc = g[i]
        for j in range(i + 1, k):
            acc -= H[i, j] * g[j]
        g[i] = acc / H[i, i] if H[i, i] != 0.0 else 0.0
    n = out.shape[0]
    if out is not x0:
        for i in range(n):
            out[i] = x0[i]
    for j in range(k):
        yj = g[j]
        vj = V[j]
        for i in range(n):
            out[i] += yj * vj[i]


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **OUTER_KERNEL)
def gmres_dense(A, b, x0, kmax, rtol):
    """Solve ``A x = b`` by GMRES(kmax) without restart from the guess ``x0``.

    Parameters
    ----------
    A : (n, n) array
    b, x0 : (n,) arrays
    kmax : maximum Krylov dimension (iterations)
    rtol : stop when ``‖b − A x‖ ≤ rtol ‖b‖``

    Returns
    -------
    x : (n,) solution estimate
    iterations : int
    residual : float, the GMRES estimate of ``‖b − A x‖``
    """
    n = b.shape[0]
    V = np.zeros((kmax + 1, n))
    H = np.zeros((kmax + 1, kmax))
    cs = np.zeros(kmax)
    sn = np.zeros(kmax)
    g = np.zeros(kmax + 1)
    x = np.empty(n)
    residual = gmres_start(b - A @ x0, V, g)
    target = rtol * math.sqrt(np.dot(b, b))
    k = 0
    while k < kmax and residual > target:
        w = A @ V[k]
        residual = gmres_iterate(k, w, V, H, cs, sn, g)
        k += 1
    gmres_finish(k, V, H, g, x0, x)
    return x, k, residual


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
