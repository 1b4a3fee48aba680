"""The linearised x channel: gains against scipy's Riccati solver, a closed form and a batch
least-squares solve, the loop matrix against step-by-step simulations (with the delay queue
and an aged velocity), the kit's channel against its printed transfer functions, the ZOH
against scipy.signal, and the linear kit loop against a flight."""

import math

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import expm, solve_discrete_are
from scipy.signal import cont2discrete

from ardrone_nmpc.core.types import GRAVITY_MPS2
from ardrone_nmpc.experiments.xchannel import (KitXPlant, XPlant, closed_loop_matrix,
                                               first_step_gain, first_step_law,
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


# ----------------------------------------------------------------------------- the kit's channel

# the kit's printed transfer functions (docs/plant.md §4), not the backend's state space
TF_PITCH = ([2.5139, 4.8661], [1.0, 3.9784, 11.9184])
TF_PITCH2U = ([-6.1543], [1.0, 0.6650])
TF_GXC = ([-15.47, -29.95], [1.0, 4.643, 14.56, 7.926])  # pitch port → u, as printed


def test_kit_channel_is_the_printed_pitch_to_speed_transfer_function_turned_to_world_signs():
    """θ_cmd (world, nose down +) drives the port with −θ_cmd, and u = Gxc(port): the channel's
    θ_cmd → ẋ response is −ssPitch·ssPitch2U, and −Gxc as printed (to its 4 digits)."""
    a, b = KitXPlant().continuous()
    c = np.array([0.0, 1.0, 0.0, 0.0])
    w = np.logspace(-1, 1.5, 20)
    h_kit = np.array([c @ np.linalg.solve(1j * x * np.eye(4) - a, b[:, 0]) for x in w])
    product = np.polymul(TF_PITCH[0], TF_PITCH2U[0]), np.polymul(TF_PITCH[1], TF_PITCH2U[1])
    _, h_stages = signal.freqs(*product, worN=w)
    _, h_printed = signal.freqs(*TF_GXC, worN=w)
    np.testing.assert_allclose(h_kit, -h_stages, rtol=1e-4)
    np.testing.assert_allclose(h_kit, -h_printed, rtol=2e-3)


def test_kit_zero_order_hold_matches_scipy():
    plant = KitXPlant(period_s=0.065)
    a, b = plant.discrete()
    ac, bc = plant.continuous()
    ad, bd, *_ = cont2discrete((ac, bc, np.eye(4), np.zeros((4, 1))), 0.065, method="zoh")
    np.testing.assert_allclose(a, ad, atol=1e-12)
    np.testing.assert_allclose(b, bd, atol=1e-12)


@pytest.mark.parametrize("plant", [KitXPlant(velocity_age_s=0.03),
                                   XPlant(tilt_gain=0.7, velocity_age_s=0.05),
                                   KitXPlant(velocity_age_s=0.02, delay_s=0.0)],
                         ids=["kit", "ardrone", "kit-no-delay"])
def test_loop_matrix_with_an_aged_velocity_equals_a_simulation_sampling_it_early(plant):
    """The loop matrix against the continuous plant run piecewise (scipy's matrix exponential
    over [t_k, t_{k+1} − a] and [t_{k+1} − a, t_{k+1}]), the velocity read at t_{k+1} − a."""
    k = first_step_gain(horizon_steps=15, dtau_s=0.1, q_x=12, q_v=2, r_theta=12)
    ac, bc = plant.continuous()
    n, age, period = ac.shape[0], plant.velocity_age_s, plant.period_s

    def run(s, u, t):
        m = np.zeros((n + 1, n + 1))
        m[:n, :n], m[:n, n:] = ac, bc
        e = expm(m * t)
        return e[:n, :n] @ s + e[:n, n] * u

    d = plant.delay_ticks
    s = np.zeros(n)
    s[0], s[1] = 0.5, -0.2
    queue = [0.0] * d
    v_meas = (expm(-ac * age) @ s)[1]  # before tick 0 no command acted: free motion
    z = np.zeros(closed_loop_matrix(k, plant).shape[0])
    z[:n] = s
    m = closed_loop_matrix(k, plant)
    for _ in range(60):
        u_now = float(-k[0, 0] * s[0] - k[0, 1] * v_meas)
        queue.append(u_now)
        applied = queue.pop(0)
        early = run(s, applied, period - age)
        v_meas = early[1]
        s = run(early, applied, age)
        z = m @ z
        np.testing.assert_allclose(z[:n], s, atol=1e-10)


def test_first_step_law_is_the_batch_least_squares_optimum_with_the_preview():
    """The recursion's (K₀, F) against the horizon's quadratic program solved in one piece:
    the inputs minimising the Euler-discretised stage costs for a reference that steps inside
    the horizon, by numpy's least squares."""
    n_h, dtau, qx, qv, r = 15, 0.1, 12.0, 2.0, 12.0
    k0, f = first_step_law(horizon_steps=n_h, dtau_s=dtau, q_x=qx, q_v=qv, r_theta=r)
    assert f.sum() == pytest.approx(k0[0, 0], rel=1e-12)
    a = np.array([[1.0, dtau], [0.0, 1.0]])
    b = np.array([0.0, G * dtau])
    x0 = np.array([0.3, -0.1])
    ref = np.where(np.arange(1, n_h + 1) >= 6, -1.0, 0.0)  # stages 1 … N
    # x_j = A^j x0 + Σ_{i<j} A^{j−1−i} B u_i; cost Σ_{j=1}^{N−1} Δτ q (x_j − r_j)² + Σ Δτ r u²
    rows, rhs = [], []
    for j in range(1, n_h):
        aj = np.linalg.matrix_power(a, j)
        g = np.zeros((2, n_h))
        for i in range(j):
            g[:, i] = np.linalg.matrix_power(a, j - 1 - i) @ b
        free = aj @ x0 - np.array([ref[j - 1], 0.0])
        for w, row in zip((qx, qv), range(2)):
            rows.append(math.sqrt(dtau * w) * g[row])
            rhs.append(-math.sqrt(dtau * w) * free[row])
    rows += list(math.sqrt(dtau * r) * np.eye(n_h))
    rhs += [0.0] * n_h
    u = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]
    assert u[0] == pytest.approx(float(-k0[0] @ x0 + f[0] @ ref), rel=1e-9)


def test_half_a_tick_of_velocity_age_removes_the_lower_gain_delta_tau_boundary():
    """The issue's figure: at 0.7× tilt gain Δτ = 0.15 s is stable with a fresh ẋ and
    unstable with a 32.5 ms old one; on the kit every case stays stable."""
    rows = stability_table([(15, 0.15)], q_x=12, q_v=2, r_theta=12,
                           plants={"fresh": XPlant(tilt_gain=0.7),
                                   "aged": XPlant(tilt_gain=0.7, velocity_age_s=0.0325),
                                   "kit": KitXPlant(velocity_age_s=0.0325)})
    assert verdict(rows[0]["rho_fresh"]) == "stable"
    assert verdict(rows[0]["rho_aged"]) == "unstable"
    assert verdict(rows[0]["rho_kit"]) == "stable"


def test_the_linear_kit_loop_predicts_a_small_flown_step(tmp_path):
    """A 0.1 m x step flown on thesis_kit in the thesis formulation with the converged Newton
    solver (the law the linearisation is) follows the linear loop at its mean navdata age
    within 6 % of the step (the report's small-signal check measures it)."""
    from pathlib import Path

    from ardrone_nmpc.experiments.reproduce.xloop import small_step_checks

    checks = {c.solver: c for c in small_step_checks(Path("configs"), tmp_path, 0)}
    assert checks["newton"].max_error_frac < 0.06 and checks["newton"].theta_peak_rad < 0.1
    assert 0.0 < checks["newton"].age_s < 0.065


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
