"""C/GMRES (Ohtsuka): one continuation update per tick, bounds by dummy inputs (condensed by
default, see :mod:`~ardrone_nmpc.control.kernels`).
"""

from __future__ import annotations

import numpy as np

from ardrone_nmpc.control.kernels import STAGE_CONDENSED, STAGE_DUMMY
from ardrone_nmpc.control.ocp import OcpSpec
from ardrone_nmpc.control.solver_base import NmpcSolverBase
from ardrone_nmpc.core import defaults

INITIAL_KMAX = 40  # Krylov dimension of a (re-)initialising Newton solve: once, not per tick


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

    def __init__(self, spec: OcpSpec, *, period_s: float = defaults.LOOP_PERIOD_S,
                 kmax: int = defaults.KMAX, zeta_per_s: float = defaults.ZETA_PER_S,
                 fd_step: float = defaults.FD_STEP, gmres_rtol: float = defaults.GMRES_RTOL,
                 tolerance: float = defaults.TOLERANCE,
                 max_newton_iterations: int = defaults.MAX_NEWTON_ITERATIONS,
                 dummy_weight: float = defaults.DUMMY_WEIGHT,
                 divergence_residual: float = defaults.DIVERGENCE_RESIDUAL,
                 newton_trigger_residual: float = defaults.NEWTON_TRIGGER_RESIDUAL,
                 condensed: bool = defaults.CONDENSED):
        self.stage_dim = STAGE_CONDENSED if condensed else STAGE_DUMMY
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
        self.memory.zeta_per_s = zeta_per_s
        self.memory.newton_trigger_residual = newton_trigger_residual

    @classmethod
    def from_config(cls, controller, *, period_s: float) -> "CGMRESController":
        s = controller.solver
        return cls(OcpSpec.from_config(controller), period_s=period_s, kmax=s.kmax,
                   zeta_per_s=s.zeta_per_s, fd_step=s.fd_step, gmres_rtol=s.gmres_rtol,
                   tolerance=s.tolerance, max_newton_iterations=s.max_newton_iterations,
                   dummy_weight=s.dummy_weight, divergence_residual=s.divergence_residual,
                   newton_trigger_residual=s.newton_trigger_residual, condensed=s.condensed)

    def _kernel_call(self) -> tuple:
        """The tick's kernel and its fixed arguments bound once (SolverMemory.cgmres_step's
        call without its frame and three attribute reads, every tick); the base's solve
        calls it without :meth:`_tick`'s frame."""
        return self.memory.cgmres_call()

    def _initial_guess(self) -> None:
        spec = self.spec
        centre = 0.5 * (spec.u_max + spec.u_min)
        stage = centre
        if self.stage_dim == STAGE_DUMMY:  # v = w, μ from H_v = 0
            half = 0.5 * (spec.u_max - spec.u_min)
            stage = np.concatenate([centre, half, self.dummy_weight / (2.0 * half)])
        self.U[:] = np.tile(stage, spec.horizon_steps)
        self.dU[:] = 0.0

    def _tick(self, x, ref, initialise: bool) -> int:
        step, mem, iprm = self._step
        return step(mem, x, ref, iprm, initialise)
