"""Small shared records and the named indices of the state and input vectors.

State ``x = [x, ẋ, y, ẏ, z, ż, ψ]`` (m, m/s, m, m/s, m, m/s, rad) and input
``u = [z̈, φ, θ, ψ̇]`` (m/s², rad, rad, rad/s), exactly as thesis eq. 3.10–3.11.
"""

from __future__ import annotations

from dataclasses import MISSING, dataclass, fields

# State indices (thesis x1..x7, zero-based).
IX_X, IX_VX, IX_Y, IX_VY, IX_Z, IX_VZ, IX_PSI = range(7)
STATE_DIM = 7
STATE_NAMES = ("x_m", "vx_mps", "y_m", "vy_mps", "z_m", "vz_mps", "psi_rad")

# Input indices (thesis u1..u4, zero-based).
IU_ZACC, IU_PHI, IU_THETA, IU_PSIRATE = range(4)
INPUT_DIM = 4
INPUT_NAMES = ("u_zacc_mps2", "u_phi_rad", "u_theta_rad", "u_psirate_radps")

GRAVITY_MPS2 = 9.81


class _Factory:
    """The default of a field with a ``default_factory`` (shown as the dataclass shows it)."""

    def __repr__(self) -> str:
        return "<factory>"


_FACTORY = _Factory()


_set_class = object.__dict__["__class__"].__set__  # ``object.__setattr__(o, "__class__", t)``


def slot_init(cls):
    """``cls`` (a frozen slotted dataclass) with a faster ``__init__`` (these records are built
    several times a lockstep tick, issue 26): the dataclass's sets each field by a looked-up
    ``object.__setattr__`` call. This one turns the new record, for the time of its
    ``__init__``, into an instance of a plain twin class with the same slots (the same memory
    layout, which CPython checks at each ``__class__`` assignment), whose ``self.name = value``
    are the interpreter's specialised slot stores, and then back into ``cls`` (NavdataSample:
    ~340 ns, against ~500 by one slot-descriptor call a field, ~3× that by the dataclass's own
    ``__init__``). A subclass's record
    (its layout may differ) is set field by field through the slots' descriptors. The same
    parameters and defaults (a ``default_factory`` called for each record left without a
    value); equality, hash, repr, ``dataclasses.replace``, pickling and the frozen
    ``__setattr__`` are the dataclass's.

    ``cls.make`` (the twin class itself, whose ``__init__`` ends by turning its instance into
    a ``cls``) builds the very same record from the same arguments with neither the subclass
    test nor the first class change (NavdataSample ~260 ns): for the callers that build one
    each lockstep tick."""
    if cls.__bases__ != (object,) or tuple(cls.__slots__) != tuple(f.name for f in fields(cls)):
        raise TypeError(f"{cls.__name__}: slot_init wants a slotted dataclass with no base")
    if "make" in cls.__slots__:
        raise TypeError(f"{cls.__name__}.make: a field would hide slot_init's constructor")
    twin = type(f"_{cls.__name__}Unfrozen", (), {"__slots__": cls.__slots__,
                                                 "__module__": cls.__module__})
    params, ns = [], {"_FACTORY": _FACTORY, "_cls": cls, "_twin": twin, "_set_class": _set_class}
    by_descriptor = fast = ""
    for f in fields(cls):
        if not f.init or hasattr(cls, "__post_init__"):
            raise TypeError(f"{cls.__name__}.{f.name}: needs the dataclass's own __init__")
        ns[f"_set_{f.name}"] = cls.__dict__[f.name].__set__  # the slot's member descriptor
        value = f.name
        if f.default_factory is not MISSING:
            ns[f"_factory_{f.name}"] = f.default_factory
            params.append(f"{f.name}=_FACTORY")
            value = f"_factory_{f.name}() if {f.name} is _FACTORY else {f.name}"
        elif f.default is MISSING:
            params.append(f.name)
        else:
            ns[f"_default_{f.name}"] = f.default
            params.append(f"{f.name}=_default_{f.name}")
        by_descriptor += f"        _set_{f.name}(self, {value})\n"
        fast += f"    self.{f.name} = {value}\n"
    signature = f"(self, {', '.join(params)}):\n"
    exec(f"def __init__{signature}"  # noqa: S102 - our names
         f"    if type(self) is not _cls:\n{by_descriptor}        return\n"
         f"    _set_class(self, _twin)\n{fast}    self.__class__ = _cls\n"
         f"def _twin_init{signature}{fast}    self.__class__ = _cls\n", ns)
    for owner, name, init in ((cls, cls.__qualname__, ns["__init__"]),
                              (twin, f"{cls.__qualname__}.make", ns["_twin_init"])):
        init.__name__, init.__qualname__ = "__init__", f"{name}.__init__"
        init.__module__ = cls.__module__
        init.__annotations__ = {f.name: f.type for f in fields(cls)} | {"return": None}
        owner.__init__ = init
    twin.__qualname__ = f"{cls.__qualname__}.make"
    cls.make = twin
    return cls


@slot_init
@dataclass(frozen=True, slots=True)
class AttitudeCommand:
    """What a high-level controller asks of the drone's inner loops for one tick.

    Attributes
    ----------
    vz_ref_mps : vertical-speed reference (m/s), up positive.
    phi_rad : roll reference (rad); positive accelerates towards −y at ψ = 0.
    theta_rad : pitch reference (rad); positive accelerates towards +x at ψ = 0.
    psirate_radps : yaw-rate reference (rad/s), counter-clockwise seen from above.
    """

    vz_ref_mps: float
    phi_rad: float
    theta_rad: float
    psirate_radps: float


# ----------------------------------------------------------------------------- flight records
# Produced by the simulated plant (sim/plant.py) and, on real hardware, by the links; consumed
# by the estimator, the supervisor and the recorder. Vectors are read-only float64 arrays, so
# the records compare by identity (``eq=False``): compare fields with numpy instead.

import enum as _enum
import math as _math

import numpy as _np


class FlightMode(_enum.Enum):
    """The drone's flight state as the ground station sees it (docs/protocol.md §4.5, §5)."""

    LANDED = "landed"          # on the ground, motors off; PCMD ignored
    TAKING_OFF = "taking_off"  # automatic climb to the take-off height; PCMD ignored
    FLYING = "flying"          # airborne, following PCMD (or hovering with the flag at 0)
    LANDING = "landing"        # automatic descent to the ground; PCMD ignored
    EMERGENCY = "emergency"    # motors cut (falls, then lies on the ground) until reset

    @property
    def airborne(self) -> bool:
        """True while the motors run (take-off, flying, landing)."""
        return self in (FlightMode.TAKING_OFF, FlightMode.FLYING, FlightMode.LANDING)


@slot_init
@dataclass(frozen=True, slots=True, eq=False)
class PlantTruth:
    """The simulated drone's true state (world frame, docs/design.md §4).

    Attributes
    ----------
    t_s : plant time (s).
    position_m : (3,) [x, y, z] (m); x forward, y left, z up.
    velocity_mps : (3,) world velocity [ẋ, ẏ, ż] (m/s).
    roll_rad : roll φ (rad), model convention of thesis eq. 3.13: φ > 0 accelerates towards −y
        at ψ = 0 (right wing down; the same sign as PCMD roll).
    pitch_rad : pitch θ (rad), model convention: θ > 0 accelerates towards +x at ψ = 0 (nose
        down; the opposite sign of PCMD pitch and of navdata theta).
    psi_rad : heading ψ (rad), counter-clockwise from +x, wrapped to (−π, π].
    psi_rate_radps : ψ̇ (rad/s), counter-clockwise positive.
    mode : flight mode.
    battery_pct : battery level (%).
    """

    t_s: float
    position_m: _np.ndarray
    velocity_mps: _np.ndarray
    roll_rad: float
    pitch_rad: float
    psi_rad: float
    psi_rate_radps: float
    mode: FlightMode
    battery_pct: float


@slot_init
@dataclass(frozen=True, slots=True, eq=False)
class MocapPose:
    """One motion-capture pose of the drone (docs/mocap-stream.md), converted to SI.

    Attributes
    ----------
    t_s : time of the pose (s): plant time in simulation, receipt time on the real link.
    position_m : (3,) [x, y, z] (m), world frame (x forward, y left, z up).
    rotation_xyz_rad : (3,) Euler angles [rx, ry, rz] (rad) with R = Rx(rx)·Ry(ry)·Rz(rz)
        (intrinsic X→Y→Z, scipy ``Rotation.from_euler("XYZ", …)``), R mapping body to world.
    psi_rad : heading ψ = atan2(R[1,0], R[0,0]) (rad), counter-clockwise, wrapped to (−π, π].
    """

    t_s: float
    position_m: _np.ndarray
    rotation_xyz_rad: _np.ndarray
    psi_rad: float


@slot_init
@dataclass(frozen=True, slots=True, eq=False)
class NavdataSample:
    """One navdata demo sample (docs/protocol.md §4.4) in the drone's own sign conventions, SI-ish units.

    Only the units differ from the wire (millidegrees → degrees, mm → m, mm/s → m/s); the signs
    are the drone's: body frame x forward, y right, z down.

    Attributes
    ----------
    t_s : time of the sample (s).
    mode : flight mode (ctrl_state major / state bits on the wire).
    battery_pct : battery level (%).
    roll_deg : navdata phi (°), > 0 right wing down (= world φ in degrees, plus trim bias).
    pitch_deg : navdata theta (°), > 0 nose up (= −world θ in degrees, plus trim bias).
    yaw_deg : navdata psi (°), > 0 clockwise seen from above (= −world ψ), with an arbitrary
        offset set at take-off and a slow drift; wrapped to (−180, 180].
    altitude_m : ultrasound altitude (m), ≥ 0; 0 when not airborne.
    vx_body_mps : optical-flow speed along the body x axis (forward positive), m/s.
    vy_body_mps : optical-flow speed along the body y axis, **right positive** (navdata vy; the
        world-frame "left" speed is −vy_body_mps).
    vz_mps : vertical speed (m/s), **down positive** (navdata body z down).
    ctrl_state : the raw ctrl_state word (``major << 16 | minor``) it came with; None when the
        source has none (simulation without a wire).
    state_bits : the packet's drone state word (docs/protocol.md §4.2: fault bits among
        them); None when the source has none (simulation without a wire).
    """

    t_s: float
    mode: FlightMode
    battery_pct: float
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    altitude_m: float
    vx_body_mps: float
    vy_body_mps: float
    vz_mps: float
    ctrl_state: int | None = None
    state_bits: int | None = None


@slot_init
@dataclass(frozen=True, slots=True)
class TickInputs:
    """What the links hold at tick time ``t_s`` (s, the run's clock): the control tick's input.

    ``pose``/``navdata`` are the newest received (None before the first); ``*_rx_t_s`` their
    receipt times on the same clock (ages are measured from those). ``target`` is the newest
    pose of the second tracked object (reference kind ``follow`` or a moving obstacle; None
    otherwise). Here rather than in ``runtime`` so the simulators can build one without
    importing the runtime.
    """

    t_s: float
    pose: MocapPose | None
    pose_rx_t_s: float
    navdata: NavdataSample | None
    navdata_rx_t_s: float
    target: MocapPose | None = None
    target_rx_t_s: float = -_math.inf
