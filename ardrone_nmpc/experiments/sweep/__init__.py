"""Parameter sweeps: the Cartesian grid of lockstep simulations (``ardrone-nmpc sweep``).

:mod:`.grid` parses ``--grid`` and builds the cases, :mod:`.cases` flies one case into its
run directory and finds the ones an earlier run finished, :mod:`.status` judges a case
(metrics, ok/unstable), :mod:`.engines` runs them on the one executor (:mod:`ardrone_nmpc.experiments.parallel`: here, a local pool, Dask) and
:mod:`ardrone_nmpc.runs.sweep_table` reads and writes ``sweep.csv``. Everything is re-exported here.
"""

from ardrone_nmpc.experiments.sweep.cases import (PARTIAL_DIR, CaseResult, finished_result,
                                                  resume_results, run_case, sweep_row, warm_up,
                                                  warm_worker)
from ardrone_nmpc.experiments.sweep.engines import iter_dask, iter_local, run_cases
from ardrone_nmpc.experiments.sweep.grid import (Case, GridParam, build_cases, case_id,
                                                 parse_grid, split_values, value_text)
from ardrone_nmpc.experiments.sweep.status import (DIVERGE_M, TAIL_FRACTION, case_metrics,
                                                   classify)
from ardrone_nmpc.runs.sweep_table import (METRIC_COLUMNS, RANK_METRICS, STATUSES, SWEEP_FILE,
                                           SweepCsvAppender, SweepTable, SweepTableError,
                                           rank_rows, read_sweep, sweep_columns,
                                           write_sweep_csv)

__all__ = [
    "DIVERGE_M",
    "METRIC_COLUMNS",
    "PARTIAL_DIR",
    "RANK_METRICS",
    "STATUSES",
    "SWEEP_FILE",
    "TAIL_FRACTION",
    "Case",
    "CaseResult",
    "GridParam",
    "SweepCsvAppender",
    "SweepTable",
    "SweepTableError",
    "build_cases",
    "case_id",
    "case_metrics",
    "classify",
    "finished_result",
    "iter_dask",
    "iter_local",
    "parse_grid",
    "rank_rows",
    "read_sweep",
    "resume_results",
    "run_case",
    "run_cases",
    "split_values",
    "sweep_columns",
    "sweep_row",
    "value_text",
    "warm_up",
    "warm_worker",
    "write_sweep_csv",
]
