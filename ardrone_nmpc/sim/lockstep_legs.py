"""The direct sensor path's tick in one compiled call, when nothing but physics happens in it.

:class:`CompiledLegs` runs :func:`~ardrone_nmpc.sim.sensor_step.lockstep_run` on the plant's
state for :meth:`LockstepSensors.advance_to
<ardrone_nmpc.sim.sensors.LockstepSensors.advance_to>` (and for ``LockstepDrone.advance_to``,
which calls :meth:`CompiledLegs.run` without the sampler's frame, then hands what it left to
the sampler's ``go_on``). Between its runs the kernel's arrays hold that state (the plant's
clock, battery, biases, gusts, command, delay ring and state vector, the normal blocks' and the
sensor grids' positions): packing it from the attributes and writing it back every tick cost as
much as the physics. The attributes leave the instances' ``__dict__`` meanwhile, and any read
of one — the plant's Python path, the firmware, a fault, a test — writes them all back first
(:mod:`~ardrone_nmpc.sim.held_state`); a write meanwhile is newer than the arrays and is kept,
and the next run takes the state again. What a tick reads between runs comes from the arrays:
the samples, and the truth of the last run (:meth:`CompiledLegs.truth`,
:meth:`CompiledLegs.live` for ``LockstepDrone.truth_cells`` and the PCMD chain) — unless a held
attribute was written since (then the attributes, released, are read). It reads and writes the
plant's and the firmware's internals (it is their compiled path, not a client), and is used
only when the Python path's tick would do what the kernel does:

* the plant is an :class:`~ardrone_nmpc.sim.plant.AirframePlant` FLYING, TAKING_OFF or LANDING
  on its own dynamics (no other backend's ``_motors_on_step``: what ``_flying_advance`` and
  ``_auto_advance`` compile) or a :class:`~ardrone_nmpc.sim.plant_kit.KitPlant` on the kit's
  (its channels after the 10-state in the kernel's state array), under a firmware and a sampler
  whose classes override none of what the kernel does in their place
  (:meth:`CompiledLegs.eligible`);
* the navdata's flight mode is the plant's, the one the link's take-off guard saw last — or a
  new one whose sample the sampler lets the guard see after the run
  (``LockstepSensors.defers_mode``: the guard does nothing then);
* the firmware would change nothing on the way but its flags: its held PCMD is applied and not
  capped, and by the tick's time no link-loss watchdog fires, nor the hover watchdog unless the
  plant's command is hover already (the silence only grows within a tick, so none fires earlier
  either; the com-watchdog bit and the hover watchdog's flags and held PCMD, which nothing
  reads on the way, are set after the run, as the Python path's calls would have left them).

The kernel itself stops before a leg that a climb near the altitude cap or an emptying battery
would change; the Python path goes on from there. It flies the leg that ends a take-off or a
landing (the climb settled: FLYING; the touch-down: LANDED) when nothing but the plant's mode
changes with it — no hover watchdog due, no climb held (what the firmware does with those
depends on the mode), and a guard that may see the new mode's sample after the run — and else
hands it back (flown, found to end it, and undone).

:meth:`CompiledLegs.command` is the same kind of shortcut for the tick's PCMD: the chain
:meth:`SimulatedDrone.execute_pcmd <ardrone_nmpc.sim.drone.SimulatedDrone.execute_pcmd>` →
:meth:`DroneFirmware.execute_pcmd <ardrone_nmpc.sim.drone_firmware.DroneFirmware.execute_pcmd>`
(the sequence rule) → ``apply_command`` (the altitude cap) → :meth:`AirframePlant.command
<ardrone_nmpc.sim.plant.AirframePlant.command>` written out in one method, for a drone whose
classes override none of them, on a tick at which no injected fault may drop the datagram.
"""

from __future__ import annotations

import math
import operator
import struct

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.entry_points import entry_point
from ardrone_nmpc.core.types import FlightMode, MocapPose, NavdataSample, PlantTruth
from ardrone_nmpc.protocol.at import Pcmd
from ardrone_nmpc.sim import sensor_step as ks
from ardrone_nmpc.sim.airframe import N_STATE
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim.drone_firmware import _HOVER_CMD, _PROGRESSIVE, DroneFirmware
from ardrone_nmpc.sim.held_state import overrides_none
from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.sim.plant_kit import KitPlant

__all__ = ["ALL_DONE", "SAMPLER_REPLACED", "TRUTH_CELLS_OF", "CompiledLegs"]

# the modes the kernel flies (compared by identity: an Enum hashes in Python), and LANDED,
# which a landing's end it flies leaves
_FLYING, _TAKING_OFF, _LANDING = FlightMode.FLYING, FlightMode.TAKING_OFF, FlightMode.LANDING
_LANDED = FlightMode.LANDED
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
SAMPLER_REPLACED = ("_run_to", "_direct_events", "took_pose", "took_navdata")
#: What :meth:`CompiledLegs.command` does in the drone's, firmware's and plant's place
_COMMAND_REPLACED = ((SimulatedDrone, ("execute_pcmd", "_at_lost")),
                     (DroneFirmware, ("execute_pcmd", "_accept", "apply_command")),
                     (AirframePlant, ("command",)))
#: … and what :meth:`CompiledLegs.land_again` does besides
_LANDING_REPLACED = ((SimulatedDrone, ("execute_at",)),
                     (DroneFirmware, ("execute_datagram", "execute", "_on_ref")))
_isfinite = math.isfinite
#: the plant's command DroneFirmware.apply_command makes of a hover (``_HOVER_CMD``)
_HOVER_APPLIED = (0.0, 0.0, 0.0, 0.0, False)
_HOVER = Pcmd.hover()  # the firmware's held PCMD of a hover PCMD (DroneFirmware.execute)
_HOVER_PCMD = (_HOVER.flags, _HOVER.roll_frac, _HOVER.pitch_frac, _HOVER.gaz_frac,
               _HOVER.yaw_frac)
_lockstep_run = ks.lockstep_run
_frozen = np.frombuffer  # over immutable bytes: a read-only array
#: what :meth:`CompiledLegs.run` returns when it ran all the tick's legs (nothing left)
ALL_DONE: tuple = ((), False)
# the counters and the float state written straight into iv and sv (native int64 and double:
# the arrays' own types, the same bits) and read back: no per-element numpy conversion
_PUT_IV = struct.Struct(f"{ks.I_POS_NAV + 1}q").pack_into  # iv[I_STEPS … I_POS_NAV]
_GET_IV = struct.Struct(f"{ks.I_POS_NAV + 1}q").unpack_from
_GET_POS, _PUT_POS = struct.Struct("4q").unpack_from, struct.Struct("4q").pack_into
_AT_POS = 8 * ks.I_POS_BIAS  # iv[I_POS_BIAS … I_POS_NAV]
# sv[S_PENDING … S_GUST1]: the plant's state the arrays hold between runs
_PUT_STATE = struct.Struct(f"{ks.S_GUST1 - ks.S_PENDING + 1}d").pack_into
_AT_PENDING = 8 * ks.S_PENDING
# sv[S_ROLL … S_ENDS]: the plant's command (held as its _current: the tick's PCMD carried into
# the run's one pack, not packed by CompiledLegs.command), what the firmware, the faults and
# the modes may change any time, and the tick's time
_PUT_INPUTS = struct.Struct(f"{ks.S_ENDS - ks.S_ROLL + 1}d").pack_into
_AT_ROLL = 8 * ks.S_ROLL
_GET_SV = struct.Struct(f"{ks.S_GUST1 - ks.S_PENDING + 1}d").unpack_from  # sv[S_PENDING …]
#: the plant's attributes the arrays hold between runs (sim/held_state.py; the sampler's:
#: its class's HELD_IN_ARRAYS) — a thesis_kit plant's, its channels too (``_kit``: in the
#: state array after the 10-state, ``ks.X_KIT``)
_PLANT_HELD = AirframePlant.HELD_IN_ARRAYS
_KIT_HELD = KitPlant.HELD_IN_ARRAYS
# the kernel's layout, bound once (run reads them every tick)
_O_NAV, _MOCAP, _NAV = ks.O_NAV, ks.MOCAP, ks.NAV
# byte offsets in buf of the pose's position and XYZ angles, the truth's position and velocity
_AT_POSITION, _AT_ANGLES = 8 * (ks.B_OUT + ks.O_POSE + 1), 8 * (ks.B_OUT + ks.O_POSE + 4)
_AT_STATE, _AT_VELOCITY = 8 * (ks.B_OUT + ks.O_STATE), 8 * (ks.B_OUT + ks.O_STATE + 3)
# the truth's time, battery and 10-state, side by side in out (truth()), from buf's bytes
if not ks.O_T + 1 == ks.O_BATTERY == ks.O_STATE - 1:
    raise ImportError("lockstep_legs: the truth's floats are not side by side in out")
_AT_TRUTH = 8 * (ks.B_OUT + ks.O_T)
_GET_TRUTH = struct.Struct(f"{ks.O_STATE + 10 - ks.O_T}d").unpack_from
#: the floats of out a tick reads (at these out indices, in order): the pose's time and ψ, the
#: navdata sample's time, battery, angles and altitude (its speeds: numpy scalars, from out),
#: the event times, the last firmware time, the truth's time, x, y, z, ż and ψ
_RUN_READ = (ks.O_POSE, ks.O_POSE + 7, *range(ks.O_NAV, ks.O_NAV + 6), ks.O_EV_T0, ks.O_EV_T1,
             ks.O_LAST_NOW, ks.O_T, ks.O_STATE, ks.O_STATE + 1, ks.O_STATE + 2,
             ks.O_STATE + 5, ks.O_STATE + 8)


def _run_layout(floats: tuple, at_ints: int, n_ints: int) -> str:
    """The struct format reading out's ``floats`` (ascending indices), then ``n_ints`` int64
    from float64 index ``at_ints`` of buf: what lies between, pad bytes (no object made)."""
    fmt, at = "", ks.B_OUT
    for i in (*(ks.B_OUT + i for i in floats), at_ints):
        fmt += f"{8 * (i - at)}x" if i > at else ""
        fmt += "d" if i < at_ints else f"{n_ints}q"
        at = i + 1
    return fmt


# what a run left, from buf's bytes: out's floats a tick reads, then iv[I_DONE … I_KIND1] (iv
# follows out) — one unpack (struct's: half of tolist's cost; 21 objects, not all 37), in
# native mode (the arrays' own types, bit for bit: ~20 % faster than "=", whose standard
# sizes unpack each double by PyFloat_Unpack8); every field falls on a multiple of 8 bytes,
# so native alignment adds no padding (checked below)
_RUN_LAYOUT = _run_layout(_RUN_READ, ks.B_IV + ks.I_DONE, 4)
if struct.calcsize(_RUN_LAYOUT) != struct.calcsize("=" + _RUN_LAYOUT):
    raise ImportError("lockstep_legs: the run's layout is padded in native mode")
_GET_RUN = struct.Struct(_RUN_LAYOUT).unpack_from
# where the run's floats are in what _GET_RUN gives (CompiledLegs.live_out)
(_R_POSE_T, _R_POSE_PSI, _R_NAV, _R_EV_T0, _R_EV_T1, _R_LAST_NOW, _R_T, _R_X, _R_VZ,
 _R_PSI) = (_RUN_READ.index(i) for i in (
    ks.O_POSE, ks.O_POSE + 7, ks.O_NAV, ks.O_EV_T0, ks.O_EV_T1, ks.O_LAST_NOW, ks.O_T,
    ks.O_STATE, ks.O_STATE + 5, ks.O_STATE + 8))
_R_DONE = len(_RUN_READ)  # … then the events', and their kinds
_R_EVENTS, _R_KIND0, _R_KIND1 = _R_DONE + 1, _R_DONE + 2, _R_DONE + 3
#: x, y, z, ψ, ż of :attr:`CompiledLegs.live_out` (``LockstepDrone.truth_cells``)
TRUTH_CELLS_OF = operator.itemgetter(_R_X, _R_X + 1, _R_X + 2, _R_PSI, _R_VZ)

_F64 = np.dtype(np.float64)
_PI = math.pi
_BUF_KIND = np.empty(0)  # a stand-in of CompiledLegs' buf (a plain 1-D float64) for its kind


def _kernel_for(x, rows, blocks):
    """:func:`~ardrone_nmpc.sim.sensor_step.lockstep_run`'s compiled entry point — the
    dispatcher's own choice for these arrays, without its per-call look-up of seven
    arguments' types (core/entry_points) — when the plant's arrays are of a kind it compiled
    (CompiledLegs builds its own float64, C-contiguous, aligned, writeable: their types until
    the next :meth:`_take <CompiledLegs._take>` asks again); else, or before the kernel is
    compiled (or without the JIT), the dispatcher."""
    return entry_point(_lockstep_run, x, rows, _BUF_KIND, *blocks) or _lockstep_run


class CompiledLegs:
    """The compiled tick of one lockstep sensor sampler's plant and firmware (module
    docstring). :meth:`run` returns what it left to ``advance_to``'s direct path."""

    def __init__(self, sensors) -> None:
        self.sensors = sensors
        self.plant = sensors.plant
        self.firmware = sensors.firmware
        self.buf = buf = np.zeros(ks.BUF_SIZE)  # the kernel's out, iv, sv and p (views)
        self.out, self.iv = buf[ks.B_OUT:ks.B_IV], buf[ks.B_IV:ks.B_SV].view(np.int64)
        self.sv, self.p = buf[ks.B_SV:ks.B_P], buf[ks.B_P:]
        # sv's memory as a memoryview: a pack into it skips numpy's buffer export (~70 ns
        # of every run's one pack)
        self._sv_memory = memoryview(self.sv)
        self._p_key: tuple = ()
        self.turbulent = False
        self._x = self._x_state = self._x_aux = None  # the last run's state array, its tuples
        self._x_kit = None  # … and a kit plant's channels (the array released from it)
        self._kit = isinstance(self.plant, KitPlant)
        self._plant_held = _KIT_HELD if self._kit else _PLANT_HELD
        # while held (_take … release): (x, fifo, ring, the normal blocks), the blocks'
        # arrays, the kernel's arrays, the attributes taken out, whether a run changed them
        self._held: tuple = ()
        self._blocks: tuple = ()
        self._saved = self._sensors_saved = None
        self._args: tuple = ()
        self._ran = False
        self._plant_len = self._sensors_len = 0  # the dicts' sizes while held
        self._kernel = _lockstep_run
        #: what a tick reads of the last run (a tuple: the floats of ``out`` at
        #: ``_RUN_READ``'s indices, then iv's done, events and kinds) while the arrays hold
        #: the state it left (its truth's time, x, y, z, ż, ψ: ``TRUTH_CELLS_OF``), else None
        self.live_out = None
        #: the bytes of buf's out and iv after the last run (out's first, at buf's offsets: the
        #: truth's arrays are views of them)
        self.live_raw = b""
        self._run_bytes = buf[:ks.B_SV].tobytes  # (what a run left: out, iv; a bound method)
        drone = sensors.drone
        #: :meth:`command` may stand in for the drone's PCMD chain when no injected fault
        #: may drop the datagram (``LockstepDrone.set_command`` asks the faults)
        self.stands_in = self.commands_eligible(drone)
        #: the tick's PCMD by :meth:`command` (else the drone's own chain)
        self.takes_commands = drone.faults is None and self.stands_in
        #: :meth:`land_again` may stand in for the landing's datagram when no injected
        #: fault may drop it (``LockstepDrone.land`` asks the faults)
        self.lands_in = self.stands_in and self.commands_eligible(drone, _LANDING_REPLACED)
        #: a landing's REF held again by :meth:`land_again`
        self.lands_again = drone.faults is None and self.lands_in
        self.counters = drone.counters

    @staticmethod
    def eligible(plant, firmware=None) -> bool:
        """A plant this path can fly: the airframe's own dynamics, sensors and state — and,
        when given, a firmware whose class overrides none of what the kernel does in its
        place."""
        # (a class default of a held attribute would shadow its HeldInArrays: _PLANT_HELD)
        # the airframe's dynamics, or the kit's (KitPlant's own methods: the kernel's branch)
        kit = isinstance(plant, KitPlant)
        for obj, base, names in ((plant, KitPlant if kit else AirframePlant,
                                  _REPLACED + (_KIT_HELD if kit else _PLANT_HELD)),
                                 (firmware, DroneFirmware, _FIRMWARE_REPLACED)):
            if obj is None and base is DroneFirmware:
                continue
            if not overrides_none(obj, base, names):
                return False
        return True

    @staticmethod
    def commands_eligible(drone, chain: tuple = _COMMAND_REPLACED) -> bool:
        """A drone whose PCMD chain :meth:`command` may stand in for (or another ``chain``:
        ``(class, method names)`` pairs): none of its drone's, firmware's or plant's classes
        overrides a method of the chain."""
        for base, names in chain:
            obj = drone if base is SimulatedDrone else (
                drone.firmware if base is DroneFirmware else drone.plant)
            if not overrides_none(obj, base, names):
                return False
        return True

    def command(self, seq: int, roll: float, pitch: float, gaz: float, yaw: float,
                now: float | None = None) -> None:
        """:meth:`SimulatedDrone.execute_pcmd` of one progressive PCMD (``seq``, the float
        fractions) at firmware time ``now`` with no injected fault deciding its datagram's
        fate, written out (module docstring): the same counters, firmware state and plant
        command."""
        fw, c = self.firmware, self.counters
        c.at_datagrams_in += 1
        c.at_commands_in += 1
        if not (seq == 1 or seq > fw.last_seq):  # the sequence rule refuses it
            c.at_commands_stale += 1
            fw.apply_command()
            return
        fw.last_seq = seq  # DroneFirmware._accept
        c.at_commands_applied += 1
        plant, o = self.plant, self.live_out  # the last run's truth while held (live(),
        if o is not None and len(plant.__dict__) != self._plant_len:  # without its frame)
            self.release()
            o = None
        if now is None:  # the plant's time (t_s() of the o read above)
            now = plant.t_s if o is None else o[_R_T]
        fw.last_cmd_t = now
        fw.link_lost = False
        fw.lost_com_hover = False
        if fw.comwdg_clear == "any":
            fw.comwdg_latched = False
        fw.pcmd = fw._applied_pcmd = (_PROGRESSIVE, roll, pitch, gaz, yaw)  # apply_command:
        at_cap = False
        # only an airborne climb is capped (FlightMode.airborne by identity: ~0.2 µs less)
        mode = plant._mode
        if gaz > 0.0 and (mode is _FLYING or mode is _TAKING_OFF or mode is _LANDING):
            if o is not None:  # DroneFirmware._z_stop_m of the held state
                z, vz = o[_R_X + 2], o[_R_VZ]  # (max(0.0, vz) spelled out)
                at_cap = (z + (vz if vz > 0.0 else 0.0) * fw._lead_s()
                          >= fw.config.altitude_max_m)
            else:
                at_cap = fw._z_stop_m() >= fw.config.altitude_max_m
        if at_cap:
            gaz = 0.0
        fw.alt_capped = at_cap
        cmd = (roll, pitch, gaz, yaw, True)
        if cmd != fw.applied:
            # (fractions within [−1, 1], as a rule: AirframePlant.command's clip keeps them)
            within = (-1.0 <= roll <= 1.0 and -1.0 <= pitch <= 1.0 and -1.0 <= gaz <= 1.0
                      and -1.0 <= yaw <= 1.0)
            if within or (_isfinite(roll) and _isfinite(pitch) and _isfinite(gaz)
                          and _isfinite(yaw)):
                if not within:  # AirframePlant.command: each fraction clipped to [−1, 1],
                    # min(1.0, max(−1.0, v)) spelled out (a finite v: the same float)
                    roll = roll if roll > -1.0 else -1.0
                    roll = roll if roll < 1.0 else 1.0
                    pitch = pitch if pitch > -1.0 else -1.0
                    pitch = pitch if pitch < 1.0 else 1.0
                    gaz = gaz if gaz > -1.0 else -1.0
                    gaz = gaz if gaz < 1.0 else 1.0
                    yaw = yaw if yaw > -1.0 else -1.0
                    yaw = yaw if yaw < 1.0 else 1.0
                if o is not None:  # held: the next run packs it (a write while held, else)
                    self._saved["_current"] = (roll, pitch, gaz, yaw, False)
                else:
                    plant._current = (roll, pitch, gaz, yaw, False)
            else:
                plant.command(roll, pitch, gaz, yaw)  # its ValueError, nothing changed
            fw.applied = cmd

    def land_again(self, seq: int) -> bool:
        """:meth:`SimulatedDrone.execute_at <ardrone_nmpc.sim.drone.SimulatedDrone.
        execute_at>` of the datagram a landing holds every tick — REF land (``seq``), a hover
        PCMD (``seq + 1``) — at the plant's time, written out as :meth:`command` writes the
        PCMD's: the same counters and firmware state (both accepted, traffic for the
        watchdogs; no REF edge, no take-off bit; the hover applied, not capped), the
        plant's mode and command unchanged — LANDING, hover already. False, nothing done,
        for any other case (a drone it does not stand in for, a stale number, another mode
        or command)."""
        fw, c = self.firmware, self.counters
        if not (self.lands_in and self.plant._mode is _LANDING and seq > fw.last_seq
                and fw.applied == _HOVER_APPLIED):
            return False
        now = self.t_s()
        c.at_datagrams_in += 1
        c.at_commands_in += 2
        c.at_commands_applied += 2
        fw.last_seq = seq + 1  # DroneFirmware._accept of each
        fw.last_cmd_t = now
        fw.link_lost = False
        fw.lost_com_hover = False
        if fw.comwdg_clear == "any":
            fw.comwdg_latched = False
        fw.ref_emergency = fw.ref_start = False  # _on_ref of REF land while LANDING
        fw.pcmd = fw._applied_pcmd = _HOVER_PCMD  # apply_command of the hover: the
        fw.alt_capped = False                     # plant's command stays
        return True

    def _params(self) -> np.ndarray:
        """The flight's parameters, built anew (:meth:`run` keeps them while the plant's
        params, noise and per-flight biases are the ones they were built from)."""
        plant, sensors = self.plant, self.sensors
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
        # the plant's _auto_command's gaz (KitPlant's: per unit of the kit's vertical gain)
        p[ks.P_GAZ_UP] = plant._auto_command(_TAKING_OFF)[2]
        p[ks.P_GAZ_DOWN] = plant._auto_command(_LANDING)[2]
        p[ks.P_TAU_VZ], p[ks.P_TAKEOFF_ALT] = pp.tau_vz_s, pp.takeoff_altitude_m
        k = pp.rhs_coefficients
        if len(k) != ks.N_K:
            raise ValueError(f"{ks.N_K} RHS coefficients expected, got {len(k)}")
        p[ks.P_K:ks.P_KIT_K] = k
        if self._kit:
            p[ks.P_KIT_K:] = plant._coefficients
        self._p_key = key
        self.turbulent = pp.turbulence_std_mps > 0.0
        return p

    # ------------------------------------------------------------------ the arrays hold it
    def _take(self) -> None:
        """The plant's and the sensors' state into the arrays, its attributes out of their
        ``__dict__``: the arrays hold them until :meth:`release` (sim/held_state.py)."""
        plant, fw, sensors = self.plant, self.firmware, self.sensors
        d = plant.__dict__
        for name in self._plant_held:  # (a subclass's __init__ may leave one to the class)
            if name not in d:
                d[name] = getattr(plant, name)
        fifo, bias_n, gust_n = d["_fifo"], d["_bias_normals"], d["_gust_normals"]
        mocap_n, nav_n = d["_mocap_normals"], d["_nav_normals"]
        _PUT_IV(self.iv, 0, d["_steps"], fifo.head, sensors._next_mocap_k,
                sensors._next_nav_k, bias_n.pos, gust_n.pos, mocap_n.pos, nav_n.pos)
        gust, vel_bias = d["_gust_mps"], d["_vel_bias"]
        _PUT_STATE(self.sv, _AT_PENDING, d["_pending_s"], d["_battery"], d["_yaw_bias_deg"],
                   vel_bias[0], vel_bias[1], gust[0], gust[1])
        # the plant's state array: the one the last run left while the plant's state is the
        # one released from it (the same tuples), else a new one
        if (d["_state"] is self._x_state and d["_tilt_aux"] is self._x_aux
                and (not self._kit or d["_kit"] is self._x_kit)):
            x = self._x
        elif self._kit:  # its 10-state and channels (ks.X_KIT; no second-order form)
            x = self._x = np.array((*d["_state"], *d["_kit"].tolist()), dtype=np.float64)
        else:
            x = self._x = plant._state_array()
        self._held = (x, fifo, fifo.rows, bias_n, gust_n, mocap_n, nav_n)
        self._blocks = (bias_n.values, gust_n.values, mocap_n.values, nav_n.values)
        self._args = (x, fifo.rows, self.buf, *self._blocks)  # the kernel's, in its order
        self._kernel = _kernel_for(x, fifo.rows, self._blocks)
        self._saved = {name: d.pop(name) for name in self._plant_held}
        sd = sensors.__dict__
        self._sensors_saved = {name: sd.pop(name) for name in type(sensors).HELD_IN_ARRAYS}
        plant._held_by = sensors._held_by = self
        self._ran = False
        self.live_out = None
        self._plant_len, self._sensors_len = len(d), len(sd)

    def release(self) -> None:
        """The held attributes back into the plant's and the sensors' ``__dict__`` — as the
        runs since :meth:`_take` left them, but for any written meanwhile (those are newer)."""
        plant, sensors = self.plant, self.sensors
        if plant.__dict__.get("_held_by") is not self:
            return
        saved, sensors_saved = self._saved, self._sensors_saved
        if self._ran:  # what the Python path's calls would have left
            x, fifo, _, bias_n, gust_n, mocap_n, nav_n = self._held
            (steps, fifo.head, next_mocap, next_nav, bias_n.pos, pos_gust, mocap_n.pos,
             nav_n.pos) = _GET_IV(self.iv)
            pending, battery, yaw_bias, vb0, vb1, gust0, gust1 = _GET_SV(self.sv, _AT_PENDING)
            values = x.tolist()  # AirframePlant._from_state_array
            if self._kit:  # the kit's channels after its 10-state (its _tilt_aux: unused)
                saved["_kit"] = self._x_kit = x[N_STATE:].copy()
                values = values[:N_STATE]
            elif len(values) > N_STATE:
                saved["_tilt_aux"] = (values[N_STATE], values[N_STATE + 1])
                values = values[:N_STATE]
            saved["_state"] = self._x_state = tuple(values)
            self._x_aux = saved["_tilt_aux"]
            saved["_steps"], saved["_pending_s"], saved["_battery"] = steps, pending, battery
            saved["_yaw_bias_deg"], saved["_vel_bias"] = yaw_bias, (vb0, vb1)
            if self.turbulent:
                saved["_gust_mps"] = (gust0, gust1)
                gust_n.pos = pos_gust
            sensors_saved["_next_mocap_k"], sensors_saved["_next_nav_k"] = next_mocap, next_nav
        else:
            self._x_state, self._x_aux = saved["_state"], saved["_tilt_aux"]
            self._x_kit = saved.get("_kit")
        for obj, values in ((plant, saved), (sensors, sensors_saved)):
            d = obj.__dict__
            for name, value in values.items():
                d.setdefault(name, value)
            d["_held_by"] = None
        self._saved = self._sensors_saved = None
        self.live_out = None

    def held(self) -> bool:
        """The arrays hold the plant's state now (its readers release it, or read
        :attr:`live_out`)."""
        return self.plant.__dict__.get("_held_by") is self

    def live(self):
        """:attr:`live_out` — unless a held attribute of the plant was written since the run
        (a fault's battery, a command: the written value is the newer): then the attributes
        are released and None (read the plant). (:meth:`command` and
        ``LockstepDrone.truth_cells``, every tick, test the same without this call.)"""
        o = self.live_out
        if o is not None and len(self.plant.__dict__) != self._plant_len:
            self.release()
            return None
        return o

    def t_s(self) -> float:
        """:attr:`AirframePlant.t_s`, the last run's while the arrays hold its state (the
        time of a REF or a config write: read without releasing them)."""
        o = self.live()
        return self.plant.t_s if o is None else o[_R_T]

    def truth(self):
        """:attr:`AirframePlant.truth`, from the last run's while the arrays hold its state."""
        o = self.live()
        if o is None:
            return self.plant.truth
        raw = self.live_raw  # the run's out bytes: the truth's floats (its position and
        t, battery, *_, phi, theta, psi, r = _GET_TRUTH(raw, _AT_TRUTH)  # velocity: read-only
        # arrays, as AirframePlant.truth's, float64 views of them, bit for bit); a float in
        # (−π, π] is its own wrap: wrap_angle_rad's own fast path
        return PlantTruth.make(t, _frozen(raw, _F64, 3, _AT_STATE),
                               _frozen(raw, _F64, 3, _AT_VELOCITY), phi, theta,
                               psi if -_PI < psi <= _PI else wrap_angle_rad(psi), r,
                               self.plant._mode, battery)

    # ------------------------------------------------------------------ one tick
    def refill(self, need: tuple = (ks.NEED_BIAS, ks.NEED_GUST, ks.NEED_MOCAP,
                                    ks.NEED_NAV)) -> None:
        """New blocks of normals for those that ran short (held: the positions in iv; a
        block's run found one short: ``sim/drone_block.LEGS_SHORT``); ``need``: of each."""
        bias_n, gust_n, mocap_n, nav_n = blocks = self._held[3:]
        iv = self.iv
        bias_n.pos, gust_n.pos, mocap_n.pos, nav_n.pos = _GET_POS(iv, _AT_POS)
        for normals, n in zip(blocks, need):
            if normals is not gust_n or self.turbulent:
                normals.ensure(n)
        _PUT_POS(iv, _AT_POS, bias_n.pos, gust_n.pos, mocap_n.pos, nav_n.pos)
        self._blocks = tuple(b.values for b in blocks)
        x, rows, buf = self._args[:3]
        self._args = (x, rows, buf, *self._blocks)
        self._kernel = _kernel_for(x, rows, self._blocks)

    def _modes_seen(self, o, mode, taken: int) -> None:
        """After a run begun in ``mode`` that the navdata did not show yet, or that flew the
        take-off's or the landing's end (``o``: what it left): the plant's mode then (as
        ``_auto_advance`` leaves it), its navdata sample's — the mode at the end of the
        sample's leg (LANDED: AirframePlant.navdata's zeros) — and a new one seen by the
        guard (as :meth:`run` asked, ``defers_mode``)."""
        sensors, changed = self.sensors, int(self.iv[ks.I_CHANGED])
        mode_then = mode
        if changed >= 0:
            mode_then = self.plant._mode = _FLYING if mode is _TAKING_OFF else _LANDED
        if taken and o[_R_KIND0] == _NAV:
            leg = 0
        elif taken == 2 and o[_R_KIND1] == _NAV:
            leg = 1
        else:  # no navdata sample in what the run did
            return
        nav = sensors.nav
        if 0 <= changed <= leg:  # sampled after the change
            nav = sensors.nav = NavdataSample.make(
                nav.t_s, mode_then, nav.battery_pct, nav.roll_deg, nav.pitch_deg, nav.yaw_deg,
                *((0.0, 0.0, 0.0, 0.0) if mode_then is _LANDED else (
                    nav.altitude_m, nav.vx_body_mps, nav.vy_body_mps, nav.vz_mps)))
        if nav.mode is not sensors._nav_mode:
            sensors.took_mode(sensors.nav_rx_t_s, nav.mode)

    def _ran_to(self, raw: bytes, o: tuple, mode, hover_due: bool, new_mode: bool,
                ends: float, target_drawn: bool = False) -> tuple[list, bool]:
        """:meth:`run`'s rest after a kernel run that did something (``raw``, ``o``: its
        bytes and floats; begun in ``mode``, with :meth:`run`'s findings; ``target_drawn``:
        :meth:`_took`'s): the firmware's flags, the samples, the mode — the Python path's."""
        fw = self.firmware
        done, n_events = o[_R_DONE], o[_R_EVENTS]
        self._ran = True
        self.live_raw = raw
        now = o[_R_LAST_NOW]
        # a firmware advance ran: its watchdogs, of which only the com watchdog's and the
        # hover's can act (checked above) — what the Python path's calls would have left by
        # then: the com-watchdog bit latched; the held PCMD dropped for hover and applied
        # (the plant's command unchanged: it was hover)
        fw.latch_after_run(now)
        if hover_due and now == now and now - fw.last_cmd_t > fw.hover_after_s:
            fw.lost_com_hover = True
            fw.pcmd = fw._applied_pcmd = _HOVER_CMD
        taken = n_events if done > n_events else done  # the events whose legs it ran
        if taken:  # at most one of each kind (mocap first on a tie)
            if o[_R_KIND0] == _MOCAP:
                t_pose, t_nav = o[_R_EV_T0], o[_R_EV_T1] if taken == 2 else None
            else:
                t_pose, t_nav = o[_R_EV_T1] if taken == 2 else None, o[_R_EV_T0]
            self._took(raw, o, t_pose, t_nav, mode, target_drawn)
        if done > n_events:  # all the legs (the usual tick)
            self.live_out = o
            if new_mode or ends:  # (rare: a take-off's or landing's tick)
                self._modes_seen(o, mode, taken)
            return ALL_DONE
        self.release()  # the Python path goes on from here
        if new_mode or ends:
            self._modes_seen(o, mode, taken)
        return [(o[_R_EV_T0], o[_R_KIND0]), (o[_R_EV_T1], o[_R_KIND1])][done:n_events], True

    def _took(self, raw: bytes, o: tuple, t_pose, t_nav, mode,
              target_drawn: bool = False) -> None:
        """The samples a run (or a block of runs: its last) left in ``out`` — the pose of
        event time ``t_pose``, the navdata sample of ``t_nav`` (None: not taken) — written
        as the sampler's took_* would (what one writes the other reads not; ``mode``: the
        plant's, the sample's)."""
        sensors = self.sensors
        if t_pose is not None:
            # position, angles: read-only arrays, as AirframePlant.mocap_pose's (float64
            # views of out's bytes: the values of o's floats, bit for bit)
            pose = MocapPose.make(o[_R_POSE_T], _frozen(raw, _F64, 3, _AT_POSITION),
                                  _frozen(raw, _F64, 3, _AT_ANGLES), o[_R_POSE_PSI])
            # LockstepSensors.took_pose, spelled out — but not the second object's draw if a
            # block's kernel drew this frame's (``target_drawn``: second_object.take_frame)
            if sensors.target_cfg is None or target_drawn:
                sensors.pose, sensors.pose_rx_t_s = pose, t_pose + sensors.mocap_latency_s
            else:
                sensors.took_pose(t_pose, pose)
        if t_nav is not None:  # LockstepSensors.took_navdata, spelled out (its mode is
            q, r, out = _O_NAV, _R_NAV, self.out  # the plant's: checked by run, or after)
            # the types of AirframePlant.navdata's values (numpy scalars from its draws)
            sensors.nav = NavdataSample.make(
                o[r], mode, o[r + 1], o[r + 2], o[r + 3], o[r + 4],
                out[q + 5] if o[r + 5] > 0.0 else 0.0, out[q + 6], out[q + 7], out[q + 8])
            sensors.nav_rx_t_s = t_nav

    def run(self, t_s: float) -> tuple[list, bool] | None:
        """The kernel's run to ``t_s`` — None, nothing done, unless the Python path's tick to
        ``t_s`` is what the kernel does (module docstring); the samples of the events it
        passed are the sensors'. Returns the events it left to the Python path (``(t,
        kind)``, in order) and whether the last leg (to ``t_s``) is left too."""
        plant, fw, sensors = self.plant, self.firmware, self.sensors
        mode = plant._mode  # a mode the kernel flies, the one the navdata shows — or a new
        if not (mode is _FLYING or mode is _TAKING_OFF or mode is _LANDING):
            return None
        new_mode = mode is not sensors._nav_mode  # one its sample may show after the run
        if new_mode and not sensors.defers_mode(mode):
            return None
        # a quiet firmware: its PCMD applied, not capped, and by t_s no watchdog fires — but
        # the hover watchdog while the plant's command is hover already (its flags only)
        pcmd, last_cmd_t = fw.pcmd, fw.last_cmd_t
        if pcmd is not fw._applied_pcmd or fw.alt_capped or last_cmd_t is None:
            return None
        silence = t_s - last_cmd_t
        hover_due = silence > fw.hover_after_s and not fw.lost_com_hover
        if ((hover_due and fw.applied != _HOVER_APPLIED)
                or not (fw.link_lost or not silence > fw.link_loss_s)):
            return None
        ends = 0.0  # FLYING; a take-off's or landing's end flown too, when nothing else
        if mode is not _FLYING:  # changes with the mode (the hover watchdog and the cap act
            flags, _, _, fw_gaz, _ = pcmd  # only airborne) and the guard may see it after
            climbing = flags & _PROGRESSIVE and fw_gaz > 0.0
            ends = 0.0 if hover_due or climbing else (
                1.0 if sensors.defers_mode(_FLYING if mode is _TAKING_OFF else _LANDED)
                else 0.0)
        self.pack(t_s, pcmd, mode, ends)
        self._kernel(*self._args)
        raw = self._run_bytes()  # out's and iv's bytes: the floats, the pose's arrays
        o = _GET_RUN(raw)
        if o[_R_DONE] < 0:  # a block ran short: new ones, and again
            self.refill()
            return self.run(t_s)
        return self._ran_to(raw, o, mode, hover_due, new_mode, ends)

    def pack(self, t_s: float, pcmd: tuple, mode, ends: float) -> None:
        """The arrays ready for a run to ``t_s`` (the plant in ``mode``, the firmware's held
        ``pcmd``, :meth:`run`'s ``ends``): the state held, the parameters, the inputs."""
        plant, fw, sensors = self.plant, self.firmware, self.sensors
        d = plant.__dict__  # (a last run's truth: the arrays hold the state since)
        if (self.live_out is None or len(d) != self._plant_len
                or len(sensors.__dict__) != self._sensors_len):
            if d.get("_held_by") is not self:
                self._take()
            elif len(d) != self._plant_len or len(sensors.__dict__) != self._sensors_len:
                self.release()  # a held attribute was written meanwhile: it is the newer
                self._take()
        old = self._p_key  # the flight's parameters, unchanged as a rule
        if not (old and old[0] is plant.params and old[1] is plant.noise
                and old[2] is plant._trim_bias_rad and old[3] == plant._yaw_drift_sign):
            self._params()
        flags, _, _, fw_gaz, _ = pcmd
        if flags & _PROGRESSIVE and fw_gaz > 0.0:  # the firmware watches the cap
            climbing, lead_s, alt_max_m = 1.0, fw._lead_s(), fw.config.altitude_max_m
        else:
            climbing = lead_s = alt_max_m = 0.0
        kernel_mode = (ks.MODE_FLYING if mode is _FLYING else  # as the kernel takes it
                       ks.MODE_TAKING_OFF if mode is _TAKING_OFF else ks.MODE_LANDING)
        w0, w1, w2 = plant.wind_mps.tolist()
        roll, pitch, gaz, yaw, hold = self._saved["_current"]  # the plant's command, held
        _PUT_INPUTS(self._sv_memory, _AT_ROLL, roll, pitch, gaz, yaw, 1.0 if hold else 0.0,
                    climbing, lead_s, alt_max_m, w0, w1, w2, kernel_mode, t_s, ends)

    def ran_block(self, t_pose, t_nav, mode) -> None:
        """The arrays after a block of ticks' runs (``sim/drone_block``) of a plant in
        ``mode``: what a tick reads of the last run, and the newest samples (their event
        times; None: taken before the block, the sampler's still)."""
        raw = self._run_bytes()
        self._ran = True
        self.live_raw, self.live_out = raw, _GET_RUN(raw)
        self._took(raw, self.live_out, t_pose, t_nav, mode)

    def block_ran_to(self, mode, ends: float, hover_due: bool = False,
                     target_drawn: bool = False) -> tuple[list, bool]:
        """:meth:`run`'s rest for the tick a block of a plant in ``mode`` ended after its
        legs (their run's bytes still in the arrays; ``ends``, ``hover_due``: the run's;
        ``target_drawn``: the block drew the second object's pose of the run's frame)."""
        raw = self._run_bytes()
        return self._ran_to(raw, _GET_RUN(raw), mode, hover_due, False, ends, target_drawn)
