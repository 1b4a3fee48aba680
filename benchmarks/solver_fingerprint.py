"""Fingerprint the obstacle-free solvers: hashes of exactly what they compute.

    python benchmarks/solver_fingerprint.py

Prints a SHA-256 prefix of the inputs, states and residual norms of the ``bench`` closed loop
(both solvers, 150 ticks) and of 8-s ``step_x`` and ``square`` lockstep flights (seed 3).
Run it on two commits — e.g. ``git archive <commit> ardrone_nmpc | tar -x -C /tmp/base`` and
``PYTHONPATH=/tmp/base python benchmarks/solver_fingerprint.py`` — to check that a change
leaves the solvers bit-for-bit the same (docs/solver-notes.md §7). Same machine only: LLVM's
fast-math code may round differently on another CPU.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

import ardrone_nmpc
from ardrone_nmpc.experiments.bench import closed_loop
from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.control.cgmres import CGMRESController
from ardrone_nmpc.control.newton import NewtonGMRESController
from ardrone_nmpc.control.ocp import OcpSpec
from ardrone_nmpc.runtime.lockstep import run_lockstep

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
COLUMNS = ("x_true_m", "y_true_m", "z_true_m", "u_phi_rad", "u_theta_rad", "u_zacc_mps2",
           "residual_norm")


class _Rows:
    path = None

    def __init__(self):
        self.rows = []

    def write_row(self, row):
        self.rows.append([row.get(c, np.nan) for c in COLUMNS])

    def event(self, *args, **kwargs):
        pass


def fingerprints() -> dict[str, np.ndarray]:
    out = {}
    for name, cls in (("cgmres", CGMRESController), ("newton", NewtonGMRESController)):
        solver = cls(OcpSpec())
        inputs = []

        def solve(t, x, ref):
            r = solver.solve(t, x, ref)
            inputs.append(r.u.copy())
            return r.u, r.residual_norm, r.ok, r.solve_time_us

        _, _, residuals, _, _, states = closed_loop(solve, solver.spec, steps=150,
                                                    period_s=0.065)
        out[f"bench {name}"] = np.concatenate([np.ravel(inputs), states.ravel(), residuals])
    for config in ("step_x", "square"):
        rows = _Rows()
        run_lockstep(load_config(CONFIGS / f"{config}.yaml", ["duration_s=8"]), recorder=rows,
                     seed=3)
        out[f"lockstep {config}"] = np.array(rows.rows, dtype=float).ravel()
    return out


if __name__ == "__main__":
    print(f"package: {Path(ardrone_nmpc.__file__).parent}")
    for key, values in fingerprints().items():
        digest = hashlib.sha256(values.tobytes()).hexdigest()[:16]
        print(f"{key:16} {values.size:6} values  sha256 {digest}")
