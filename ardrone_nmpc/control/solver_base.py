"""What both NMPC solvers share: the one contract ``solve(t_s, x, ref) -> SolveResult``,
input checks, timing and recovery, around the kernels' memory.

The schemes differ in the unknowns per stage and in what a tick does (subclass hooks):
:class:`~ardrone_nmpc.control.cgmres.CGMRESController` (one continuation update per tick) and
:class:`~ardrone_nmpc.control.newton.NewtonGMRESController` (Newton to a tolerance per tick);
:func:`~ardrone_nmpc.control.solver.make_nmpc` builds the one a config names.

A failed tick (non-finite values, ‖F‖ above ``divergence_residual``) re-initialises the
solver and solves afresh at once; the result still says what happened, and its ``u`` is
always finite and inside the bounds. The caller (supervisor) decides what to send.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ardrone_nmpc.control.kernels import (FLAG_BAD_INPUT, FLAG_NON_FINITE, FLAG_OK,
                                          STAGE_CONDENSED, SolverMemory)
from ardrone_nmpc.control.obstacles import OBS_X, OBS_Z
from ardrone_nmpc.control.ocp import OcpSpec, SolverStatus, SolveResult
from ardrone_nmpc.core.types import INPUT_DIM, STATE_DIM

_F64 = np.dtype(np.float64)
_OK = SolverStatus.OK  # bound once: an enum member's lookup costs ~0.1 µs
_perf_counter_ns = time.perf_counter_ns  # the tick times every solve
# a SolveResult from its seven fields without the NamedTuple's Python ``__new__`` (a frame
# and a default-argument fill a tick): the same tuple
_new_tuple = tuple.__new__
_X_SHAPE = (STATE_DIM,)
assert FLAG_OK == 0  # solve_prepared tests a tick's flag for truth


class NmpcSolverBase:
    """What both NMPC solvers share: packing, input checks, timing, recovery."""

    method = "base"
    stage_dim = STAGE_CONDENSED
    _newton_every_tick = False  # True: every tick is a Newton solve held to ``tolerance``

    def __init__(self, spec: OcpSpec, *, period_s: float, kmax: int, fd_step: float,
                 gmres_rtol: float, tolerance: float, max_newton_iterations: int,
                 dummy_weight: float, divergence_residual: float, newton_kmax: int):
        if kmax < 1:
            raise ValueError(f"kmax: must be ≥ 1, got {kmax}")
        if not (period_s > 0 and math.isfinite(period_s)):
            raise ValueError(f"period_s: must be positive, got {period_s}")
        if not fd_step > 0:
            raise ValueError(f"fd_step: must be positive, got {fd_step}")
        self.spec = spec
        self.period_s = float(period_s)
        self.kmax = int(kmax)
        self.tolerance = float(tolerance)
        self.divergence_residual = float(divergence_residual)
        mem = self.memory = SolverMemory(
            horizon_steps=spec.horizon_steps, stage_dim=self.stage_dim, kmax=self.kmax,
            newton_kmax=min(int(newton_kmax), spec.horizon_steps * self.stage_dim),
            max_newton_iterations=max_newton_iterations, obstacles=spec.obstacles,
            gauss_newton=spec.obstacle_gauss_newton)
        self.U, self.dU, self._u, self.obstacles = mem.U, mem.dU, mem.u, mem.obstacles
        mem.set_weights(q=spec.q, q_terminal=spec.q_terminal, r=spec.r, u_min=spec.u_min,
                        u_max=spec.u_max)
        mem.dummy_weight = dummy_weight
        mem.fd_step = fd_step
        mem.gmres_rtol = gmres_rtol
        mem.period_s = period_s
        mem.tolerance = tolerance
        mem.dtau_s = mem.dtau_next_s = spec.dtau_s
        self._ramped = spec.horizon_ramp_rate_per_s > 0
        # Δτ when the spec keeps it fixed (its stage_dtau_s' own test), asked every tick
        self._fixed_dtau_s = spec.dtau_s if spec.horizon_ramp_rate_per_s <= 0.0 else None
        self._ref_shape = (spec.horizon_steps + 1, STATE_DIM)
        self._t0_s: float | None = None
        # the kernels' stats as a list: the array's own tolist bound once (read every tick;
        # SolverMemory.stats_values without its frame)
        self._stats_values = mem.stats_array.tolist
        # ``(kernel, memory, settings)`` of a subclass whose tick is
        # ``kernel(memory, x, ref, settings, initialise)`` (C/GMRES); None: :meth:`_tick`
        self._kernel: tuple | None = None

    @property
    def dummy_weight(self) -> float:
        return self.memory.dummy_weight

    def move_obstacles(self, centres_m: np.ndarray) -> None:
        """Set the obstacles' centres (n, 3) m for the next ticks (a moving obstacle)."""
        centres = np.asarray(centres_m, dtype=float)
        if centres.shape != (self.obstacles.shape[0], 3) or not np.all(np.isfinite(centres)):
            raise ValueError(f"move_obstacles: expected {self.obstacles.shape[0]}×3 finite "
                             f"centres, got shape {centres.shape}")
        self.obstacles[:, OBS_X:OBS_Z + 1] = centres

    @property
    def inputs_horizon(self) -> np.ndarray:
        """(N, 4) predicted inputs of the current solution."""
        return self.U.reshape(self.spec.horizon_steps, self.stage_dim)[:, :INPUT_DIM]

    @property
    def fixed_dtau_s(self) -> float | None:
        """Δτ (s) when it never changes (no horizon ramp), else None."""
        return self._fixed_dtau_s

    def stage_dtau_s(self, t_s: float) -> float:
        """Δτ the solver uses at ``t_s`` (the horizon ramp starts at the first solve)."""
        if self._fixed_dtau_s is not None:
            return self._fixed_dtau_s
        elapsed = 0.0 if self._t0_s is None else t_s - self._t0_s
        return self.spec.stage_dtau_s(elapsed)

    def reset(self) -> None:
        """Forget the solution; the next :meth:`solve` starts from the box centre."""
        self._t0_s = None

    def solve(self, t_s: float, x: np.ndarray, ref: np.ndarray) -> SolveResult:
        """One control tick.

        Parameters
        ----------
        t_s : time (s) of the measurement ``x``.
        x : (7,) state estimate ``[x, ẋ, y, ẏ, z, ż, ψ]``.
        ref : (N+1, 7) reference at the stage times ``t_s + i·Δτ`` (``stage_dtau_s(t_s)``);
            ψ is unwrapped inside, any 2π branch will do.
        """
        # the identity test first: comparing a dtype with np.float64 costs ~0.3 µs
        if x.__class__ is not np.ndarray or (x.dtype is not _F64 and x.dtype != _F64):
            x = np.asarray(x, dtype=np.float64)
        if ref.__class__ is not np.ndarray or (ref.dtype is not _F64 and ref.dtype != _F64):
            ref = np.asarray(ref, dtype=np.float64)
        if x.shape != _X_SHAPE or ref.shape != self._ref_shape:
            raise ValueError(f"solve: x must be (7,), ref ({self.spec.horizon_steps + 1}, 7); "
                             f"got {x.shape} and {ref.shape}")
        return self.solve_prepared(t_s, x, ref)

    def solve_prepared(self, t_s: float, x: np.ndarray, ref: np.ndarray) -> SolveResult:
        """:meth:`solve` for a caller that vouches for its arrays — ``x`` a (7,) and ``ref`` a
        (N+1, 7) float64 ndarray (the control stage's fast path builds them) —: the same
        solve without the checks and conversions (µs a tick)."""
        initialise = self._t0_s is None
        if initialise:
            self._t0_s = t_s
            self._initial_guess()
        if self._ramped:
            self.memory.dtau_s = self.stage_dtau_s(t_s)
            self.memory.dtau_next_s = self.stage_dtau_s(t_s + self.memory.fd_step)
        kernel = self._kernel
        t0 = _perf_counter_ns()
        if kernel is not None:  # the subclass' bound kernel call, without its _tick frame
            flag = kernel[0](kernel[1], x, ref, kernel[2], initialise)
        else:
            flag = self._tick(x, ref, initialise)
        elapsed_us = (_perf_counter_ns() - t0) * 1e-3
        newton_it, gmres_it, newton_norm, norm = self._stats_values()
        if flag:  # not FLAG_OK (one test a tick, not two)
            if flag == FLAG_BAD_INPUT:
                # Nothing to solve with: keep the solution, report, hand back the last input.
                return SolveResult(self._u.copy(), SolverStatus.NON_FINITE, math.inf, 0,
                                   elapsed_us)
            if flag == FLAG_NON_FINITE:
                return self._recover(t_s, x, ref, SolverStatus.NON_FINITE, elapsed_us)
        if norm > self.divergence_residual:
            return self._recover(t_s, x, ref, SolverStatus.DIVERGED, elapsed_us)
        status = _OK
        if newton_norm > self.tolerance and (initialise or self._newton_every_tick):
            status = SolverStatus.MAX_ITERATIONS
        return _new_tuple(SolveResult, (self._u.copy(), status, norm, int(gmres_it), elapsed_us,
                                        int(newton_it), False))

    def _recover(self, t_s, x, ref, status, elapsed_us) -> SolveResult:
        """Re-initialise and solve afresh from the box centre; report ``status``."""
        self._t0_s = t_s
        self._initial_guess()
        t0 = time.perf_counter_ns()
        flag = self._tick(x, ref, True)
        elapsed_us += (time.perf_counter_ns() - t0) * 1e-3
        stats = self.memory.stats()
        if flag != FLAG_OK or stats.residual > self.divergence_residual:
            self._initial_guess()  # even a fresh solve failed: centre of the box, flagged
            self._u[:] = 0.5 * (self.spec.u_min + self.spec.u_max)
            self._t0_s = None
        return SolveResult(self._u.copy(), status, stats.residual, int(stats.gmres_iterations),
                           elapsed_us, int(stats.newton_iterations), True)

    # subclass hooks
    def _initial_guess(self) -> None:
        raise NotImplementedError

    def _tick(self, x, ref, initialise: bool) -> int:
        raise NotImplementedError


