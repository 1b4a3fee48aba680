"""A short lockstep step_x run against its stored golden trace (tests/golden/step_x_short.csv).

Tolerances catch behaviour changes, not floating-point rounding (the stored file keeps 9
significant digits): each is at most 1 % of its column's own stored range — a tolerance above
the signal (the y and ψ of a step in x move by 1 mm and 0.2 mrad) would pass any behaviour.
A deliberate change regenerates the file with ``python tests/golden/make_golden.py``.
"""

from pathlib import Path

import numpy as np

from tests.golden.make_golden import COLUMNS, golden_rows

GOLDEN = Path(__file__).parent / "step_x_short.csv"


def test_step_x_matches_the_golden_run():
    stored = np.loadtxt(GOLDEN, delimiter=",", skiprows=1)
    now = golden_rows()
    assert now.shape == stored.shape
    tol = {"t_s": 1e-9, "x_true_m": 2e-3, "y_true_m": 4e-6, "z_true_m": 2e-3,
           "psi_true_rad": 2e-6, "u_theta_rad": 1.5e-3, "cmd_pitch_frac": 7e-3, "vz_mps": 2e-3}
    for j, name in enumerate(COLUMNS):
        span = np.ptp(stored[:, j])
        assert tol[name] <= 0.01 * span, (name, tol[name], span)  # below the signal
        np.testing.assert_allclose(now[:, j], stored[:, j], atol=tol[name], rtol=0, err_msg=name)
    # and the run did what a step does: x left 0 for −1.5 m
    x = stored[:, COLUMNS.index("x_true_m")]
    assert x[0] > -0.05 and x[-1] < -0.8
