"""A block of lockstep ticks' rows handed to a recorder at once, as the numbers the block's
kernel wrote (``runs/block_row``) and their labels: the cells
(:func:`~ardrone_nmpc.runs.log_columns.block_cells`, row by row) or the columns are made
when the recorder needs them — a recorder that keeps a few columns, or keeps the rows in
memory until it is read, makes no row's cells (``write_block``: ``runs/memory``,
``experiments/tick_bench``; docs/architecture.md, runs).
"""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.runs.block_row import (BR_BATTERY, BR_COMPUTE_US, BR_GMRES, BR_MOCAP_MS,
                                         BR_MOCAP_T, BR_NAV_MS, BR_NAV_PITCH, BR_NAV_ROLL,
                                         BR_NAV_STATE, BR_NAV_VX, BR_NAV_VY, BR_NEWTON,
                                         BR_NORM, BR_SATURATED, BR_SOLVE_US, BR_T,
                                         BR_TARGET_X, BR_TRUE_PSI, BR_TRUE_VZ, BR_TRUE_X,
                                         BR_TRUE_Y, BR_TRUE_Z)
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, block_cells

__all__ = ["BlockRows"]

_PI = math.pi


class BlockRows:
    """``numbers``: a block's rows (``BLOCK_ROW`` floats a tick, owned: the kernel's table is
    copied); ``mode``: their mode label; ``saturated``, ``status``, ``nav_mode``: the texts
    of the saturation bits, the solver's status and the navdata's mode
    (:func:`~ardrone_nmpc.runs.log_columns.block_cells`'); ``target``: the rows have a
    second object's cells; ``wire``: its navdata samples came through the wire (a sensor
    fault: ``sim/wire_block``), their speeds Python floats and their state word in the
    rows. Their cells, row by row or column by column, are the very values
    (and types) the per-tick path's rows have."""

    __slots__ = ("numbers", "mode", "saturated", "status", "nav_mode", "target", "wire")

    def __init__(self, numbers: np.ndarray, mode: str, saturated: tuple, status: str,
                 nav_mode: str, target: bool = False, wire: bool = False) -> None:
        self.numbers, self.mode = numbers, mode
        self.saturated, self.status, self.nav_mode = saturated, status, nav_mode
        self.target, self.wire = target, wire

    def __len__(self) -> int:
        return len(self.numbers)

    def times_s(self) -> list[float]:
        """The rows' experiment times (``t_s``)."""
        return self.numbers[:, BR_T].tolist()

    def column(self, index: int) -> list[float]:
        """The rows' numbers at ``runs/block_row`` index ``index`` (floats)."""
        return self.numbers[:, index].tolist()

    def cells(self) -> list[list]:
        """Each row's cells in ``LOG_COLUMNS`` order (:func:`block_cells`)."""
        rows = self.numbers
        sat, status, mode, nav_mode = self.saturated, self.status, self.mode, self.nav_mode
        target = self.target
        if self.wire:
            return [block_cells(v, v[BR_NAV_VX], v[BR_NAV_VY], sat, status, mode, nav_mode,
                                target, int(v[BR_NAV_STATE])) for v in rows.tolist()]
        return [block_cells(v, vx, vy, sat, status, mode, nav_mode, target)
                for v, vx, vy in zip(rows.tolist(), rows[:, BR_NAV_VX], rows[:, BR_NAV_VY])]

    def columns(self) -> list[list]:
        """Each ``LOG_COLUMNS`` column's cells over the rows: ``zip(*self.cells())``'s values
        and types, made column by column (:meth:`column_cells`)."""
        return [self.column_cells(i) for i in range(len(_SOURCES))]

    def column_cells(self, i: int) -> list:
        """The cells of ``LOG_COLUMNS[i]`` over the rows (``zip(*self.cells())[i]``)."""
        kind, at = (_TARGET_SOURCES if self.target else _SOURCES)[i]
        if self.wire and i in _WIRE_KINDS:
            kind, at = _WIRE_KINDS[i]
        rows = self.numbers
        if kind == _NUMBER:
            return rows[:, at].tolist()
        if kind == _CONST:
            return [at] * len(rows)
        if kind == _INT:
            return [int(v) for v in rows[:, at].tolist()]
        if kind == _SCALAR:  # (numpy scalars, as block_cells is given them)
            return list(rows[:, at])
        if kind == _ANGLE:
            return [p if -_PI < p <= _PI else wrap_angle_rad(p) for p in rows[:, at].tolist()]
        if kind == _SATURATED:
            sat = self.saturated
            return [sat[int(b)] for b in rows[:, at].tolist()]
        return [getattr(self, at)] * len(rows)  # (_LABEL: the mode, the status, nav_mode)


# where each LOG_COLUMNS cell of a block's row comes from (block_cells' order): a number of
# the row, a number as an int, a numpy scalar, the truth's ψ wrapped, the saturation bits'
# text, a label of the block, or a constant
_NUMBER, _INT, _SCALAR, _ANGLE, _SATURATED, _LABEL, _CONST = range(7)
_SOURCES = (*((_NUMBER, i) for i in range(21)), (_SATURATED, BR_SATURATED),
            (_NUMBER, BR_SOLVE_US), (_LABEL, "status"), (_NUMBER, BR_NORM), (_INT, BR_GMRES),
            (_INT, BR_NEWTON), (_LABEL, "mode"), (_NUMBER, BR_MOCAP_MS), (_NUMBER, BR_NAV_MS),
            (_NUMBER, BR_BATTERY), (_CONST, ""), (_NUMBER, BR_COMPUTE_US),
            (_NUMBER, BR_MOCAP_T), (_SCALAR, BR_NAV_VX), (_SCALAR, BR_NAV_VY),
            (_LABEL, "nav_mode"), (_NUMBER, BR_NAV_ROLL), (_NUMBER, BR_NAV_PITCH),
            (_CONST, math.nan), *((_CONST, "") for _ in range(7)), (_NUMBER, BR_TRUE_X),
            (_NUMBER, BR_TRUE_Y), (_NUMBER, BR_TRUE_Z), (_ANGLE, BR_TRUE_PSI),
            (_NUMBER, BR_TRUE_VZ))
#: … through the wire (``BlockRows.wire``): the speeds' cells floats, the state word an int
_WIRE_KINDS = {LOG_COLUMNS.index("nav_vx_body_mps"): (_NUMBER, BR_NAV_VX),
               LOG_COLUMNS.index("nav_vy_body_mps"): (_NUMBER, BR_NAV_VY),
               LOG_COLUMNS.index("nav_state_bits"): (_INT, BR_NAV_STATE)}
#: … and a row with a second object's cells (``target_x_m`` … ``target_age_ms``: numbers)
_TARGET_SOURCES = (*_SOURCES[:41], *((_NUMBER, BR_TARGET_X + j) for j in range(6)),
                   *_SOURCES[47:])
