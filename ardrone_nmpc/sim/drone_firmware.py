"""The simulated AR.Drone's firmware: AT commands applied to the plant, the communication
watchdogs, the altitude cap, and the status its navdata reports (docs/protocol.md, "behaviour a
faithful simulator should reproduce"; [?] marks that document's design choices).

No sockets, threads or clock of its own: both runners' simulated drone
(:class:`~ardrone_nmpc.sim.drone.SimulatedDrone`) owns one — the loopback
:class:`~ardrone_nmpc.sim.drone_server.DroneServer` calls it under its lock with the wall time,
the lockstep link (:class:`~ardrone_nmpc.sim.lockstep_drone.LockstepDrone`) with plant time —
so it is testable datagram by datagram and every rule here holds in ``simulate`` and ``fly
--sim`` alike.

* Sequence numbers: a command runs only if ``seq == 1`` or ``seq > last``; ``last`` resets to
  0 after ``link_loss_s`` without an accepted command [?]. Ignored commands are counted
  (``at_commands_stale``) and are no traffic for the watchdogs.
* ``AT*REF``: bit 9 is a level — set while landed (no emergency, no VBAT_LOW) takes off, so a
  REF still asking for take-off after the drone landed by itself launches it again; clear
  while taking off or flying lands. Bit 8 acts on its 0→1 edge: not in emergency → emergency
  (motors cut, state bits 31 and 16); in emergency on the ground → cleared [?]. The sequence
  rule makes a second client's commands count only when their seq is 1 or above the last
  accepted, whoever sent it.
* ``AT*PCMD`` / ``PCMD_MAG``: flag bit 0 set → the fractions go to the plant; clear → hover.
* Altitude cap: a climbing gaz becomes 0 (minor ALT_OUT_ZONE) once z + v_z·(command delay +
  τ_z), where the climb would stop, reaches ``control:altitude_max`` (checked whenever time
  passes or a command arrives).
* ``AT*FTRIM`` counted only when landed, ``AT*CALIB`` only in flight (no manoeuvre).
* ``AT*CONFIG`` (see :mod:`~ardrone_nmpc.sim.drone_config`; applied or, in another
  multiconfig session, ignored) sets the ACK bit 6 — except in a session that ignores plain
  CONFIG, where a write without its ids is not even acknowledged;
  ``AT*CTRL`` 5 clears it, 4 dumps the configuration on the control port and sets it, 6 dumps
  an empty custom-config list and sets it. ``AT*COMWDG`` clears the com-watchdog bit.
* Watchdogs from the last accepted command: > ``comwdg_s`` → bit 30 (cleared by any command,
  or with ``comwdg_clear="comwdg"`` only by ``AT*COMWDG``); > ``hover_after_s`` airborne → the
  held PCMD is dropped (HOVERING / LOST_COM); > ``link_loss_s`` → bit 13 and the sequence
  resets, the drone keeps hovering, and its navdata falls back to bootstrap until
  ``general:navdata_demo`` is written again (the client "disconnected" [?]: ARDroneLib's
  ``ardrone_general_navdata.c`` answers exactly that bootstrap after a reconnection).
* Status: VBAT_LOW (battery below ``vbat_low_pct``, or the bit injected) and the injected
  hardware fault bits (:attr:`DroneFirmware.fault_bits`) go into the state word.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.protocol.at import (
    CTRL_MODE_ACK,
    CTRL_MODE_CFG_GET,
    CTRL_MODE_CUSTOM_CFG_GET,
    AtCommand,
    Calib,
    Comwdg,
    Config,
    ConfigIds,
    Ctrl,
    Ftrim,
    Pcmd,
    PcmdFlag,
    PcmdMag,
    Ref,
    parse_datagram_lenient,
)
from ardrone_nmpc.protocol.navdata import (CtrlCodes, DroneState, DroneStatus, Navdata,
                                           drone_navdata, encode_drone_navdata)
from ardrone_nmpc.sim.drone_config import ConfigStore, HeldSession, OutdoorProfiles

__all__ = ["DroneFirmware", "DroneServerCounters", "VBAT_LOW_PCT"]

#: Battery level (%) below which a simulated drone sets state bit 15 (VBAT_LOW) and refuses to
#: take off.
VBAT_LOW_PCT = 20.0

_HOVER_CMD = (0, 0.0, 0.0, 0.0, 0.0)      # (flags, roll, pitch, gaz, yaw)
_PROGRESSIVE = int(PcmdFlag.PROGRESSIVE)  # a plain int: IntFlag arithmetic is slow per tick
_VBAT_LOW = int(DroneState.VBAT_LOW)  # (the same: battery_low's, once a packet)
# The firmware's 200 Hz control loop: how often a climb near the cap is checked on a plant
# that does not integrate in steps of its own (``params.integration_step_s``).
CONTROL_LOOP_S = 0.005


@dataclass
class DroneServerCounters:
    """Traffic and timing counters of a simulated drone (a snapshot copy when read)."""

    at_datagrams_in: int = 0          # datagrams on the AT port (incl. malformed ones)
    at_commands_in: int = 0           # well-formed commands
    at_commands_applied: int = 0      # accepted by the sequence rule and executed
    at_commands_stale: int = 0        # ignored by the sequence rule
    at_commands_unknown: int = 0      # well-formed commands of other names (ANIM, LED, …)
    malformed_datagrams: int = 0      # datagrams with at least one malformed part
    malformed_commands: int = 0       # malformed commands (an oversized datagram counts one)
    config_writes: int = 0            # acknowledged AT*CONFIG
    config_writes_ignored: int = 0    # … of them not applied (another multiconfig session)
    config_writes_unacknowledged: int = 0  # CONFIG without the session's ids, not even ACKed
    ftrim_accepted: int = 0
    calib_accepted: int = 0
    navdata_datagrams_in: int = 0     # wake-ups (any datagram on the navdata port)
    navdata_packets_out: int = 0
    navdata_send_errors: int = 0
    navdata_stream_starts: int = 0
    navdata_stream_stops: int = 0     # streams stopped for lack of client traffic
    control_connections: int = 0
    config_dumps: int = 0
    physics_steps: int = 0
    physics_max_lag_s: float = 0.0    # largest lateness of a physics wake-up
    link_losses: int = 0
    at_datagrams_lost: int = 0        # discarded on arrival by an injected AT-loss fault


class DroneFirmware:
    """The drone's protocol state and behaviour (module docstring); call under the lock.

    Parameters
    ----------
    plant : the simulated drone.
    counters : the server's :class:`DroneServerCounters` (updated here).
    dump_config : writes a text on the control port (``AT*CTRL`` 4 and 6); None = not served.
    comwdg_s, hover_after_s, link_loss_s : watchdog times (s).
    comwdg_clear : "any" or "comwdg" (who clears state bit 30).
    ctrl_codes : the transition codes navdata reports (:class:`CtrlCodes`).
    altitude_max_m : initial ``control:altitude_max`` (m).
    vbat_low_pct : battery level (%) below which state bit 15 is set and take-off refused.
    fault_bits : the hardware fault bits reported from power-on (:class:`DroneState` values;
        :attr:`fault_bits` takes more as injected faults start).
    session : a multiconfig session the drone is in (:class:`HeldSession`), None = default.
    outdoor : the drone's stored profiles, last flown outdoors
        (:class:`~ardrone_nmpc.sim.drone_config.OutdoorProfiles`), None = indoor defaults.
    """

    def __init__(self, plant, *, counters: DroneServerCounters,
                 dump_config: Optional[Callable[[str], None]] = None, comwdg_s: float = 0.05,
                 hover_after_s: float = 0.25, link_loss_s: float = 2.0,
                 comwdg_clear: str = "any", ctrl_codes: CtrlCodes = CtrlCodes.SDK,
                 altitude_max_m: float = 3.0, vbat_low_pct: float = VBAT_LOW_PCT,
                 fault_bits: int = 0, session: Optional[HeldSession] = None,
                 outdoor: Optional[OutdoorProfiles] = None) -> None:
        self.plant = plant
        self.counters = counters
        self.dump_config = dump_config
        self.comwdg_s = comwdg_s
        self.hover_after_s = hover_after_s
        self.link_loss_s = link_loss_s
        self.comwdg_clear = comwdg_clear
        self.ctrl_codes = CtrlCodes(ctrl_codes)
        self.vbat_low_pct = float(vbat_low_pct)
        self.fault_bits = int(fault_bits)
        self.config = ConfigStore(plant, altitude_max_m=altitude_max_m, session=session,
                                  outdoor=outdoor)
        self.last_seq = 0
        self.last_cmd_t: Optional[float] = None      # last accepted AT command
        self.comwdg_latched = True
        self.lost_com_hover = False
        self.link_lost = False
        self.ref_start = False
        self.ref_emergency = False
        self.user_emergency = False
        self.ack = False
        self.pcmd = _HOVER_CMD
        self.applied: tuple | None = None
        self._applied_pcmd: tuple | None = None  # the held command ``applied`` came from
        self._lead_params = None
        self._lead = 0.0
        self.alt_capped = False
        self.nav_seq = 0

    # ------------------------------------------------------------------ AT intake

    def receive(self, data: bytes, now: float) -> None:
        """Apply one AT datagram received at ``now``."""
        commands, errors = parse_datagram_lenient(data)
        c = self.counters
        c.at_datagrams_in += 1
        if errors:
            c.malformed_datagrams += 1
            c.malformed_commands += len(errors)
        self.execute_datagram(commands, now)

    def execute_datagram(self, commands, now: float) -> None:
        """The decoded commands of one datagram, in order, then the held command applied."""
        ids = None   # those of an AT*CONFIG_IDS right before (the SDK sends the pair together)
        for cmd in commands:
            self.counters.at_commands_in += 1
            self.execute(cmd, now, ids)
            b = cmd.body
            ids = (b.session_id, b.profile_id, b.application_id) if isinstance(b, ConfigIds) \
                else None
        self.apply_command()

    def execute_pcmd(self, seq: int, pcmd: tuple, now: float) -> None:
        """A datagram of one progressive PCMD — ``seq`` and ``(flags, roll, pitch, gaz,
        yaw)`` — as :meth:`execute_datagram` runs it, without the command objects (the
        lockstep link sends one every tick)."""
        self.counters.at_commands_in += 1
        if self._accept(seq, now):
            self.pcmd = pcmd
        self.apply_command()

    def _accept(self, seq: int, now: float) -> bool:
        """The sequence-number rule; an accepted command is traffic for the watchdogs."""
        c = self.counters
        if not (seq == 1 or seq > self.last_seq):
            c.at_commands_stale += 1
            return False
        self.last_seq = seq
        c.at_commands_applied += 1
        self.last_cmd_t = now
        self.link_lost = False
        self.lost_com_hover = False
        if self.comwdg_clear == "any":
            self.comwdg_latched = False
        return True

    def execute(self, cmd: AtCommand, now: float,
                ids: Optional[tuple[str, str, str]] = None) -> None:
        """One command under the sequence-number rule (``ids``: the ``AT*CONFIG_IDS`` before
        it in the datagram, if any)."""
        if not self._accept(cmd.seq, now):
            return
        c = self.counters
        body = cmd.body
        mode = self.plant.mode
        if isinstance(body, Ref):
            self._on_ref(body)
        elif isinstance(body, (Pcmd, PcmdMag)):
            self.pcmd = (body.flags, body.roll_frac, body.pitch_frac, body.gaz_frac,
                         body.yaw_frac)
        elif isinstance(body, Comwdg):
            self.comwdg_latched = False
        elif isinstance(body, Config):
            if not self.config.acknowledges(body.key, ids):
                c.config_writes_unacknowledged += 1
                return
            c.config_writes += 1
            c.config_writes_ignored += not self.config.write(body.key, body.value, ids)
            self.ack = True                              # acknowledged, applied or not
        elif isinstance(body, ConfigIds):
            self.config.config_ids = (body.session_id, body.profile_id, body.application_id)
        elif isinstance(body, Ctrl):
            self._on_ctrl(body.mode)
        elif isinstance(body, Ftrim):
            c.ftrim_accepted += mode is FlightMode.LANDED
        elif isinstance(body, Calib):
            c.calib_accepted += mode is FlightMode.FLYING
        else:
            c.at_commands_unknown += 1

    def _on_ref(self, ref: Ref) -> None:
        plant = self.plant
        start, emergency = ref.is_takeoff, ref.is_emergency
        if emergency and not self.ref_emergency:        # 0→1 edge of bit 8
            if plant.mode is FlightMode.EMERGENCY:
                if plant.reset_emergency():
                    self.user_emergency = False
            elif plant.emergency():
                self.user_emergency = True
                self.pcmd = _HOVER_CMD
        self.ref_emergency = emergency
        self.ref_start = start
        mode = plant.mode
        if start and mode is FlightMode.LANDED and not self.vbat_low:
            plant.takeoff()                              # the plant refuses an empty battery
        elif not start and mode in (FlightMode.TAKING_OFF, FlightMode.FLYING):
            plant.land()

    def _on_ctrl(self, mode: int) -> None:
        if mode == CTRL_MODE_ACK:
            self.ack = False
        elif mode in (CTRL_MODE_CFG_GET, CTRL_MODE_CUSTOM_CFG_GET):
            if self.dump_config is not None:
                self.dump_config(self.config.text() if mode == CTRL_MODE_CFG_GET else "")
            self.ack = True

    # ------------------------------------------------------------------ time passing

    def advance(self, dt_s: float, now: float) -> None:
        """Time passing: the plant by ``dt_s``, then the watchdogs and the held command (the
        altitude cap) at ``now``. While a climb nears the cap, the cap is checked after every
        integration step, as the drone's control loop does, however long ``dt_s`` (the
        loopback server steps 5 ms, the lockstep link from one sensor event to the next)."""
        plant = self.plant
        flags, _, _, gaz, _ = self.pcmd
        if not (flags & _PROGRESSIVE and gaz > 0.0) or not self._climb_may_reach_cap(dt_s):
            plant.advance(dt_s)
            self.watchdogs(now)
            if self.pcmd is not self._applied_pcmd or self.alt_capped:  # else nothing to do
                self.apply_command()
            return
        h = getattr(plant.params, "integration_step_s", CONTROL_LOOP_S)
        n = int(dt_s / h)
        for _ in range(n):
            plant.advance(h)
            self.apply_command()
        plant.advance(dt_s - n * h)  # the remainder (carried by the plant)
        self.watchdogs(now)
        self.apply_command()

    def _lead_s(self) -> float:
        """After the command delay, the first-order vertical loop (τ_z) still rises
        v_z·(T_d + τ_z): the lead of :meth:`_z_stop_m` (cached per plant params)."""
        params = self.plant.params
        if params is not self._lead_params:
            self._lead_params = params
            self._lead = (getattr(params, "command_delay_s", 0.0)
                          + getattr(params, "tau_vz_s", 0.0))
        return self._lead

    def _z_stop_m(self) -> float:
        """Where a climb stops if gaz drops to 0 now."""
        z, vz = self.plant.altitude_m_and_rate_mps
        return float(z) + max(0.0, float(vz)) * self._lead_s()

    def _climb_may_reach_cap(self, dt_s: float) -> bool:
        """A climb is held and within reach of the cap in ``dt_s`` (a bound: at most
        ``control_vz_max`` for ``dt_s``, its stop ``control_vz_max``·lead above)."""
        flags, _, _, gaz, _ = self.pcmd
        if not (flags & _PROGRESSIVE and gaz > 0.0 and self.plant.mode.airborne):
            return False
        z, _ = self.plant.altitude_m_and_rate_mps
        reach_m = self.plant.params.control_vz_max_mps * (dt_s + self._lead_s())
        return z + reach_m >= self.config.altitude_max_m

    def silence(self, now: float) -> float:
        """Seconds since the last accepted command (inf before the first)."""
        return math.inf if self.last_cmd_t is None else now - self.last_cmd_t

    def latch_after_run(self, now: float) -> None:
        """The com-watchdog bit as :meth:`watchdogs` would have latched it by ``now``, the
        last firmware time of a compiled run of the legs (NaN: none ran) — the other
        watchdogs were checked not to fire (``CompiledLegs``, ``QuietWire``)."""
        if now == now and not self.comwdg_latched and now - self.last_cmd_t > self.comwdg_s:
            self.comwdg_latched = True

    def watchdogs(self, now: float) -> None:
        silence = self.silence(now)
        if silence > self.comwdg_s:
            self.comwdg_latched = True
        if (silence > self.hover_after_s and not self.lost_com_hover
                and self.plant.mode.airborne):
            self.lost_com_hover = True
            self.pcmd = _HOVER_CMD
        if silence > self.link_loss_s and not self.link_lost and self.last_cmd_t is not None:
            self.link_lost = True
            self.last_seq = 0
            self.config.bootstrap = True       # navdata restarts in bootstrap (module doc)
            self.counters.link_losses += 1

    def apply_command(self) -> None:
        """Send the effective PCMD (held command, altitude cap) to the plant when it changes."""
        pcmd = self.pcmd
        flags, roll, pitch, gaz, yaw = pcmd
        progressive = bool(flags & _PROGRESSIVE)
        climbing = progressive and gaz > 0.0
        if pcmd is self._applied_pcmd and not climbing:  # applied, and no cap to watch
            return
        self._applied_pcmd = pcmd
        plant = self.plant
        at_cap = False
        if climbing and plant.mode.airborne:  # only a climb is capped
            at_cap = self._z_stop_m() >= self.config.altitude_max_m
        if at_cap:
            gaz = 0.0
        self.alt_capped = at_cap
        cmd = (roll, pitch, gaz, yaw, True) if progressive else (0.0, 0.0, 0.0, 0.0, False)
        if cmd != self.applied:
            plant.command(*cmd[:4], progressive=cmd[4])
            self.applied = cmd

    # ------------------------------------------------------------------ navdata

    def status(self, now: float, battery_pct: float | None = None) -> DroneStatus:
        """What the drone reports about itself now (``battery_pct``: the plant's then, when
        the caller has it — the compiled legs, holding the plant's state)."""
        return DroneStatus(
            self.plant.mode.value, moving=self.moving,
            alt_out_zone=self.alt_capped, lost_com=self.lost_com_hover,
            user_emergency=self.user_emergency, start_button=self.ref_start, ack=self.ack,
            bootstrap=self.config.bootstrap, demo=self.config.demo,
            com_watchdog=self.comwdg_latched or (self.comwdg_clear == "any"
                                                 and self.silence(now) > self.comwdg_s),
            com_lost=self.link_lost, battery_low=self.battery_low(
                self.plant.battery_pct if battery_pct is None else battery_pct),
            faults=self.fault_bits)

    def status_inputs(self) -> tuple:
        """What :meth:`status` reads of the firmware and its plant, but for the time and the
        battery it is given: equal inputs, the same status at the same time and battery (a
        quiet tick's packets, most ticks', share one: ``sim/quiet_wire``). Kept beside
        :meth:`status`: what it comes to read, this holds too."""
        config = self.config
        return (self.plant.mode, self.moving, self.alt_capped, self.lost_com_hover,
                self.user_emergency, self.ref_start, self.ack, config.bootstrap, config.demo,
                self.comwdg_latched, self.link_lost, self.fault_bits, self.ctrl_codes)

    @property
    def moving(self) -> bool:
        """A progressive PCMD with a non-zero value held: what :meth:`status` reports of the
        command (ctrl_state FLYING, else HOVERING)."""
        flags, roll, pitch, gaz, yaw = self.pcmd
        return bool(flags & _PROGRESSIVE) and any((roll, pitch, gaz, yaw))

    @property
    def vbat_low(self) -> bool:
        """State bit 15: the battery below :attr:`vbat_low_pct`, or the bit injected."""
        return self.battery_low(self.plant.battery_pct)

    def battery_low(self, battery_pct: float) -> bool:
        """:attr:`vbat_low` of a plant's battery at ``battery_pct``."""
        return battery_pct < self.vbat_low_pct or bool(self.fault_bits & _VBAT_LOW)

    def skip_packet(self) -> None:
        """A packet lost on the way: its sequence number is used all the same."""
        self._next_sequence()

    def _next_sequence(self) -> int:
        """The next packet's sequence number, taken (from 1 again after 2³² − 1)."""
        self.nav_seq = self.nav_seq + 1 if self.nav_seq < 0xFFFFFFFF else 1
        return self.nav_seq

    def packet(self, now: float) -> bytes:
        """The next navdata packet (its sequence counts up from 1 across stream restarts)."""
        seq = self._next_sequence()
        status = self.status(now)
        sample = None if status.bootstrap else self.plant.navdata()
        return encode_drone_navdata(status, seq, sample, codes=self.ctrl_codes,
                                    options_mask=self.config.navdata_options,
                                    t_s=self.plant.t_s)

    def packet_of(self, now: float, sample) -> Navdata:
        """:meth:`packet` of a navdata ``sample`` the plant's compiled legs drew at ``now``
        (out of bootstrap; its ``t_s`` and ``battery_pct``: the plant's then), as a receiver
        decodes it (:func:`~ardrone_nmpc.protocol.navdata.drone_navdata`)."""
        seq = self._next_sequence()
        return drone_navdata(self.status(now, sample.battery_pct), seq, sample,
                             codes=self.ctrl_codes, options_mask=self.config.navdata_options,
                             t_s=sample.t_s)
