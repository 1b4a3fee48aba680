"""``bench --tick``'s recorder (experiments/tick_bench._Clocks): rows kept as they come, dict
rows and rows as cells alike, their two clocks read after the flight."""

from __future__ import annotations

import math

from ardrone_nmpc.experiments.tick_bench import _Clocks
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS


def test_clocks_are_read_from_dict_rows_and_cells_in_row_order():
    clocks = _Clocks()
    cells = [""] * len(LOG_COLUMNS)
    cells[LOG_COLUMNS.index("solve_us")], cells[LOG_COLUMNS.index("compute_us")] = 7.5, 17.25
    clocks.write_row({"t_s": 0.0, "compute_us": 3.0})  # no solve (a hold, the P controller)
    clocks.write_cells(cells)
    clocks.write_row({"solve_us": None, "compute_us": "4.5"})
    solve_us, compute_us = clocks.clocks()
    assert compute_us == [3.0, 17.25, 4.5]
    assert math.isnan(solve_us[0]) and solve_us[1] == 7.5 and math.isnan(solve_us[2])
