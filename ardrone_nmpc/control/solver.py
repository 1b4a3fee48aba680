"""The NMPC solver a configuration names: :func:`make_nmpc`.

Both schemes share :class:`~ardrone_nmpc.control.solver_base.NmpcSolverBase` (the contract
``solve(t_s, x, ref) -> SolveResult``); callers build them here and need not know which.
"""

from __future__ import annotations

from ardrone_nmpc.control.cgmres import CGMRESController
from ardrone_nmpc.control.newton import NewtonGMRESController
from ardrone_nmpc.control.solver_base import NmpcSolverBase

__all__ = ["make_nmpc"]

_SOLVERS = {cls.method: cls for cls in (CGMRESController, NewtonGMRESController)}


def make_nmpc(controller, *, period_s: float) -> NmpcSolverBase:
    """The solver named by ``controller.solver.method`` (``cgmres`` | ``newton``), built from
    a ``config.ControllerConfig`` section for the control period ``period_s`` (s)."""
    method = controller.solver.method
    if method not in _SOLVERS:
        raise ValueError(f"controller.solver.method: unknown solver {method!r}")
    return _SOLVERS[method].from_config(controller, period_s=period_s)
