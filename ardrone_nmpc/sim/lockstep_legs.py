"""The direct sensor path's tick in one compiled call, when nothing but physics happens in it.

:class:`CompiledLegs` hands :func:`~ardrone_nmpc.sim.sensor_step.lockstep_run` the plant's
state, runs it and takes the state back, for
:meth:`LockstepSensors._advance_direct <ardrone_nmpc.sim.sensors.LockstepSensors>`. It reads
and writes the plant's and the firmware's internals (it is their compiled path, not a
client), and is used only when the Python path's tick would do what the kernel does:

* the plant is an :class:`~ardrone_nmpc.sim.plant.AirframePlant` FLYING, TAKING_OFF or
  LANDING on its own dynamics (no other backend's ``_motors_on_step``: what
  ``_flying_advance`` and ``_auto_advance`` compile), under a firmware and a sampler whose
  classes override none of what the kernel does in their place (:meth:`CompiledLegs.eligible`);
* the navdata's flight mode is the plant's, the one the link's take-off guard saw last (no
  guard call; the kernel hands back a leg that changes the mode);
* the firmware would change nothing on the way but its com-watchdog bit: its held PCMD is
  applied and not capped, and by the tick's time no hover, no link-loss watchdog fires (the
  silence only grows within a tick, so none fires earlier either; the com-watchdog bit,
  which nothing reads on the way, is latched after the run, as the Python path's calls
  would have left it).

The kernel itself stops before a leg that a climb near the altitude cap or an emptying
battery would change, or that ends a take-off or landing (flown, found to, and undone); the
Python path goes on from there.

:meth:`CompiledLegs.command` is the same kind of shortcut for the tick's PCMD: the chain
:meth:`SimulatedDrone.execute_pcmd <ardrone_nmpc.sim.drone.SimulatedDrone.execute_pcmd>` →
:meth:`DroneFirmware.execute_pcmd <ardrone_nmpc.sim.drone_firmware.DroneFirmware.execute_pcmd>`
(the sequence rule) → ``apply_command`` (the altitude cap) →
:meth:`AirframePlant.command <ardrone_nmpc.sim.plant.AirframePlant.command>` written out in
one method, for a drone without injected faults whose classes override none of them.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim.airframe import N_STATE
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim.drone_firmware import _PROGRESSIVE, DroneFirmware
from ardrone_nmpc.sim.plant import AirframePlant

__all__ = ["SAMPLER_REPLACED", "CompiledLegs"]

# the modes the kernel flies (compared by identity: an Enum hashes in Python)
_FLYING, _TAKING_OFF, _LANDING = FlightMode.FLYING, FlightMode.TAKING_OFF, FlightMode.LANDING
#: What the kernel does in the plant's place: a subclass overriding any of these flies the
#: Python path (its override would be skipped)
_REPLACED = ("advance", "_flying_advance", "_substep", "_motors_on_step", "_advance_biases",
             "_state_array", "_from_state_array", "mocap_pose", "navdata", "truth",
             "_auto_advance", "_auto_command", "_ground_contact", "_check_transitions",
             "_at_rest", "altitude_m_and_rate_mps", "t_s")
#: … in the firmware's (its advance: watchdogs, the cap's checks) and in the sampler's (its
#: legs; LockstepSensors checks its own class, it imports this module)
_FIRMWARE_REPLACED = ("advance", "watchdogs", "silence", "apply_command",
                      "_climb_may_reach_cap")
SAMPLER_REPLACED = ("_run_to", "_direct_events")
#: What :meth:`CompiledLegs.command` does in the drone's, firmware's and plant's place
_COMMAND_REPLACED = ((SimulatedDrone, ("execute_pcmd", "_at_lost")),
                     (DroneFirmware, ("execute_pcmd", "_accept", "apply_command")),
                     (AirframePlant, ("command",)))
_isfinite = math.isfinite
_f64 = np.float64
_lockstep_run = ks.lockstep_run
_frozen = np.frombuffer  # over immutable bytes: a read-only array
_NONE: tuple = ()
# the counters and the float state written straight into iv and sv (native int64 and double:
# the arrays' own types, the same bits) and read back: no per-element numpy conversion
_PUT_IV = struct.Struct(f"{ks.I_POS_NAV + 1}q").pack_into  # iv[I_STEPS … I_POS_NAV]
_PUT_SV = struct.Struct(f"{ks.SV_SIZE}d").pack_into
_GET_SV = struct.Struct(f"{ks.S_GUST1 + 1}d").unpack_from  # sv[S_T … S_GUST1]
# the kernel's layout, bound once (run reads them every tick)
_O_POSE, _O_NAV, _O_EV_T0, _O_EV_T1, _O_LAST_NOW = (ks.O_POSE, ks.O_NAV, ks.O_EV_T0, ks.O_EV_T1,
                                                    ks.O_LAST_NOW)
_MOCAP = ks.MOCAP


class CompiledLegs:
    """The compiled tick of one lockstep sensor sampler's plant and firmware (module
    docstring). :meth:`run` returns what it left to ``_advance_direct``."""

    def __init__(self, sensors) -> None:
        self.sensors = sensors
        self.plant = sensors.plant
        self.firmware = sensors.firmware
        self.iv = np.zeros(ks.IV_SIZE, dtype=np.int64)
        self.sv = np.zeros(ks.SV_SIZE)
        self.p = np.zeros(ks.P_SIZE)
        self.out = np.zeros(ks.OUT_SIZE)
        self._p_key: tuple = ()
        self.turbulent = False
        self._x = self._x_state = self._x_aux = None  # the last run's state array, its tuples
        drone = sensors.drone
        #: the tick's PCMD by :meth:`command` (else the drone's own chain)
        self.takes_commands = drone.faults is None and self.commands_eligible(drone)
        self.counters = drone.counters

    @staticmethod
    def eligible(plant, firmware=None) -> bool:
        """A plant this path can fly: the airframe's own dynamics, sensors and state — and,
        when given, a firmware whose class overrides none of what the kernel does in its
        place."""
        for obj, base, names in ((plant, AirframePlant, _REPLACED),
                                 (firmware, DroneFirmware, _FIRMWARE_REPLACED)):
            if obj is None and base is DroneFirmware:
                continue
            kind = type(obj)
            if not (isinstance(obj, base)
                    and all(getattr(kind, name) is getattr(base, name) for name in names)):
                return False
        return True

    @staticmethod
    def commands_eligible(drone) -> bool:
        """A drone whose PCMD chain :meth:`command` may stand in for: none of its drone's,
        firmware's or plant's classes overrides a method of the chain."""
        for base, names in _COMMAND_REPLACED:
            obj = drone if base is SimulatedDrone else (
                drone.firmware if base is DroneFirmware else drone.plant)
            kind = type(obj)
            if not (isinstance(obj, base)
                    and all(getattr(kind, name) is getattr(base, name) for name in names)):
                return False
        return True

    def command(self, seq: int, roll: float, pitch: float, gaz: float, yaw: float,
                now: float) -> None:
        """:meth:`SimulatedDrone.execute_pcmd` of one progressive PCMD (``seq``, the float
        fractions) at firmware time ``now`` without injected faults, written out (module
        docstring): the same counters, firmware state and plant command."""
        fw, c = self.firmware, self.counters
        c.at_datagrams_in += 1
        c.at_commands_in += 1
        if not (seq == 1 or seq > fw.last_seq):  # the sequence rule refuses it
            c.at_commands_stale += 1
            fw.apply_command()
            return
        fw.last_seq = seq  # DroneFirmware._accept
        c.at_commands_applied += 1
        fw.last_cmd_t = now
        fw.link_lost = False
        fw.lost_com_hover = False
        if fw.comwdg_clear == "any":
            fw.comwdg_latched = False
        fw.pcmd = fw._applied_pcmd = (_PROGRESSIVE, roll, pitch, gaz, yaw)  # apply_command:
        plant = self.plant  # a new held command, progressive
        at_cap = False
        if gaz > 0.0 and plant.mode.airborne:  # only a climb is capped
            at_cap = fw._z_stop_m() >= fw.config.altitude_max_m
        if at_cap:
            gaz = 0.0
        fw.alt_capped = at_cap
        cmd = (roll, pitch, gaz, yaw, True)
        if cmd != fw.applied:
            if _isfinite(roll) and _isfinite(pitch) and _isfinite(gaz) and _isfinite(yaw):
                # AirframePlant.command: each fraction clipped to [−1, 1]
                plant._current = (min(1.0, max(-1.0, roll)), min(1.0, max(-1.0, pitch)),
                                  min(1.0, max(-1.0, gaz)), min(1.0, max(-1.0, yaw)), False)
            else:
                plant.command(roll, pitch, gaz, yaw)  # its ValueError, nothing changed
            fw.applied = cmd

    def ready(self, t_s: float) -> bool:
        """The Python path's tick to ``t_s`` is what the kernel does (module docstring)."""
        plant, fw = self.plant, self.firmware
        mode = plant._mode
        if mode is not self.sensors._nav_mode or not (
                mode is _FLYING or mode is _TAKING_OFF or mode is _LANDING):
            return False
        if fw.pcmd is not fw._applied_pcmd or fw.alt_capped:
            return False
        if fw.last_cmd_t is None:
            return False
        silence = t_s - fw.last_cmd_t
        return ((fw.lost_com_hover or not silence > fw.hover_after_s)
                and (fw.link_lost or not silence > fw.link_loss_s))

    def _params(self) -> np.ndarray:
        """The flight's parameters (rebuilt when the plant's params, noise or per-flight
        biases change)."""
        plant, sensors = self.plant, self.sensors
        old = self._p_key
        if (old and old[0] is plant.params and old[1] is plant.noise
                and old[2] is plant._trim_bias_rad and old[3] == plant._yaw_drift_sign):
            return self.p
        key = (plant.params, plant.noise, plant._trim_bias_rad, plant._yaw_drift_sign)
        pp, nz, p = plant.params, plant.noise, self.p
        h = pp.integration_step_s
        p[ks.P_H] = h
        p[ks.P_DRAIN] = pp.battery_drain_pct_per_min * h / 60.0
        p[ks.P_YAW_DRIFT] = plant._yaw_drift_sign * pp.navdata_yaw_drift_radps
        p[ks.P_YAW_WALK] = pp.navdata_yaw_walk_rad_per_sqrt_s
        p[ks.P_VB_STD] = pp.navdata_velocity_bias_std_mps
        p[ks.P_VB_TAU] = pp.navdata_velocity_bias_tau_s
        p[ks.P_TURB_STD] = pp.turbulence_std_mps
        p[ks.P_TURB_TAU] = pp.turbulence_tau_s
        p[ks.P_MOCAP_PERIOD] = sensors.mocap_period_s
        p[ks.P_MOCAP_LATENCY] = sensors.mocap_latency_s
        p[ks.P_NAV_PERIOD] = sensors.nav_period_s
        p[ks.P_SP] = nz.mocap_position_std_m
        p[ks.P_SA] = nz.mocap_angle_std_rad
        p[ks.P_ATT_STD] = nz.navdata_attitude_std_rad
        p[ks.P_YAW_STD] = nz.navdata_yaw_std_rad
        p[ks.P_ALT_STD] = nz.navdata_altitude_std_m
        p[ks.P_VEL_STD] = nz.navdata_velocity_std_mps
        p[ks.P_TRIM0], p[ks.P_TRIM1] = plant._trim_bias_rad
        p[ks.P_BIAS0], p[ks.P_BIAS1] = pp.navdata_velocity_bias_mps
        p[ks.P_VMAX] = pp.control_vz_max_mps
        p[ks.P_VZ_GAIN], p[ks.P_SAG] = pp.vz_gain, pp.battery_sag_frac
        # AirframePlant._auto_command's gaz
        p[ks.P_GAZ_UP] = pp.takeoff_climb_mps / pp.control_vz_max_mps
        p[ks.P_GAZ_DOWN] = -pp.landing_speed_mps / pp.control_vz_max_mps
        p[ks.P_TAU_VZ], p[ks.P_TAKEOFF_ALT] = pp.tau_vz_s, pp.takeoff_altitude_m
        k = pp.rhs_coefficients
        if len(k) != ks.N_K:
            raise ValueError(f"{ks.N_K} RHS coefficients expected, got {len(k)}")
        p[ks.P_K:] = k
        self._p_key = key
        self.turbulent = pp.turbulence_std_mps > 0.0
        return p

    def _state_array(self) -> np.ndarray:
        """The plant's state array: the one the last run left while the plant's state is the
        one it took from it (the same tuples), else a new one."""
        plant = self.plant
        if plant._state is self._x_state and plant._tilt_aux is self._x_aux:
            return self._x
        return plant._state_array()

    def run(self, t_s: float) -> tuple[list, bool]:
        """The kernel's run to ``t_s``; the samples of the events it passed are the sensors'.
        Returns the events it left to the Python path (``(t, kind)``, in order) and whether
        the last leg (to ``t_s``) is left too."""
        plant, fw, sensors = self.plant, self.firmware, self.sensors
        p = self._params()
        iv, sv, out = self.iv, self.sv, self.out
        fifo = plant._fifo
        bias_n, gust_n = plant._bias_normals, plant._gust_normals
        mocap_n, nav_n = plant._mocap_normals, plant._nav_normals
        _PUT_IV(iv, 0, plant._steps, fifo.head, sensors._next_mocap_k, sensors._next_nav_k,
                bias_n.pos, gust_n.pos, mocap_n.pos, nav_n.pos)
        gust, vel_bias, wind = plant._gust_mps, plant._vel_bias, plant.wind_mps
        roll, pitch, gaz, yaw, hold = plant._current
        flags, _, _, fw_gaz, _ = fw.pcmd
        if flags & _PROGRESSIVE and fw_gaz > 0.0:  # the firmware watches the cap
            climbing, lead_s, alt_max_m = 1.0, fw._lead_s(), fw.config.altitude_max_m
        else:
            climbing = lead_s = alt_max_m = 0.0
        mode = plant._mode  # as the kernel takes it (sv[S_MODE])
        kernel_mode = (ks.MODE_FLYING if mode is _FLYING else
                       ks.MODE_TAKING_OFF if mode is _TAKING_OFF else ks.MODE_LANDING)
        _PUT_SV(sv, 0, t_s, plant._pending_s, plant._battery, plant._yaw_bias_deg, vel_bias[0],
                vel_bias[1], gust[0], gust[1], roll, pitch, gaz, yaw, 1.0 if hold else 0.0,
                climbing, lead_s, alt_max_m, wind[0], wind[1], wind[2], kernel_mode)
        x = self._state_array()
        _lockstep_run(x, fifo.rows, iv, sv, p, bias_n.values, gust_n.values, mocap_n.values,
                      nav_n.values, out)
        (steps, head, next_mocap, next_nav, pos_bias, pos_gust, pos_mocap, pos_nav, done,
         n_events, kind0, kind1) = iv.tolist()
        if done < 0:  # a block ran short: new ones, and again
            bias_n.ensure(ks.NEED_BIAS)
            mocap_n.ensure(ks.NEED_MOCAP)
            nav_n.ensure(ks.NEED_NAV)
            if self.turbulent:
                gust_n.ensure(ks.NEED_GUST)
            return self.run(t_s)
        (_, pending, battery, yaw_bias, vb0, vb1, gust0, gust1) = _GET_SV(sv)
        o = out.tolist()
        plant._steps, fifo.head, plant._pending_s, plant._battery = steps, head, pending, battery
        plant._yaw_bias_deg, plant._vel_bias = yaw_bias, (vb0, vb1)
        if self.turbulent:
            plant._gust_mps = (gust0, gust1)
            gust_n.pos = pos_gust
        values = x.tolist()  # AirframePlant._from_state_array
        if len(values) > N_STATE:
            plant._tilt_aux = (values[N_STATE], values[N_STATE + 1])
            values = values[:N_STATE]
        plant._state = self._x_state = tuple(values)
        self._x, self._x_aux = x, plant._tilt_aux
        bias_n.pos, mocap_n.pos, nav_n.pos = pos_bias, pos_mocap, pos_nav
        sensors._next_mocap_k, sensors._next_nav_k = next_mocap, next_nav
        now = o[_O_LAST_NOW]
        # a firmware advance ran: its watchdogs, of which only the com watchdog's can act
        # (ready) — the bit the Python path's calls would have latched by then
        if now == now and not fw.comwdg_latched and now - fw.last_cmd_t > fw.comwdg_s:
            fw.comwdg_latched = True
        for i in range(min(done, n_events)):
            kind, t_event = (kind0, o[_O_EV_T0]) if i == 0 else (kind1, o[_O_EV_T1])
            if kind == _MOCAP:
                q = _O_POSE
                pose = _frozen(out[q + 1:q + 7].tobytes())  # position, angles: read-only
                sensors.took_pose(t_event, MocapPose(o[q], pose[:3], pose[3:], o[q + 7]))
            else:
                q = _O_NAV
                altitude = o[q + 5]
                # the types of AirframePlant.navdata's values (numpy scalars from its draws)
                sensors.took_navdata(t_event, NavdataSample(
                    o[q], mode, o[q + 1], o[q + 2], o[q + 3], o[q + 4],
                    _f64(altitude) if altitude > 0.0 else 0.0, _f64(o[q + 6]), _f64(o[q + 7]),
                    _f64(o[q + 8])))
        if done > n_events:
            return _NONE, False
        events = [(o[_O_EV_T0], kind0), (o[_O_EV_T1], kind1)][done:n_events]
        return events, True
