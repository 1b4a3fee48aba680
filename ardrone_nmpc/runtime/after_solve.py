"""The controller's stages after the NMPC's solve, on the nominal tick, in one compiled call.

After ``Control.solve`` the usual tick made six Python calls and four numba dispatches —
the supervisor's verdict on the solution (``Supervisor.check_solution``), the attitude
command (``Control.command``), its mapping to PCMD (``Supervision.command``), the delay
ring's write (``DelayPrediction.push``), the response estimator's feed
(``ResponseEstimation.update``) and the integrator's step (``OffsetFree.update``): ~10 µs,
mostly glue (issue 26). :func:`after_solve` does their arithmetic — the same expressions in
the same order, Python's ``min``/``max`` and NaN tests spelled out — over the same arrays
the Python stages use (the delay ring, the estimator's state, the integrator's buffers), so
either path can take any tick. It first tests everything that makes the tick nominal and
answers :data:`NOT_NOMINAL`, with nothing written, when one fails: the caller then runs the
Python stages, which decide as they always did.

:class:`AfterSolve` is the Python side: its preconditions (the solver trusted, no solver
fallback under way), the call, and the records the tick's row and the drone's command need.
The fit every ``refit_s`` and the events stay in Python (``ResponseEstimation.refit``).
"""

from __future__ import annotations

import math
import struct

import numpy as np
from numba import njit

from ardrone_nmpc.control.mapping import UNSATURATED, PcmdCommand
from ardrone_nmpc.core.kernel_cache import first_warm_up, flush_stale_caches
from ardrone_nmpc.core.numerics import INNER_KERNEL, OUTER_KERNEL
from ardrone_nmpc.core.types import (INPUT_DIM, IU_PHI, IU_PSIRATE, IU_THETA, IU_ZACC, IX_VZ,
                                     AttitudeCommand)
from ardrone_nmpc.estimation.disturbance import SATURATION_FRAC, integrate_period
from ardrone_nmpc.estimation.response_kernels import (CMD_SEND, TIMES_ROUNDED, feed,
                                                      microseconds, new_state)
from ardrone_nmpc.runtime.supervision import CMD_SATURATED_TEXT, Sent
from ardrone_nmpc.safety import NOMINAL

__all__ = ["AfterSolve", "NOT_NOMINAL", "SATURATED_TEXT", "after_solve", "warm_up_kernels"]

#: :func:`after_solve`'s first answer when the tick is not nominal (nothing written).
NOT_NOMINAL = -1
_NOTHING = np.zeros(0)  # the estimator's state, the integrator's buffers: of a flight without
_NO_FLAGS = np.zeros((3, 0), dtype=np.bool_)
_NDARRAY = np.ndarray
_FLOAT = float


@njit(cache=True, **OUTER_KERNEL)
def after_solve(zacc, phi, theta, rate, vz_base_mps, vz_lead_s, vz_max_mps, tilt_cap_rad, gain,
                e, v, y, ring, row, response, has_nav, t_nav_s, roll_deg, pitch_deg, t_s, x,
                ref_now, ref_horizon, offset, offset_flags):
    """The nominal tick's stages after the solve, over their state (module docstring).

    The NMPC's input (``zacc`` … ``rate``), the ż it is added to (``vz_base_mps``,
    ``Control.command``'s), the supervisor's tilt cap, the attitude gain and the mapping's
    scales (``e``, ``v``, ``y``: E, V, Y) as numbers (a float costs numba's dispatch ~2 ns,
    an array ~65); ``ring`` the delay's inputs sent and ``row`` the next row; ``response``
    the estimator's state (empty: none), fed the navdata sample (``has_nav`` 1) and the
    command sent at ``t_s``; ``offset``, ``offset_flags`` the integrator's buffers (empty:
    none), stepped on the estimate ``x`` and the reference now and over the horizon
    (``ref_now``, ``ref_horizon``: unshifted, as logged).

    Returns (code, ż ref, the four PCMD fractions, their saturation bits — roll 1, pitch 2,
    gaz 4, yaw 8 —, the feed's answer); code :data:`NOT_NOMINAL` when the tick is not nominal,
    and then nothing was written."""
    nothing = (NOT_NOMINAL, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)
    # check_solution's verdict on a trusted solve: its input finite
    if not (math.isfinite(zacc) and math.isfinite(phi) and math.isfinite(theta)
            and math.isfinite(rate)):
        return nothing
    # Control.command: the ż reference, clipped (Python's min/max: a NaN stays)
    vz = vz_base_mps + zacc * vz_lead_s
    if not (vz - vz == 0.0 and vz_lead_s >= 0.0):  # vz_reference_mps answers or raises
        return nothing
    if -vz_max_mps > vz:
        vz = -vz_max_mps
    if vz_max_mps < vz:
        vz = vz_max_mps
    # Supervision.command's usual case: the tilt inside the cap (else it clips and flags)
    if not (-tilt_cap_rad <= phi <= tilt_cap_rad and -tilt_cap_rad <= theta <= tilt_cap_rad):
        return nothing
    # the estimator's times to the microsecond; one its kernel refuses is Python's to round
    fed = response.size != 0
    if fed:
        if has_nav:
            t_nav_s = microseconds(t_nav_s)
            if t_nav_s < 0.0:
                return nothing
        t_s = microseconds(t_s)
        if t_s < 0.0:
            return nothing
    # --- nominal: from here on the stages' state is written
    roll, pitch = phi, theta
    if gain != 1.0:
        roll, pitch = phi / gain, theta / gain
    roll, pitch, gaz, yaw, bits = _fractions(vz, roll, pitch, rate, e, v, y)
    # DelayPrediction.push: rows i and i + capacity
    capacity = ring.shape[0] // 2
    for r in (row, row + capacity):
        ring[r, IU_ZACC] = zacc
        ring[r, IU_PHI] = phi
        ring[r, IU_THETA] = theta
        ring[r, IU_PSIRATE] = rate
    code = 0
    if fed:  # ResponseEstimation.update's feed: the sample, then the command sent
        code = feed(response, has_nav != 0, t_nav_s, roll_deg, pitch_deg, CMD_SEND + TIMES_ROUNDED,
                    t_s, roll, pitch)
    if offset.size != 0:  # OffsetFree.update: frozen_axes of the command, then the step
        _freeze(roll, pitch, gaz, yaw, bits, offset_flags[2])
        integrate_period(x, ref_now, ref_horizon, offset, offset_flags)
    return (0, vz, roll, pitch, gaz, yaw, bits, code)


@njit(cache=True, **INNER_KERNEL)
def _fractions(vz, roll, pitch, rate, e, v, y):
    """``pcmd_of_floats``' arithmetic: the four fractions, and their clip flags as bits."""
    fr = roll / e
    fp = -pitch / e
    fg = vz / v
    fy = -rate / y
    if -1.0 <= fr <= 1.0 and -1.0 <= fp <= 1.0 and -1.0 <= fg <= 1.0 and -1.0 <= fy <= 1.0:
        return fr + 0.0, fp + 0.0, fg + 0.0, fy + 0.0, 0
    fr, b0 = _clip_unit(fr)
    fp, b1 = _clip_unit(fp)
    fg, b2 = _clip_unit(fg)
    fy, b3 = _clip_unit(fy)
    return fr, fp, fg, fy, b0 | b1 << 1 | b2 << 2 | b3 << 3


@njit(cache=True, **INNER_KERNEL)
def _clip_unit(f):
    """``mapping._clip_unit``: ``f`` clipped to [−1, 1] (−0.0 made 0.0), and 1 if it was."""
    if f > 1.0:
        return 1.0, 1
    if f < -1.0:
        return -1.0, 1
    return f + 0.0, 0


@njit(cache=True, **INNER_KERNEL)
def _freeze(roll, pitch, gaz, yaw, bits, frozen):
    """``frozen_axes`` of the fractions and flags, into the integrator's ``frozen`` row
    (left clear, as ``ReferenceIntegrator.step`` leaves it, when nothing is frozen)."""
    lim = SATURATION_FRAC
    if (-lim < roll < lim and -lim < pitch < lim and -lim < gaz < lim and -lim < yaw < lim
            and bits == 0):
        return
    tilt = (abs(roll) >= lim or bits & 1 != 0) or (abs(pitch) >= lim or bits & 2 != 0)
    frozen[0] = tilt
    frozen[1] = tilt
    frozen[2] = abs(gaz) >= lim or bits & 4 != 0
    frozen[3] = abs(yaw) >= lim or bits & 8 != 0


# the PcmdCommand flags and the ``cmd_saturated`` text of each set of bits
_SATURATED = [UNSATURATED] + [tuple(bool(b >> k & 1) for k in range(4)) for b in range(1, 16)]
#: the ``cmd_saturated`` text of each set of :func:`after_solve`'s saturation bits
SATURATED_TEXT = tuple(CMD_SATURATED_TEXT[s] for s in _SATURATED)
_pack_input = struct.Struct(f"{INPUT_DIM}d").pack
_frombuffer = np.frombuffer
_make_pcmd = PcmdCommand.make
_make_cmd = AttitudeCommand.make


class AfterSolve:
    """The Python side of :func:`after_solve` for one tick's stages (``Tick``'s): bound to
    them, and to the estimator's and the integrator's buffers, when it is made."""

    def __init__(self, tick) -> None:
        self.supervisor = tick.supervisor
        self.control = tick.control
        self.supervision = tick.supervision
        self.delay = tick.delay
        self.response = tick.response
        self.offset = tick.offset
        self._response_state = (_NOTHING if self.response is None
                                else self.response.estimator._state)
        integrator = self.offset.integrator if self.offset is not None else None
        self._offset = (_NOTHING, _NO_FLAGS) if integrator is None else (integrator._work,
                                                                         integrator._flags)

    def nominal(self, inputs, x, sol):
        """The nominal tick's :class:`~ardrone_nmpc.runtime.stages.Sent` and the response
        fit's events, all stages after the solve done; None (nothing done) when the tick is
        not nominal."""
        if not sol.ok:  # check_solution's other verdicts
            return None
        u = sol.u_flown
        if u.__class__ is not _NDARRAY:  # (check_solution takes any sequence: its path)
            return None
        settings = self.settings()
        if settings is None:
            return None
        gain, lead, vz_max, tilt_cap, e, v, y = settings
        zacc, phi, theta, rate = u.tolist()  # Python floats: ~2 ns each to numba, an array ~65
        # Control.command's
        vz_base = (float(self.supervision.vz_ref_mps) if self.control.vz_from_commands
                   else sol.x_solve.item(IX_VZ))
        nav = inputs.navdata
        if nav is not None:
            has, t_nav, roll_deg, pitch_deg = 1, inputs.navdata_rx_t_s, nav.roll_deg, nav.pitch_deg
        else:
            has, t_nav, roll_deg, pitch_deg = 0, 0.0, 0.0, 0.0
        offset, flags = self._offset
        code, vz, roll, pitch, gaz, yaw, bits, fed = after_solve(
            zacc, phi, theta, rate, vz_base, lead, vz_max, tilt_cap, gain, e, v, y,
            self.delay._sent, self.delay._next, self._response_state, has, t_nav, roll_deg,
            pitch_deg, inputs.t_s, x, sol.ref_now, sol.ref_horizon, offset, flags)
        if code:
            return None
        return self._records(inputs.t_s, zacc, phi, theta, rate, vz, roll, pitch, gaz, yaw,
                             bits, fed)

    def settings(self) -> tuple | None:
        """The numbers :func:`after_solve` computes with — the attitude gain, the ż lead and
        limit, the supervisor's tilt cap, the mapping's scales — or None when a precondition
        of the compiled call does not hold (the solver distrusted, or a number not a Python
        float)."""
        if self.supervisor._solver_fallback:  # check_solution's other verdicts
            return None
        control, supervision = self.control, self.supervision
        gain, lead, vz_max = supervision.attitude_gain, control.vz_lead_s, control._vz_max_mps
        tilt_cap = self.supervisor.max_tilt_rad
        e, v, y = supervision._scales
        # the numbers the stages compute with as Python floats, as a config gives them: with
        # numpy scalars the Python stages answer numpy scalars (float32 ones: float32
        # arithmetic, NEP 50) and Supervision takes its general path — their ticks, not the
        # kernel's (an int would also cost the kernel a compile aloft); a float32 tilt cap
        # would be compared in float32 by Python's clip
        if not (gain.__class__ is _FLOAT and lead.__class__ is _FLOAT
                and vz_max.__class__ is _FLOAT and tilt_cap.__class__ is _FLOAT
                and e.__class__ is _FLOAT and v.__class__ is _FLOAT and y.__class__ is _FLOAT):
            return None
        return gain, lead, vz_max, tilt_cap, e, v, y

    def _records(self, t_s, zacc, phi, theta, rate, vz, roll, pitch, gaz, yaw, bits, fed):
        """What the Python stages keep and the tick hands on, from the kernel's answer."""
        pcmd, u_sent, events = self.written(t_s, zacc, phi, theta, rate, vz, roll, pitch, gaz,
                                            yaw, bits, fed)
        return tuple.__new__(Sent, (pcmd, u_sent, True, NOMINAL, _make_cmd(vz, phi, theta, rate),
                                    SATURATED_TEXT[bits])), events

    def kept(self, zacc, phi, theta, rate, vz, roll, pitch, gaz, yaw, bits) -> tuple:
        """What the supervisor and :class:`Supervision` keep of a nominal tick's answer (the
        input sent, the ż reference, the PCMD fractions and saturation bits): the PCMD and
        the input sent (read-only), kept as their last (:meth:`written`'s, and a block of
        ticks' last one's: ``runtime/lockstep_block``)."""
        self.supervisor._solver_failures = 0
        pcmd = _make_pcmd(roll, pitch, gaz, yaw, _SATURATED[bits])
        u_sent = _frombuffer(_pack_input(zacc, phi, theta, rate))
        supervision = self.supervision
        supervision.zacc_mps2 = zacc
        supervision.vz_ref_mps = vz
        supervision._last = (pcmd, u_sent)
        return pcmd, u_sent

    def written(self, t_s, zacc, phi, theta, rate, vz, roll, pitch, gaz, yaw, bits, fed):
        """What the Python stages keep of the kernel's answer, written to them: the PCMD sent,
        the input sent (``u``: read-only) and the response fit's events — without the
        :class:`Sent` a row that takes the answer's numbers needs no more of."""
        pcmd, u_sent = self.kept(zacc, phi, theta, rate, vz, roll, pitch, gaz, yaw, bits)
        self.delay._advance()
        response = self.response
        if response is None:
            return pcmd, u_sent, []
        if fed:  # a new sample: the estimate is fitted when it is read
            response.estimator._estimate = None
        if t_s < response._next_fit_s:  # (refit's own first test, without its call: no fit due)
            return pcmd, u_sent, []
        return pcmd, u_sent, response.refit(t_s)


def warm_up_kernels() -> None:
    """Load (or compile) :func:`after_solve` now — once per process —, its callees from the
    cache first (``core/kernel_cache.first_warm_up``), not on the first tick aloft."""
    if not first_warm_up(after_solve):
        return
    x = np.zeros(7)
    ring = np.zeros((2, INPUT_DIM))
    state = new_state(np.zeros(2), np.ones(1), 4, 0.2, 30.0, 15)
    after_solve(0.0, 0.0, 0.0, 0.0, 0.0, 0.065, 0.7, 0.3, 1.0, 1.0, 1.0, 1.0, ring, 0, state, 1,
                1.0, 0.0, 0.0, 1.0, x, x, np.zeros((2, 7)), _NOTHING, _NO_FLAGS)


flush_stale_caches(__name__)  # kernels calling other files: core/kernel_cache.py
