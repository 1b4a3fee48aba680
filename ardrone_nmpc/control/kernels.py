"""Numba kernels of the thesis OCP (eq. 3.14–3.25): residual F(U, x, t), fdgmres, C/GMRES, Newton.

Problem (per stage ``i = 0 … N−1``, forward Euler, thesis eq. 3.14/3.16)::

    x_{i+1} = x_i + f(x_i, u_i) Δτ
    L_i     = ½ (x_i − x_d,i)ᵀ q (x_i − x_d,i) + ½ u_iᵀ r u_i
    Φ       = ½ (x_N − x_d,N)ᵀ q_f (x_N − x_d,N)            (q_f = 0 in the thesis)

Costates run backward, ``λ_N = q_f (x_N − x_d,N)``, ``λ_i = λ_{i+1} + H_x Δτ`` (eq. 3.19/3.20),
and ``F`` stacks the stationarity conditions per stage (eq. 3.21). Stage layouts (``m``):

* ``m = 12`` — dummy-input form (Ohtsuka): unknowns ``[u(4), v(4), μ(4)]``; each bound
  ``u_min ≤ u ≤ u_max`` becomes ``(u − c)² + v² − w² = 0`` (``c``, ``w`` centre and half-width)
  and the cost gains ``−ρ_d Σ v``. Rows ``H_u = r u + f_uᵀλ + 2μ(u − c)``, ``H_v = −ρ_d + 2μv``,
  ``C``.
* ``m = 4`` — the same equations condensed: ``C = 0`` and ``H_v = 0`` give
  ``v = √(w² − (u − c)²)``, ``μ = ρ_d / 2v``, so ``2μ(u − c) = ρ_d s/√(1 − s²)`` with
  ``s = (u − c)/w``. ``F`` is the gradient of the barrier-augmented cost and ``F_U`` its
  symmetric Hessian, on which restarted GMRES(5) converges; on the indefinite ``m = 12``
  system it stagnates (docs/solver-notes.md).
* obstacles (any layout) — an exterior penalty ``½ w max(0, d² − ‖p − c‖²)²``
  (:mod:`~ardrone_nmpc.control.obstacles`) on every predicted position, the terminal one
  included; its position gradient joins ``H_x`` in the costate recursion. Jacobian
  products see its Gauss–Newton curvature and Newton line searches the cost
  (:func:`condensed_cost`) as merit, so that the iterations head for a way round an obstacle,
  not for the stationary path through its centre (docs/solver-notes.md §7).
* ``m = 8`` — the thesis' eq. 3.25: unknowns ``[u(4), ν(4)]`` and an active set
  ``a ∈ {−1, 0, +1}`` per input; an active bound imposes ``u = u_max − ε`` (``u_min + ε``), an
  inactive one ``ν = 0``. Rows ``H_u = r u + f_uᵀλ + a ν``, then the constraint or ``ν``.

Packed arguments keep the Python→numba call cheap (one dispatch per tick, few arrays):

* ``W`` (5, 7): rows ``q``, ``q_f``, ``r`` (first 4), ``u_min`` (first 4), ``u_max`` (first 4).
* ``prm`` (9,): ``Δτ, Δτ(t+h), ρ_d, ζ, h, η, Δt_control, tolerance, Newton trigger ‖F‖``.
* ``iprm`` (6,): ``m, kmax, max Newton iterations, kmax of a Newton solve, obstacles,
  Gauss–Newton obstacle curvature (0/1)``.
* ``obs`` (n_obs, ``OBS_COLS``): the obstacle table, rewritable between ticks. Kernels take
  ``obs=None`` without obstacles: numba prunes every ``if obs is not None`` branch at compile
  time, so the obstacle-free solver is the same machine code as before obstacles existed
  (bit-identical results; a runtime ``n_obs == 0`` test would let LLVM's fast-math
  contract and reassociate differently).
* ``buf``: one flat workspace, carved by :func:`_views` (:func:`workspace_size` long).
* ``stats`` (4,) out: ``Newton iterations, GMRES iterations, ‖F‖ after Newton, ‖F‖ at the
  continuation point``.

``U`` is flat: stage ``i`` occupies ``U[i*m : (i+1)*m]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control import obstacles
from ardrone_nmpc.control.gmres import FAST_MATH, gmres_finish, gmres_iterate, gmres_start
from ardrone_nmpc.control.obstacles import OBS_COLS
from ardrone_nmpc.model import dynamics

GRAVITY_MPS2 = 9.81
NX = 7
NU = 4
STAGE_CONDENSED = 4
STAGE_ACTIVE = 8
STAGE_DUMMY = 12
# Beyond |s| = S_MAX the condensed bound term continues along its tangent, so an iterate
# outside the box gets a finite, steep residual that pulls it back instead of a NaN.
S_MAX = 0.999
# An update that would take a condensed input across its bound moves it this fraction of the
# way to the bound instead (component-wise fraction-to-the-boundary): the barrier is only
# meaningful inside the box, and outside it the model's tan() has spurious stationary points.
FRACTION_TO_BOUND = 0.99
# prm indices
P_DTAU, P_DTAU_NEXT, P_RHO, P_ZETA, P_H, P_RTOL, P_PERIOD, P_TOL, P_TRIGGER = range(9)
N_PRM = 9
ACTIVE_SET_ROUNDS = 32  # eq. 3.25 re-solves per tick at most
# With obstacles, a Newton re-projection stops at this fraction of the trigger residual and
# solves each Newton step to this relative GMRES residual (inexact Newton): its Gauss–Newton
# iterations converge only linearly, and the continuation finishes the job (solver-notes §7).
REPROJECTION_FRACTION = 0.5
REPROJECTION_RTOL = 0.1
NO_ACTIVE = np.zeros((1, 1), dtype=np.int8)  # the active set argument of layouts without one
NO_BASE = np.zeros((1, 3))  # the base positions argument of exact evaluations
# return flags
FLAG_OK, FLAG_BAD_INPUT, FLAG_NON_FINITE = 0, 1, 2


def workspace_size(horizon_steps: int, stage_dim: int, kmax: int) -> int:
    """Length of the flat ``buf`` for :func:`_views`."""
    n = horizon_steps * stage_dim
    rows = horizon_steps + 1
    return (3 * rows * NX + rows * 5 + (kmax + 1) * n + (kmax + 1) * kmax + 3 * kmax + 1 + 7 * n
            + NX + rows * 3)


def memory_size(horizon_steps: int, stage_dim: int, kmax: int, n_obstacles: int = 0) -> int:
    """Length of one solver's packed float memory (see :func:`unpack`)."""
    n = horizon_steps * stage_dim
    return (2 * n + NU + 4 + 5 * NX + N_PRM + n_obstacles * OBS_COLS
            + workspace_size(horizon_steps, stage_dim, kmax))


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def rollout_rk4(x, inputs, dt, out):
    """``out`` = ``x`` integrated through ``inputs`` (k, 4), each held for ``dt`` (RK4 of
    eq. 3.13) — the delay compensation's prediction of the state a new command will meet."""
    out[:] = x
    k1 = np.empty(NX)
    k2 = np.empty(NX)
    k3 = np.empty(NX)
    k4 = np.empty(NX)
    tmp = np.empty(NX)
    for r in range(inputs.shape[0]):
        u = inputs[r]
        _model(out, u, k1)
        for i in range(NX):
            tmp[i] = out[i] + 0.5 * dt * k1[i]
        _model(tmp, u, k2)
        for i in range(NX):
            tmp[i] = out[i] + 0.5 * dt * k2[i]
        _model(tmp, u, k3)
        for i in range(NX):
            tmp[i] = out[i] + dt * k3[i]
        _model(tmp, u, k4)
        for i in range(NX):
            out[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


# Eq. 3.13 compiled from its single definition in ardrone_nmpc.model.
_model = njit(cache=True, error_model="numpy", fastmath=FAST_MATH, inline="always")(dynamics)
# The obstacle penalty compiled from ardrone_nmpc.control.obstacles. (numba's cache keys on
# this file: after editing obstacles.py, delete control/__pycache__/*.nb[ic].)
penalty = njit(cache=True, error_model="numpy", fastmath=FAST_MATH)(obstacles.penalty)
penalty_gradient = njit(cache=True, error_model="numpy", fastmath=FAST_MATH,
                        inline="always")(obstacles.penalty_gradient)
aim_obstacles = njit(cache=True, error_model="numpy", fastmath=FAST_MATH)(
    obstacles.aim_obstacles)


@njit(cache=True)
def unpack(mem, n_stages, m, n_obs):
    """Views of one solver's packed memory: ``(U, dU, u_out, stats, W, prm, obs, buf)``.

    One array instead of seven keeps the Python→numba call of every tick cheap (dispatch
    costs per argument); the Python side holds the same views.
    """
    n = n_stages * m
    o = 0
    U = mem[o:o + n]; o += n
    dU = mem[o:o + n]; o += n
    u_out = mem[o:o + NU]; o += NU
    stats = mem[o:o + 4]; o += 4
    W = mem[o:o + 5 * NX].reshape((5, NX)); o += 5 * NX
    prm = mem[o:o + N_PRM]; o += N_PRM
    obs = mem[o:o + n_obs * OBS_COLS].reshape((n_obs, OBS_COLS)); o += n_obs * OBS_COLS
    return U, dU, u_out, stats, W, prm, obs, mem[o:]


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def _views(buf, n_stages, m, kmax):
    """Carve ``buf`` into (xs, ref0, ref1, trig, V, H, cs, sn, g, F0, F1, rhs, Ut, Ft, w, dU, x1,
    pbase)."""
    n = n_stages * m
    rows = n_stages + 1
    o = 0
    xs = buf[o:o + rows * NX].reshape((rows, NX)); o += rows * NX
    ref0 = buf[o:o + rows * NX].reshape((rows, NX)); o += rows * NX
    ref1 = buf[o:o + rows * NX].reshape((rows, NX)); o += rows * NX
    trig = buf[o:o + rows * 5].reshape((rows, 5)); o += rows * 5
    V = buf[o:o + (kmax + 1) * n].reshape((kmax + 1, n)); o += (kmax + 1) * n
    H = buf[o:o + (kmax + 1) * kmax].reshape((kmax + 1, kmax)); o += (kmax + 1) * kmax
    cs = buf[o:o + kmax]; o += kmax
    sn = buf[o:o + kmax]; o += kmax
    g = buf[o:o + kmax + 1]; o += kmax + 1
    F0 = buf[o:o + n]; o += n
    F1 = buf[o:o + n]; o += n
    rhs = buf[o:o + n]; o += n
    Ut = buf[o:o + n]; o += n
    Ft = buf[o:o + n]; o += n
    w = buf[o:o + n]; o += n
    dU = buf[o:o + n]; o += n
    x1 = buf[o:o + NX]; o += NX
    pbase = buf[o:o + rows * 3].reshape((rows, 3))
    return xs, ref0, ref1, trig, V, H, cs, sn, g, F0, F1, rhs, Ut, Ft, w, dU, x1, pbase


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, inline="always")
def sincos_small(a):
    """``(sin a, cos a)``: Taylor polynomials to a¹³/a¹⁴ for |a| ≤ 0.5 (error < 1e-16),
    the library functions beyond. Cheaper than two calls for the small ψ increments."""
    if abs(a) > 0.5:
        return math.sin(a), math.cos(a)
    a2 = a * a
    s = a * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0 * (1.0 - a2 / 42.0 * (1.0 - a2 / 72.0 * (
        1.0 - a2 / 110.0 * (1.0 - a2 / 156.0))))))
    c = 1.0 - a2 / 2.0 * (1.0 - a2 / 12.0 * (1.0 - a2 / 30.0 * (1.0 - a2 / 56.0 * (
        1.0 - a2 / 90.0 * (1.0 - a2 / 132.0 * (1.0 - a2 / 182.0))))))
    return s, c


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def bound_gradient(s):
    """``s/√(1 − s²)`` for |s| < S_MAX, continued along its tangent beyond (condensed bounds)."""
    if abs(s) < S_MAX:
        return s / math.sqrt(1.0 - s * s)
    s0 = S_MAX if s > 0 else -S_MAX
    c = 1.0 - S_MAX * S_MAX
    return s0 / math.sqrt(c) + (s - s0) / (c * math.sqrt(c))


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def bound_barrier(s):
    """Antiderivative of :func:`bound_gradient`: ``−√(1 − s²)``, continued beyond S_MAX by
    the quadratic whose slope is the tangent continuation."""
    if abs(s) < S_MAX:
        return -math.sqrt(1.0 - s * s)
    s0 = S_MAX if s > 0 else -S_MAX
    c = 1.0 - S_MAX * S_MAX
    ds = s - s0
    return -math.sqrt(c) + ds * s0 / math.sqrt(c) + 0.5 * ds * ds / (c * math.sqrt(c))


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def condensed_cost(U, xs, ref, dtau, W, rho, obs):
    """The cost whose gradient is the condensed residual (``F = ∇_U J / Δτ``, m = 4).

    ``J = Σ_i Δτ [½ e_iᵀ q e_i + ½ u_iᵀ r u_i + ρ Σ_j w_j b(s_ij) + P(x_i)]
    + ½ e_Nᵀ q_f e_N + Δτ P(x_N)`` with ``e_i = x_i − x_d,i``, ``b`` :func:`bound_barrier`
    (the eliminated dummy inputs' ``−ρ v``), ``P`` the obstacle penalty. ``xs`` must hold the
    rollout of ``U`` (as :func:`residual` leaves it).
    """
    n_stages = ref.shape[0] - 1
    q = W[0]
    total = 0.0
    for i in range(n_stages + 1):
        weights = W[1] if i == n_stages else q
        stage = 0.0
        for k in range(NX):
            e = xs[i, k] - ref[i, k]
            stage += 0.5 * weights[k] * e * e
        if i == n_stages:
            total += stage + dtau * penalty(obs, xs[i, 0], xs[i, 2], xs[i, 4])
            break
        b = i * STAGE_CONDENSED
        for j in range(NU):
            u = U[b + j]
            lo = W[3, j]
            hi = W[4, j]
            stage += 0.5 * W[2, j] * u * u
            stage += rho * 0.5 * (hi - lo) * bound_barrier((2.0 * u - (hi + lo)) / (hi - lo))
        stage += penalty(obs, xs[i, 0], xs[i, 2], xs[i, 4])
        total += dtau * stage
    return total


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def keep_inside(U_old, U_new, W):
    """Condensed layout: pull every input of ``U_new`` that left the box back inside.

    A component whose update would cross a bound goes ``FRACTION_TO_BOUND`` of the way from
    its old value to that bound instead; the others keep their full step.
    """
    for k in range(U_new.shape[0]):
        j = k % NU
        lo = W[3, j]
        hi = W[4, j]
        if U_new[k] >= hi:
            U_new[k] = U_old[k] + FRACTION_TO_BOUND * (hi - U_old[k])
        elif U_new[k] <= lo:
            U_new[k] = U_old[k] + FRACTION_TO_BOUND * (lo - U_old[k])


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def residual(U, m, x0, ref, dtau, W, rho, eps, active, xs, trig, out, same_inputs=False,
             obs=None, base=NO_BASE, gauss_newton=False):
    """Evaluate ``F(U, x0, t)`` into ``out`` (N·m,); return ``‖F‖₂``.

    ``ref`` (N+1, 7): the reference at the stage times ``t + iΔτ``. ``xs`` (N+1, 7) ends
    holding the predicted trajectory; ``trig`` (N+1, 5) caches the forward pass' sin/cos/tan.
    ``same_inputs``: ``U`` is the one of the previous call, so the inputs' tan/sec in
    ``trig`` are still valid (saves 3N trig calls; ψ's are recomputed as ``x0`` may differ).
    ``obs`` (n_obs, ``OBS_COLS``) or None: obstacles penalised at every predicted position.
    ``gauss_newton``: take the penalty gradients' directions at ``base`` (N+1, 3), the
    positions of a base rollout, instead of the positions of this one — for Jacobian–vector
    products with Gauss–Newton curvature of the penalty (:func:`fdgmres`).
    """
    n_stages = ref.shape[0] - 1
    xs[0, :] = x0
    spsi = math.sin(x0[6])
    cpsi = math.cos(x0[6])
    for i in range(n_stages):
        b = i * m
        if i > 0:  # ψ_i = ψ_{i−1} + Δτ u_{i−1,3}: rotate instead of two more trig calls
            s_d, c_d = sincos_small(dtau * U[b - m + 3])
            spsi, cpsi = spsi * c_d + cpsi * s_d, cpsi * c_d - spsi * s_d
        if same_inputs:
            tphi = trig[i, 2]
            tth = trig[i, 3]
            sec_th = trig[i, 4]
        else:
            tphi = math.tan(U[b + 1])
            sec_th = 1.0 / math.cos(U[b + 2])
            tth = math.sin(U[b + 2]) * sec_th
            trig[i, 2] = tphi
            trig[i, 3] = tth
            trig[i, 4] = sec_th
        thrust = U[b] + GRAVITY_MPS2
        trig[i, 0] = spsi
        trig[i, 1] = cpsi
        xs[i + 1, 0] = xs[i, 0] + dtau * xs[i, 1]
        xs[i + 1, 1] = xs[i, 1] + dtau * (spsi * tphi * sec_th + cpsi * tth) * thrust
        xs[i + 1, 2] = xs[i, 2] + dtau * xs[i, 3]
        xs[i + 1, 3] = xs[i, 3] + dtau * (-cpsi * tphi * sec_th + spsi * tth) * thrust
        xs[i + 1, 4] = xs[i, 4] + dtau * xs[i, 5]
        xs[i + 1, 5] = xs[i, 5] + dtau * U[b]
        xs[i + 1, 6] = xs[i, 6] + dtau * U[b + 3]
    # λ_N = Φ_xᵀ, then backward (eq. 3.19, 3.20); l0..l6 hold λ_{i+1}.
    qf = W[1]
    l0 = qf[0] * (xs[n_stages, 0] - ref[n_stages, 0])
    l1 = qf[1] * (xs[n_stages, 1] - ref[n_stages, 1])
    l2 = qf[2] * (xs[n_stages, 2] - ref[n_stages, 2])
    l3 = qf[3] * (xs[n_stages, 3] - ref[n_stages, 3])
    l4 = qf[4] * (xs[n_stages, 4] - ref[n_stages, 4])
    l5 = qf[5] * (xs[n_stages, 5] - ref[n_stages, 5])
    l6 = qf[6] * (xs[n_stages, 6] - ref[n_stages, 6])
    if obs is not None:  # the terminal state is penalised like a stage (weight Δτ)
        g0, g2, g4 = _penalty_gradient_at(obs, xs, n_stages, base, gauss_newton)
        l0 += dtau * g0
        l2 += dtau * g2
        l4 += dtau * g4
    q = W[0]
    norm2 = 0.0
    for i in range(n_stages - 1, -1, -1):
        b = i * m
        spsi = trig[i, 0]
        cpsi = trig[i, 1]
        tphi = trig[i, 2]
        tth = trig[i, 3]
        sec_th = trig[i, 4]
        thrust = U[b] + GRAVITY_MPS2
        ax = spsi * tphi * sec_th + cpsi * tth  # ẍ / (z̈ + g)
        ay = -cpsi * tphi * sec_th + spsi * tth  # ÿ / (z̈ + g)
        # f_uᵀ λ_{i+1}
        fl0 = l1 * ax + l3 * ay + l5
        fl1 = (l1 * spsi - l3 * cpsi) * (1.0 + tphi * tphi) * sec_th * thrust
        sec2th = 1.0 + tth * tth
        fl2 = (l1 * (spsi * tphi * tth * sec_th + cpsi * sec2th)
               + l3 * (-cpsi * tphi * tth * sec_th + spsi * sec2th)) * thrust
        fl3 = l6
        for j in range(NU):
            fl = fl0 if j == 0 else (fl1 if j == 1 else (fl2 if j == 2 else fl3))
            norm2 += _stage_rows(U, b, j, i, m, fl, W, rho, eps, active, out)
        # λ_i = λ_{i+1} + H_x Δτ, H_x = q (x_i − x_d,i) + f_xᵀ λ_{i+1}
        dxdpsi = -ay * thrust  # ∂ẍ/∂ψ
        dydpsi = ax * thrust  # ∂ÿ/∂ψ
        n0 = l0 + dtau * q[0] * (xs[i, 0] - ref[i, 0])
        n1 = l1 + dtau * (q[1] * (xs[i, 1] - ref[i, 1]) + l0)
        n2 = l2 + dtau * q[2] * (xs[i, 2] - ref[i, 2])
        n3 = l3 + dtau * (q[3] * (xs[i, 3] - ref[i, 3]) + l2)
        n4 = l4 + dtau * q[4] * (xs[i, 4] - ref[i, 4])
        n5 = l5 + dtau * (q[5] * (xs[i, 5] - ref[i, 5]) + l4)
        n6 = l6 + dtau * (q[6] * (xs[i, 6] - ref[i, 6]) + l1 * dxdpsi + l3 * dydpsi)
        if obs is not None:  # + ∂P/∂x of the penalty in H_x
            g0, g2, g4 = _penalty_gradient_at(obs, xs, i, base, gauss_newton)
            n0 += dtau * g0
            n2 += dtau * g2
            n4 += dtau * g4
        l0, l1, l2, l3, l4, l5, l6 = n0, n1, n2, n3, n4, n5, n6
    return math.sqrt(norm2)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, inline="always")
def _penalty_gradient_at(obs, xs, i, base, gauss_newton):
    """Obstacle penalty gradient at the predicted position of stage ``i``; directions at
    ``base[i]`` when ``gauss_newton``, else exact."""
    if gauss_newton:
        return penalty_gradient(obs, xs[i, 0], xs[i, 2], xs[i, 4],
                                base[i, 0], base[i, 1], base[i, 2])
    return penalty_gradient(obs, xs[i, 0], xs[i, 2], xs[i, 4], xs[i, 0], xs[i, 2], xs[i, 4])


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, inline="always")
def _stage_rows(U, b, j, i, m, fl, W, rho, eps, active, out):
    """Rows of input ``j`` at stage ``i`` for layout ``m``; returns their squared norm."""
    u = U[b + j]
    r = W[2, j]
    lo = W[3, j]
    hi = W[4, j]
    if m == STAGE_CONDENSED:
        e_u = r * u + fl + rho * bound_gradient((2.0 * u - (hi + lo)) / (hi - lo))
        out[b + j] = e_u
        return e_u * e_u
    if m == STAGE_DUMMY:
        half = 0.5 * (hi - lo)
        v = U[b + 4 + j]
        mu = U[b + 8 + j]
        du = u - 0.5 * (hi + lo)
        e_u = r * u + fl + 2.0 * mu * du
        e_v = -rho + 2.0 * mu * v
        e_c = du * du + v * v - half * half
        out[b + j] = e_u
        out[b + 4 + j] = e_v
        out[b + 8 + j] = e_c
        return e_u * e_u + e_v * e_v + e_c * e_c
    a = active[i, j]
    nu = U[b + 4 + j]
    e_u = r * u + fl + a * nu
    if a > 0:
        e_c = u - (hi - eps)
    elif a < 0:
        e_c = (lo + eps) - u
    else:
        e_c = nu
    out[b + j] = e_u
    out[b + 4 + j] = e_c
    return e_u * e_u + e_c * e_c


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
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
            residual(U, m, x0, ref, dtau, W, rho, eps, active, xs, trig, Ft, False, obs)
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
        residual(Ut, m, x0, ref, dtau, W, rho, eps, active, xs, trig, Ft, False, obs, pbase,
                 gauss_newton)
        for i in range(n):
            w[i] = rhs[i] - (Ft[i] - Fbase[i]) * inv_h
    else:  # a zero guess needs no product: one F evaluation saved
        w[:] = rhs
    res = gmres_start(w, V, g)
    target = 0.0
    for i in range(n):
        target += rhs[i] * rhs[i]
    target = rtol * math.sqrt(target)
    k = 0
    while k < kmax and res > target:
        vk = V[k]
        for i in range(n):
            Ut[i] = U[i] + h * vk[i]
        residual(Ut, m, x0, ref, dtau, W, rho, eps, active, xs, trig, Ft, False, obs, pbase,
                 gauss_newton)
        for i in range(n):
            w[i] = (Ft[i] - Fbase[i]) * inv_h
        res = gmres_iterate(k, w, V, H, cs, sn, g)
        k += 1
    gmres_finish(k, V, H, g, guess, out)
    return k, res


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def prepare_reference(x, ref, out):
    """Copy ``ref`` into ``out`` with ψ unwrapped along the horizon and shifted by 2πk to
    lie near ``x[6]`` (the OCP penalises ψ − ψ_d unwrapped). False if anything is non-finite."""
    for k in range(NX):
        if not math.isfinite(x[k]):
            return False
    two_pi = 2.0 * math.pi
    prev = x[6]
    for i in range(ref.shape[0]):
        for k in range(NX):
            if not math.isfinite(ref[i, k]):
                return False
            out[i, k] = ref[i, k]
        out[i, 6] = ref[i, 6] + two_pi * round((prev - ref[i, 6]) / two_pi)
        prev = out[i, 6]
    return True


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def clip_first_input(U, W, u_out):
    """``u_out = clip(U[0:4], u_min, u_max)``; False if any is non-finite."""
    for j in range(NU):
        u = U[j]
        if not math.isfinite(u):
            return False
        u_out[j] = min(max(u, W[3, j]), W[4, j])
    return True


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def newton_solve(U, m, x, ref, dtau, W, rho, eps, active, tol, max_iter, h, kmax, rtol, views,
                 obs=None, gauss_newton=False):
    """Newton/GMRES on ``F(U, x, t) = 0`` (eq. 3.22–3.24) with a backtracking line search.

    ``U`` is updated in place. Returns ``(Newton iterations, GMRES iterations, ‖F‖)``.
    The line search asks ‖F‖ to fall; with obstacles in the condensed layout it asks the
    cost (:func:`condensed_cost`) to fall instead (Armijo), so that the iteration heads for
    a minimum: ‖F‖ falls just as well towards the stationary path through an obstacle's
    centre, and an obstacle ahead on the reference line puts Newton right next to it.
    """
    xs, _, _, trig, _, _, _, _, _, F0, _, rhs, Ut, Ft, _, dU, _, _ = views
    norm = residual(U, m, x, ref, dtau, W, rho, eps, active, xs, trig, F0, False, obs)
    by_cost = False
    cost = 0.0
    if obs is not None:
        by_cost = m == STAGE_CONDENSED
        cost = condensed_cost(U, xs, ref, dtau, W, rho, obs)
    it = 0
    gm_total = 0
    while it < max_iter and norm > tol and math.isfinite(norm):
        rhs[:] = -F0
        dU[:] = 0.0
        k, _ = fdgmres(U, m, x, ref, dtau, W, rho, eps, active, F0, rhs, dU, h, kmax, rtol,
                       views, dU, obs, gauss_newton)
        gm_total += k
        it += 1
        slope = 0.0
        if obs is not None:
            if by_cost:
                slope = dtau * np.dot(F0, dU)  # dJ/ds along U + s dU (F = ∇J/Δτ)
                if not slope < 0.0:
                    break  # an inexact or indefinite solve gave no descent direction
        step = 1.0
        trial = norm
        trial_cost = cost
        accepted = False
        for _ in range(12):
            Ut[:] = U + step * dU
            if m == STAGE_CONDENSED:
                keep_inside(U, Ut, W)
            trial = residual(Ut, m, x, ref, dtau, W, rho, eps, active, xs, trig, Ft, False, obs)
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
        U[:] = Ut
        F0[:] = Ft
        norm = trial
        cost = trial_cost
    return it, gm_total, norm


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def cgmres_tick(U, dU, x, ref, W, prm, iprm, initialise, buf, u_out, stats, obs=None):
    """One C/GMRES control tick (Ohtsuka 2004); ``U``, ``dU``, ``u_out``, ``stats`` are written.

    With ``initialise`` it first solves ``F = 0`` by Newton/GMRES from ``U`` (start on the
    solution manifold); so it does when ‖F‖ at the new measurement exceeds the trigger. Then it solves ``F_U U̇ = −ζ F − F_x ẋ − F_t`` with forward differences along
    ``(ẋ, 1)``, ``ẋ = f(x, u_0)``, warm-started from the last ``U̇``; writes ``u_0`` of the
    solution at ``t`` to ``u_out`` and sets ``U ← U + U̇ Δt`` (Ohtsuka's explicit-Euler
    integration of the continuation). Returns a ``FLAG_*``.
    """
    m = iprm[0]
    kmax = iprm[1]
    n_stages = ref.shape[0] - 1
    views = _views(buf, n_stages, m, max(kmax, iprm[3]))
    xs, ref0, ref1, trig, _, _, _, _, _, F0, F1, rhs, _, _, _, _, x1, _ = views
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
        norm = residual(U, m, x, ref0, dtau, W, rho, 0.0, NO_ACTIVE, xs, trig, F0, False, obs)
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
    _model(x, U[:NU], x1)
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
             obs)
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
    U[:] = Unew
    stats[1] += k
    stats[3] = norm0
    if not (math.isfinite(norm0) and applied_ok and math.isfinite(U[0])):
        return FLAG_NON_FINITE
    return FLAG_OK


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
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


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
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


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def cgmres_step(mem, x, ref, iprm, initialise):
    """:func:`cgmres_tick` on packed memory (the per-tick entry point from Python)."""
    U, dU, u_out, stats, W, prm, obs, buf = unpack(mem, ref.shape[0] - 1, iprm[0], iprm[4])
    if obs.shape[0] == 0:  # the obstacle-free specialisation (see the module docstring)
        return cgmres_tick(U, dU, x, ref, W, prm, iprm, initialise, buf, u_out, stats)
    return cgmres_tick(U, dU, x, ref, W, prm, iprm, initialise, buf, u_out, stats, obs)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def newton_step(mem, x, ref, iprm, active):
    """:func:`newton_tick` on packed memory (the per-tick entry point from Python)."""
    U, _, u_out, stats, W, prm, obs, buf = unpack(mem, ref.shape[0] - 1, iprm[0], iprm[4])
    if obs.shape[0] == 0:  # the obstacle-free specialisation (see the module docstring)
        return newton_tick(U, x, ref, W, prm, iprm, active, buf, u_out, stats)
    return newton_tick(U, x, ref, W, prm, iprm, active, buf, u_out, stats, obs)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH)
def newton_tick(U, x, ref, W, prm, iprm, active, buf, u_out, stats, obs=None):
    """One tick of the thesis' method (m = 8): Newton/fdgmres to tolerance, then eq. 3.25.

    After each solve the active set is updated (:func:`update_active_set`) and, if it
    changed, the solve repeats — at most ``ACTIVE_SET_ROUNDS`` times. Returns a ``FLAG_*``.
    """
    m = STAGE_ACTIVE
    n_stages = ref.shape[0] - 1
    views = _views(buf, n_stages, m, iprm[1])
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
