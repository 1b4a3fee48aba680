"""The optimality residual ``F(U, x, t)`` of every stage layout, its cost, and the model.

:func:`residual` rolls the model forward (forward Euler, eq. 3.14/3.16), runs the costates
backward (eq. 3.19/3.20) and stacks the stationarity rows of layout ``m`` (eq. 3.21);
:func:`condensed_cost` is the cost whose gradient the condensed residual is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control import obstacles
from ardrone_nmpc.control.gmres import FAST_MATH
from ardrone_nmpc.control.kernels.layout import NO_BASE, NU, NX, STAGE_CONDENSED, STAGE_DUMMY
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.types import GRAVITY_MPS2
from ardrone_nmpc.model import dynamics as _dynamics

# Beyond |s| = S_MAX the condensed bound term continues along its tangent, so an iterate
# outside the box gets a finite, steep residual that pulls it back instead of a NaN.
S_MAX = 0.999
# An update that would take a condensed input across its bound moves it this fraction of the
# way to the bound instead (component-wise fraction-to-the-boundary): the barrier is only
# meaningful inside the box, and outside it the model's tan() has spurious stationary points.
FRACTION_TO_BOUND = 0.99

# Eq. 3.13 compiled from its single definition in ardrone_nmpc.model.
dynamics = njit(cache=True, error_model="numpy", fastmath=FAST_MATH, inline="always")(_dynamics)
# The obstacle penalty compiled from ardrone_nmpc.control.obstacles.
penalty = njit(cache=True, error_model="numpy", fastmath=FAST_MATH)(obstacles.penalty)
penalty_gradient = njit(cache=True, error_model="numpy", fastmath=FAST_MATH,
                        inline="always")(obstacles.penalty_gradient)
aim_obstacles = njit(cache=True, error_model="numpy", fastmath=FAST_MATH)(
    obstacles.aim_obstacles)


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **OUTER_KERNEL)
def rollout_rk4(x, inputs, dt, out):
    """``out`` = ``x`` integrated through ``inputs`` (k, 4), each held for ``dt`` (RK4 of
    eq. 3.13) — the delay compensation's prediction of the state a new command will meet."""
    rollout_rk4_into(x, inputs, dt, out, np.empty(5 * NX))


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def rollout_rk4_into(x, inputs, dt, out, scratch):
    """:func:`rollout_rk4` with its four slopes and trial state in ``scratch`` (5·NX, any
    contents): a compiled caller with a buffer of its own (the tick's ``nmpc_inputs``)
    allocates nothing, five allocations a tick."""
    for i in range(NX):
        out[i] = x[i]
    k1 = scratch[0:NX]
    k2 = scratch[NX:2 * NX]
    k3 = scratch[2 * NX:3 * NX]
    k4 = scratch[3 * NX:4 * NX]
    tmp = scratch[4 * NX:5 * NX]
    for r in range(inputs.shape[0]):
        u = inputs[r]
        dynamics(out, u, k1)
        for i in range(NX):
            tmp[i] = out[i] + 0.5 * dt * k1[i]
        dynamics(tmp, u, k2)
        for i in range(NX):
            tmp[i] = out[i] + 0.5 * dt * k2[i]
        dynamics(tmp, u, k3)
        for i in range(NX):
            tmp[i] = out[i] + dt * k3[i]
        dynamics(tmp, u, k4)
        for i in range(NX):
            out[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


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


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def bound_gradient(s):
    """``s/√(1 − s²)`` for |s| < S_MAX, continued along its tangent beyond (condensed bounds)."""
    if abs(s) < S_MAX:
        return s / math.sqrt(1.0 - s * s)
    s0 = S_MAX if s > 0 else -S_MAX
    c = 1.0 - S_MAX * S_MAX
    return s0 / math.sqrt(c) + (s - s0) / (c * math.sqrt(c))


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def bound_barrier(s):
    """Antiderivative of :func:`bound_gradient`: ``−√(1 − s²)``, continued beyond S_MAX by
    the quadratic whose slope is the tangent continuation."""
    if abs(s) < S_MAX:
        return -math.sqrt(1.0 - s * s)
    s0 = S_MAX if s > 0 else -S_MAX
    c = 1.0 - S_MAX * S_MAX
    ds = s - s0
    return -math.sqrt(c) + ds * s0 / math.sqrt(c) + 0.5 * ds * ds / (c * math.sqrt(c))


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
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


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
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


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
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
    for k in range(NX):
        xs[0, k] = x0[k]
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
