"""Reference trajectories: the desired state x_d(t) and its horizon for the NMPC.

A trajectory gives the desired *state* ``[x, ẋ, y, ẏ, z, ż, ψ]`` (m, m/s, m, m/s, m, m/s, rad;
order of :mod:`ardrone_nmpc.core.types`) at any time ``t`` (s from the start of the experiment).
Velocities are part of it: the NMPC penalises velocity error, so a moving reference carries its
own velocity and a set point has zero velocity.

Every trajectory implements the :class:`Trajectory` protocol:

* ``state_at(t_s)`` — vectorised over times: ``(len(t), 7)``;
* ``duration_s`` — the natural length (s): a path's end time (it holds its last point after it),
  ``inf`` for set points (hover, step) and endless paths (ellipse);
* ``polyline_m()`` — the path as a ``(K, 3)`` polyline for path-deviation metrics. Consecutive
  points are distinct (no zero-length segments) and at most 2 cm apart, except for set points:
  a hover is its one point, a step its start and target points (one point if they coincide, as
  in a pure heading step).

:func:`horizon` stacks ``state_at`` over the NMPC's stage times ``t + i·Δτ``, i = 0..N.
:func:`make_trajectory` builds a trajectory from a :class:`~ardrone_nmpc.config.schema.ReferenceConfig`.

ψ in a reference is continuous (unwrapped) along time; the controller wraps errors.
Times before 0 (or before a waypoint file's first time) hold the first point with zero velocity.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z, STATE_DIM
from ardrone_nmpc.reference.waypoints import ReferenceError, WaypointFile, read_waypoint_file

if TYPE_CHECKING:  # pragma: no cover
    from ardrone_nmpc.config.schema import ReferenceConfig

__all__ = [
    "Ellipse",
    "Hover",
    "KIND_FIELDS",
    "LORENZ_BETA",
    "LORENZ_RHO",
    "LORENZ_SIGMA",
    "Lorenz",
    "POLYLINE_SPACING_M",
    "ReferenceError",
    "Square",
    "SquareAltitudes",
    "Step",
    "Trajectory",
    "Waypoints",
    "horizon",
    "ignored_fields",
    "input_files",
    "make_trajectory",
    "path_file",
]

#: Largest spacing (m) between consecutive points of a path's polyline.
POLYLINE_SPACING_M = 0.02

#: Most points of a computed (Lorenz) polyline; a longer path is sampled more coarsely than
#: POLYLINE_SPACING_M (24 MB of points; the configs' Lorenz path needs ≈ 6000).
MAX_POLYLINE_POINTS = 1_000_000

#: Lorenz-system parameters (the classic chaotic set).
LORENZ_SIGMA = 10.0
LORENZ_RHO = 28.0
LORENZ_BETA = 8.0 / 3.0

_POS = (IX_X, IX_Y, IX_Z)
_VEL = (IX_VX, IX_VY, IX_VZ)


@runtime_checkable
class Trajectory(Protocol):
    """A desired state as a function of time (see the module docstring)."""

    @property
    def duration_s(self) -> float:
        """Natural length (s); ``inf`` for set points and endless paths."""
        ...

    def state_at(self, t_s: np.ndarray) -> np.ndarray:
        """Desired states ``(len(t), 7)`` at times ``t_s`` (s)."""
        ...

    def polyline_m(self) -> np.ndarray:
        """The path as a ``(K, 3)`` polyline (m)."""
        ...


# ----------------------------------------------------------------------------- helpers


_F64 = np.dtype(np.float64)


def is_times(t_s: object) -> bool:
    """True for what :func:`_times` passes through as it is: a 1-D C-contiguous float64
    ndarray, the horizon's times every tick (its conversions cost µs a tick, issue 26)."""
    return (type(t_s) is np.ndarray and t_s.dtype is _F64 and t_s.ndim == 1
            and t_s.flags.c_contiguous)


def _times(t_s: np.ndarray | float | Sequence[float]) -> np.ndarray:
    """Times as a 1-D float array (a scalar becomes one time)."""
    if is_times(t_s):  # the general path would return a view of the same values
        return t_s
    return _times_general(t_s)


def _times_general(t_s: np.ndarray | float | Sequence[float]) -> np.ndarray:
    """:func:`_times` for any input (tests check the fast path against it)."""
    return np.atleast_1d(np.asarray(t_s, dtype=np.float64)).ravel()


def _vec(value: Sequence[float] | np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected {n} values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: values must be finite")
    return arr


def _positive(value: float, name: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: must be a finite number > 0, got {value}")
    return value


def _states(n: int) -> np.ndarray:
    return np.zeros((n, STATE_DIM), dtype=np.float64)


def _dedupe(points: np.ndarray) -> np.ndarray:
    """Drop points equal to their predecessor (no zero-length segments)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) < 2:
        return points
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.any(np.diff(points, axis=0) != 0.0, axis=1)
    return points[keep]


def _densify(points: np.ndarray, spacing_m: float = POLYLINE_SPACING_M) -> np.ndarray:
    """Insert evenly spaced points on each segment so that no two consecutive points are more
    than ``spacing_m`` apart; the original points are kept exactly."""
    points = _dedupe(points)
    if len(points) < 2:
        return points
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / spacing_m))
        frac = np.arange(1, n + 1, dtype=np.float64)[:, None] / n
        seg = a + frac * (b - a)
        seg[-1] = b
        out.append(seg)
    return np.vstack(out)


def horizon(traj: Trajectory, t_s: float, dtau_s: float, n_steps: int) -> np.ndarray:
    """The reference over an NMPC horizon.

    Parameters
    ----------
    traj : the trajectory.
    t_s : current time (s).
    dtau_s : prediction step Δτ (s), > 0.
    n_steps : horizon length N (steps), ≥ 1.

    Returns
    -------
    ndarray (N+1, 7)
        Row i is ``traj.state_at(t_s + i·Δτ)``, i = 0..N.
    """
    n_steps = int(n_steps)
    if n_steps < 1:
        raise ValueError(f"n_steps: must be >= 1, got {n_steps}")
    dtau_s = _positive(dtau_s, "dtau_s")
    times = float(t_s) + dtau_s * np.arange(n_steps + 1, dtype=np.float64)
    return traj.state_at(times)


# ----------------------------------------------------------------------------- set points


class Hover:
    """Hold a position and heading.

    Parameters
    ----------
    position_m : (3,) [x, y, z] (m).
    psi_rad : heading ψ (rad).
    """

    duration_s = math.inf

    def __init__(self, position_m: Sequence[float], psi_rad: float = 0.0) -> None:
        self.position_m = _vec(position_m, 3, "position_m")
        self.psi_rad = float(psi_rad)
        self._state = _states(1)[0]
        self._state[list(_POS)] = self.position_m
        self._state[IX_PSI] = self.psi_rad
        # the compiled lookup's arrays: a step at t = −∞ from the point to itself
        self._kernel_args = _set_point_args(self._state, self._state, -math.inf)

    def state_at(self, t_s: np.ndarray) -> np.ndarray:
        out = np.empty((_times(t_s).size, STATE_DIM))  # np.tile's rows, without its µs
        out[...] = self._state
        return out

    def polyline_m(self) -> np.ndarray:
        """The single hover point, (1, 3)."""
        return self.position_m[None, :].copy()


class Step:
    """A step of all axes together: the start before ``step_time_s``, the target from it on.

    The thesis' single-axis steps (x 0 → −1.5 m, y 1 m, take-off to z = 1 m, ψ 0 → 1 rad) are
    configurations whose start and target differ in one axis only. Velocities are zero.

    Parameters
    ----------
    start_m, target_m : (3,) positions [x, y, z] (m).
    start_psi_rad, target_psi_rad : headings (rad), used as given (not wrapped).
    step_time_s : time of the step (s); the target holds at ``t ≥ step_time_s``.
    """

    duration_s = math.inf

    def __init__(self, start_m: Sequence[float], start_psi_rad: float,
                 target_m: Sequence[float], target_psi_rad: float,
                 step_time_s: float = 1.0) -> None:
        self.start_m = _vec(start_m, 3, "start_m")
        self.target_m = _vec(target_m, 3, "target_m")
        self.start_psi_rad = float(start_psi_rad)
        self.target_psi_rad = float(target_psi_rad)
        self.step_time_s = float(step_time_s)
        self._before = Hover(self.start_m, self.start_psi_rad).state_at(0.0)[0]
        self._after = Hover(self.target_m, self.target_psi_rad).state_at(0.0)[0]
        self._kernel_args = _set_point_args(self._before, self._after, self.step_time_s)

    def state_at(self, t_s: np.ndarray) -> np.ndarray:
        t = _times(t_s)
        return np.where((t >= self.step_time_s)[:, None], self._after, self._before)

    def polyline_m(self) -> np.ndarray:
        """Start and target, (2, 3); (1, 3) if they coincide (a heading-only step)."""
        return _dedupe(np.vstack([self.start_m, self.target_m]))


def _set_point_args(before: np.ndarray, after: np.ndarray, step_time_s: float) -> tuple | None:
    """The arrays of the compiled waypoint lookup (``reference/kernels.waypoint_states``) whose
    states are ``before`` at t < ``step_time_s`` and ``after`` from it on, both at rest —
    :meth:`Step.state_at`'s bits — or None where the lookup cannot give them exactly.

    Two knots at ``step_time_s``: the segment between them is never entered, so at or after
    the step the lookup returns the last knot and +0.0 velocities as they are; before it (and
    at a NaN time) it computes ``a + 0.0·(b − a)`` from the first knot a: a's bits, except for
    a −0.0 coordinate (or an overflowing difference) — that set point keeps numpy's path."""
    positions_m = np.vstack([before[list(_POS)], after[list(_POS)]])
    psi_rad = np.array([before[IX_PSI], after[IX_PSI]])
    a = np.append(positions_m[0], psi_rad[0])
    b = np.append(positions_m[1], psi_rad[1])
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused here
        if (a + 0.0 * (b - a)).tobytes() != a.tobytes():
            return None
    return (np.full(2, step_time_s), positions_m, psi_rad, np.zeros(1), np.zeros((1, 3)))


# ----------------------------------------------------------------------------- piecewise linear


class Waypoints:
    """Linear interpolation between timed waypoints.

    Between waypoints k and k+1 the position moves at the constant velocity
    ``(p[k+1] − p[k]) / (t[k+1] − t[k])`` (right-continuous: at ``t[k]`` the state carries the
    velocity of the segment that starts there). Before the first time the first waypoint holds,
    from the last time on the last one, both with zero velocity. ψ is interpolated along the
    shortest way: the waypoint headings are unwrapped first (consecutive differences ≤ π).

    Parameters
    ----------
    t_s : (K,) strictly increasing times (s), K ≥ 2.
    positions_m : (K, 3) positions [x, y, z] (m).
    psi_rad : (K,) headings (rad), wrapped or not.
    """

    def __init__(self, t_s: Sequence[float] | np.ndarray, positions_m: np.ndarray,
                 psi_rad: Sequence[float] | np.ndarray) -> None:
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        p = np.asarray(positions_m, dtype=np.float64)
        psi = np.asarray(psi_rad, dtype=np.float64).reshape(-1)
        if t.size < 2:
            raise ValueError(f"t_s: at least 2 waypoints are needed, got {t.size}")
        if p.shape != (t.size, 3):
            raise ValueError(f"positions_m: expected shape ({t.size}, 3), got {p.shape}")
        if psi.shape != t.shape:
            raise ValueError(f"psi_rad: expected {t.size} values, got {psi.size}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(psi))):
            raise ValueError("waypoints must be finite")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise ValueError(f"t_s: time {t[k]} is not after the previous {t[k - 1]}")
        self.t_s = t
        self.positions_m = p
        self.psi_rad = np.unwrap(psi)
        self._dt = np.diff(t)
        self._vel = np.diff(p, axis=0) / self._dt[:, None]  # (K-1, 3) segment velocities
        # one layout for the compiled lookup (one specialisation)
        self._kernel_args = tuple(np.ascontiguousarray(a) for a in
                                  (t, p, self.psi_rad, self._dt, self._vel))

    @classmethod
    def from_file(cls, waypoints: WaypointFile) -> Waypoints:
        """The trajectory of a waypoint file read by
        :func:`~ardrone_nmpc.reference.waypoints.read_waypoint_file`."""
        return cls(waypoints.t_s, waypoints.positions_m, waypoints.psi_rad)

    @property
    def duration_s(self) -> float:
        """Time of the last waypoint (s)."""
        return float(self.t_s[-1])

    def state_at(self, t_s: np.ndarray) -> np.ndarray:
        kernel = _waypoint_states if _waypoint_states is not None else _waypoint_kernel()
        t = np.ascontiguousarray(_times(t_s))
        out = np.empty((t.size, STATE_DIM))
        kernel(*self._kernel_args, t, out)
        return out

    def polyline_m(self) -> np.ndarray:
        """The waypoints, densified to ≤ 2 cm spacing."""
        return _densify(self.positions_m)


#: The compiled lookup of :class:`Waypoints`, imported at its first use (numba: not at the
#: command line's start-up; an import statement per lookup costs ½ µs a tick).
_waypoint_states = None


def _waypoint_kernel():
    global _waypoint_states
    from ardrone_nmpc.reference.kernels import waypoint_states

    _waypoint_states = waypoint_states
    return waypoint_states


def _square_corners_xy(start_xy_m: np.ndarray, side_m: float) -> np.ndarray:
    """Corners of a lap: start, then legs +x, +y, −x, −y (counter-clockwise seen from above),
    back to the start. (5, 2)."""
    steps = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=np.float64)
    return start_xy_m + side_m * steps


class Square(Waypoints):
    """One lap of a square at constant altitude and heading, constant speed on each leg.

    The first corner is the start ``start_m[:2]``; the legs go +x, +y, −x, −y
    (counter-clockwise seen from above, x forward, y left) and return to it. Corner k
    (k = 0..4, corner 4 = corner 0) is reached at ``t = k·leg_duration_s``; on a leg the
    velocity is the leg vector / leg_duration_s (speed side_m / leg_duration_s), after the
    lap (``t ≥ 4·leg_duration_s``) the start holds with zero velocity.

    Parameters
    ----------
    start_m : (3,) first corner [x, y] and altitude z (m).
    side_m : side length (m), > 0.
    leg_duration_s : time per side (s), > 0.
    psi_rad : constant heading (rad).
    """

    def __init__(self, start_m: Sequence[float], side_m: float = 1.0,
                 leg_duration_s: float = 5.0, psi_rad: float = 0.0) -> None:
        start = _vec(start_m, 3, "start_m")
        self.side_m = _positive(side_m, "side_m")
        self.leg_duration_s = _positive(leg_duration_s, "leg_duration_s")
        xy = _square_corners_xy(start[:2], self.side_m)
        corners = np.column_stack([xy, np.full(5, start[2])])
        super().__init__(self.leg_duration_s * np.arange(5.0), corners, np.full(5, float(psi_rad)))


class SquareAltitudes(Waypoints):
    """The square of :class:`Square` with a different altitude at each corner.

    Corner k (k = 0..3) is at altitude ``altitudes_m[k]``; the lap closes at corner 0
    (altitude ``altitudes_m[0]``). Each leg interpolates the altitude linearly, so ż is the
    leg's altitude change / leg_duration_s. The reference starts at corner 0 at
    ``altitudes_m[0]`` (not at a start altitude).

    Parameters
    ----------
    start_xy_m : (2,) first corner [x, y] (m) (a (3,) value's z is ignored).
    side_m : side length (m), > 0.
    altitudes_m : (4,) corner altitudes (m).
    leg_duration_s : time per side (s), > 0.
    psi_rad : constant heading (rad).
    """

    def __init__(self, start_xy_m: Sequence[float], side_m: float = 1.0,
                 altitudes_m: Sequence[float] = (0.8, 1.0, 1.2, 1.4),
                 leg_duration_s: float = 5.0, psi_rad: float = 0.0) -> None:
        start = np.asarray(start_xy_m, dtype=np.float64).reshape(-1)
        start = _vec(start[:2] if start.size == 3 else start, 2, "start_xy_m")
        alt = _vec(altitudes_m, 4, "altitudes_m")
        self.side_m = _positive(side_m, "side_m")
        self.leg_duration_s = _positive(leg_duration_s, "leg_duration_s")
        self.altitudes_m = alt
        xy = _square_corners_xy(start, self.side_m)
        corners = np.column_stack([xy, np.append(alt, alt[0])])
        super().__init__(self.leg_duration_s * np.arange(5.0), corners, np.full(5, float(psi_rad)))


# ----------------------------------------------------------------------------- curves


class Ellipse:
    """An endless elliptical path at constant altitude and heading, counter-clockwise.

    ``x = cx + a cos(ωt)``, ``y = cy + b sin(ωt)``, ``z = altitude``, ω = 2π / period, with the
    analytic velocities ``ẋ = −aω sin(ωt)``, ``ẏ = bω cos(ωt)``, ż = 0. It starts at
    ``(cx + a, cy)`` moving towards +y. Peak speed ``ω·max(a, b)``.

    Parameters
    ----------
    center_m : (2,) centre [cx, cy] (m).
    semi_axes_m : (2,) semi-axes [a (along x), b (along y)] (m), > 0.
    altitude_m : altitude z (m).
    period_s : time per lap T (s), > 0.
    psi_rad : constant heading (rad).
    """

    duration_s = math.inf

    def __init__(self, center_m: Sequence[float] = (0.0, 0.0),
                 semi_axes_m: Sequence[float] = (1.0, 0.6), altitude_m: float = 1.0,
                 period_s: float = 20.0, psi_rad: float = 0.0) -> None:
        self.center_m = _vec(center_m, 2, "center_m")
        self.semi_axes_m = _vec(semi_axes_m, 2, "semi_axes_m")
        if np.any(self.semi_axes_m <= 0):
            raise ValueError("semi_axes_m: must be > 0")
        self.altitude_m = float(altitude_m)
        self.period_s = _positive(period_s, "period_s")
        self.psi_rad = float(psi_rad)
        self.omega_radps = 2.0 * math.pi / self.period_s

    def state_at(self, t_s: np.ndarray) -> np.ndarray:
        t = _times(t_s)
        a, b = self.semi_axes_m
        w = self.omega_radps
        c, s = np.cos(w * t), np.sin(w * t)
        out = _states(t.size)
        out[:, IX_X] = self.center_m[0] + a * c
        out[:, IX_VX] = -a * w * s
        out[:, IX_Y] = self.center_m[1] + b * s
        out[:, IX_VY] = b * w * c
        out[:, IX_Z] = self.altitude_m
        out[:, IX_PSI] = self.psi_rad
        return out

    def polyline_m(self) -> np.ndarray:
        """One closed lap (first point repeated at the end), ≤ 2 cm spacing."""
        # chord ≤ arc ≤ max(a, b)·Δθ
        n = max(8, math.ceil(2.0 * math.pi * float(self.semi_axes_m.max())
                             / (0.9 * POLYLINE_SPACING_M)))
        theta = np.linspace(0.0, 2.0 * math.pi, n + 1)
        a, b = self.semi_axes_m
        pts = np.column_stack([self.center_m[0] + a * np.cos(theta),
                               self.center_m[1] + b * np.sin(theta),
                               np.full(theta.size, self.altitude_m)])
        pts[-1] = pts[0]
        return pts


def _lorenz_rhs(_tau: float, s: np.ndarray) -> np.ndarray:
    x, y, z = s
    return np.array([LORENZ_SIGMA * (y - x), x * (LORENZ_RHO - z) - y, x * y - LORENZ_BETA * z])


def _lorenz_rhs_many(s: np.ndarray) -> np.ndarray:
    """RHS for states ``(3, n)`` → ``(3, n)``."""
    x, y, z = s
    return np.vstack([LORENZ_SIGMA * (y - x), x * (LORENZ_RHO - z) - y, x * y - LORENZ_BETA * z])


class Lorenz:
    """A path along the Lorenz attractor (σ = 10, ρ = 28, β = 8/3), scaled to the flight space.

    The system is integrated once at construction (``scipy.integrate.solve_ivp``, DOP853,
    rtol = atol = 1e-10, dense output) from the fixed initial point (1, 1, 1); the first
    ``transient`` Lorenz time units are discarded so the path starts on the attractor. With
    Lorenz state ``(X, Y, Z)(τ)`` and ``τ = τ0 + time_scale · t``::

        x = cx + scale·X,   y = cy + scale·Y,   z = altitude + scale·(Z − 25)

    and the velocities are ``scale·time_scale·f(X, Y, Z)`` from the ODE right-hand side f
    (exact for the integrated path, not finite differences). Outside ``[0, duration_s]`` the
    end points hold with zero velocity.

    On the attractor |X| ≲ 18, |Y| ≲ 25, 5 ≲ Z ≲ 45 and the speed reaches ≈ 343 Lorenz units
    (over 150 Lorenz time units), so the peak reference speed is ≈ 343·scale·time_scale m/s and
    the altitude spans about ±20·scale around ``altitude``. The defaults (scale 0.05 m,
    time_scale 0.05) give ≈ 0.86 m/s, x ∈ ±0.9 m, y ∈ ±1.25 m, z ∈ altitude ± 1 m.

    Parameters
    ----------
    scale_m : metres per Lorenz unit, > 0.
    time_scale : Lorenz time per second of flight (dimensionless), > 0.
    center_m : (2,) horizontal centre [cx, cy] (m).
    altitude_m : altitude of Z = 25 (m).
    psi_rad : constant heading (rad).
    duration_s : flight time covered (s), > 0.
    transient : Lorenz time discarded before t = 0 (dimensionless), ≥ 0.
    """

    def __init__(self, scale_m: float = 0.05, time_scale: float = 0.05,
                 center_m: Sequence[float] = (0.0, 0.0), altitude_m: float = 1.25,
                 psi_rad: float = 0.0, duration_s: float = 120.0,
                 transient: float = 10.0) -> None:
        from scipy.integrate import solve_ivp

        self.scale_m = _positive(scale_m, "scale_m")
        self.time_scale = _positive(time_scale, "time_scale")
        self.center_m = _vec(center_m, 2, "center_m")
        self.altitude_m = float(altitude_m)
        self.psi_rad = float(psi_rad)
        self._duration_s = _positive(duration_s, "duration_s")
        self.transient = float(transient)
        if not (math.isfinite(self.transient) and self.transient >= 0):
            raise ValueError(f"transient: must be >= 0, got {transient}")
        s0 = np.array([1.0, 1.0, 1.0])
        if self.transient > 0:
            pre = solve_ivp(_lorenz_rhs, (0.0, self.transient), s0, method="DOP853",
                            rtol=1e-10, atol=1e-10)
            if not pre.success:  # pragma: no cover - solve_ivp does not fail on this system
                raise ReferenceError(f"Lorenz integration failed: {pre.message}")
            s0 = pre.y[:, -1]
        self._tau_end = self.time_scale * self._duration_s
        sol = solve_ivp(_lorenz_rhs, (0.0, self._tau_end), s0, method="DOP853",
                        rtol=1e-10, atol=1e-10, dense_output=True)
        if not sol.success:  # pragma: no cover
            raise ReferenceError(f"Lorenz integration failed: {sol.message}")
        self._sol = sol.sol
        self._offset = np.array([self.center_m[0], self.center_m[1],
                                 self.altitude_m - 25.0 * self.scale_m])

    @property
    def duration_s(self) -> float:
        """Flight time covered by the integration (s)."""
        return self._duration_s

    def state_at(self, t_s: np.ndarray) -> np.ndarray:
        t = _times(t_s)
        inside = (t >= 0.0) & (t <= self._duration_s)
        tau = self.time_scale * np.clip(t, 0.0, self._duration_s)
        lor = np.asarray(self._sol(tau), dtype=np.float64).reshape(3, t.size)
        vel = (self.scale_m * self.time_scale) * _lorenz_rhs_many(lor)
        out = _states(t.size)
        out[:, list(_POS)] = self._offset + self.scale_m * lor.T
        out[:, list(_VEL)] = np.where(inside[:, None], vel.T, 0.0)
        out[:, IX_PSI] = self.psi_rad
        return out

    def peak_speed_mps(self, dt_s: float = 0.005) -> float:
        """Largest reference speed (m/s) on a ``dt_s`` grid over ``[0, duration_s]``."""
        t = np.linspace(0.0, self._duration_s, max(2, math.ceil(self._duration_s / dt_s) + 1))
        s = self.state_at(t)
        return float(np.linalg.norm(s[:, list(_VEL)], axis=1).max())

    def polyline_m(self) -> np.ndarray:
        """The path over ``[0, duration_s]``, ≤ 2 cm spacing (chord ≤ speed·Δt); at most
        :data:`MAX_POLYLINE_POINTS` points (coarser spacing beyond that)."""
        peak = self.peak_speed_mps()
        dt = 0.75 * POLYLINE_SPACING_M / max(peak, 1e-9)
        n = min(MAX_POLYLINE_POINTS, max(2, math.ceil(self._duration_s / dt) + 1))
        t = np.linspace(0.0, self._duration_s, n)
        return _dedupe(self.state_at(t)[:, list(_POS)])


# ----------------------------------------------------------------------------- files


def path_file(ref_cfg: ReferenceConfig) -> WaypointFile:
    """The waypoint file of a 'path' reference, read and checked
    (:func:`~ardrone_nmpc.reference.waypoints.read_waypoint_file`); every error starts
    ``reference.path_file:``."""
    if ref_cfg.path_file is None:
        raise ReferenceError("reference.path_file: required when kind is 'path'")
    try:
        return read_waypoint_file(ref_cfg.path_file)
    except ReferenceError as err:
        raise ReferenceError(f"reference.path_file: {err}") from None


def input_files(ref_cfg: ReferenceConfig) -> dict[str, WaypointFile]:
    """The input files a reference names, read and checked: ``{"path_file": …}`` for kind
    'path' and for any kind that names one (a named file must exist even where the kind
    ignores it — :func:`ignored_fields` warns of that). ``check`` and every run read them
    here, before anything is created."""
    if ref_cfg.kind == "path" or ref_cfg.path_file is not None:
        return {"path_file": path_file(ref_cfg)}
    return {}


#: The reference fields that only some kinds read (the others are read by every kind).
KIND_FIELDS: dict[str, tuple[str, ...]] = {
    "target_m": ("step",), "target_psi_rad": ("step",), "step_time_s": ("step",),
    "side_m": ("square", "square_altitudes"), "leg_duration_s": ("square", "square_altitudes"),
    "altitudes_m": ("square_altitudes",), "center_m": ("ellipse", "lorenz"),
    "semi_axes_m": ("ellipse",), "period_s": ("ellipse",), "lorenz_scale_m": ("lorenz",),
    "lorenz_time_scale": ("lorenz",), "path_file": ("path",), "follow": ("follow",),
}


def ignored_fields(ref_cfg: ReferenceConfig) -> list[str]:
    """One line per reference field set away from its default that the chosen kind does not
    read (``reference.path_file: ignored by reference.kind 'step' (read by: path)``)."""
    notes = []
    for name, kinds in KIND_FIELDS.items():
        info = type(ref_cfg).model_fields[name]
        default = info.get_default(call_default_factory=True)
        if ref_cfg.kind not in kinds and getattr(ref_cfg, name) != default:
            notes.append(f"reference.{name}: ignored by reference.kind {ref_cfg.kind!r} "
                         f"(read by: {', '.join(kinds)})")
    return notes


# ----------------------------------------------------------------------------- from config


def make_trajectory(ref_cfg: ReferenceConfig, duration_s: float | None = None) -> Trajectory:
    """Build the trajectory of a :class:`~ardrone_nmpc.config.schema.ReferenceConfig`.

    ========================  =================================================================
    kind                      trajectory
    ========================  =================================================================
    ``hover``                 :class:`Hover` at ``start_m``, ``start_psi_rad``
    ``step``                  :class:`Step` start → target at ``step_time_s``
    ``square``                :class:`Square` from corner ``start_m`` (its z is the altitude)
    ``square_altitudes``      :class:`SquareAltitudes` from corner ``start_m[:2]``,
                              ``altitudes_m``
    ``ellipse``               :class:`Ellipse` around ``center_m`` at altitude ``start_m[2]``
    ``lorenz``                :class:`Lorenz` around ``center_m``, altitude ``start_m[2]``,
                              ``lorenz_scale_m``, ``lorenz_time_scale``
    ``path``                  :class:`Waypoints` of ``path_file`` (:func:`path_file`)
    ``follow``                :class:`~ardrone_nmpc.reference.live.LiveTarget` (a second mocap object)
    ``excitation``            :class:`~ardrone_nmpc.reference.excitation.Excitation` around
                              ``start_m`` (the identification flight)
    ========================  =================================================================

    Paths use ``start_psi_rad`` as their constant heading. ``duration_s`` (s) is the flight
    time a Lorenz path must cover (default: :class:`Lorenz`'s); other kinds ignore it.
    Raises :class:`ReferenceError` for a missing or bad waypoint file or an unknown kind.
    """
    kind = ref_cfg.kind
    start = np.asarray(ref_cfg.start_m, dtype=np.float64)
    psi = float(ref_cfg.start_psi_rad)
    if kind == "hover":
        return Hover(start, psi)
    if kind == "step":
        return Step(start, psi, ref_cfg.target_m, ref_cfg.target_psi_rad, ref_cfg.step_time_s)
    if kind == "square":
        return Square(start, ref_cfg.side_m, ref_cfg.leg_duration_s, psi)
    if kind == "square_altitudes":
        return SquareAltitudes(start[:2], ref_cfg.side_m, ref_cfg.altitudes_m,
                               ref_cfg.leg_duration_s, psi)
    if kind == "ellipse":
        return Ellipse(ref_cfg.center_m, ref_cfg.semi_axes_m, start[2], ref_cfg.period_s, psi)
    if kind == "lorenz":
        extra = {} if duration_s is None else {"duration_s": duration_s}
        return Lorenz(ref_cfg.lorenz_scale_m, ref_cfg.lorenz_time_scale, ref_cfg.center_m,
                      start[2], psi, **extra)
    if kind == "path":
        return Waypoints.from_file(path_file(ref_cfg))
    if kind == "excitation":
        from ardrone_nmpc.reference.excitation import Excitation

        e = ref_cfg.excitation
        return Excitation(start, psi, e.amplitude_m, e.amplitude_psi_rad, axis_s=e.axis_s,
                          bit_s=e.bit_s, rest_s=e.rest_s, sweep_m=e.sweep_m,
                          sweep_mps=e.sweep_mps)
    if kind == "follow":  # live: fed each tick by the runner (ardrone_nmpc/reference/live.py)
        from ardrone_nmpc.reference.live import LiveTarget

        return LiveTarget(ref_cfg)
    raise ReferenceError(f"reference.kind: unknown trajectory kind {kind!r}")
