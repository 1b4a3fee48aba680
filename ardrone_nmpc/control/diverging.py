"""A solver made to diverge: the simulated ``faults.solver_diverge`` (docs/fault-matrix.md).

Only simulating runners build it, around the solver the tick would use, from the simulated
drone's schedule: the control stage itself knows no fault. The inner solver still solves —
its warm start carries on as it would — and only the status the supervisor judges says the
solve diverged, so the supervisor's solver-failure chain (hold, P fallback, recovery) runs as
after a real divergence, while the log keeps what was solved.
"""

from __future__ import annotations

from functools import partial
from typing import Callable

from ardrone_nmpc.control.ocp import SolveResult, SolverStatus

__all__ = ["DivergingSolver", "diverging_wrapper"]


class DivergingSolver:
    """``inner`` whose answers are marked :attr:`SolverStatus.DIVERGED` while ``diverges(t)``
    (``t`` the time the solve is for: experiment time); every other attribute is the inner
    solver's."""

    def __init__(self, inner, diverges: Callable[[float], bool]) -> None:
        self._inner = inner
        self._diverges = diverges

    def solve(self, t_s: float, *args, **kwargs) -> SolveResult:
        result = self._inner.solve(t_s, *args, **kwargs)
        if self._diverges(t_s):
            return result._replace(status=SolverStatus.DIVERGED)
        return result

    def solve_prepared(self, t_s: float, x, ref) -> SolveResult:
        """The inner solver's ``solve_prepared`` (the control stage's fast path), marked as
        :meth:`solve` marks it: defined here, not forwarded, which would skip the mark."""
        result = self._inner.solve_prepared(t_s, x, ref)
        if self._diverges(t_s):
            return result._replace(status=SolverStatus.DIVERGED)
        return result

    @property
    def inner(self):
        """The solver that solves (its answers are this one's when :meth:`marks` is False)."""
        return self._inner

    def marks(self, t_s: float) -> bool:
        """Whether the answer of a solve for ``t_s`` is marked; else it is the inner solver's
        as it is — a compiled tick of the inner solver may take that tick
        (``runtime/control_tick.py``)."""
        return self._diverges(t_s)

    def __getattr__(self, name: str):
        return getattr(self._inner, name)


def diverging_wrapper(diverges: Callable[[float], bool] | None) -> Callable | None:
    """The tick's ``wrap_solver`` for a simulation whose solver diverges when ``diverges(t)``
    (None: nothing to wrap)."""
    return None if diverges is None else partial(DivergingSolver, diverges=diverges)
