"""Backward finite differences: the baseline ż estimate and horizontal velocity from mocap.

``v[k] = (p[k] − p[k−1]) / Δt``. Unbiased for ż at mid-tick but noisy: with mocap noise σ the
difference has standard deviation √2·σ/Δt (2.6 mm at 65 ms → 57 mm/s), which is why the thesis
filters ż (ch. 4). Horizontal velocity normally comes from navdata; this is the fallback.
"""

from __future__ import annotations

import math
from typing import Sequence

from ardrone_nmpc.estimation.base import EstimatorError, check_finite, check_step

__all__ = ["FiniteDifferenceVz", "BackwardDifference"]


class NoVz:
    """No vertical-speed estimate: ż ≡ 0 (m/s) — the thesis' first altitude experiment
    (§3.5, fig. 3.2), where the NMPC flew without ż feedback. Follows
    :class:`~ardrone_nmpc.estimation.base.VerticalSpeedEstimator`.
    """

    def reset(self, z_m: float, vz_mps: float = 0.0) -> None:
        check_finite("z_m", z_m)

    def update(self, z_m: float, zacc_mps2: float, dt_s: float) -> float:
        check_step(z_m, zacc_mps2, dt_s)
        return 0.0

    @property
    def vz_mps(self) -> float:
        return 0.0

    def state(self) -> tuple:
        """Nothing: what a compiled step carries on (``runtime/tick_kernels.estimate_step``)."""
        return ()

    def set_state(self) -> None:
        """Put back a :meth:`state` (nothing)."""

    def __repr__(self) -> str:
        return "NoVz()"


class FiniteDifferenceVz:
    """Baseline vertical-speed estimate ``(z[k] − z[k−1]) / Δt`` (m/s); ignores z̈.

    Follows :class:`~ardrone_nmpc.estimation.base.VerticalSpeedEstimator`.
    """

    def __init__(self) -> None:
        self.reset(0.0, 0.0)

    def reset(self, z_m: float, vz_mps: float = 0.0) -> None:
        """Forget the history; ``vz_mps`` is returned until a difference can be taken."""
        self._z_m = check_finite("z_m", z_m)
        self._vz = check_finite("vz_mps", vz_mps)
        self._initialised = False

    def update(self, z_m: float, zacc_mps2: float, dt_s: float) -> float:
        """Return ``(z_m − z_prev) / dt_s`` (m/s); ``zacc_mps2`` is validated but unused."""
        z, _, dt = check_step(z_m, zacc_mps2, dt_s)
        if self._initialised:
            self._vz = (z - self._z_m) / dt
        self._initialised = True
        self._z_m = z
        return self._vz

    def state(self) -> tuple[float, float, bool]:
        """(z anchor, ż, initialised): what a compiled step carries on
        (``runtime/tick_kernels.estimate_step``, the same arithmetic)."""
        return self._z_m, self._vz, self._initialised

    def set_state(self, z_m: float, vz_mps: float, initialised: bool) -> None:
        """Put back a :meth:`state` (after a compiled step carried it on)."""
        self._z_m, self._vz, self._initialised = z_m, vz_mps, bool(initialised)

    @property
    def vz_mps(self) -> float:
        """Last ż estimate, m/s."""
        return self._vz

    @property
    def z_m(self) -> float:
        """Altitude of the last update, m."""
        return self._z_m

    def __repr__(self) -> str:
        return "FiniteDifferenceVz()"


class BackwardDifference:
    """Backward-difference velocity of an n-vector position, e.g. (x, y, z) in m → m/s.

    Parameters
    ----------
    size : int, optional
        Length of the position vector (default 3).

    Notes
    -----
    The first update after construction or :meth:`reset` returns zeros (there is nothing to
    difference against). Inputs are plain sequences and outputs tuples of python floats so the
    per-tick cost is a few float operations.
    """

    def __init__(self, size: int = 3) -> None:
        if int(size) != size or size < 1:
            raise EstimatorError(f"size must be a positive integer, got {size!r}")
        self._n = int(size)
        self.reset()

    def reset(self) -> None:
        """Forget the previous position; the next update returns zeros."""
        self._prev: tuple[float, ...] | None = None
        self._vel: tuple[float, ...] = (0.0,) * self._n

    def update(self, position_m: Sequence[float], dt_s: float) -> tuple[float, ...]:
        """Return ``(p − p_prev) / dt_s`` per component (m/s).

        Parameters
        ----------
        position_m : sequence of float, length ``size``
            Newest position, m.
        dt_s : float
            Time since the previous update, s, > 0.

        Raises
        ------
        EstimatorError
            Wrong length, a non-finite component, or ``dt_s <= 0``. State is left untouched.
        """
        if len(position_m) != self._n:
            raise EstimatorError(f"position_m must have {self._n} entries, got {len(position_m)}")
        p = tuple(map(float, position_m))
        if not all(map(math.isfinite, p)):
            i = next(i for i, v in enumerate(p) if not math.isfinite(v))
            raise EstimatorError(f"position_m[{i}] must be finite, got {p[i]!r}")
        dt = float(dt_s)
        if not dt > 0.0 or dt == math.inf:  # the usual tick: one test (NaN fails it)
            dt = check_finite("dt_s", dt_s)
            raise EstimatorError(f"dt_s must be > 0, got {dt!r}")
        prev = self._prev
        if prev is not None:
            if len(p) == 2:  # the tick's (x, y): spelled out, a generator costs ~0.5 µs
                self._vel = ((p[0] - prev[0]) / dt, (p[1] - prev[1]) / dt)
            else:
                self._vel = tuple((a - b) / dt for a, b in zip(p, prev))
        self._prev = p
        return self._vel

    @property
    def velocity_mps(self) -> tuple[float, ...]:
        """Last velocity estimate, m/s."""
        return self._vel

    def state(self) -> tuple[tuple[float, ...] | None, tuple[float, ...]]:
        """(previous position or None, velocity): what a compiled step carries on from
        (``runtime/tick_kernels.estimate_step``, the same arithmetic)."""
        return self._prev, self._vel

    def set_state(self, previous_m: tuple[float, ...] | None,
                  velocity_mps: tuple[float, ...]) -> None:
        """Put back a :meth:`state` (after a compiled step carried it on)."""
        self._prev = None if previous_m is None else tuple(previous_m)
        self._vel = tuple(velocity_mps)

    def __repr__(self) -> str:
        return f"BackwardDifference(size={self._n})"
