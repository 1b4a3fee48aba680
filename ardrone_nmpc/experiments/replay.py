"""``replay``: a recorded run fed back through the tick, or re-sent as a live pose stream.

The same :class:`~ardrone_nmpc.runtime.tick.Tick` serves ``fly``, ``simulate`` and
``replay --rerun``; only the clock and the links change. Here the clock is manual — the
experiment clock of the log itself (``t_s``) — and the "links" are the logged measurements
(``log.csv`` columns written by :func:`~ardrone_nmpc.runs.log_columns.measurement_columns`,
decoded by :func:`~ardrone_nmpc.runs.log_columns.tick_inputs_of_rows`):

* the mocap pose: ``x_m, y_m, z_m, psi_rad`` (the pose's position and ψ, exactly), its own time
  ``mocap_t_s`` and its age ``mocap_age_ms`` at the tick;
* the navdata sample: ``nav_vx_body_mps, nav_vy_body_mps, battery_pct, nav_mode`` and its age
  ``navdata_age_ms``.

What is *not* logged, and what the replay puts in its place: the pose's roll and pitch (0 —
the tick only uses position and ψ); navdata attitude (``nav_roll_deg``/``nav_pitch_deg`` if a
log has them, else NaN: the supervisor's measured-tilt check then never fires), yaw,
altitude and vertical speed (NaN, so a consumer that starts using them shows up instead of
silently reading zeros).

Functions
---------
:func:`rows_to_inputs` rebuilds the :class:`~ardrone_nmpc.core.types.TickInputs` of every row;
:func:`rerun` steps a fresh tick through them and compares the commands; :func:`broadcast`
re-sends the logged poses as the UDP pose stream (docs/mocap-stream.md).
"""

from __future__ import annotations

import math
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ardrone_nmpc.control.diverging import diverging_wrapper
from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.types import IX_PSI, MocapPose
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap
from ardrone_nmpc.reference.experiment import experiment_trajectory
from ardrone_nmpc.runs.log_columns import (
    RERUN_COLUMNS, SAME_POSE_TOLERANCE_S, ReplayError, pose_of_row, tick_inputs_of_rows,
    unlogged_pose,
)
from ardrone_nmpc.runs.rundir import LOG_FILE, RunData, format_number
from ardrone_nmpc.runs.window import experiment_rows
from ardrone_nmpc.runtime.schedule import phase, write_events
from ardrone_nmpc.core.types import TickInputs
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.safety import Action
from ardrone_nmpc.sim.faults import FaultSchedule

__all__ = [
    "CMD_COLUMNS", "COMPARED_COLUMNS", "INPUT_COLUMNS", "RERUN_COLUMNS", "RERUN_FILE",
    "SAME_POSE_TOLERANCE_S", "BroadcastResult", "ReplayError", "RerunCost", "RerunResult",
    "broadcast", "logged_poses", "missing_rerun_columns", "require_rerun_columns", "rerun",
    "rows_to_inputs", "write_rerun_csv",
]

CMD_COLUMNS = ("cmd_roll_frac", "cmd_pitch_frac", "cmd_gaz_frac", "cmd_yaw_frac")
INPUT_COLUMNS = ("u_zacc_mps2", "u_phi_rad", "u_theta_rad", "u_psirate_radps")
COMPARED_COLUMNS = CMD_COLUMNS + INPUT_COLUMNS
#: The per-tick differences written next to the recomputed ``log.csv``.
RERUN_FILE = "rerun.csv"

_STATE_COLUMNS = ("x_m", "vx_mps", "y_m", "vy_mps", "z_m", "vz_mps", "psi_rad")


# ----------------------------------------------------------------------------- inputs


def missing_rerun_columns(*, run: RunData) -> list[str]:
    """The :data:`RERUN_COLUMNS` the run's ``log.csv`` header lacks (older versions).

    :func:`~ardrone_nmpc.runs.rundir.read_run` fills absent columns with NaN, which a run that
    never saw a pose would also show, so the header itself is read. A ``RunData`` built in
    memory (no ``log.csv`` on disk) counts as complete.
    """
    log = Path(run.path) / LOG_FILE
    try:
        with open(log, encoding="utf-8") as f:
            header = {c.strip() for c in f.readline().split(",")}
    except OSError:
        return [c for c in RERUN_COLUMNS if c not in run.columns]
    return [c for c in RERUN_COLUMNS if c not in header]


def require_rerun_columns(*, run: RunData) -> None:
    """Raise :class:`ReplayError` naming the :data:`RERUN_COLUMNS` the log lacks, if any."""
    missing = missing_rerun_columns(run=run)
    if missing:
        raise ReplayError(f"{run.path}: log.csv has no {', '.join(missing)} column"
                          f"{'s' if len(missing) > 1 else ''} (written by an older version): "
                          f"it can be re-summarised, not re-run")


def rows_to_inputs(*, run: RunData) -> list[TickInputs]:
    """The :class:`TickInputs` of every logged tick, on the experiment clock
    (:func:`~ardrone_nmpc.runs.log_columns.tick_inputs_of_rows`).

    Raises
    ------
    ReplayError
        The log lacks :data:`RERUN_COLUMNS`, or a ``nav_mode`` cell is not a flight mode.
    """
    require_rerun_columns(run=run)
    return tick_inputs_of_rows(run.columns, run.n_rows)


# ----------------------------------------------------------------------------- rerun


@dataclass(frozen=True)
class RerunCost:
    """The NMPC stage cost of thesis eq. 3.14, summed over the experiment's ticks.

    ``Σ_k ½ (x_k − x_d(t_k))ᵀ q (x_k − x_d(t_k)) + ½ u_kᵀ r u_k`` · period (cost·s), q and r
    from the *rerun* config, x_k the **logged** state estimates, x_d the rerun config's
    reference (velocities included), u_k the logged or the recomputed input.

    Open-loop counterfactual: the logged states did not respond to the recomputed inputs, so
    the state part is shared and only the input part differs — it prices the new commands on
    the old flight, it does not predict how the new controller would have flown. Rows
    without a state estimate (stale-mocap hover) are left out; a NaN input (the P controller
    logs no z̈, a hover row none at all) counts as 0 — no commanded acceleration.

    Attributes
    ----------
    rows : ticks summed (t_s ≥ 0 with a state; all ticks with a state if none has t_s ≥ 0).
    state : the shared state part (cost·s).
    input_logged, input_rerun : the input parts (cost·s).
    """

    rows: int
    state: float
    input_logged: float
    input_rerun: float

    @property
    def logged(self) -> float:
        """Total with the logged inputs (cost·s)."""
        return self.state + self.input_logged

    @property
    def rerun(self) -> float:
        """Total with the recomputed inputs (cost·s)."""
        return self.state + self.input_rerun


@dataclass
class RerunResult:
    """What :func:`rerun` recomputed and how it differs from the log.

    Attributes
    ----------
    t_s : (n,) tick times (s, experiment clock).
    rows : the recomputed log rows (as :meth:`Tick.step` made them).
    logged : column → (n,) logged values, for :data:`COMPARED_COLUMNS`.
    recomputed : column → (n,) recomputed values (NaN where the tick logged none).
    diff : column → (n,) recomputed − logged; 0 where both are NaN, ±inf where only one is
        (one side commanded, the other hovered).
    max_abs_diff : column → max |diff| (0 for an empty run).
    logged_mode, mode : (n,) the logged and recomputed ``mode`` per tick.
    cost : :class:`RerunCost`.
    unlogged_pose_rows : ticks whose pose was new but whose position was not logged (a
        stale-mocap hover of an older tick): replayed with the previous pose, ageing.
    """

    t_s: np.ndarray
    rows: list[dict]
    logged: dict[str, np.ndarray]
    recomputed: dict[str, np.ndarray]
    diff: dict[str, np.ndarray]
    max_abs_diff: dict[str, float]
    logged_mode: np.ndarray
    mode: np.ndarray
    cost: RerunCost
    unlogged_pose_rows: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def mode_mismatches(self) -> int:
        """Ticks whose recomputed mode differs from the logged one."""
        return int(np.sum(self.logged_mode != self.mode))

    @property
    def max_abs_diff_overall(self) -> float:
        return max(self.max_abs_diff.values(), default=0.0)


def _difference(recomputed: np.ndarray, logged: np.ndarray) -> np.ndarray:
    """recomputed − logged; both NaN → 0 (neither side had a value), one NaN → inf."""
    with np.errstate(invalid="ignore"):
        diff = recomputed - logged
    r_nan, l_nan = np.isnan(recomputed), np.isnan(logged)
    diff[r_nan & l_nan] = 0.0
    diff[r_nan ^ l_nan] = math.inf
    return diff


def _cost(*, cfg, trajectory, t_s: np.ndarray, states: np.ndarray, u_logged: np.ndarray,
          u_rerun: np.ndarray) -> RerunCost:
    """:class:`RerunCost` of ``states`` (n, 7) with both input histories (n, 4)."""
    ctl = cfg.controller
    q, r = np.asarray(ctl.q, float), np.asarray(ctl.r, float)
    window = experiment_rows(t_s, among=np.all(np.isfinite(states), axis=1))
    if not window.any():
        return RerunCost(0, 0.0, 0.0, 0.0)
    err = states[window] - trajectory.state_at(t_s[window])
    err[:, IX_PSI] = wrap_angle_rad(err[:, IX_PSI])  # as OcpSpec.stage_cost
    period = cfg.loop.period_s

    def input_part(u: np.ndarray) -> float:
        u = np.nan_to_num(u[window], nan=0.0)
        return 0.5 * float(np.sum(u * u * r)) * period

    return RerunCost(int(window.sum()), 0.5 * float(np.sum(err * err * q)) * period,
                     input_part(u_logged), input_part(u_rerun))


def _column(rows: list[dict], name: str) -> np.ndarray:
    return np.array([float(row.get(name, math.nan)) for row in rows], dtype=float)


def rerun(*, run: RunData, cfg, recorder=None,
          progress: Callable[[float], None] | None = None) -> RerunResult:
    """Feed the run's logged measurements through a fresh :class:`Tick` built from ``cfg``.

    Every row from the first is fed in order (the estimators and the NMPC warm start carry
    state), with the mode label the flight used ("settle" before t = 0, "track" after; a row
    the runner relabelled "landing" keeps that label when the tick has latched land/stop too).
    With the run's own config the commands are reproduced to float round-off; with a changed
    one they are the counterfactual commands on the same measurements.

    Parameters
    ----------
    run : the recorded run (:func:`~ardrone_nmpc.runs.rundir.read_run`).
    cfg : the configuration to recompute with (``run.config``, possibly with overrides).
    recorder : a :class:`~ardrone_nmpc.runs.rundir.RunRecorder` receiving the recomputed rows.
    progress : called with the fraction done after each tick.

    Raises
    ------
    ReplayError
        The log lacks the measurement columns (an older version) or holds no rows.
    """
    inputs = rows_to_inputs(run=run)
    if not inputs:
        raise ReplayError(f"{run.path}: log.csv holds no ticks")
    trajectory = experiment_trajectory(cfg)
    # the run's injected solver divergence, as the simulating runner that flew it wrapped it
    tick = Tick(cfg, trajectory,
                wrap_solver=diverging_wrapper(FaultSchedule(cfg.faults).solver_divergence))
    logged_mode = run.columns["mode"]
    rows: list[dict] = []
    for k, inp in enumerate(inputs):
        # manual clock = the experiment clock: the tick's clock offset is 0
        out = tick.step(inp, t_exp_s=inp.t_s, mode=phase(inp.t_s))
        if logged_mode[k] == "landing" and out.action in (Action.LAND, Action.STOP):
            out.row["mode"] = "landing"  # the runner's label for its descent after a landing
        rows.append(out.row)
        if recorder is not None:
            recorder.write_row(out.row)
            # the supervisor's mode changes, as the flight wrote them
            write_events(recorder.event, inp.t_s, out.events)
        if progress is not None:
            progress((k + 1) / len(inputs))
    if cfg.reference.kind == "follow":  # live: price against what the rerun tick followed
        trajectory = _RowReference(rows)
    return _compare(run=run, cfg=cfg, trajectory=trajectory, inputs=inputs, rows=rows)


class _RowReference:
    """The reference the rerun ticks logged (positions and ψ; velocities 0), as a trajectory
    — for kind ``follow``, whose reference exists only tick by tick."""

    def __init__(self, rows: list[dict]) -> None:
        self._t = _column(rows, "t_s")
        self._ref = np.column_stack([_column(rows, c) for c in
                                     ("x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad")])

    def state_at(self, t_s) -> np.ndarray:
        idx = np.clip(np.searchsorted(self._t, np.atleast_1d(t_s)), 0, len(self._t) - 1)
        out = np.zeros((idx.size, 7))
        out[:, [0, 2, 4, 6]] = self._ref[idx]
        return out


def _compare(*, run: RunData, cfg, trajectory, inputs: list[TickInputs],
             rows: list[dict]) -> RerunResult:
    """Differences per compared column, the cost, and the bookkeeping of :func:`rerun`."""
    cols = run.columns
    logged = {c: np.asarray(cols[c], dtype=float) for c in COMPARED_COLUMNS}
    recomputed = {c: _column(rows, c) for c in COMPARED_COLUMNS}
    diff = {c: _difference(recomputed[c], logged[c]) for c in COMPARED_COLUMNS}
    max_abs = {c: float(np.max(np.abs(d))) if d.size else 0.0 for c, d in diff.items()}
    t_s = np.asarray(cols["t_s"], dtype=float)
    states = np.column_stack([np.asarray(cols[c], dtype=float) for c in _STATE_COLUMNS])
    cost = _cost(cfg=cfg, trajectory=trajectory, t_s=t_s, states=states,
                 u_logged=np.column_stack([logged[c] for c in INPUT_COLUMNS]),
                 u_rerun=np.column_stack([recomputed[c] for c in INPUT_COLUMNS]))
    unlogged = sum(1 for i, inp in enumerate(inputs) if unlogged_pose(cols, i, inp.pose))
    mode = np.array([str(row.get("mode", "")) for row in rows], dtype=object)
    return RerunResult(t_s=t_s, rows=rows, logged=logged, recomputed=recomputed, diff=diff,
                       max_abs_diff=max_abs, logged_mode=np.asarray(cols["mode"], dtype=object),
                       mode=mode, cost=cost, unlogged_pose_rows=unlogged,
                       notes=list(run.warnings))


def write_rerun_csv(*, result: RerunResult, path: Path) -> Path:
    """Write the per-tick differences: ``t_s, logged_mode, mode, d_<column>…`` (recomputed −
    logged, numbers as in ``log.csv``). Returns ``path``."""
    header = ["t_s", "logged_mode", "mode"] + [f"d_{c}" for c in COMPARED_COLUMNS]
    lines = [",".join(header)]
    for i, t in enumerate(result.t_s):
        cells = [format_number(t), str(result.logged_mode[i]), str(result.mode[i])]
        cells += [format_number(result.diff[c][i]) for c in COMPARED_COLUMNS]
        lines.append(",".join(cells))
    path = Path(path)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


# ----------------------------------------------------------------------------- broadcast


@dataclass(frozen=True)
class BroadcastResult:
    """What :func:`broadcast` sent.

    Attributes
    ----------
    frames : datagrams sent (one per distinct logged pose).
    skipped : distinct poses not sent because their position was not logged.
    span_s : logged time from the first to the last pose sent (s).
    target : (host, port) sent to.
    """

    frames: int
    skipped: int
    span_s: float
    target: tuple[str, int]


def logged_poses(*, run: RunData) -> tuple[list[MocapPose], int]:
    """The distinct poses the run's ticks saw, in order, and how many had no logged position.

    Times are ``mocap_t_s`` (their differences are the stream's timing). Needs the
    ``mocap_t_s`` column (:class:`ReplayError` otherwise).
    """
    if "mocap_t_s" in missing_rerun_columns(run=run):
        raise ReplayError(f"{run.path}: log.csv has no mocap_t_s column (written by an older "
                          f"version): the pose timing is unknown, nothing to broadcast")
    cols = run.columns
    poses: list[MocapPose] = []
    unlogged_times: list[float] = []
    pose = None
    for i in range(run.n_rows):
        new = pose_of_row(cols, i, pose)
        if unlogged_pose(cols, i, new):
            t = float(cols["mocap_t_s"][i])
            if not unlogged_times or abs(t - unlogged_times[-1]) > SAME_POSE_TOLERANCE_S:
                unlogged_times.append(t)
        elif new is not None and new is not pose:
            poses.append(new)
        pose = new
    return poses, len(unlogged_times)


def _target(host: str, port: int, allow_remote: bool) -> tuple[str, int]:
    from ardrone_nmpc.sim.drone_server import require_loopback_host

    if not allow_remote:  # only an explicit --host leaves this machine
        host = require_loopback_host(host, "broadcast host")
    port = int(port)
    if not 1 <= port <= 65535:
        raise ReplayError(f"--port: {port} is not a UDP port (1..65535)")
    return host, port


def broadcast(*, run: RunData, port: int, host: str = "127.0.0.1", speed: float = 1.0,
              object_name: str | None = None, allow_remote: bool = False,
              clock: Callable[[], float] = time.monotonic,
              sleep: Callable[[float], None] = time.sleep,
              progress: Callable[[float], None] | None = None) -> BroadcastResult:
    """Re-send the run's logged poses as the mocap UDP stream (docs/mocap-stream.md).

    One datagram per distinct logged pose (a pose seen on several ticks is sent once), at its
    logged time (``mocap_t_s`` spacing) divided by ``speed``, on absolute deadlines from the
    first. The log holds the pose each *tick* used (≈ 15 Hz), not every mocap frame, so that is
    the stream's rate; frame numbers count the datagrams (1, 2, …: no gaps). Roll and pitch
    are not logged and are sent as 0 (ψ as the rotation about z).

    Parameters
    ----------
    run : the recorded run. port : UDP port (1..65535). host : target address; must be a
        loopback address unless ``allow_remote`` (the CLI sets it for an explicit ``--host``).
    speed : playback speed factor (> 0; 2 = twice as fast). object_name : the pose item's
        name (default: the run config's ``mocap.object_name``).
    clock, sleep : monotonic seconds and the sleep used for the deadlines (tests).
    progress : called with the fraction of the poses sent.

    Raises
    ------
    ValueError
        A non-loopback host without ``allow_remote``, a bad port or speed, a log without
        ``mocap_t_s`` (:class:`ReplayError`). OSError from the socket.
    """
    if not (math.isfinite(speed) and speed > 0):
        raise ReplayError(f"--speed: must be a positive number, got {speed!r}")
    target = _target(host, port, allow_remote)
    name = object_name or run.config.mocap.object_name
    poses, skipped = logged_poses(run=run)
    datagrams = [_datagram(pose, frame, name) for frame, pose in enumerate(poses, start=1)]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        t0 = clock()
        for k, (pose, data) in enumerate(zip(poses, datagrams)):
            wait = t0 + (pose.t_s - poses[0].t_s) / speed - clock()
            if wait > 0:
                sleep(wait)
            sock.sendto(data, target)
            if progress is not None:
                progress((k + 1) / len(poses))
    span = poses[-1].t_s - poses[0].t_s if poses else 0.0
    return BroadcastResult(len(poses), skipped, span, target)


def _datagram(pose: MocapPose, frame: int, name: str) -> bytes:
    """One pose as the wire datagram (millimetres, rotation (0, 0, ψ))."""
    item = MocapObjectPose.from_si(name, pose.position_m, (0.0, 0.0, pose.psi_rad))
    return encode_mocap(MocapFrame.of(frame & 0xFFFFFFFF, [item]))
