"""Vertical-speed estimators of thesis ch. 4: Kalman filter, Luenberger observer, differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm

from ardrone_nmpc.estimation import (
    BackwardDifference,
    EstimatorError,
    FiniteDifferenceVz,
    LuenbergerVz,
    ScalarKalmanVz,
    VerticalSpeedEstimator,
    make_vz_estimator,
    observer_gain,
    steady_state_kalman,
)
from ardrone_nmpc.estimation.kalman import THESIS_Q, THESIS_R
from ardrone_nmpc.estimation.luenberger import observer_matrix

DT = 0.065


def exact_trajectory(z0, v0, accels, dts):
    """Samples (z[k], ż[k]) of ż' = u with u piecewise constant: exactly the estimators' model."""
    z, v = [z0], [v0]
    for a, dt in zip(accels, dts):
        z.append(z[-1] + v[-1] * dt + 0.5 * a * dt * dt)
        v.append(v[-1] + a * dt)
    return np.array(z), np.array(v)


# --------------------------------------------------------------------------- Kalman filter
class TestSteadyStateKalman:
    @pytest.mark.parametrize("q,r", [(THESIS_Q, THESIS_R), (1e-3, 1e-3), (1e-6, 1.0), (5.0, 0.1)])
    def test_matches_scalar_riccati_closed_form(self, q, r):
        p_prior, k = steady_state_kalman(q, r)
        closed = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
        assert p_prior == pytest.approx(closed, rel=1e-9)
        # ... which is the fixed point of P⁻ ← P⁻ − P⁻²/(P⁻ + R) + Q.
        assert p_prior - p_prior**2 / (p_prior + r) + q == pytest.approx(p_prior, rel=1e-9)
        assert k == pytest.approx(closed / (closed + r), rel=1e-9)

    def test_thesis_values(self):
        _, k = steady_state_kalman(THESIS_Q, THESIS_R)
        assert k == pytest.approx(0.2574, abs=5e-4)  # mostly trusts the model, as §4.4 says

    def test_zero_q_has_no_steady_state(self):
        with pytest.raises(EstimatorError, match="q must be > 0"):
            steady_state_kalman(0.0, 1.0)


class TestScalarKalman:
    @pytest.mark.parametrize("p0", [0.0, 1e-2, 10.0])
    def test_gain_and_covariance_converge_to_dare(self, p0):
        kf = ScalarKalmanVz(THESIS_Q, THESIS_R, p0)
        p_prior_ss, k_ss = steady_state_kalman(THESIS_Q, THESIS_R)
        kf.reset(0.0)
        kf.update(0.0, 0.0, DT)
        assert math.isnan(kf.gain)  # first call only initialises
        for _ in range(200):
            kf.update(0.0, 0.0, DT)
        assert kf.gain == pytest.approx(k_ss, rel=1e-10)
        assert kf.covariance == pytest.approx((1.0 - k_ss) * p_prior_ss, rel=1e-10)

    def test_first_gain_is_eq_4_9(self):
        kf = ScalarKalmanVz(0.1, 0.3, 0.5)
        kf.update(1.0, 0.0, DT)
        kf.update(1.0, 0.0, DT)
        assert kf.gain == pytest.approx(0.6 / 0.9)
        assert kf.covariance == pytest.approx((1 - 0.6 / 0.9) * 0.6)

    @given(
        st.lists(st.floats(-3.0, 3.0), min_size=5, max_size=60),
        st.floats(-1.0, 1.0),
        st.floats(-2.0, 2.0),
    )
    def test_exact_data_tracks_vz_with_zero_error(self, accels, z0, v0):
        z, v = exact_trajectory(z0, v0, accels, [DT] * len(accels))
        kf = ScalarKalmanVz(THESIS_Q, THESIS_R, 1e-2)
        kf.reset(z[0], v[0])
        assert kf.update(z[0], 0.0, DT) == v[0]
        for k, a in enumerate(accels, start=1):
            assert kf.update(z[k], a, DT) == pytest.approx(v[k], abs=1e-9)

    def test_initial_error_decays_by_one_minus_gain(self):
        accels = [1.0] * 40
        z, v = exact_trajectory(0.0, 0.0, accels, [DT] * 40)
        kf = ScalarKalmanVz(THESIS_Q, THESIS_R, 1e-2)
        kf.reset(z[0], 0.5)  # 0.5 m/s wrong
        kf.update(z[0], 0.0, DT)
        err = 0.5
        for k, a in enumerate(accels, start=1):
            est = kf.update(z[k], a, DT)
            err *= 1.0 - kf.gain
            assert est - v[k] == pytest.approx(err, abs=1e-12)

    def test_literal_eq_4_9_lags_half_a_tick(self):
        # With C = 1 the difference (= ż at mid-tick) pulls the estimate u·Δt/2 low.
        a = 2.0
        z, v = exact_trajectory(0.0, 0.0, [a] * 400, [DT] * 400)
        kf = ScalarKalmanVz(THESIS_Q, THESIS_R, 1e-2, measurement_at_midpoint=False)
        kf.reset(z[0])
        kf.update(z[0], 0.0, DT)
        for k in range(1, 401):
            est = kf.update(z[k], a, DT)
        assert est - v[-1] == pytest.approx(-a * DT / 2, rel=1e-6)

    def test_variance_reduction_against_finite_difference(self):
        rng = np.random.default_rng(20190501)
        n = 20000
        sigma_m = 2.6e-3  # gives the thesis' R = 2σ²/Δt² = 3.2e-3
        assert 2 * sigma_m**2 / DT**2 == pytest.approx(THESIS_R, rel=0.01)
        accels = np.repeat(rng.uniform(-1.0, 1.0, n // 20), 20)  # piecewise-constant z̈
        z, v = exact_trajectory(1.0, 0.0, accels, [DT] * n)
        z_meas = z + rng.normal(0.0, sigma_m, z.shape)

        kf = ScalarKalmanVz(THESIS_Q, THESIS_R, 1e-2)
        fd = FiniteDifferenceVz()
        kf.reset(z_meas[0], 0.0)
        fd.reset(z_meas[0])
        kf.update(z_meas[0], 0.0, DT)
        fd.update(z_meas[0], 0.0, DT)
        kf_err, fd_err = [], []
        for k in range(1, n + 1):
            kf_err.append(kf.update(z_meas[k], accels[k - 1], DT) - v[k])
            # Fair to the difference: compare it with ż at mid-tick, where it is unbiased.
            fd_err.append(fd.update(z_meas[k], 0.0, DT) - (v[k] - 0.5 * accels[k - 1] * DT))
        skip = 100
        rmse_kf = math.sqrt(np.mean(np.square(kf_err[skip:])))
        rmse_fd = math.sqrt(np.mean(np.square(fd_err[skip:])))
        assert rmse_fd == pytest.approx(math.sqrt(2) * sigma_m / DT, rel=0.03)
        assert rmse_kf < 0.3 * rmse_fd
        # Steady filter driven by differenced white noise: var ratio = K²/(2 − K).
        _, k_ss = steady_state_kalman(THESIS_Q, THESIS_R)
        assert rmse_kf / rmse_fd == pytest.approx(k_ss / math.sqrt(2 - k_ss), rel=0.05)

    @pytest.mark.parametrize("q,r,p0,match", [(-1, 1, 1, "q must"), (1, 0, 1, "r must"),
                                              (1, 1, -1, "p0 must"), (math.nan, 1, 1, "q must")])
    def test_bad_parameters(self, q, r, p0, match):
        with pytest.raises(EstimatorError, match=match):
            ScalarKalmanVz(q, r, p0)


# ----------------------------------------------------------------------- Luenberger observer
class TestLuenberger:
    def test_thesis_gain(self):
        assert observer_gain(5.0) == (10.0, 25.0)
        assert LuenbergerVz().gain == (10.0, 25.0)

    @given(st.floats(0.1, 50.0))
    def test_double_pole_at_minus_lambda0(self, lam):
        f = observer_matrix(observer_gain(lam))
        # Compare characteristic polynomials: a double root's eigenvalues are ill-conditioned.
        np.testing.assert_allclose(np.poly(f), np.poly([-lam, -lam]), rtol=1e-12)

    @given(st.floats(0.5, 20.0), st.floats(0.005, 0.5))
    def test_discrete_transition_eigenvalues(self, lam, dt):
        obs = LuenbergerVz(lam)
        phi, *_ = obs.discrete_matrices(dt)
        rho = math.exp(-lam * dt)
        assert np.trace(phi) == pytest.approx(2 * rho, rel=1e-9)
        assert np.linalg.det(phi) == pytest.approx(rho * rho, rel=1e-9)
        f = observer_matrix(observer_gain(lam))
        np.testing.assert_allclose(phi, expm(f * dt), rtol=1e-10, atol=1e-14)

    @settings(max_examples=50)
    @given(
        st.lists(st.tuples(st.floats(-3.0, 3.0), st.floats(0.02, 0.12)), min_size=3, max_size=80),
        st.floats(-1.0, 1.0),
        st.floats(0.5, 12.0),
    )
    def test_error_decays_like_closed_form(self, steps, delta_mps, lam):
        # Noise-free data from the model (any piecewise-constant z̈, jittery Δt): the error obeys
        # x̃' = (A − KC) x̃, whose double-pole solution from x̃0 = [0, δ] is
        # x̃(t) = δ e^{−λt} [t, 1 + λt].
        accels = [a for a, _ in steps]
        dts = [dt for _, dt in steps]
        z, v = exact_trajectory(1.0, 0.3, accels, dts)
        obs = LuenbergerVz(lam)
        obs.reset(z[0], v[0] + delta_mps)
        obs.update(z[0], 0.0, 0.065)
        t = 0.0
        for k, (a, dt) in enumerate(steps, start=1):
            t += dt
            est = obs.update(z[k], a, dt)
            decay = math.exp(-lam * t)
            assert est - v[k] == pytest.approx(delta_mps * (1 + lam * t) * decay, abs=1e-9)
            assert obs.z_m - z[k] == pytest.approx(delta_mps * t * decay, abs=1e-9)

    def test_ramp_and_parabola_tracked_exactly(self):
        for a in (0.0, 1.5):
            z, v = exact_trajectory(0.0, 1.0, [a] * 100, [DT] * 100)
            obs = LuenbergerVz()
            obs.reset(z[0], v[0])
            obs.update(z[0], 0.0, DT)
            errs = [obs.update(z[k], a, DT) - v[k] for k in range(1, 101)]
            assert max(map(abs, errs)) < 1e-10

    def test_zoh_measurement_hold_is_biased(self):
        # Documents why "model" is the default: holding z[k] over the tick biases ż.
        a = 1.0
        z, v = exact_trajectory(1.0, 0.3, [a] * 200, [DT] * 200)
        obs = LuenbergerVz(measurement_hold="zoh")
        obs.reset(z[0], v[0])
        obs.update(z[0], 0.0, DT)
        for k in range(1, 201):
            est = obs.update(z[k], a, DT)
        assert est - v[-1] == pytest.approx(-0.0836, abs=1e-3)

    def test_constant_dt_is_cached(self):
        obs = LuenbergerVz(gain=(11.0, 31.0))  # (a gain of its own: the cache is the process')
        obs.update(0.0, 0.0, DT)
        for k in range(50):
            obs.update(0.01 * k, 0.0, DT)
        assert len(obs._cache) == 1
        for k in range(100):
            obs.update(0.0, 0.0, 0.06 + 1e-5 * k)
        assert len(obs._cache) <= 32

    def test_the_cache_is_shared_by_one_gain_s_observers_and_bounded(self, monkeypatch):
        from collections import OrderedDict

        from ardrone_nmpc.estimation import luenberger

        monkeypatch.setattr(luenberger, "_SHARED_CACHES", OrderedDict())
        a, b = LuenbergerVz(gain=(10.0, 25.0)), LuenbergerVz(gain=(10.0, 25.0))
        zoh = LuenbergerVz(gain=(10.0, 25.0), measurement_hold="zoh")
        assert a._cache is b._cache and zoh._cache is not a._cache
        assert a.coefficients(DT) == b.cached_coefficients()[0][1]
        assert zoh.coefficients(DT) != a.coefficients(DT)  # (a key of its own)
        for k in range(luenberger._SHARED_GAINS):  # a tune's gains: the oldest forgotten
            LuenbergerVz(gain=(1.0 + k, 1.0))
        assert len(luenberger._SHARED_CACHES) == luenberger._SHARED_GAINS
        assert a._cache is not LuenbergerVz(gain=(10.0, 25.0))._cache
        assert a.coefficients(DT) == LuenbergerVz(gain=(10.0, 25.0)).coefficients(DT)

    @pytest.mark.parametrize("gain", [(-10.0, 25.0), (10.0, 0.0), (10.0, -25.0), (0.0, 25.0)])
    def test_non_hurwitz_gain_rejected(self, gain):
        with pytest.raises(ValueError, match="Hurwitz"):
            LuenbergerVz(gain=gain)

    @pytest.mark.parametrize("lam", [0.0, -5.0, math.inf])
    def test_bad_lambda_rejected(self, lam):
        with pytest.raises(ValueError, match="lambda0_per_s"):
            LuenbergerVz(lam)

    def test_explicit_gain_overrides_lambda(self):
        assert LuenbergerVz(5.0, gain=[4.0, 4.0]).gain == (4.0, 4.0)


# ------------------------------------------------------------------------ shared contract
ESTIMATORS = [
    lambda: ScalarKalmanVz(THESIS_Q, THESIS_R, 1e-2),
    lambda: LuenbergerVz(),
    lambda: FiniteDifferenceVz(),
]
IDS = ["kalman", "luenberger", "difference"]


@pytest.mark.parametrize("make", ESTIMATORS, ids=IDS)
class TestContract:
    def test_is_protocol(self, make):
        assert isinstance(make(), VerticalSpeedEstimator)

    def test_first_update_only_initialises(self, make):
        est = make()
        assert est.update(5.0, 100.0, DT) == 0.0
        est.reset(1.0, 0.7)
        assert est.update(3.0, 100.0, DT) == 0.7  # no jump from the 2 m between reset and update
        assert est.vz_mps == 0.7
        assert est.update(3.0 + 0.7 * DT, 0.0, DT) == pytest.approx(0.7, abs=1e-9)

    @pytest.mark.parametrize("dt", [0.0, -0.065])
    def test_nonpositive_dt_rejected(self, make, dt):
        est = make()
        est.update(1.0, 0.0, DT)
        with pytest.raises(EstimatorError, match="dt_s must be > 0"):
            est.update(1.0, 0.0, dt)

    @pytest.mark.parametrize(
        "args,field",
        [
            ((math.nan, 0.0, DT), "z_m"),
            ((1.0, math.inf, DT), "zacc_mps2"),
            ((1.0, 0.0, math.nan), "dt_s"),
        ],
    )
    def test_non_finite_rejected_and_state_kept(self, make, args, field):
        est = make()
        est.reset(1.0, 0.2)
        est.update(1.0, 0.0, DT)
        with pytest.raises(EstimatorError, match=field):
            est.update(*args)
        assert est.vz_mps == 0.2
        assert est.update(1.0 + 0.2 * DT, 0.0, DT) == pytest.approx(0.2, abs=1e-9)

    def test_reset_rejects_nan(self, make):
        with pytest.raises(EstimatorError, match="vz_mps"):
            make().reset(0.0, math.nan)


def test_finite_difference_value():
    fd = FiniteDifferenceVz()
    fd.update(1.0, 0.0, 0.1)
    assert fd.update(1.05, 9.0, 0.1) == pytest.approx(0.5)
    assert fd.update(1.05, 0.0, 0.05) == 0.0


class TestBackwardDifference:
    def test_vector_velocity(self):
        bd = BackwardDifference()
        assert bd.update([1.0, 2.0, 3.0], DT) == (0.0, 0.0, 0.0)
        vel = bd.update([1.0 + 0.065, 2.0 - 0.13, 3.0], DT)
        assert vel == pytest.approx((1.0, -2.0, 0.0))
        assert bd.velocity_mps == vel
        bd.reset()
        assert bd.update([0.0, 0.0, 0.0], DT) == (0.0, 0.0, 0.0)

    def test_bad_inputs(self):
        bd = BackwardDifference(2)
        bd.update([0.0, 0.0], DT)
        with pytest.raises(EstimatorError, match="2 entries"):
            bd.update([0.0, 0.0, 0.0], DT)
        with pytest.raises(EstimatorError, match=r"position_m\[1\]"):
            bd.update([0.0, math.nan], DT)
        with pytest.raises(EstimatorError, match="dt_s"):
            bd.update([0.1, 0.0], 0.0)
        assert bd.update([0.1, 0.0], 0.1) == pytest.approx((1.0, 0.0))
        with pytest.raises(EstimatorError, match="size"):
            BackwardDifference(0)


class TestFactory:
    def test_kinds(self):
        kw = dict(kalman_q=1e-3, kalman_r=2e-3, kalman_p0=0.5, lambda0_per_s=3.0, gain=None)
        kf = make_vz_estimator("kalman", **kw)
        assert isinstance(kf, ScalarKalmanVz)
        kf.update(0.0, 0.0, DT)
        kf.update(0.0, 0.0, DT)
        assert kf.gain == pytest.approx(0.501 / 0.503)  # q, r, p0 were passed through
        obs = make_vz_estimator("luenberger", **kw)
        assert isinstance(obs, LuenbergerVz) and obs.gain == (6.0, 9.0)
        assert make_vz_estimator("luenberger", **{**kw, "gain": (10.0, 25.0)}).gain == (10.0, 25.0)
        assert isinstance(make_vz_estimator("difference", **kw), FiniteDifferenceVz)

    def test_keyword_only(self):
        with pytest.raises(TypeError):
            make_vz_estimator("kalman", 1e-3)  # type: ignore[misc]

    def test_unknown_kind(self):
        with pytest.raises(ValueError, match="unknown vz estimator kind 'ekf'"):
            make_vz_estimator("ekf")


def test_none_estimator_reports_zero_whatever_the_motion():
    est = make_vz_estimator("none")
    est.reset(1.0)
    assert [est.update(1.0 + 0.1 * k, 2.0, 0.065) for k in range(5)] == [0.0] * 5
    with pytest.raises(EstimatorError):
        est.update(1.0, 0.0, 0.0)
