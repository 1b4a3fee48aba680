"""The thesis' own NMPC scheme: per tick, Newton/fdgmres to a tolerance (Algorithm 1).

Unknowns per stage are ``[u(4), ν(4)]``; bounds are handled as in thesis eq. 3.25 — after a
solve, each violated bound ``C ≥ 0`` is imposed as ``C − ε = 0`` and the solve repeated (an
active bound whose multiplier turns negative is released). Warm start: the previous tick's
solution and active set.
"""

from __future__ import annotations

import numpy as np

from ardrone_nmpc.control.kernels import STAGE_ACTIVE
from ardrone_nmpc.control.ocp import OcpSpec
from ardrone_nmpc.control.solver_base import NmpcSolverBase
from ardrone_nmpc.core import defaults


class NewtonGMRESController(NmpcSolverBase):
    """Newton/GMRES NMPC (thesis §3.4).

    Parameters
    ----------
    spec : :class:`OcpSpec`.
    period_s : control period (s); only recorded (no continuation here).
    kmax : k_max of Algorithm 1, per Newton step (``controller.solver.newton_kmax``).
    fd_step : h of eq. 3.24. gmres_rtol : η of Algorithm 1.
    tolerance : ‖F‖ at which a tick's Newton iterations stop.
    max_newton_iterations : Newton steps per solve (per active-set round).
    bound_epsilon : ε of eq. 3.25 — active bounds are imposed ε inside the box.
    divergence_residual : ‖F‖ above which the solver re-initialises.

    ``residual_norm`` is ‖F‖ at the end of the tick's iterations; ``max-iterations`` when it
    is still above ``tolerance``.
    """

    method = "newton"
    stage_dim = STAGE_ACTIVE
    _newton_every_tick = True

    def __init__(self, spec: OcpSpec, *, period_s: float = defaults.LOOP_PERIOD_S,
                 kmax: int = defaults.NEWTON_KMAX, fd_step: float = defaults.FD_STEP,
                 gmres_rtol: float = defaults.GMRES_RTOL, tolerance: float = defaults.TOLERANCE,
                 max_newton_iterations: int = defaults.MAX_NEWTON_ITERATIONS,
                 bound_epsilon: float = defaults.BOUND_EPSILON,
                 divergence_residual: float = defaults.DIVERGENCE_RESIDUAL):
        super().__init__(spec, period_s=period_s, kmax=kmax, fd_step=fd_step,
                         gmres_rtol=gmres_rtol, tolerance=tolerance,
                         max_newton_iterations=max_newton_iterations, dummy_weight=0.0,
                         divergence_residual=divergence_residual, newton_kmax=kmax)
        self.memory.bound_epsilon = bound_epsilon
        self.active = np.zeros((spec.horizon_steps, 4), dtype=np.int8)
        self._bind_newton()

    #: what :meth:`_bind_newton` makes (not copied, not pickled)
    _BOUND = (*NmpcSolverBase._BOUND, "newton_call")

    def _bind_newton(self) -> None:
        """:attr:`newton_call` made of the memory and the active set (again for a copy)."""
        #: ``(kernel, memory, settings, active set)``: a tick is
        #: ``kernel(memory, x, ref, settings, active)`` — :meth:`_tick`'s call, bound for the
        #: controller's one compiled call (``runtime/control_tick``), which calls the kernel
        self.newton_call = (*self.memory.newton_call(), self.active)

    def __setstate__(self, state: dict) -> None:
        super().__setstate__(state)
        self._bind_newton()

    @classmethod
    def from_config(cls, controller, *, period_s: float) -> "NewtonGMRESController":
        s = controller.solver
        return cls(OcpSpec.from_config(controller), period_s=period_s, kmax=s.newton_kmax,
                   fd_step=s.fd_step, gmres_rtol=s.gmres_rtol, tolerance=s.tolerance,
                   max_newton_iterations=s.max_newton_iterations,
                   bound_epsilon=s.bound_epsilon, divergence_residual=s.divergence_residual)

    def _initial_guess(self) -> None:
        self.U[:] = 0.0
        self.U.reshape(self.spec.horizon_steps, self.stage_dim)[:, :4] = (
            0.5 * (self.spec.u_min + self.spec.u_max))
        self.active[:] = 0

    def _tick(self, x, ref, initialise: bool) -> int:
        return self.memory.newton_step(x, ref, self.active)

