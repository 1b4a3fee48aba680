"""The plant's and the sampler's attributes held in the compiled legs' arrays between runs
(sim/held_state.py, sim/lockstep_legs.py) behave as the attributes themselves: a copy, a
deep copy or a pickle of a held plant or sampler carries its state; a write while held is
what the truth and the next PCMD see, as on the Python path."""

import copy
import pickle

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
CFG = load_config(str(ROOT / "configs" / "square.yaml"), [])

# the plant's and the sampler's attributes the legs hold (sim/lockstep_legs.py)
PLANT_HELD = ("_state", "_tilt_aux", "_steps", "_pending_s", "_battery", "_yaw_bias_deg",
              "_vel_bias", "_gust_mps", "_current")
SENSORS_HELD = ("_next_mocap_k", "_next_nav_k")


def _flying(legs: bool, plant=None) -> LockstepDrone:
    """A drone a few ticks into its flight: with ``legs`` (and legs), the arrays hold its
    state."""
    drone = LockstepDrone(CFG, plant=plant)
    if not legs:
        drone.sensors._legs = drone._legs = None
    period = CFG.loop.period_s
    drone.connect()
    drone.takeoff()
    while drone.truth.mode is not FlightMode.FLYING:
        drone.advance_to(drone.truth.t_s + period)
    t0 = drone.truth.t_s
    for k in range(1, 4):
        drone.advance_to(t0 + k * period)
        drone.set_command(0.1, -0.05, 0.1, 0.02)
    if legs and drone.sensors._legs is not None:
        assert drone.sensors._legs.held() and "_state" not in vars(drone.sim.plant)
    return drone


def _values(obj, names):
    return tuple(getattr(obj, name) for name in names)


@pytest.mark.parametrize("how", ["copy", "deepcopy", "pickle"])
def test_a_held_plant_or_sampler_copies_with_its_state(how):
    """copy.copy, copy.deepcopy (sim/loopback.warm_physics flies a plant's deep copy) and
    pickle see the held attributes too: the copy holds the Python path's values, its own."""
    clone = {"copy": copy.copy, "deepcopy": copy.deepcopy,
             "pickle": lambda obj: pickle.loads(pickle.dumps(obj))}[how]
    python, compiled = _flying(False), _flying(True)
    plant = clone(compiled.sim.plant)
    assert _values(plant, PLANT_HELD) == _values(python.sim.plant, PLANT_HELD)
    assert plant._held_by is None
    if how == "copy":  # (a sampler's deep copy takes its drone's lock: not copyable)
        sensors = clone(compiled.sensors)
        assert _values(sensors, SENSORS_HELD) == _values(python.sensors, SENSORS_HELD)
    # the original flies on as the Python path's
    for drone in (python, compiled):
        drone.advance_to(drone.truth.t_s + CFG.loop.period_s)
    assert (_values(compiled.sim.plant, PLANT_HELD)
            == _values(python.sim.plant, PLANT_HELD))


def test_a_held_attribute_of_an_object_its_holder_does_not_hold_is_an_attribute_error():
    """An object carrying another's holder (a clone made from ``vars`` while held): a read of
    a held attribute it lacks is an AttributeError — getattr's default, hasattr work — not a
    KeyError."""
    drone = _flying(True)
    plant = drone.sim.plant
    clone = type(plant).__new__(type(plant))
    clone.__dict__.update(vars(plant))
    assert getattr(clone, "_battery", "missing") == "missing"
    assert not hasattr(clone, "_state")
    with pytest.raises(AttributeError, match="_state"):
        clone._state
    assert copy.copy(clone)._held_by is None  # not the holder's to hold
    assert "_state" in vars(plant)  # (the original: released, its own state)


def test_a_write_while_held_is_what_the_truth_reads():
    """A battery fault or a moved plant written while the arrays hold the state: the truth
    (and its logged cells) read the written values, not the last run's."""
    shots = []
    for legs in (False, True):
        drone = _flying(legs)
        plant = drone.sim.plant
        plant.set_battery_pct(50.0)
        battery = drone.truth.battery_pct
        moved = (1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0.0, 0.0, 0.5, 0.0)
        plant._state = moved  # (a test's teleport: no read first)
        shots.append((battery, drone.truth_cells(), drone.truth.position_m.tolist(),
                       plant._state))
    assert shots[0] == shots[1]
    assert shots[1][0] == 50.0


def test_a_write_while_held_is_what_the_logged_cells_and_the_cap_read_first():
    """A moved plant written while the arrays hold the state, read first by the logged
    truth cells (LockstepDrone.truth_cells reads the run's floats itself) — or first by a
    climbing PCMD's altitude-cap check (CompiledLegs.command, the same): the written state,
    as on the Python path."""
    moved = (1.0, 2.0, 2.95, 0.1, 0.2, 0.3, 0.0, 0.0, 0.5, 0.0)  # just under the 3 m cap
    for first in ("cells", "pcmd"):
        shots = []
        for legs in (False, True):
            drone = _flying(legs)
            fw, plant = drone.sim.firmware, drone.sim.plant
            plant._state = moved  # (a test's teleport: no read first)
            if first == "cells":
                shots.append(drone.truth_cells())
            drone.set_command(0.0, 0.0, 0.5, 0.0)
            shots.append((fw.alt_capped, fw.applied, plant._current, drone.truth_cells()))
        assert shots[: len(shots) // 2] == shots[len(shots) // 2:], first
        assert shots[-1][-1][:3] == moved[:3] and shots[-1][0], first  # capped: z + lead·ż


def test_a_plant_command_while_held_then_a_pcmd():
    """The plant commanded directly while held (a write of its command), then the tick's
    PCMD through the drone: the PCMD is the plant's command, as on the Python path."""
    shots = []
    for legs in (False, True):
        drone = _flying(legs)
        drone.sim.plant.command(0.3, 0.3, 0.0, 0.0)
        drone.set_command(0.2, -0.05, 0.1, 0.02)
        current = drone.sim.plant._current
        drone.advance_to(drone.truth.t_s + CFG.loop.period_s)
        shots.append((current, drone.truth_cells(), drone.sim.plant._state))
    assert shots[0] == shots[1]



@pytest.mark.parametrize("owner,name", [("plant", "_battery"), ("plant", "_tilt_aux"),
                                        ("plant", "_state"), ("sensors", "_next_nav_k")])
def test_a_class_default_of_a_held_attribute_keeps_the_python_path(owner, name, monkeypatch):
    """A subclass (a test's emulator) giving a held attribute a class-level default shadows
    the base's HeldInArrays: while held, a read would give that default, not the flight's
    value, and release nothing. Such a plant or sampler flies the Python path: its reads are
    the plain Python path's."""
    from ardrone_nmpc.sim import lockstep_drone as lockstep_module
    from ardrone_nmpc.sim.plant import AirframePlant
    from ardrone_nmpc.sim.sensors import LockstepSensors

    base = {"plant": AirframePlant, "sensors": LockstepSensors}[owner]
    kind = type("Shadowing", (base,), {name: None})
    if owner == "sensors":
        monkeypatch.setattr(lockstep_module, "LockstepSensors", kind)
    plant = kind.from_config(CFG.sim, CFG.drone) if owner == "plant" else None
    drone = _flying(True, plant=plant)
    obj = {"plant": drone.sim.plant, "sensors": drone.sensors}[owner]
    assert type(obj) is kind
    python = _flying(False)
    names = PLANT_HELD if owner == "plant" else SENSORS_HELD
    assert _values(obj, names) == _values(
        {"plant": python.sim.plant, "sensors": python.sensors}[owner], names)
    assert drone.sensors._legs is None
