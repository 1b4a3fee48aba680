"""A run's log as a typed table (``export --format parquet``): the column types and units.

* counts (``gmres_iterations``, ``newton_iterations``) and the raw ``nav_ctrl_state`` word are
  64-bit integers (null where the log has NaN) — float64 if a value is not a whole number;
* the closed sets of strings (``mode``, ``solver_status``, ``nav_mode``) are categorical
  (dictionary-encoded);
* ``cmd_saturated`` (four ``0``/``1`` flags) is four booleans, ``cmd_saturated_roll``,
  ``_pitch``, ``_gaz``, ``_yaw`` (null where the cell is not four flags);
* ``time_utc`` (after ``t_s``): the row's absolute time, UTC, nanoseconds — ``t_s`` on the
  epoch the MCAP export uses, which puts the run's earliest row or event at its creation time
  (``config.yaml``, whole seconds);
* every other column float64, bit for bit.

Each field carries its unit in its Arrow metadata (``unit``), and the schema the whole map
(``ardrone_nmpc.units``, JSON). Units come from the column names (docs/design.md §4: the unit
is in the name) and :data:`UNITLESS` for the few names without one.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from ardrone_nmpc.runs.rundir import STRING_COLUMNS, RunData

__all__ = ["CATEGORY_COLUMNS", "INTEGER_COLUMNS", "SATURATION_AXES", "TIME_COLUMN",
           "UNITLESS", "UNITS_KEY", "column_unit", "log_table"]

INTEGER_COLUMNS = frozenset({"gmres_iterations", "newton_iterations", "nav_ctrl_state"})
CATEGORY_COLUMNS = frozenset({"mode", "solver_status", "nav_mode"})
SATURATION_AXES = ("roll", "pitch", "gaz", "yaw")
TIME_COLUMN = "time_utc"
UNITS_KEY = b"ardrone_nmpc.units"

#: Unit suffixes of column names, longest first (``_mps2`` before ``_mps`` before ``_m``).
_SUFFIXES = (("_mps2", "m/s²"), ("_radps", "rad/s"), ("_per_s", "1/s"), ("_mps", "m/s"),
             ("_rad", "rad"), ("_deg", "°"), ("_frac", "1"), ("_pct", "%"), ("_hz", "Hz"),
             ("_ms", "ms"), ("_us", "µs"), ("_s", "s"), ("_m", "m"))
#: Columns whose name carries no unit: their unit ("" for codes and labels).
UNITLESS: dict[str, str] = {
    "residual_norm": "1", "gmres_iterations": "count", "newton_iterations": "count",
    "nav_ctrl_state": "", "cmd_saturated": "", "solver_status": "", "mode": "",
    "nav_mode": "", **{f"cmd_saturated_{a}": "" for a in SATURATION_AXES},
    TIME_COLUMN: "UTC",
}


def column_unit(name: str) -> str:
    """The unit of a table column (KeyError for a name with neither suffix nor entry)."""
    if name in UNITLESS:
        return UNITLESS[name]
    for suffix, unit in _SUFFIXES:
        if name.endswith(suffix):
            return unit
    raise KeyError(f"{name}: no unit (add it to table_schema.UNITLESS)")


def _integers(values: np.ndarray) -> np.ndarray | None:
    """``values`` as int64 with NaN → masked, or None if one is not a whole int64."""
    finite = np.isfinite(values)
    if np.any(~finite & ~np.isnan(values)):
        return None
    whole = values[finite]
    if whole.size and (np.any(whole != np.round(whole)) or np.any(np.abs(whole) >= 2.0 ** 63)):
        return None
    return np.where(finite, values, 0).astype(np.int64)


def _flags(cells: list[str], k: int) -> list[bool | None]:
    return [c[k] == "1" if len(c) == 4 and set(c) <= {"0", "1"} else None for c in cells]


def _field(pa, name: str, array):
    return pa.field(name, array.type, metadata={b"unit": column_unit(name).encode()})


def log_table(pa, run: RunData, origin_ns: int):
    """The log of ``run`` as a ``pyarrow.Table`` (module docstring); ``origin_ns`` is the
    epoch (ns) of ``t_s = 0``."""
    fields, arrays = [], []

    def add(name: str, array) -> None:
        fields.append(_field(pa, name, array))
        arrays.append(array)

    for name, values in run.columns.items():
        if name == "cmd_saturated":
            cells = [str(c) for c in values.tolist()]
            for k, axis in enumerate(SATURATION_AXES):
                add(f"cmd_saturated_{axis}", pa.array(_flags(cells, k), type=pa.bool_()))
        elif name in CATEGORY_COLUMNS:
            add(name, pa.array([str(c) for c in values.tolist()]).dictionary_encode())
        elif name in INTEGER_COLUMNS and (ints := _integers(
                np.asarray(values, dtype=np.float64))) is not None:
            add(name, pa.array(ints, mask=np.isnan(np.asarray(values, dtype=np.float64))))
        elif name in STRING_COLUMNS:
            add(name, pa.array([str(c) for c in values.tolist()], type=pa.string()))
        else:
            add(name, pa.array(np.asarray(values, dtype=np.float64), type=pa.float64()))
        if name == "t_s":
            t = np.asarray(values, dtype=np.float64)
            stamps = [origin_ns + round(v * 1e9) if math.isfinite(v) else None
                      for v in t.tolist()]
            add(TIME_COLUMN, pa.array(stamps, type=pa.timestamp("ns", tz="UTC")))
    units: dict[str, Any] = {f.name: column_unit(f.name) for f in fields}
    schema = pa.schema(fields, metadata={UNITS_KEY: json.dumps(units, ensure_ascii=False)
                                         .encode()})
    return pa.Table.from_arrays(arrays, schema=schema)
