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
from ardrone_nmpc.core.entry_points import ArrayKind, VettedCall
from ardrone_nmpc.core.types import INPUT_DIM, STATE_DIM

_F64 = np.dtype(np.float64)
_OK = SolverStatus.OK  # bound once: an enum member's lookup costs ~0.1 µs
_perf_counter_ns = time.perf_counter_ns  # the tick times every solve
# a SolveResult from its seven fields without the NamedTuple's Python ``__new__`` (a frame
# and a default-argument fill a tick): the same tuple
_new_tuple = tuple.__new__
_X_SHAPE = (STATE_DIM,)
assert FLAG_OK == 0  # solve_prepared tests a tick's flag for truth


def _vetted_call(kernel, mem: np.ndarray, iprm: np.ndarray) -> VettedCall:
    """The calls of ``kernel(mem, x, ref, iprm, initialise)`` (a C/GMRES tick) by its entry
    point once the arrays are vetted (``core/entry_points``): ``x`` a plain 1-D and ``ref`` a
    plain 2-D float64 array, ``mem`` and ``iprm`` of their own kinds."""
    return VettedCall(kernel, ArrayKind(mem.ndim, mem.dtype), ArrayKind(1), ArrayKind(2),
                      ArrayKind(iprm.ndim, iprm.dtype), False)


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
        self._bind_memory()

    #: what :meth:`_bind_memory` makes of the memory (not copied, not pickled)
    _BOUND = ("U", "dU", "_u", "obstacles", "_stats_values", "_u_copy", "_step", "_kernel",
              "_vetted_call")

    def _bind_memory(self) -> None:
        """The memory's views under the solver's names and its tick's calls bound once (made
        again for a copy: :meth:`__setstate__`)."""
        mem = self.memory
        self.U, self.dU, self._u, self.obstacles = mem.U, mem.dU, mem.u, mem.obstacles
        # the kernels' stats as a list: the array's own tolist bound once (read every tick;
        # SolverMemory.stats_values without its frame)
        self._stats_values = mem.stats_array.tolist
        self._u_copy = mem.u.copy  # the result's own input, a tick (the method bound once)
        # ``(kernel, memory, settings)`` of a subclass whose tick is
        # ``kernel(memory, x, ref, settings, initialise)`` (C/GMRES); None: :meth:`_tick`
        self._step: tuple | None = self._kernel_call()
        # what solve_prepared calls that kernel by: ``(call, memory, settings, x, ref)`` —
        # its compiled entry point while ``x`` and ``ref`` are the arrays it vetted
        # (:meth:`_call_unvetted`), never None's (no array is None)
        self._kernel: tuple | None = None if self._step is None else (*self._step, None, None)
        # that kernel's calls with arrays not vetted (:meth:`_call_unvetted`)
        self._vetted_call = None if self._step is None else _vetted_call(*self._step)

    def __getstate__(self) -> dict:
        """Without the views and calls :meth:`_bind_memory` makes (an entry point does not
        pickle; the vetted arrays are the caller's)."""
        state = self.__dict__.copy()
        for name in self._BOUND:
            del state[name]
        return state

    def __setstate__(self, state: dict) -> None:
        """A deep copy or unpickling: numpy copies each view apart from its array, so the
        views and calls are made of the copied memory again — the copy solves on its own
        memory as the original does on its, and writes nothing of the original's."""
        self.__dict__.update(state)
        self._bind_memory()

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
        solve without the checks and conversions (µs a tick). C/GMRES' kernel is called by
        its compiled entry point with the arrays it vetted (:meth:`_call_unvetted`): their
        kinds are checked once per array object, which must not be reshaped or retyped in
        place (``a.shape = …``, ``a.dtype = …``) while the solver is fed it."""
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
            call, mem, iprm, vetted_x, vetted_ref = kernel
            if x is vetted_x and ref is vetted_ref:  # its entry point (_call_unvetted)
                flag = call(mem, x, ref, iprm, initialise)
            else:
                flag = self._call_unvetted(x, ref, initialise)
        else:
            flag = self._tick(x, ref, initialise)
        return self.judged(t_s, x, ref, flag, (_perf_counter_ns() - t0) * 1e-3, initialise)

    def judged(self, t_s: float, x: np.ndarray, ref: np.ndarray, flag: int, elapsed_us: float,
               initialise: bool) -> SolveResult:
        """The :class:`SolveResult` of a tick whose kernel answered ``flag`` after
        ``elapsed_us`` (:meth:`solve_prepared`'s, or the controller's one compiled call's,
        ``runtime/control_tick.py``, which decides its usual tick itself): the status from
        the flag, the residual and the tolerance; a failed tick recovered (:meth:`_recover`)."""
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
        return _new_tuple(SolveResult, (self._u_copy(), status, norm, int(gmres_it), elapsed_us,
                                        int(newton_it), False))

    def _call_unvetted(self, x: np.ndarray, ref: np.ndarray, initialise: bool) -> int:
        """The bound kernel's call with arrays other than the ones vetted: the dispatcher,
        which looks at their types. The same two arrays a second time in a row are vetted —
        plain (core/entry_points.VettedCall), the kinds the memory's call is compiled for —
        and kept with its entry point, so that the next calls with them take it at once: the control
        stage's fast path passes its own arrays every tick, and a caller with new arrays
        every call pays no check."""
        _, mem, iprm = self._step
        call = self._vetted_call
        flag = call(mem, x, ref, iprm, initialise)
        vetted = call.vetted  # (mem, x, ref, iprm) once an entry point was taken for them
        if vetted and vetted[1] is x and vetted[2] is ref:
            self._kernel = (call.entry, mem, iprm, x, ref)
        return flag

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
    def _kernel_call(self) -> tuple | None:
        """``(kernel, memory, settings)`` when a tick is ``kernel(memory, x, ref, settings,
        initialise)`` (bound once: :meth:`solve_prepared` calls it without :meth:`_tick`)."""
        return None

    def _initial_guess(self) -> None:
        raise NotImplementedError

    def _tick(self, x, ref, initialise: bool) -> int:
        raise NotImplementedError


