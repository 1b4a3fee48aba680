"""The simulated AR.Drone as one object: plant + firmware + injected faults.

Both runners fly this same drone. ``simulate`` advances it in lockstep through
:class:`~ardrone_nmpc.sim.lockstep_drone.LockstepDrone` — the interface of the drone's link on
a manual clock; ``fly --sim`` serves it over UDP: the
:class:`~ardrone_nmpc.sim.drone_server.DroneServer` hands it the AT datagrams and sends its
navdata, the :class:`~ardrone_nmpc.sim.mocap_server.MocapServer` streams its pose. So the
firmware's rules — altitude cap, watchdogs, REF semantics, the configuration store
(:class:`~ardrone_nmpc.sim.drone_firmware.DroneFirmware`) — and the fault decisions
(:class:`~ardrone_nmpc.sim.fault_injection.ServerFaults`) exist once and hold in both — also
what a real drone reports about itself (fault bits, VBAT_LOW at its own level, bootstrap after a
link loss, a session that ignores plain CONFIG, indoor/outdoor profiles, a Wi-Fi blackout).

Not thread-safe by itself: the servers call it under their shared lock.
"""

from __future__ import annotations

import math
from typing import Callable

from ardrone_nmpc.sim.backends import make_plant
from ardrone_nmpc.sim.drone_firmware import DroneFirmware, DroneServerCounters
from ardrone_nmpc.sim.fault_injection import ServerFaults
from ardrone_nmpc.sim.faults import FaultSchedule

__all__ = ["SimulatedDrone"]


class SimulatedDrone:
    """A plant with its firmware and its injected faults (module docstring).

    Parameters
    ----------
    plant : the airframe (:func:`~ardrone_nmpc.sim.backends.make_plant`).
    faults : the injected faults (None: none).
    control_port_mode : "serve", or how the control port fails to answer ("silent",
        "refused").
    counters : the traffic counters to update (a new set by default).
    firmware_options : :class:`DroneFirmware` keyword arguments (watchdog times, ctrl_state
        codes, the altitude cap, a held configuration session …).
    """

    def __init__(self, plant, *, faults: ServerFaults | None = None,
                 control_port_mode: str = "serve", counters: DroneServerCounters | None = None,
                 **firmware_options) -> None:
        self.plant = plant
        self.faults = faults
        self.control_port_mode = control_port_mode
        self.counters = counters if counters is not None else DroneServerCounters()
        self.firmware = DroneFirmware(plant, counters=self.counters, **firmware_options)

    @classmethod
    def from_config(cls, cfg, *, seed: int | None = None, plant=None,
                    **firmware_options) -> SimulatedDrone:
        """The drone of an experiment: the plant of its ``sim`` and ``drone`` sections (seeded
        by ``seed``, default ``sim.seed``; or ``plant``, another airframe with
        :class:`~ardrone_nmpc.sim.plant.AirframePlant`'s interface landed at time 0, such as
        the tests' emulators), the altitude cap it is configured with, and the
        ``faults`` — the firmware's own (ctrl_state codes, a configuration session left by
        another application, a control port that does not answer, the profiles of a drone
        last flown outdoors, its VBAT_LOW level, fault bits from power-on) from the start, a
        constant wind blowing from the start, the others on the experiment clock."""
        seed = cfg.sim.seed if seed is None else int(seed)
        plant = make_plant(cfg.sim, cfg.drone, seed=seed) if plant is None else plant
        schedule = FaultSchedule(cfg.faults, seed)
        plant.wind_mps = schedule.wind_mps(-math.inf)
        options = {"altitude_max_m": cfg.drone.altitude_max_m,
                   "ctrl_codes": schedule.ctrl_codes(), "session": schedule.held_session(),
                   "outdoor": schedule.outdoor_profiles(),
                   "fault_bits": schedule.power_on_fault_bits()}
        if schedule.vbat_low_pct() is not None:
            options["vbat_low_pct"] = schedule.vbat_low_pct()
        options.update(firmware_options)
        faults = ServerFaults(schedule, plant) if schedule.any else None
        return cls(plant, faults=faults, control_port_mode=schedule.control_port_mode(),
                   **options)

    # ------------------------------------------------------------------ the experiment clock
    def start_experiment(self, t0_s: float) -> list[dict]:
        """Experiment time 0 is ``t0_s`` on the faults' clock; returns the events that announce
        what is injected (``{"kind": "faults", "windows": …}``; none without faults)."""
        if self.faults is None:
            return []
        self.faults.set_clock(t0_s)
        windows = [list(w) for w in self.faults.schedule.windows()]
        return [{"kind": "faults", "windows": windows}]

    def take_events(self) -> list[tuple[float, dict]]:
        """``(experiment time s, event)`` of the injected faults that started since the last
        call, in order."""
        return [] if self.faults is None else self.faults.take_events()

    @property
    def solver_divergence(self) -> Callable[[float], bool] | None:
        """When the ground station's solver is made to diverge — ``faults.solver_diverge``, a
        predicate of experiment time that a simulating runner wraps its solver with — or None
        if it never is."""
        return None if self.faults is None else self.faults.schedule.solver_divergence

    # ------------------------------------------------------------------ time passing
    def advance(self, dt_s: float, now_s: float) -> None:
        """The plant faults due at ``now_s``, then ``dt_s`` of physics and the firmware's
        watchdogs and altitude cap (the servers' physics step)."""
        self.update_faults(now_s)
        self.firmware.advance(dt_s, now_s)

    def update_faults(self, fault_t_s: float) -> None:
        """The plant faults due at ``fault_t_s`` (the faults' clock) act; fault bits that
        start go into the firmware's state word."""
        if self.faults is None:
            return
        for event in self.faults.update_plant(fault_t_s):
            if event.get("fault") == "drone_faults":
                self.firmware.fault_bits |= self.faults.schedule.drone_fault_bits()

    # ------------------------------------------------------------------ AT commands in
    def receive_at(self, data: bytes, now_s: float) -> bool:
        """One AT datagram arriving at ``now_s``; False if an injected loss discarded it (no
        traffic for the drone's watchdogs either)."""
        if self._at_lost(now_s):
            return False
        self.firmware.receive(data, now_s)
        return True

    def execute_at(self, commands, now_s: float, fault_t_s: float) -> bool:
        """One datagram's decoded commands (the lockstep link: no bytes, so no float32
        rounding) at firmware time ``now_s``; ``fault_t_s`` is the faults' clock. False if an
        injected loss discarded it."""
        if self._at_lost(fault_t_s):
            return False
        self.counters.at_datagrams_in += 1
        self.firmware.execute_datagram(commands, now_s)
        return True

    def execute_pcmd(self, seq: int, pcmd: tuple, now_s: float, fault_t_s: float) -> bool:
        """:meth:`execute_at` of a datagram of one progressive PCMD (``seq``, ``(flags,
        roll, pitch, gaz, yaw)``: :meth:`DroneFirmware.execute_pcmd`)."""
        if self._at_lost(fault_t_s):
            return False
        self.counters.at_datagrams_in += 1
        self.firmware.execute_pcmd(seq, pcmd, now_s)
        return True

    def wakeup_lost(self, now_s: float) -> bool:
        """A datagram on the navdata port at ``now_s`` never reaches the drone (a blackout)."""
        return self.faults is not None and self.faults.wakeup_lost(now_s)

    def _at_lost(self, fault_t_s: float) -> bool:
        if self.faults is not None and self.faults.at_lost(fault_t_s):
            self.counters.at_datagrams_lost += 1
            return True
        return False

    # ------------------------------------------------------------------ navdata out
    def navdata_datagrams(self, now_s: float, fault_t_s: float | None = None) -> list[bytes]:
        """The datagrams of the navdata packet due at ``now_s`` (none if it is lost: its
        sequence number passes all the same), corrupted, duplicated or held back as the
        faults say (``fault_t_s``: their clock, default ``now_s``)."""
        faults = self.faults
        t = now_s if fault_t_s is None else fault_t_s
        if faults is not None and faults.navdata_lost(t):
            self.firmware.skip_packet()
            return []
        packet = self.firmware.packet(now_s)
        return [packet] if faults is None else faults.navdata_datagrams(t, packet)
