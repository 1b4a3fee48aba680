"""The one-step interface shared by the vertical-speed (ż) estimators of thesis ch. 4.

Every 65 ms tick the loop calls ``update(z_m, zacc_mps2, dt_s)`` with the newest mocap altitude,
the z̈ the controller applied over the tick just ended (u1[k−1]) and the time since the previous
update, and gets back the corrected ż estimate. The scalar updates run on python floats: a
handful of multiplications per tick, no array allocation.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

__all__ = ["EstimatorError", "VerticalSpeedEstimator", "check_finite", "check_step"]


class EstimatorError(ValueError):
    """An estimator was fed an input it cannot use (non-finite value, non-positive dt)."""


@runtime_checkable
class VerticalSpeedEstimator(Protocol):
    """Estimates ż (m/s) from measured altitude z (m) and the commanded z̈ (m/s²).

    Contract
    --------
    * The first ``update`` after construction or ``reset`` only initialises: it anchors the
      altitude to ``z_m`` and returns the reset ż (0 after construction). There is no previous
      sample to difference against, and the dt since a reset is not meaningful.
    * Later calls run one predict/correct step over ``dt_s`` and return the corrected ż.
    * ``dt_s <= 0`` or any non-finite input raises :class:`EstimatorError`, also on the first
      call, and leaves the estimator's state untouched.
    """

    def reset(self, z_m: float, vz_mps: float = 0.0) -> None:
        """Forget the history; seed the altitude (m) and vertical speed (m/s) estimates."""
        ...

    def update(self, z_m: float, zacc_mps2: float, dt_s: float) -> float:
        """Run one tick and return the corrected ż estimate (m/s)."""
        ...

    @property
    def vz_mps(self) -> float:
        """The last ż estimate (m/s)."""
        ...


def check_finite(name: str, value: float) -> float:
    """Return ``float(value)`` or raise :class:`EstimatorError` naming ``name`` if non-finite."""
    v = float(value)
    if not math.isfinite(v):
        raise EstimatorError(f"{name} must be finite, got {v!r}")
    return v


def check_step(z_m: float, zacc_mps2: float, dt_s: float) -> tuple[float, float, float]:
    """Validate one ``update``'s inputs; returns them as python floats.

    Raises
    ------
    EstimatorError
        If any input is non-finite or ``dt_s <= 0``.
    """
    z, a, dt = float(z_m), float(zacc_mps2), float(dt_s)
    if not (math.isfinite(z) and math.isfinite(a) and math.isfinite(dt)):  # name the first
        check_finite("z_m", z)
        check_finite("zacc_mps2", a)
        check_finite("dt_s", dt)
    if dt <= 0.0:
        raise EstimatorError(f"dt_s must be > 0, got {dt!r}")
    return z, a, dt
