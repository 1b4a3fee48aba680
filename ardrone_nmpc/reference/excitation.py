"""The identification flight's reference: small pseudo-random steps on each axis in turn.

Around the start point, x, then y, then z, then ψ each get ``axis_s`` seconds of a
pseudo-random binary sequence (PRBS) of set points ``±amplitude``, one bit every ``bit_s``,
then ``rest_s`` back at the start. The closed loop answers each step with a burst of tilt,
climb or turn commands — what ``ardrone-nmpc identify`` fits the drone's channels on
(docs/identification.md §1). The bits are those of a 7-bit maximal-length linear feedback
shift register (x⁷ + x⁶ + 1), the same sequence on every axis and every flight.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ardrone_nmpc.core.types import IX_PSI, IX_X, IX_Y, IX_Z, STATE_DIM

__all__ = ["Excitation", "prbs_bits"]

_AXES = (IX_X, IX_Y, IX_Z, IX_PSI)


def prbs_bits(n: int) -> np.ndarray:
    """The first ``n`` bits (±1) of the PRBS7 sequence (period 127)."""
    state, out = 0x7F, np.empty(n)
    for i in range(n):
        bit = ((state >> 6) ^ (state >> 5)) & 1
        state = ((state << 1) | bit) & 0x7F
        out[i] = 1.0 if bit else -1.0
    return out


class Excitation:
    """Set points ``start ± amplitude`` per axis in turn (module docstring).

    Parameters
    ----------
    start_m : (3,) hover point [x, y, z] (m); start_psi_rad its heading (rad).
    amplitude_m : (3,) step size on x, y, z (m); amplitude_psi_rad on ψ (rad).
    axis_s : seconds of steps per axis; bit_s : seconds per bit; rest_s : seconds at the
        start point after each axis.
    """

    def __init__(self, start_m: Sequence[float], start_psi_rad: float,
                 amplitude_m: Sequence[float], amplitude_psi_rad: float, *,
                 axis_s: float, bit_s: float, rest_s: float) -> None:
        self.start = np.zeros(STATE_DIM)
        self.start[[IX_X, IX_Y, IX_Z]] = np.asarray(start_m, dtype=float)
        self.start[IX_PSI] = float(start_psi_rad)
        self.amplitude = np.array([*amplitude_m, amplitude_psi_rad], dtype=float)
        self.axis_s, self.bit_s, self.rest_s = float(axis_s), float(bit_s), float(rest_s)
        self.bits = prbs_bits(max(1, math.ceil(self.axis_s / self.bit_s)))

    @property
    def duration_s(self) -> float:
        """The four axes and their rests (s); the start point holds after it."""
        return 4.0 * (self.axis_s + self.rest_s)

    def state_at(self, t_s) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).ravel()
        out = np.tile(self.start, (t.size, 1))
        span = self.axis_s + self.rest_s
        axis = np.floor(t / span).astype(int)
        within = t - axis * span
        active = (t >= 0.0) & (axis < 4) & (within < self.axis_s)
        k = np.clip((within / self.bit_s).astype(int), 0, len(self.bits) - 1)
        for a, index in enumerate(_AXES):
            rows = active & (axis == a)
            out[rows, index] += self.amplitude[a] * self.bits[k[rows]]
        return out

    def polyline_m(self) -> np.ndarray:
        """The start and the six extreme set points, (7, 3): the flight's places."""
        p = self.start[[IX_X, IX_Y, IX_Z]]
        pts = [p]
        for a in range(3):
            for sign in (-1.0, 1.0):
                q = p.copy()
                q[a] += sign * self.amplitude[a]
                pts.append(q)
        return np.array(pts)
