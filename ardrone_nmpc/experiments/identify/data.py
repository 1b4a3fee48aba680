"""What ``identify`` fits on: a run's logged commands, navdata and mocap, as time series.

Every series is on the run's experiment clock: a command at its tick time ``t_s`` (when it
was sent), a navdata sample at ``t_s − navdata_age_ms`` (its receipt), a mocap pose at
``t_s − mocap_age_ms`` (its stamp as the tick saw it); a sample seen by several ticks counts
once. Only the ticks the controller flew count as commands (mode ``track`` or ``settle``): a
hover, a hold or a landing is not what the drone was told to fly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_rad

__all__ = ["Flight", "IdentifyError", "read_flight", "series"]

_FLOWN = ("track", "settle")


class IdentifyError(ValueError):
    """A run that cannot be identified from (one line)."""


@dataclass(frozen=True)
class Flight:
    """One run's series (module docstring) and the limits its drone held.

    ``segments`` are the (start, end) times (s) of the stretches the controller flew without
    a break; a fit never carries a state across a break.
    """

    name: str
    t_cmd: np.ndarray            # (n,)
    cmd: np.ndarray              # (n, 4) roll, pitch, gaz, yaw PCMD fractions
    t_nav: np.ndarray            # (m,)
    nav_tilt_rad: np.ndarray     # (m, 2) roll, pitch (drone signs)
    t_pose: np.ndarray           # (p,)
    pose: np.ndarray             # (p, 4) x, y, z (m), ψ (rad, unwrapped)
    segments: tuple[tuple[float, float], ...]
    euler_angle_max_rad: float
    control_vz_max_mps: float
    control_yaw_radps: float


def _unique(t: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ok = np.isfinite(t) & np.all(np.isfinite(values.reshape(len(t), -1)), axis=1)
    t, values = t[ok], values[ok]
    t, first = np.unique(t, return_index=True)
    return t, values[first]


def _segments(t: np.ndarray, flown: np.ndarray, period_s: float) -> list[tuple[float, float]]:
    out, start = [], None
    for i, (ti, f) in enumerate(zip(t, flown)):
        if f and start is None:
            start = ti
        if start is not None and (not f or i == len(t) - 1
                                  or t[i + 1] - ti > 1.5 * period_s):
            end = ti if f else t[i - 1]
            if end - start > 2.0:
                out.append((float(start), float(end)))
            start = None
    return out


def series(name: str, columns, drone, period_s: float) -> Flight:
    """A :class:`Flight` of a run's log columns and its ``drone`` config section."""
    c = columns
    t = np.asarray(c["t_s"], dtype=float)
    mode = np.array(["" if not isinstance(m, str) else m for m in c["mode"]], dtype=object)
    flown = np.isin(mode, _FLOWN) & np.isfinite(t)
    cmd = np.column_stack([np.asarray(c[f"cmd_{a}_frac"], dtype=float)
                           for a in ("roll", "pitch", "gaz", "yaw")])
    flown &= np.all(np.isfinite(cmd), axis=1)
    t_nav, nav = _unique(t - np.asarray(c["navdata_age_ms"], float) * 1e-3,
                         np.radians(np.column_stack([c["nav_roll_deg"], c["nav_pitch_deg"]])))
    pose_cols = np.column_stack([c["x_m"], c["y_m"], c["z_m"], c["psi_rad"]]).astype(float)
    t_pose, pose = _unique(t - np.asarray(c["mocap_age_ms"], float) * 1e-3, pose_cols)
    if len(pose):
        pose[:, 3] = pose[0, 3] + np.cumsum(np.r_[0.0, wrap_angle_rad(np.diff(pose[:, 3]))])
    segments = _segments(t, flown, period_s)
    if not segments or len(t_nav) < 30 or len(t_pose) < 30:
        raise IdentifyError(f"{name}: too little flown with navdata and mocap to identify "
                            "from (fly configs/identify.yaml)")
    return Flight(name, t[flown], cmd[flown], t_nav, nav, t_pose, pose, tuple(segments),
                  drone.euler_angle_max_rad, drone.control_vz_max_mps, drone.control_yaw_radps)


def read_flight(run_dir: str | Path) -> Flight:
    """The :class:`Flight` of a run directory. Raises :class:`IdentifyError`."""
    from ardrone_nmpc.runs.rundir import LogError, read_run

    try:
        run = read_run(run_dir)
    except LogError as err:
        raise IdentifyError(str(err)) from None
    return series(Path(run_dir).name, run.columns, run.config.drone, run.config.loop.period_s)


def held_out(t: np.ndarray, block_s: float = 2.5, every: int = 4) -> np.ndarray:
    """True for the samples of every ``every``-th block of ``block_s`` seconds: the part of a
    record a fit does not see and is judged on."""
    return (np.floor(np.asarray(t) / block_s).astype(int) % every) == every - 1


def differentiate(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central differences of ``y`` (n, …) over ``t`` at the midpoints' neighbours:
    (t[1:-1], (y[2:] − y[:-2])/(t[2:] − t[:-2]))."""
    if len(t) < 3:
        return np.zeros(0), np.zeros((0, *np.shape(y)[1:]))
    dt = (t[2:] - t[:-2]).reshape(-1, *([1] * (np.ndim(y) - 1)))
    return t[1:-1], (y[2:] - y[:-2]) / np.where(dt > 0, dt, math.inf)
