"""A flight session: connect → preflight → take off (``__enter__``) … land (``__exit__``).

Landing is structure, not the caller's job: leaving the ``with`` block for any reason — the
end of the experiment, Ctrl-C, an exception, a lost link — lands the drone and waits until
navdata shows it on the ground (or the attempts run out, which is reported, never hidden).
"""

from __future__ import annotations

import math
import time
from typing import Callable

from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.runtime.schedule import LANDING_TIMEOUT_S, TAKEOFF_TIMEOUT_S
from ardrone_nmpc.errors import UserError


class PreflightError(UserError, RuntimeError):
    """A preflight check failed: the drone did not take off."""


class FlightSession:
    """Owns take-off and landing of one experiment.

    Parameters
    ----------
    cfg : ExperimentConfig (``drone`` limits, ``safety`` floors).
    drone : a connected-or-connectable :class:`~ardrone_nmpc.links.drone_link.DroneLink`.
    mocap : a running :class:`~ardrone_nmpc.links.mocap_source.MocapSource`.
    event : ``event(kind, **fields)`` sink for the run's events.jsonl.
    clock : monotonic seconds.
    """

    TAKEOFF_TIMEOUT_S, LANDING_TIMEOUT_S = TAKEOFF_TIMEOUT_S, LANDING_TIMEOUT_S

    def __init__(self, cfg, drone, mocap, *, event: Callable[..., None],
                 clock: Callable[[], float] = time.monotonic):
        self.cfg = cfg
        self.drone = drone
        self.mocap = mocap
        self.event = event
        self.clock = clock
        self.landed_cleanly: bool | None = None

    # -- entering: connect, preflight, take off ------------------------------------------
    def __enter__(self) -> "FlightSession":
        d = self.cfg.drone
        self.drone.connect(timeout_s=5.0)
        written = self.drone.configure_limits(
            euler_angle_max_rad=d.euler_angle_max_rad, control_vz_max_mps=d.control_vz_max_mps,
            control_yaw_radps=d.control_yaw_radps, altitude_max_m=d.altitude_max_m)
        self.event("config_written", **{str(k): v for k, v in dict(written).items()})
        try:  # read back what the drone now holds (control port): logged, not trusted blindly
            held = self.drone.read_config(timeout_s=2.0)
            self.event("config_read", **{k: held.get(k) for k in written})
        except Exception as err:  # noqa: BLE001 - a drone without the port still flies
            self.event("config_read_failed", error=str(err))
        try:
            self.preflight()
            self.drone.flat_trim()
            self.drone.takeoff()
            self.event("takeoff")
            self._wait_for(lambda m: m is FlightMode.FLYING, self.TAKEOFF_TIMEOUT_S, "take-off")
        except BaseException:
            self.land()  # whatever went wrong after the motors may have started
            raise
        return self

    def preflight(self) -> None:
        """Navdata flowing, not in emergency, battery above the floor, mocap object visible."""
        nav = self._wait_navdata(2.0)
        if nav.mode is FlightMode.EMERGENCY:
            raise PreflightError("drone in emergency: reset it before flying")
        if nav.mode is not FlightMode.LANDED:
            raise PreflightError(f"drone not landed (mode {nav.mode.value}): refusing take-off")
        floor = self.cfg.safety.battery_floor_pct
        if not nav.battery_pct > floor:
            raise PreflightError(f"battery {nav.battery_pct:.0f} % at or below the floor "
                                 f"({floor:.0f} %, safety.battery_floor_pct)")
        deadline = self.clock() + 2.0
        while True:
            pose, rx_t = self.mocap.latest()
            age_ms = (self.clock() - rx_t) * 1e3 if pose is not None else math.inf
            if age_ms <= self.cfg.safety.mocap_hover_ms:
                break
            if self.clock() > deadline:
                raise PreflightError(
                    f"mocap object {self.cfg.mocap.object_name!r} not visible from "
                    f"{self.mocap.where} (last pose age {age_ms:.0f} ms)")
            time.sleep(0.02)
        self.event("preflight_ok", battery_pct=nav.battery_pct)

    # -- leaving: land, always ------------------------------------------------------------
    def __exit__(self, exc_type, exc, tb) -> bool:
        reason = "end" if exc_type is None else exc_type.__name__
        try:
            self.event("landing", reason=reason)
        finally:  # a failing log (disk full) must not keep the drone in the air
            self.land()
        return False  # never swallow the exception

    def land(self) -> bool:
        """Command landing until navdata shows the drone landed; True if it did in time.

        Interrupts (Ctrl-C, SIGTERM) arriving meanwhile do not stop the landing: the first is
        re-raised once the drone is down or the landing timed out.
        """
        interrupt: BaseException | None = None
        deadline = self.clock() + self.LANDING_TIMEOUT_S
        while self.landed_cleanly is not True:
            try:
                self.drone.land()  # the link also drops the flight command to hover
                self._wait_for(lambda m: m in (FlightMode.LANDED, FlightMode.EMERGENCY),
                               max(deadline - self.clock(), 0.0), "landing",
                               resend=self.drone.land)
                self.landed_cleanly = True
                self.event("landed")
            except KeyboardInterrupt as err:  # Ctrl-C or SIGTERM: keep landing
                interrupt = interrupt or err
                if self.clock() > deadline:
                    self.landed_cleanly = False
                    break
            except Exception as err:  # noqa: BLE001 - reported; the caller's exception wins
                self.landed_cleanly = False
                self.event("landing_failed", error=str(err) or type(err).__name__)
                break
        if interrupt is not None:
            raise interrupt
        return bool(self.landed_cleanly)

    # -- helpers --------------------------------------------------------------------------
    def _wait_navdata(self, timeout_s: float):
        deadline = self.clock() + timeout_s
        while self.drone.navdata is None:
            if self.clock() > deadline:
                raise PreflightError("no navdata from the drone")
            time.sleep(0.02)
        return self.drone.navdata

    def _wait_for(self, done, timeout_s: float, what: str, resend=None) -> None:
        deadline = self.clock() + timeout_s
        next_resend = self.clock() + 1.0
        while True:
            nav = self.drone.navdata
            if nav is not None and done(nav.mode):
                return
            if self.clock() > deadline:
                mode = nav.mode.value if nav is not None else "no navdata"
                raise RuntimeError(f"{what} did not complete in {timeout_s:.0f} s ({mode})")
            if resend is not None and self.clock() > next_resend:
                resend()
                next_resend += 1.0
            time.sleep(0.02)
