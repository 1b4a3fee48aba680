"""The ``controller`` section: NMPC (solver, weights, bounds, obstacles, offset-free
integral action) or the thesis' P controller (docs/thesis.md)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal, Optional

from pydantic import Field, model_validator

from ardrone_nmpc.config.fields import (
    CoordinateVec3, NonNegative, NonNegativeVec4,
    NonNegativeVec7, PathSize, Positive, PositiveVec4, Section, Vec4, auto_or_number,
    require_increasing,
)
from ardrone_nmpc.core import defaults


class SolverConfig(Section):
    """Numerical settings of the NMPC solvers (thesis §3.3, Algorithm 1; Ohtsuka's C/GMRES)."""

    method: Literal["cgmres", "newton"] = Field(
        "cgmres", description="'cgmres': continuation/GMRES, one GMRES solve per tick; "
        "'newton': the thesis' per-step Newton iterations with fdgmres.")
    kmax: int = Field(defaults.KMAX, ge=1, le=1000,
                      description="C/GMRES: Krylov-subspace dimension per solve (count).")
    newton_kmax: int = Field(
        defaults.NEWTON_KMAX, ge=1, le=1000, description="Method 'newton': Krylov dimension "
        "k_max of each Newton step (Algorithm 1; the thesis gives none). Its system is "
        "uncondensed (8 unknowns per stage): with 5, GMRES stops far above η and Newton stalls "
        "at ‖F‖ ≈ 0.1 (docs/thesis-reproduction.md).")
    zeta_per_s: Positive = Field(
        defaults.ZETA_PER_S, description="Continuation stabilisation gain ζ (1/s): dF/dt = −ζ F.")
    fd_step: Positive = Field(
        defaults.FD_STEP,
        description="Forward-difference step h of Jacobian-vector products (dimensionless).")
    gmres_rtol: float = Field(
        defaults.GMRES_RTOL, gt=0, lt=1,
        description="GMRES relative residual tolerance η (thesis Algorithm 1).")
    tolerance: Positive = Field(
        defaults.TOLERANCE,
        description="Target ‖F‖ of Newton solves (initial solve and method 'newton').")
    max_newton_iterations: int = Field(defaults.MAX_NEWTON_ITERATIONS, ge=1, le=1000,
                                       description="Newton iteration cap per solve.")
    dummy_weight: Positive = Field(
        defaults.DUMMY_WEIGHT,
        description="Linear cost weight of the dummy inputs that enforce the input bounds.")
    bound_epsilon: NonNegative = Field(
        defaults.BOUND_EPSILON,
        description="ε of thesis eq. 3.25: an active bound C < 0 becomes C − ε = 0 ('newton').")
    horizon_ramp_rate_per_s: NonNegative = Field(
        defaults.HORIZON_RAMP_RATE_PER_S,
        description="α (1/s) in T(t) = N·Δτ·(1 − e^(−αt)); 0 = fixed horizon as in the thesis.")
    divergence_residual: Positive = Field(
        defaults.DIVERGENCE_RESIDUAL,
        description="‖F‖ above which a solve counts as diverged and the solver re-initialises.")
    newton_trigger_residual: Positive = Field(
        defaults.NEWTON_TRIGGER_RESIDUAL,
        description="C/GMRES: ‖F‖ at a new measurement above which the tick first "
        "re-projects onto F = 0 by Newton/GMRES warm-started from the current solution (a "
        "reference jump is an impulse the continuation cannot follow).")
    condensed: bool = Field(
        defaults.CONDENSED,
        description="C/GMRES: eliminate the dummy inputs and multipliers per stage in closed "
        "form (4 unknowns per stage, not 12). Same equations; GMRES(5) stagnates on the "
        "uncondensed saddle-point system, so false is for comparison only.")


class PGainsConfig(Section):
    """Gains of the baseline proportional controller (thesis eq. 4.16; the thesis gives none).
    The defaults are tuned on the ``ardrone`` plant; the ``thesis_kit`` profile sets the kit's
    Baseline Controller's (config/profiles.py)."""

    k1_per_s: Positive = Field(0.7, description="ż_ref = k1 (z_d − z), 1/s (tuned in "
                               "simulation: see control/proportional.py PGains).")
    k2_rad_per_mps: Positive = Field(
        0.2, description="Roll φ per m/s of lateral speed error, rad/(m/s).")
    k3_rad_per_mps: Positive = Field(
        0.2, description="Pitch θ per m/s of forward speed error, rad/(m/s).")
    k4_per_s: Positive = Field(1.0, description="ψ̇ = k4 (ψ_d − ψ), 1/s.")


class ObstacleConfig(Section):
    """A static obstacle the NMPC keeps out of: the constraint ‖p − c‖ ≥ d, d = radius + margin.

    A sphere measures the 3-D distance from its centre; a cylinder is vertical and unbounded
    in height and measures the horizontal distance only (its centre's z is ignored).
    """

    kind: Literal["sphere", "cylinder"] = Field(
        ..., description="'sphere' (3-D distance) or 'cylinder' (vertical; horizontal distance).")
    center_m: CoordinateVec3 = Field(
        ..., description="Centre [x, y, z] (m); z is ignored for a cylinder.")
    radius_m: PathSize = Field(..., description="Radius of the obstacle itself (m), ≤ 1000.")
    margin_m: NonNegative = Field(
        0.3, description="Safety margin added to the radius (m): the drone's half-size (≈ 0.26 m "
        "with the indoor hull) plus a buffer. The NMPC keeps the drone's centre d = radius + "
        "margin from the obstacle's centre.")
    mocap_object: Optional[str] = Field(
        None, min_length=1, max_length=24, description="A moving obstacle: the mocap object "
        "whose newest position is the centre each tick (center_m until it is first seen; the "
        "last position is kept when it goes stale). null: static.")


class OffsetFreeConfig(Section):
    """Offset-free tracking: integral action on the position/yaw error, fed to the NMPC as a
    shift of its reference (docs/solver-notes.md, "Offset-free tracking"). A constant wind, a
    vertical gain mismatch, battery sag or a navdata velocity bias then leave no steady error.
    Vectors are ordered [x, y, z, ψ]."""

    enabled: bool = Field(True, description="Integral action on (true) or off (false: the "
                          "NMPC tracks the reference itself, as in the thesis).")
    ki_per_s: NonNegativeVec4 = Field(
        (0.5, 0.5, 0.4, 0.15), description="Integral gain per axis (1/s): the reference shift "
        "moves by −ki·e per second while it learns, [x, y, z, ψ]; 0 switches an axis off.")
    kp: NonNegativeVec4 = Field(
        (0.0, 0.0, 1.0, 0.0), description="Proportional part of the shift while learning "
        "(dimensionless, m per m / rad per rad), [x, y, z, ψ]: stiffens a slow loop so the "
        "integrator settles without overshoot (velocity form: it never jumps the shift).")
    error_band: PositiveVec4 = Field(
        (0.5, 0.5, 0.5, 0.3), description="An axis learns only while |error| is below this "
        "[m, m, m, rad] (conditional integration: a step's transient does not wind up).")
    hold_s: NonNegativeVec4 = Field(
        (1.5, 1.5, 1.5, 2.0), description="It starts learning once the axis has been at rest "
        "inside its error band this long (s), and goes on until the error leaves the band or "
        "the reference moves: the tail of a step is the loop's own.")
    steady_band: PositiveVec4 = Field(
        (0.01, 0.01, 0.02, 0.01), description="'At rest' also needs the error steady: its "
        "range since the axis came to rest within this [m, m, m, rad] — a step's tail that "
        "still converges restarts the hold.")
    speed_band: PositiveVec4 = Field(
        (0.15, 0.15, 0.05, 0.3), description="'At rest': the estimated rate of the axis below "
        "this [m/s, m/s, m/s, rad/s].")
    release_speed: PositiveVec4 = Field(
        (0.3, 0.3, 0.3, 0.6), description="A learning axis stops (and needs a new hold) when "
        "its rate exceeds this [m/s, m/s, m/s, rad/s]: a gust is not a constant disturbance. "
        "Above speed_band, so the motion the shift itself causes does not stop it.")
    max_shift: PositiveVec4 = Field(
        (0.5, 0.5, 0.5, 0.3), description="Largest reference shift [m, m, m, rad]: a bad "
        "sensor cannot drag the drone further than this from the reference.")


class AdaptationConfig(Section):
    """How the controller uses the flight's own measurement of the drone's command delay and
    tilt per unit command (``delay_compensation_s: auto``, ``attitude_gain: auto``;
    docs/solver-notes.md §10). Every navdata sample updates the estimate (the last
    ``window_s`` of PCMD and navdata weigh most); every ``refit_s`` it is read, and each of
    the delay and the gain is used once confident (delay σ ≤ 20 ms with R² ≥ 0.2 and no rival
    delay a tick away; gain σ ≤ 10 % with R² ≥ 0.3), clipped to the bounds."""

    delay_prior_s: NonNegative = Field(
        0.26, le=2.0, description="Delay (s) compensated until the flight's estimate is "
        "confident (auto); 0.26 = the thesis simulator's.")
    delay_min_s: NonNegative = Field(0.0, le=2.0, description="Smallest delay (s) auto uses.")
    delay_max_s: NonNegative = Field(0.5, le=2.0, description="Largest delay (s) auto uses.")
    gain_prior: Positive = Field(
        1.0, le=5.0, description="Tilt per unit command relative to drone.euler_angle_max_rad "
        "assumed until the estimate is confident (attitude_gain auto).")
    gain_min: Positive = Field(
        0.6, le=5.0, description="Smallest gain auto uses; at most planned_tilt_frac, so "
        "that the largest tilt the NMPC plans, divided by it, is still a PCMD within ±1.")
    gain_max: Positive = Field(2.5, le=5.0, description="Largest gain auto uses.")
    window_s: Positive = Field(
        30.0, ge=5.0, le=600.0, description="Memory of the estimate (s): a sample's weight "
        "is exp(−age / window_s).")
    refit_s: Positive = Field(
        1.0, ge=0.2, le=60.0, description="Seconds between readings of the estimate (each "
        "one an event, and auto's chance to change what it uses).")

    _delay_bounds = require_increasing("delay_min_s", "delay_max_s")
    _gain_bounds = require_increasing("gain_min", "gain_max")


class ControllerConfig(Section):
    """Controller choice and the optimal control problem (thesis eq. 3.14–3.16, 4.17)."""

    kind: Literal["nmpc", "p"] = Field(
        "nmpc", description="'nmpc': nonlinear MPC; 'p': proportional baseline (eq. 4.16).")
    horizon_steps: int = Field(defaults.HORIZON_STEPS, ge=1, le=1000,
                               description="Prediction horizon N (steps).")
    dtau_s: Positive = Field(defaults.DTAU_S, le=1.0,
                             description="Prediction step Δτ (s), ≤ 1; horizon T = N·Δτ.")
    q: NonNegativeVec7 = Field(
        defaults.Q_STATE,
        description="State weights diag q, order [x, ẋ, y, ẏ, z, ż, ψ]; the thesis' (§4.4) "
        "are [12, 2, 7, 2, 5, 10, 13], x and y detuned here for robustness "
        "(docs/solver-notes.md §10).")
    r: PositiveVec4 = Field(
        defaults.R_INPUT,
        description="Input weights diag r, order [z̈, φ, θ, ψ̇]; the thesis' 'Case 2' is "
        "[4, 12, 12, 24], roll and pitch detuned here (docs/solver-notes.md §10).")
    q_terminal: NonNegativeVec7 = Field(
        defaults.Q_TERMINAL,
        description="Terminal state weights, order as q (the thesis has none).")
    u_min: Vec4 = Field(
        defaults.U_MIN,
        description="Input lower bounds [m/s², rad, rad, rad/s] (thesis eq. 4.17).")
    u_max: Vec4 = Field(
        defaults.U_MAX,
        description="Input upper bounds [m/s², rad, rad, rad/s]; each above u_min (eq. 4.17).")
    vz_lead_s: Optional[Positive] = Field(
        0.5, description="ż reference = ż estimate + z̈ · vz_lead_s (s). The drone's vertical "
        "loop is a first-order lag; this inverts it exactly when vz_lead_s is its time "
        "constant (0.5 s: docs/plant.md, sim.plant.tau_vz_s). null = one control period, the "
        "thesis' integration (end of §4.4), which assumes a new vertical speed within a tick "
        "and overshoots altitude steps by 6–7 % in simulation (2.3 % with 0.5).")
    delay_compensation_s: auto_or_number(low=0.0, high=2.0) = Field(  # type: ignore[valid-type]
        "auto", description="Command delay (s, ≤ 2) the NMPC predicts through: the state "
        "is rolled forward through the commands already sent and the OCP solved for the moment "
        "the new command takes effect. 0.26 = the thesis simulator's delay (and sim.plant's); "
        "0 = the thesis' delay-free formulation, which limit-cycles (±0.3 m) against that delay. "
        "'auto': adaptation.delay_prior_s until the flight's own estimate of the delay is "
        "confident, then that estimate (bounded; an event when it changes).")
    attitude_gain: auto_or_number(low=0.0, high=5.0, low_open=True) = Field(  # type: ignore[valid-type]
        "auto", description="The drone's tilt per unit PCMD roll/pitch relative to "
        "drone.euler_angle_max_rad, which the NMPC's commands are divided by (1: the firmware's "
        "nominal gain; real drones measure 0.6 … 2). 'auto': adaptation.gain_prior until the "
        "flight's own estimate is confident, then that estimate (bounded; an event when it "
        "changes). The P controller's commands (kind p, or the fallback) are not divided: its "
        "gains are chosen on the plant (eq. 4.16).")
    planned_tilt_frac: float = Field(
        0.55, gt=0.0, le=1.0, description="Largest roll/pitch the NMPC plans, as a fraction of "
        "drone.euler_angle_max_rad (0 … 1]. Below 1 it keeps a margin: a drone that tilts less "
        "per unit command than nominally still reaches the plan (attitude_gain auto divides "
        "its gain out, down to adaptation.gain_min), one that tilts more stays under "
        "safety.max_tilt_rad before its gain is measured.")
    adaptation: AdaptationConfig = Field(
        default_factory=AdaptationConfig, description="The priors and bounds of 'auto' "
        "delay_compensation_s and attitude_gain.")
    solver: SolverConfig = Field(default_factory=SolverConfig, description="NMPC solver settings.")
    obstacles: tuple[ObstacleConfig, ...] = Field(
        (), max_length=32, description="Obstacles the NMPC avoids (exterior penalty on "
        "‖p − c‖² ≥ d², docs/solver-notes.md §7); none by default. The P controller ignores "
        "them.")
    obstacle_weight: Positive = Field(
        2000.0, description="Weight w of the obstacle penalty ½ w max(0, d² − ‖p − c‖²)² in the "
        "stage cost (1/m⁴, relative to q and r). Larger: less intrusion into the margin, a "
        "stiffer problem for GMRES.")
    obstacle_lookahead_s: NonNegative = Field(
        0.3, le=3.0, description="A moving obstacle (mocap_object) is placed where its "
        "estimated velocity takes it this long after the command takes effect; its motion over "
        "the horizon is not modelled, and this short look-ahead stands in for it (s; "
        "configs/moving_obstacle.yaml: 0 s → 31 ticks inside the margin, 0.3 s → none).")
    obstacle_tie_break_m: NonNegative = Field(
        0.05, description="Tie-break of head-on approaches (m): each tick the penalty's centre "
        "moves this far to the left of the line of sight from the drone, and d grows by as "
        "much (the penalised region still covers the obstacle). A drone within this distance "
        "of the line through the centre passes the obstacle on its right; 0 leaves the choice "
        "to noise.")
    obstacle_curvature: Literal["gauss-newton", "exact"] = Field(
        "gauss-newton", description="Curvature of the obstacle penalty in the solvers' "
        "Jacobian products: 'gauss-newton' drops the negative part, so the path through an "
        "obstacle's centre repels the continuation instead of attracting it; 'exact' is the "
        "true Hessian (for comparison).")
    p_gains: PGainsConfig = Field(
        default_factory=PGainsConfig, description="Gains of the 'p' controller.")
    offset_free: OffsetFreeConfig = Field(
        default_factory=OffsetFreeConfig, description="Offset-free tracking (integral action "
        "of the NMPC; the 'p' controller has none). true/false is short for "
        "{enabled: true/false} with the default gains.")

    _u_bounds = require_increasing("u_min", "u_max")

    @model_validator(mode="before")
    @classmethod
    def _offset_free_shorthand(cls, data: Any) -> Any:
        # controller.offset_free: false (a bool) → the section with enabled false
        if isinstance(data, Mapping) and isinstance(data.get("offset_free"), bool):
            data = {**data, "offset_free": {"enabled": data["offset_free"]}}
        return data
