"""The supervision stage of the tick (:mod:`ardrone_nmpc.runtime.stages`): the supervisor's
verdict turned into the command sent (:class:`Supervision`), and what a tick sends
(:class:`Sent`).

Its own module for size (the stages module stays under the architecture test's cap);
:mod:`~ardrone_nmpc.runtime.stages` re-exports :data:`HOVER`, :class:`Sent` and
:class:`Supervision`, so imports from there keep working. The control case's compiled twin,
the nominal tick's: ``runtime/after_solve.py``.
"""

from __future__ import annotations

import math
import struct
from typing import NamedTuple

import numpy as np

from ardrone_nmpc.control.mapping import UNSATURATED, DroneLimits, PcmdCommand, pcmd_of_floats
from ardrone_nmpc.core.types import INPUT_DIM, IU_ZACC, AttitudeCommand
from ardrone_nmpc.safety import Action, Decision, Supervisor

__all__ = ["CMD_SATURATED_TEXT", "HOVER", "Sent", "Supervision"]

HOVER = PcmdCommand(0.0, 0.0, 0.0, 0.0, (False, False, False, False))

#: the ``cmd_saturated`` text of the (roll, pitch, gaz, yaw) flags: one lookup, not four
#: conditionals and three concatenations
CMD_SATURATED_TEXT = {(a, b, c, d): "".join("1" if f else "0" for f in (a, b, c, d))
                      for a in (False, True) for b in (False, True) for c in (False, True)
                      for d in (False, True)}

# enum members bound once: ``Action.CONTROL`` is a lookup through the enum's metaclass
# (~0.1 µs), and the tick makes a dozen
_CONTROL, _FALLBACK, _HOLD = Action.CONTROL, Action.FALLBACK, Action.HOLD
# the (4,) input sent, from four Python floats (native doubles, the same bits)
_pack_input = struct.Struct(f"{INPUT_DIM}d").pack
_frombuffer = np.frombuffer
# a Sent from all its fields without the NamedTuple's Python ``__new__`` (a frame a tick)
_new_tuple = tuple.__new__


class Sent(NamedTuple):
    """What a tick sends and why (a NamedTuple, as :class:`Solution`).

    ``u`` is the (4,) input as flown, for the delay predictor and the ż estimator (z̈ only
    from the NMPC; zeros for a hover): read, never written (the usual tick's is read-only).
    ``flown`` is a newly sent command after tilt clipping and ``saturated`` its
    ``cmd_saturated`` flags (None for a hold or a hover).
    """

    pcmd: PcmdCommand
    u: np.ndarray
    progressive: bool
    decision: Decision
    flown: AttitudeCommand | None = None
    saturated: str | None = None


class Supervision:
    """The supervisor's verdict turned into the command sent, and the memory of it.

    A hold resends the last command sent (a hover if none was); a control or fallback
    command is tilt-clipped and mapped (a hover if it is not finite); hover, land and stop
    send the drone's own hover and forget the last command.

    Parameters
    ----------
    supervisor : the flight's :class:`~ardrone_nmpc.safety.Supervisor`.
    limits : for the mapping to PCMD fractions.
    attitude_gain : the drone's tilt per unit command over the nominal one; the NMPC's
        commands (:attr:`Action.CONTROL`) are divided by it, the P fallback's are not (its
        gains are chosen on the plant, thesis eq. 4.16). 1 for the P controller itself.
    """

    def __init__(self, supervisor: Supervisor, limits: DroneLimits,
                 attitude_gain: float = 1.0) -> None:
        self.supervisor = supervisor
        self.limits = limits
        self.attitude_gain = attitude_gain  # the drone's tilt per unit command, over E
        self._last: tuple[PcmdCommand, np.ndarray] | None = None  # for a hold
        self.vz_ref_mps = 0.0  # ż reference of the command last sent (0 after a hover)
        self.zacc_mps2 = 0.0   # z̈ of the input last sent (the ż estimator's input)

    @property
    def limits(self) -> DroneLimits:
        """The command at PCMD ±1 (:func:`~ardrone_nmpc.control.mapping.command_scales`)."""
        return self._limits

    @limits.setter
    def limits(self, limits: DroneLimits) -> None:
        self._limits = limits
        # unpacked once: the mapping's three attribute lookups a tick (pcmd_of_floats)
        self._scales = (limits.euler_angle_max_rad, limits.control_vz_max_mps,
                        limits.control_yaw_radps)

    def command(self, decision: Decision, cmd: AttitudeCommand | None,
                zacc_mps2: float) -> Sent:
        """What ``decision`` sends; ``cmd`` is the controller's command for control/fallback,
        ``zacc_mps2`` the NMPC's z̈ behind it (NaN for the P controller). It notes the ż
        reference and the z̈ sent (:attr:`vz_ref_mps`, :attr:`zacc_mps2`). The control case's
        compiled twin, the nominal tick's: ``runtime/after_solve.py``."""
        if decision.action is _CONTROL and cmd is not None:
            # the usual tick: the controller's command as Python floats, its tilt inside the
            # cap (which a NaN fails) — :meth:`_command`'s control case with nothing to
            # clip, convert or refuse; anything else goes there
            vz, roll, pitch, rate = cmd.vz_ref_mps, cmd.phi_rad, cmd.theta_rad, cmd.psirate_radps
            cap = self.supervisor.max_tilt_rad
            if (vz.__class__ is float and roll.__class__ is float
                    and pitch.__class__ is float and rate.__class__ is float
                    and zacc_mps2.__class__ is float and -cap <= roll <= cap
                    and -cap <= pitch <= cap and vz - vz == 0.0 and rate - rate == 0.0):
                k = self.attitude_gain
                e, vz_max, yaw_max = self._scales
                if k != 1.0:  # (float(): a gain may be a numpy scalar)
                    pcmd = pcmd_of_floats(vz, float(roll / k), float(pitch / k), rate, e,
                                          vz_max, yaw_max)
                else:
                    pcmd = pcmd_of_floats(vz, roll, pitch, rate, e, vz_max, yaw_max)
                saturated = pcmd.saturated
                flags = "0000" if saturated is UNSATURATED else CMD_SATURATED_TEXT[saturated]
                zacc = zacc_mps2 if zacc_mps2 - zacc_mps2 == 0.0 else 0.0
                # np.array((zacc, roll, pitch, rate))'s values, read-only (the delay ring
                # copies it, nothing writes it): ~100 ns under numpy's look at the tuple
                u_sent = _frombuffer(_pack_input(zacc, roll, pitch, rate))
                self.zacc_mps2 = zacc
                self.vz_ref_mps = vz
                self._last = (pcmd, u_sent)
                return _new_tuple(Sent, (pcmd, u_sent, True, decision, cmd, flags))
        return self._command(decision, cmd, zacc_mps2)

    def _command(self, decision: Decision, cmd: AttitudeCommand | None,
                 zacc_mps2: float) -> Sent:
        """:meth:`command`, every case."""
        action = decision.action
        if action is _HOLD and self._last is not None:
            pcmd, u_sent = self._last
            self.zacc_mps2 = float(u_sent[IU_ZACC])
            return _new_tuple(Sent, (pcmd, u_sent, True, decision, None, None))
        if cmd is not None and (action is _CONTROL or action is _FALLBACK):
            roll, pitch = cmd.phi_rad, cmd.theta_rad
            cap = self.supervisor.max_tilt_rad
            if -cap <= roll <= cap and -cap <= pitch <= cap:  # what clip_tilt_rad leaves be
                roll_clipped = pitch_clipped = False
            else:
                roll, roll_clipped = self.supervisor.clip_tilt_rad(roll)
                pitch, pitch_clipped = self.supervisor.clip_tilt_rad(pitch)
            vz, rate = cmd.vz_ref_mps, cmd.psirate_radps
            if (math.isfinite(vz) and math.isfinite(roll) and math.isfinite(pitch)
                    and math.isfinite(rate)):
                # the NMPC's tilt per its model's gain: the tilt to ask for so that the drone
                # tilts by the command's; P's gains are chosen on the plant. Finite, checked
                # above: pcmd_of's arithmetic without its checks (float(): a numpy scalar's
                # fraction would log as one)
                k = self.attitude_gain
                e, vz_max, yaw_max = self._scales
                if action is _CONTROL and k != 1.0:
                    pcmd = pcmd_of_floats(float(vz), float(roll / k), float(pitch / k),
                                          float(rate), e, vz_max, yaw_max)
                else:
                    pcmd = pcmd_of_floats(float(vz), float(roll), float(pitch), float(rate),
                                          e, vz_max, yaw_max)
                saturated = pcmd.saturated
                if saturated is UNSATURATED and not (roll_clipped or pitch_clipped):
                    flags = "0000"
                else:
                    s0, s1, s2, s3 = saturated
                    flags = CMD_SATURATED_TEXT[(s0 or roll_clipped, s1 or pitch_clipped, s2, s3)]
                zacc = zacc_mps2 if action is _CONTROL and math.isfinite(zacc_mps2) else 0.0
                u_sent = np.array((zacc, roll, pitch, rate))  # a tuple: ~10% under a list
                self.zacc_mps2 = float(zacc)  # u_sent[IU_ZACC], without numpy's scalar
                self.vz_ref_mps = vz
                self._last = (pcmd, u_sent)
                # the command as flown: the controller's own record unless a tilt was clipped
                flown = (cmd if not (roll_clipped or pitch_clipped)
                         else AttitudeCommand(vz, roll, pitch, rate))
                # every field given: the tuple without the NamedTuple's Python ``__new__``
                return _new_tuple(Sent, (pcmd, u_sent, True, decision, flown, flags))
            decision = Decision(Action.HOVER, "nonfinite-command")  # never sent
        elif action is _HOLD:  # nothing sent yet that could be held
            decision = Decision(Action.HOVER, decision.reason)
        # hover, land, stop: the drone's own hover — no acceleration, for the delay predictor
        # and the integrators; the last NMPC input is never flown
        self.vz_ref_mps = 0.0
        self.zacc_mps2 = 0.0
        self._last = None
        return _new_tuple(Sent, (HOVER, np.zeros(INPUT_DIM), False, decision, None, None))
