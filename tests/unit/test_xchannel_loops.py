"""The x channel's gains, step responses and predicted loop against independent computations:
the horizon's quadratic program with terminal weights solved by least squares, a tick-by-tick
simulation of the continuous plant (scipy's matrix exponential) with the command queue, the
preview of the reference and the tick's delay prediction (docs/solver-notes.md §10), and the
verdict's and tables' definitions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm

from ardrone_nmpc.core.types import GRAVITY_MPS2
from ardrone_nmpc.experiments.xchannel import (
    KitXPlant,
    XPlant,
    closed_loop_matrix,
    first_step_gain,
    first_step_law,
    predicted_loop_matrix,
    region_table,
    spectral_radius,
    stability_table,
    step_response,
    verdict,
)

G = GRAVITY_MPS2


def _qp_first_input(x0, ref, *, n_h, dtau, qx, qv, r, qfx=0.0, qfv=0.0) -> float:
    """The first input minimising Σ_{j=1}^{N−1} Δτ(q_x e_x² + q_v v²) + q_f,x e_x,N² + q_f,v v_N²
    + Σ_{i<N} Δτ r u_i² over the Euler model ẍ = g u, by least squares (e_x = x_j − ref_j)."""
    a = np.array([[1.0, dtau], [0.0, 1.0]])
    b = np.array([0.0, G * dtau])
    rows, rhs = [], []
    for j in range(1, n_h + 1):
        g = np.zeros((2, n_h))
        for i in range(j):
            g[:, i] = np.linalg.matrix_power(a, j - 1 - i) @ b
        free = np.linalg.matrix_power(a, j) @ x0 - np.array([ref[j - 1], 0.0])
        weights = (dtau * qx, dtau * qv) if j < n_h else (qfx, qfv)
        for w, row in zip(weights, range(2)):
            rows.append(math.sqrt(w) * g[row])
            rhs.append(-math.sqrt(w) * free[row])
    rows += list(math.sqrt(dtau * r) * np.eye(n_h))
    rhs += [0.0] * n_h
    return float(np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0][0])


@pytest.mark.parametrize("n_h, dtau, qfx, qfv", [(1, 0.1, 5.0, 3.0), (2, 0.3, 40.0, 0.0),
                                                 (3, 0.2, 0.0, 7.0), (8, 0.1, 25.0, 4.0)])
def test_terminal_weights_enter_the_gain_as_the_quadratic_program_says(n_h, dtau, qfx, qfv):
    qx, qv, r = 12.0, 2.0, 12.0
    k = first_step_gain(horizon_steps=n_h, dtau_s=dtau, q_x=qx, q_v=qv, r_theta=r,
                        qf_x=qfx, qf_v=qfv)
    zero = np.zeros(n_h)
    for x0 in (np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.4, -0.3])):
        u0 = _qp_first_input(x0, zero, n_h=n_h, dtau=dtau, qx=qx, qv=qv, r=r, qfx=qfx, qfv=qfv)
        assert float(-k[0] @ x0) == pytest.approx(u0, rel=1e-9, abs=1e-12)
    assert k.shape == (1, 2) and k[0, 1] > 0.0   # (N = 1: x₁ does not depend on u₀)


@pytest.mark.parametrize("bad", [dict(horizon_steps=0, dtau_s=0.1),
                                 dict(horizon_steps=-3, dtau_s=0.1),
                                 dict(horizon_steps=5, dtau_s=0.0),
                                 dict(horizon_steps=5, dtau_s=-0.1),
                                 dict(horizon_steps=5, dtau_s=math.nan)])
def test_a_horizon_of_no_steps_or_no_length_is_refused(bad):
    with pytest.raises(ValueError, match="^horizon_steps must be ≥ 1 and dtau_s > 0$"):
        first_step_gain(q_x=1.0, q_v=1.0, r_theta=1.0, **bad)


@pytest.mark.parametrize("n_h, step_at", [(2, 1), (6, 3), (15, 1), (15, 9)])
def test_the_preview_is_the_quadratic_programs_answer_to_any_reference(n_h, step_at):
    dtau, qx, qv, r = 0.1, 12.0, 2.0, 12.0
    k0, f = first_step_law(horizon_steps=n_h, dtau_s=dtau, q_x=qx, q_v=qv, r_theta=r)
    assert f.shape == (1, n_h)
    rng = np.random.default_rng(n_h)
    for ref in (np.where(np.arange(1, n_h + 1) >= step_at, 0.7, 0.0), rng.normal(size=n_h)):
        x0 = np.array([0.2, 0.1])
        u0 = _qp_first_input(x0, ref, n_h=n_h, dtau=dtau, qx=qx, qv=qv, r=r)
        assert float(-k0[0] @ x0 + f[0] @ ref) == pytest.approx(u0, rel=1e-9, abs=1e-12)


def _run(ac, bc, s, u, t):
    """The continuous plant from ``s`` over ``t`` with the input ``u`` held."""
    n = ac.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n], m[:n, n:] = ac, bc
    e = expm(m * t)
    return e[:n, :n] @ s + e[:n, n] * u


def _simulated_step(law, plant, *, dtau_s, step_m, step_s, ticks):
    """x at each tick of the loop run tick by tick: the command −K₀[x, v_meas] + F·preview
    (the references at the horizon's stage times from now), queued ``delay_ticks`` periods,
    the velocity read ``velocity_age_s`` before the tick."""
    k0, f = law
    ac, bc = plant.continuous()
    s = np.zeros(ac.shape[0])
    queue = [0.0] * plant.delay_ticks
    v_meas, out = 0.0, []
    stages_s = dtau_s * np.arange(1, f.shape[1] + 1)
    for i in range(ticks + 1):
        out.append(s[0])
        preview = np.where(i * plant.period_s + stages_s >= step_s - 1e-9, step_m, 0.0)
        queue.append(float(-k0[0, 0] * s[0] - k0[0, 1] * v_meas + f[0] @ preview))
        applied = queue.pop(0)
        early = _run(ac, bc, s, applied, plant.period_s - plant.velocity_age_s)
        s = _run(ac, bc, early, applied, plant.velocity_age_s)
        v_meas = early[1]
    return np.array(out)


@pytest.mark.parametrize("plant", [XPlant(tilt_gain=0.8), XPlant(delay_s=0.0),
                                   KitXPlant(), KitXPlant(delay_s=0.0),
                                   XPlant(velocity_age_s=0.03), KitXPlant(velocity_age_s=0.02),
                                   XPlant(delay_s=0.0, velocity_age_s=0.03)],
                         ids=["ardrone", "ardrone-no-delay", "kit", "kit-no-delay",
                              "ardrone-aged", "kit-aged", "ardrone-aged-no-delay"])
@pytest.mark.parametrize("step_s", [0.0, 0.7])
def test_the_step_response_is_the_loop_run_tick_by_tick(plant, step_s):
    law = first_step_law(horizon_steps=15, dtau_s=0.1, q_x=12.0, q_v=2.0, r_theta=12.0)
    got = step_response(law, plant, dtau_s=0.1, step_m=0.3, step_s=step_s, ticks=90)
    want = _simulated_step(law, plant, dtau_s=0.1, step_m=0.3, step_s=step_s, ticks=90)
    assert got.shape == (91,)
    np.testing.assert_allclose(got, want, atol=1e-10)
    assert np.max(np.abs(want)) > 0.05   # the step was flown


def _simulated_predicted_loop(gain, plant: XPlant, *, compensation_s, difference_velocity,
                              s0, ticks):
    """The tick as docs/solver-notes.md §10 describes it, step by step: x measured, ẋ from the
    backward difference of x (or the true ẋ), the state run forward through the last
    ceil(compensation / T) commands by ẍ = g θ held per tick, θ = −K x_pred; the plant's
    command changes ``delay_s`` after the tick computed it (within a tick when the delay is
    not whole ticks)."""
    t = plant.period_s
    ac, bc = plant.continuous()
    nc = math.ceil(compensation_s / t - 1e-9)
    s, x_prev = np.array(s0, float), float(s0[0])
    sent: list[tuple[float, float]] = []   # (time it acts from, command)
    out = []
    for k in range(ticks):
        now = k * t
        out.append(s.copy())
        v = (s[0] - x_prev) / t if difference_velocity else s[1]
        x_pred, v_pred = s[0], v
        history = [0.0] * nc + [u for _, u in sent]   # no command before the first tick
        for u in history[len(history) - nc:]:
            x_pred += v_pred * t + G * u * t * t / 2.0
            v_pred += G * u * t
        sent.append((now + plant.delay_s, float(-gain[0, 0] * x_pred - gain[0, 1] * v_pred)))
        x_prev = s[0]
        # integrate over [now, now + t] with the command in force at each moment
        edges = sorted({now, now + t} | {a for a, _ in sent if now < a < now + t})
        for lo, hi in zip(edges[:-1], edges[1:]):
            acting = [u for a, u in sent if a <= lo + 1e-12]
            s = _run(ac, bc, s, acting[-1] if acting else 0.0, hi - lo)
    return np.array(out)


@pytest.mark.parametrize("delay_s, compensation_s, difference", [
    (0.26, 0.26, True), (0.2, 0.2, True), (0.1, 0.26, False), (0.0, 0.13, True),
    (0.4, 0.0, False), (0.03, 0.065, True)])
def test_the_predicted_loop_matrix_is_the_tick_run_step_by_step(delay_s, compensation_s,
                                                                difference):
    k = first_step_gain(horizon_steps=15, dtau_s=0.1, q_x=4.0, q_v=0.5, r_theta=48.0)
    plant = XPlant(tau_tilt_s=0.12, tilt_gain=0.9, drag_per_s=0.5, delay_s=delay_s)
    m = predicted_loop_matrix(k, plant, compensation_s=compensation_s,
                              difference_velocity=difference)
    s0 = np.array([0.5, -0.1, 0.02])
    want = _simulated_predicted_loop(k, plant, compensation_s=compensation_s,
                                     difference_velocity=difference, s0=s0, ticks=50)
    z = np.zeros(m.shape[0])
    z[:3], z[3] = s0, s0[0]   # at rest before: the previous x is this one
    for k_tick in range(50):
        np.testing.assert_allclose(z[:3], want[k_tick], atol=1e-10)
        z = m @ z


def test_verdicts_and_their_tolerance():
    assert verdict(0.998) == "stable" and verdict(0.9995) == "marginal"
    assert verdict(1.0) == "marginal" and verdict(1.0009) == "marginal"
    assert verdict(1.0011) == "unstable" and verdict(0.9989) == "stable"
    assert verdict(math.inf) == "unstable" and verdict(math.nan) == "unstable"
    assert verdict(0.95, tol=0.1) == "marginal" and verdict(1.05, tol=0.01) == "unstable"
    assert verdict(0.95, tol=0.01) == "stable"
    # "within tol of 1" includes both edges
    assert verdict(1.0 - 1e-3) == "marginal" and verdict(1.0 + 1e-3) == "marginal"
    assert verdict(0.9, tol=0.1) == "marginal" and verdict(1.1, tol=0.1) == "marginal"


@pytest.mark.parametrize("delay_s, ticks", [(0.26, 4), (0.29, 4), (0.30, 5), (0.03, 0),
                                            (0.0, 0), (0.033, 1)])
def test_the_delay_is_rounded_to_whole_periods(delay_s, ticks):
    assert XPlant(delay_s=delay_s).delay_ticks == ticks
    assert KitXPlant(delay_s=delay_s).delay_ticks == ticks


def test_a_fresh_velocity_is_the_state_velocity():
    c_s, c_u = XPlant().velocity_row()
    assert list(c_s) == [0.0, 1.0, 0.0] and list(c_u) == [0.0]
    c_s, c_u = KitXPlant().velocity_row()
    assert list(c_s) == [0.0, 1.0, 0.0, 0.0] and list(c_u) == [0.0]


def test_the_stability_table_is_each_cases_gain_and_radius():
    plants = {"a": XPlant(tilt_gain=0.7), "b": KitXPlant(velocity_age_s=0.03)}
    rows = stability_table([(15, 0.1), (6, 0.3)], q_x=12.0, q_v=2.0, r_theta=12.0,
                           plants=plants)
    for row, (n, dtau) in zip(rows, [(15, 0.1), (6, 0.3)]):
        k = first_step_gain(horizon_steps=n, dtau_s=dtau, q_x=12.0, q_v=2.0, r_theta=12.0)
        assert (row["N"], row["dtau_s"]) == (n, dtau)
        assert (row["k_x"], row["k_v"]) == (float(k[0, 0]), float(k[0, 1]))
        for name, plant in plants.items():
            eig = np.linalg.eigvals(closed_loop_matrix(k, plant))
            assert row[f"rho_{name}"] == pytest.approx(float(np.max(np.abs(eig))), rel=1e-12)
            assert row[f"rho_{name}"] == pytest.approx(
                spectral_radius(horizon_steps=n, dtau_s=dtau, q_x=12.0, q_v=2.0, r_theta=12.0,
                                plant=plant), rel=1e-12)


def _rho(k, plant, comp):
    m = predicted_loop_matrix(k, plant, compensation_s=comp, difference_velocity=True)
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def test_the_region_table_is_the_worst_corner_with_and_without_adaptation():
    weights = ((12.0, 2.0, 12.0), (4.0, 0.5, 48.0))
    delays, gains, lags = (0.0, 0.3), (0.7, 1.6), (0.08,)
    rows = region_table(weights, delays_s=delays, gains=gains, lags_s=lags, prior_s=0.2)
    assert len(rows) == 2
    for row, (qx, qv, r) in zip(rows, weights):
        k = first_step_gain(horizon_steps=15, dtau_s=0.1, q_x=qx, q_v=qv, r_theta=r)
        assert row["weights"] == (qx, qv, r)
        assert row["K"] == (float(k[0, 0]), float(k[0, 1]))
        corners = [(_rho(k, XPlant(lag, g, 0.58, d), 0.2), d, g, lag)
                   for d in delays for g in gains for lag in lags]
        assert row["worst_fixed"] == max(corners)
        assert row["worst_adapted"] == max(_rho(k, XPlant(lag, 1.0, 0.58, d), d)
                                           for d in delays for lag in lags)
        assert row["nominal"] == _rho(k, XPlant(), 0.2)
