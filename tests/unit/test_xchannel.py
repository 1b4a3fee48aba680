"""The linearised x channel: gains against scipy's Riccati solver and a closed form, the loop
matrix against a step-by-step simulation, the ZOH against scipy.signal."""

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are
from scipy.signal import cont2discrete

from ardrone_nmpc.core.types import GRAVITY_MPS2
from ardrone_nmpc.experiments.xchannel import (XPlant, closed_loop_matrix, first_step_gain,
                                               spectral_radius, stability_table, verdict)

G = GRAVITY_MPS2


def test_long_horizon_gain_is_the_infinite_horizon_lq_gain():
    dtau, qx, qv, r = 0.1, 12.0, 2.0, 12.0
    a = np.array([[1.0, dtau], [0.0, 1.0]])
    b = np.array([[0.0], [G * dtau]])
    p = solve_discrete_are(a, b, dtau * np.diag([qx, qv]), np.array([[dtau * r]]))
    k_inf = np.linalg.solve(dtau * r + b.T @ p @ b, b.T @ p @ a)
    k = first_step_gain(horizon_steps=400, dtau_s=dtau, q_x=qx, q_v=qv, r_theta=r)
    np.testing.assert_allclose(k, k_inf, rtol=1e-9)


def test_two_step_gain_closed_form():
    """N = 2, no terminal weight: P₁ = Δτ Q, K₀ = (Δτ r + Bᵀ P₁ B)⁻¹ Bᵀ P₁ A by hand."""
    dtau, qx, qv, r = 0.3, 12.0, 2.0, 12.0
    bq = G * dtau  # B = [0, g Δτ]
    # Bᵀ P₁ B = Δτ q_v (g Δτ)²; Bᵀ P₁ A = g Δτ · Δτ q_v · [0, 1]
    denom = dtau * r + dtau * qv * bq * bq
    expected = np.array([[0.0, bq * dtau * qv / denom]])
    k = first_step_gain(horizon_steps=2, dtau_s=dtau, q_x=qx, q_v=qv, r_theta=r)
    np.testing.assert_allclose(k, expected, rtol=1e-12)
    assert np.all(first_step_gain(horizon_steps=1, dtau_s=dtau, q_x=qx, q_v=qv,
                                  r_theta=r) == 0.0)  # one step: x₁ is not weighted


def test_zero_order_hold_matches_scipy():
    plant = XPlant(tau_tilt_s=0.1, tilt_gain=0.8, drag_per_s=0.58, period_s=0.065)
    a, b = plant.discrete()
    ac = np.array([[0, 1, 0], [0, -0.58, 0.8 * G], [0, 0, -10.0]])
    bc = np.array([[0.0], [0.0], [10.0]])
    ad, bd, *_ = cont2discrete((ac, bc, np.eye(3), np.zeros((3, 1))), 0.065, method="zoh")
    np.testing.assert_allclose(a, ad, atol=1e-12)
    np.testing.assert_allclose(b, bd, atol=1e-12)


def test_loop_matrix_equals_a_step_by_step_simulation_with_the_delay_queue():
    plant = XPlant(tilt_gain=0.7)
    k = first_step_gain(horizon_steps=15, dtau_s=0.1, q_x=12, q_v=2, r_theta=12)
    a, b = plant.discrete()
    m = closed_loop_matrix(k, plant)
    d = plant.delay_ticks
    assert d == 4
    s = np.array([0.5, -0.2, 0.05])  # x, v, θ
    queue = [0.0] * d  # commands in flight, oldest first
    z = np.concatenate([s, np.zeros(d)])
    for _ in range(60):
        u_now = float(-k[0, 0] * s[0] - k[0, 1] * s[1])
        s = a @ s + b[:, 0] * queue.pop(0)
        queue.append(u_now)
        z = m @ z
        np.testing.assert_allclose(z[:3], s, atol=1e-12)


def test_issue_figures_and_the_thesis_boundaries():
    """The review's numbers (docs/thesis-reproduction.md): at 0.7× tilt gain Δτ = 0.08 / 0.1
    are unstable and 0.15 stable; N = 5 and 6 at Δτ = 0.3 are equally marginal at 1×."""
    rows = stability_table([(15, 0.08), (15, 0.1), (15, 0.15)], q_x=12, q_v=2, r_theta=12,
                           plants={"k07": XPlant(tilt_gain=0.7)})
    assert [round(r["rho_k07"], 4) for r in rows] == [1.0067, 1.0041, 0.9945]
    rho5 = spectral_radius(horizon_steps=5, dtau_s=0.3, q_x=12, q_v=2, r_theta=12)
    rho6 = spectral_radius(horizon_steps=6, dtau_s=0.3, q_x=12, q_v=2, r_theta=12)
    assert abs(rho5 - rho6) < 2e-3 and abs(rho5 - 1.0) < 2e-3 and abs(rho6 - 1.0) < 2e-3


def test_no_delay_no_lag_loop_is_stable_and_verdicts():
    plant = XPlant(tau_tilt_s=1e-4, delay_s=0.0)
    assert spectral_radius(horizon_steps=15, dtau_s=0.1, q_x=12, q_v=2, r_theta=12,
                           plant=plant) < 1.0
    assert verdict(0.99) == "stable" and verdict(1.01) == "unstable"
    assert verdict(float("nan")) == "unstable"
    with pytest.raises(ValueError):
        first_step_gain(horizon_steps=0, dtau_s=0.1, q_x=1, q_v=1, r_theta=1)


def test_the_predicted_loop_reduces_to_the_plain_loop_without_prediction():
    """Delay compensation 0 and the true velocity: the plain loop's spectrum."""
    from ardrone_nmpc.experiments.xchannel import (XPlant, closed_loop_matrix, first_step_gain,
                                                   predicted_loop_matrix)

    k = first_step_gain(horizon_steps=15, dtau_s=0.1, q_x=12, q_v=2, r_theta=12)
    plant = XPlant(delay_s=0.26)
    plain = np.sort(np.abs(np.linalg.eigvals(closed_loop_matrix(k, plant))))
    mine = np.abs(np.linalg.eigvals(predicted_loop_matrix(k, plant, compensation_s=0.0,
                                                          difference_velocity=False)))
    nonzero = np.sort(mine[mine > 1e-9])
    np.testing.assert_allclose(nonzero, plain[plain > 1e-9], rtol=1e-9)


def test_no_fixed_weights_cover_the_region_and_adaptation_does():
    from ardrone_nmpc.experiments.xchannel import region_table

    thesis, defaults, detuned = region_table()
    assert thesis["worst_fixed"][0] > 1.05 and thesis["worst_adapted"] < 0.97
    assert defaults["worst_fixed"][0] < thesis["worst_fixed"][0]
    assert defaults["worst_fixed"][1:] == (0.4, 2.0, 0.2)  # the hardest corner
    assert detuned["worst_fixed"][0] < 1.0 and defaults["worst_adapted"] < 0.96
