"""The grid of plant deviations ``robustness`` flies a config over (docs/robustness.md §1).

The default is the region a real AR.Drone can be in: command delay 0–0.4 s, tilt per unit
command 0.6–2× ``euler_angle_max``, attitude lag 0.05–0.2 s, vertical gain 0.6–1.4, steady
wind 0 and 0.4 m/s. A grid file changes the axes (any ``--set`` path, values as YAML)::

    axes:
      sim.plant.command_delay_s: [0.0, 0.2, 0.4]
      sim.plant.attitude_gain: [0.6, 2.0]
      faults.wind.velocity_mps: [[0, 0, 0], [0.32, 0.24, 0]]
    map: {x: sim.plant.command_delay_s, y: sim.plant.attitude_gain,
          panel: faults.wind.velocity_mps}

``map`` names the axes of the figure (x and y of each panel, one panel per value of
``panel``); left out, the first axis is x, the second y and the last the panel.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.experiments.sweep.grid import GridParam, value_text

__all__ = ["DEFAULT_GRID", "RobustnessGrid", "corner_variants", "grid_from_data", "load_grid"]

DELAY = "sim.plant.command_delay_s"
GAIN = "sim.plant.attitude_gain"
WIND = "faults.wind.velocity_mps"
#: |w| = 0.4 m/s, from the front left (the issue's 0.3/0.2 m/s direction, scaled)
WIND_04 = (0.32, 0.24, 0.0)


@dataclass(frozen=True)
class RobustnessGrid:
    """Axes (dotted path, values) and the map's x, y and panel axes."""

    axes: tuple[tuple[str, tuple[Any, ...]], ...]
    x: str
    y: str
    panel: str

    def params(self) -> list[GridParam]:
        """The axes as sweep grid parameters (the first varies slowest)."""
        return [GridParam(path, tuple(value_text(v) for v in values), tuple(values))
                for path, values in self.axes]

    @property
    def size(self) -> int:
        n = 1
        for _, values in self.axes:
            n *= len(values)
        return n


DEFAULT_GRID = RobustnessGrid(
    axes=((WIND, ((0.0, 0.0, 0.0), WIND_04)),
          (DELAY, (0.0, 0.1, 0.2, 0.3, 0.4)),
          (GAIN, (0.6, 1.0, 1.5, 2.0)),
          ("sim.plant.tau_tilt_s", (0.05, 0.2)),
          ("sim.vz_gain", (0.6, 1.4))),
    x=DELAY, y=GAIN, panel=WIND)


def _listed(value: Any) -> Any:
    return [_listed(v) for v in value] if isinstance(value, (list, tuple)) else value


def grid_from_data(data: Any, *, where: str = "grid") -> RobustnessGrid:
    """A grid from the parsed YAML of a grid file (module docstring). Raises ConfigError."""
    if not isinstance(data, Mapping) or not isinstance(data.get("axes"), Mapping):
        raise ConfigError(f"{where}: expected a mapping with 'axes: {{dotted.path: [values…]}}'")
    errors, axes = [], []
    for path, values in data["axes"].items():
        if not isinstance(path, str) or not isinstance(values, list) or not values:
            errors.append(f"{where}: axes.{path}: expected a non-empty list of values")
            continue
        texts = [value_text(_listed(v)) for v in values]
        if len(set(texts)) != len(texts):
            errors.append(f"{where}: axes.{path}: a value is given twice")
        axes.append((path, tuple(_listed(v) for v in values)))
    unknown = set(data) - {"axes", "map"}
    if unknown:
        errors.append(f"{where}: unknown keys {sorted(unknown)} (axes, map)")
    names = [p for p, _ in axes]
    mapping = data.get("map") or {}
    if not isinstance(mapping, Mapping) or set(mapping) - {"x", "y", "panel"}:
        errors.append(f"{where}: map: expected {{x: path, y: path, panel: path}}")
        mapping = {}
    chosen = {"x": mapping.get("x", names[0] if names else None),
              "y": mapping.get("y", names[1] if len(names) > 1 else None),
              "panel": mapping.get("panel", names[-1] if len(names) > 2 else None)}
    for key, path in chosen.items():
        if path is not None and path not in names:
            errors.append(f"{where}: map.{key}: {path!r} is not one of the axes")
    if chosen["x"] is None or chosen["y"] is None:
        errors.append(f"{where}: give at least two axes (the map's x and y)")
    if errors:
        raise ConfigError(errors)
    return RobustnessGrid(tuple(axes), chosen["x"], chosen["y"], chosen["panel"] or "")


def load_grid(path: str | Path | None) -> RobustnessGrid:
    """The grid of a grid file, or :data:`DEFAULT_GRID` for None."""
    if path is None:
        return DEFAULT_GRID
    from ardrone_nmpc.config.io import read_option_file

    return grid_from_data(read_option_file(path, "--grid-file"), where=f"--grid-file {path}")


def corner_variants(grid: RobustnessGrid) -> list[tuple[str, tuple[str, ...]]]:
    """``tune --robust``'s plants: the corners of the grid (each axis at its first or last
    value; beyond four axes of two ends, the half whose number of last values is even — a
    resolution-V half fraction: every pair of axes still meets in all four combinations)
    and its centre (each axis at its middle value), as (label, ``--set`` overrides)."""
    from itertools import product

    ends = [(path, (values[0], values[-1]) if len(values) > 1 else (values[0],))
            for path, values in grid.axes]
    varied = sum(len(e) > 1 for _, e in ends)
    out = []
    for pick in product(*(range(len(e)) for _, e in ends)):
        if varied > 4 and sum(pick) % 2:
            continue
        values = [e[i] for (_, e), i in zip(ends, pick)]
        out.append(_variant("".join("+" if i else "-" for i in pick), grid, values))
    out.append(_variant("centre", grid, [_middle(values) for _, values in grid.axes]))
    return out


def _middle(values: Sequence[Any]) -> Any:
    """The midpoint of an axis' ends (numbers, or vectors elementwise); else its middle
    value."""
    lo, hi = values[0], values[-1]
    try:
        if isinstance(lo, (list, tuple)):
            return [round((a + b) / 2.0, 9) for a, b in zip(lo, hi)]
        return round((lo + hi) / 2.0, 9)
    except TypeError:
        return values[len(values) // 2]


def _variant(label: str, grid: RobustnessGrid, values) -> tuple[str, tuple[str, ...]]:
    return label, tuple(f"{path}={value_text(_listed(v))}"
                        for (path, _), v in zip(grid.axes, values))
