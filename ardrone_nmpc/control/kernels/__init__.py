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

Modules: ``layout`` (the packed memory), ``residual`` (F, its cost, the compiled model),
``solve`` (fdgmres, Newton, the active set), ``steps`` (one tick of each scheme), ``memory``
(:class:`SolverMemory`, what the solvers hold). The solvers use :class:`SolverMemory` only;
the kernel functions are exported here for tests and benchmarks.
"""

from __future__ import annotations

from ardrone_nmpc.control.kernels import layout, residual as _residual, solve
from ardrone_nmpc.control.kernels.layout import (FLAG_BAD_INPUT, FLAG_NON_FINITE, FLAG_OK,
                                                NO_ACTIVE, STAGE_ACTIVE, STAGE_CONDENSED,
                                                STAGE_DUMMY, memory_size, workspace_size)
from ardrone_nmpc.control.kernels.memory import SolverMemory, SolverStats
from ardrone_nmpc.control.kernels.residual import (aim_obstacles, penalty, penalty_gradient,
                                                  rollout_rk4, rollout_rk4_into, sincos_small)
from ardrone_nmpc.control.kernels.steps import (cgmres_step, cgmres_step_obstacles, newton_step,
                                                newton_step_obstacles)
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import callable_from_python

# The kernels only other kernels call are compiled without numba's Python wrapper (the cold
# start, docs/benchmarks.md); tests, benchmarks and the reference solver call these twins (the
# same source and options, so the same machine code), compiled on their first call.
bound_barrier = callable_from_python(_residual.bound_barrier)
bound_gradient = callable_from_python(_residual.bound_gradient)
condensed_cost = callable_from_python(_residual.condensed_cost)
residual = callable_from_python(_residual.residual)
carve_workspace = callable_from_python(layout.carve_workspace)
fdgmres = callable_from_python(solve.fdgmres)
newton_solve = callable_from_python(solve.newton_solve)
prepare_reference = callable_from_python(solve.prepare_reference)

__all__ = [
    "FLAG_BAD_INPUT", "FLAG_NON_FINITE", "FLAG_OK", "NO_ACTIVE", "STAGE_ACTIVE",
    "STAGE_CONDENSED", "STAGE_DUMMY", "SolverMemory", "SolverStats", "aim_obstacles",
    "bound_barrier", "bound_gradient", "carve_workspace", "cgmres_step", "cgmres_step_obstacles",
    "condensed_cost", "fdgmres", "memory_size", "newton_solve", "newton_step",
    "newton_step_obstacles", "penalty", "penalty_gradient",
    "prepare_reference", "residual", "rollout_rk4", "rollout_rk4_into", "sincos_small",
    "workspace_size",
]

# numba keys a cached kernel on its own file only: flush the solver's (and the twins' above)
# when any kernel source changed (core/kernel_cache.py)
flush_stale_caches(__name__, "ardrone_nmpc.control.kernels.layout",
                   "ardrone_nmpc.control.kernels.residual", "ardrone_nmpc.control.kernels.solve",
                   "ardrone_nmpc.control.kernels.steps")
