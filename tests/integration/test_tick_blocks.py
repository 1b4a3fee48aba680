"""The lockstep runner's blocks of ticks (``lockstep.BLOCK_TICKS``) change nothing.

Each case is flown twice, with blocks (the module's ``BLOCK_TICKS``, or a length given) and
without (``BLOCK_TICKS = 0``: the per-tick path), and the two must leave the same bits: every
row cell and its Python type (the clock cells ``compute_us`` and ``solve_us``: their type
only), the events, the ``SimResult``, the ``progress`` calls, and the state the objects hold
(:func:`state`: the drone's counters, firmware, sensors and plant, the tick's stages) — at
each ``Tick.step`` the block flight makes (the per-tick flight's state at the same tick's
step), at the progress call after each such tick (:meth:`Flight.python_ticks`), when the
loop ends (``_land`` called) and after the flight.
The objects are caught by wrapping ``LockstepDrone.__init__`` and ``Tick.__init__``: nothing
in the product is changed for it. Cases: waypoint flights (the ones whose ticks the compiled
controller takes) with each option that changes their tick, a saturating command, a climb
at the altitude cap, a supervisor's landing, curves read from a table, ẋ, ẏ from the
navdata's speeds, every ż estimator, injected faults (blocks between the ticks at which one
may act), faults of the sensors' bytes (the wire's blocks: the receiving link's whole state
and the datagrams on their way compared too). Without
``BLOCK_TICKS`` (a tree before blocks) the comparisons skip. The lead's gate with more
flights: ``benchmarks/tick_equivalence.py``.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import struct
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.estimation import luenberger
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS
from ardrone_nmpc.runs.memory import MemoryRecorder
from ardrone_nmpc.runtime import lockstep
from ardrone_nmpc.runtime.tick import Tick
from ardrone_nmpc.sim.command_fifo import CommandFifo
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone
from ardrone_nmpc.sim.normal_blocks import NormalBlocks
from ardrone_nmpc.sim import wire_block
from ardrone_nmpc.sim.plant_kit import KitPlant
from ardrone_nmpc.sim.sensors import LockstepSensors
from tests.link_state import bits as link_bits
from tests.link_state import link_state

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
CLOCK_CELLS = frozenset({"compute_us", "solve_us"})  # wall-clock: their type compared only
SETTLE = ["sim.settle_s=1"]
KIT = "sim.plant.profile=thesis_kit"
NEWTON = "controller.solver.method=newton"
# Newton ticks that stop at their iterations above the tolerance (a share of them)
TIGHT = ["controller.solver.tolerance=2e-6", "controller.solver.max_newton_iterations=2"]
# held in the compiled legs' arrays (sim/held_state): in an instance's __dict__ only while
# released, so compared after a release (at the loop's end, after the flight) and not before
# (the kit plant's: the airframe's and its channels')
_HELD = frozenset(KitPlant.HELD_IN_ARRAYS + LockstepSensors.HELD_IN_ARRAYS + ("_held_by",))
# the firmware's cache of the cap's lead time (DroneFirmware._lead_s): filled when first read;
# the counters (compared on their own)
_FIRMWARE_SKIP = frozenset({"_lead_params", "_lead", "counters"})

# (name, config, overrides, seed)
CASES = [
    ("square", "square", ["duration_s=25"], 0),
    ("square_altitudes", "square_altitudes", ["duration_s=12", *SETTLE], 1),
    ("square_no_offset_free", "square",
     ["duration_s=12", *SETTLE, "controller.offset_free.enabled=false"], 2),
    # no response estimation: the delay and the gain given
    ("square_numeric_response", "square",
     ["duration_s=12", *SETTLE, "controller.delay_compensation_s=0.26",
      "controller.attitude_gain=1.0"], 3),
    # no delay compensation: nothing pending, the predicted state the estimate itself
    ("square_no_delay_comp", "square",
     ["duration_s=10", *SETTLE, "controller.delay_compensation_s=0"], 9),
    ("square_uncondensed", "square",
     ["duration_s=8", *SETTLE, "controller.solver.condensed=false"], 12),
    # other sample rates and latency (several poses, navdata samples a tick), another period
    ("square_sensor_rates", "square",
     ["duration_s=8", *SETTLE, "sim.mocap_rate_hz=240", "sim.navdata_rate_hz=200",
      "sim.noise.mocap_latency_ms=20"], 10),
    ("square_slow_sensors", "square",  # (ticks without a pose, without a navdata sample)
     ["duration_s=8", *SETTLE, "sim.mocap_rate_hz=30", "sim.navdata_rate_hz=10",
      "sim.noise.mocap_latency_ms=10"], 16),
    ("square_period", "square", ["duration_s=8", *SETTLE, "loop.period_s=0.05"], 13),
    ("square_disturbed", "square",
     ["duration_s=12", *SETTLE, "sim.plant.turbulence_std_mps=0.3", "sim.vz_gain=0.8",
      "sim.battery_sag_frac=0.3", "sim.navdata_velocity_bias_mps=[0.05,-0.03]"], 5),
    # a drone that tilts a third of the model's: many ticks saturate the command
    ("square_saturating", "square", ["duration_s=12", *SETTLE, "controller.attitude_gain=0.3"],
     0),
    # the climb to the 1.4 m corner meets the 1.3 m cap: the firmware caps its gaz (the
    # legs leave a climb near the cap to Python: blocks before and after)
    ("altitude_cap", "square_altitudes", ["duration_s=20", *SETTLE, "drone.altitude_max_m=1.3"],
     0),
    # the battery reaches the floor: the supervisor lands, the descent's ticks logged
    ("low_battery", "square", ["duration_s=10", *SETTLE, "sim.plant.battery_start_pct=23",
                               "sim.plant.battery_drain_pct_per_min=30"], 0),
    # injected faults that leave the sensors alone: blocks fly the ticks at which none may
    # act, the per-tick path the others (a one-shot fault due in the settle phase, a delay
    # jump, a short window of AT loss, a gust, a constant wind, the outdoor profiles, an
    # emergency, a landing of the drone's own)
    ("fault_mix", "square", ["duration_s=12", *SETTLE, "faults.battery_floor.start_s=-0.5",
                             "faults.battery_floor.level_pct=60", "faults.delay_jump.start_s=3",
                             "faults.delay_jump.delay_s=0.2", "faults.at_loss.start_s=5",
                             "faults.at_loss.duration_s=0.3", "faults.at_loss.probability=0.5",
                             "faults.wind_gust.start_s=7", "faults.wind_gust.duration_s=0.5",
                             "faults.wind.velocity_mps=[0.3,-0.2,0]"], 7),
    ("fault_outdoor_profile", "square", ["duration_s=8", *SETTLE,
                                         "faults.outdoor_profile.euler_angle_max_rad=0.35"], 8),
    ("fault_emergency", "square", ["duration_s=10", *SETTLE, "faults.emergency.start_s=4"], 0),
    ("fault_self_land", "square", ["duration_s=10", *SETTLE, "faults.self_land.start_s=4"], 0),
    ("fault_battery_floor", "square", ["duration_s=10", *SETTLE,
                                       "faults.battery_floor.start_s=4"], 0),
    # a diverging solver: blocks and the compiled tick outside its window, Python inside (the
    # supervisor's hold, fallback and recovery) — a window in the track phase, one across
    # fits (a refit every 0.2 s)
    ("fault_solver_diverge", "square", ["duration_s=8", *SETTLE,
                                        "faults.solver_diverge.start_s=3"], 0),
    ("fault_solver_diverge_fit", "square", ["duration_s=10", *SETTLE,
                                            "controller.adaptation.refit_s=0.2",
                                            "faults.solver_diverge.start_s=4.05",
                                            "faults.solver_diverge.duration_s=0.5"], 3),
    # ẋ, ẏ from the navdata's speeds (the block rotates them as the estimate does)
    ("square_navdata_velocity", "square",
     ["duration_s=8", *SETTLE, "estimator.horizontal_velocity=navdata"], 4),
    # curves read from a table of their states (reference/experiment.tabulated), filled a
    # tick or a block at a time: the ellipse, Lorenz's (past its end: held), the
    # identification flight's every axis; fits between blocks; navdata speeds
    ("ellipse", "ellipse", ["duration_s=10", *SETTLE], 0),
    ("ellipse_refit_navdata", "ellipse",
     ["duration_s=8", *SETTLE, "controller.adaptation.refit_s=0.2",
      "estimator.horizontal_velocity=navdata"], 18),
    ("lorenz", "lorenz", ["duration_s=8", *SETTLE], 1),
    ("identify", "identify", ["duration_s=14", *SETTLE, "reference.excitation.axis_s=2.4",
                              "reference.excitation.rest_s=0.5",
                              "reference.excitation.sweep_m=0.1"], 2),
    # the thesis_kit plant (its channels' dynamics in the legs: sim/plant_kit): a square,
    # disturbed, into the cap, its battery reaching the floor
    ("square_kit", "square", ["duration_s=8", *SETTLE, KIT], 6),
    ("square_kit_disturbed", "square",
     ["duration_s=10", *SETTLE, KIT, "sim.plant.turbulence_std_mps=0.3", "sim.vz_gain=0.8",
      "sim.battery_sag_frac=0.3"], 5),
    ("kit_altitude_cap", "square_altitudes",
     ["duration_s=14", *SETTLE, KIT, "drone.altitude_max_m=1.3"], 0),
    ("kit_low_battery", "square", ["duration_s=10", *SETTLE, KIT,
                                   "sim.plant.battery_start_pct=23",
                                   "sim.plant.battery_drain_pct_per_min=30"], 0),
    # obstacles (the blocks' kernel solving with the obstacle table: tick_block_obstacles):
    # the avoidance's detour, on the kit plant, with a gust between blocks
    ("obstacle", "obstacle", ["duration_s=10", *SETTLE], 0),
    ("obstacle_kit_gust", "obstacle", ["duration_s=8", *SETTLE, KIT, "faults.wind_gust.start_s=3",
                                       "faults.wind_gust.duration_s=0.3"], 3),
    # the thesis' Newton scheme (the blocks' kernel calling its tick: tick_block_newton): a
    # square, the kit plant's hover, ticks stopped above the tolerance (Python's verdict:
    # accepted, or the P fallback flies them), a diverging solver's window, an obstacle
    ("newton_square", "square", ["duration_s=12", *SETTLE, NEWTON], 0),
    ("newton_hover_kit", "hover", ["duration_s=6", *SETTLE, KIT, NEWTON], 1),
    ("newton_tolerance", "square", ["duration_s=10", *SETTLE, NEWTON, *TIGHT], 2),
    ("newton_rejected", "square", ["duration_s=10", *SETTLE, NEWTON, *TIGHT,
                                   "safety.solver_accept_max_iterations=false"], 3),
    ("newton_solver_diverge", "square", ["duration_s=8", *SETTLE, NEWTON,
                                         "faults.solver_diverge.start_s=3"], 4),
    ("newton_obstacle", "obstacle", ["duration_s=8", *SETTLE, NEWTON], 5),
    # the P controller (thesis eq. 4.16): its blocks (runtime/control_tick_p), a wind
    ("p_square", "square", ["duration_s=8", *SETTLE, "controller.kind=p"], 6),
    ("p_wind", "hover", ["duration_s=6", *SETTLE, "controller.kind=p",
                         "faults.wind.velocity_mps=[0.6,0.2,0]"], 7),
    # a second object on the mocap stream (runtime/second_object): logged, a moving
    # obstacle (its frames' noise, its filter, the obstacle's centre), without noise, on a
    # figure 8, on the kit plant with a gust between blocks
    ("square_target", "square", ["duration_s=8", *SETTLE, "sim.target.speed_mps=0.3"], 14),
    ("moving_obstacle", "moving_obstacle", ["duration_s=8", *SETTLE], 0),
    ("moving_obstacle_fig8_noiseless", "moving_obstacle",
     ["duration_s=10", *SETTLE, "sim.target.path=figure8", "sim.noise.mocap_position_std_m=0"],
     5),
    ("moving_obstacle_kit_gust", "moving_obstacle",
     ["duration_s=8", *SETTLE, KIT, "faults.wind_gust.start_s=3",
      "faults.wind_gust.duration_s=0.3"], 6),
    # a followed object (its reference's table filled in the block): in its frame and
    # heading, its pose stale on some ticks (age 3 or 8 ms against a 5 ms limit)
    ("follow_car", "follow_car", ["duration_s=8", *SETTLE], 0),
    ("follow_object_frame_stale", "follow_car",
     ["duration_s=8", *SETTLE, "reference.follow.offset_frame=object",
      "reference.follow.heading=object", "reference.follow.max_age_ms=5"], 7),
    # a block that ends after a tick's legs (the battery's floor: an emptying battery's
    # leg) or after its controller's call (Newton above its tolerance): the frame the
    # kernel drew the object's pose of is not drawn again by the Python path going on
    ("moving_obstacle_low_battery", "moving_obstacle",
     ["duration_s=10", *SETTLE, "sim.plant.battery_start_pct=23",
      "sim.plant.battery_drain_pct_per_min=30"], 7),
    ("follow_newton_tolerance", "follow_car", ["duration_s=8", *SETTLE, NEWTON, *TIGHT], 1),
    # the Luenberger observer (its coefficients' table in the estimate's state: a Δt not
    # in it, a tick for Python), with the P controller, through a mocap dropout
    ("square_luenberger", "square", ["duration_s=8", *SETTLE, "estimator.kind=luenberger"],
     11),
    ("p_luenberger", "square", ["duration_s=8", *SETTLE, "estimator.kind=luenberger",
                                "controller.kind=p"], 12),
    ("dropout_luenberger", "square", ["duration_s=10", *SETTLE, "estimator.kind=luenberger",
                                      "faults.mocap_dropout.start_s=4",
                                      "faults.mocap_dropout.duration_s=0.2"], 13),
    # the other ż estimators: the difference, none (ż ≡ 0: the thesis' first altitude flight)
    ("square_difference", "square", ["duration_s=8", *SETTLE, "estimator.kind=difference"],
     11),
    ("altitude_none", "altitude_none", ["duration_s=8", *SETTLE], 3),
    # faults that touch the sensors' bytes (every frame and packet through the wire:
    # sim/wire_block's blocks between the faults' windows): each stream's loss, a repeated
    # dropout, a zero pose, extra latency, both disorders, corruption, a blackout (the
    # drone's bootstrap answered), other rates and latency, the kit plant with turbulence
    ("fault_mocap_dropout", "square", ["duration_s=10", *SETTLE, "faults.mocap_dropout.start_s=4",
                                       "faults.mocap_dropout.duration_s=0.2"], 0),
    ("wire_navdata_loss", "square", ["duration_s=8", *SETTLE, "faults.navdata_loss.start_s=4",
                                     "faults.navdata_loss.duration_s=0.3"], 1),
    # (a window shorter than the feedback's limit, ending within a tick)
    ("wire_navdata_loss_short", "square", ["duration_s=8", *SETTLE,
                                           "faults.navdata_loss.start_s=3.01",
                                           "faults.navdata_loss.duration_s=0.05"], 12),
    ("wire_repeated_dropout", "square", ["duration_s=8", *SETTLE,
                                         "faults.mocap_dropout.start_s=2",
                                         "faults.mocap_dropout.duration_s=0.1",
                                         "faults.mocap_dropout.repeat_every_s=1.5"], 2),
    ("wire_occlusion_zero", "square", ["duration_s=8", *SETTLE,
                                       "faults.mocap_occlusion.start_s=3",
                                       "faults.mocap_occlusion.duration_s=0.3",
                                       "faults.mocap_occlusion.zero_pose=true"], 3),
    ("wire_latency", "square", ["duration_s=8", *SETTLE, "faults.mocap_latency.start_s=3",
                                "faults.mocap_latency.duration_s=1"], 4),
    ("wire_disorder_mocap", "square", ["duration_s=8", *SETTLE, "faults.disorder.start_s=3",
                                       "faults.disorder.duration_s=1",
                                       "faults.disorder.stream=mocap"], 5),
    ("wire_disorder_navdata", "square", ["duration_s=8", *SETTLE, "faults.disorder.start_s=3",
                                         "faults.disorder.duration_s=1",
                                         "faults.disorder.stream=navdata"], 6),
    ("wire_corrupt", "square", ["duration_s=8", *SETTLE, "faults.navdata_corrupt.start_s=3",
                                "faults.navdata_corrupt.duration_s=0.3"], 7),
    ("wire_blackout", "square", ["duration_s=8", *SETTLE, "faults.blackout.start_s=3",
                                 "faults.blackout.duration_s=0.3"], 8),
    ("wire_sensor_rates", "square", ["duration_s=8", *SETTLE, "sim.mocap_rate_hz=240",
                                     "sim.navdata_rate_hz=200", "sim.noise.mocap_latency_ms=20",
                                     "faults.mocap_dropout.start_s=3",
                                     "faults.mocap_dropout.duration_s=0.2"], 9),
    # the battery's low bit in the packets (a worn battery's level, above the floor: an alarm
    # the block ends at, the supervisor lands) — a dropout after the flight's end: the wire
    ("wire_low_battery", "square", ["duration_s=10", *SETTLE, "sim.plant.battery_start_pct=32",
                                    "faults.vbat_low.threshold_pct=30",
                                    "sim.plant.battery_drain_pct_per_min=30",
                                    "faults.mocap_dropout.start_s=30",
                                    "faults.mocap_dropout.duration_s=0.2"], 11),
    # a climb near the cap (the legs stop before its leg: the tick's rest Python's)
    ("wire_altitude_cap", "square_altitudes", ["duration_s=12", *SETTLE,
                                               "drone.altitude_max_m=1.3",
                                               "faults.navdata_loss.start_s=30"], 13),
    ("wire_kit_turbulent", "square", ["duration_s=8", *SETTLE, KIT,
                                      "sim.plant.turbulence_std_mps=0.3",
                                      "faults.mocap_dropout.start_s=3",
                                      "faults.mocap_dropout.duration_s=0.2"], 10),
    ("hover", "hover", ["duration_s=6", *SETTLE], 0),
    ("step_z", "step_z", ["duration_s=6", *SETTLE], 0),
]


# ---------------------------------------------------------------- values as bits
def bits(value, depth: int = 0):
    """``value`` as a comparable record of its bits and types: floats by their 8 bytes (a
    NaN's payload, −0.0) and their class (``float`` is not ``np.float64``), arrays by dtype,
    shape and bytes, records field by field; another object by its class only."""
    if depth > 6:
        return ("deep", type(value).__name__)
    if value is None or value.__class__ is str or value.__class__ is bool:
        return value
    kind = type(value).__name__
    if isinstance(value, enum.Enum):
        return (kind, value.name)
    if isinstance(value, float):  # float and np.float64 alike: the double's bytes
        return (kind, struct.pack("<d", value).hex(), repr(float(value)))
    if isinstance(value, (int, np.integer, np.bool_)):
        return (kind, int(value))
    if isinstance(value, np.generic):  # float32 and others
        return (kind, value.tobytes().hex())
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            return (kind, value.shape, tuple(bits(v, depth + 1) for v in value.ravel()))
        return (kind, value.dtype.str, value.shape, np.ascontiguousarray(value).tobytes().hex())
    if isinstance(value, (bytes, bytearray)):
        return (kind, bytes(value).hex())
    if isinstance(value, (tuple, list)):
        return (kind, tuple(bits(v, depth + 1) for v in value))
    if isinstance(value, dict):
        return (kind, tuple((k, bits(v, depth + 1)) for k, v in value.items()))
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return (kind, tuple((f.name, bits(getattr(value, f.name), depth + 1))
                            for f in dataclasses.fields(value)))
    if isinstance(value, NormalBlocks):  # where its generator's stream stands: the state
        # before the blocks drawn ahead and the count consumed since (refills may differ)
        return (kind, bits(value._state, depth + 1), value._skip + value.pos)
    if isinstance(value, CommandFifo):
        return (kind, bits(value.rows, depth + 1), value.head)
    return ("object", kind)


def _attrs(out: dict, prefix: str, obj, skip: frozenset = frozenset(),
           arrays: bool = True) -> None:
    """Each attribute in ``obj.__dict__`` (no descriptor read: nothing held is released)."""
    for name, value in vars(obj).items():
        if (name in skip or (not arrays and isinstance(value, np.ndarray))
                or (callable(value) and not isinstance(value, np.ndarray))):
            continue  # (a callable: a bound kernel or dispatcher, no state)
        out[f"{prefix}.{name}"] = bits(value)


def state(flight: "Flight", *, release: bool = False, stages_too: bool = True) -> dict:
    """What the flight's objects hold now, name → bits: the drone's and (``stages_too``)
    the tick's stages' (``tick.…``). ``release``: the compiled legs' held state written
    back first (sim/held_state), then compared too; without, nothing is read that would
    release it (a mid-flight snapshot must not change the path it watches)."""
    drone, tick = flight.drone, flight.tick
    sim, sensors = drone.sim, drone.sensors
    plant, legs = sim.plant, drone._legs  # (the direct path's, or the wire's quiet ticks')
    if release and legs is not None:
        legs.release()
    skip = frozenset() if release else _HELD
    out: dict = {}
    _attrs(out, "drone", drone, arrays=False)  # (its arrays: a compiled call's numbers)
    _attrs(out, "drone._guard", drone._guard)
    _attrs(out, "sim", sim, frozenset({"counters"}))
    _attrs(out, "counters", sim.counters)
    _attrs(out, "firmware", sim.firmware, _FIRMWARE_SKIP)
    _attrs(out, "sensors", sensors, skip)
    _attrs(out, "sensors.nav_stats", sensors.nav_stats, frozenset({"_lock"}))
    _attrs(out, "plant", plant, skip)
    held = legs is not None and legs.held()
    out["plant._current"] = bits(legs._saved["_current"] if held else plant._current)
    faults = sim.faults
    if faults is not None:  # (their draws, counters, events and plant faults still due)
        _attrs(out, "faults", faults, frozenset({"_lock", "schedule", "_plant_faults"}))
        _attrs(out, "faults._plant_faults", faults._plant_faults, frozenset({"plant"}))
        out["faults.rng"] = bits(repr(faults.schedule.rng.bit_generator.state))
    # the second object's generator: where its stream stands (its frames' noise)
    out["sensors._target_rng"] = bits(repr(sensors._target_rng.bit_generator.state))
    if sensors.wire:  # the receiving link's whole state, the datagrams on their way
        for name, value in link_state(sensors.mocap).items():
            out[f"sensors.mocap.{name}"] = bits(repr(value))
        out["sensors._queue"] = bits(repr([(a, o, s, link_bits(x)) for a, o, s, x in  # (a
                                           sorted(sensors._queue)]))  # heap: its order)
    out["truth"] = bits(drone.truth)
    out["truth_cells"] = bits(drone.truth_cells())
    if stages_too:
        stages(out, tick)
    return out


def stages(out: dict, tick: Tick) -> None:
    """What the tick's stages carry to the next tick (as ``tests/tick_flights.carried``,
    by name), and their other scalars and records."""
    _attrs(out, "tick", tick, arrays=False)
    for name in ("supervision", "supervisor", "delay", "estimation", "response"):
        stage = getattr(tick, name)
        if stage is not None:  # (the delay's ring, the estimate and the filter's state)
            _attrs(out, f"tick.{name}", stage)
    control, nmpc = tick.control, tick.control.nmpc
    # its arrays: the solve's answer, the reference (np.empty until a waypoint solve wrote
    # it; the predicted state's, _x_solve, until one with a delay did: not compared)
    _attrs(out, "tick.control", control, arrays=False)
    if nmpc is not None and control._work_args is not None:
        out["tick.control._states"] = bits(control._states)
    if nmpc is not None:
        _attrs(out, "tick.nmpc", nmpc, arrays=False)
        out["tick.nmpc.memory"] = bits(nmpc.memory.snapshot())
    if tick.response is not None:
        estimator = tick.response.estimator  # its state and estimate (its arrays but
        _attrs(out, "tick.response.estimator", estimator, arrays=False)  # _state: a fit's)
        out["tick.response.estimator._state"] = bits(estimator._state)
        out["tick.response.estimator._estimate"] = bits(estimator._estimate)
    if tick.offset is not None:
        _attrs(out, "tick.offset.integrator", tick.offset.integrator)
    if tick.obstacles is not None:  # a moving obstacle's tracked object (its filter)
        _attrs(out, "tick.obstacles.track", tick.obstacles.track)
    if tick.follow is not None:  # a followed one's (its filter, its pose's freshness)
        _attrs(out, "tick.follow", tick.follow)
        _attrs(out, "tick.follow._object", tick.follow._object)


def differences(a: dict, b: dict, limit: int = 12) -> list[str]:
    """The names whose bits differ (or that one side lacks), with both values."""
    lines = [f"{name}: {_shown(a.get(name, '<absent>'), b.get(name, '<absent>'))}"
             for name in sorted(set(a) | set(b)) if a.get(name, ()) != b.get(name, ())]
    return lines[:limit] + ([f"… {len(lines) - limit} more"] if len(lines) > limit else [])


def _shown(a, b) -> str:
    """Two bits records told apart: an array's first differing element, else both (cut)."""
    if (isinstance(a, tuple) and isinstance(b, tuple) and a[0] == b[0] == "ndarray"
            and len(a) == len(b) == 4 and a[1:3] == b[1:3]):
        x = np.frombuffer(bytes.fromhex(a[3]), a[1])
        y = np.frombuffer(bytes.fromhex(b[3]), b[1])
        apart = [i for i in range(x.size) if x[i:i + 1].tobytes() != y[i:i + 1].tobytes()]
        if apart:
            i = apart[0]
            return (f"array {a[1]} {a[2]}: {len(apart)} elements differ, first [flat {i}] "
                    f"{x[i]!r} != {y[i]!r}")
    return f"{str(a)[:300]} != {str(b)[:300]}"


# ---------------------------------------------------------------- a flight, watched
class Recorder(MemoryRecorder):
    """A :class:`MemoryRecorder` (cells taken as they are) that also keeps each row's bits
    as it was written (a row changed after it was handed over shows), and notes each write
    in ``trail``."""

    def __init__(self, trail: list) -> None:
        super().__init__()
        self.written: list = []
        self.trail = trail

    def write_cells(self, cells: list) -> None:
        self.trail.append("write")
        self.written.append(row_bits(cells))
        super().write_cells(cells)

    def write_row(self, row) -> None:
        self.trail.append("write")
        self.written.append(row_bits(row))
        super().write_row(row)

    def write_block(self, rows) -> None:
        """A block of rows (``runs/block_rows``): each row's cells noted as a write."""
        for cells in rows.cells():
            self.trail.append("write")
            self.written.append(row_bits(cells))
        super().write_block(rows)


def row_bits(row) -> tuple:
    """A row (cells in ``LOG_COLUMNS`` order, or a dict) as (form, (column, bits) …); the
    clock cells by their type only."""
    pairs = zip(LOG_COLUMNS, row) if row.__class__ is list else row.items()
    return (row.__class__.__name__,
            tuple((c, type(v).__name__ if c in CLOCK_CELLS else bits(v)) for c, v in pairs))


class Flight:
    """One flight's objects, rows, events, result, and the states seen (:func:`state`) at
    the points ``wanted`` (None: every one) — ``("step", t_exp_s bits, n-th call at that
    time)``: the entry of :meth:`Tick.step`; ``("progress", i)``: the runner's ``i``-th
    ``progress`` call — and when the loop ends (``_land``'s entry) and after the flight.
    ``trail``: the watched calls in order (``step``, ``progress``, ``write`` of a row,
    ``advance``: the runner's ``LockstepDrone.advance_to``). ``close_every`` n: after every
    n-th run of rows (a block's, or a tick's) the blocks' open chain is written back
    (``TickBlocks.close``, the flight's: :attr:`blocks`) — those progress points:
    :attr:`closed`."""

    def __init__(self, wanted: set | None, close_every: int = 0) -> None:
        self.wanted = wanted
        self.close_every = close_every
        self.blocks = None
        self.closed: set = set()
        self.runs_of_rows = 0
        self.left_in_run = 0  # progress calls left of the run of rows going on
        self.trail: list[str] = []
        self.drone: LockstepDrone | None = None
        self.tick: Tick | None = None
        self.recorder = Recorder(self.trail)
        self.steps = 0
        self.calls: dict = {}  # t_exp_s bits → Tick.step calls at that time
        self.progress: list[float] = []  # progress(fraction)'s fractions
        self.seen: dict = {}  # point → state
        self.at_loop_end: dict | None = None
        self.after: dict | None = None
        self.result = None

    def see(self, point: tuple, *, stages_too: bool = True) -> None:
        if self.wanted is None or point in self.wanted:
            self.seen[point] = state(self, stages_too=stages_too)

    def python_ticks(self) -> set:
        """The progress points right after a tick ``Tick.step`` took (its row written): the
        state after that tick in any flight. (Not those after a block's rows: a chain of
        blocks may write its state back only when Python reads it next.)"""
        ticks, i, last = set(), -1, None
        for what in self.trail:
            if what == "progress":
                i += 1
                if last == "step":
                    ticks.add(("progress", i))
            if what != "write":
                last = what
        return ticks


def fly(cfg, seed: int, monkeypatch, *, block_ticks: int | None,
        wanted: set | None = None, recorded: bool = True, close_every: int = 0) -> Flight:
    """Fly ``cfg`` with ``block_ticks`` (None: the module's ``BLOCK_TICKS``; 0: none),
    watched (:class:`Flight`); ``recorded`` False: no recorder (no rows, no events)."""
    flight = Flight(wanted, close_every)
    blocks_class = lockstep.TickBlocks
    drone_init, tick_init, step, land = (LockstepDrone.__init__, Tick.__init__, Tick.step,
                                         lockstep._land)
    advance_to = LockstepDrone.advance_to

    def new_drone_init(self, *args, **kwargs):
        drone_init(self, *args, **kwargs)
        flight.drone = self

    def new_tick_init(self, *args, **kwargs):
        tick_init(self, *args, **kwargs)
        flight.tick = self

    def watched_step(self, inputs, *, t_exp_s, **kwargs):
        flight.trail.append("step")
        flight.steps += 1
        t = float(t_exp_s).hex()
        n = flight.calls[t] = flight.calls.get(t, -1) + 1  # (a time stepped twice: apart)
        # a tick whose controller's call a block made already (its answer handed on) has
        # the stages' state of after that call: the drone's compared only
        flight.see(("step", t, n), stages_too=kwargs.get("answer") is None)
        return step(self, inputs, t_exp_s=t_exp_s, **kwargs)

    def watched_advance_to(self, *args, **kwargs):
        flight.trail.append("advance")
        return advance_to(self, *args, **kwargs)

    def progress(fraction: float) -> None:
        point = ("progress", len(flight.progress))
        trail = flight.trail
        if not flight.left_in_run:  # a run of calls begins: one a row written before it
            flight.left_in_run = next((n for n in range(len(trail))
                                       if trail[len(trail) - 1 - n] != "write"), len(trail))
        trail.append("progress")
        flight.progress.append(fraction)
        if flight.left_in_run:
            flight.left_in_run -= 1
            if not flight.left_in_run and flight.close_every:  # the run's last: its tick's
                flight.runs_of_rows += 1
                if flight.runs_of_rows % flight.close_every == 0 and flight.blocks is not None:
                    flight.blocks.close()
                    flight.closed.add(point)
        flight.see(point)

    def watched_land(*args, **kwargs):
        flight.at_loop_end = state(flight, release=True)
        return land(*args, **kwargs)

    if close_every:
        blocks_init = blocks_class.__init__

        def new_blocks_init(self, *args, **kwargs):
            blocks_init(self, *args, **kwargs)
            flight.blocks = self

    with monkeypatch.context() as m:
        if block_ticks is not None:
            m.setattr(lockstep, "BLOCK_TICKS", block_ticks)
        # the Luenberger observer's coefficients by Δt are the process' (earlier flights' fill
        # its step's table: a cache of a pure function): each flight starts with none known
        m.setattr(luenberger, "_SHARED_CACHES", OrderedDict())
        m.setattr(LockstepDrone, "__init__", new_drone_init)
        m.setattr(LockstepDrone, "advance_to", watched_advance_to)
        m.setattr(Tick, "__init__", new_tick_init)
        m.setattr(Tick, "step", watched_step)
        m.setattr(lockstep, "_land", watched_land)
        if close_every:
            m.setattr(blocks_class, "__init__", new_blocks_init)
        flight.result = lockstep.run_lockstep(
            cfg, recorder=flight.recorder if recorded else None, seed=seed, progress=progress)
    flight.after = state(flight, release=True)
    return flight


def fly_both(cfg, seed: int, monkeypatch, block_ticks: int | None = None, *,
             recorded: bool = True, close_every: int = 0) -> tuple:
    """The flight with blocks, then without, watched at the block flight's step entries and
    at its progress calls that :meth:`Flight.python_ticks` finds (and its chains closed:
    ``close_every``)."""
    block = fly(cfg, seed, monkeypatch, block_ticks=block_ticks, recorded=recorded,
                close_every=close_every)
    wanted = ({p for p in block.seen if p[0] == "step"} | block.python_ticks()
              | block.closed)
    block.seen = {p: s for p, s in block.seen.items() if p in wanted}
    plain = fly(cfg, seed, monkeypatch, block_ticks=0, wanted=wanted, recorded=recorded)
    return block, plain


def _kept(recorder: MemoryRecorder) -> list:
    """The rows the recorder keeps now, a block of rows (``runs/block_rows``) as its rows'
    cells made from its numbers now."""
    return [cells for row in recorder._rows
            for cells in (row.cells() if row.__class__.__name__ == "BlockRows" else (row,))]


def _events(recorder: MemoryRecorder) -> list:
    return [bits({k: v for k, v in e.items() if k != "wall_s"}) for e in recorder.events]


def _result(result) -> tuple:
    return (result.ticks, result.final_mode, result.run_dir, result.ending,
            bits(result.end_t_s))


def assert_same_flights(block: Flight, plain: Flight) -> None:
    """The two flights' rows, events, results and states bit for bit (module docstring);
    a failure tells each kind that differs, the first row and the first state in time that
    do (a state names the field: most often the cause of the rows')."""
    problems = [f"{name}: a row changed after it was written"
                for name, flight in (("blocks", block), ("per tick", plain))
                if [row_bits(r) for r in _kept(flight.recorder)] != flight.recorder.written]
    problems += _rows_apart(block.recorder.written, plain.recorder.written)
    ev_b, ev_p = _events(block.recorder), _events(plain.recorder)
    if ev_b != ev_p:
        k = next((k for k, (x, y) in enumerate(zip(ev_b, ev_p)) if x != y), min(len(ev_b),
                                                                               len(ev_p)))
        problems.append(f"events differ from #{k}: {ev_b[k:k + 1]} != {ev_p[k:k + 1]}")
    if _result(block.result) != _result(plain.result):
        problems.append(f"results: {_result(block.result)} != {_result(plain.result)}")
    if bits(block.progress) != bits(plain.progress):
        problems.append("progress(fraction) calls differ")
    missing = [p for p in block.seen if p not in plain.seen]
    if missing:
        problems.append(f"points the flight without blocks did not reach: {missing}")
    for point, seen in block.seen.items():  # in the order the block flight saw them
        other = plain.seen.get(point, {})
        if not any(name.startswith("tick.") for name in seen):  # (the drone's only)
            other = {name: v for name, v in other.items() if not name.startswith("tick.")}
        diff = differences(seen, other)
        if diff:
            where = (f"Tick.step's entry at t_exp_s {float.fromhex(point[1])} (call "
                     f"{point[2]})" if point[0] == "step"
                     else f"the progress call after tick {point[1]}")
            problems.append(f"state at {where} (the first that differs):\n  "
                            + "\n  ".join(diff))
            break
    for when, a, b in (("when the loop ended", block.at_loop_end, plain.at_loop_end),
                       ("after the flight", block.after, plain.after)):
        diff = differences(a or {}, b or {})
        if diff:
            problems.append(f"state {when}:\n  " + "\n  ".join(diff))
    assert not problems, "blocks != per tick:\n" + "\n".join(problems)


def _rows_apart(rows_b: list, rows_p: list) -> list[str]:
    """The first row that differs (its cells that do), and a count that does."""
    for i, (rb, rp) in enumerate(zip(rows_b, rows_p)):
        if rb != rp:
            cells = [f"{cb[0]}: {cb[1]!r} != {cp[1]!r}" for cb, cp in zip(rb[1], rp[1])
                     if cb != cp]
            return [f"row {i} (of {len(rows_p)}) differs, form {rb[0]} / {rp[0]}: "
                    + "; ".join(cells[:8])]
    if len(rows_b) != len(rows_p):
        return [f"rows: {len(rows_b)} with blocks, {len(rows_p)} without"]
    return []


def _config(config: str, overrides: list[str]):
    return load_config(CONFIGS / f"{config}.yaml", list(overrides))


# ---------------------------------------------------------------- the tests
def test_bits_tell_types_and_payloads_apart():
    """The comparison sees what ``==`` does not: a float's class, −0.0, a NaN's payload, an
    int for a float, an array's dtype."""
    nan2 = struct.unpack("<d", struct.pack("<Q", 0x7FF8000000000001))[0]
    pairs = [(1.5, np.float64(1.5)), (0.0, -0.0), (math.nan, nan2), (1, 1.0), (True, 1),
             (np.zeros(2), np.zeros(2, dtype=np.float32)), ((1.0,), [1.0])]
    for a, b in pairs:
        assert bits(a) != bits(b), (a, b)
    assert bits(math.nan) == bits(float("nan"))
    assert bits(np.array([1.0, math.nan])) == bits(np.array([1.0, math.nan]))


@pytest.mark.parametrize("name, config, overrides, seed", CASES, ids=[c[0] for c in CASES])
def test_blocks_change_nothing(name, config, overrides, seed, monkeypatch):
    """Each case with the module's blocks and without: the same bits (module docstring)."""
    assert_same_flights(*fly_both(_config(config, overrides), seed, monkeypatch))


@pytest.mark.parametrize("block_ticks, overrides", [
    (1, ["sim.mocap_rate_hz=30", "sim.navdata_rate_hz=10"]),  # blocks without a sample
    (7, []),
    (1000, []),
], ids=["1_slow_sensors", "7", "1000"])
def test_other_blocks_change_nothing(block_ticks, overrides, monkeypatch):
    """Blocks of other lengths than the default: their state written back and taken again
    at other ticks (1: every tick; 1000: a phase's ticks at most)."""
    cfg = _config("square", ["duration_s=12", *SETTLE, *overrides])
    assert_same_flights(*fly_both(cfg, 8, monkeypatch, block_ticks))


@pytest.mark.parametrize("block_ticks, close_every", [(None, 1), (7, 3)])
def test_chains_closed_mid_flight(block_ticks, close_every, monkeypatch):
    """A chain of blocks written back (``TickBlocks.close``) after every ``close_every``-th
    block's rows: the state then is the per-tick flight's after the same tick, and the
    flight goes on from it the same (blocks entered again from the Python objects)."""
    cfg = _config("square", ["duration_s=12", *SETTLE])
    block, plain = fly_both(cfg, 17, monkeypatch, block_ticks, close_every=close_every)
    assert len(block.closed) > 5
    assert_same_flights(block, plain)


def test_blocks_change_nothing_unrecorded(monkeypatch):
    """A flight without a recorder (its blocks' rows only counted): the same result,
    progress and states."""
    cfg = _config("square", ["duration_s=12", *SETTLE])
    assert_same_flights(*fly_both(cfg, 15, monkeypatch, recorded=False))


def test_blocks_take_the_square(monkeypatch):
    """The square's usual ticks go in blocks: far fewer ``Tick.step`` calls than rows (and
    without blocks, one a row)."""
    cfg = _config("square", ["duration_s=10", *SETTLE])
    plain = fly(cfg, 0, monkeypatch, block_ticks=0, wanted=set())
    rows = len(plain.recorder.written)
    assert plain.steps == rows > 100
    assert lockstep.BLOCK_TICKS > 1  # (blocks by default)
    block = fly(cfg, 0, monkeypatch, block_ticks=None, wanted=set())
    assert len(block.recorder.written) == rows
    assert block.steps * 4 < rows, f"{block.steps} Tick.step calls for {rows} rows"


@pytest.mark.parametrize("config, overrides", [
    ("ellipse", []), ("lorenz", []), ("identify", []),
    ("square", ["estimator.horizontal_velocity=navdata"]),
    ("square", ["estimator.kind=luenberger"]), ("altitude_luenberger", []),
    ("square", ["estimator.kind=luenberger", "controller.kind=p"]),
    ("square", ["estimator.kind=difference"]), ("altitude_none", []),
], ids=["ellipse", "lorenz", "identify", "navdata_velocity", "luenberger",
        "altitude_luenberger", "p_luenberger", "difference", "altitude_none"])
def test_blocks_take_the_curves_and_the_navdata_speeds(config, overrides, monkeypatch):
    """The curves' usual ticks (their states read from a table), those of ẋ, ẏ from the
    navdata's speeds and those of the other ż estimators go in blocks: far fewer
    ``Tick.step`` calls than rows."""
    cfg = _config(config, ["duration_s=10", *SETTLE, *overrides])
    block = fly(cfg, 0, monkeypatch, block_ticks=None, wanted=set())
    rows = len(block.recorder.written)
    assert rows > 100
    assert block.steps * 4 < rows, f"{block.steps} Tick.step calls for {rows} rows"


def test_blocks_take_a_logged_object(monkeypatch):
    """A flight whose mocap stream has a second object (logged, nothing else) goes in
    blocks: far fewer ``Tick.step`` calls than rows, every row with the object's cells."""
    cfg = _config("square", ["duration_s=10", *SETTLE, "sim.target.speed_mps=0.3"])
    block = fly(cfg, 0, monkeypatch, block_ticks=None, wanted=set())
    rows = block.recorder.written
    assert len(rows) > 100
    assert block.steps * 4 < len(rows), f"{block.steps} Tick.step calls for {len(rows)} rows"
    ages = block.recorder.columns()["target_age_ms"]
    assert np.isfinite(ages[1:]).all()


def test_a_followed_object_flies_blocks(monkeypatch):
    """``follow`` (its reference fed the object's pose each tick, its table filled in the
    block): far fewer ``Tick.step`` calls than rows, and the tally saw the object."""
    cfg = _config("follow_car", ["duration_s=10", *SETTLE])
    block = fly(cfg, 0, monkeypatch, block_ticks=None, wanted=set())
    rows = len(block.recorder.written)
    assert rows > 100 and block.steps * 4 < rows, f"{block.steps} Tick.step calls, {rows} rows"
    assert block.result.ending == "completed"  # (not failed-no-target)


def _case(name: str) -> tuple:
    return next(c for c in CASES if c[0] == name)


def test_fault_flights_fly_blocks_as_the_drones_own_chain(monkeypatch):
    """A faulted flight with blocks, and one without whose every PCMD goes through the
    drone's own chain (``SimulatedDrone.execute_pcmd``, its AT-loss decision asked: as
    before blocks flew faulted flights) — the same rows, events, result and states at the
    loop's end and after; and most of its ticks in blocks."""
    from ardrone_nmpc.sim.fault_injection import ServerFaults

    _, config, overrides, seed = _case("fault_mix")
    cfg = _config(config, overrides)
    block = fly(cfg, seed, monkeypatch, block_ticks=None, wanted=set())
    rows = len(block.recorder.written)
    assert block.steps * 3 < rows, f"{block.steps} Tick.step calls for {rows} rows"
    monkeypatch.setattr(ServerFaults, "at_loss_acts", lambda self, now_s: True)
    plain = fly(cfg, seed, monkeypatch, block_ticks=0, wanted=set())
    assert plain.steps == rows
    assert plain.drone.sim.faults.counters.at_lost > 0  # (the window drew)
    assert_same_flights(block, plain)


@pytest.mark.parametrize("name", ["fault_mocap_dropout", "wire_navdata_loss",
                                  "wire_repeated_dropout", "wire_disorder_navdata",
                                  "wire_sensor_rates", "wire_kit_turbulent"])
def test_sensor_fault_flights_fly_blocks_between_the_faults_windows(name, monkeypatch):
    """A flight with a fault on the sensors' bytes (every frame and packet through the
    wire: sim/wire_block) flies most of its ticks in blocks — the ticks outside the
    faults' windows — and the ticks inside them are ``Tick.step``'s."""
    _, config, overrides, seed = _case(name)
    block = fly(_config(config, overrides), seed, monkeypatch, block_ticks=None, wanted=set())
    rows = block.recorder.rows
    assert block.drone.sensors.wire
    assert block.steps * 3 < len(rows), f"{block.steps} Tick.step calls for {len(rows)} rows"


def test_a_wire_block_entered_with_the_com_watchdog_latched(monkeypatch):
    """A command lost at a Python tick of a wire flight (sent, never received: patched)
    leaves the firmware's com-watchdog bit latched when the next block begins; the block's
    first command clears it and each packet then shows the bit by its own time, as the
    per-tick path's (a block that kept the entry's bit in every packet's word logged it in
    50 rows: review of the wire's blocks)."""
    cfg = _config("square", ["duration_s=8", *SETTLE, "faults.mocap_dropout.start_s=3",
                             "faults.mocap_dropout.duration_s=0.2"])
    first = fly(cfg, 1, monkeypatch, block_ticks=None, wanted=set())
    stepped = sorted(float.fromhex(t) for t in first.calls)  # (a block follows the tick)
    lost_at = next(t for t in stepped if t > 0.5
                   and not any(abs(u - t - 0.065) < 1e-9 for u in stepped))
    set_command, entry = LockstepDrone.set_command, wire_block.wire_block_entry
    latched_at_entry = []

    def losing(self, *args, **kwargs):
        if abs(self.t_exp_s - lost_at) < 1e-9:
            self._seq += 1  # (its number taken)
            return None
        return set_command(self, *args, **kwargs)

    def watched(legs, d, seq):
        entered = entry(legs, d, seq)
        if entered and legs.firmware.comwdg_latched:
            latched_at_entry.append(seq)
        return entered

    monkeypatch.setattr(LockstepDrone, "set_command", losing)
    monkeypatch.setattr(wire_block, "wire_block_entry", watched)
    block, plain = fly_both(cfg, 1, monkeypatch)
    assert latched_at_entry
    assert_same_flights(block, plain)


def test_a_diverging_solver_flies_blocks_outside_its_window(monkeypatch):
    """A flight whose solver diverges from 3 s for 1 s: most of its ticks in blocks, every
    tick in the window ``Tick.step``'s with its solve marked diverged (the wrapper's), and
    the ticks after it back in blocks."""
    _, config, overrides, seed = _case("fault_solver_diverge")
    block = fly(_config(config, overrides), seed, monkeypatch, block_ticks=None, wanted=set())
    rows = block.recorder.rows
    assert block.steps * 3 < len(rows), f"{block.steps} Tick.step calls for {len(rows)} rows"
    window = [r for r in rows if 3.0 <= r["t_s"] < 4.0]
    assert len(window) > 10
    assert all(r["solver_status"] == "diverged" for r in window)
    assert all(float(r["t_s"]).hex() in block.calls for r in window)  # (Python's ticks)
    after = [r for r in rows if r["t_s"] >= 4.0 and r["mode"] == "track"]
    stepped = sum(float(r["t_s"]).hex() in block.calls for r in after)
    assert after and stepped * 3 < len(after), f"{stepped} of {len(after)} stepped after"


@pytest.mark.parametrize("period_s, n_settle", [(0.05, 20), (0.065, 15), (1 / 30, 31)])
def test_plain_ticks_end_before_the_first_tick_a_fault_may_act_at(period_s, n_settle):
    """``TickBlocks._plain_ticks``: the ticks from k on whose experiment time (the
    runner's expression) is below the drone's ``plain_until_s`` — at tick times exactly,
    between them, now, never."""
    class Drone:
        bound = math.inf

        def plain_until_s(self, t_s):
            return self.bound

    blocks = object.__new__(lockstep.TickBlocks)
    blocks.period_s, blocks.n_settle, blocks.drone = period_s, n_settle, Drone()
    t_exp = lockstep.Schedule.t_exp_s.__get__(blocks)  # (the same expression)
    for k in (0, 7, 40, 333):
        for bound in (t_exp(k), t_exp(k + 1), t_exp(k + 12), t_exp(k + 12) + 1e-12,
                      t_exp(k + 12) - 1e-12, t_exp(k) - 5.0, -math.inf, math.inf):
            blocks.drone.bound, blocks._unplain_k = bound, -1
            want = next((n for n in range(1000) if not t_exp(k + n) < bound), math.inf)
            assert blocks._plain_ticks(k) == want, (k, bound)
            if want > 2 and want < math.inf:  # kept: the ticks before it change nothing
                assert blocks._plain_ticks(k + 2) == want - 2


@pytest.mark.parametrize("overrides", [[], [KIT]], ids=["obstacle", "obstacle_kit"])
def test_blocks_take_the_obstacles(overrides, monkeypatch):
    """A static obstacle's flight goes in blocks (their kernel solving with the obstacle
    table), and a moving one's (its centre moved in the kernel: runtime/second_object)."""
    for config in ("obstacle", "moving_obstacle"):
        block = fly(_config(config, ["duration_s=10", *SETTLE, *overrides]), 0, monkeypatch,
                    block_ticks=None, wanted=set())
        rows = len(block.recorder.written)
        assert rows > 100 and block.steps * 4 < rows, (config, block.steps, rows)


def test_blocks_take_the_kit_square(monkeypatch):
    """The thesis_kit plant's square goes in blocks too (its dynamics in the legs)."""
    cfg = _config("square", ["duration_s=10", *SETTLE, KIT])
    block = fly(cfg, 0, monkeypatch, block_ticks=None, wanted=set())
    rows = len(block.recorder.written)
    assert rows > 100 and block.steps * 4 < rows, f"{block.steps} Tick.step calls, {rows} rows"


@pytest.mark.parametrize("config, overrides", [("square", []), ("square", [KIT]),
                                              ("obstacle", [])],
                         ids=["square", "square_kit", "obstacle"])
def test_blocks_take_the_newton_scheme(config, overrides, monkeypatch):
    """The thesis' Newton scheme's usual ticks go in blocks (their kernel calling its
    tick), with obstacles too."""
    cfg = _config(config, ["duration_s=10", *SETTLE, NEWTON, *overrides])
    block = fly(cfg, 0, monkeypatch, block_ticks=None, wanted=set())
    rows = len(block.recorder.written)
    assert rows > 100 and block.steps * 4 < rows, f"{block.steps} Tick.step calls, {rows} rows"
