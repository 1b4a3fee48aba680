"""The x channel linearised at hover: the NMPC's first-step gain and its closed-loop spectral radius.

Why: the thesis reports that N = 5 (Δτ = 0.3 s) diverges where N = 6 holds, and that Δτ = 0.08 s
is worse than Δτ ≥ 0.1 s. Simulated flights of a limit-cycling loop cannot say *why*; the
spectral radius of the linearised loop can (ρ > 1: the loop is unstable and the flight cycles
at the tilt limit; ρ < 1: it settles). ``reproduce`` prints it next to the simulated runs.

Linearisation (docs/thesis.md §3.3, eq. 3.13–3.14 at hover, ψ = 0): the NMPC predicts
``ẍ = g θ`` over N forward-Euler steps of Δτ with stage cost Δτ·(q_x x² + q_v ẋ² + r θ²)
and terminal cost q_f,x x² + q_f,v ẋ² (the ½ of eq. 3.14 cancels in the gain). Its
first input is the finite-horizon LQ gain K₀ of the Riccati recursion. The plant is a
continuous state space on ``[x, v, …]`` driven by the tilt command: the ``ardrone`` profile's
first-order tilt lag, tilt gain and drag (:class:`XPlant`, docs/plant.md), or the kit's
identified second-order attitude and velocity channel under its command convention
(:class:`KitXPlant`, docs/plant-profiles.md §2). The command arrives ``delay_s`` later, in
whole periods, held over each ``period_s``; the velocity the NMPC is fed is
``velocity_age_s`` old (navdata's sample age; the position, from mocap, is fresh).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ardrone_nmpc.core.types import GRAVITY_MPS2
from ardrone_nmpc.sim.plant_kit import KIT, KitModel


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


def first_step_law(*, horizon_steps: int, dtau_s: float, q_x: float, q_v: float,
                   r_theta: float) -> tuple[np.ndarray, np.ndarray]:
    """(K₀, F): the NMPC's first input ``θ = −K₀ [x, ẋ] + F·r`` with the reference positions
    ``r`` at stages 1 … N (reference velocities 0: a step), linearised at hover — the tracking
    form of :func:`first_step_gain` (its affine term run back from stage N), so a reference
    step the horizon already sees acts before it happens, as in flight. For a constant
    reference ``F`` sums to ``K₀[0]``: only the error counts."""
    k0 = first_step_gain(horizon_steps=horizon_steps, dtau_s=dtau_s, q_x=q_x, q_v=q_v,
                         r_theta=r_theta)
    a = np.array([[1.0, dtau_s], [0.0, 1.0]])
    b = np.array([[0.0], [GRAVITY_MPS2 * dtau_s]])
    q = dtau_s * np.diag([q_x, q_v])
    r = np.array([[dtau_s * r_theta]])
    # value x'P x + 2 s'x, s linear in the references: s = S r, S (2 × N), from P_N = 0, s_N = 0
    p = np.zeros((2, 2))
    s = np.zeros((2, horizon_steps))
    for j in range(horizon_steps - 1, -1, -1):  # stage j's input from stage j + 1's value
        g = np.linalg.inv(r + b.T @ p @ b)
        k = g @ b.T @ p @ a
        f = -g @ b.T @ s  # u_j = −K_j x − g Bᵀ s_{j+1}
        if j == 0:
            return k0, f.reshape(1, -1)
        closed = a - b @ k
        p = q + a.T @ p @ closed
        s = closed.T @ s
        s[:, j - 1] -= q[:, 0]  # −Q_j r_j with r_j = [x_ref,j, 0] (reference j is column j − 1)
    raise AssertionError("unreachable")


def _zoh(ac: np.ndarray, bc: np.ndarray, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(e^{A t}, ∫₀ᵗ e^{A s} ds B): the state and a held input's effect after ``t_s``."""
    n = ac.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n], m[:n, n:] = ac, bc
    e = expm(m * t_s)
    return e[:n, :n], e[:n, n:]


class _Channel:
    """What every x-channel plant shares: ZOH over a period, the delay in whole periods."""

    delay_s: float
    period_s: float
    velocity_age_s: float

    def continuous(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def discrete(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) over one period with the tilt command held (zero-order hold)."""
        return _zoh(*self.continuous(), self.period_s)

    @property
    def delay_ticks(self) -> int:
        """The transport delay in whole periods (the kit's 4 · 65 ms = 0.26 s is exact)."""
        return int(round(self.delay_s / self.period_s))

    def velocity_row(self) -> tuple[np.ndarray, np.ndarray]:
        """(c_s, c_u): the measured velocity ``c_s·s_k + c_u·u_prev``, ``velocity_age_s`` old,
        from this tick's state ``s_k`` and the command applied over the last period
        ``u_prev`` (run backwards: s(t − a) = e^{−A a}(s_k − Γ(a)·u_prev))."""
        n = self.continuous()[0].shape[0]
        e_v = np.zeros(n)
        e_v[1] = 1.0
        if self.velocity_age_s == 0.0:
            return e_v, np.zeros(1)
        phi, gamma = _zoh(*self.continuous(), self.velocity_age_s)
        back = np.linalg.inv(phi)
        return e_v @ back, -(e_v @ back @ gamma)


@dataclass(frozen=True)
class XPlant(_Channel):
    """The ``ardrone`` profile's x channel at hover (docs/plant.md): ``[x, v, θ]`` with the tilt
    lag τ, ``v̇ = k g θ − k_d v`` (k: tilt gain factor, k_d: drag)."""

    tau_tilt_s: float = 0.10
    tilt_gain: float = 1.0
    drag_per_s: float = 0.58
    delay_s: float = 0.26
    period_s: float = 0.065
    velocity_age_s: float = 0.0

    def continuous(self) -> tuple[np.ndarray, np.ndarray]:
        ac = np.array([[0.0, 1.0, 0.0],
                       [0.0, -self.drag_per_s, self.tilt_gain * GRAVITY_MPS2],
                       [0.0, 0.0, -1.0 / self.tau_tilt_s]])
        bc = np.array([[0.0], [0.0], [1.0 / self.tau_tilt_s]])
        return ac, bc


@dataclass(frozen=True)
class KitXPlant(_Channel):
    """The ``thesis_kit`` profile's x channel at hover, ψ = 0, under the kit's command
    convention (the tilt command in rad is the port's fraction): ``[x, v, q₁, q₂]`` with the
    kit's ``ssPitch`` (θ = C_p q, nose-down positive) and ``ssPitch2U`` (v̇ = a_u v − b_u c_u θ).
    ``tilt_gain`` scales the attitude channel (a weaker or stronger kit)."""

    model: KitModel = KIT
    tilt_gain: float = 1.0
    delay_s: float = 0.26
    period_s: float = 0.065
    velocity_age_s: float = 0.0

    def continuous(self) -> tuple[np.ndarray, np.ndarray]:
        k = self.model
        au, bu, cu = k.pitch2u_abc
        (p11, p12), (p21, p22) = k.pitch_a
        c1, c2 = (self.tilt_gain * c for c in k.pitch_c)
        # world θ = −θ_k, the port's pitch = −θ_cmd: q = −(ssPitch state) follows θ_cmd
        ac = np.array([[0.0, 1.0, 0.0, 0.0],
                       [0.0, au, -bu * cu * c1, -bu * cu * c2],
                       [0.0, 0.0, p11, p12],
                       [0.0, 0.0, p21, p22]])
        bc = np.array([[0.0], [0.0], [k.pitch_b[0]], [k.pitch_b[1]]])
        return ac, bc


def closed_loop_matrix(gain: np.ndarray, plant: _Channel) -> np.ndarray:
    """The loop ``θ_cmd,k = −K [x_k, v_meas,k]`` acting ``delay_ticks`` periods later, as one
    matrix on ``[s, u_{k−1}, …, u_{k−d}]`` (the plant's state and the commands in flight, the
    oldest last), and with a velocity age, ``u_prev`` (the command applied over the last
    period) appended."""
    a, b = plant.discrete()
    n = a.shape[0]
    d = plant.delay_ticks
    aged = plant.velocity_age_s > 0.0
    size = n + d + (1 if aged else 0)
    k = np.asarray(gain, float).reshape(-1)[:2]
    c_s, c_u = plant.velocity_row()
    k_row = np.zeros(size)  # θ_cmd,k as a row on the loop's state
    k_row[0] -= k[0]
    k_row[:n] -= k[1] * c_s
    if aged:
        k_row[size - 1] -= k[1] * c_u[0]
    m = np.zeros((size, size))
    m[:n, :n] = a
    if d == 0:
        m[:n, :] += b @ k_row[None, :]
        if aged:
            m[size - 1, :] = k_row
        return m
    m[:n, n + d - 1] = b[:, 0]  # the oldest command in flight acts over this period
    m[n, :] = k_row            # the command computed now enters the queue
    for i in range(1, d):
        m[n + i, n + i - 1] = 1.0
    if aged:
        m[size - 1, n + d - 1] = 1.0  # … and is the last period's applied command next tick
    return m


def spectral_radius(*, horizon_steps: int, dtau_s: float, q_x: float, q_v: float,
                    r_theta: float, plant: _Channel = XPlant()) -> float:
    """ρ of the linearised x loop: > 1 unstable (a limit cycle at the tilt limit in flight)."""
    k = first_step_gain(horizon_steps=horizon_steps, dtau_s=dtau_s, q_x=q_x, q_v=q_v,
                        r_theta=r_theta)
    return float(max(abs(np.linalg.eigvals(closed_loop_matrix(k, plant)))))


def stability_table(cases, *, q_x: float, q_v: float, r_theta: float,
                    plants: dict[str, _Channel]) -> list[dict]:
    """One row per ``(N, Δτ)`` case: K₀ and ρ against each named plant."""
    rows = []
    for n, dtau in cases:
        k = first_step_gain(horizon_steps=n, dtau_s=dtau, q_x=q_x, q_v=q_v, r_theta=r_theta)
        row = {"N": n, "dtau_s": dtau, "k_x": float(k[0, 0]), "k_v": float(k[0, 1])}
        for name, plant in plants.items():
            row[f"rho_{name}"] = float(max(abs(np.linalg.eigvals(closed_loop_matrix(k, plant)))))
        rows.append(row)
    return rows


def step_response(law: tuple[np.ndarray, np.ndarray], plant: _Channel, *, dtau_s: float,
                  step_m: float, step_s: float, ticks: int) -> np.ndarray:
    """x at ticks 0 … ``ticks`` of the linear loop (``law`` from :func:`first_step_law`) from
    rest at 0 when the reference steps to ``step_m`` at ``step_s`` (no input bound): what a
    flight small enough not to saturate follows."""
    k0, f = law
    m = closed_loop_matrix(k0, plant)  # the feedback; the preview enters the queue as well
    n = plant.continuous()[0].shape[0]
    entry = np.zeros(m.shape[0])
    entry[n if plant.delay_ticks else 0] = 1.0  # where the tick's command enters
    if not plant.delay_ticks:
        entry[:n] = plant.discrete()[1][:, 0]
        if plant.velocity_age_s > 0.0:
            entry[-1] = 1.0
    stages_s = dtau_s * np.arange(1, f.shape[1] + 1)
    z = np.zeros(m.shape[0])
    out = np.empty(ticks + 1)
    for i in range(ticks + 1):
        out[i] = z[0]
        preview = np.where(i * plant.period_s + stages_s >= step_s - 1e-9, step_m, 0.0)
        z = m @ z + entry * float(f[0] @ preview)
    return out


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
