"""The kit plant's compiled flying advance (plant_kit.kit_flying_advance) gives the bits of the
step-by-step path it stands for: two kit plants of one seed, one made to take every step in
Python, flown alike — commands, odd advance lengths, wind, turbulence, battery sag, a delay
jump, a battery that empties — hold the same state, kit state, battery, biases and samples."""

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.backends import make_plant
from ardrone_nmpc.sim.plant_kit import KitPlant


def _plant(overrides, python: bool):
    cfg = load_config(None, ["sim.plant.profile=thesis_kit", *overrides])
    plant = make_plant(cfg.sim, cfg.drone, seed=3)
    assert isinstance(plant, KitPlant)
    used = [0]
    if python:
        plant._flying_advance = lambda n, h, wind, normals: 0
    else:
        compiled = plant._flying_advance

        def counted(n, h, wind, normals):
            done = compiled(n, h, wind, normals)
            used[0] += done
            return done
        plant._flying_advance = counted
    return plant, used


def _bits(v):
    if isinstance(v, np.ndarray):
        return v.tobytes()
    if isinstance(v, tuple):
        return tuple(_bits(x) for x in v)
    if isinstance(v, float):
        return np.float64(v).tobytes()
    return v


def _snapshot(plant):
    nav, pose, truth = plant.navdata(), plant.mocap_pose(), plant.truth
    return (_bits(plant._state), plant._kit.tobytes(), _bits(plant._battery), plant._steps,
            _bits(plant._pending_s), _bits(plant._yaw_bias_deg), _bits(plant._vel_bias),
            _bits(plant._gust_mps), plant.mode,
            tuple(_bits(getattr(nav, f)) for f in nav.__slots__),
            tuple(_bits(getattr(pose, f)) for f in pose.__slots__),
            tuple(_bits(getattr(truth, f)) for f in truth.__slots__))


def _fly(plant, steps=600):
    shots = []
    plant.takeoff()
    for k in range(steps):
        if plant.mode is FlightMode.FLYING:
            plant.command(0.2 * ((k // 40) % 3 - 1), -0.1, 0.3 * ((k // 25) % 2) - 0.1, 0.05)
        plant.wind_mps = np.array([0.3, -0.2, 0.0]) if k > 100 else np.zeros(3)
        plant.advance((0.0173, 0.065, 0.003, 0.01)[k % 4])
        if k == 300:
            plant.set_command_delay_s(0.4)  # a delay jump: the ring resized
        shots.append(_snapshot(plant))
    return shots


CASES = {
    "plain": [],
    "sag_and_turbulence": ["sim.battery_sag_frac=0.3", "sim.plant.turbulence_std_mps=0.4",
                           "sim.noise.navdata_velocity_std_mps=0.05"],
    "battery_empties": ["sim.plant.battery_start_pct=22",
                        "sim.plant.battery_drain_pct_per_min=100"],
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_kit_flying_advance_gives_the_step_by_step_bits(name):
    python, _ = _plant(CASES[name], python=True)
    compiled, used = _plant(CASES[name], python=False)
    a, b = _fly(python), _fly(compiled)
    assert used[0] > 1000  # the compiled steps flew most of it
    if name == "battery_empties":  # … up to the step that empties it, the plant's own
        assert python._battery == 0.0 and python.mode is not FlightMode.FLYING
    for i, (x, y) in enumerate(zip(a, b)):
        assert x == y, f"advance {i}"
