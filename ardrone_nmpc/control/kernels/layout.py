"""The kernels' packed memory: sizes, slot indices and the views carved from it.

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
* ``buf``: one flat workspace, carved by :func:`carve_workspace` (:func:`workspace_size`
  long).
* ``stats`` (4,) out: ``Newton iterations, GMRES iterations, ‖F‖ after Newton, ‖F‖ at the
  continuation point``.

``U`` is flat: stage ``i`` occupies ``U[i*m : (i+1)*m]``. Python code outside this package
reaches all of it through :class:`~ardrone_nmpc.control.kernels.memory.SolverMemory`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ardrone_nmpc.control.gmres import FAST_MATH
from ardrone_nmpc.control.obstacles import OBS_COLS
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL

NX = 7
NU = 4
STAGE_CONDENSED = 4
STAGE_ACTIVE = 8
STAGE_DUMMY = 12
# prm indices
P_DTAU, P_DTAU_NEXT, P_RHO, P_ZETA, P_H, P_RTOL, P_PERIOD, P_TOL, P_TRIGGER = range(9)
N_PRM = 9
NO_ACTIVE = np.zeros((1, 1), dtype=np.int8)  # the active set argument of layouts without one
NO_BASE = np.zeros((1, 3))  # the base positions argument of exact evaluations
# A False that numba types as a plain bool: a literal False argument compiles a specialisation
# of its own of every kernel it reaches (the cold start pays for each).
NO = np.bool_(False)
# return flags
FLAG_OK, FLAG_BAD_INPUT, FLAG_NON_FINITE = 0, 1, 2


def workspace_size(horizon_steps: int, stage_dim: int, kmax: int) -> int:
    """Length of the flat ``buf`` for :func:`carve_workspace`."""
    n = horizon_steps * stage_dim
    rows = horizon_steps + 1
    return (3 * rows * NX + rows * 5 + (kmax + 1) * n + (kmax + 1) * kmax + 3 * kmax + 1 + 7 * n
            + NX + rows * 3)


def memory_size(horizon_steps: int, stage_dim: int, kmax: int, n_obstacles: int = 0) -> int:
    """Length of one solver's packed float memory (see :func:`unpack`)."""
    n = horizon_steps * stage_dim
    return (2 * n + NU + 4 + 5 * NX + N_PRM + n_obstacles * OBS_COLS
            + workspace_size(horizon_steps, stage_dim, kmax))


@njit(cache=True, **INNER_KERNEL)
def u_out_at(n_stages, m):
    """Where :func:`unpack`'s ``u_out`` (NU) starts in the memory, ``stats`` (4) right after
    it: a caller reading the solver's answer alone reads it there, without :func:`unpack`'s
    eight views (their reference counts: ~0.2 µs a call)."""
    return 2 * n_stages * m


@njit(cache=True, **OUTER_KERNEL)
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


@njit(cache=True, error_model="numpy", fastmath=FAST_MATH, **INNER_KERNEL)
def carve_workspace(buf, n_stages, m, kmax):
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
