"""The simulated drone as ``simulate`` flies it: the interface of the drone's link on a manual
clock — no sockets, no threads, no sleeping.

:class:`LockstepDrone` offers what :class:`~ardrone_nmpc.links.drone_link.DroneLink` offers a
runner — an AT sender (REF levels, PCMD: numbered commands the firmware applies under its
sequence rule), a navdata receiver (the newest sample, with the link's take-off guard), the
configuration port (the same :class:`~ardrone_nmpc.links.drone_config.ConfigHandshake` writes,
the dump read back) — over the experiment's
:class:`~ardrone_nmpc.sim.drone.SimulatedDrone`, the drone ``fly --sim`` serves over UDP. The
runner owns the clock: :meth:`LockstepDrone.advance_to` runs the drone and its sensors
(:class:`~ardrone_nmpc.sim.sensors.LockstepSensors`) to a plant time. Commands skip the bytes
(their fractions reach the firmware as the doubles the tick computed, not as the wire's
float32s); what the firmware does with them is the same.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ardrone_nmpc.core.angles import wrap_angle_rad
from ardrone_nmpc.core.types import FlightMode, PlantTruth, TickInputs
from ardrone_nmpc.links.drone_commands import TakeoffGuard
from ardrone_nmpc.links.drone_config import ConfigHandshake, LinkError, parse_config_text
from ardrone_nmpc.protocol.at import AtBody, Config, ConfigIds, Pcmd, PcmdFlag, Ref
from ardrone_nmpc.sim.drone import SimulatedDrone
from ardrone_nmpc.sim import drone_block, wire_block
from ardrone_nmpc.sim.lockstep_legs import ALL_DONE, TRUTH_CELLS_OF
from ardrone_nmpc.sim.plant import AirframePlant
from ardrone_nmpc.sim.sensors import LockstepSensors

__all__ = ["LockstepDrone"]

_HOVER = Pcmd.hover()
# REF land made once: a body's checks cost ~3 µs, and the landing holds it every tick of its
# descent (a Ref is frozen: one instance serves every send)
_LAND = Ref.landing()
_DESCENT_TICKS = 64  # the most ticks of a take-off or a landing one compiled call flies
_ID_KEYS = ("custom:session_id", "custom:profile_id", "custom:application_id")


_PROGRESSIVE = int(PcmdFlag.PROGRESSIVE)
_PI = math.pi
_set = object.__setattr__


class _Numbered(NamedTuple):
    """A command as the firmware takes it from a decoded datagram: its number and its body
    (built every tick, so without :class:`AtCommand`'s wire checks)."""

    seq: int
    body: AtBody


def _exact_pcmd(roll_frac: float, pitch_frac: float, gaz_frac: float, yaw_frac: float) -> Pcmd:
    """A progressive PCMD holding the tick's doubles: :class:`Pcmd`'s constructor rounds to the
    wire's float32, and no wire is crossed here."""
    body = object.__new__(Pcmd)
    _set(body, "flags", _PROGRESSIVE)
    _set(body, "roll_frac", float(roll_frac))
    _set(body, "pitch_frac", float(pitch_frac))
    _set(body, "gaz_frac", float(gaz_frac))
    _set(body, "yaw_frac", float(yaw_frac))
    return body


class LockstepDrone(ConfigHandshake):
    """The experiment's simulated drone behind the link's interface (module docstring).

    Parameters
    ----------
    cfg : ExperimentConfig.
    seed : seed of the plant and the fault draws (default ``sim.seed``).
    """

    host = "simulated-drone"

    def __init__(self, cfg, *, seed: int | None = None, plant=None) -> None:
        self.sim = SimulatedDrone.from_config(cfg, seed=seed, plant=plant)
        if self.sim.faults is not None:
            self.sim.faults.set_clock(0.0)  # the faults' clock is experiment time itself
        self.control_port = cfg.drone.control_port
        self.config_ids = cfg.drone.config_ids
        self.bootstrap_answers = 0
        self.sensors = LockstepSensors(cfg, self.sim, on_navdata=self._on_navdata,
                                       on_bootstrap=self._answer_bootstrap,
                                       defers_mode=self._guard_ignores,
                                       watching=self._guard_on)
        self._seq = 0
        self._ref: Ref | None = None        # the REF held
        self._ref_unsent: Ref | None = None  # … not yet received by the drone
        self._guard = TakeoffGuard()
        self.self_landing: str | None = None
        self.t_exp_s = -math.inf  # experiment time of the clock now (the faults' clock)
        # the sampler's compiled legs (None without): the truth of their last run while they
        # hold the state (a legs object no longer used never runs: its live_out stays None)
        sensors = self.sensors  # (the direct path's, or the wire path's quiet ticks')
        quiet = getattr(sensors, "_quiet", None)
        self._legs = sensors._legs if quiet is None else quiet.legs
        self._wire_rest = False  # (a wire block's last run stopped before a leg: after_block)
        self._waited = np.zeros(drone_block.D_SIZE)  # (ascend's and descend's numbers)
        plant = self.sim.plant  # the airframe's truth without a PlantTruth (truth_cells)
        self._airframe = (isinstance(plant, AirframePlant)
                          and type(plant).truth is AirframePlant.truth)

    # ------------------------------------------------------------------ the manual clock
    def connect(self) -> None:
        """What :meth:`DroneLink.connect` writes: the session ids (if configured), then
        ``general:navdata_demo`` — the drone leaves bootstrap and sends demo navdata."""
        if self.config_ids is not None:
            for key, value in zip(_ID_KEYS, self.config_ids):
                self.write_config(key, value)
        self.write_config("general:navdata_demo", True)

    def start_experiment(self, t_zero_s: float) -> list[dict]:
        """Experiment time 0 is plant time ``t_zero_s``; returns the events announcing what the
        drone injects."""
        self.sensors.t_zero_s = t_zero_s
        return self.sim.start_experiment(0.0)

    def advance_to(self, t_s: float, t_exp_s: float | None = None) -> None:
        """Run the drone to plant time ``t_s``; with ``t_exp_s`` (the experiment time of this
        step of the clock) the plant faults due by then act first."""
        if t_exp_s is not None:
            self.t_exp_s = t_exp_s
            if self.sim.faults is not None:  # (SimulatedDrone.update_faults' own test)
                self.sim.update_faults(t_exp_s)
        sensors = self.sensors
        legs = sensors._legs  # (LockstepSensors.advance_to without its frame: every tick)
        if legs is None:
            sensors.advance_to(t_s)
            return
        left = legs.run(t_s)
        if left is not ALL_DONE:  # the Python legs, or what the run left
            sensors.go_on(t_s, left)

    def plain_until_s(self, t_exp_s: float) -> float:
        """The experiment time from ``t_exp_s`` on before which nothing injected acts on the
        drone (``ServerFaults.quiet_until_s``: the faults' clock is experiment time here):
        its ticks then are a fault-free drone's, which blocks of ticks may fly. inf without
        injected faults; at or before ``t_exp_s``: something may act then."""
        faults = self.sim.faults
        if faults is None:
            return math.inf
        if self.sensors.wire:  # the wire's quiet ticks (sim/wire_block): from the plant's
            # time, where the tick's first legs begin, not t_exp_s — a bound no later
            return wire_block.quiet_until_s(self.sensors, self._legs)
        return faults.quiet_until_s(t_exp_s)

    def block_entry(self, d, second_object: bool = False) -> bool:
        """``d`` filled for a block of ticks from the next (``sim/drone_block``), or False:
        the next tick is not one a block flies (``drone_block.block_entry``; a REF waiting
        to be sent, a drone that landed by itself); ``second_object``: the block draws the
        second object's frames."""
        legs = self._legs
        if legs is None or self._ref_unsent is not None or self.self_landing is not None:
            return False
        if self.sensors.wire:
            return wire_block.wire_block_entry(legs, d, self._seq + 1)
        return drone_block.block_entry(legs, d, self._seq + 1, second_object)

    def after_block(self, d, ran: bool, t_exp_s: float) -> None:
        """What a block of ticks left (``d``), written back: the PCMDs numbered, the
        firmware's, the plant's and the sampler's state; ``t_exp_s``: the experiment time
        of the last tick whose legs it ran (``ran``)."""
        self._seq += int(d[drone_block.D_COMMANDS])
        if ran:
            self.t_exp_s = t_exp_s
        drone_block.after_block(self._legs, d[:drone_block.D_SIZE], self._seq, ran)
        if self.sensors.wire:  # the frames and packets of its ticks sent and received
            self._wire_rest = wire_block.sent(self._legs, d)

    def blocks_sent(self, d) -> None:
        """A chain of blocks of the wire's ticks goes on: the frames and packets of its
        ticks so far sent and received (``sim/wire_block.sent``; the drone's state stays
        the chain's: its exits that go on leave no run stopped before a leg)."""
        rest = wire_block.sent(self._legs, d)
        assert not rest, "a chain of blocks went on after a run stopped before a leg"

    def block_ran_to(self, t_s: float, mode: FlightMode = FlightMode.FLYING,
                     ends: float = 0.0, hover_due: bool = False,
                     target_drawn: bool = False) -> None:
        """The rest of :meth:`advance_to` to plant time ``t_s`` for the tick a block of a
        plant in ``mode`` ended after its legs (``ends`` 1: a run that may fly the mode's
        end; ``hover_due``: the hover watchdog due in its run; ``target_drawn``: the block
        drew the second object's pose of the run's frame — ``runtime/second_object``)."""
        sensors = self.sensors
        if sensors.wire:  # (a quiet tick's: its run's frames and packets sent, received)
            if self._wire_rest:  # the rest of a run that stopped before a leg
                self._wire_rest = False
                self._legs.release()
                sensors._send_through_wire(t_s)
                sensors.deliver(t_s)
            return
        left = sensors._legs.block_ran_to(mode, ends, hover_due, target_drawn)
        if left is not ALL_DONE:
            sensors.go_on(t_s, left)

    def ascend(self, period_s: float, timeout_s: float) -> int:
        """Ticks of a take-off a runner waits out (each :meth:`advance_to` the plant's time
        now plus ``period_s``) in one compiled call (``sim/drone_block.drone_ascent``) while
        each is the usual one, until the plant's time reaches ``timeout_s`` or the climb
        settles (FLYING): the ticks done (0: the next tick is not one it flies)."""
        legs, d = self.sensors._legs, self._waited
        ref = self._ref
        # (injected faults too: none acts before experiment time — a take-off's ticks are
        # advance_to's without one — and the ascent sends no command)
        if not (legs is not None and ref is not None and ref.is_takeoff
                and self._ref_unsent is None and drone_block.ascent_entry(legs, d)):
            return 0
        # (the climb's end flown too where the guard may see its sample after the run, as
        # CompiledLegs.run flies it)
        ends = 1.0 if self.sensors.defers_mode(FlightMode.FLYING) else 0.0
        n, status, t_s, hover_due, run_ends = drone_block.drone_ascent(
            d, *legs._args, legs.t_s(), period_s, _DESCENT_TICKS, timeout_s, ends)
        legs_ran = status == drone_block.LEGS_PARTIAL
        drone_block.after_ascent(legs, d, n > 0 or legs_ran)
        if status == drone_block.LEGS_SHORT:
            legs.refill()
        if legs_ran:
            self.block_ran_to(t_s, FlightMode.TAKING_OFF, run_ends, hover_due)
            n += 1
        return n

    def descend(self, t_first_s: float, k: int, period_s: float, deadline_s: float,
                t_start_s: float) -> tuple[int, bool]:
        """Ticks ``k`` … of a landing a runner waits out (plant time ``t_first_s +
        k·period_s``, experiment time that less ``t_start_s``: each :meth:`advance_to`
        then :meth:`land`) in one compiled call (``sim/drone_block.drone_descent``) while
        each is the usual one, until the plant's time reaches ``deadline_s``: ``(ticks
        done, whether the next tick's legs ran)`` — that tick's rest (:meth:`land`, …) is
        the caller's. ``(0, False)``: nothing done (the tick is not one it flies)."""
        legs, d = self.sensors._legs, self._waited
        # (with injected faults: the ticks before the first at which one may act)
        n_max = _DESCENT_TICKS if self.sim.faults is None else self._plain_descent(
            t_first_s, k, period_s, t_start_s)
        if not (n_max and legs is not None and self._ref is _LAND and self._ref_unsent is None
                and drone_block.descent_entry(legs, d, self._seq + 1)):
            return 0, False
        # (the touch-down flown too where the guard may see its sample after the run, as
        # CompiledLegs.run flies it: the REF held is a landing's, no climb, no hover due)
        ends = 1.0 if self.sensors.defers_mode(FlightMode.LANDED) else 0.0
        n, status = drone_block.drone_descent(d, *legs._args, t_first_s, period_s, k,
                                              n_max, deadline_s, ends)
        legs_ran = status == drone_block.LEGS_PARTIAL
        self._seq += 2 * n
        if n or legs_ran:
            self.t_exp_s = t_first_s + (k + n - (0 if legs_ran else 1)) * period_s - t_start_s
        drone_block.after_descent(legs, d, self._seq, n > 0 or legs_ran)
        if status == drone_block.LEGS_SHORT:
            legs.refill()
        if legs_ran:
            self.block_ran_to(t_first_s + (k + n) * period_s, FlightMode.LANDING, ends)
        return n, legs_ran

    def climb_out(self, period_s: float, timeout_s: float,
                  between=None) -> tuple[FlightMode, float]:
        """A take-off a runner waits out after :meth:`takeoff`: ticks of ``period_s`` — in
        one call while :meth:`ascend` flies them, else one :meth:`advance_to` each — until
        the plant flies (FLYING) or its time reaches ``timeout_s``; ``between()`` before
        each (a signal check). ``(mode, plant time s)`` at the end (the runner's and the
        precompile's take-off: one home)."""
        mode, t_s = self.mode_and_t()
        while mode is not FlightMode.FLYING and t_s < timeout_s:
            if between is not None:
                between()
            if not self.ascend(period_s, timeout_s):
                self.advance_to(t_s + period_s)
            mode, t_s = self.mode_and_t()
        return mode, t_s

    def touch_down(self, t_first_s: float, k: int, period_s: float, deadline_s: float,
                   t_start_s: float, on_events=None) -> tuple[FlightMode, float]:
        """A landing a runner waits out, unlogged, after :meth:`land`: ticks ``k`` … (plant
        time ``t_first_s + k·period_s``, experiment time that less ``t_start_s``) — in one
        call while :meth:`descend` flies them, else each :meth:`advance_to`, the injected
        faults' events to ``on_events(events)`` and REF land again — until LANDED, an
        EMERGENCY or the plant's time at ``deadline_s``: ``(mode, plant time s)`` then."""
        landed, emergency = FlightMode.LANDED, FlightMode.EMERGENCY
        mode, t_s = self.mode_and_t()
        while mode is not landed and t_s < deadline_s:
            if mode is emergency:
                break
            n, legs_ran = self.descend(t_first_s, k, period_s, deadline_s, t_start_s)
            k += n
            if n and not legs_ran:  # (ticks done whole: the loop's test again)
                mode, t_s = self.mode_and_t()
                continue
            if not legs_ran:
                t_plant = t_first_s + k * period_s
                self.advance_to(t_plant, t_plant - t_start_s)
            events = self.take_events()  # the faults that started: mostly none
            if events and on_events is not None:
                on_events(events)
            self.land()  # REF land, held as the link's keepalive holds it
            k += 1
            mode, t_s = self.mode_and_t()
        return mode, t_s

    def _plain_descent(self, t_first_s: float, k: int, period_s: float,
                       t_start_s: float) -> int:
        """How many of a landing's ticks from ``k`` (at most a descent's) nothing injected
        acts at: their experiment times, as :meth:`descend` and the runner make them,
        before :meth:`plain_until_s`."""
        t_exp_s = t_first_s + k * period_s - t_start_s
        bound = self.plain_until_s(t_exp_s)
        n = 0
        while n < _DESCENT_TICKS and t_first_s + (k + n) * period_s - t_start_s < bound:
            n += 1
        return n

    def take_events(self) -> list[tuple[float, dict]]:
        """``(experiment time s, event)`` of the injected faults that started since the last
        call."""
        return self.sim.take_events()

    @property
    def state_word(self) -> int:
        """The state word the drone reports now (its fault bits: the preflight reads them)."""
        return int(self.sim.firmware.status(self.sim.plant.t_s).state_bits())

    @property
    def truth(self) -> PlantTruth:
        """The plant's true state (a simulating runner logs it)."""
        legs = self._legs
        if legs is not None:  # (from the compiled legs' arrays while they hold the state)
            return legs.truth()
        return self.sim.plant.truth

    def mode_and_t(self) -> tuple[FlightMode, float]:
        """(mode, t_s) of :attr:`truth`, without building it (a landing's wait, every tick):
        an airframe's, read while the compiled legs hold its state."""
        legs = self._legs
        if legs is None:
            truth = self.sim.plant.truth
            return truth.mode, truth.t_s
        return self.sim.plant._mode, legs.t_s()

    def truth_cells(self) -> tuple:
        """(x, y, z, ψ, ż) of :attr:`truth` (the logged truth, every tick): an airframe's read
        from its state, the values :attr:`AirframePlant.truth` would hold, without building
        it."""
        legs = self._legs  # the last run's truth while the legs hold the (airframe's) state
        o = legs.live_out if legs is not None else None
        if o is not None:  # (CompiledLegs.live without its frame: every tick)
            if len(legs.plant.__dict__) == legs._plant_len:  # the run's floats (ψ most often
                x, y, z, psi, vz = TRUTH_CELLS_OF(o)  # in (−π, π], where the wrap returns it)
                return x, y, z, psi if -_PI < psi <= _PI else wrap_angle_rad(psi), vz
            legs.release()  # a held attribute was written since: the plant's
        plant = self.sim.plant
        if self._airframe:
            state = plant._state  # ψ wrapped as AirframePlant.truth wraps it
            return state[0], state[1], state[2], wrap_angle_rad(state[8]), state[5]
        truth = plant.truth
        p, v = truth.position_m, truth.velocity_mps
        return p[0], p[1], p[2], truth.psi_rad, v[2]

    # ------------------------------------------------------------------ navdata receiver
    def inputs(self, t_s: float) -> TickInputs:
        """What the links hold at plant time ``t_s``."""
        return self.sensors.inputs(t_s)

    @property
    def navdata(self):
        """The newest navdata sample (None before the first)."""
        return self.sensors.nav

    @property
    def navdata_rx_t_s(self) -> float:
        return self.sensors.nav_rx_t_s

    def _guard_on(self) -> bool:
        """The take-off guard watches the navdata: a take-off REF is held, and the drone has
        not landed by itself."""
        ref = self._ref
        return not (ref is None or not ref.is_takeoff or ref.is_emergency or self.self_landing)

    def _on_navdata(self, state, ctrl_major) -> None:
        if not self._guard_on():
            return
        what = self._guard.observe(state, ctrl_major)
        if what is not None:  # the take-off bit is dropped at once, and for good
            self.self_landing = f"the drone {what}"
            self._hold(Ref.landing())

    def _guard_ignores(self, mode: FlightMode) -> bool:
        """A navdata sample showing the new flight mode ``mode`` makes :meth:`_on_navdata`
        send nothing, whenever in the tick's compiled run it reaches it: no take-off REF is
        held (the guard is off), or ``mode`` is one the guard cannot act on — taking off or
        flying: the flight bit set, no emergency, a major of taking off, or flying or
        hovering (the hover watchdog, which may fire in a run, changes one to the other),
        never a landing's (a run stops before a mode change)."""
        return (not self._guard_on() or mode is FlightMode.TAKING_OFF
                or mode is FlightMode.FLYING)

    def _answer_bootstrap(self) -> None:
        """A bootstrap packet (the drone lost its client): write ``navdata_demo`` again, as
        :class:`~ardrone_nmpc.links.drone_link.DroneLink` does."""
        self.bootstrap_answers += 1
        if self.config_ids is not None:
            self.write_config("custom:session_id", self.config_ids[0])
        self.write_config("general:navdata_demo", True)

    # ------------------------------------------------------------------ AT sender
    def takeoff(self) -> None:
        """Hold REF take-off; the command is reset to hover."""
        if self.self_landing is not None:
            raise LinkError(f"take-off refused: {self.self_landing}")
        self._guard.reset()
        self._hold(Ref.takeoff())

    def land(self) -> None:
        """Hold REF land; the command is reset to hover."""
        legs = self._legs  # held again (a landing's every tick): the chain written out,
        # unless an injected AT loss decides the datagram's fate
        if (self._ref is _LAND and self._ref_unsent is None and legs is not None
                and (legs.lands_again or legs.lands_in
                     and not self.sim.faults.at_loss_acts(self.t_exp_s))
                and legs.land_again(self._seq + 1)):
            self._seq += 2
            return
        self._hold(_LAND)

    def emergency(self) -> None:
        """Cut the motors (REF bit 8 rising)."""
        self._hold(Ref.emergency())

    def set_command(self, roll_frac: float, pitch_frac: float, gaz_frac: float,
                    yaw_frac: float, *, progressive: bool = True) -> None:
        """PCMD — with the REF held until one datagram carrying it arrived: the firmware acts
        on REF's level and edges, which a repeat does not change (the UDP link repeats it
        against loss; here only an injected loss drops a datagram)."""
        ref, seq = self._ref_unsent, self._seq  # every tick: spelled out
        if ref is None and progressive:  # the firmware takes the PCMD's values as they are
            self._seq = seq + 1
            legs = self._legs
            # the chain written out, unless an injected AT loss decides this datagram's fate
            if legs is not None and (legs.takes_commands or legs.stands_in
                                     and not self.sim.faults.at_loss_acts(self.t_exp_s)):
                legs.command(seq + 1, float(roll_frac), float(pitch_frac), float(gaz_frac),
                             float(yaw_frac))  # at the plant's time
                return
            self.sim.execute_pcmd(seq + 1, (_PROGRESSIVE, float(roll_frac), float(pitch_frac),
                                            float(gaz_frac), float(yaw_frac)),
                                  self._plant_t_s(), self.t_exp_s)
            return
        pcmd = _exact_pcmd(roll_frac, pitch_frac, gaz_frac, yaw_frac) if progressive else _HOVER
        if ref is None:
            commands = (_Numbered(seq + 1, pcmd),)
        else:
            commands = (_Numbered(seq + 1, ref), _Numbered(seq + 2, pcmd))
        self._seq = seq + len(commands)
        if self.sim.execute_at(commands, self._plant_t_s(), self.t_exp_s):
            self._ref_unsent = None

    def hover(self) -> None:
        self.set_command(0.0, 0.0, 0.0, 0.0, progressive=False)

    def _hold(self, ref: Ref) -> None:
        self._ref = ref
        if self._send([ref, _HOVER]):
            self._ref_unsent = None
        else:  # lost (an injected AT loss): it goes with the next command
            self._ref_unsent = ref

    def _send(self, bodies: list[AtBody]) -> bool:
        seq = self._seq
        commands = [_Numbered(seq + i, body) for i, body in enumerate(bodies, start=1)]
        self._seq = seq + len(bodies)
        return self.sim.execute_at(commands, self._plant_t_s(), self.t_exp_s)

    def _plant_t_s(self) -> float:
        """The plant's time: the compiled legs' (without releasing the state they hold —
        a landing's REF, held every tick, would release it every tick)."""
        legs = self._legs
        return legs.t_s() if legs is not None else self.sim.plant.t_s

    # ------------------------------------------------------------------ configuration port
    def write_config(self, key, value, timeout_s: float = 1.0) -> str:
        """``AT*CONFIG`` (after ``AT*CONFIG_IDS`` if configured), acknowledged at once — or
        never, by a session that ignores plain CONFIG (LinkError, as the link's handshake
        times out)."""
        cfg = Config.of(key, value)
        bodies: list[AtBody] = [ConfigIds(*self.config_ids)] if self.config_ids else []
        counters = self.sim.counters
        unacknowledged = counters.config_writes_unacknowledged
        self._send([*bodies, cfg])
        if counters.config_writes_unacknowledged > unacknowledged:
            raise LinkError(f"config {key}={cfg.value!r}: no ACK from the drone (a multiconfig "
                            "session that ignores plain CONFIG: set drone.config_ids to it)")
        return cfg.value

    def read_config(self, timeout_s: float = 2.0) -> dict[str, str]:
        """The configuration dump, unless the control port does not answer."""
        mode = self.sim.control_port_mode
        if mode != "serve":
            raise LinkError(f"fault control_port_drop: {mode}, no configuration dump")
        return parse_config_text(self.sim.firmware.config.text())
