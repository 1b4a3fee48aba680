"""One control tick of each NMPC scheme on the packed memory (the entry points from Python).

* :func:`cgmres_step` — C/GMRES (Ohtsuka): a continuation update per tick, a Newton
  re-projection when ‖F‖ jumps;
* :func:`newton_step` — the thesis' scheme: Newton/fdgmres to tolerance, then eq. 3.25.
"""

from __future__ import annotations

import math

from numba import njit

from ardrone_nmpc.control.gmres import FAST_MATH
from ardrone_nmpc.control.kernels.layout import (
    FLAG_BAD_INPUT, FLAG_NON_FINITE, FLAG_OK, NO, NO_ACTIVE, NU, NX, P_DTAU, P_DTAU_NEXT, P_H,
    P_PERIOD, P_RHO, P_RTOL, P_TOL, P_TRIGGER, P_ZETA, STAGE_ACTIVE, STAGE_CONDENSED,
    carve_workspace, unpack)
from ardrone_nmpc.control.kernels.residual import aim_obstacles, dynamics, keep_inside, residual
from ardrone_nmpc.control.kernels.solve import (activate_blocking_bounds, clip_first_input,
                                               fdgmres, newton_solve, prepare_reference,
                                               update_active_set)
from ardrone_nmpc.core.numerics import OUTER_KERNEL

ACTIVE_SET_ROUNDS = 32  # eq. 3.25 re-solves per tick at most
# With obstacles, a Newton re-projection stops at this fraction of the trigger residual and
# solves each Newton step to this relative GMRES residual (inexact Newton): its Gauss–Newton
# iterations converge only linearly, and the continuation finishes the job (solver-notes §7).
REPROJECTION_FRACTION = 0.5
REPROJECTION_RTOL = 0.1


# The ticks are inlined into their entry points (numba IR), not compiled as functions of their
# own: every compiled function re-optimises and re-emits the machine code of all it calls, so a
# level less is ~2 CPU s less of the cold start (docs/benchmarks.md "Cold start").
@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, inline="always")
def cgmres_tick(U, dU, x, ref, W, prm, iprm, initialise, buf, u_out, stats, obs=None):
    """One C/GMRES control tick (Ohtsuka 2004); ``U``, ``dU``, ``u_out``, ``stats`` are written.

    With ``initialise`` it first solves ``F = 0`` by Newton/GMRES from ``U`` (start on the
    solution manifold); so it does when ‖F‖ at the new measurement exceeds the trigger. Then
    it solves ``F_U U̇ = −ζ F − F_x ẋ − F_t`` with forward differences along
    ``(ẋ, 1)``, ``ẋ = f(x, u_0)``, warm-started from the last ``U̇``; writes ``u_0`` of the
    solution at ``t`` to ``u_out`` and sets ``U ← U + U̇ Δt`` (Ohtsuka's explicit-Euler
    integration of the continuation). Returns a ``FLAG_*``.
    """
    m = iprm[0]
    kmax = iprm[1]
    n_stages = ref.shape[0] - 1
    views = carve_workspace(buf, n_stages, m, max(kmax, iprm[3]))
    xs, ref0, ref1, trig, _, _, _, _, _, F0, F1, rhs, _, _, _, _, x1, pbase = views
    gauss_newton = iprm[5] != 0
    stats[:] = 0.0
    if not prepare_reference(x, ref, ref0):
        return FLAG_BAD_INPUT
    if obs is not None:
        aim_obstacles(obs, x)
    dtau = prm[P_DTAU]
    dtau_next = prm[P_DTAU_NEXT]
    rho = prm[P_RHO]
    h = prm[P_H]
    rtol = prm[P_RTOL]
    newton_ran = initialise
    if initialise:
        it, gm, norm = newton_solve(U, m, x, ref0, dtau, W, rho, 0.0, NO_ACTIVE, prm[P_TOL],
                                    iprm[2], h, iprm[3], rtol, views, obs, gauss_newton)
        stats[0] = it
        stats[1] = gm
        stats[2] = norm
        dU[:] = 0.0
    else:
        norm = residual(U, m, x, ref0, dtau, W, rho, 0.0, NO_ACTIVE, xs, trig, F0, NO, obs,
                        pbase, NO)
        if norm > prm[P_TRIGGER]:
            newton_ran = True
            # A jump the continuation cannot follow (a reference step is an impulse in F_t):
            # re-project onto F = 0 by line-searched Newton, warm-started from U.
            # With obstacles: an inexact, early-stopped re-projection (REPROJECTION_*).
            tol = prm[P_TOL]
            eta = rtol
            if obs is not None:
                tol = max(tol, REPROJECTION_FRACTION * prm[P_TRIGGER])
                eta = max(rtol, REPROJECTION_RTOL)
            it, gm, norm = newton_solve(U, m, x, ref0, dtau, W, rho, 0.0, NO_ACTIVE, tol,
                                        iprm[2], h, iprm[3], eta, views, obs, gauss_newton)
            stats[0] = it
            stats[1] = gm
            stats[2] = norm
            dU[:] = 0.0
    # x1 = x + h f(x, u0)
    dynamics(x, U[:NU], x1)
    for i in range(NX):
        x1[i] = x[i] + h * x1[i]
    # the reference at t + h, interpolated along the horizon
    c = h / dtau
    for i in range(n_stages + 1):
        i0 = i if i < n_stages else n_stages - 1  # the last point extrapolates the last slope
        for k in range(NX):
            ref1[i, k] = ref0[i, k] + c * (ref0[i0 + 1, k] - ref0[i0, k])
    norm0 = norm  # F0 holds F(U, x, t): computed above, or left current by newton_solve
    # F0's input trig is valid for U unless a Newton line search evaluated other points last
    residual(U, m, x1, ref1, dtau_next, W, rho, 0.0, NO_ACTIVE, xs, trig, F1, not newton_ran,
             obs, pbase, NO)
    zeta = prm[P_ZETA]
    for i in range(F0.shape[0]):
        rhs[i] = -zeta * F0[i] - (F1[i] - F0[i]) / h
    k, _ = fdgmres(U, m, x1, ref1, dtau_next, W, rho, 0.0, NO_ACTIVE, F1, rhs, dU, h, kmax,
                   rtol, views, dU, obs, gauss_newton)
    # Apply U(t)[0] — the input the prediction above assumed — then integrate U to t + Δt.
    # Applying the integrated U[0] instead would apply the input meant for one period later
    # (measured +4 % closed-loop cost), and extrapolating back along the horizon breaks the
    # consistency with ẋ = f(x, U[0]) and leaves a fixed point with F ≠ 0 (a steady offset).
    applied_ok = clip_first_input(U, W, u_out)
    period = prm[P_PERIOD]
    Unew = views[12]  # Ut: free again after fdgmres
    for i in range(U.shape[0]):
        Unew[i] = U[i] + period * dU[i]
    if m == STAGE_CONDENSED:
        keep_inside(U, Unew, W)
    for i in range(U.shape[0]):
        U[i] = Unew[i]
    stats[1] += k
    stats[3] = norm0
    if not (math.isfinite(norm0) and applied_ok and math.isfinite(U[0])):
        return FLAG_NON_FINITE
    return FLAG_OK



# The per-tick entry points from Python, on packed memory: one per scheme and per obstacle
# table (empty or not), so that a run compiles only the one its solver calls.
@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **OUTER_KERNEL)
def cgmres_step(mem, x, ref, iprm, initialise):
    """:func:`cgmres_tick` without obstacles (the obstacle-free specialisation: the
    ``obs is not None`` branches are not compiled, see the layout's docstring)."""
    U, dU, u_out, stats, W, prm, _, buf = unpack(mem, ref.shape[0] - 1, iprm[0], iprm[4])
    return cgmres_tick(U, dU, x, ref, W, prm, iprm, initialise, buf, u_out, stats)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **OUTER_KERNEL)
def cgmres_step_obstacles(mem, x, ref, iprm, initialise):
    """:func:`cgmres_tick` with the obstacle table of the memory."""
    U, dU, u_out, stats, W, prm, obs, buf = unpack(mem, ref.shape[0] - 1, iprm[0], iprm[4])
    return cgmres_tick(U, dU, x, ref, W, prm, iprm, initialise, buf, u_out, stats, obs)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **OUTER_KERNEL)
def newton_step(mem, x, ref, iprm, active):
    """:func:`newton_tick` without obstacles."""
    U, _, u_out, stats, W, prm, _, buf = unpack(mem, ref.shape[0] - 1, iprm[0], iprm[4])
    return newton_tick(U, x, ref, W, prm, iprm, active, buf, u_out, stats)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **OUTER_KERNEL)
def newton_step_obstacles(mem, x, ref, iprm, active):
    """:func:`newton_tick` with the obstacle table of the memory."""
    U, _, u_out, stats, W, prm, obs, buf = unpack(mem, ref.shape[0] - 1, iprm[0], iprm[4])
    return newton_tick(U, x, ref, W, prm, iprm, active, buf, u_out, stats, obs)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, inline="always")
def newton_tick(U, x, ref, W, prm, iprm, active, buf, u_out, stats, obs=None):
    """One tick of the thesis' method (m = 8): Newton/fdgmres to tolerance, then eq. 3.25.

    After each solve the active set is updated (:func:`update_active_set`) and, if it
    changed, the solve repeats — at most ``ACTIVE_SET_ROUNDS`` times. Returns a ``FLAG_*``.
    """
    m = STAGE_ACTIVE
    n_stages = ref.shape[0] - 1
    views = carve_workspace(buf, n_stages, m, iprm[1])
    ref0 = views[1]
    stats[:] = 0.0
    if not prepare_reference(x, ref, ref0):
        return FLAG_BAD_INPUT
    if obs is not None:
        aim_obstacles(obs, x)
    eps = prm[P_RHO]  # the ε of eq. 3.25 travels in the ρ slot for this layout
    norm = 0.0
    for _ in range(ACTIVE_SET_ROUNDS):
        it, gm, norm = newton_solve(U, m, x, ref0, prm[P_DTAU], W, 0.0, eps, active,
                                    prm[P_TOL], iprm[2], prm[P_H], iprm[1], prm[P_RTOL], views,
                                    obs, iprm[5] != 0)
        stats[0] += it
        stats[1] += gm
        changed = update_active_set(U, active, W, eps, n_stages)
        stalled = math.isfinite(norm) and norm > prm[P_TOL] and it < iprm[2]
        if stalled and not changed:
            changed = activate_blocking_bounds(U, views[15], active, W, eps, n_stages)
        if not changed:
            break
    stats[2] = norm
    stats[3] = norm
    if not (math.isfinite(norm) and clip_first_input(U, W, u_out)):
        return FLAG_NON_FINITE
    return FLAG_OK
