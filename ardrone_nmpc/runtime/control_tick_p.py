"""The P controller's nominal tick (thesis eq. 4.16) in one compiled call, as the NMPC's.

``Tick.step`` of a P flight made the Python stages' calls a tick: the supervisor's looks,
the estimate, ``Control._p_solve`` (``runtime/p_tick``: the reference and the law compiled),
the command's mapping (``Supervision.command``), the delay ring's write and the response
estimator's feed (issue 26). :func:`control_tick_p` makes them from compiled code — the
stages before the solve (:func:`~.before_solve.before_solve`, its lookup ``p_tick``'s: one
time, nothing pending), the law (:func:`~.p_tick.p_law`) where the NMPC solves, and the
stages after it (:func:`~.after_solve.after_solve`) — and takes
:func:`~.control_tick.control_tick`'s arguments, so that blocks of ticks fly P flights by
its kernel's twin (``runtime/lockstep_block.tick_block_p``).

``after_solve`` maps an NMPC's z̈ to a ż reference (``vz_base + z̈ · lead``, clipped); P's
ż reference is the law's, sent unclipped (``Control.command`` hands the P command as it
is): it is given as the base with z̈ 0 and a lead of −0 — ``vz + 0 · (−0)`` is ``vz`` to the
bit, a −0 included —, and no limit. The z̈ sent is 0 (``Supervision.command``: P's z̈ is
NaN, not finite), the attitude gain 1 (P's gains are chosen on the plant).

:class:`PControlTick` is the Python side: :class:`~.control_tick.ControlTick`'s call and
vetting, with P's preconditions (a waypoint reference packed by its first tick, a
:class:`~.before_solve.BeforeSolve` of its own for the arguments), P's tail (the gains
where the solver's memory goes) and P's records: the per-tick path's ``Solution`` and
``Sent``, so that the row is its row (``log_columns._general_row``: no solver's cells).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ardrone_nmpc.control.kernels import FLAG_OK
from ardrone_nmpc.core import monotonic
from ardrone_nmpc.core.entry_points import VettedCall
from ardrone_nmpc.core.kernel_cache import flush_stale_caches
from ardrone_nmpc.core.numerics import OUTER_KERNEL
from ardrone_nmpc.core.types import STATE_DIM, AttitudeCommand
from ardrone_nmpc.reference.experiment import HoldStartThen
from ardrone_nmpc.runtime.after_solve import after_solve
from ardrone_nmpc.runtime.before_solve import BeforeSolve, before_solve
from ardrone_nmpc.runtime.control_tick import (_ARRAYS_OF, _KINDS, NOT_NOMINAL, SOLVED,
                                               ControlTick, control_tick)
from ardrone_nmpc.runtime.estimate import Estimation
from ardrone_nmpc.runtime.p_tick import p_law
from ardrone_nmpc.runtime.stages import Control, Solution
from ardrone_nmpc.runtime.supervision import Supervision
from ardrone_nmpc.runtime.tick_kernels import E_X
from ardrone_nmpc.safety import Supervisor

__all__ = ["PControlTick", "control_tick_p"]

_FLOAT = float
_NO_SETTINGS = np.zeros(6, np.int64)  # (control_tick's solver settings: P has none)


@njit(cache=True, **OUTER_KERNEL)
def control_tick_p(t_s, pose_rx_t_s, navdata_rx_t_s, state_bits, battery_pct, roll_deg,
                   pitch_deg, px, py, pz, psi_rad, pose_t_s, zacc_mps2, navdata_velocity,
                   nav_vx_mps, nav_vy_mps, est, limits, t_exp_s, ring, first, pending, lead_s,
                   x_solve, shift, states, work, rows, vz_ref_last_mps, ring_row, mem, iprm,
                   horizon, step_arg, divergence_residual, vz_from_commands, vz_lead_s,
                   vz_max_mps, tilt_cap_rad, gain, e, v, y, response, has_nav, offset,
                   offset_flags):
    """The P controller's nominal tick, over its state (module docstring):
    :func:`~.control_tick.control_tick`'s arguments and answer, ``mem`` the gains
    (k1 … k4), ``states`` (1, 7) the reference now, ``work`` and ``rows`` ``p_tick``'s;
    the delay's window (``first``, ``pending``, ``lead_s``), the solver's settings, the
    ż base and lead and limit are not read. Its answer's solver figures are 0 (the row has
    none), its z̈ the one sent (0); on :data:`SOLVED` (the stages after the law found the
    tick not nominal) its ż reference and attitude are the law's, for Python to send."""
    code, mocap_ms, nav_ms = before_solve(
        t_s, pose_rx_t_s, navdata_rx_t_s, state_bits, battery_pct, roll_deg, pitch_deg, px, py,
        pz, psi_rad, pose_t_s, zacc_mps2, navdata_velocity, nav_vx_mps, nav_vy_mps, est, limits,
        t_exp_s, ring, 0, 0, 0.0, x_solve, shift, states, work, rows)
    if code != 0:
        return (NOT_NOMINAL, mocap_ms, nav_ms, 0, 0.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 0.0, 0.0, 0.0, 0, 0)
    x = est[E_X:E_X + STATE_DIM]
    vz_p, phi, theta, rate = p_law(x, states[0], mem[0], mem[1], mem[2], mem[3])
    code, vz, roll, pitch, gaz, yaw, bits, fed = after_solve(
        0.0, phi, theta, rate, vz_p, -0.0, math.inf, tilt_cap_rad, gain, e, v, y, ring,
        ring_row, response, has_nav, navdata_rx_t_s, roll_deg, pitch_deg, t_s, x, states[0],
        states[1:], offset, offset_flags)
    if code != 0:
        return (SOLVED, mocap_ms, nav_ms, FLAG_OK, 0.0, 0.0, 0, 0, 0.0, phi, theta, rate, vz_p,
                0.0, 0.0, 0.0, 0.0, 0, 0)
    return (0, mocap_ms, nav_ms, FLAG_OK, 0.0, 0.0, 0, 0, 0.0, phi, theta, rate, vz, roll,
            pitch, gaz, yaw, bits, fed)


_CALL = VettedCall(control_tick_p, *_KINDS)  # (control_tick's arguments' kinds)


class PControlTick(ControlTick):
    """:class:`~.control_tick.ControlTick` for a P flight's tick (module docstring):
    :meth:`answer` and the vetting are its parent's."""

    #: the nominal row is not cells: the per-tick path's P row (``Tick.step``)
    cells = False

    @staticmethod
    def takes(tick) -> bool:
        """Whether the compiled call can take ``tick``'s nominal ticks: the P controller
        against a waypoint reference (``p_tick``'s: not a table), the compiled estimator,
        the stages' own classes (a subclass' overrides are called), the stages after the
        solve built — on a platform whose clock the kernel reads
        (``core/monotonic.SAME_CLOCK``, as the NMPC's)."""
        traj = tick.trajectory
        return (monotonic.SAME_CLOCK and tick.control.nmpc is None
                and traj.__class__ is HoldStartThen and traj.waypoint_args is not None
                and not traj.tabulated and tick.estimation.compiled
                and tick.after_solve is not None and type(tick.supervisor) is Supervisor
                and type(tick.estimation) is Estimation and type(tick.control) is Control
                and type(tick.supervision) is Supervision)

    def __init__(self, tick) -> None:  # (ControlTick's stages, P's kernel: no solver)
        self._stages(tick, BeforeSolve(tick))
        self.nmpc, self._marks = None, None
        self.kernel = control_tick_p
        self._call = _CALL
        self._arrays_at = _ARRAYS_OF[control_tick]

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.kernel, self._call = control_tick_p, _CALL

    def prepared(self) -> tuple | None:
        """The call's tail (:meth:`_prepare`), or None when a precondition of the call that
        no tick's inputs change does not hold: the waypoints packed by P's first tick
        (``Control._p_solve``), no solver fallback (P has none: the supervisor's own)."""
        control, supervision, supervisor = self.control, self.supervision, self.supervisor
        if control._p_work is None or supervisor._solver_fallback:
            return None
        key = self._key
        if not (control.p_gains is key[0] and control.vz_from_commands is key[1]
                and supervision.attitude_gain is key[2] and control.vz_lead_s is key[3]
                and control._vz_max_mps is key[4] and supervisor.max_tilt_rad is key[5]
                and supervision._scales is key[6]) and not self._prepare(None):
            return None
        return self._tail

    def _prepare(self, horizon) -> bool:
        """The call's tail from the stages' objects now (``ControlTick._prepare``'s, the
        gains where the solver's memory goes), kept with the objects it was made of; False
        when a number is not a Python float (``p_tick``'s Python path: its own kinds)."""
        control, supervision = self.control, self.supervision
        key = (control.p_gains, control.vz_from_commands, supervision.attitude_gain,
               control.vz_lead_s, control._vz_max_mps, self.supervisor.max_tilt_rad,
               supervision._scales)
        settings = self.after.settings()
        g = key[0]
        gains = (g.k1_per_s, g.k2_rad_per_mps, g.k3_rad_per_mps, g.k4_per_s)
        if settings is None or not all(k.__class__ is _FLOAT for k in gains):
            return False
        gain, lead, vz_max, tilt_cap, e, v, y = settings
        offset, flags = self.after._offset
        self._tail = (np.array(gains), _NO_SETTINGS, control._states, False, math.inf,
                      key[1], lead, vz_max, tilt_cap, gain, e, v, y,
                      self.after._response_state, 1, offset, flags)
        self._key = key
        self._entry = None  # the tail's arrays vetted on the next call
        return True

    def finish(self, inputs, t_exp_s: float, answer: tuple):
        """``ControlTick.finish`` for P: the records of the tick (code 0) — the per-tick
        path's ``Solution`` (no solver's result: its P command) and ``Sent`` —, the law's
        command for Python to send (SOLVED), or False (NOT_NOMINAL)."""
        (code, mocap_ms, nav_ms, _, _, _, _, _, zacc, phi, theta, rate, vz, roll, pitch, gaz,
         yaw, bits, fed) = answer
        if code == NOT_NOMINAL:
            return False
        x = self.before.estimation._x
        sol = Solution(self.control._ref_now, x, p_command=AttitudeCommand(vz, phi, theta, rate))
        if code:
            return (mocap_ms, nav_ms), x, sol, False
        sent, events = self.after._records(inputs.t_s, zacc, phi, theta, rate, vz, roll, pitch,
                                           gaz, yaw, bits, fed)
        return (mocap_ms, nav_ms), x, sol, (sent, events)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
