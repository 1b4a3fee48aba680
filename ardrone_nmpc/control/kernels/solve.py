"""Solving ``F(U, x, t) = 0``: matrix-free GMRES (thesis Algorithm 1) and line-searched
Newton (eq. 3.22–3.24), the eq. 3.25 active set (and its blocking bound for a stalled solve),
and the checks around a tick.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control.gmres import FAST_MATH, gmres_finish, gmres_iterate, gmres_start
from ardrone_nmpc.control.kernels.layout import NO, NU, NX, STAGE_ACTIVE, STAGE_CONDENSED
from ardrone_nmpc.control.kernels.residual import condensed_cost, keep_inside, residual
from ardrone_nmpc.core.angles import unwrap_near_turns
from ardrone_nmpc.core.numerics import INNER_KERNEL

# ψ of a reference stage moved by whole turns next to the previous one (compiled from the
# single definition in ardrone_nmpc.core.angles).
_unwrap_near_turns = njit(cache=True, error_model="numpy", fastmath=FAST_MATH,
                          inline="always")(unwrap_near_turns)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def fdgmres(U, m, x0, ref, dtau, W, rho, eps, active, Fbase, rhs, guess, h, kmax, rtol,
            views, out, obs=None, gauss_newton=False):
    """Thesis Algorithm 1: solve ``F_U w = rhs`` with ``F_U w ≈ (F(U + h w) − Fbase)/h``.

    ``Fbase`` must be ``F(U, x0, …)``. Starts from ``guess`` (warm start); writes the
    solution into ``out`` (may alias ``guess``). Returns ``(iterations, residual estimate)``.
    With obstacles and ``gauss_newton``, the products see the obstacle penalty's
    Gauss–Newton curvature (directions frozen at the rollout of ``U``), not its exact one.
    """
    xs, _, _, trig, V, H, cs, sn, g, _, _, _, Ut, Ft, w, _, _, pbase = views
    n = U.shape[0]
    if obs is not None:
        if gauss_newton:  # the base rollout's positions (one more evaluation)
            residual(U, m, x0, ref, dtau, W, rho, eps, active, xs, trig, Ft, NO, obs, pbase,
                     NO)
            for i in range(xs.shape[0]):
                pbase[i, 0] = xs[i, 0]
                pbase[i, 1] = xs[i, 2]
                pbase[i, 2] = xs[i, 4]
    inv_h = 1.0 / h
    warm = False
    for i in range(n):
        if guess[i] != 0.0:
            warm = True
            break
    if warm:
        for i in range(n):
            Ut[i] = U[i] + h * guess[i]
        residual(Ut, m, x0, ref, dtau, W, rho, eps, active, xs, trig, Ft, NO, obs, pbase,
                 gauss_newton)
        for i in range(n):
            w[i] = rhs[i] - (Ft[i] - Fbase[i]) * inv_h
    else:  # a zero guess needs no product: one F evaluation saved
        for i in range(n):
            w[i] = rhs[i]
    res = gmres_start(w, V, g)
    target = 0.0
    for i in range(n):
        target += rhs[i] * rhs[i]
    target = rtol * math.sqrt(target)
    k = np.int64(0)  # not a literal 0: that would compile gmres_iterate for it alone
    while k < kmax and res > target:
        vk = V[k]
        for i in range(n):
            Ut[i] = U[i] + h * vk[i]
        residual(Ut, m, x0, ref, dtau, W, rho, eps, active, xs, trig, Ft, NO, obs, pbase,
                 gauss_newton)
        for i in range(n):
            w[i] = (Ft[i] - Fbase[i]) * inv_h
        res = gmres_iterate(k, w, V, H, cs, sn, g)
        k += 1
    gmres_finish(k, V, H, g, guess, out)
    return k, res


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def prepare_reference(x, ref, out):
    """Copy ``ref`` into ``out`` with ψ unwrapped along the horizon and shifted by 2πk to
    lie near ``x[6]`` (the OCP penalises ψ − ψ_d unwrapped). False if anything is non-finite."""
    for k in range(NX):
        if not math.isfinite(x[k]):
            return False
    prev = x[6]
    for i in range(ref.shape[0]):
        for k in range(NX):
            if not math.isfinite(ref[i, k]):
                return False
            out[i, k] = ref[i, k]
        out[i, 6] = _unwrap_near_turns(ref[i, 6], prev)
        prev = out[i, 6]
    return True


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def clip_first_input(U, W, u_out):
    """``u_out = clip(U[0:4], u_min, u_max)``; False if any is non-finite."""
    for j in range(NU):
        u = U[j]
        if not math.isfinite(u):
            return False
        u_out[j] = min(max(u, W[3, j]), W[4, j])
    return True


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def newton_solve(U, m, x, ref, dtau, W, rho, eps, active, tol, max_iter, h, kmax, rtol, views,
                 obs=None, gauss_newton=False):
    """Newton/GMRES on ``F(U, x, t) = 0`` (eq. 3.22–3.24) with a backtracking line search.

    ``U`` is updated in place. Returns ``(Newton iterations, GMRES iterations, ‖F‖)``.
    The line search asks ‖F‖ to fall; with obstacles in the condensed layout it asks the
    cost (:func:`condensed_cost`) to fall instead (Armijo), so that the iteration heads for
    a minimum: ‖F‖ falls just as well towards the stationary path through an obstacle's
    centre, and an obstacle ahead on the reference line puts Newton right next to it.
    """
    xs, _, _, trig, _, _, _, _, _, F0, _, rhs, Ut, Ft, _, dU, _, pbase = views
    n = U.shape[0]
    norm = residual(U, m, x, ref, dtau, W, rho, eps, active, xs, trig, F0, NO, obs, pbase, NO)
    by_cost = False
    cost = 0.0
    if obs is not None:
        by_cost = m == STAGE_CONDENSED
        cost = condensed_cost(U, xs, ref, dtau, W, rho, obs)
    it = 0
    gm_total = 0
    while it < max_iter and norm > tol and math.isfinite(norm):
        for i in range(n):
            rhs[i] = -F0[i]
        dU[:] = 0.0
        k, _ = fdgmres(U, m, x, ref, dtau, W, rho, eps, active, F0, rhs, dU, h, kmax, rtol,
                       views, dU, obs, gauss_newton)
        gm_total += k
        it += 1
        slope = 0.0
        if obs is not None:
            if by_cost:
                # dJ/ds along U + s dU (F = ∇J/Δτ); a loop, not np.dot: numba's np.dot calls
                # BLAS, whose kernel (and order of summation) the CPU chooses
                for i in range(F0.shape[0]):
                    slope += F0[i] * dU[i]
                slope *= dtau
                if not slope < 0.0:
                    break  # an inexact or indefinite solve gave no descent direction
        step = 1.0
        trial = norm
        trial_cost = cost
        accepted = False
        for _ in range(12):
            for i in range(n):
                Ut[i] = U[i] + step * dU[i]
            if m == STAGE_CONDENSED:
                keep_inside(U, Ut, W)
            trial = residual(Ut, m, x, ref, dtau, W, rho, eps, active, xs, trig, Ft, NO, obs,
                             pbase, NO)
            accepted = math.isfinite(trial) and trial < (1.0 - 1e-4 * step) * norm
            if obs is not None:
                if by_cost:
                    trial_cost = condensed_cost(Ut, xs, ref, dtau, W, rho, obs)
                    accepted = (math.isfinite(trial)
                                and trial_cost <= cost + 1e-4 * step * slope)
            if accepted:
                break
            step *= 0.5
        if not accepted:
            break
        for i in range(n):
            U[i] = Ut[i]
            F0[i] = Ft[i]
        norm = trial
        cost = trial_cost
    return it, gm_total, norm



@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def update_active_set(U, active, W, eps, n_stages):
    """Eq. 3.25 bookkeeping after a solve; True if the active set changed.

    Every violated bound joins the set and its input is projected to ``bound ∓ ε`` (the next
    Newton solve then starts feasible for it); an active bound whose multiplier ν turned
    negative (it pushes the wrong way) leaves the set.
    """
    m = STAGE_ACTIVE
    changed = False
    for i in range(n_stages):
        for j in range(NU):
            u = U[i * m + j]
            if active[i, j] == 0 and u > W[4, j]:
                active[i, j] = 1
                U[i * m + j] = W[4, j] - eps
                changed = True
            elif active[i, j] == 0 and u < W[3, j]:
                active[i, j] = -1
                U[i * m + j] = W[3, j] + eps
                changed = True
            elif active[i, j] != 0 and U[i * m + 4 + j] < 0.0:
                active[i, j] = 0
                U[i * m + 4 + j] = 0.0
                changed = True
    return changed


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def activate_blocking_bounds(U, dU, active, W, eps, n_stages):
    """Eq. 3.25 for a stalled solve: move along the last Newton direction ``dU`` to the first
    bound it meets, which joins the active set (its input at ``bound ∓ ε``). True if one did.

    An unconstrained Newton iteration aimed at a target far outside the box can stall (no
    step lowers ‖F‖, e.g. where tan θ grows without bound) before any input leaves the box,
    and eq. 3.25 would then never see a violation. As in a primal active-set method, the
    blocking bound of the direction is the one to impose; imposing every bound the full
    step would cross over-constrains the next solve when the direction is poor.
    """
    m = STAGE_ACTIVE
    alpha = 1.0
    for i in range(n_stages):
        for j in range(NU):
            k = i * m + j
            if active[i, j] != 0 or dU[k] == 0.0:
                continue
            if U[k] + dU[k] > W[4, j] - eps:
                alpha = min(alpha, max(0.0, (W[4, j] - eps - U[k]) / dU[k]))
            elif U[k] + dU[k] < W[3, j] + eps:
                alpha = min(alpha, max(0.0, (W[3, j] + eps - U[k]) / dU[k]))
    changed = False
    for i in range(n_stages):
        for j in range(NU):
            k = i * m + j
            if active[i, j] != 0:
                continue
            u = U[k] + alpha * dU[k]
            if u >= W[4, j] - eps * (1.0 + 1e-9) and dU[k] > 0.0:
                active[i, j] = 1
                U[k] = W[4, j] - eps
                changed = True
            elif u <= W[3, j] + eps * (1.0 + 1e-9) and dU[k] < 0.0:
                active[i, j] = -1
                U[k] = W[3, j] + eps
                changed = True
            else:
                U[k] = u
    return changed
