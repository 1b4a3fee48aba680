"""The thesis OCP solved exactly by CasADi/IPOPT — the yardstick for the fast solvers.

Same problem as :mod:`~ardrone_nmpc.control.kernels` (eq. 3.14, forward Euler, eq. 4.17 box
bounds as hard bounds, no dummy-input penalty), single shooting in the inputs. Needs the
``compare`` extra (``pip install -e '.[compare]'``).
"""

from __future__ import annotations

import numpy as np

from ardrone_nmpc.control.kernels import prepare_reference
from ardrone_nmpc.control.ocp import OcpSpec
from ardrone_nmpc.core.types import GRAVITY_MPS2, INPUT_DIM, STATE_DIM


def _import_casadi():
    try:
        import casadi
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise RuntimeError("CasADi is not installed: pip install -e '.[compare]'") from exc
    return casadi


class IpoptController:
    """Per-tick exact optimum of the OCP, warm-started from the shifted previous solution."""

    def __init__(self, spec: OcpSpec, *, tolerance: float = 1e-8):
        if spec.obstacles.shape[0]:
            raise RuntimeError("the IPOPT comparison models no obstacles; "
                               "set controller.obstacles=[] to compare")
        ca = _import_casadi()
        self.spec = spec
        n_stages, dtau = spec.horizon_steps, spec.dtau_s
        U = ca.SX.sym("U", INPUT_DIM * n_stages)
        P = ca.SX.sym("P", STATE_DIM * (n_stages + 2))  # x0, then reference rows 0..N
        x = P[:STATE_DIM]
        cost = 0
        for i in range(n_stages):
            u = U[INPUT_DIM * i: INPUT_DIM * (i + 1)]
            e = x - P[STATE_DIM * (i + 1): STATE_DIM * (i + 2)]
            cost += 0.5 * (ca.dot(e, spec.q * e) + ca.dot(u, spec.r * u)) * dtau
            x = x + _f(ca, x, u) * dtau
        e = x - P[STATE_DIM * (n_stages + 1):]
        cost += 0.5 * ca.dot(e, spec.q_terminal * e)
        opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": tolerance,
                "ipopt.sb": "yes", "ipopt.warm_start_init_point": "yes"}
        self._solver = ca.nlpsol("ocp", "ipopt", {"x": U, "f": cost, "p": P}, opts)
        self._lbx = np.tile(spec.u_min, n_stages)
        self._ubx = np.tile(spec.u_max, n_stages)
        self._guess = np.zeros(INPUT_DIM * n_stages)
        self._lam = np.zeros(INPUT_DIM * n_stages)

    def solve(self, x: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, bool]:
        """Return ``(u (4,), success)`` for state ``x`` (7,) and reference ``ref`` (N+1, 7)."""
        x = np.ascontiguousarray(x, dtype=float)
        unwrapped = np.empty_like(ref, dtype=float)
        if not prepare_reference(x, np.ascontiguousarray(ref, dtype=float), unwrapped):
            return np.zeros(INPUT_DIM), False  # non-finite input: nothing to solve
        p = np.concatenate([x, unwrapped.reshape(-1)])
        sol = self._solver(x0=self._guess, lam_x0=self._lam, p=p, lbx=self._lbx, ubx=self._ubx)
        ok = bool(self._solver.stats()["success"])
        U = np.asarray(sol["x"]).reshape(-1)
        lam = np.asarray(sol["lam_x"]).reshape(-1)
        # warm start for the next tick: shift by one stage, repeat the last
        self._guess = np.concatenate([U[INPUT_DIM:], U[-INPUT_DIM:]])
        self._lam = np.concatenate([lam[INPUT_DIM:], lam[-INPUT_DIM:]])
        return np.clip(U[:INPUT_DIM], self.spec.u_min, self.spec.u_max), ok


def _f(ca, x, u):
    """Eq. 3.13 in CasADi symbols."""
    spsi, cpsi = ca.sin(x[6]), ca.cos(x[6])
    tphi, tth, cth = ca.tan(u[1]), ca.tan(u[2]), ca.cos(u[2])
    thrust = u[0] + GRAVITY_MPS2
    return ca.vertcat(x[1], (spsi * tphi / cth + cpsi * tth) * thrust,
                      x[3], (-cpsi * tphi / cth + spsi * tth) * thrust,
                      x[5], u[0], u[3])
