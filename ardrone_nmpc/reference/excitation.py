"""The identification flight's reference: small steps and sweeps on each axis in turn.

Around the start point, x, then y, then z, then ψ each get ``axis_s`` seconds of a
pseudo-random binary sequence (PRBS) of set points ``±amplitude``, one bit every ``bit_s``;
x and y then a sweep — the set point travels at ``sweep_mps`` out to ``+sweep_m``, back to
``−sweep_m`` and home (a triangle; its speed is part of the reference) — and every axis ends
with ``rest_s`` at the start. The steps answer with bursts of tilt, climb or turn commands,
which show the command delay and the attitude response; the sweeps hold a speed long enough
for the drag to show in the tilt it takes (docs/identification.md §1). The bits are those of
a 7-bit maximal-length linear feedback shift register (x⁷ + x⁶ + 1) started from the state
0111000, whose first bits change sign often and after holds of one and two bits
(+ − − + − − + + − +): short and long steps, the same on every axis and every flight.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_X, IX_Y, IX_Z, STATE_DIM

__all__ = ["PRBS_SEED", "Excitation", "prbs_bits"]

_AXES = (IX_X, IX_Y, IX_Z, IX_PSI)
_SPEEDS = (IX_VX, IX_VY)
PRBS_SEED = 0b0111000


def prbs_bits(n: int) -> np.ndarray:
    """The first ``n`` bits (±1) of the PRBS7 sequence (period 127) from :data:`PRBS_SEED`."""
    state, out = PRBS_SEED, np.empty(n)
    for i in range(n):
        bit = ((state >> 6) ^ (state >> 5)) & 1
        state = ((state << 1) | bit) & 0x7F
        out[i] = 1.0 if bit else -1.0
    return out


def _triangle(t: np.ndarray, amplitude: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and speed of 0 → +A → −A → 0 at ±speed, ``t`` from 0 to 4A/speed."""
    leg = amplitude / speed
    phase = np.clip(t / leg, 0.0, 4.0)
    pos = np.where(phase < 1.0, phase, np.where(phase < 3.0, 2.0 - phase, phase - 4.0))
    vel = np.where((phase < 1.0) | (phase >= 3.0), 1.0, -1.0) * speed
    return amplitude * pos, np.where((t >= 0) & (t < 4.0 * leg), vel, 0.0)


class Excitation:
    """Steps, sweeps and rests per axis in turn (module docstring).

    Parameters
    ----------
    start_m : (3,) hover point [x, y, z] (m); start_psi_rad its heading (rad).
    amplitude_m : (3,) step size on x, y, z (m); amplitude_psi_rad on ψ (rad).
    axis_s : seconds of steps per axis; bit_s : seconds per bit.
    sweep_m, sweep_mps : the x and y sweeps' reach (m) and speed (m/s); 0 m: none.
    rest_s : seconds at the start point after each axis.
    """

    def __init__(self, start_m: Sequence[float], start_psi_rad: float,
                 amplitude_m: Sequence[float], amplitude_psi_rad: float, *,
                 axis_s: float, bit_s: float, rest_s: float, sweep_m: float = 0.0,
                 sweep_mps: float = 0.2) -> None:
        self.start = np.zeros(STATE_DIM)
        self.start[[IX_X, IX_Y, IX_Z]] = np.asarray(start_m, dtype=float)
        self.start[IX_PSI] = float(start_psi_rad)
        self.amplitude = np.array([*amplitude_m, amplitude_psi_rad], dtype=float)
        self.axis_s, self.bit_s, self.rest_s = float(axis_s), float(bit_s), float(rest_s)
        self.sweep_m, self.sweep_mps = float(sweep_m), float(sweep_mps)
        self.sweep_s = 4.0 * self.sweep_m / self.sweep_mps if self.sweep_m > 0 else 0.0
        self.bits = prbs_bits(max(1, math.ceil(self.axis_s / self.bit_s)))
        spans = [self.axis_s + (self.sweep_s if a < 2 else 0.0) + self.rest_s
                 for a in range(4)]
        self.starts = np.concatenate([[0.0], np.cumsum(spans)])

    @property
    def duration_s(self) -> float:
        """The four axes and their rests (s); the start point holds after it."""
        return float(self.starts[-1])

    def state_at(self, t_s) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).ravel()
        out = np.tile(self.start, (t.size, 1))
        for a, index in enumerate(_AXES):
            within = t - self.starts[a]
            steps = (within >= 0.0) & (within < self.axis_s)
            k = np.clip((within[steps] / self.bit_s).astype(int), 0, len(self.bits) - 1)
            out[steps, index] += self.amplitude[a] * self.bits[k]
            if a < 2 and self.sweep_s > 0.0:
                ts = within - self.axis_s
                sweep = (ts >= 0.0) & (ts < self.sweep_s)
                pos, vel = _triangle(ts[sweep], self.sweep_m, self.sweep_mps)
                out[sweep, index] += pos
                out[sweep, _SPEEDS[a]] = vel
        return out

    def polyline_m(self) -> np.ndarray:
        """The start and the extreme set points, (7, 3): the flight's places."""
        p = self.start[[IX_X, IX_Y, IX_Z]]
        pts = [p]
        for a in range(3):
            reach = max(self.amplitude[a], self.sweep_m if a < 2 else 0.0)
            for sign in (-1.0, 1.0):
                q = p.copy()
                q[a] += sign * reach
                pts.append(q)
        return np.array(pts)
