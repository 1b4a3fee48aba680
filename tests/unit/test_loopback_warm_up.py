"""The loopback's physics warm-up (sim/loopback.warm_physics): it flies a copy of the plant
through what the physics thread will run — so a cold numba cache compiles before the servers
start, not during the first take-off, where the stall once cost ``fly --sim`` its navdata
("take-off failed: navdata lost" on the first two flights of a fresh install) — and it leaves
the served plant exactly as it was."""

import pickle
import threading

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.backends import make_plant
from ardrone_nmpc.sim.loopback import warm_physics
from tests.standins.airframe_emulator import AirframeEmulator

_FLIGHT = (FlightMode.LANDED, FlightMode.TAKING_OFF, FlightMode.FLYING, FlightMode.LANDING,
           FlightMode.LANDED)


def _plants():
    for profile in ("ardrone", "thesis_kit"):
        cfg = load_config(None, [f"sim.plant.profile={profile}"])
        yield profile, make_plant(cfg.sim, cfg.drone, seed=11)
    yield "emulator", AirframeEmulator()


@pytest.mark.parametrize("name,plant", list(_plants()), ids=lambda v: v if isinstance(v, str) else "")
def test_the_warm_up_flies_a_whole_flight_on_a_copy(name, plant):
    before = pickle.dumps(plant)
    assert warm_physics(plant, 0.005) == _FLIGHT
    assert pickle.dumps(plant) == before  # state, clock, command, generator: untouched
    assert plant.mode is FlightMode.LANDED and plant.t_s == 0.0


def test_a_plant_that_refuses_the_take_off_is_only_copied():
    cfg = load_config(None, ["sim.plant.battery_start_pct=5"])
    plant = make_plant(cfg.sim, cfg.drone)
    assert plant.battery_pct < plant.params.takeoff_min_battery_pct  # refused below it
    assert warm_physics(plant, 0.005) == (FlightMode.LANDED,)


def test_a_plant_that_cannot_be_copied_is_served_cold():
    plant = AirframeEmulator()
    plant.lock = threading.Lock()  # a user's backend holding a lock: deepcopy refuses
    assert warm_physics(plant, 0.005) == ()
    assert plant.mode is FlightMode.LANDED


@pytest.mark.parametrize("model", ["lag", "second_order"])
def test_the_warm_up_reaches_the_plants_step_by_step_step(model, monkeypatch):
    """A late physics wake-up advances several steps at once: when the climb settles, or the
    battery empties, inside one, the plant flies the rest step by step (``_motors_on_step``:
    ``airframe_rk4``, or ``airframe_rk4_array`` for the second-order attitude) — a kernel the
    compiled take-off, flight and landing never call, so the warm-up must reach it too (else
    a cold cache compiles it in the physics thread at the end of the first take-off)."""
    from ardrone_nmpc.sim import plant as plant_module

    calls = []
    for name in ("airframe_rk4", "airframe_rk4_array"):
        kernel = getattr(plant_module, name)
        monkeypatch.setattr(plant_module, name,
                            lambda *a, _k=kernel, _n=name: calls.append(_n) or _k(*a))
    cfg = load_config(None, [f"sim.plant.attitude_model={model}"])
    plant = make_plant(cfg.sim, cfg.drone, seed=11)
    before = pickle.dumps(plant)
    assert warm_physics(plant, 0.005) == _FLIGHT
    assert set(calls) == {"airframe_rk4_array" if model == "second_order" else "airframe_rk4"}
    assert pickle.dumps(plant) == before


def test_a_plant_that_starts_aloft_is_warmed_too(monkeypatch):
    """An initial altitude above 0 starts the plant FLYING: no take-off to fly, but the flight
    and the landing still are (the physics thread flies them from its first step)."""
    from ardrone_nmpc.sim import plant as plant_module

    calls = []
    kernel = plant_module.flying_advance
    monkeypatch.setattr(plant_module, "flying_advance",
                        lambda *a: calls.append(1) or kernel(*a))
    cfg = load_config(None, ["sim.plant.initial_position_m=[0, 0, 1.0]"])
    plant = make_plant(cfg.sim, cfg.drone, seed=11)
    before = pickle.dumps(plant)
    assert warm_physics(plant, 0.005) == _FLIGHT[2:]
    assert len(calls) > 100
    assert pickle.dumps(plant) == before
