"""Velocity estimation from motion capture (thesis ch. 4).

Vertical speed ż is not measured: it is estimated from the mocap altitude and the controller's
z̈ by a scalar Kalman filter (eq. 4.5–4.9), a Luenberger observer (eq. 4.10–4.15) or, as the
baseline, a finite difference. All follow :class:`VerticalSpeedEstimator`; build one with
:func:`make_vz_estimator`. Horizontal velocity comes from navdata or :class:`BackwardDifference`.
"""

from __future__ import annotations

from typing import Sequence

from ardrone_nmpc.estimation.base import EstimatorError, VerticalSpeedEstimator
from ardrone_nmpc.estimation.differentiate import BackwardDifference, FiniteDifferenceVz, NoVz
from ardrone_nmpc.estimation.kalman import THESIS_Q, THESIS_R, ScalarKalmanVz, steady_state_kalman
from ardrone_nmpc.estimation.luenberger import THESIS_LAMBDA0_PER_S, LuenbergerVz, observer_gain

__all__ = [
    "EstimatorError",
    "VerticalSpeedEstimator",
    "ScalarKalmanVz",
    "steady_state_kalman",
    "LuenbergerVz",
    "observer_gain",
    "FiniteDifferenceVz",
    "NoVz",
    "BackwardDifference",
    "make_vz_estimator",
    "VZ_ESTIMATOR_KINDS",
]

VZ_ESTIMATOR_KINDS = ("kalman", "luenberger", "difference", "none")

# Initial ż covariance: the drone starts at rest, so a modest prior (0.1 m/s std) is honest.
DEFAULT_KALMAN_P0 = 1e-2


def make_vz_estimator(
    kind: str,
    *,
    kalman_q: float = THESIS_Q,
    kalman_r: float = THESIS_R,
    kalman_p0: float = DEFAULT_KALMAN_P0,
    lambda0_per_s: float = THESIS_LAMBDA0_PER_S,
    gain: Sequence[float] | None = None,
) -> VerticalSpeedEstimator:
    """Build a vertical-speed estimator by name.

    Parameters
    ----------
    kind : {"kalman", "luenberger", "difference", "none"}
        Which estimator ("none": ż ≡ 0).
    kalman_q, kalman_r, kalman_p0 : float
        Kalman process/measurement variance per step and initial covariance, (m/s)².
        Defaults: the thesis' Q = 2.8559e-4, R = 3.2e-3, and P0 = 1e-2.
    lambda0_per_s : float
        Luenberger double-pole magnitude, 1/s (thesis: 5).
    gain : sequence of 2 float, optional
        Explicit Luenberger gain [k1, k2]; overrides ``lambda0_per_s``.

    Returns
    -------
    VerticalSpeedEstimator

    Raises
    ------
    ValueError
        Unknown ``kind`` (or invalid parameters for the chosen kind).
    """
    if kind == "kalman":
        return ScalarKalmanVz(kalman_q, kalman_r, kalman_p0)
    if kind == "luenberger":
        return LuenbergerVz(lambda0_per_s, gain)
    if kind == "difference":
        return FiniteDifferenceVz()
    if kind == "none":
        return NoVz()
    raise ValueError(f"unknown vz estimator kind {kind!r}; expected one of {VZ_ESTIMATOR_KINDS}")
