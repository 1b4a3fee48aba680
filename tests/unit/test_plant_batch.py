"""The plant's compiled run of FLYING substeps (with the heading's wrap and the navdata biases)
equals its step-by-step path bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.plant import AirframePlant


def _fly(cfg, *, batched: bool, monkeypatch, batched_steps: list | None = None) -> list[tuple]:
    original = AirframePlant._flying_advance

    def counted(self, n, h, wind, normals):
        done = original(self, n, h, wind, normals) if batched else 0
        if batched_steps is not None:
            batched_steps.append(done)
        return done

    monkeypatch.setattr(AirframePlant, "_flying_advance", counted)
    plant = AirframePlant.from_config(cfg.sim, cfg.drone, seed=3)
    rng = np.random.default_rng(11)
    plant.takeoff()
    trace = []
    for k in range(400):
        if k % 5 == 0:  # hold each command a while; dive now and then (ground contact)
            gaz = -1.0 if k % 60 == 0 else rng.uniform(-0.6, 0.6)
            plant.command(*rng.uniform(-0.5, 0.5, 2), gaz, rng.uniform(-0.5, 0.5),
                          progressive=k % 45 != 0)
        if k == 200:
            plant.wind_mps = np.array([0.4, -0.2, 0.1])
        plant.advance(rng.choice([0.003, 0.01, 0.065, 0.13]))
        t, nav = plant.truth, plant.navdata()  # navdata: the yaw offset and velocity biases
        trace.append((plant.t_s, plant.mode, plant.battery_pct, *t.position_m, *t.velocity_mps,
                      t.roll_rad, t.pitch_rad, t.psi_rad, t.psi_rate_radps, nav.yaw_deg,
                      nav.vx_body_mps, nav.vy_body_mps))
    monkeypatch.undo()
    return trace


@pytest.mark.parametrize("overrides", [
    [],                                              # the default 0.26 s command delay
    ["sim.plant.command_delay_s=0"],                 # commands act at once
    ["sim.plant.attitude_model=second_order"],       # two hidden states
    ["sim.plant.battery_drain_pct_per_min=100",      # empties the battery in flight
     "sim.plant.battery_start_pct=25"],
    ["sim.battery_sag_frac=0.4",                     # the vertical gain sags with it
     "sim.plant.battery_drain_pct_per_min=60"],
    ["sim.battery_sag_frac=0.4", "sim.plant.attitude_model=second_order"],
])
def test_batched_flying_advance_equals_the_step_by_step_path(overrides, monkeypatch):
    cfg = load_config(None, overrides)
    slow = _fly(cfg, batched=False, monkeypatch=monkeypatch)
    steps: list[int] = []
    fast = _fly(cfg, batched=True, monkeypatch=monkeypatch, batched_steps=steps)
    assert sum(steps) > 500  # the compiled path did fly many substeps
    assert fast == slow  # exact: same floats, modes, battery, time
    if "sim.plant.battery_start_pct=25" in overrides:  # the battery emptied in flight: it landed by itself
        assert slow[-1][2] == 0.0 and slow[-1][1] in (FlightMode.LANDING, FlightMode.LANDED)
    else:  # the dives touched the ground while flying
        assert any(row[5] == 0.0 and row[1] is FlightMode.FLYING for row in slow)


def test_a_backend_with_its_own_dynamics_keeps_the_step_by_step_path():
    from ardrone_nmpc.sim.plant_kit import KitPlant

    class OtherDynamics(KitPlant):  # neither the airframe's nor the kit's compiled steps
        def _motors_on_step(self, command, h, wind):
            return KitPlant._motors_on_step(self, command, h, wind)

    cfg = load_config(None, ["sim.plant.profile=thesis_kit"])
    plant = OtherDynamics.from_config(cfg.sim, cfg.drone, seed=0)
    assert type(plant)._motors_on_step is not AirframePlant._motors_on_step
    plant.takeoff()
    while plant.mode is not FlightMode.FLYING:
        plant.advance(0.065)
    assert plant._flying_advance(13, plant.params.integration_step_s, (0.0, 0.0, 0.0),
                                 np.zeros(3)) == 0


def test_the_compiled_wrap_is_the_wrap_bit_for_bit():
    import math

    from ardrone_nmpc.core.angles import TWO_PI, ieee_remainder, wrap_angle_deg, wrap_angle_rad
    from ardrone_nmpc.core.angle_kernels import wrap_half_turn

    rng = np.random.default_rng(0)
    angles = np.concatenate([rng.normal(0.0, 5.0, 3000), rng.normal(0.0, 1e4, 300),
                             np.arange(-9, 10) * math.pi, np.arange(-9, 10) * 180.0,
                             [0.0, -0.0, 1e300, -5e-324, math.inf, -math.inf, math.nan]])
    for a in angles.tolist():
        rad, deg = wrap_angle_rad(a), wrap_angle_deg(a)
        # bits, and NaN is NaN
        assert np.float64(wrap_half_turn(a, math.pi)).tobytes() == np.float64(rad).tobytes()
        assert np.float64(wrap_half_turn(a, 180.0)).tobytes() == np.float64(deg).tobytes()
        if math.isfinite(a):
            assert ieee_remainder(a, TWO_PI) == math.remainder(a, TWO_PI)
            assert ieee_remainder(a, 360.0) == math.remainder(a, 360.0)
