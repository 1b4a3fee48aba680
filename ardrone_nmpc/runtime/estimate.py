"""The estimation stage of the tick (:mod:`ardrone_nmpc.runtime.stages`): the state estimate
``[x, ẋ, y, ẏ, z, ż, ψ]`` from the newest mocap pose and navdata.

Its own module for size (the stages module stays under the architecture test's cap);
:mod:`~ardrone_nmpc.runtime.stages` re-exports :class:`Estimation` and
:func:`navdata_velocity_world`, so imports from there keep working.
"""

from __future__ import annotations

import math

import numpy as np

from ardrone_nmpc.core.entry_points import ArrayKind, VettedCall
from ardrone_nmpc.core.types import IX_PSI, IX_VX, IX_VY, IX_VZ, IX_X, IX_Y, IX_Z, STATE_DIM
from ardrone_nmpc.core.types import MocapPose, NavdataSample
from ardrone_nmpc.estimation import BackwardDifference, make_vz_estimator
from ardrone_nmpc.estimation.differentiate import FiniteDifferenceVz, NoVz
from ardrone_nmpc.estimation.kalman import ScalarKalmanVz
from ardrone_nmpc.estimation.luenberger import LuenbergerVz
from ardrone_nmpc.runtime.tick_kernels import (
    E_HAS_POSE, E_HAS_PREV, E_INIT, E_K, E_LAST_T, E_MIDPOINT, E_P, E_P0, E_PREV_X, E_PREV_Y,
    E_Q, E_R, E_SIZE, E_TABLE, E_VEL_X, E_VEL_Y, E_VZ, E_VZ_KIND, E_X, E_Z, E_Z_PREV,
    ESTIMATED, LU_ENTRIES, LU_ENTRY, NO_COEFFICIENTS, VZ_DIFFERENCE, VZ_KALMAN, VZ_LUENBERGER,
    VZ_NONE, estimate_step,
)

__all__ = ["Estimation", "navdata_velocity_world"]

# the estimate's slots in index order, written in one assignment (seven cost ~0.5 µs more)
assert (IX_X, IX_VX, IX_Y, IX_VY, IX_Z, IX_VZ, IX_PSI) == tuple(range(STATE_DIM))
assert ESTIMATED == 0  # Estimation.update tests estimate_step's answer for truth
_NDARRAY = np.ndarray  # a pose's position: an ndarray (a subclass takes the general spelling)
_FLOAT = float


#: ``estimate_step``'s call on an estimation's own state and float numbers (the flags: bools)
_STEP = VettedCall(estimate_step, ArrayKind(1), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False, 0.0, 0.0)
#: the ż estimators the compiled step carries on: its name for each, and the slots their
#: ``state()`` goes to (``set_state`` takes it back)
_VZ_KINDS = {ScalarKalmanVz: (VZ_KALMAN, (E_Z, E_VZ, E_P, E_K, E_INIT)),
             LuenbergerVz: (VZ_LUENBERGER, (E_Z, E_VZ, E_Z_PREV, E_INIT)),
             FiniteDifferenceVz: (VZ_DIFFERENCE, (E_Z, E_VZ, E_INIT)),
             NoVz: (VZ_NONE, ())}


def navdata_velocity_world(nav: NavdataSample, psi_rad: float) -> tuple[float, float]:
    """Navdata body velocities (forward, right-positive) → world (ẋ, ẏ) at heading ψ (CCW)."""
    c, s = math.cos(psi_rad), math.sin(psi_rad)
    fwd, right = nav.vx_body_mps, nav.vy_body_mps
    return fwd * c + right * s, fwd * s - right * c


class Estimation:
    """The state ``[x, ẋ, y, ẏ, z, ż, ψ]`` from the newest mocap pose and navdata.

    Position and ψ from mocap; ż from the vertical-speed estimator (fed the z̈ applied over
    the last interval); ẋ/ẏ from navdata (``estimator.horizontal_velocity: navdata``, when
    there is any) or else backward differences of the mocap positions. A pose seen again (the
    same stamp) updates no estimator.

    Parameters
    ----------
    est_cfg : :class:`~ardrone_nmpc.config.schema.EstimatorConfig`.
    """

    def __init__(self, est_cfg) -> None:
        self._vz_estimator = make_vz_estimator(
            est_cfg.kind, kalman_q=est_cfg.kalman_q, kalman_r=est_cfg.kalman_r,
            kalman_p0=est_cfg.kalman_p0, lambda0_per_s=est_cfg.luenberger_lambda0_per_s,
            gain=est_cfg.luenberger_gain)
        self._xy_difference = BackwardDifference(size=2)
        self.velocity_from_navdata = est_cfg.horizontal_velocity == "navdata"
        self._last_pose_t_s: float | None = None
        self._x = np.zeros(STATE_DIM)
        # the ż estimator's (any of estimator.kind's) and the difference's state in one buffer,
        # updated by one compiled call (runtime/tick_kernels.estimate_step) until
        # someone asks for the estimator objects themselves: they get it back (_leave_compiled)
        self._compiled = type(self._vz_estimator) in _VZ_KINDS
        if self._compiled:
            self._state = np.zeros(E_SIZE)
            self._bind_state()
            self._to_compiled()

    def _bind_state(self) -> None:
        """The estimate as a view of the compiled step's state (it writes it there), and the
        step's call: ``estimate_step``'s compiled entry point for this state once known
        (core/entry_points.VettedCall.bind: the dispatcher on the first call if not yet), which
        skips the dispatcher's look-up of ten arguments' types. The state is a plain float64
        vector (VettedCall checks it); of the numbers,
        the flags are literals and each float parameter is only made a float64 — by
        ``float()`` in the entry point's unboxing, by the dispatcher's specialisation for
        another number's type in the kernel, the same value either way."""
        self._x = self._state[E_X:E_X + STATE_DIM]
        _STEP.bind(self, "_step", self._state)

    def __getstate__(self) -> dict:
        """Without what :meth:`_bind_state` makes (an entry point does not pickle)."""
        state = self.__dict__.copy()
        if "_state" in state:
            del state["_x"], state["_step"]
        return state

    def __setstate__(self, state: dict) -> None:
        """A deep copy or unpickling: numpy copies a view apart from its array, so the
        estimate is made a view of the copied state again (else the copy's updates would
        write one array and answer another)."""
        self.__dict__.update(state)
        if "_state" in state:
            self._bind_state()

    # the estimators as objects: their state, handed back from the compiled step
    @property
    def vz_estimator(self):
        """The ż estimator (:func:`~ardrone_nmpc.estimation.make_vz_estimator`)."""
        self._leave_compiled()
        return self._vz_estimator

    @vz_estimator.setter
    def vz_estimator(self, estimator) -> None:
        self._leave_compiled()
        self._vz_estimator = estimator

    @property
    def xy_difference(self) -> BackwardDifference:
        """The backward difference of the mocap x, y."""
        self._leave_compiled()
        return self._xy_difference

    @property
    def compiled(self) -> bool:
        """True while the compiled step (``estimate_step``) holds the estimators' state."""
        return self._compiled

    def _to_compiled(self) -> None:
        s = self._state
        s[E_HAS_POSE] = self._last_pose_t_s is not None
        s[E_LAST_T] = self._last_pose_t_s if self._last_pose_t_s is not None else math.nan
        vz = self._vz_estimator
        kind, slots = _VZ_KINDS[type(vz)]
        s[E_VZ_KIND] = kind
        if kind == VZ_KALMAN:
            s[E_Q], s[E_R], s[E_P0], s[E_MIDPOINT] = vz.constants
        s[list(slots)] = vz.state()
        s[E_TABLE:E_TABLE + LU_ENTRIES * LU_ENTRY:LU_ENTRY] = math.nan  # no Δt yet
        self._next_entry = 0
        if kind == VZ_LUENBERGER:  # but those the observer knows (earlier flights')
            for dt_s, coefficients in vz.cached_coefficients()[-LU_ENTRIES:]:
                self._add_coefficients(dt_s, coefficients)
        previous, (s[E_VEL_X], s[E_VEL_Y]) = self._xy_difference.state()
        s[E_HAS_PREV] = previous is not None
        s[E_PREV_X], s[E_PREV_Y] = previous if previous is not None else (0.0, 0.0)

    def _leave_compiled(self) -> None:
        """The compiled step's state back into the estimator objects, which hold it from now on
        (the Python path: the same arithmetic)."""
        if not self._compiled:
            return
        self._compiled = False
        (has_pose, last_t, *_, has_prev, prev_x, prev_y, vel_x, vel_y) = (
            self._state[:E_X].tolist())
        self._last_pose_t_s = last_t if has_pose else None
        _, slots = _VZ_KINDS[type(self._vz_estimator)]
        self._vz_estimator.set_state(*self._state[list(slots)].tolist())
        self._xy_difference.set_state((prev_x, prev_y) if has_prev else None, (vel_x, vel_y))

    def _add_coefficients(self, dt_s: float, coefficients: tuple) -> None:
        """The observer's ``coefficients`` for ``dt_s`` into the step's table, over its oldest
        entry: its Python object's (``LuenbergerVz.coefficients``), the same bits either way."""
        s = self._state
        at = E_TABLE + self._next_entry * LU_ENTRY
        s[at + 1:at + LU_ENTRY] = coefficients
        s[at] = dt_s
        self._next_entry = (self._next_entry + 1) % LU_ENTRIES

    def update(self, pose: MocapPose, navdata: NavdataSample | None,
               zacc_mps2: float) -> np.ndarray:
        """The estimate after ``pose``; ``zacc_mps2`` is the z̈ applied since the last pose.

        Returns the stage's own (7,) array, overwritten by the next call.
        """
        pos = pose.position_m  # as Python floats: numpy's scalars cost ~10× to handle
        px, py, pz = pos.tolist() if pos.__class__ is _NDARRAY else map(float, pos)
        t_s = pose.t_s
        if t_s.__class__ is not _FLOAT and not isinstance(t_s, (float, int)):
            # a float32 stamp, say: the Python path's Δt is its type's difference, the
            # step's a float64's — the objects carry on
            self._leave_compiled()
        if self._compiled:
            # ``not``: ESTIMATED is 0 (one comparison a tick less)
            if navdata is None or not self.velocity_from_navdata:
                navdata_velocity, vx, vy = False, 0.0, 0.0
            else:
                navdata_velocity = True
                vx, vy = navdata_velocity_world(navdata, pose.psi_rad)
            code = self._step(self._state, px, py, pz, pose.psi_rad, t_s, zacc_mps2,
                              navdata_velocity, vx, vy)
            if not code:
                return self._x
            if code == NO_COEFFICIENTS:  # a Δt the observer's table lacks: added, stepped
                dt_s = float(t_s) - float(self._state[E_LAST_T])  # (the step's: float64)
                self._add_coefficients(dt_s, self._vz_estimator.coefficients(dt_s))
                if not self._step(self._state, px, py, pz, pose.psi_rad, t_s, zacc_mps2,
                                  navdata_velocity, vx, vy):
                    return self._x
            self._leave_compiled()  # refused: the estimators raise their own error below
        if pose.t_s != self._last_pose_t_s:
            if self._last_pose_t_s is None:
                self._vz_estimator.reset(pz)
                self._xy_difference.reset()
                self._xy_difference.update((px, py), 1.0)
            else:
                dt = pose.t_s - self._last_pose_t_s
                self._vz_estimator.update(pz, zacc_mps2, dt)
                self._xy_difference.update((px, py), dt)
            self._last_pose_t_s = pose.t_s
        if self.velocity_from_navdata and navdata is not None:
            vx, vy = navdata_velocity_world(navdata, pose.psi_rad)
        else:
            vx, vy = self._xy_difference.velocity_mps
        x = self._x
        # [x, ẋ, y, ẏ, z, ż, ψ]
        x[:] = (px, vx, py, vy, pz, self._vz_estimator.vz_mps, pose.psi_rad)
        return x
