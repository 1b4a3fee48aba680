"""The lockstep loop's drone calls, one a side of a tick: :meth:`LockstepDrone.advance_inputs`
is ``advance_to``, ``take_events`` and ``inputs``, :meth:`LockstepDrone.command_truth` is
``set_command`` and ``truth_cells`` — two drones of one seed, one called each way with the
same commands, give the same answers and hold the same state on every tick: clean (the
compiled legs), without the compiled legs, and with faults whose events the calls hand over
(a wind gust, a battery floor, a self-landing; AT loss, which drops commands)."""

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

from tests.unit.test_lockstep_legs import ROOT, _record, _snapshot, _zigzag


def _answers(events, inputs, cells):
    return (events, inputs.t_s, inputs.pose_rx_t_s, inputs.navdata_rx_t_s, inputs.target_rx_t_s,
            _record(inputs.pose), _record(inputs.navdata), _record(inputs.target), cells)


def _fly(cfg, combined: bool, legs: bool, ticks: int):
    drone = LockstepDrone(cfg)
    if not legs:
        drone.sensors._legs = drone._legs = None
    period = cfg.loop.period_s
    drone.connect()
    drone.takeoff()
    while drone.truth.mode is not FlightMode.FLYING:
        drone.advance_to(drone.truth.t_s + period)
    t_first = drone.truth.t_s
    drone.start_experiment(t_first)
    shots, n_events = [], 0
    for k in range(ticks):
        t, t_exp = t_first + k * period, k * period
        roll, pitch, gaz, yaw = _zigzag(k)
        progressive = k % 9 != 0  # a hover now and then
        if combined:
            events, inputs = drone.advance_inputs(t, t_exp)
            cells = drone.command_truth(roll, pitch, gaz, yaw, progressive=progressive)
        else:
            drone.advance_to(t, t_exp)
            events, inputs = drone.take_events(), drone.inputs(t)
            drone.set_command(roll, pitch, gaz, yaw, progressive=progressive)
            cells = drone.truth_cells()
        n_events += len(events)
        shots.append(_answers(events, inputs, cells))
        if k % 17 == 0:  # every attribute now and then (the arrays give them back)
            shots.append(_snapshot(drone, t))
    shots.append(_snapshot(drone, t))
    return shots, n_events, drone


@pytest.mark.parametrize("overrides, legs, events", [
    ([], True, False),
    ([], False, False),
    (["sim.plant.turbulence_std_mps=0.3"], True, False),
    (["faults.wind_gust.start_s=3"], True, True),
    (["faults.battery_floor.start_s=3"], True, True),
    (["faults.self_land.start_s=3"], True, True),
    (["faults.at_loss.start_s=3", "faults.at_loss.probability=0.5"], True, False),
])
def test_one_call_a_side_of_a_tick_is_the_calls_it_stands_for(overrides, legs, events):
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), ["duration_s=20", *overrides])
    separate, n_separate, _ = _fly(cfg, False, legs, 200)
    combined, n_combined, drone = _fly(cfg, True, legs, 200)
    assert (drone.sensors._legs is not None) == legs
    assert n_combined == n_separate and (n_combined > 0) == events
    assert len(combined) == len(separate)
    for i, (a, b) in enumerate(zip(separate, combined)):
        assert a == b, f"shot {i}"
