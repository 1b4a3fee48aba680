"""The lockstep runner's truth cells without a PlantTruth: :meth:`LockstepDrone.truth_cells`
through :func:`put_truth` gives the cells (keys in order, bits) :func:`truth_columns` takes
from a built :class:`PlantTruth` — for the airframe (through take-off and a turning climb, a
heading beyond ±π included), the kit plant and a plant of another backend."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.runs.log_columns import put_truth, truth_columns
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


# ----------------------------------------------------------------- the truth's cells
def _truth_cells_bits(drone):
    row: dict = {}
    put_truth(row, drone.truth_cells())
    old = truth_columns(drone.truth)
    assert list(row) == list(old)
    return ([np.float64(v).tobytes() for v in row.values()],
            [np.float64(v).tobytes() for v in old.values()])


@pytest.mark.parametrize("overrides", [[], ["sim.plant.profile=thesis_kit"]])
def test_truth_cells_are_the_truth_bit_for_bit(overrides):
    cfg = load_config(CONFIGS / "square.yaml", ["duration_s=5", *overrides])
    drone = LockstepDrone(cfg)
    assert drone._airframe
    drone.connect()
    drone.takeoff()
    t = drone.truth.t_s
    for k in range(120):  # take-off, then a turning climb
        t += cfg.loop.period_s
        drone.advance_to(t)
        if drone.truth.mode is FlightMode.FLYING:
            drone.set_command(0.1, -0.05, 0.2, 0.8)
        new, old = _truth_cells_bits(drone)
        assert new == old, k
    plant = drone.sim.plant
    for psi in (math.pi, -math.pi, 4.0, -7.5, 1e3):  # wrapped as PlantTruth wraps
        plant._state = (*plant._state[:8], psi, plant._state[9])
        new, old = _truth_cells_bits(drone)
        assert new == old, psi


def test_truth_cells_of_another_backend_come_from_its_truth():
    from tests.standins.airframe_emulator import AirframeEmulator

    cfg = load_config(CONFIGS / "hover.yaml", ["duration_s=2"])
    drone = LockstepDrone(cfg, plant=AirframeEmulator(seed=3))
    assert not drone._airframe
    drone.connect()
    drone.takeoff()
    drone.advance_to(drone.truth.t_s + 2.0)
    new, old = _truth_cells_bits(drone)
    assert new == old
