"""Output-error fits of the drone's channels (docs/identification.md §3).

Each channel is a low-order transfer function from a logged input (held between its samples)
to a logged output, possibly after a delay: the model's output is simulated from the input
alone (output error: no measured output feeds it back), on a 2 ms grid (``scipy.signal``'s
exact zero-order-hold discretisation and ``lfilter``), read at the output's times minus the
delay, and its parameters are the least-squares fit (``scipy.optimize.least_squares``) over
the samples that are not held out. Their uncertainty is the fit's covariance σ²(JᵀJ)⁻¹,
inflated by the residual's lag-1 correlation; the model is judged on the held-out samples
(:func:`~ardrone_nmpc.experiments.identify.data.held_out`) by the fit
``100·(1 − ‖y − ŷ‖/‖y − ȳ‖)`` %.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import cont2discrete, lfilter

__all__ = ["Channel", "FitResult", "Param", "fit_channel", "simulate"]

GRID_S = 0.002
SKIP_S = 1.0  # the start of each segment: the simulation's initial state is a guess


@dataclass(frozen=True)
class Param:
    """One fitted parameter: its value, σ, unit and how it prints."""

    name: str
    value: float
    std: float
    unit: str = ""
    fmt: str = ".3g"

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", float(self.value))
        object.__setattr__(self, "std", float(self.std))

    def line(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.name}: {self.value:{self.fmt}}{unit} ± {self.std:{self.fmt}}"


@dataclass
class FitResult:
    """A channel's parameters (by key), its held-out fit (%) per output, and its cost."""

    params: dict[str, Param]
    held_out_fit_pct: list[float]
    cost: float
    model: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def held_out(self) -> float:
        return float(np.mean(self.held_out_fit_pct))


@dataclass(frozen=True)
class Channel:
    """The data of one channel over one flown stretch: input times and values (n, a) (held),
    output times and values (m, a) for ``a`` axes, and which outputs are held out."""

    t_in: np.ndarray
    u: np.ndarray
    t_out: np.ndarray
    y: np.ndarray
    test: np.ndarray


def simulate(num: Sequence[float], den: Sequence[float], t_in: np.ndarray, u: np.ndarray,
             t_out: np.ndarray, delay_s: float = 0.0) -> np.ndarray:
    """The output of ``num/den`` (continuous, a proper transfer function) driven by ``u``
    (held from each ``t_in`` on; before the first, 0 and at rest: a flown stretch starts
    from the drone's own hover) at ``t_out`` after a delay of ``delay_s``: (m,) for a (n,)
    input."""
    grid = np.arange(t_in[0] - 0.5, t_out[-1] - delay_s + 2 * GRID_S, GRID_S)
    k = np.searchsorted(t_in, grid, side="right") - 1
    held = np.where(k >= 0, u[np.clip(k, 0, len(t_in) - 1)], 0.0)
    numd, dend, _ = cont2discrete((np.atleast_1d(num), np.atleast_1d(den)), GRID_S,
                                  method="zoh")
    out = lfilter(np.ravel(numd), dend, held)
    return np.interp(t_out - delay_s, grid, out)


def _fit_pct(y: np.ndarray, yhat: np.ndarray) -> float:
    den = float(np.linalg.norm(y - y.mean()))
    return 100.0 * (1.0 - float(np.linalg.norm(y - yhat)) / den) if den > 0 else math.nan


def _lag1(r: np.ndarray) -> float:
    r = r - r.mean()
    d = float(r @ r)
    return min(max(float(r[1:] @ r[:-1]) / d, 0.0), 0.95) if d > 0 and r.size > 2 else 0.0


def fit_channel(channels: Sequence[Channel], model: Callable[[np.ndarray, Channel], np.ndarray],
                x0: Sequence[float], *, lower: Sequence[float], upper: Sequence[float],
                x_scale: Sequence[float]) -> tuple[np.ndarray, np.ndarray, list[float], float]:
    """Least squares of ``model(params, channel) → (m, a)`` outputs against every channel's
    training outputs. Returns (params, their σ, the held-out fit % per output axis, cost)."""

    def residual(p: np.ndarray) -> np.ndarray:
        parts = []
        for ch in channels:
            r = model(p, ch) - ch.y
            keep = (~ch.test) & (ch.t_out >= ch.t_in[0] + SKIP_S)
            parts.append(r[keep].ravel())
        return np.concatenate(parts)

    sol = least_squares(residual, np.asarray(x0, float), bounds=(lower, upper),
                        x_scale=np.asarray(x_scale, float), method="trf")
    r = sol.fun
    dof = max(r.size - len(x0), 1)
    sigma2 = float(r @ r) / dof
    inflate = (1.0 + _lag1(r)) / (1.0 - _lag1(r))
    try:
        cov = np.linalg.pinv(sol.jac.T @ sol.jac) * sigma2 * inflate
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(len(x0), math.inf)
    axes = channels[0].y.shape[1]
    fits = []
    for a in range(axes):
        ys, yh = [], []
        for ch in channels:
            keep = ch.test & (ch.t_out >= ch.t_in[0] + SKIP_S)
            ys.append(ch.y[keep, a])
            yh.append(model(sol.x, ch)[keep, a])
        fits.append(_fit_pct(np.concatenate(ys), np.concatenate(yh)))
    return sol.x, std, fits, float(sol.cost)
