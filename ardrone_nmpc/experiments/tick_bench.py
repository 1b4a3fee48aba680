"""The lockstep tick's cost, split by stage (``bench --tick``).

Flies a config in lockstep, its rows kept in memory (as ``tune``'s flights are), and splits
the wall time per tick with the clocks the tick already keeps in its row: the solver's update
(``solve_us``: the kernel and its dispatch), the rest of the controller tick (``compute_us``
less ``solve_us``: feedback ages, estimation, the supervisor, the delay prediction, the
command, the offset-free stage) and everything between two ticks (the flight's wall time less
``compute_us``: the simulated drone — firmware, plant, sensors, faults — the runner, building
and keeping the row). The first flight loads (or compiles) the kernels and is not timed; of
``repeats`` identical flights (one seed: the same ticks) the fastest is kept.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

from ardrone_nmpc.runs.block_row import BR_COMPUTE_US, BR_SOLVE_US
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS

__all__ = ["TickSplit", "bench_tick"]

_SOLVE_US, _COMPUTE_US = LOG_COLUMNS.index("solve_us"), LOG_COLUMNS.index("compute_us")


@dataclass(frozen=True)
class TickSplit:
    """µs per tick of one flight (the JSON contract of ``bench --tick --json``)."""

    ticks: int
    solved_ticks: int
    simulated_s: float
    wall_s: float
    update_us: float        # the solver's update, mean over the ticks that solved
    solver_us: float        # the solver's update, per tick (all ticks)
    controller_us: float    # the rest of the controller tick, per tick
    drone_runner_us: float  # the simulated drone, the runner and the row, per tick

    @property
    def tick_us(self) -> float:
        return self.wall_s * 1e6 / self.ticks

    @property
    def tick_per_update(self) -> float:
        """A whole lockstep tick over one solver update (issue 26's ratio)."""
        return self.tick_us / self.update_us if self.update_us > 0 else math.nan

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.wall_s

    def to_json(self) -> dict:
        return asdict(self) | {"tick_us": self.tick_us, "tick_per_update": self.tick_per_update,
                               "real_time_factor": self.real_time_factor}


class _Clocks:
    """A recorder that keeps the two clock cells of each row as they are (a float, or what
    marks none), read as numbers after the flight: no conversion a tick, and no row kept
    (kept rows are containers the garbage collector walks, ~1 ms a flight)."""

    path = None  # no run directory

    def __init__(self) -> None:
        self._solve: list = []
        self._compute: list = []

    def write_row(self, row: dict) -> None:
        self._solve.append(row.get("solve_us"))
        self._compute.append(row.get("compute_us"))

    def write_cells(self, cells: list) -> None:
        """A row as the lockstep runner hands it to the recorders that take cells (the run
        directory's and tuning's: ``runs/log_columns.tick_cells``)."""
        self._solve.append(cells[_SOLVE_US])
        self._compute.append(cells[_COMPUTE_US])

    def write_block(self, rows) -> None:
        """A block of rows (``runs/block_rows.BlockRows``): its two clocks' columns."""
        self._solve.extend(rows.column(BR_SOLVE_US))
        self._compute.extend(rows.column(BR_COMPUTE_US))

    def event(self, *args, **kwargs) -> None:
        pass

    def clocks(self) -> tuple[list[float], list[float]]:
        """``solve_us`` and ``compute_us`` of every row, NaN where a row has none."""
        return list(map(_number, self._solve)), list(map(_number, self._compute))


def _number(value) -> float:
    return math.nan if value is None or value == "" else float(value)


def _fly(cfg, seed: int | None) -> TickSplit:
    from ardrone_nmpc.runtime.lockstep import run_lockstep

    clocks = _Clocks()
    t0 = time.perf_counter()
    result = run_lockstep(cfg, recorder=clocks, seed=seed)
    wall_s = time.perf_counter() - t0
    solve_us, compute_us = clocks.clocks()
    ticks = len(compute_us)
    solved = [s for s in solve_us if math.isfinite(s)]
    solve_total = sum(solved)
    compute_total = sum(c for c in compute_us if math.isfinite(c))
    return TickSplit(
        ticks=ticks, solved_ticks=len(solved), simulated_s=result.end_t_s, wall_s=wall_s,
        update_us=solve_total / len(solved) if solved else math.nan,
        solver_us=solve_total / ticks, controller_us=(compute_total - solve_total) / ticks,
        drone_runner_us=(wall_s * 1e6 - compute_total) / ticks)


def bench_tick(cfg, *, repeats: int = 3, seed: int | None = None) -> TickSplit:
    """The fastest of ``repeats`` lockstep flights of ``cfg`` (after one untimed flight, and
    blocks of ticks' kernel loaded or compiled: the flights a warm machine flies)."""
    from ardrone_nmpc.runtime.lockstep import warm_up_blocks

    warm_up_blocks()
    _fly(cfg, seed)
    return min((_fly(cfg, seed) for _ in range(repeats)), key=lambda s: s.wall_s)
