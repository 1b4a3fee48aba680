"""Fault injection (config section ``faults``, simulation only): when each fault is active, the
byte-level corruptions, and the plant-side faults.

Times are experiment times (s; 0 = the first tick after the settle phase). The simulated drone
(:class:`~ardrone_nmpc.sim.drone.SimulatedDrone`) asks a :class:`FaultSchedule` per sensor
frame, datagram or tick; the runners never do: the lockstep link feeds the faulted datagrams
through the real decoders and link logic (:mod:`ardrone_nmpc.sim.sensors`), ``fly --sim``
through the loopback servers. Randomness (duplicate/reorder/AT-loss draws) comes from one generator
seeded by the run's seed, so a faulted run is as reproducible as a clean one.

Firmware faults make the simulated drone behave like a real one a careless client trips over:
another firmware's ctrl_state codes (``ctrl_codes``), a drone left in another configuration
session (``foreign_session``), a control port that does not answer (``control_port_drop``),
stored indoor/outdoor profiles of a drone last flown outdoors (``outdoor_profile``), a
VBAT_LOW level above the tool's floor (``vbat_low``) — all from the start, before any
experiment time — a landing of its own (``self_land``, at a time; a take-off REF afterwards
launches it again), fault bits in its state word (``drone_faults``, at a time or from
power-on) and a Wi-Fi blackout (``blackout``: nothing passes either way). The firmware holds
the VBAT_LOW level and the fault bits (:class:`~ardrone_nmpc.sim.drone.SimulatedDrone` hands
them over).
"""

from __future__ import annotations

import math
import struct
from typing import Callable

import numpy as np

from ardrone_nmpc.protocol.navdata import HEADER_BYTES, OPTION_HEAD_BYTES, CtrlCodes, DroneState
from ardrone_nmpc.sim.drone_config import HeldSession, OutdoorProfiles

__all__ = ["Disorder", "FaultSchedule", "PlantFaults", "corrupt_navdata", "SENSOR_FAULTS",
           "PLANT_FAULTS", "LINK_FAULTS"]

#: Faults that act on the sensor datagrams (the lockstep runner then goes through the bytes).
#: The drone's own reports (state bits) exist only on the wire, so their faults are here too.
SENSOR_FAULTS = frozenset({"mocap_dropout", "mocap_occlusion", "mocap_latency",
                           "navdata_loss", "navdata_corrupt", "disorder", "ctrl_codes",
                           "drone_faults", "vbat_low", "blackout"})
#: Faults that act on the simulated drone itself.
PLANT_FAULTS = frozenset({"at_loss", "battery_floor", "emergency", "wind_gust", "wind",
                          "delay_jump", "self_land", "foreign_session", "outdoor_profile",
                          "drone_faults", "vbat_low", "blackout"})
#: Faults of the drone's configuration link (the TCP control port): the loopback drone serves
#: one; the lockstep runner reads its configuration store directly and takes this fault as
#: "no dump".
LINK_FAULTS = frozenset({"control_port_drop"})

_OPTION_HEAD = struct.Struct("<HH")


def _within(fault, t_s: float) -> bool:
    return fault is not None and fault.start_s <= t_s < fault.start_s + fault.duration_s


def corrupt_navdata(data: bytes, kind: str) -> bytes:
    """``data`` (a whole navdata packet) corrupted the way ``kind`` says.

    ``checksum``: the checksum value's last byte flipped; ``truncated``: the packet cut in
    half; ``zero_option``: the first option's size field set to 0 (a decoder that trusted it
    would loop for ever).
    """
    buf = bytearray(data)
    if kind == "checksum":
        buf[-1] ^= 0xFF
    elif kind == "truncated":
        del buf[len(buf) // 2:]
    elif kind == "zero_option":
        if len(buf) >= HEADER_BYTES + OPTION_HEAD_BYTES:
            tag, _ = _OPTION_HEAD.unpack_from(buf, HEADER_BYTES)
            _OPTION_HEAD.pack_into(buf, HEADER_BYTES, tag, 0)
    else:
        raise ValueError(f"unknown navdata corruption {kind!r}")
    return bytes(buf)


class Disorder:
    """Duplicates and holds back the datagrams of one stream.

    A held-back datagram goes out right after the next one (the two arrive swapped, as over a
    reordering network); while one is held, no second one is held.
    """

    def __init__(self) -> None:
        self._held: bytes | None = None

    @property
    def holding(self) -> bool:
        return self._held is not None

    def __call__(self, data: bytes, duplicate: bool, hold: bool) -> list[bytes]:
        """The datagrams to send now, in order, for ``data`` and the draws of its send time."""
        held, self._held = self._held, None
        out: list[bytes] = []
        if hold and held is None:
            self._held = data
        else:
            out.append(data)
            if held is not None:
                out.append(held)
        if duplicate:
            out.append(data)
        return out


class FaultSchedule:
    """Which faults of a :class:`~ardrone_nmpc.config.schema.FaultsConfig` act at a time.

    Parameters
    ----------
    faults : FaultsConfig.
    seed : seed of the fault draws (duplicates, reordering, AT loss).
    """

    def __init__(self, faults, seed: int = 0) -> None:
        self.cfg = faults
        self.active = frozenset(faults.active())
        self.rng = np.random.default_rng([int(seed), 0xFA17])

    @property
    def any(self) -> bool:
        return bool(self.active)

    @property
    def touches_sensors(self) -> bool:
        return bool(self.active & SENSOR_FAULTS)

    # ------------------------------------------------------------------ mocap
    def mocap_dropped(self, t_s: float) -> bool:
        """No mocap datagram sent at ``t_s`` (dropout burst, repeated if configured)."""
        f = self.cfg.mocap_dropout
        if f is None or t_s < f.start_s:
            return False
        phase = t_s - f.start_s
        if f.repeat_every_s is not None:
            phase = math.fmod(phase, f.repeat_every_s)
        return phase < f.duration_s

    def mocap_occlusion(self, t_s: float) -> str | None:
        """``"missing"`` or ``"zero"`` while the object is occluded at ``t_s``, else None."""
        f = self.cfg.mocap_occlusion
        if not _within(f, t_s):
            return None
        return "zero" if f.zero_pose else "missing"

    def mocap_extra_latency_s(self, t_s: float) -> float:
        """Latency added to a mocap datagram sent at ``t_s`` (s)."""
        f = self.cfg.mocap_latency
        return f.extra_latency_ms * 1e-3 if _within(f, t_s) else 0.0

    # ------------------------------------------------------------------ navdata
    def navdata_lost(self, t_s: float) -> bool:
        return _within(self.cfg.navdata_loss, t_s) or self.blackout(t_s)

    def blackout(self, t_s: float) -> bool:
        """Nothing passes either way at ``t_s`` (a Wi-Fi blackout)."""
        return _within(self.cfg.blackout, t_s)

    def navdata_corruption(self, t_s: float) -> str | None:
        f = self.cfg.navdata_corrupt
        return f.kind if _within(f, t_s) else None

    # ------------------------------------------------------------------ both streams
    def disorder(self, stream: str, t_s: float) -> tuple[bool, bool]:
        """``(duplicate, hold_back)`` draws for a datagram of ``stream`` sent at ``t_s``."""
        f = self.cfg.disorder
        if f is None or f.stream != stream or not _within(f, t_s):
            return False, False
        draw = self.rng.random(2)
        return bool(draw[0] < f.duplicate_probability), bool(draw[1] < f.reorder_probability)

    # ------------------------------------------------------------------ the drone
    def at_lost(self, t_s: float) -> bool:
        """The AT datagram of the tick at ``t_s`` never reaches the drone."""
        if self.blackout(t_s):
            return True
        f = self.cfg.at_loss
        return _within(f, t_s) and bool(self.rng.random() < f.probability)

    def at_loss_acts(self, t_s: float) -> bool:
        """:meth:`at_lost` at ``t_s`` decides (a draw, a blackout): outside, it answers False
        and draws nothing."""
        return self.blackout(t_s) or _within(self.cfg.at_loss, t_s)

    def window_spans(self, repeated: bool = True) -> list[tuple[float, float]]:
        """``(start_s, end_s)`` of every fault that acts over a window (the sensors', AT
        loss, blackout, a gust, the solver's; a repeated dropout ends never — left out if
        not ``repeated``: its bursts are :meth:`mocap_dropped`'s alone) — the one-shot faults
        are :meth:`plant_events`, the others act for the whole flight."""
        return [(start, end) for name, start, end in self.windows()
                if hasattr(getattr(self.cfg, name), "duration_s")
                and (repeated or not self.repeats(name))]

    def repeats(self, name: str) -> bool:
        """The fault ``name`` acts in bursts for ever (a repeated mocap dropout)."""
        return name == "mocap_dropout" and self.cfg.mocap_dropout.repeat_every_s is not None

    def solver_diverges(self, t_s: float) -> bool:
        """The NMPC solution of the tick at ``t_s`` is replaced by a diverged, non-finite one
        (the tick's control stage asks, :class:`~ardrone_nmpc.runtime.stages.Control`)."""
        return _within(self.cfg.solver_diverge, t_s)

    @property
    def solver_divergence(self) -> Callable[[float], bool] | None:
        """:meth:`solver_diverges`, or None when no divergence is configured (nothing for a
        simulating runner to wrap its solver with)."""
        return None if self.cfg.solver_diverge is None else self.solver_diverges

    def wind_mps(self, t_s: float) -> np.ndarray:
        """Air velocity at ``t_s``: the constant wind plus a gust in its window (m/s)."""
        w = np.zeros(3)
        if self.cfg.wind is not None:
            w += self.cfg.wind.velocity_mps
        if _within(self.cfg.wind_gust, t_s):
            w += self.cfg.wind_gust.velocity_mps
        return w

    def plant_events(self) -> list[tuple[float, str, float]]:
        """One-shot plant faults ``(t_s, kind, value)``, in time order."""
        out = []
        c = self.cfg
        if c.battery_floor is not None:
            out.append((c.battery_floor.start_s, "battery", c.battery_floor.level_pct))
        if c.emergency is not None:
            out.append((c.emergency.start_s, "emergency", math.nan))
        if c.delay_jump is not None:
            out.append((c.delay_jump.start_s, "delay", c.delay_jump.delay_s))
        if c.self_land is not None:
            out.append((c.self_land.start_s, "self_land", math.nan))
        if c.drone_faults is not None and c.drone_faults.start_s is not None:
            out.append((c.drone_faults.start_s, "drone_faults", self.drone_fault_bits()))
        return sorted(out)

    def drone_fault_bits(self) -> int:
        """The state bits of the ``drone_faults`` fault (0 without one)."""
        f = self.cfg.drone_faults
        return 0 if f is None else sum(int(DroneState[name]) for name in set(f.bits))

    def power_on_fault_bits(self) -> int:
        """The state bits the drone reports from power-on (``drone_faults`` without a start)."""
        f = self.cfg.drone_faults
        return self.drone_fault_bits() if f is not None and f.start_s is None else 0

    def vbat_low_pct(self) -> float | None:
        """The firmware's VBAT_LOW level (%) of the ``vbat_low`` fault, or None."""
        f = self.cfg.vbat_low
        return None if f is None else f.threshold_pct

    def outdoor_profiles(self) -> OutdoorProfiles | None:
        """The profiles of a drone last flown outdoors (from the start), or None."""
        f = self.cfg.outdoor_profile
        return None if f is None else OutdoorProfiles.of_fault(f)

    # ------------------------------------------------------------------ the firmware
    def ctrl_codes(self) -> CtrlCodes:
        """The ctrl_state transition codes the drone's navdata reports."""
        f = self.cfg.ctrl_codes
        return CtrlCodes.SDK if f is None else CtrlCodes(f.codes)

    def held_session(self) -> HeldSession | None:
        """The multiconfig session the drone was left in (from the start), or None."""
        f = self.cfg.foreign_session
        return None if f is None else HeldSession.of_fault(f)

    def control_port_mode(self) -> str:
        """"serve", or how the control port fails to answer ("silent", "refused")."""
        f = self.cfg.control_port_drop
        return "serve" if f is None else f.mode

    def windows(self) -> list[tuple[str, float, float]]:
        """``(name, start_s, end_s)`` of every configured fault (end inf for one-shot ones and
        the constant wind), for reports and the fault matrix."""
        out = []
        for name in sorted(self.active):
            f = getattr(self.cfg, name)
            start = getattr(f, "start_s", None)
            start = -math.inf if start is None else start  # (fault bits from power-on)
            duration = getattr(f, "duration_s", math.inf)
            if self.repeats(name):
                duration = math.inf
            out.append((name, start, start + duration))
        return out


class PlantFaults:
    """Applies a schedule's plant-side faults to an
    :class:`~ardrone_nmpc.sim.plant.AirframePlant` as experiment time passes.

    ``update(t_s)`` returns the events of faults that started (``{"kind": "fault", …}``);
    fault bits that start are announced here and reported by the firmware
    (:meth:`~ardrone_nmpc.sim.drone.SimulatedDrone.update_faults`).
    (A drone left in another configuration session is the firmware's configuration store's:
    :meth:`FaultSchedule.held_session`.)
    """

    def __init__(self, schedule: FaultSchedule, plant) -> None:
        self.schedule = schedule
        self.plant = plant
        self._pending = schedule.plant_events()
        self._gust_on = False

    def next_due_s(self) -> float:
        """When :meth:`update` next changes anything but the wind's array: the first one-shot
        fault's time (inf: none left); −inf while a gust blows (its end is due)."""
        if self._gust_on:
            return -math.inf
        return self._pending[0][0] if self._pending else math.inf

    def update(self, t_s: float) -> list[dict]:
        events = []
        plant, sched = self.plant, self.schedule
        while self._pending and self._pending[0][0] <= t_s:
            _, kind, value = self._pending.pop(0)
            if kind == "battery":
                plant.set_battery_pct(value)
                events.append({"kind": "fault", "fault": "battery_floor", "level_pct": value})
            elif kind == "emergency":
                plant.emergency()
                events.append({"kind": "fault", "fault": "emergency"})
            elif kind == "delay":
                plant.set_command_delay_s(value)
                events.append({"kind": "fault", "fault": "delay_jump", "delay_s": value})
            elif kind == "self_land":   # the firmware's own decision: through landing
                events.append({"kind": "fault", "fault": "self_land",
                               "accepted": plant.land()})
            elif kind == "drone_faults":
                events.append({"kind": "fault", "fault": "drone_faults",
                               "bits": sorted(self.schedule.cfg.drone_faults.bits)})
        plant.wind_mps = sched.wind_mps(t_s)
        gust = _within(sched.cfg.wind_gust, t_s)
        if gust != self._gust_on:
            self._gust_on = gust
            events.append({"kind": "fault", "fault": "wind_gust", "on": gust})
        return events
