"""The kit plant's compiled steps of the lockstep legs (plant_kit.kit_flying_steps,
kit_auto_steps) give the bits of KitPlant's Python step (``_substep`` with its
``_motors_on_step``, ``_ground_contact``, ``_at_rest``, ``_check_transitions``): one plant
stepped in Python, its state, channels, battery, delay ring and mode copied into arrays and
stepped by the kernel beside it, compared after every step — changing commands, wind, a
sagging and mismatched vertical gain, the take-off to its hand-over, the landing to its
touch-down, a battery that empties."""

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.numerics import callable_from_python
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.backends import make_plant
from ardrone_nmpc.sim.plant_kit import KitPlant, kit_auto_steps, kit_flying_steps
from ardrone_nmpc.sim.plant_step import AUTO_FLYING, AUTO_LANDED, AUTO_LANDING, AUTO_SAME

_flying = callable_from_python(kit_flying_steps)
_auto = callable_from_python(kit_auto_steps)
_MODES = {AUTO_SAME: None, AUTO_FLYING: FlightMode.FLYING, AUTO_LANDING: FlightMode.LANDING,
          AUTO_LANDED: FlightMode.LANDED}
DISTURBED = ["sim.battery_sag_frac=0.3", "sim.vz_gain=0.85"]


def _plant(overrides) -> KitPlant:
    cfg = load_config(None, ["sim.plant.profile=thesis_kit", *overrides])
    plant = make_plant(cfg.sim, cfg.drone, seed=3)
    assert isinstance(plant, KitPlant)
    return plant


def _bits(plant) -> tuple:
    """The plant's stepped state as bits (the tuple's floats, the arrays' bytes)."""
    return (np.array(plant._state).tobytes(), plant._kit.tobytes(),
            np.float64(plant._battery).tobytes(), plant._fifo.head,
            plant._fifo.rows.tobytes(), plant._mode)


class _Arrays:
    """The plant's state as the kernels take it, stepped one step at a time."""

    def __init__(self, plant: KitPlant) -> None:
        self.plant = plant
        self.state = np.array(plant._state, dtype=np.float64)
        self.kit = plant._kit.copy()
        self.ring = plant._fifo.rows.copy()
        self.head, self.battery, self.mode = plant._fifo.head, plant._battery, plant._mode

    def step(self, wind: tuple) -> None:
        p, plant = self.plant.params, self.plant
        h, drain = p.integration_step_s, p.battery_drain_pct_per_min * p.integration_step_s / 60
        roll, pitch, gaz, yaw, hold = plant._current
        if self.mode is FlightMode.FLYING:
            done, self.head, self.battery = _flying(
                self.state, self.kit, self.ring, self.head, roll, pitch, gaz, yaw, hold,
                plant._coefficients, wind, h, 1, self.battery, drain, p.vz_gain,
                p.battery_sag_frac)
            assert done == 1
            return
        landing = self.mode is FlightMode.LANDING
        done, self.head, self.battery, mode = _auto(
            self.state, self.kit, self.ring, self.head, roll, pitch, gaz, yaw, hold, landing,
            plant._auto_command(self.mode)[2], plant._coefficients, wind, h, 1, self.battery,
            drain, p.vz_gain, p.battery_sag_frac, p.tau_vz_s, p.takeoff_altitude_m)
        assert done == 1
        self.mode = _MODES[mode] or self.mode

    def bits(self) -> tuple:
        return (self.state.tobytes(), self.kit.tobytes(), np.float64(self.battery).tobytes(),
                self.head, self.ring.tobytes(), self.mode)


def _step_both(plant: KitPlant, arrays: _Arrays, wind: tuple) -> None:
    plant._substep(plant.params.integration_step_s, wind)
    arrays.step(wind)
    assert arrays.bits() == _bits(plant)


@pytest.mark.parametrize("overrides", [[], DISTURBED], ids=["nominal", "disturbed"])
def test_the_compiled_kit_steps_are_the_python_steps_bits(overrides):
    plant = _plant(overrides)
    assert plant.takeoff()
    arrays = _Arrays(plant)
    steps = {FlightMode.TAKING_OFF: 0, FlightMode.FLYING: 0, FlightMode.LANDING: 0}
    for k in range(3000):
        mode = plant._mode
        if mode is FlightMode.LANDED:
            break
        steps[mode] += 1
        if mode is FlightMode.FLYING:
            if k % 37 == 0:  # commands of both signs, hover now and then
                plant.command(0.4 * ((k // 74) % 3 - 1), -0.3 + 0.1 * (k % 5), 0.2 - 0.05
                              * (k % 7), 0.3 * ((k // 111) % 2) - 0.15,
                              progressive=(k // 37) % 5 != 4)
            if steps[mode] == 1500:
                assert plant.land()
                arrays.mode = plant._mode
        wind = (0.3, -0.2, 0.05) if k % 400 > 150 else (0.0, 0.0, 0.0)
        _step_both(plant, arrays, wind)
    assert plant._mode is FlightMode.LANDED  # the touch-down: at rest, the channels at 0
    assert not plant._kit.any() and plant._state[2] == 0.0
    assert min(steps.values()) > 100  # each mode stepped many times


def test_a_take_off_whose_battery_empties_lands_as_the_python_step_does():
    plant = _plant(["sim.plant.battery_start_pct=2", "sim.plant.battery_drain_pct_per_min=100",
                    *DISTURBED])
    plant.params = plant.params.replace(takeoff_min_battery_pct=0.0)
    assert plant.takeoff()
    arrays = _Arrays(plant)
    modes = []
    for _ in range(3000):
        if plant._mode is FlightMode.LANDED:
            break
        _step_both(plant, arrays, (0.1, 0.0, 0.0))
        modes.append(plant._mode)
    assert FlightMode.LANDING in modes and plant._battery == 0.0
