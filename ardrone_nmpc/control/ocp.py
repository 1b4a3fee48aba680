"""The thesis OCP as data, the solver result record, and what both NMPC solvers share.

Kept free of numba so that building an :class:`OcpSpec` from a config is cheap; the solvers
import the kernels when they are constructed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import NamedTuple

import numpy as np

from ardrone_nmpc.control.obstacles import (OBS_COLS, OBS_DIST, OBS_SHIFT, OBS_WEIGHT,
                                            obstacle_table)
from ardrone_nmpc.core import defaults
from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.types import IX_PSI


class SolverStatus(str, Enum):
    """Outcome of one controller solve; the supervisor, not the solver, picks the fallback."""

    OK = "ok"
    MAX_ITERATIONS = "max-iterations"
    DIVERGED = "diverged"
    NON_FINITE = "non-finite"


class SolveResult(NamedTuple):
    """One tick of an NMPC solver (a NamedTuple: immutable and cheap to build per tick).

    Attributes
    ----------
    u : (4,) input ``[z̈ m/s², φ rad, θ rad, ψ̇ rad/s]`` to apply; always finite and within the
        bounds (after a failure it is the re-initialised solver's first input).
    status : :class:`SolverStatus`.
    residual_norm : ‖F‖₂ of the optimality conditions (see each solver for which point).
    gmres_iterations : Krylov iterations spent this tick (all Newton steps together).
    solve_time_us : wall time of the solve (µs), measured around the kernels.
    newton_iterations : Newton steps this tick (0 for a pure continuation update).
    reinitialised : the solver reset its guess this tick (divergence or non-finite values).
    """

    u: np.ndarray
    status: SolverStatus
    residual_norm: float
    gmres_iterations: int
    solve_time_us: float
    newton_iterations: int = 0
    reinitialised: bool = False

    @property
    def ok(self) -> bool:
        return self.status is SolverStatus.OK


def _vector(values, length: int, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (length,):
        raise ValueError(f"{name}: expected {length} values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: values must be finite")
    return arr


@dataclass(frozen=True)
class OcpSpec:
    """Thesis eq. 3.14 with eq. 4.17 bounds: weights (diagonals), horizon and input box.

    Its defaults are the thesis' problem (its weights: the solver tests' reference problem);
    a flight's comes from its config (:meth:`from_config`), whose weights default otherwise.

    Parameters
    ----------
    horizon_steps : N, prediction steps.
    dtau_s : Δτ (s), prediction step at full horizon.
    q : (7,) state weights; r : (4,) input weights; q_terminal : (7,) terminal weights.
    u_min, u_max : (4,) input bounds (m/s², rad, rad, rad/s).
    horizon_ramp_rate_per_s : α of ``T(t) = N Δτ (1 − e^{−α t})``; 0 keeps Δτ fixed.
    obstacles : (n, ``OBS_COLS``) obstacle table (:func:`~ardrone_nmpc.control.obstacles.
        obstacle_table`): kind, centre (m), constraint distance d (m), penalty weight,
        tie-break shift (m); none by default.
    obstacle_gauss_newton : the solvers' Jacobian products see the penalty's Gauss–Newton
        curvature (positive semi-definite), not its exact one.
    """

    horizon_steps: int = defaults.HORIZON_STEPS
    dtau_s: float = defaults.DTAU_S
    q: np.ndarray = field(default_factory=lambda: np.array(defaults.THESIS_Q_STATE))
    r: np.ndarray = field(default_factory=lambda: np.array(defaults.THESIS_R_INPUT))
    q_terminal: np.ndarray = field(default_factory=lambda: np.array(defaults.Q_TERMINAL))
    u_min: np.ndarray = field(default_factory=lambda: np.array(defaults.U_MIN))
    u_max: np.ndarray = field(default_factory=lambda: np.array(defaults.U_MAX))
    horizon_ramp_rate_per_s: float = defaults.HORIZON_RAMP_RATE_PER_S
    obstacles: np.ndarray = field(default_factory=lambda: np.zeros((0, OBS_COLS)))
    obstacle_gauss_newton: bool = True

    def __post_init__(self):
        if self.horizon_steps < 1:
            raise ValueError(f"horizon_steps: must be ≥ 1, got {self.horizon_steps}")
        if not (self.dtau_s > 0 and math.isfinite(self.dtau_s)):
            raise ValueError(f"dtau_s: must be a positive number, got {self.dtau_s}")
        for name, length in (("q", 7), ("r", 4), ("q_terminal", 7), ("u_min", 4), ("u_max", 4)):
            object.__setattr__(self, name, _vector(getattr(self, name), length, name))
        if np.any(self.q < 0) or np.any(self.q_terminal < 0) or np.any(self.r <= 0):
            raise ValueError("weights: q, q_terminal must be ≥ 0 and r > 0")
        if np.any(self.u_min >= self.u_max):
            raise ValueError("u_min: must be below u_max for every input")
        obstacles = np.array(self.obstacles, dtype=float).reshape(-1, OBS_COLS)
        if not np.all(np.isfinite(obstacles)):
            raise ValueError("obstacles: values must be finite")
        positive = obstacles[:, [OBS_DIST, OBS_WEIGHT]]
        if np.any(positive <= 0) or np.any(obstacles[:, OBS_SHIFT] < 0):
            raise ValueError("obstacles: distances and weights must be positive, "
                             "tie-break shifts ≥ 0")
        object.__setattr__(self, "obstacles", obstacles)

    @classmethod
    def from_config(cls, controller) -> "OcpSpec":
        """Build from a ``config.ControllerConfig`` section."""
        return cls(
            horizon_steps=controller.horizon_steps,
            dtau_s=controller.dtau_s,
            q=controller.q,
            r=controller.r,
            q_terminal=controller.q_terminal,
            u_min=controller.u_min,
            u_max=controller.u_max,
            horizon_ramp_rate_per_s=controller.solver.horizon_ramp_rate_per_s,
            obstacles=obstacle_table(controller.obstacles, controller.obstacle_weight,
                                     controller.obstacle_tie_break_m),
            obstacle_gauss_newton=controller.obstacle_curvature == "gauss-newton",
        )

    def stage_dtau_s(self, elapsed_s: float) -> float:
        """Δτ at ``elapsed_s`` after the controller started (the horizon ramp)."""
        if self.horizon_ramp_rate_per_s <= 0.0:
            return self.dtau_s
        return self.dtau_s * (1.0 - math.exp(-self.horizon_ramp_rate_per_s * max(elapsed_s, 0.0)))

    def stage_cost(self, x: np.ndarray, x_ref: np.ndarray, u: np.ndarray) -> float:
        """``½ (x − x_d)ᵀ q (x − x_d) + ½ uᵀ r u`` (ψ error wrapped; tracking only, without
        the obstacle penalty)."""
        err = np.asarray(x, float) - np.asarray(x_ref, float)
        err[IX_PSI] = wrap_angle_rad(err[IX_PSI])
        return 0.5 * float(err @ (self.q * err) + u @ (self.r * u))
