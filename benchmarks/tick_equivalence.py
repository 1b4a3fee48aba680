"""Every row of ~30 lockstep flights, bit for bit, on two trees: is a change behaviour-neutral?

    python benchmarks/tick_equivalence.py record FILE [--only NAME,…]
    python benchmarks/tick_equivalence.py compare A B

``record`` flies each case (a config, ``--set`` overrides and a seed: clean flights of every
reference kind, both solvers, the P controller, both plant profiles, the estimators, the
disturbance options and every fault of the matrix) with the tree on ``sys.path`` and stores
every ``log.csv`` cell it would write (numbers as float64, strings as text) and every event
into ``FILE`` (a pickle). Run it on the base commit and on the change — e.g.
``git archive <commit> | tar -x -C /tmp/base`` then
``PYTHONPATH=/tmp/base python benchmarks/tick_equivalence.py record base.pkl`` — and
``compare`` prints, per case, whether the two are the same bits (the wall-clock columns
``solve_us``, ``compute_us``, ``tick_late_ms`` and the events' ``wall_s`` excepted), and the
first differing row and column when they are not. Exit 1 on any difference.
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLOCK_COLUMNS = frozenset({"solve_us", "compute_us", "tick_late_ms"})

# (name, config, overrides, seed): short flights, each through what its name says.
SHORT = ["duration_s=8", "sim.settle_s=1"]
SQUARE = ["duration_s=12", "sim.settle_s=1"]
KIT = ["sim.plant.profile=thesis_kit"]
NEWTON = ["controller.solver.method=newton"]
# Newton ticks that stop at their iterations above the tolerance (a share of them)
TIGHT = ["controller.solver.tolerance=2e-6", "controller.solver.max_newton_iterations=2"]
CASES: list[tuple[str, str, list[str], int]] = [
    ("hover", "hover", SHORT, 0),
    ("step_x", "step_x", SHORT, 1),
    ("step_y", "step_y", SHORT, 2),
    ("step_z", "step_z", SHORT, 3),
    ("step_psi", "step_psi", SHORT, 4),
    ("square", "square", ["duration_s=25"], 0),
    ("square_long", "square", ["duration_s=60"], 7),
    ("ellipse", "ellipse", ["duration_s=12"], 0),
    ("lorenz", "lorenz", ["duration_s=10"], 0),
    ("obstacle", "obstacle", ["duration_s=10"], 0),
    ("moving_obstacle", "moving_obstacle", ["duration_s=8"], 0),
    ("follow_car", "follow_car", ["duration_s=8"], 0),
    ("newton", "step_x", SHORT + ["controller.solver.method=newton"], 0),
    ("uncondensed", "step_z", SHORT + ["controller.solver.condensed=false"], 0),
    ("p_controller", "step_x", SHORT + ["controller.kind=p"], 0),
    ("kit", "step_x", SHORT + ["sim.plant.profile=thesis_kit"], 0),
    ("kit_convention", "step_x", SHORT + ["drone.command_convention=kit"], 0),
    ("luenberger", "altitude_luenberger", SHORT, 0),
    ("no_vz", "altitude_none", SHORT, 0),
    ("difference_vz", "step_z", SHORT + ["estimator.kind=difference"], 2),
    ("luenberger_square", "square", ["duration_s=25", "estimator.kind=luenberger"], 3),
    ("luenberger_p", "step_x", SHORT + ["estimator.kind=luenberger", "controller.kind=p"], 4),
    ("luenberger_dropout", "square", ["duration_s=12", "estimator.kind=luenberger",
                                      "faults.mocap_dropout.start_s=4",
                                      "faults.mocap_dropout.duration_s=0.3"], 5),
    ("navdata_velocity", "step_y", SHORT + ["estimator.horizontal_velocity=navdata"], 0),
    ("no_offset_free", "step_x", SHORT + ["controller.offset_free.enabled=false"], 0),
    ("no_delay_comp", "step_x", SHORT + ["controller.delay_compensation_s=0"], 0),
    ("disturbances", "hover", SHORT + ["sim.vz_gain=0.8", "sim.battery_sag_frac=0.3",
                                       "sim.navdata_velocity_bias_mps=[0.05,-0.03]",
                                       "sim.plant.turbulence_std_mps=0.3"], 5),
    ("wind", "hover", SHORT + ["faults.wind.velocity_mps=[0.6,0.2,0]"], 0),
    ("wind_gust", "square", ["duration_s=10", "faults.wind_gust.start_s=3"], 0),
    ("delay_jump", "step_x", SHORT + ["faults.delay_jump.start_s=2"], 0),
    ("battery_floor", "hover", SHORT + ["faults.battery_floor.start_s=3"], 0),
    ("emergency", "hover", SHORT + ["faults.emergency.start_s=3"], 0),
    ("self_land", "hover", SHORT + ["faults.self_land.start_s=3"], 0),
    ("at_loss", "hover", SHORT + ["faults.at_loss.start_s=3", "faults.at_loss.probability=0.7"],
     0),
    ("solver_diverge", "step_x", SHORT + ["faults.solver_diverge.start_s=2"], 0),
    ("mocap_dropout", "hover", SHORT + ["faults.mocap_dropout.start_s=3",
                                        "faults.mocap_dropout.duration_s=0.2"], 0),
    ("navdata_loss", "hover", SHORT + ["faults.navdata_loss.start_s=3"], 0),
    # a wind the drone cannot hold against blows it out of a fence round the reference
    ("geofence", "step_x", SHORT + ["safety.geofence_min_m=[-1.6,-3,0]",
                                    "faults.wind.velocity_mps=[-1.0,0,0]"], 0),
    ("low_battery_start", "hover", SHORT + ["sim.plant.battery_start_pct=22",
                                            "sim.plant.battery_drain_pct_per_min=30"], 0),
    ("altitude_cap", "step_z", SHORT + ["drone.altitude_max_m=1.3"], 0),
    # waypoint flights (the square's): the controller's one compiled call takes their usual
    # ticks (runtime/control_tick), the faults and options its tests hand to Python
    ("square_navdata_velocity", "square", SQUARE + ["estimator.horizontal_velocity=navdata"], 3),
    ("square_no_offset_free", "square", SQUARE + ["controller.offset_free.enabled=false"], 0),
    ("square_no_delay_comp", "square", SQUARE + ["controller.delay_compensation_s=0"], 0),
    ("square_mocap_dropout", "square", SQUARE + ["faults.mocap_dropout.start_s=4",
                                                 "faults.mocap_dropout.duration_s=0.2"], 0),
    ("square_navdata_loss", "square", SQUARE + ["faults.navdata_loss.start_s=4"], 0),
    ("square_at_loss", "square", SQUARE + ["faults.at_loss.start_s=4",
                                           "faults.at_loss.probability=0.7"], 0),
    ("square_delay_jump", "square", SQUARE + ["faults.delay_jump.start_s=4"], 0),
    ("square_battery_floor", "square", SQUARE + ["faults.battery_floor.start_s=6"], 0),
    # a drone that tilts a third of the model's: most nominal ticks saturate the command
    ("square_saturating", "square", SQUARE + ["controller.attitude_gain=0.3"], 0),
    # blocks of ticks (runtime/lockstep_block) fly the usual ticks of these: what ends a
    # block — a fit due, a leg the kernel leaves, a capped climb, an emptying battery —
    # and the samples a block's ticks take or not
    ("square_disturbances", "square", SQUARE + [
        "sim.vz_gain=0.8", "sim.battery_sag_frac=0.3",
        "sim.navdata_velocity_bias_mps=[0.05,-0.03]", "sim.plant.turbulence_std_mps=0.3"], 5),
    ("square_altitude_cap", "square", SQUARE + ["drone.altitude_max_m=1.1"], 0),
    ("square_fast_refit", "square", SQUARE + ["controller.adaptation.refit_s=0.2"], 2),
    ("square_fixed_response", "square", SQUARE + ["controller.delay_compensation_s=0.26",
                                                  "controller.attitude_gain=1.0"], 1),
    ("square_navdata_200hz", "square", SQUARE + ["sim.navdata_rate_hz=200"], 0),
    ("square_mocap_10hz", "square", SQUARE + ["sim.mocap_rate_hz=10"], 0),
    ("square_low_battery", "square", SQUARE + ["sim.plant.battery_start_pct=22",
                                               "sim.plant.battery_drain_pct_per_min=30"], 0),
    ("square_uncondensed", "square", SQUARE + ["controller.solver.condensed=false"], 0),
    # slow mocap against tight limits: hold and hover verdicts between blocks
    ("square_mocap_verdicts", "square", SQUARE + ["sim.mocap_rate_hz=10",
                                                  "safety.mocap_hold_ms=95",
                                                  "safety.mocap_hover_ms=105"], 0),
    # the sensors' faults through the wire (sim/sensors.py): every stream, each kind of act —
    # frames missing or zero, late, duplicated and reordered, packets corrupted, a blackout,
    # a repeated dropout — and the wire with a scripted target, the kit plant, turbulence
    ("square_occlusion", "square", SQUARE + ["faults.mocap_occlusion.start_s=4",
                                             "faults.mocap_occlusion.duration_s=0.3"], 0),
    ("square_occlusion_zero", "square", SQUARE + ["faults.mocap_occlusion.start_s=4",
                                                  "faults.mocap_occlusion.duration_s=0.3",
                                                  "faults.mocap_occlusion.zero_pose=true"], 0),
    ("square_mocap_latency", "square", SQUARE + ["faults.mocap_latency.start_s=4",
                                                 "faults.mocap_latency.duration_s=0.5",
                                                 "faults.mocap_latency.extra_latency_ms=120"], 0),
    ("square_disorder_mocap", "square", SQUARE + ["faults.disorder.start_s=3",
                                                  "faults.disorder.duration_s=2",
                                                  "faults.disorder.stream=mocap"], 1),
    ("square_disorder_navdata", "square", SQUARE + ["faults.disorder.start_s=3",
                                                    "faults.disorder.duration_s=2",
                                                    "faults.disorder.stream=navdata"], 2),
    ("square_navdata_corrupt", "square", SQUARE + ["faults.navdata_corrupt.start_s=4",
                                                   "faults.navdata_corrupt.duration_s=0.5"], 0),
    ("square_blackout", "square", SQUARE + ["faults.blackout.start_s=4",
                                            "faults.blackout.duration_s=0.3"], 0),
    ("square_repeated_dropout", "square", SQUARE + ["faults.mocap_dropout.start_s=3",
                                                    "faults.mocap_dropout.duration_s=0.1",
                                                    "faults.mocap_dropout.repeat_every_s=2"], 0),
    ("follow_car_dropout", "follow_car", ["duration_s=8", "faults.mocap_dropout.start_s=3",
                                          "faults.mocap_dropout.duration_s=0.2"], 0),
    ("kit_mocap_dropout", "square", SQUARE + KIT + ["faults.mocap_dropout.start_s=4",
                                                    "faults.mocap_dropout.duration_s=0.2"], 0),
    ("turbulent_mocap_dropout", "square", SQUARE + ["sim.plant.turbulence_std_mps=0.3",
                                                    "faults.mocap_dropout.start_s=4",
                                                    "faults.mocap_dropout.duration_s=0.2"], 5),
    # curves read from a table of their states (reference/experiment.tabulated) and ẋ, ẏ
    # from the navdata's speeds, in blocks: the identification flight's every axis, fits
    # between blocks (a lead that moves: the table's times), no offset-free shift
    ("identify", "identify", SHORT[1:] + ["duration_s=14", "reference.excitation.axis_s=2.4",
                                          "reference.excitation.rest_s=0.5",
                                          "reference.excitation.sweep_m=0.1"], 0),
    ("ellipse_fast_refit", "ellipse", SHORT + ["controller.adaptation.refit_s=0.2"], 1),
    ("lorenz_fast_refit", "lorenz", SHORT + ["controller.adaptation.refit_s=0.2"], 2),
    ("ellipse_no_offset_free", "ellipse", SHORT + ["controller.offset_free.enabled=false"], 0),
    ("ellipse_navdata_velocity", "ellipse", SHORT + ["estimator.horizontal_velocity=navdata"],
     3),
    ("square_navdata_velocity_bias", "square", SQUARE + [
        "estimator.horizontal_velocity=navdata", "sim.navdata_velocity_bias_mps=[0.05,-0.03]",
        "sim.plant.turbulence_std_mps=0.3"], 5),
    # injected faults that leave the sensors alone: blocks fly the ticks at which none acts
    # (runtime/lockstep_block), the per-tick path the ticks at which one may
    ("square_wind", "square", SQUARE + ["faults.wind.velocity_mps=[0.4,-0.2,0]"], 1),
    ("square_wind_gust", "square", SQUARE + ["faults.wind_gust.start_s=4",
                                             "faults.wind_gust.velocity_mps=[1.0,0.3,0]"], 0),
    ("square_emergency", "square", SQUARE + ["faults.emergency.start_s=5"], 0),
    ("square_self_land", "square", SQUARE + ["faults.self_land.start_s=5"], 0),
    ("square_outdoor_profile", "square",
     SQUARE + ["faults.outdoor_profile.euler_angle_max_rad=0.35"], 0),
    # a one-shot fault due in the settle phase, a delay jump, a short AT-loss window, a gust
    # between two ticks (no tick inside its window)
    ("square_fault_mix", "square", SQUARE + [
        "faults.battery_floor.start_s=-0.5", "faults.battery_floor.level_pct=60",
        "faults.delay_jump.start_s=3", "faults.delay_jump.delay_s=0.2",
        "faults.at_loss.start_s=6", "faults.at_loss.duration_s=0.2",
        "faults.at_loss.probability=0.5", "faults.wind_gust.start_s=8.013",
        "faults.wind_gust.duration_s=0.005"], 4),
    # a diverging solver: the compiled tick and blocks outside its window, Python inside —
    # a window in the track phase, and a short one across fits (a refit every 0.2 s)
    ("square_solver_diverge", "square", SQUARE + ["faults.solver_diverge.start_s=4",
                                                  "faults.solver_diverge.duration_s=1"], 0),
    ("square_solver_diverge_fit", "square", SQUARE + [
        "controller.adaptation.refit_s=0.2", "faults.solver_diverge.start_s=5.05",
        "faults.solver_diverge.duration_s=0.5"], 2),
    # faults during the landing the runner waits out (its descent in one call between them)
    ("square_landing_faults", "square", SQUARE + [
        "faults.at_loss.start_s=12.3", "faults.at_loss.duration_s=0.6",
        "faults.at_loss.probability=0.5", "faults.wind_gust.start_s=13.2",
        "faults.wind_gust.duration_s=0.3"], 2),
    # the thesis_kit plant (sim/plant_kit) in the compiled legs and blocks: its take-off,
    # flight and landing, the disturbances it feels, an emptying battery, the cap, and a
    # run of `reproduce` in the thesis' formulation (ẋ, ẏ from the navdata)
    ("kit_hover", "hover", SHORT + KIT, 0),
    ("kit_square", "square", SQUARE + KIT, 0),
    ("kit_square_disturbances", "square", SQUARE + KIT + [
        "sim.vz_gain=0.8", "sim.battery_sag_frac=0.3",
        "sim.navdata_velocity_bias_mps=[0.05,-0.03]", "sim.plant.turbulence_std_mps=0.3"], 5),
    ("kit_wind", "hover", SHORT + KIT + ["faults.wind.velocity_mps=[0.6,0.2,0]"], 0),
    ("kit_square_low_battery", "square", SQUARE + KIT + [
        "sim.plant.battery_start_pct=22", "sim.plant.battery_drain_pct_per_min=30"], 0),
    ("kit_altitude_cap", "step_z", SHORT + KIT + ["drone.altitude_max_m=1.3"], 0),
    ("kit_reproduce_thesis", "step_psi", SHORT + KIT + [
        "safety.geofence_min_m=[-50,-50,-1]", "safety.geofence_max_m=[50,50,50]",
        "controller.delay_compensation_s=0", "controller.vz_lead_s=null",
        "estimator.horizontal_velocity=navdata", "controller.attitude_gain=1",
        "controller.planned_tilt_frac=1", "controller.offset_free=false"], 0),
    # obstacles in the compiled controller's tick (control_tick_obstacles) and in blocks
    # (tick_block_obstacles); a moving one per tick (its centre fed between ticks)
    ("obstacle_kit", "obstacle", SHORT + KIT, 1),
    ("obstacle_navdata", "obstacle", SHORT + [
        "estimator.horizontal_velocity=navdata", "controller.offset_free.enabled=false"], 2),
    ("obstacle_gust", "obstacle", SHORT + [
        "faults.wind_gust.start_s=3.013", "faults.wind_gust.duration_s=0.3"], 3),
    ("moving_obstacle_kit", "moving_obstacle", SHORT + KIT, 4),
    # a second mocap object in blocks (runtime/second_object): a moving obstacle's frames,
    # noise and centres, the object logged alone; followed (its reference's table filled in
    # the kernel), in the object's frame and heading, without prediction, its pose stale on
    # some ticks (age 3 or 8 ms), on a figure 8 without noise, the kit with the navdata's
    # speeds, a gust between blocks
    ("moving_obstacle_long", "moving_obstacle", ["duration_s=30"], 3),
    ("moving_obstacle_fig8", "moving_obstacle", ["duration_s=12", "sim.target.path=figure8"],
     5),
    ("moving_obstacle_noiseless", "moving_obstacle", [
        "duration_s=12", "sim.noise.mocap_position_std_m=0"], 6),
    ("moving_obstacle_gust", "moving_obstacle", [
        "duration_s=12", "faults.wind_gust.start_s=3.013", "faults.wind_gust.duration_s=0.3"],
     7),
    ("moving_obstacle_navdata", "moving_obstacle", [
        "duration_s=12", "estimator.horizontal_velocity=navdata"], 8),
    ("target_logged", "hover", ["duration_s=8", "sim.target.object_name=car",
                                "sim.target.path=circle"], 2),
    ("follow_car_long", "follow_car", ["duration_s=20"], 9),
    ("follow_object_frame", "follow_car", [
        "duration_s=12", "reference.follow.offset_frame=object",
        "reference.follow.heading=object"], 1),
    ("follow_no_predict", "follow_car", ["duration_s=12", "reference.follow.predict=false"],
     2),
    ("follow_stale", "follow_car", ["duration_s=12", "reference.follow.max_age_ms=5"], 3),
    ("follow_fig8_noiseless", "follow_car", [
        "duration_s=12", "sim.target.path=figure8", "sim.noise.mocap_position_std_m=0"], 4),
    ("follow_kit_navdata", "follow_car", [
        "duration_s=12", "estimator.horizontal_velocity=navdata", *KIT], 5),
    ("follow_gust", "follow_car", ["duration_s=12", "faults.wind_gust.start_s=3.013",
                                   "faults.wind_gust.duration_s=0.3"], 6),
    ("follow_unseen", "follow_car", ["duration_s=6", "sim.target=null"], 7),  # (no-target)
    # blocks ending after a tick's legs or its controller's call with a second object (the
    # object drawn once for the tick's frame: review17's find)
    ("moving_obstacle_low_battery", "moving_obstacle", [
        "duration_s=10", "sim.settle_s=1", "sim.plant.battery_start_pct=23",
        "sim.plant.battery_drain_pct_per_min=30"], 7),
    ("follow_newton_tolerance", "follow_car", ["duration_s=8", "sim.settle_s=1", *NEWTON,
                                               *TIGHT], 1),
    # the thesis' Newton scheme in the compiled controller's tick (control_tick_newton) and
    # in blocks (tick_block_newton): clean flights, a waypoint and a curve's reference, the
    # kit plant, fits between blocks; ticks stopped above the tolerance (max-iterations:
    # Python's verdict), accepted or flown by the P fallback; a diverging solver; obstacles
    ("newton_square", "square", SQUARE + NEWTON, 0),
    ("newton_hover_kit", "hover", SHORT + KIT + NEWTON, 1),
    ("newton_ellipse", "ellipse", SHORT + NEWTON, 2),
    ("newton_square_wind_fit", "square", SQUARE + NEWTON + [
        "faults.wind.velocity_mps=[0.4,-0.2,0]", "controller.adaptation.refit_s=0.2"], 3),
    ("newton_square_tolerance", "square", SQUARE + NEWTON + TIGHT, 0),
    ("newton_square_rejected", "square", SQUARE + NEWTON + TIGHT + [
        "safety.solver_accept_max_iterations=false"], 2),
    ("newton_square_solver_diverge", "square", SQUARE + NEWTON + [
        "faults.solver_diverge.start_s=4", "faults.solver_diverge.duration_s=1"], 0),
    ("newton_obstacle", "obstacle", SHORT + NEWTON, 1),
    # the P controller (thesis eq. 4.16; the per-tick Python stages)
    ("p_square", "square", SQUARE + ["controller.kind=p"], 0),
    ("p_wind", "hover", SHORT + ["controller.kind=p", "faults.wind.velocity_mps=[0.6,0.2,0]"],
     1),
    ("p_delay_jump", "step_x", SHORT + ["controller.kind=p", "faults.delay_jump.start_s=2"], 2),
]


class _Capture:
    """A recorder that keeps every row and event: rows given as dicts or as cells."""

    path = None

    def __init__(self) -> None:
        self.rows: list[dict] = []
        self.events: list[tuple] = []

    def write_row(self, row) -> None:
        self.rows.append(dict(row))

    def write_cells(self, cells) -> None:
        """A row given as its cells in ``LOG_COLUMNS`` order (the lockstep runner's nominal
        tick, as the sweep's, tune's and simulate's recorders take it): kept as the dict
        ``write_row`` would have been given (``cells_row``, as ``MemoryRecorder.rows`` does),
        so the cases fly the cells path and compare with a record of the dict path."""
        from ardrone_nmpc.runs.log_columns import cells_row

        self.rows.append(cells_row(cells))

    def write_block(self, rows) -> None:
        """A block of rows (``runs/block_rows.BlockRows``, as ``MemoryRecorder`` and the
        bench take them): each row's cells kept as :meth:`write_cells` keeps them."""
        for cells in rows.cells():
            self.write_cells(cells)

    def event(self, t_s, kind, **fields) -> None:
        fields.pop("wall_s", None)
        self.events.append((t_s, kind, fields))


def _table(rows: list[dict]) -> tuple[np.ndarray, dict]:
    from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS

    numeric = [c for c in LOG_COLUMNS if c not in STRING_COLUMNS and c not in CLOCK_COLUMNS]
    values = np.full((len(rows), len(numeric)), np.nan)
    strings = {c: [] for c in STRING_COLUMNS}
    for i, row in enumerate(rows):
        for j, c in enumerate(numeric):
            v = row.get(c, math.nan)
            values[i, j] = math.nan if v is None or v == "" else float(v)
        for c in STRING_COLUMNS:
            v = row.get(c, "")
            strings[c].append(getattr(v, "value", v))
    return values, {"numeric": numeric, "strings": strings}


def _count_block_ticks() -> dict | None:
    """A tree with blocks of ticks (``runtime/lockstep_block``): their kernel loaded or
    compiled first (else a flight on a cold cache flies none), and a count of the ticks
    they fly (the gate compares them; a tree without: None)."""
    from ardrone_nmpc.runtime import lockstep

    if not hasattr(lockstep, "warm_up_blocks"):
        return None
    lockstep.warm_up_blocks()
    counts: dict = {}
    fly = lockstep.TickBlocks.fly

    def counted(self, *args):
        answer = fly(self, *args)
        counts["ticks"] = counts.get("ticks", 0) + answer[0]
        return answer

    lockstep.TickBlocks.fly = counted
    return counts


def record(path: str, only: set[str] | None) -> None:
    import ardrone_nmpc
    from ardrone_nmpc.config.io import load_config
    from ardrone_nmpc.runtime.lockstep import TakeoffRefused, run_lockstep

    out = {"tree": str(Path(ardrone_nmpc.__file__).parents[1]), "cases": {}}
    in_blocks = _count_block_ticks()
    for name, config, overrides, seed in CASES:
        if only and name not in only:
            continue
        cfg = load_config(ROOT / "configs" / f"{config}.yaml", overrides)
        capture = _Capture()
        t0 = time.perf_counter()
        try:
            result = run_lockstep(cfg, recorder=capture, seed=seed)
            ending = (result.ticks, result.ending, result.final_mode.value, result.end_t_s)
        except TakeoffRefused as err:
            ending = ("refused", str(err))
        wall = time.perf_counter() - t0
        values, meta = _table(capture.rows)
        out["cases"][name] = {"values": values, **meta, "events": capture.events,
                              "ending": ending}
        blocks = ""
        if in_blocks is not None:  # (kept: a compare of a block tree that flew none fails)
            out["cases"][name]["block_ticks"] = n_blocks = in_blocks.pop("ticks", 0)
            blocks = f" ({n_blocks} in blocks)"
        print(f"{name:<20} {len(capture.rows):5d} rows{blocks} {wall:6.2f} s  {ending}",
              flush=True)
    with open(path, "wb") as f:
        pickle.dump(out, f)


def _same(a, b) -> bool:
    return pickle.dumps(a) == pickle.dumps(b)


def compare(path_a: str, path_b: str) -> int:
    with open(path_a, "rb") as f:
        a = pickle.load(f)
    with open(path_b, "rb") as f:
        b = pickle.load(f)
    print(f"A: {a['tree']}\nB: {b['tree']}")
    bad = 0
    for name in a["cases"]:
        if name not in b["cases"]:  # not flown is not the same bits (a gate must not pass)
            print(f"{name:<20} missing in B")
            bad += 1
            continue
        ca, cb = a["cases"][name], b["cases"][name]
        problems = []
        va, vb = ca["values"], cb["values"]
        if va.shape != vb.shape:
            problems.append(f"shape {va.shape} vs {vb.shape}")
        else:
            diff = va.view(np.int64) != vb.view(np.int64)
            if diff.any():
                i, j = np.argwhere(diff)[0]
                problems.append(f"{diff.sum()} cells, first row {i} {ca['numeric'][j]}: "
                                f"{va[i, j]!r} vs {vb[i, j]!r}")
        for c, sa in ca["strings"].items():
            sb = cb["strings"].get(c)
            if sa != sb:
                i = next((k for k, (x, y) in enumerate(zip(sa, sb or [])) if x != y), None)
                problems.append(f"strings {c} first row {i}")
        if not _same(ca["events"], cb["events"]):
            k = next((k for k, (x, y) in enumerate(zip(ca["events"], cb["events"]))
                      if not _same(x, y)), min(len(ca["events"]), len(cb["events"])))
            problems.append(f"events differ from #{k}: "
                            f"{ca['events'][k:k + 1]} vs {cb['events'][k:k + 1]}")
        if ca["ending"] != cb["ending"]:
            problems.append(f"ending {ca['ending']} vs {cb['ending']}")
        bad += bool(problems)
        print(f"{name:<20} {'same bits' if not problems else '; '.join(problems)}")
    print(f"{len(a['cases']) - bad} of {len(a['cases'])} cases bit-identical")
    for side, cases in (("A", a["cases"]), ("B", b["cases"])):
        counts = [c["block_ticks"] for c in cases.values() if "block_ticks" in c]
        if counts and not sum(counts):  # a tree with blocks whose flights flew none: its
            print(f"{side}: no tick flown in blocks (their kernel not compiled?): the "
                  f"block path was not compared")  # block path compared with nothing
            bad += 1
    return 1 if bad else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    r = sub.add_parser("record")
    r.add_argument("file")
    r.add_argument("--only", default="")
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = parser.parse_args()
    if args.what == "record":
        record(args.file, set(filter(None, args.only.split(","))))
    else:
        sys.exit(compare(args.a, args.b))


if __name__ == "__main__":
    main()
