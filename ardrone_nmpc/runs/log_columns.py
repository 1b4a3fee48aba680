"""The columns of ``log.csv`` — name, unit, meaning — with the builders that fill a row and the
decoder that turns logged rows back into what the tick saw (docs/design.md §5).

One home: the recorder (:mod:`~ardrone_nmpc.runs.rundir`) writes and reads these columns; the
tick fills them through :func:`tick_row` (with :func:`measurement_columns`, the raw
measurements); a simulating runner adds :func:`truth_columns`, the real-time runner
:func:`link_columns`; ``replay --rerun`` rebuilds each tick's
:class:`~ardrone_nmpc.core.types.TickInputs` from them (:func:`tick_inputs_of_rows`). The
builders read the tick's stage results by attribute (they live in the runtime, a layer above).
"""

from __future__ import annotations

import math
import operator
from typing import NamedTuple

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.types import (
    IU_PHI, IU_PSIRATE, IU_THETA, IU_ZACC, IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z,
    FlightMode, MocapPose, NavdataSample, TickInputs,
)
from ardrone_nmpc.errors import UserError
from ardrone_nmpc.runs.block_row import (BR_BATTERY, BR_COMPUTE_US, BR_GMRES, BR_MOCAP_MS,
                                          BR_MOCAP_T, BR_NAV_MS, BR_NAV_PITCH, BR_NAV_ROLL,
                                          BR_NEWTON, BR_NORM, BR_SATURATED, BR_SOLVE_US,
                                          BR_TARGET_AGE, BR_TARGET_X, BR_TRUE_PSI,
                                          BR_TRUE_VZ, BR_TRUE_X, BR_TRUE_Y, BR_TRUE_Z)
from ardrone_nmpc.safety import Action

_FALLBACK = Action.FALLBACK  # bound once: an enum member's lookup costs ~0.1 µs

__all__ = ["COLUMNS", "Column", "LOG_COLUMNS", "REQUIRED_COLUMNS", "RERUN_COLUMNS",
           "ReplayError", "SAME_POSE_TOLERANCE_S", "STRING_COLUMNS", "UNITS", "link_columns",
           "pose_of_row", "unlogged_pose",
           "measurement_columns", "put_truth", "tick_inputs_of_rows", "tick_row",
           "truth_columns", "MODE_CELL", "TICK_CELL_KEYS", "TRUTH_CELLS", "block_cells", "cells_row",
           "nominal_cells", "put_truth_cells", "tick_cell_values", "tick_cells"]


class Column(NamedTuple):
    """One ``log.csv`` column: its name (unit in the name), the unit alone, what it holds."""

    name: str
    unit: str
    meaning: str


#: The columns of ``log.csv``, in order. ``*_ref_*`` is the reference at the tick, ``u_*`` the
#: controller's input, ``cmd_*`` the PCMD fractions sent, ``*_true_*`` the simulated plant's
#: truth (empty in real flight). The raw measurements (``mocap_t_s`` … ``nav_pitch_deg``,
#: ``target_*``) are what ``replay --rerun`` feeds through the tick again.
COLUMNS: tuple[Column, ...] = (
    Column("t_s", "s", "experiment time of the tick (negative while settling)"),
    Column("x_m", "m", "estimated x (mocap)"),
    Column("y_m", "m", "estimated y (mocap)"),
    Column("z_m", "m", "estimated z (mocap)"),
    Column("psi_rad", "rad", "estimated heading ψ (mocap)"),
    Column("vx_mps", "m/s", "estimated ẋ"),
    Column("vy_mps", "m/s", "estimated ẏ"),
    Column("vz_mps", "m/s", "estimated ż (Kalman / Luenberger)"),
    Column("x_ref_m", "m", "reference x at the tick"),
    Column("y_ref_m", "m", "reference y at the tick"),
    Column("z_ref_m", "m", "reference z at the tick"),
    Column("psi_ref_rad", "rad", "reference ψ at the tick"),
    Column("u_zacc_mps2", "m/s²", "controller input z̈"),
    Column("u_phi_rad", "rad", "controller input φ"),
    Column("u_theta_rad", "rad", "controller input θ"),
    Column("u_psirate_radps", "rad/s", "controller input ψ̇"),
    Column("vz_ref_mps", "m/s", "ż reference flown"),
    Column("cmd_roll_frac", "1", "PCMD roll fraction sent"),
    Column("cmd_pitch_frac", "1", "PCMD pitch fraction sent"),
    Column("cmd_gaz_frac", "1", "PCMD gaz fraction sent"),
    Column("cmd_yaw_frac", "1", "PCMD yaw fraction sent"),
    Column("cmd_saturated", "", "saturation flags roll, pitch, gaz, yaw (0/1 each)"),
    Column("solve_us", "µs", "NMPC solve time"),
    Column("solver_status", "", "ok, max-iterations, diverged, non-finite (empty: no solve)"),
    Column("residual_norm", "1", "‖F‖ of the optimality conditions"),
    Column("gmres_iterations", "1", "Krylov iterations this tick"),
    Column("newton_iterations", "1", "Newton steps this tick"),
    Column("mode", "", "the supervisor's verdict (settle, track, hold-…, land-…, landing …)"),
    Column("mocap_age_ms", "ms", "age of the newest mocap pose at the tick"),
    Column("navdata_age_ms", "ms", "age of the newest navdata at the tick"),
    Column("battery_pct", "%", "battery level (navdata)"),
    Column("tick_late_ms", "ms", "lateness of the tick's wake-up (fly)"),
    Column("compute_us", "µs", "time spent in the tick"),
    Column("mocap_t_s", "s", "the pose's own stamp on the link's clock"),
    Column("nav_vx_body_mps", "m/s", "navdata forward velocity (body frame)"),
    Column("nav_vy_body_mps", "m/s", "navdata right velocity (body frame)"),
    Column("nav_mode", "", "the drone's flight mode in its newest navdata"),
    Column("nav_roll_deg", "°", "navdata roll"),
    Column("nav_pitch_deg", "°", "navdata pitch"),
    Column("nav_state_bits", "1", "the state word of that navdata (its fault bits: the "
           "supervisor reads them)"),
    Column("nav_ctrl_state", "1", "raw ctrl_state word of that navdata (fly)"),
    Column("target_x_m", "m", "followed object x"),
    Column("target_y_m", "m", "followed object y"),
    Column("target_z_m", "m", "followed object z"),
    Column("target_psi_rad", "rad", "followed object ψ"),
    Column("target_t_s", "s", "followed object's pose stamp"),
    Column("target_age_ms", "ms", "followed object's pose age at the tick"),
    Column("x_true_m", "m", "simulated truth x"),
    Column("y_true_m", "m", "simulated truth y"),
    Column("z_true_m", "m", "simulated truth z"),
    Column("psi_true_rad", "rad", "simulated truth ψ"),
    Column("vz_true_mps", "m/s", "simulated truth ż"),
)
LOG_COLUMNS: tuple[str, ...] = tuple(c.name for c in COLUMNS)
UNITS: dict[str, str] = {c.name: c.unit for c in COLUMNS}

#: Columns holding strings: ``cmd_saturated`` (4 flags ``0``/``1``, roll, pitch, gaz, yaw),
#: ``solver_status`` (``ok``, ``max-iterations``, …; empty without a solve), ``mode`` (the
#: supervisor's verdict) and ``nav_mode`` (the drone's flight mode from its newest navdata).
STRING_COLUMNS: frozenset[str] = frozenset({"cmd_saturated", "solver_status", "mode",
                                            "nav_mode"})

#: Columns a ``log.csv`` header must name (docs/design.md); the others of :data:`LOG_COLUMNS`
#: are filled with NaN (or ``""``) by :func:`~ardrone_nmpc.runs.rundir.read_run` when absent.
REQUIRED_COLUMNS: tuple[str, ...] = (
    "t_s", "x_m", "y_m", "z_m", "psi_rad", "vx_mps", "vy_mps", "vz_mps",
    "x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad",
    "u_zacc_mps2", "u_phi_rad", "u_theta_rad", "u_psirate_radps",
    "cmd_roll_frac", "cmd_pitch_frac", "cmd_gaz_frac", "cmd_yaw_frac",
    "solve_us", "solver_status", "mode", "mocap_age_ms", "navdata_age_ms", "battery_pct",
)

#: Columns a log needs beyond the required ones for ``replay --rerun`` (added with the raw
#: measurements).
RERUN_COLUMNS: tuple[str, ...] = ("mocap_t_s", "nav_vx_body_mps", "nav_vy_body_mps",
                                  "nav_mode")


# ----------------------------------------------------------------------------- builders
def measurement_columns(inputs: TickInputs) -> dict:
    """The raw measurements of ``inputs`` as log columns (replay feeds them back).

    ``mocap_t_s`` is the pose's own time stamp as the tick saw it (the link's clock: receipt
    time in ``fly``, plant time in simulation), bit for bit: the estimators difference it, and
    moved to the experiment clock it would carry the tick's offset (rounding; in ``fly`` its
    lateness) into those differences.
    """
    nav = inputs.navdata
    pose = inputs.pose
    return {
        "mocap_t_s": pose.t_s if pose is not None else math.nan,
        "battery_pct": nav.battery_pct if nav is not None else math.nan,
        "nav_vx_body_mps": nav.vx_body_mps if nav is not None else math.nan,
        "nav_vy_body_mps": nav.vy_body_mps if nav is not None else math.nan,
        "nav_mode": nav.mode.value if nav is not None else "",
        "nav_roll_deg": nav.roll_deg if nav is not None else math.nan,
        "nav_pitch_deg": nav.pitch_deg if nav is not None else math.nan,
        "nav_state_bits": (nav.state_bits if nav is not None and nav.state_bits is not None
                           else math.nan),
    } | _target_columns(inputs)


def _target_columns(inputs: TickInputs) -> dict:
    target = inputs.target
    if target is None:
        return {}
    p = target.position_m
    return {"target_x_m": p[0], "target_y_m": p[1], "target_z_m": p[2],
            "target_psi_rad": target.psi_rad, "target_t_s": target.t_s,
            "target_age_ms": (inputs.t_s - inputs.target_rx_t_s) * 1e3}


def _solution_columns(sol) -> dict:
    ref = sol.ref_now
    cols = {"x_ref_m": ref[IX_X], "y_ref_m": ref[IX_Y], "z_ref_m": ref[IX_Z],
            "psi_ref_rad": ref[IX_PSI]}
    result = sol.result
    if result is None:  # the P controller: no z̈
        cmd = sol.p_command
        return cols | {"u_zacc_mps2": math.nan, "u_phi_rad": cmd.phi_rad,
                       "u_theta_rad": cmd.theta_rad, "u_psirate_radps": cmd.psirate_radps}
    u = result.u  # as solved, also when the supervisor flies something else
    return cols | {"u_zacc_mps2": u[IU_ZACC], "u_phi_rad": u[IU_PHI], "u_theta_rad": u[IU_THETA],
                   "u_psirate_radps": u[IU_PSIRATE], "solve_us": result.solve_time_us,
                   "residual_norm": result.residual_norm,
                   "gmres_iterations": result.gmres_iterations,
                   "newton_iterations": result.newton_iterations}


def tick_row(*, t_exp_s: float, inputs: TickInputs, ages_ms: tuple[float, float],
             x: np.ndarray | None, solution, sent, mode: str, compute_us: float) -> dict:
    """The tick's ``log.csv`` row.

    ``x`` is the estimate (None without a pose), ``solution`` the controller's
    (:class:`~ardrone_nmpc.runtime.stages.Solution`; None when the supervisor stopped the
    tick before it), ``sent`` what went out (:class:`~ardrone_nmpc.runtime.stages.Sent`),
    ``mode`` the label.
    """
    nav, result = inputs.navdata, solution.result if solution is not None else None
    flown = sent.flown
    if (result is not None and x is not None and nav is not None and inputs.pose is not None
            and inputs.target is None and flown is not None
            and sent.decision.action is not _FALLBACK):
        # the usual NMPC tick: one literal, the keys in the general path's order (the
        # recorder plans per key sequence); x, ref, u as Python floats (the same float64s)
        xs, ref, u, pcmd = x.tolist(), solution.ref_now.tolist(), result.u.tolist(), sent.pcmd
        state_bits = nav.state_bits
        return {
            "t_s": t_exp_s, "mocap_age_ms": ages_ms[0], "navdata_age_ms": ages_ms[1],
            "solver_status": solution.status,
            "cmd_saturated": sent.saturated if sent.saturated is not None else "0000",
            "mocap_t_s": inputs.pose.t_s, "battery_pct": nav.battery_pct,
            "nav_vx_body_mps": nav.vx_body_mps, "nav_vy_body_mps": nav.vy_body_mps,
            "nav_mode": nav.mode.value, "nav_roll_deg": nav.roll_deg,
            "nav_pitch_deg": nav.pitch_deg,
            "nav_state_bits": state_bits if state_bits is not None else math.nan,
            "x_m": xs[IX_X], "y_m": xs[IX_Y], "z_m": xs[IX_Z], "psi_rad": xs[IX_PSI],
            "vx_mps": xs[IX_VX], "vy_mps": xs[IX_VY], "vz_mps": xs[IX_VZ],
            "x_ref_m": ref[IX_X], "y_ref_m": ref[IX_Y], "z_ref_m": ref[IX_Z],
            "psi_ref_rad": ref[IX_PSI],
            "u_zacc_mps2": u[IU_ZACC], "u_phi_rad": u[IU_PHI], "u_theta_rad": u[IU_THETA],
            "u_psirate_radps": u[IU_PSIRATE], "solve_us": result.solve_time_us,
            "residual_norm": result.residual_norm,
            "gmres_iterations": result.gmres_iterations,
            "newton_iterations": result.newton_iterations,
            "vz_ref_mps": flown.vz_ref_mps,
            "cmd_roll_frac": pcmd.roll_frac, "cmd_pitch_frac": pcmd.pitch_frac,
            "cmd_gaz_frac": pcmd.gaz_frac, "cmd_yaw_frac": pcmd.yaw_frac,
            "mode": mode, "compute_us": compute_us}
    return _general_row(t_exp_s=t_exp_s, inputs=inputs, ages_ms=ages_ms, x=x,
                        solution=solution, sent=sent, mode=mode, compute_us=compute_us)


def tick_cells(t_exp_s: float, inputs: TickInputs, ages_ms: tuple[float, float],
               x: np.ndarray | None, solution, sent, mode: str, compute_us: float
               ) -> list | None:
    """:func:`tick_row`'s usual NMPC row as its cells in :data:`LOG_COLUMNS` order (``""`` for
    a column it lacks; the truth's cells ``""`` until :func:`put_truth_cells`), or None for
    any other tick (take :func:`tick_row`). The lockstep runner's row: the recorder takes
    the cells as they are, without a dict to map back to column order. The same values as
    :func:`tick_row`'s fast path, the same conditions (tests/unit/test_tick_cells.py); its
    arguments also positional (:meth:`~ardrone_nmpc.runtime.tick.Tick.step`'s call)."""
    nav, result = inputs.navdata, solution.result if solution is not None else None
    flown, pose = sent.flown, inputs.pose
    if not (result is not None and x is not None and nav is not None
            and pose is not None and inputs.target is None and flown is not None
            and sent.decision.action is not _FALLBACK):
        return None
    zacc, phi, theta, psirate = result.u.tolist()
    saturated = sent.saturated
    return nominal_cells(t_exp_s, x, solution.ref_now, zacc, phi, theta, psirate,
                         flown.vz_ref_mps, sent.pcmd,
                         saturated if saturated is not None else "0000",
                         result.solve_time_us, solution.status, result.residual_norm,
                         result.gmres_iterations, result.newton_iterations, mode, ages_ms[0],
                         ages_ms[1], nav, compute_us, pose.t_s)


def nominal_cells(t_exp_s: float, x: np.ndarray, ref_now: np.ndarray, zacc: float, phi: float,
                  theta: float, psirate: float, vz_ref_mps: float, pcmd, saturated: str,
                  solve_us: float, status: str, residual_norm: float, gmres_iterations: int,
                  newton_iterations: int, mode: str, mocap_age_ms: float,
                  navdata_age_ms: float, nav, compute_us: float, mocap_t_s: float) -> list:
    """:func:`tick_cells`' row from its values (the input solved, the ż reference and the
    ``cmd_saturated`` text sent, the solver's figures): the one home of the usual row's cells
    — ``Tick``'s nominal tick builds them from the compiled call's answer, with no record
    between (``runtime/tick.py``)."""
    # the state unpacked in its order (_STATE_ORDER)
    x_m, vx_mps, y_m, vy_mps, z_m, vz_mps, psi_rad = x.tolist()
    ref, state_bits = ref_now.tolist(), nav.state_bits
    return [
        t_exp_s, x_m, y_m, z_m, psi_rad, vx_mps, vy_mps, vz_mps,
        ref[IX_X], ref[IX_Y], ref[IX_Z], ref[IX_PSI], zacc, phi, theta, psirate,
        vz_ref_mps,
        pcmd.roll_frac, pcmd.pitch_frac, pcmd.gaz_frac, pcmd.yaw_frac,
        saturated, solve_us, status, residual_norm, gmres_iterations, newton_iterations, mode,
        mocap_age_ms, navdata_age_ms,
        nav.battery_pct, "", compute_us, mocap_t_s, nav.vx_body_mps, nav.vy_body_mps,
        nav.mode._value_, nav.roll_deg, nav.pitch_deg,  # (.value: an enum property, 0.3 µs)
        state_bits if state_bits is not None else math.nan,
        "", "", "", "", "", "", "", "", "", "", "", ""]


_PI = math.pi


def block_cells(v: list, nav_vx, nav_vy, saturated: tuple, status: str, mode: str,
                nav_mode: str, target: bool = False, nav_state=math.nan) -> list:
    """The cells of a block's row (``v``: its numbers as floats): :func:`nominal_cells`' of
    the same tick, its truth put — the same values and types (``nav_vx``, ``nav_vy``: the
    navdata's speeds, numpy scalars as the sample's; ``saturated``: the texts of the
    saturation bits; ``status``: the solver's; ``nav_mode``: the sample's mode's value);
    ``target``: a flight with a second object, its cells those of :func:`tick_row`'s row
    (:func:`_target_columns`: the same values; that row's other cells are these too);
    ``nav_state``: the sample's state word (an int through the wire; NaN: none)."""
    cells = v[:21]
    psi = v[BR_TRUE_PSI]
    cells += (saturated[int(v[BR_SATURATED])], v[BR_SOLVE_US], status, v[BR_NORM],
              int(v[BR_GMRES]), int(v[BR_NEWTON]), mode, v[BR_MOCAP_MS], v[BR_NAV_MS],
              v[BR_BATTERY], "", v[BR_COMPUTE_US], v[BR_MOCAP_T], nav_vx, nav_vy, nav_mode,
              v[BR_NAV_ROLL], v[BR_NAV_PITCH], nav_state, "",
              *(v[BR_TARGET_X:BR_TARGET_AGE + 1] if target else _NO_TARGET),
              v[BR_TRUE_X], v[BR_TRUE_Y], v[BR_TRUE_Z],
              psi if -_PI < psi <= _PI else wrap_angle_rad(psi), v[BR_TRUE_VZ])
    return cells


_NO_TARGET = ("",) * 6  # a block's row without a second object: no target cells


# tick_cells unpacks the state and the input by position (~0.1 µs less than a subscript a
# cell): the orders it assumes are core/types' — checked here, once
_STATE_ORDER = (IX_X, IX_VX, IX_Y, IX_VY, IX_Z, IX_VZ, IX_PSI)
_INPUT_ORDER = (IU_ZACC, IU_PHI, IU_THETA, IU_PSIRATE)
if _STATE_ORDER != tuple(range(7)) or _INPUT_ORDER != tuple(range(4)):  # pragma: no cover
    raise ImportError("runs/log_columns.tick_cells: the state or input order changed")


#: The keys of a :func:`tick_cells` row with its truth put: :func:`tick_row`'s fast path's,
#: in its order, then :func:`put_truth`'s (the dict :func:`cells_row` gives back).
TICK_CELL_KEYS: tuple[str, ...] = (
    "t_s", "mocap_age_ms", "navdata_age_ms", "solver_status", "cmd_saturated", "mocap_t_s",
    "battery_pct", "nav_vx_body_mps", "nav_vy_body_mps", "nav_mode", "nav_roll_deg",
    "nav_pitch_deg", "nav_state_bits", "x_m", "y_m", "z_m", "psi_rad", "vx_mps", "vy_mps",
    "vz_mps", "x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad", "u_zacc_mps2", "u_phi_rad",
    "u_theta_rad", "u_psirate_radps", "solve_us", "residual_norm", "gmres_iterations",
    "newton_iterations", "vz_ref_mps", "cmd_roll_frac", "cmd_pitch_frac", "cmd_gaz_frac",
    "cmd_yaw_frac", "mode", "compute_us",
    "x_true_m", "y_true_m", "z_true_m", "psi_true_rad", "vz_true_mps")
_COLUMN_INDEX = {name: i for i, name in enumerate(LOG_COLUMNS)}
#: ``cells -> the values of its TICK_CELL_KEYS`` (a tuple, at C speed)
tick_cell_values = operator.itemgetter(*(_COLUMN_INDEX[k] for k in TICK_CELL_KEYS))
#: The cells :func:`put_truth_cells` fills (x, y, z, ψ, ż of the truth, adjacent columns; the
#: lockstep runner's loop assigns them itself, without the call).
TRUTH_CELLS = slice(_COLUMN_INDEX["x_true_m"], _COLUMN_INDEX["vz_true_mps"] + 1)
#: The cell of ``mode`` (the lockstep runner relabels its landing rows).
MODE_CELL = _COLUMN_INDEX["mode"]


#: The keys of :func:`tick_row`'s row of a usual NMPC tick that saw a second object, its
#: truth put (the general path's order: :func:`_target_columns` after the measurements')
TARGET_CELL_KEYS: tuple[str, ...] = (
    *TICK_CELL_KEYS[:TICK_CELL_KEYS.index("x_m")], "target_x_m", "target_y_m", "target_z_m",
    "target_psi_rad", "target_t_s", "target_age_ms",
    *TICK_CELL_KEYS[TICK_CELL_KEYS.index("x_m"):])
_target_cell_values = operator.itemgetter(*(_COLUMN_INDEX[k] for k in TARGET_CELL_KEYS))


#: the cells :func:`_general_row` reads from arrays: numpy scalars there (the object's
#: position, the estimate, the reference, the input solved — the P controller's: floats)
_INPUT_KEYS = ("u_zacc_mps2", "u_phi_rad", "u_theta_rad", "u_psirate_radps")
_ARRAY_KEYS = frozenset({
    "target_x_m", "target_y_m", "target_z_m", "x_m", "y_m", "z_m", "psi_rad", "vx_mps",
    "vy_mps", "vz_mps", "x_ref_m", "y_ref_m", "z_ref_m", "psi_ref_rad", *_INPUT_KEYS})
_ARRAY_CELLS = tuple(i for i, k in enumerate(TARGET_CELL_KEYS) if k in _ARRAY_KEYS)
_F64 = np.float64
#: the solver's cells: a P controller's row has none (:func:`_solution_columns`)
_SOLVER_KEYS = ("solve_us", "residual_norm", "gmres_iterations", "newton_iterations")


def target_cells_row(cells: list) -> dict:
    """:func:`cells_row` of a usual tick's cells with a second object's
    (:func:`block_cells`' ``target``): the very dict :func:`tick_row` builds for that tick
    and :func:`put_truth` completes (same keys, same order, same values and types)."""
    values = list(_target_cell_values(cells))
    for i in _ARRAY_CELLS:
        values[i] = _F64(values[i])
    return dict(zip(TARGET_CELL_KEYS, values))


def put_truth_cells(cells: list, truth: tuple) -> None:
    """:func:`put_truth` for a :func:`tick_cells` row: ``(x, y, z, ψ, ż)`` into its slots."""
    cells[TRUTH_CELLS] = truth


def _p_keys(keys: tuple[str, ...]) -> tuple:
    """A P row's keys (``keys`` without the solver's), their cells' getter, where its
    numpy scalars sit (the arrays' cells but the input's: P's command is floats), and its
    ``solver_status`` and z̈ cells."""
    p_keys = tuple(k for k in keys if k not in _SOLVER_KEYS)
    arrays = tuple(i for i, k in enumerate(p_keys)
                   if k in _ARRAY_KEYS and k not in _INPUT_KEYS)
    return (p_keys, operator.itemgetter(*(_COLUMN_INDEX[k] for k in p_keys)), arrays,
            p_keys.index("solver_status"), p_keys.index("u_zacc_mps2"))


_P_ROWS = (_p_keys(TICK_CELL_KEYS), _p_keys(TARGET_CELL_KEYS))


def p_cells_row(cells: list, target: bool = False) -> dict:
    """The P controller's nominal row from a block's cells (:func:`block_cells`'; its
    ``target``: a second object's): the very dict :func:`tick_row` builds for that tick
    (:func:`_general_row`: no solver's cells, no z̈, an empty ``solver_status``) and
    :func:`put_truth` completes — same keys, same order, same values and types."""
    keys, values_of, arrays, status, zacc = _P_ROWS[target]
    values = list(values_of(cells))
    for i in arrays:
        values[i] = _F64(values[i])
    values[status], values[zacc] = "", math.nan
    return dict(zip(keys, values))


def cells_row(cells: list) -> dict:
    """The dict row of a :func:`tick_cells` row with its truth put: the very dict
    :func:`tick_row` and :func:`put_truth` build (same keys, same order, same values)."""
    return dict(zip(TICK_CELL_KEYS, tick_cell_values(cells)))


def _general_row(*, t_exp_s: float, inputs: TickInputs, ages_ms: tuple[float, float],
                 x: np.ndarray | None, solution, sent, mode: str, compute_us: float) -> dict:
    """:func:`tick_row` of any tick (the P controller, a target, no pose, a hold, …)."""
    row = {"t_s": t_exp_s, "mocap_age_ms": ages_ms[0], "navdata_age_ms": ages_ms[1],
           "solver_status": solution.status if solution is not None else "",
           "cmd_saturated": sent.saturated if sent.saturated is not None else "0000"}
    row |= measurement_columns(inputs)
    if x is not None:  # logged even when stale (mocap_age_ms says so)
        row |= {"x_m": x[IX_X], "y_m": x[IX_Y], "z_m": x[IX_Z], "psi_rad": x[IX_PSI],
                "vx_mps": x[IX_VX], "vy_mps": x[IX_VY], "vz_mps": x[IX_VZ]}
    if solution is not None:
        row |= _solution_columns(solution)
    flown = sent.flown
    if flown is not None:
        row["vz_ref_mps"] = flown.vz_ref_mps
        if sent.decision.action is _FALLBACK:  # the P command flown instead
            row |= {"u_phi_rad": flown.phi_rad, "u_theta_rad": flown.theta_rad,
                    "u_psirate_radps": flown.psirate_radps}
    pcmd = sent.pcmd
    row |= {"cmd_roll_frac": pcmd.roll_frac, "cmd_pitch_frac": pcmd.pitch_frac,
            "cmd_gaz_frac": pcmd.gaz_frac, "cmd_yaw_frac": pcmd.yaw_frac,
            "mode": mode, "compute_us": compute_us}
    return row


def truth_columns(truth) -> dict:
    """The simulated plant's true state (a :class:`~ardrone_nmpc.core.types.PlantTruth`)."""
    return {"x_true_m": truth.position_m[0], "y_true_m": truth.position_m[1],
            "z_true_m": truth.position_m[2], "psi_true_rad": truth.psi_rad,
            "vz_true_mps": truth.velocity_mps[2]}


def put_truth(row: dict, cells: tuple) -> None:
    """:func:`truth_columns` written into ``row`` from ``(x, y, z, ψ, ż)`` (the lockstep
    runner's every tick: :meth:`~ardrone_nmpc.sim.lockstep_drone.LockstepDrone.truth_cells`,
    without a PlantTruth)."""
    row["x_true_m"], row["y_true_m"], row["z_true_m"], row["psi_true_rad"], \
        row["vz_true_mps"] = cells


def link_columns(late_s: float, navdata: NavdataSample | None) -> dict:
    """What the real-time runner adds: the tick's lateness and the navdata's raw ctrl_state."""
    ctrl = navdata.ctrl_state if navdata is not None else None
    return {"tick_late_ms": late_s * 1e3, "nav_ctrl_state": ctrl if ctrl is not None else math.nan}


# ----------------------------------------------------------------------------- decoder
#: Two rows whose ``mocap_t_s`` differ by less than this saw the same pose: distinct poses are
#: a mocap frame (≥ 1 ms) apart. Logs whose ``mocap_t_s`` is the pose stamp moved to the
#: experiment clock by a per-tick offset (written since 5b5377e) can show one pose a few ulps
#: apart on two ticks in simulation — and, in ``fly``, by the tick's lateness (≈ ms), which
#: no tolerance can absorb: such logs do not re-run exactly (see the report on the issue).
SAME_POSE_TOLERANCE_S = 1e-9


class ReplayError(UserError, ValueError):
    """A run that cannot be replayed as asked (one line for the user)."""


def pose_of_row(cols: dict, i: int, previous: MocapPose | None) -> MocapPose | None:
    """The pose row ``i`` saw: the previous one again, a new one, or None before the first.

    A new pose without a logged position (a stale-mocap hover row of a tick that did not
    estimate) never reached the estimators in the flight, so the previous pose stands in — its
    time stays the estimators' last sample time, as it did in the flight — and only the
    row's age (the supervisor's input) moves on. NaN position if there is no previous pose.
    """
    t_pose = float(cols["mocap_t_s"][i])
    if math.isnan(t_pose):
        return None
    x, y, z, psi = (float(cols[c][i]) for c in ("x_m", "y_m", "z_m", "psi_rad"))
    logged = not math.isnan(x)
    if previous is not None:
        if abs(t_pose - previous.t_s) <= SAME_POSE_TOLERANCE_S:
            if not logged or not math.isnan(previous.position_m[0]):
                return previous  # the same object: the tick recognises it by its time
            t_pose = previous.t_s  # first logged sighting of a pose first seen unlogged
        elif not logged:
            return previous
    position = np.array([x, y, z])
    rotation = np.array([0.0, 0.0, psi])  # roll and pitch are not logged (nor used)
    position.setflags(write=False)
    rotation.setflags(write=False)
    return MocapPose(t_s=t_pose, position_m=position, rotation_xyz_rad=rotation, psi_rad=psi)


def unlogged_pose(cols: dict, i: int, pose: MocapPose | None) -> bool:
    """Row ``i`` saw a pose the decoder could not rebuild (see :func:`pose_of_row`)."""
    if pose is None:
        return False
    return (math.isnan(pose.position_m[0])
            or abs(float(cols["mocap_t_s"][i]) - pose.t_s) > SAME_POSE_TOLERANCE_S)


def _navdata_of_row(cols: dict, i: int, rx_t_s: float) -> NavdataSample | None:
    """The navdata sample row ``i`` saw (None before the first): logged fields, NaN others."""
    mode = str(cols["nav_mode"][i])
    if not mode or not math.isfinite(rx_t_s):
        return None
    try:
        flight_mode = FlightMode(mode)
    except ValueError:
        raise ReplayError(f"log.csv row {i + 2}: nav_mode {mode!r} is not a flight mode "
                          f"({', '.join(m.value for m in FlightMode)})") from None
    nan = math.nan
    # navdata attitude is not among the measurement columns (yet): taken when a log has it
    roll, pitch = (float(cols[c][i]) if c in cols else nan
                   for c in ("nav_roll_deg", "nav_pitch_deg"))
    state = float(cols["nav_state_bits"][i]) if "nav_state_bits" in cols else nan
    return NavdataSample(t_s=rx_t_s, mode=flight_mode, battery_pct=float(cols["battery_pct"][i]),
                         roll_deg=roll, pitch_deg=pitch, yaw_deg=nan, altitude_m=nan,
                         vx_body_mps=float(cols["nav_vx_body_mps"][i]),
                         vy_body_mps=float(cols["nav_vy_body_mps"][i]), vz_mps=nan,
                         state_bits=int(state) if math.isfinite(state) else None)


def _target_of_row(cols, i: int) -> tuple[MocapPose | None, float]:
    """The followed object's pose of row ``i`` (reference kind ``follow``), if logged."""
    if "target_t_s" not in cols or not math.isfinite(float(cols["target_t_s"][i])):
        return None, -math.inf
    position = np.array([float(cols[c][i]) for c in ("target_x_m", "target_y_m", "target_z_m")])
    psi = float(cols["target_psi_rad"][i])
    pose = MocapPose(t_s=float(cols["target_t_s"][i]), position_m=position,
                     rotation_xyz_rad=np.array([0.0, 0.0, psi]), psi_rad=psi)
    return pose, float(cols["t_s"][i]) - float(cols["target_age_ms"][i]) * 1e-3


def tick_inputs_of_rows(cols: dict, n_rows: int) -> list[TickInputs]:
    """The :class:`TickInputs` of every logged tick (``cols``: column → values over the rows,
    with :data:`RERUN_COLUMNS`), on the experiment clock.

    The tick's clock is the row's ``t_s`` (so the tick's clock offset is 0 and the pose keeps
    its logged ``mocap_t_s``); receipt times are ``t_s − age``. A pose seen on several ticks
    is one object (the estimators update on a *new* pose only). Raises :class:`ReplayError`
    for a ``nav_mode`` cell that is not a flight mode.
    """
    inputs: list[TickInputs] = []
    pose: MocapPose | None = None
    for i in range(n_rows):
        t = float(cols["t_s"][i])
        pose = pose_of_row(cols, i, pose)
        mocap_age_s = float(cols["mocap_age_ms"][i]) * 1e-3
        nav_age_s = float(cols["navdata_age_ms"][i]) * 1e-3
        pose_rx = t - mocap_age_s if pose is not None else -math.inf
        nav_rx = t - nav_age_s if math.isfinite(nav_age_s) else -math.inf
        target, target_rx = _target_of_row(cols, i)
        inputs.append(TickInputs(t, pose, pose_rx, _navdata_of_row(cols, i, nav_rx), nav_rx,
                                 target, target_rx))
    return inputs
