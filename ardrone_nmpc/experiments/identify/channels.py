"""The drone's channels as ``identify`` fits them (docs/identification.md §2), each from the
logged series of :mod:`.data` by :func:`.fit.fit_channel`:

=============  ===================================================  ==========================
channel        model (per axis)                                     input → output
=============  ===================================================  ==========================
attitude       k·E·G(s)·e^(−d s) + b, G = 1/(τ s + 1) or            PCMD roll, pitch → navdata
               ω²(T s + 1)/(s² + 2ζω s + ω²) (the kit's form)       roll, pitch
velocity       a/(s + p) on tan(tilt) + b, per body axis            navdata tilt → mocap speed
vertical       G·V/(τ s + 1)·e^(−d s) + b                           PCMD gaz → mocap climb rate
yaw            −g·Y/(τ s + 1)·e^(−d s) + b                          PCMD yaw → mocap turn rate
=============  ===================================================  ==========================

E, V, Y are the drone's ``euler_angle_max``, ``control_vz_max``, ``control_yaw``; d is the
command delay the attitude fit finds, used by the vertical and yaw fits too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ardrone_nmpc.core.types import GRAVITY_MPS2
from ardrone_nmpc.estimation.attitude_response import fit_attitude_response
from ardrone_nmpc.experiments.identify.data import Flight, differentiate, held_out
from ardrone_nmpc.experiments.identify.fit import Channel, FitResult, Param, fit_channel, simulate

__all__ = ["fit_attitude", "fit_velocity", "fit_vertical", "fit_yaw"]

#: A second-order form must beat the first-order lag's held-out fit by this much (points).
SECOND_ORDER_MARGIN_PCT = 1.0


def _window(t: np.ndarray, seg: tuple[float, float]) -> np.ndarray:
    return (t >= seg[0]) & (t <= seg[1])


def _channels(flights: Sequence[Flight], t_in_of, u_of, t_out_of, y_of) -> list[Channel]:
    out = []
    for f in flights:
        for seg in f.segments:
            ti, to = t_in_of(f), t_out_of(f)
            wi, wo = _window(ti, seg), _window(to, (seg[0] + 0.7, seg[1]))
            if wi.sum() < 10 or wo.sum() < 10:
                continue
            out.append(Channel(ti[wi], u_of(f)[wi], to[wo], y_of(f)[wo], held_out(to[wo])))
    if not out:
        raise ValueError("no flown stretch holds enough samples")
    return out


# ----------------------------------------------------------------------------- attitude
def _attitude_channels(flights: Sequence[Flight]) -> list[Channel]:
    return _channels(flights, lambda f: f.t_cmd,
                     lambda f: f.cmd[:, :2] * f.euler_angle_max_rad,
                     lambda f: f.t_nav, lambda f: f.nav_tilt_rad)


def _first_order(p: np.ndarray, ch: Channel) -> np.ndarray:
    d, tau, k1, k2, b1, b2 = p
    return np.column_stack([k * simulate([1.0], [tau, 1.0], ch.t_in, ch.u[:, a], ch.t_out, d) + b
                            for a, (k, b) in enumerate(((k1, b1), (k2, b2)))])


def _second_order(p: np.ndarray, ch: Channel) -> np.ndarray:
    d, wn, zeta, tz, k1, k2, b1, b2 = p
    num, den = [wn * wn * tz, wn * wn], [1.0, 2.0 * zeta * wn, wn * wn]
    return np.column_stack([k * simulate(num, den, ch.t_in, ch.u[:, a], ch.t_out, d) + b
                            for a, (k, b) in enumerate(((k1, b1), (k2, b2)))])


def fit_attitude(flights: Sequence[Flight]) -> FitResult:
    """Delay, gains and the attitude loops' form; the second-order form is chosen when its
    held-out fit beats the lag's by :data:`SECOND_ORDER_MARGIN_PCT`."""
    chans = _attitude_channels(flights)
    f0 = flights[0]
    start = fit_attitude_response(f0.t_cmd, f0.cmd[:, :2], f0.t_nav, f0.nav_tilt_rad,
                                  euler_angle_max_rad=f0.euler_angle_max_rad)
    d0 = start.delay_s if math.isfinite(start.delay_s) else 0.2
    k0 = [g if math.isfinite(g) and g > 0 else 1.0 for g in start.gain]
    lag0 = start.lag_s if math.isfinite(start.lag_s) else 0.1
    x1, s1, fit1, _ = fit_channel(chans, _first_order, [d0, lag0, *k0, 0.0, 0.0],
                                  lower=[0.0, 0.01, 0.05, 0.05, -0.2, -0.2],
                                  upper=[1.0, 1.0, 5.0, 5.0, 0.2, 0.2],
                                  x_scale=[0.05, 0.05, 0.1, 0.1, 0.01, 0.01])
    best2 = None
    for wn0 in (3.5, 7.0):  # the kit's ω, and a faster start: the cost has local minima
        try:
            x2, s2, fit2, c2 = fit_channel(
                chans, _second_order, [max(d0 - 0.05, 0.0), wn0, 0.6, 0.3, *k0, 0.0, 0.0],
                lower=[0.0, 0.5, 0.1, 0.0, 0.05, 0.05, -0.2, -0.2],
                upper=[1.0, 40.0, 3.0, 2.0, 5.0, 5.0, 0.2, 0.2],
                x_scale=[0.05, 1.0, 0.1, 0.1, 0.1, 0.1, 0.01, 0.01])
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best2 is None or c2 < best2[3]:
            best2 = (x2, s2, fit2, c2)
    first = {"delay": Param("command delay", x1[0], s1[0], "s"),
             "lag": Param("attitude lag τ (first order)", x1[1], s1[1], "s"),
             "roll_gain": Param("roll gain", x1[2], s1[2], "× euler_angle_max"),
             "pitch_gain": Param("pitch gain", x1[3], s1[3], "× euler_angle_max")}
    lag_fit = float(np.mean(fit1))
    if best2 is not None and float(np.mean(best2[2])) >= lag_fit + SECOND_ORDER_MARGIN_PCT:
        x2, s2, fit2, c2 = best2
        params = {"delay": Param("command delay", x2[0], s2[0], "s"),
                  "wn": Param("attitude ω_n (second order)", x2[1], s2[1], "rad/s"),
                  "zeta": Param("attitude ζ (second order)", x2[2], s2[2]),
                  "zero": Param("attitude zero T (second order)", x2[3], s2[3], "s"),
                  "roll_gain": Param("roll gain", x2[4], s2[4], "× euler_angle_max"),
                  "pitch_gain": Param("pitch gain", x2[5], s2[5], "× euler_angle_max")}
        return FitResult(params, fit2, c2, "second_order",
                         [f"attitude form: second order with a zero (held-out fit "
                          f"{np.mean(fit2):.1f} % against the first-order lag's {lag_fit:.1f} %)"])
    other = f" against the second order's {np.mean(best2[2]):.1f} %" if best2 else ""
    return FitResult(first, fit1, 0.0, "lag",
                     [f"attitude form: first-order lag (held-out fit {lag_fit:.1f} %{other})"])


# ----------------------------------------------------------------------------- velocity
def _body_velocity(f: Flight) -> tuple[np.ndarray, np.ndarray]:
    t, v = differentiate(f.t_pose, f.pose[:, :2])
    psi = f.pose[1:-1, 3]
    c, s = np.cos(psi), np.sin(psi)
    return t, np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]])


def _drag_model(p: np.ndarray, ch: Channel) -> np.ndarray:
    a_f, p_f, a_l, p_l, b_f, b_l = p
    return np.column_stack([simulate([a_f], [1.0, p_f], ch.t_in, ch.u[:, 0], ch.t_out) + b_f,
                            simulate([a_l], [1.0, p_l], ch.t_in, ch.u[:, 1], ch.t_out) + b_l])


def _tilt_input(f: Flight) -> tuple[np.ndarray, np.ndarray]:
    """tan of the measured tilt in world/model signs (θ = −pitch; a left acceleration is
    −g tan φ), interpolated between the navdata samples onto 10 ms: held from sample to
    sample, the tilt would lag the drone's by half a navdata period (33 ms at 15 Hz), which
    biases the drag pole up by 15 %."""
    t = np.arange(f.t_nav[0], f.t_nav[-1], 0.01)
    # the C library's tan, not numpy's: numpy's is chosen by the CPU at run time and differs
    # in the last bit between AVX-512 and AVX2 machines (docs/solver-notes.md §9)
    tan_pitch = np.array([math.tan(-a) for a in f.nav_tilt_rad[:, 1]])
    tan_roll = np.array([math.tan(a) for a in f.nav_tilt_rad[:, 0]])
    return t, np.column_stack([np.interp(t, f.t_nav, tan_pitch),
                               np.interp(t, f.t_nav, -tan_roll)])


def fit_velocity(flights: Sequence[Flight]) -> FitResult:
    """Tilt → speed per body axis (forward from pitch, left from roll): the acceleration per
    unit tan(tilt) and the drag pole."""
    chans = _channels(flights, lambda f: _tilt_input(f)[0], lambda f: _tilt_input(f)[1],
                      lambda f: _body_velocity(f)[0], lambda f: _body_velocity(f)[1])
    x, s, fits, cost = fit_channel(chans, _drag_model, [GRAVITY_MPS2, 0.5] * 2 + [0.0, 0.0],
                                   lower=[1.0, 0.02, 1.0, 0.02, -1.0, -1.0],
                                   upper=[30.0, 5.0, 30.0, 5.0, 1.0, 1.0],
                                   x_scale=[1.0, 0.1, 1.0, 0.1, 0.05, 0.05])
    params = {"accel_forward": Param("forward acceleration per unit tan(pitch)", x[0], s[0],
                                     "m/s²"),
              "drag_forward": Param("forward drag pole", x[1], s[1], "1/s"),
              "accel_left": Param("left acceleration per unit tan(roll)", x[2], s[2], "m/s²"),
              "drag_left": Param("left drag pole", x[3], s[3], "1/s")}
    return FitResult(params, fits, cost, "drag")


# ----------------------------------------------------------------------------- vertical, yaw
def _fit_lag(flights: Sequence[Flight], column: int, output, delay_s: float, limit_of,
             sign: float, names: tuple[str, str], unit: str) -> FitResult:
    chans = _channels(flights, lambda f: f.t_cmd,
                      lambda f: sign * limit_of(f) * f.cmd[:, column:column + 1],
                      lambda f: output(f)[0], lambda f: output(f)[1])

    def model(p: np.ndarray, ch: Channel) -> np.ndarray:
        gain, tau, bias = p
        return (gain * simulate([1.0], [tau, 1.0], ch.t_in, ch.u[:, 0], ch.t_out, delay_s)
                + bias)[:, None]

    x, s, fits, cost = fit_channel(chans, model, [1.0, 0.2, 0.0], lower=[0.05, 0.005, -1.0],
                                   upper=[5.0, 3.0, 1.0], x_scale=[0.1, 0.05, 0.01])
    return FitResult({"gain": Param(names[0], x[0], s[0], unit),
                      "tau": Param(names[1], x[1], s[1], "s")}, fits, cost, "lag")


def fit_vertical(flights: Sequence[Flight], delay_s: float) -> FitResult:
    """PCMD gaz → climb rate: its gain relative to control_vz_max and its lag."""
    def climb(f: Flight) -> tuple[np.ndarray, np.ndarray]:
        t, v = differentiate(f.t_pose, f.pose[:, 2])
        return t, v[:, None]

    return _fit_lag(flights, 2, climb, delay_s, lambda f: f.control_vz_max_mps, 1.0,
                    ("vertical gain", "vertical lag τ"), "× control_vz_max")


def fit_yaw(flights: Sequence[Flight], delay_s: float) -> FitResult:
    """PCMD yaw → turn rate (counter-clockwise; PCMD yaw > 0 turns clockwise): its gain
    relative to control_yaw and its lag."""
    def turn(f: Flight) -> tuple[np.ndarray, np.ndarray]:
        t, r = differentiate(f.t_pose, f.pose[:, 3])
        return t, r[:, None]

    return _fit_lag(flights, 3, turn, delay_s, lambda f: f.control_yaw_radps, -1.0,
                    ("yaw gain", "yaw lag τ"), "× control_yaw")
