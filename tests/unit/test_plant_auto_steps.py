"""The plant's compiled steps of the automatic take-off and landing (sim/plant_step.py
``auto_steps``, :meth:`AirframePlant._auto_advance`) equal its step-by-step path bit for bit:
the state, hidden attitude states, mode changes (flying, touch-down, an empty battery
landing), battery, clock, command ring and biases after every advance."""

from __future__ import annotations

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.plant import AirframePlant


def _snapshot(plant) -> tuple:
    return (plant._state, plant._tilt_aux, plant._mode, plant._battery, plant._steps,
            plant._pending_s, plant._fifo.head, plant._fifo.rows.tobytes(), plant._yaw_bias_deg,
            plant._vel_bias, plant._gust_mps, plant._current)


def _fly(cfg, *, compiled: bool, monkeypatch, compiled_steps: list,
         empty_at_takeoff: bool) -> list[tuple]:
    original = AirframePlant._auto_advance

    def counted(self, n, h, wind):
        done = original(self, n, h, wind) if compiled else 0
        compiled_steps.append(done)
        return done

    monkeypatch.setattr(AirframePlant, "_auto_advance", counted)
    plant = AirframePlant.from_config(cfg.sim, cfg.drone, seed=5)
    rng = np.random.default_rng(17)
    trace = []
    for flight in range(3):
        plant.set_battery_pct(max(plant.battery_pct, 30.0))
        assert plant.takeoff()
        if empty_at_takeoff:  # it empties during the climb: it lands
            plant.set_battery_pct(0.5)
        for k in range(160):
            if k % 7 == 0:  # commands queue in the ring (ignored until flying)
                plant.command(*rng.uniform(-0.5, 0.5, 4), progressive=k % 21 != 0)
            if k == 100:
                plant.land()
            if k == 60 + flight:
                plant.wind_mps = np.array([0.3, -0.1, 0.05 * flight])
            plant.advance(rng.choice([0.003, 0.01, 0.0608, 0.13]))
            trace.append(_snapshot(plant))
            if plant.mode is FlightMode.LANDED:
                break
    monkeypatch.undo()
    return trace


@pytest.mark.parametrize("overrides,empty", [
    ([], False),
    (["sim.plant.command_delay_s=0"], False),            # no ring
    (["sim.plant.attitude_model=second_order"], False),  # hidden states, kept at touch-down
    (["sim.battery_sag_frac=0.4", "sim.plant.battery_drain_pct_per_min=60"], False),  # sag
    (["sim.plant.battery_drain_pct_per_min=100"], True),  # empties in the climb: it lands
    (["sim.plant.turbulence_std_mps=0.4"], False),
])
def test_compiled_take_off_and_landing_equal_the_step_by_step_path(overrides, empty,
                                                                   monkeypatch):
    cfg = load_config(None, overrides)
    slow_steps: list[int] = []
    slow = _fly(cfg, compiled=False, monkeypatch=monkeypatch, compiled_steps=slow_steps,
                empty_at_takeoff=empty)
    fast_steps: list[int] = []
    fast = _fly(cfg, compiled=True, monkeypatch=monkeypatch, compiled_steps=fast_steps,
                empty_at_takeoff=empty)
    modes = {snap[2] for snap in fast}
    assert FlightMode.LANDED in modes and (FlightMode.FLYING in modes) != empty
    assert sum(slow_steps) == 0 and sum(fast_steps) > 300  # the compiled path flew them
    assert len(fast) == len(slow)
    for i, (a, b) in enumerate(zip(fast, slow)):
        assert a == b, f"advance {i}"


@pytest.mark.parametrize("name", ["_substep", "_motors_on_step", "_auto_command",
                                  "_ground_contact", "_check_transitions", "_at_rest"])
def test_a_plant_that_overrides_the_automatic_steps_keeps_them(name):
    """A backend overriding any part of the steps auto_steps does (its own dynamics, say)
    takes them one by one, so its override runs."""
    cfg = load_config(None, [])
    base = getattr(AirframePlant, name)
    override = staticmethod(lambda state: base(state)) if name == "_at_rest" else (
        lambda self, *a, **k: base(self, *a, **k))
    Overriding = type("Overriding", (AirframePlant,), {name: override})
    for kind, expected in ((AirframePlant, True), (Overriding, False)):
        plant = kind.from_config(cfg.sim, cfg.drone, seed=1)
        plant.takeoff()
        assert (plant._auto_advance(4, 0.005, (0.0, 0.0, 0.0)) == 4) == expected
