"""One NMPC solver's kernel memory behind names: the Python side never indexes a slot.

Like an acados solver object, :class:`SolverMemory` owns the packed arrays the kernels work
on (:mod:`~ardrone_nmpc.control.kernels.layout`) and offers settings by name, the shared
views (the horizon ``U``, its rate ``dU``, the input ``u`` to apply, the ``obstacles`` table)
and one call per tick. The layout can change without touching the solvers.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ardrone_nmpc.control.kernels.layout import (
    P_DTAU, P_DTAU_NEXT, P_H, P_PERIOD, P_RHO, P_RTOL, P_TOL, P_TRIGGER, P_ZETA,
    memory_size, unpack)
from ardrone_nmpc.control.kernels.steps import (cgmres_step, cgmres_step_obstacles, newton_step,
                                                newton_step_obstacles)
from ardrone_nmpc.core.kernel_cache import load_cached_callees

__all__ = ["SolverMemory", "SolverStats"]


class _Slot:
    """A float setting stored in one slot of the kernels' ``prm`` array."""

    def __init__(self, index: int, doc: str):
        self.index = index
        self.__doc__ = doc

    def __get__(self, memory, owner=None):
        if memory is None:
            return self
        return float(memory._prm[self.index])

    def __set__(self, memory, value: float) -> None:
        memory._prm[self.index] = value


class SolverStats(NamedTuple):
    """What the last tick's kernels report."""

    newton_iterations: float  # Newton steps spent
    gmres_iterations: float  # Krylov iterations spent, all solves together
    newton_residual: float  # ‖F‖ after the Newton iterations
    residual: float  # ‖F‖ at the continuation point: the tick's residual


class SolverMemory:
    """The packed memory of one solver, its integer settings and its tick entry points.

    Parameters
    ----------
    horizon_steps : N. stage_dim : unknowns per stage (``layout.STAGE_*``).
    kmax : Krylov dimension of a continuation update (and of a ``newton`` Newton step).
    newton_kmax : Krylov dimension of a Newton solve (``cgmres``: the initialising one).
    max_newton_iterations : Newton steps per solve.
    obstacles : (n, ``OBS_COLS``) obstacle table (copied in; :attr:`obstacles` is the view).
    gauss_newton : Jacobian products see the obstacle penalty's Gauss–Newton curvature.
    """

    dtau_s = _Slot(P_DTAU, "Δτ (s) of the prediction at the measurement.")
    dtau_next_s = _Slot(P_DTAU_NEXT, "Δτ (s) at the measurement time + h (horizon ramp).")
    dummy_weight = _Slot(P_RHO, "ρ_d, the dummy inputs' linear weight (layouts 4 and 12).")
    bound_epsilon = _Slot(P_RHO, "ε of eq. 3.25 (layout 8 reads it where the others read ρ_d).")
    zeta_per_s = _Slot(P_ZETA, "ζ (1/s), the continuation's stabilisation gain.")
    fd_step = _Slot(P_H, "h, the forward-difference step.")
    gmres_rtol = _Slot(P_RTOL, "η, the relative GMRES tolerance.")
    period_s = _Slot(P_PERIOD, "Δt (s), the control period the continuation integrates over.")
    tolerance = _Slot(P_TOL, "‖F‖ at which Newton solves stop.")
    newton_trigger_residual = _Slot(P_TRIGGER, "C/GMRES: ‖F‖ above which a tick re-projects.")

    def __init__(self, *, horizon_steps: int, stage_dim: int, kmax: int, newton_kmax: int,
                 max_newton_iterations: int, obstacles: np.ndarray, gauss_newton: bool):
        n_obs = obstacles.shape[0]
        self.horizon_steps = horizon_steps
        self.stage_dim = stage_dim
        self._kmax = max(kmax, newton_kmax)
        self._mem = np.zeros(memory_size(horizon_steps, stage_dim, self._kmax, n_obs))
        self._iprm = np.array([stage_dim, kmax, max_newton_iterations, newton_kmax, n_obs,
                               gauss_newton], dtype=np.int64)
        self._bind()
        self.obstacles[:] = obstacles
        for entry in (self._cgmres, self._newton):  # same bits whether compiled or cached
            load_cached_callees(entry)

    #: what :meth:`_bind` makes of the memory and settings (not copied, not pickled)
    _BOUND = ("U", "dU", "u", "_stats", "_W", "_prm", "obstacles", "_buf", "_cgmres",
              "_newton")

    def _bind(self) -> None:
        """The views of the packed memory under their names, and the entry points of its
        obstacle table (only the one called is ever compiled)."""
        n_obs = int(self._iprm[4])
        (self.U, self.dU, self.u, self._stats, self._W, self._prm, self.obstacles,
         self._buf) = unpack(self._mem, self.horizon_steps, self.stage_dim, n_obs)
        self._cgmres = cgmres_step_obstacles if n_obs else cgmres_step
        self._newton = newton_step_obstacles if n_obs else newton_step

    def __getstate__(self) -> dict:
        """The memory and settings only: what :meth:`_bind` makes of them is made again."""
        state = self.__dict__.copy()
        for name in self._BOUND:
            del state[name]
        return state

    def __setstate__(self, state: dict) -> None:
        """A deep copy or unpickling: numpy copies a view apart from its array, so the views
        are made of the copied memory again — what the kernels write is what they show."""
        self.__dict__.update(state)
        self._bind()

    @property
    def kmax(self) -> int:
        """Krylov dimension of a continuation update (``newton``: of each Newton step)."""
        return int(self._iprm[1])

    @kmax.setter
    def kmax(self, value: int) -> None:
        if not 1 <= value <= self._kmax:  # the workspace holds at most this many vectors
            raise ValueError(f"kmax: must be in 1 … {self._kmax}, got {value}")
        self._iprm[1] = value

    @property
    def max_newton_iterations(self) -> int:
        """Newton steps per solve."""
        return int(self._iprm[2])

    @max_newton_iterations.setter
    def max_newton_iterations(self, value: int) -> None:
        if value < 1:
            raise ValueError(f"max_newton_iterations: must be ≥ 1, got {value}")
        self._iprm[2] = value

    def snapshot(self) -> np.ndarray:
        """A copy of the whole float memory (solution, warm start, settings, workspace)."""
        return self._mem.copy()

    def restore(self, snapshot: np.ndarray) -> None:
        """Put back what :meth:`snapshot` took (to repeat a tick from the same warm start)."""
        self._mem[:] = snapshot

    @property
    def n_obstacles(self) -> int:
        """Obstacles in the table; 0 runs the kernels' obstacle-free specialisation."""
        return int(self._iprm[4])

    def set_weights(self, *, q, q_terminal, r, u_min, u_max) -> None:
        """The OCP's diagonal weights (7, 7, 4) and input box (4, 4)."""
        self._W[0], self._W[1] = q, q_terminal
        n_u = len(r)
        self._W[2, :n_u] = r
        self._W[3, :n_u], self._W[4, :n_u] = u_min, u_max

    def stats(self) -> SolverStats:
        """The last tick's :class:`SolverStats`."""
        return SolverStats(*self._stats.tolist())

    @property
    def stats_array(self) -> np.ndarray:
        """The kernels' stats slots (a view, :class:`SolverStats`' field order)."""
        return self._stats

    def stats_values(self) -> list[float]:
        """:meth:`stats` as a plain list in its field order (the tick's: no record built)."""
        return self._stats.tolist()

    def cgmres_step(self, x: np.ndarray, ref: np.ndarray, initialise: bool) -> int:
        """One C/GMRES tick (:func:`~ardrone_nmpc.control.kernels.steps.cgmres_step`, or
        ``cgmres_step_obstacles`` with obstacles)."""
        return self._cgmres(self._mem, x, ref, self._iprm, initialise)

    def cgmres_call(self) -> tuple:
        """``(kernel, memory, settings)``: :meth:`cgmres_step` is
        ``kernel(memory, x, ref, settings, initialise)`` (for a caller that binds them once)."""
        return self._cgmres, self._mem, self._iprm

    def newton_step(self, x: np.ndarray, ref: np.ndarray, active: np.ndarray) -> int:
        """One Newton tick with the eq. 3.25 active set ``active`` (N, 4) int8."""
        return self._newton(self._mem, x, ref, self._iprm, active)

    def newton_call(self) -> tuple:
        """``(kernel, memory, settings)``: :meth:`newton_step` is
        ``kernel(memory, x, ref, settings, active)`` (for a caller that binds them once)."""
        return self._newton, self._mem, self._iprm

    # --- for tests and benchmarks of single kernels -----------------------------------
    @property
    def weights(self) -> np.ndarray:
        """The packed ``W`` (5, 7) the kernels take (see the layout)."""
        return self._W

    def workspace_views(self) -> tuple:
        """The kernels' workspace views (``layout.carve_workspace``) for direct kernel calls."""
        from ardrone_nmpc.control.kernels import carve_workspace as callable_carve_workspace

        return callable_carve_workspace(self._buf, self.horizon_steps, self.stage_dim, self._kmax)
