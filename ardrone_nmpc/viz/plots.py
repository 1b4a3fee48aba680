"""The figures the ``plot`` command draws, in one place: pure functions returning matplotlib
Figures, and :func:`save_figure`.

Each lives in the module of its concept: the run figures in
:mod:`~ardrone_nmpc.viz.run_figures`, the sweep heat map in
:mod:`~ardrone_nmpc.viz.sweep_heatmap` (``sweep.csv`` itself is read by
:mod:`ardrone_nmpc.runs.sweep_table`), what every figure shares in
:mod:`~ardrone_nmpc.viz.figure`. Importing this module does not import matplotlib.
"""

from __future__ import annotations

from ardrone_nmpc.runs.sweep_table import SWEEP_FILE, SweepTable
from ardrone_nmpc.viz.figure import PlotError, save_figure
from ardrone_nmpc.viz.run_figures import (KINDS, OFF_SCALE_FACTOR, figure_inputs, figure_path3d,
                                          figure_solver, figure_tracking)
from ardrone_nmpc.viz.sweep_heatmap import (SWEEP_METRICS, SweepGrid, figure_sweep_heatmap,
                                            read_sweep, sweep_grid)

__all__ = [
    "KINDS",
    "OFF_SCALE_FACTOR",
    "PlotError",
    "SWEEP_FILE",
    "SWEEP_METRICS",
    "SweepGrid",
    "SweepTable",
    "figure_inputs",
    "figure_path3d",
    "figure_solver",
    "figure_sweep_heatmap",
    "figure_tracking",
    "read_sweep",
    "save_figure",
    "sweep_grid",
]
