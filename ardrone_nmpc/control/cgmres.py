"""NMPC solvers over the kernels: C/GMRES (Ohtsuka) and the thesis' per-tick Newton/fdgmres.

Both share one contract — ``solve(t_s, x, ref) -> SolveResult`` — and one packing of the OCP
for the kernels; they differ in the unknowns per stage and in what a tick does:

* :class:`CGMRESController`: one continuation update per tick (GMRES(kmax)), bounds by
  dummy inputs (condensed by default, see :mod:`~ardrone_nmpc.control.kernels`);
* :class:`NewtonGMRESController` (in :mod:`~ardrone_nmpc.control.newton`): Newton iterations
  to a tolerance per tick with the thesis' eq. 3.25 active bounds.

A failed tick (non-finite values, ‖F‖ above ``divergence_residual``) re-initialises the
solver and solves afresh at once; the result still says what happened, and its ``u`` is
always finite and inside the bounds. The caller (supervisor) decides what to send.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ardrone_nmpc.control import kernels
from ardrone_nmpc.control.kernels import FLAG_BAD_INPUT, FLAG_NON_FINITE, FLAG_OK
from ardrone_nmpc.control.obstacles import OBS_X, OBS_Z
from ardrone_nmpc.control.ocp import OcpSpec, SolverStatus, SolveResult
from ardrone_nmpc.core.types import INPUT_DIM, STATE_DIM

INITIAL_KMAX = 40  # Krylov dimension of a (re-)initialising Newton solve: once, not per tick


class NmpcSolverBase:
    """What both NMPC solvers share: packing, input checks, timing, recovery."""

    method = "base"
    stage_dim = kernels.STAGE_CONDENSED
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
        newton_kmax = min(int(newton_kmax), spec.horizon_steps * self.stage_dim)
        n_obs = spec.obstacles.shape[0]
        self._mem = np.zeros(kernels.memory_size(spec.horizon_steps, self.stage_dim,
                                                 max(self.kmax, newton_kmax), n_obs))
        (self.U, self.dU, self._u, self._stats, self._W, self._prm, self.obstacles,
         self._buf) = kernels.unpack(self._mem, spec.horizon_steps, self.stage_dim, n_obs)
        self.obstacles[:] = spec.obstacles
        self._W[0], self._W[1] = spec.q, spec.q_terminal
        self._W[2, :INPUT_DIM] = spec.r
        self._W[3, :INPUT_DIM], self._W[4, :INPUT_DIM] = spec.u_min, spec.u_max
        self._prm[kernels.P_RHO] = dummy_weight
        self._prm[kernels.P_H] = fd_step
        self._prm[kernels.P_RTOL] = gmres_rtol
        self._prm[kernels.P_PERIOD] = period_s
        self._prm[kernels.P_TOL] = tolerance
        self._prm[kernels.P_DTAU] = self._prm[kernels.P_DTAU_NEXT] = spec.dtau_s
        self._iprm = np.array([self.stage_dim, self.kmax, max_newton_iterations, newton_kmax,
                               n_obs, spec.obstacle_gauss_newton], dtype=np.int64)
        self._ramped = spec.horizon_ramp_rate_per_s > 0
        self._ref_shape = (spec.horizon_steps + 1, STATE_DIM)
        self._t0_s: float | None = None

    @property
    def dummy_weight(self) -> float:
        return float(self._prm[kernels.P_RHO])

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

    def stage_dtau_s(self, t_s: float) -> float:
        """Δτ the solver uses at ``t_s`` (the horizon ramp starts at the first solve)."""
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
        if x.__class__ is not np.ndarray or x.dtype != np.float64:
            x = np.asarray(x, dtype=np.float64)
        if ref.__class__ is not np.ndarray or ref.dtype != np.float64:
            ref = np.asarray(ref, dtype=np.float64)
        if x.shape != (STATE_DIM,) or ref.shape != self._ref_shape:
            raise ValueError(f"solve: x must be (7,), ref ({self.spec.horizon_steps + 1}, 7); "
                             f"got {x.shape} and {ref.shape}")
        initialise = self._t0_s is None
        if initialise:
            self._t0_s = t_s
            self._initial_guess()
        if self._ramped:
            self._prm[kernels.P_DTAU] = self.stage_dtau_s(t_s)
            self._prm[kernels.P_DTAU_NEXT] = self.stage_dtau_s(t_s + self._prm[kernels.P_H])
        t0 = time.perf_counter_ns()
        flag = self._tick(x, ref, initialise)
        elapsed_us = (time.perf_counter_ns() - t0) * 1e-3
        newton_it, gmres_it, newton_norm, norm = self._stats.tolist()
        if flag == FLAG_BAD_INPUT:
            # Nothing to solve with: keep the solution, report, hand back the last input.
            return SolveResult(self._u.copy(), SolverStatus.NON_FINITE, math.inf, 0, elapsed_us)
        if flag == FLAG_NON_FINITE:
            return self._recover(t_s, x, ref, SolverStatus.NON_FINITE, elapsed_us)
        if norm > self.divergence_residual:
            return self._recover(t_s, x, ref, SolverStatus.DIVERGED, elapsed_us)
        status = SolverStatus.OK
        if newton_norm > self.tolerance and (initialise or self._newton_every_tick):
            status = SolverStatus.MAX_ITERATIONS
        return SolveResult(self._u.copy(), status, norm, int(gmres_it), elapsed_us,
                           int(newton_it))

    def _recover(self, t_s, x, ref, status, elapsed_us) -> SolveResult:
        """Re-initialise and solve afresh from the box centre; report ``status``."""
        self._t0_s = t_s
        self._initial_guess()
        t0 = time.perf_counter_ns()
        flag = self._tick(x, ref, True)
        elapsed_us += (time.perf_counter_ns() - t0) * 1e-3
        if flag != FLAG_OK or self._stats[3] > self.divergence_residual:
            self._initial_guess()  # even a fresh solve failed: centre of the box, flagged
            self._u[:] = 0.5 * (self.spec.u_min + self.spec.u_max)
            self._t0_s = None
        return SolveResult(self._u.copy(), status, float(self._stats[3]), int(self._stats[1]),
                           elapsed_us, int(self._stats[0]), True)

    # subclass hooks
    def _initial_guess(self) -> None:
        raise NotImplementedError

    def _tick(self, x, ref, initialise: bool) -> int:
        raise NotImplementedError


class CGMRESController(NmpcSolverBase):
    """C/GMRES NMPC: one GMRES(kmax) continuation update per tick.

    Parameters
    ----------
    spec : :class:`OcpSpec` — weights, horizon, bounds.
    period_s : control period Δt (s); the continuation integrates ``U`` over it.
    kmax : GMRES iterations per tick.
    zeta_per_s : ζ, the rate at which ``F`` is driven to zero; ``ζ Δt ≈ 1`` removes the
        whole residual in one tick.
    fd_step : h of the forward differences.
    gmres_rtol : η, relative GMRES tolerance.
    tolerance : ‖F‖ target of the initialising Newton solve.
    max_newton_iterations : Newton steps allowed in the initialising solve.
    dummy_weight : ρ_d, the linear dummy-input penalty; it keeps the optimum a little inside
        the bounds (smaller = closer to the exact box solution, stiffer near the bounds).
    divergence_residual : ‖F‖ above which the solver declares divergence and re-initialises
        from the box centre.
    newton_trigger_residual : ‖F‖ at a new measurement above which the tick first
        re-projects onto ``F = 0`` by Newton/GMRES warm-started from the current solution
        (reference jumps); the continuation update follows.
    condensed : eliminate dummy inputs and multipliers per stage in closed form (4 unknowns
        per stage instead of 12). Same equations; restarted GMRES(5) stagnates on the
        indefinite uncondensed system, so ``False`` is for comparison.

    Obstacles come with the spec (``spec.obstacles``); :meth:`move_obstacles` changes their
    centres between ticks.

    ``residual_norm`` in the result is ‖F(U, x, t)‖ at the new measurement, of the solution
    entering the tick (after the Newton re-projection when one ran): how far the
    continuation lagged the optimum.
    """

    method = "cgmres"

    def __init__(self, spec: OcpSpec, *, period_s: float = 0.065, kmax: int = 5,
                 zeta_per_s: float = 15.0, fd_step: float = 1e-6, gmres_rtol: float = 1e-3,
                 tolerance: float = 1e-4, max_newton_iterations: int = 20,
                 dummy_weight: float = 0.01, divergence_residual: float = 1e3,
                 newton_trigger_residual: float = 100.0, condensed: bool = True):
        self.stage_dim = kernels.STAGE_CONDENSED if condensed else kernels.STAGE_DUMMY
        super().__init__(spec, period_s=period_s, kmax=kmax, fd_step=fd_step,
                         gmres_rtol=gmres_rtol, tolerance=tolerance,
                         max_newton_iterations=max_newton_iterations,
                         dummy_weight=dummy_weight, divergence_residual=divergence_residual,
                         newton_kmax=INITIAL_KMAX)
        if not zeta_per_s > 0:
            raise ValueError(f"zeta_per_s: must be positive, got {zeta_per_s}")
        if not newton_trigger_residual > 0:
            raise ValueError("newton_trigger_residual: must be positive, "
                             f"got {newton_trigger_residual}")
        self._prm[kernels.P_ZETA] = zeta_per_s
        self._prm[kernels.P_TRIGGER] = newton_trigger_residual

    @classmethod
    def from_config(cls, controller, *, period_s: float) -> "CGMRESController":
        s = controller.solver
        return cls(OcpSpec.from_config(controller), period_s=period_s, kmax=s.kmax,
                   zeta_per_s=s.zeta_per_s, fd_step=s.fd_step, gmres_rtol=s.gmres_rtol,
                   tolerance=s.tolerance, max_newton_iterations=s.max_newton_iterations,
                   dummy_weight=s.dummy_weight, divergence_residual=s.divergence_residual,
                   newton_trigger_residual=s.newton_trigger_residual, condensed=s.condensed)

    def _initial_guess(self) -> None:
        spec = self.spec
        centre = 0.5 * (spec.u_max + spec.u_min)
        stage = centre
        if self.stage_dim == kernels.STAGE_DUMMY:  # v = w, μ from H_v = 0
            half = 0.5 * (spec.u_max - spec.u_min)
            stage = np.concatenate([centre, half, self.dummy_weight / (2.0 * half)])
        self.U[:] = np.tile(stage, spec.horizon_steps)
        self.dU[:] = 0.0

    def _tick(self, x, ref, initialise: bool) -> int:
        return kernels.cgmres_step(self._mem, x, ref, self._iprm, initialise)
