"""Regenerate the golden run: ``python tests/golden/make_golden.py`` (review the diff!)."""

from pathlib import Path

import numpy as np

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.runtime.lockstep import run_lockstep

HERE = Path(__file__).parent
COLUMNS = ("t_s", "x_true_m", "y_true_m", "z_true_m", "psi_true_rad", "u_theta_rad",
           "cmd_pitch_frac", "vz_mps")
OVERRIDES = ["duration_s=3.0", "sim.settle_s=0.5", "reference.step_time_s=0.2"]


class Rows:
    path = None

    def __init__(self):
        self.rows = []

    def write_row(self, row):
        self.rows.append([float(row.get(c, np.nan)) for c in COLUMNS])

    def event(self, *args, **kwargs):
        pass


def golden_rows() -> np.ndarray:
    cfg = load_config(HERE.parents[1] / "configs" / "step_x.yaml", OVERRIDES)
    rec = Rows()
    run_lockstep(cfg, recorder=rec, seed=0)
    return np.array(rec.rows)[::4]


if __name__ == "__main__":
    data = golden_rows()
    np.savetxt(HERE / "step_x_short.csv", data, delimiter=",", header=",".join(COLUMNS),
               comments="", fmt="%.9g")
    print(f"wrote {len(data)} rows")
