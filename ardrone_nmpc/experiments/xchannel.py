"""The x channel linearised at hover: the NMPC's first-step gain and its closed-loop spectral radius.

Why: the thesis reports that N = 5 (Δτ = 0.3 s) diverges where N = 6 holds, and that Δτ = 0.08 s
is worse than Δτ ≥ 0.1 s. Simulated flights of a limit-cycling loop cannot say *why*; the
spectral radius of the linearised loop can (ρ > 1: the loop is unstable and the flight cycles
at the tilt limit; ρ < 1: it settles). ``reproduce`` prints it next to the simulated runs.

Linearisation (docs/thesis.md §3.3, eq. 3.13–3.14 at hover, ψ = 0): the NMPC predicts
``ẍ = g θ`` over N forward-Euler steps of Δτ with stage cost Δτ·(q_x x² + q_v ẋ² + r θ²)
and terminal cost q_f,x x² + q_f,v ẋ² (the ½ of eq. 3.14 cancels in the gain). Its
first input is the finite-horizon LQ gain K₀ of the Riccati recursion. The plant
(docs/plant.md): θ follows the command with the tilt lag τ, ``v̇ = k g θ − k_d v`` (k: tilt
gain factor, k_d: drag), the command arrives ``delay_s`` later, held over each ``period_s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ardrone_nmpc.core.types import GRAVITY_MPS2


def first_step_gain(*, horizon_steps: int, dtau_s: float, q_x: float, q_v: float, r_theta: float,
                    qf_x: float = 0.0, qf_v: float = 0.0) -> np.ndarray:
    """K₀ (1×2) of ``θ = −K₀ [x − x_ref, ẋ]``: the NMPC's first input, linearised at hover.

    The Riccati recursion of the Euler-discretised prediction model (``A = [[1, Δτ], [0, 1]]``,
    ``B = [0, g Δτ]ᵀ``) with stage weights ``Δτ·diag(q_x, q_v)``, ``Δτ·r_theta`` and terminal
    weights ``diag(qf_x, qf_v)``, from stage N back to stage 0.
    """
    if horizon_steps < 1 or not dtau_s > 0.0:
        raise ValueError("horizon_steps must be ≥ 1 and dtau_s > 0")
    a = np.array([[1.0, dtau_s], [0.0, 1.0]])
    b = np.array([[0.0], [GRAVITY_MPS2 * dtau_s]])
    q = dtau_s * np.diag([q_x, q_v])
    r = np.array([[dtau_s * r_theta]])
    p = np.diag([qf_x, qf_v]).astype(float)
    k = np.zeros((1, 2))
    for _ in range(horizon_steps):
        k = np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
        p = q + a.T @ p @ (a - b @ k)
    return k


@dataclass(frozen=True)
class XPlant:
    """The plant's x channel at hover (docs/plant.md): tilt lag, gain, drag, delay, period."""

    tau_tilt_s: float = 0.10
    tilt_gain: float = 1.0
    drag_per_s: float = 0.58
    delay_s: float = 0.26
    period_s: float = 0.065

    def discrete(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) of ``[x, v, θ]`` over one period with the command held (zero-order hold)."""
        ac = np.array([[0.0, 1.0, 0.0],
                       [0.0, -self.drag_per_s, self.tilt_gain * GRAVITY_MPS2],
                       [0.0, 0.0, -1.0 / self.tau_tilt_s]])
        bc = np.array([[0.0], [0.0], [1.0 / self.tau_tilt_s]])
        m = np.zeros((4, 4))
        m[:3, :3], m[:3, 3:] = ac, bc
        e = expm(m * self.period_s)
        return e[:3, :3], e[:3, 3:]

    @property
    def delay_ticks(self) -> int:
        """The transport delay in whole periods (the kit's 4 · 65 ms = 0.26 s is exact)."""
        return int(round(self.delay_s / self.period_s))


def closed_loop_matrix(gain: np.ndarray, plant: XPlant) -> np.ndarray:
    """The loop ``θ_cmd,k = −K [x_k, v_k]`` acting ``delay_ticks`` periods later, as one matrix
    on ``[x, v, θ, u_{k−1}, …, u_{k−d}]`` (the commands in flight)."""
    a, b = plant.discrete()
    d = plant.delay_ticks
    n = 3 + d
    m = np.zeros((n, n))
    k_row = np.zeros(n)
    k_row[:2] = -np.asarray(gain, float).reshape(-1)[:2]
    if d == 0:
        m[:3, :3] = a
        m[:3, :] += b @ k_row[None, :]
        return m
    m[:3, :3] = a
    m[:3, 2 + d] = b[:, 0]  # the oldest command in flight acts over this period
    m[3, :] = k_row        # the command computed now enters the queue
    for i in range(1, d):
        m[3 + i, 2 + i] = 1.0
    return m


def spectral_radius(*, horizon_steps: int, dtau_s: float, q_x: float, q_v: float,
                    r_theta: float, plant: XPlant = XPlant()) -> float:
    """ρ of the linearised x loop: > 1 unstable (a limit cycle at the tilt limit in flight)."""
    k = first_step_gain(horizon_steps=horizon_steps, dtau_s=dtau_s, q_x=q_x, q_v=q_v,
                        r_theta=r_theta)
    return float(max(abs(np.linalg.eigvals(closed_loop_matrix(k, plant)))))


def stability_table(cases, *, q_x: float, q_v: float, r_theta: float,
                    plants: dict[str, XPlant]) -> list[dict]:
    """One row per ``(N, Δτ)`` case: K₀ and ρ against each named plant."""
    rows = []
    for n, dtau in cases:
        k = first_step_gain(horizon_steps=n, dtau_s=dtau, q_x=q_x, q_v=q_v, r_theta=r_theta)
        row = {"N": n, "dtau_s": dtau, "k_x": float(k[0, 0]), "k_v": float(k[0, 1])}
        for name, plant in plants.items():
            row[f"rho_{name}"] = float(max(abs(np.linalg.eigvals(closed_loop_matrix(k, plant)))))
        rows.append(row)
    return rows


def verdict(rho: float, tol: float = 1e-3) -> str:
    """``stable`` / ``marginal`` / ``unstable`` for ρ below, within ``tol`` of, or above 1."""
    if not math.isfinite(rho):
        return "unstable"
    return "stable" if rho < 1.0 - tol else ("unstable" if rho > 1.0 + tol else "marginal")


# ----------------------------------------------------------------------------- robustness
def predicted_loop_matrix(gain: np.ndarray, plant: XPlant, *, compensation_s: float,
                          difference_velocity: bool = True) -> np.ndarray:
    """The loop as the tick runs it (docs/solver-notes.md §10): ẋ from the backward
    difference of the measured x (or the true ẋ), the state predicted through the commands of
    the last ``ceil(compensation_s / period)`` ticks by the model (ẍ = g θ, held per tick),
    ``θ = −K x_pred``; the plant's delay need not be whole ticks (its command changes within
    a tick). The state is ``[x, v, θ, x_prev, u_{k−1}, …, u_{k−M}]``."""
    t = plant.period_s
    nc = math.ceil(compensation_s / t - 1e-9)
    m = int(math.floor(plant.delay_s / t + 1e-9))
    f = plant.delay_s / t - m
    a, b_late = plant.discrete()
    a_early, b_early = XPlant(plant.tau_tilt_s, plant.tilt_gain, plant.drag_per_s, 0.0,
                              f * t).discrete()
    a_rest, b_rest = XPlant(plant.tau_tilt_s, plant.tilt_gain, plant.drag_per_s, 0.0,
                            t - f * t).discrete()
    big = max(m + 1, nc, 1)
    n = 4 + big
    u = lambda j: 3 + j  # noqa: E731 - column of u_{k−j}
    meas = np.zeros((2, n))
    meas[0, 0] = 1.0
    if difference_velocity:
        meas[1, 0], meas[1, 3] = 1.0 / t, -1.0 / t
    else:
        meas[1, 1] = 1.0
    am = np.array([[1.0, t], [0.0, 1.0]])
    bm = np.array([GRAVITY_MPS2 * t * t / 2.0, GRAVITY_MPS2 * t])
    pred = np.linalg.matrix_power(am, nc) @ meas
    for i in range(1, nc + 1):
        pred[:, u(nc - i + 1)] += np.linalg.matrix_power(am, nc - i) @ bm
    k_row = -(np.asarray(gain, float).reshape(1, 2) @ pred)[0]
    mat = np.zeros((n, n))
    mat[:3, :3] = a
    # over a tick the command u_{k−m−1} acts for f·T, then u_{k−m} for the rest
    for j, bj in ((m + 1, a_rest @ b_early), (m, b_rest)):
        if j == 0:
            mat[:3, :] += bj @ k_row[None, :]
        else:
            mat[:3, u(j)] += bj[:, 0]
    mat[3, 0] = 1.0
    mat[u(1), :] = k_row
    for j in range(2, big + 1):
        mat[u(j), u(j - 1)] = 1.0
    return mat


def region_table(weights=((12.0, 2.0, 12.0), (4.0, 0.5, 48.0), (2.0, 0.0, 96.0)), *,
                 delays_s=(0.0, 0.2, 0.4), gains=(0.6, 1.0, 2.0), lags_s=(0.05, 0.2),
                 prior_s: float = 0.26) -> list[dict]:
    """Per x weights (q_x, q_ẋ, r_θ; N = 15, Δτ = 0.1 s): K, the worst ρ over the region with
    a fixed ``prior_s`` prediction and with the delay compensated and the gain divided out,
    and ρ on the nominal plant (docs/solver-notes.md §10)."""
    rows = []
    for q_x, q_v, r in weights:
        k = first_step_gain(horizon_steps=15, dtau_s=0.1, q_x=q_x, q_v=q_v, r_theta=r)

        def rho(plant: XPlant, comp: float) -> float:
            m = predicted_loop_matrix(k, plant, compensation_s=comp)
            return float(max(abs(np.linalg.eigvals(m))))

        fixed, adapted = [], []
        for d in delays_s:
            for g in gains:
                for lag in lags_s:
                    fixed.append((rho(XPlant(lag, g, 0.58, d), prior_s), d, g, lag))
                    adapted.append(rho(XPlant(lag, 1.0, 0.58, d), d))
        rows.append({"weights": (q_x, q_v, r), "K": tuple(float(v) for v in k[0]),
                     "worst_fixed": max(fixed), "worst_adapted": max(adapted),
                     "nominal": rho(XPlant(), prior_s)})
    return rows
