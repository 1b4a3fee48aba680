"""Scalar Kalman filter for the vertical speed ż (thesis §4.4, eq. 4.5–4.9).

Model (forward Euler of ż' = z̈, eq. 4.7): ``ż[k] = ż[k−1] + Δt · u1[k−1]``, i.e. A = 1,
B = Δt, C = 1. The measurement is the finite difference of the mocap altitude,
``y[k] = (z[k] − z[k−1]) / Δt``. Q and R are per-step variances in (m/s)²; the thesis measured
Q = 2.8559e-4 and R = 3.2e-3 (R is exactly 2σ²/Δt² for σ = 2.6 mm mocap noise at Δt = 65 ms).

Mid-tick measurement
--------------------
For z̈ held at u over the tick, the finite difference equals ż at the *middle* of the tick,
``y[k] = ż[k] − u·Δt/2``, not ż[k]. Eq. 4.9 taken literally (C = 1) therefore settles
``u·Δt/2`` low (3 cm/s per m/s² at 65 ms). With ``measurement_at_midpoint=True`` (default) the
predicted measurement is ``x̂⁻ − u·Δt/2`` (a feed-through D = −Δt/2), which removes that bias
and leaves the covariance recursion — hence K and P — exactly those of eq. 4.9.
"""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.estimation.base import EstimatorError, check_finite, check_step

__all__ = ["ScalarKalmanVz", "steady_state_kalman", "THESIS_Q", "THESIS_R"]

THESIS_Q = 2.8559e-4  # (m/s)² per step, thesis §4.4
THESIS_R = 3.2e-3  # (m/s)² per step, thesis §4.4


def _check_variances(q: float, r: float) -> tuple[float, float]:
    q = check_finite("q", q)
    r = check_finite("r", r)
    if q < 0.0:
        raise EstimatorError(f"q must be >= 0, got {q!r}")
    if r <= 0.0:
        raise EstimatorError(f"r must be > 0, got {r!r}")
    return q, r


def steady_state_kalman(q: float, r: float) -> tuple[float, float]:
    """Steady-state a-priori covariance and gain of the scalar filter (A = C = 1).

    Solves the filter Riccati equation with :func:`scipy.linalg.solve_discrete_are` in its
    filter form (``a = Aᵀ``, ``b = Cᵀ``). For the scalar case the fixed point of
    ``P⁻ = P⁻ − P⁻²/(P⁻ + R) + Q`` is ``P⁻ = (Q + √(Q² + 4QR)) / 2``.

    Parameters
    ----------
    q : float
        Process-noise variance per step, (m/s)², > 0.
    r : float
        Measurement-noise variance, (m/s)², > 0.

    Returns
    -------
    p_prior_ss : float
        Steady-state predicted covariance P⁻, (m/s)².
    k_ss : float
        Steady-state Kalman gain, dimensionless in (0, 1).
    """
    q, r = _check_variances(q, r)
    if q == 0.0:
        raise EstimatorError("q must be > 0 for a steady state (with q = 0 the gain decays to 0)")
    # imported here: a flight never calls this, and scipy.linalg costs a worker ~0.1 s to load
    from scipy.linalg import solve_discrete_are

    one = np.ones((1, 1))
    p = float(solve_discrete_are(one.T, one.T, np.array([[q]]), np.array([[r]]))[0, 0])
    return p, p / (p + r)


class ScalarKalmanVz:
    """Vertical-speed Kalman filter of eq. 4.9 (A = 1, B = Δt, C = 1).

    Parameters
    ----------
    q : float
        Process-noise variance per step, (m/s)², >= 0. Thesis: 2.8559e-4.
    r : float
        Variance of the finite-difference measurement, (m/s)², > 0. Thesis: 3.2e-3.
    p0 : float
        Initial (corrected) covariance, (m/s)², >= 0; also used by :meth:`reset`.
    measurement_at_midpoint : bool, optional
        Model the finite difference as ż at mid-tick (default, unbiased under constant z̈);
        ``False`` is eq. 4.9 to the letter. See the module docstring.

    Attributes
    ----------
    gain : float
        Last Kalman gain K (nan before the first correction).
    covariance : float
        Corrected covariance P, (m/s)².
    vz_mps : float
        Last corrected ż estimate, m/s.
    """

    def __init__(self, q: float, r: float, p0: float, *, measurement_at_midpoint: bool = True):
        self._q, self._r = _check_variances(q, r)
        self._p0 = check_finite("p0", p0)
        if self._p0 < 0.0:
            raise EstimatorError(f"p0 must be >= 0, got {self._p0!r}")
        self._midpoint = bool(measurement_at_midpoint)
        self.reset(0.0, 0.0)

    def reset(self, z_m: float, vz_mps: float = 0.0) -> None:
        """Forget the history: ż̂ = ``vz_mps``, P = p0; the next update only initialises."""
        self._z_m = check_finite("z_m", z_m)
        self._vz = check_finite("vz_mps", vz_mps)
        self._p = self._p0
        self._k = math.nan
        self._initialised = False

    def update(self, z_m: float, zacc_mps2: float, dt_s: float) -> float:
        """One predict/correct step; returns the corrected ż (m/s).

        Parameters
        ----------
        z_m : float
            Newest measured altitude, m.
        zacc_mps2 : float
            z̈ applied over the tick just ended (u1[k−1]), m/s².
        dt_s : float
            Time since the previous update, s, > 0.
        """
        z, u, dt = check_step(z_m, zacc_mps2, dt_s)
        if not self._initialised:
            self._z_m = z
            self._initialised = True
            return self._vz
        y = (z - self._z_m) / dt
        # Prediction (eq. 4.9, lines 1–2).
        vz_prior = self._vz + dt * u
        p_prior = self._p + self._q
        # Correction (lines 3–5); see the module docstring for the mid-tick term.
        y_pred = vz_prior - 0.5 * dt * u if self._midpoint else vz_prior
        k = p_prior / (p_prior + self._r)
        self._vz = vz_prior + k * (y - y_pred)
        self._p = (1.0 - k) * p_prior
        self._k = k
        self._z_m = z
        return self._vz

    @property
    def vz_mps(self) -> float:
        """Last corrected ż estimate, m/s."""
        return self._vz

    @property
    def constants(self) -> tuple[float, float, float, bool]:
        """(q, r, p0, measurement_at_midpoint)."""
        return self._q, self._r, self._p0, self._midpoint

    def state(self) -> tuple[float, float, float, float, bool]:
        """(z anchor, ż, P, K, initialised): what a compiled step carries on from
        (``runtime/tick_kernels.estimate_step``, the same arithmetic)."""
        return self._z_m, self._vz, self._p, self._k, self._initialised

    def set_state(self, z_m: float, vz_mps: float, p: float, k: float,
                  initialised: bool) -> None:
        """Put back a :meth:`state` (after a compiled step carried it on)."""
        self._z_m, self._vz, self._p, self._k = z_m, vz_mps, p, k
        self._initialised = bool(initialised)

    @property
    def z_m(self) -> float:
        """Altitude of the last update (the finite-difference anchor), m."""
        return self._z_m

    @property
    def gain(self) -> float:
        """Last Kalman gain K (nan until the first correction)."""
        return self._k

    @property
    def covariance(self) -> float:
        """Corrected covariance P, (m/s)²."""
        return self._p

    def __repr__(self) -> str:
        return (
            f"ScalarKalmanVz(q={self._q!r}, r={self._r!r}, p0={self._p0!r}, "
            f"measurement_at_midpoint={self._midpoint!r})"
        )
