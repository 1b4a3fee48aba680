"""Injected faults of the simulators (``faults:`` section): one optional window per fault."""

from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field

from ardrone_nmpc.config.fields import Finite, NonNegative, Positive, Section, Vec3

__all__ = ["FaultsConfig"]


class _FaultWindow(Section):
    """A fault active from ``start_s`` for ``duration_s`` (experiment time: 0 = the end of the
    settle phase, the first tick of the experiment)."""

    start_s: Finite = Field(5.0, description="When the fault starts (s, experiment time).")
    duration_s: Positive = Field(1.0, description="How long it lasts (s).")


class MocapDropoutFault(_FaultWindow):
    """No mocap datagram arrives (network loss or tracker stall)."""

    repeat_every_s: Optional[Positive] = Field(
        None, description="Repeat the burst with this period (s) until the end; null = once.")


class MocapOcclusionFault(_FaultWindow):
    """Datagrams arrive but the object is missing (markers occluded) or its pose is zero."""

    zero_pose: bool = Field(False, description="Send an all-zero pose instead of omitting it.")


class MocapLatencyFault(_FaultWindow):
    """Mocap datagrams sent during the window arrive ``extra_latency_ms`` late."""

    extra_latency_ms: Positive = Field(200.0, description="Added latency (ms).")


class NavdataLossFault(_FaultWindow):
    """No navdata arrives."""


class NavdataCorruptFault(_FaultWindow):
    """Every navdata packet of the window is corrupted on the wire."""

    kind: Literal["checksum", "truncated", "zero_option"] = Field(
        "checksum", description="Bad checksum, truncated packet, or an option of size 0.")


class DisorderFault(_FaultWindow):
    """Datagrams of one stream duplicated and reordered (swapped with the next)."""

    stream: Literal["mocap", "navdata"] = Field("mocap", description="Which stream.")
    duplicate_probability: float = Field(0.3, ge=0, le=1, description="Chance a datagram is sent twice.")
    reorder_probability: float = Field(0.3, ge=0, le=1, description="Chance a datagram is held back behind the next.")


class AtLossFault(_FaultWindow):
    """AT datagrams lost before the drone: it flies its last command until the firmware's
    watchdog, 250 ms after the last one that arrived, drops it for hover."""

    probability: float = Field(1.0, gt=0, le=1, description="Chance each command is lost.")


class SolverDivergeFault(_FaultWindow):
    """The NMPC returns a diverged, non-finite solution every tick of the window."""


class BatteryFloorFault(Section):
    """The battery drops to ``level_pct`` at ``start_s``."""

    start_s: Finite = Field(5.0, description="When (s, experiment time).")
    level_pct: float = Field(19.0, ge=0, le=100, description="Battery level it drops to (%).")


class EmergencyFault(Section):
    """The drone raises its emergency state (motors cut) at ``start_s``."""

    start_s: Finite = Field(5.0, description="When (s, experiment time).")


class WindGustFault(_FaultWindow):
    """Air moving at ``velocity_mps`` (world frame) during the window; drag pushes the drone."""

    velocity_mps: Vec3 = Field((1.5, 0.0, 0.0), description="Gust air velocity [x, y, z] (m/s).")


class WindFault(Section):
    """Constant wind for the whole flight (take-off included)."""

    velocity_mps: Vec3 = Field((0.5, 0.0, 0.0), description="Air velocity [x, y, z] (m/s).")


class DelayJumpFault(Section):
    """The command transport delay jumps to ``delay_s`` at ``start_s``."""

    start_s: Finite = Field(5.0, description="When (s, experiment time).")
    delay_s: NonNegative = Field(0.5, le=2.0, description="New command delay (s).")


class ForeignSessionFault(Section):
    """The drone was left in another multiconfig session: writes of per-session keys (the
    command limits) without that session's ``AT*CONFIG_IDS`` are acknowledged but not applied;
    it flies, and reports on the control port, the limits it holds."""

    session_id: str = Field("d2e081a3", pattern=r"^[0-9a-fA-F]{8}$", description="Its session id.")
    profile_id: str = Field("be27e2e4", pattern=r"^[0-9a-fA-F]{8}$", description="Its profile id.")
    application_id: str = Field("d87f7e0c", pattern=r"^[0-9a-fA-F]{8}$", description="Its application id.")
    euler_angle_max_rad: float = Field(0.52, gt=0, le=0.52, description="Tilt limit it holds (rad).")
    control_vz_max_mps: float = Field(2.0, ge=0.2, le=2.0, description="Climb-rate limit it holds (m/s).")
    control_yaw_radps: float = Field(6.11, ge=0.7, le=6.11, description="Yaw-rate limit it holds (rad/s).")


class SelfLandFault(Section):
    """The drone lands by itself at ``start_s`` (motor cut-out, low battery, a firmware
    decision); a REF still asking for take-off launches it again, as the firmware does."""

    start_s: Finite = Field(5.0, description="When (s, experiment time).")


class CtrlCodesFault(Section):
    """Navdata reports another firmware's ctrl_state transition codes."""

    codes: Literal["sdk", "fw2.4"] = Field(
        "fw2.4", description="'fw2.4': take-off 7, landing 9; 'sdk': 6, 8 (control_states.h).")


class ControlPortDropFault(Section):
    """The drone's TCP control port (configuration read-back) does not answer."""

    mode: Literal["silent", "refused"] = Field(
        "silent", description="'silent': connections accepted, no configuration ever sent; "
        "'refused': nothing listens.")


class FaultsConfig(Section):
    """Injected faults (simulation only: ``simulate`` and ``fly --sim``); each is off (null)
    unless given, e.g. ``--set faults.mocap_dropout.start_s=5``."""

    mocap_dropout: Optional[MocapDropoutFault] = Field(None, description="Mocap dropout bursts.")
    mocap_occlusion: Optional[MocapOcclusionFault] = Field(None, description="Object occluded.")
    mocap_latency: Optional[MocapLatencyFault] = Field(None, description="Mocap latency spike.")
    navdata_loss: Optional[NavdataLossFault] = Field(None, description="Navdata lost.")
    navdata_corrupt: Optional[NavdataCorruptFault] = Field(None, description="Navdata corrupted.")
    disorder: Optional[DisorderFault] = Field(None, description="Duplicated/reordered datagrams.")
    at_loss: Optional[AtLossFault] = Field(None, description="AT commands lost (drone side).")
    solver_diverge: Optional[SolverDivergeFault] = Field(None, description="Solver forced to diverge.")
    battery_floor: Optional[BatteryFloorFault] = Field(None, description="Battery at the floor.")
    emergency: Optional[EmergencyFault] = Field(None, description="Emergency triggered.")
    wind_gust: Optional[WindGustFault] = Field(None, description="Wind gust on the plant.")
    wind: Optional[WindFault] = Field(None, description="Constant wind on the plant.")
    delay_jump: Optional[DelayJumpFault] = Field(None, description="Command-delay jump.")
    foreign_session: Optional[ForeignSessionFault] = Field(None, description="Drone in another config session.")
    self_land: Optional[SelfLandFault] = Field(None, description="Drone lands by itself.")
    ctrl_codes: Optional[CtrlCodesFault] = Field(None, description="Other firmware's ctrl_state codes.")
    control_port_drop: Optional[ControlPortDropFault] = Field(None, description="Control port does not answer.")

    def active(self) -> list[str]:
        """Names of the faults that are set."""
        return [name for name in type(self).model_fields if getattr(self, name) is not None]
