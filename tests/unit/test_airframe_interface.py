"""Every airframe the simulated drone flies offers the members its firmware, sensors and
faults read (sim.backends.Airframe): our plants and the independent emulator alike — the
emulator once lacked the altitude the firmware's cap reads, and every emulator flight failed."""

import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.sim.backends import Airframe, make_plant
from ardrone_nmpc.sim.drone import SimulatedDrone
from tests.standins.airframe_emulator import AirframeEmulator


def _plants():
    for profile in ("ardrone", "thesis_kit"):
        cfg = load_config(None, [f"sim.plant.profile={profile}"])
        yield profile, make_plant(cfg.sim, cfg.drone)
    yield "emulator", AirframeEmulator()


@pytest.mark.parametrize("name,plant", list(_plants()), ids=lambda v: v if isinstance(v, str) else "")
def test_each_airframe_offers_the_simulated_drones_interface(name, plant):
    assert isinstance(plant, Airframe), [m for m in Airframe.__protocol_attrs__
                                         if not hasattr(plant, m)]
    z, vz = plant.altitude_m_and_rate_mps
    assert (z, vz) == pytest.approx((plant.truth.position_m[2], plant.truth.velocity_mps[2]))


def test_the_emulator_climbs_under_the_firmwares_altitude_cap():
    """Behind the simulated drone's firmware, AT commands written from the SDK's encoding
    (REF take-off bit 9 over the constant bits, PCMD gaz as the IEEE-754 bits of 1.0) take the
    emulator off, and a full-gaz climb stops near drone.altitude_max_m, far below where 12 s at
    0.7 m/s would take it."""
    cfg = load_config(None, ["drone.altitude_max_m=1.5"])
    drone = SimulatedDrone.from_config(cfg, plant=AirframeEmulator(command_delay_s=0.05))
    seq, t, dt = 1, 0.0, 0.03
    assert drone.receive_at(b"AT*REF=1,290718208\r", t)
    for _ in range(200):        # 6 s: the automatic take-off
        seq += 1
        drone.receive_at(f"AT*REF={seq},290718208\r".encode(), t)
        drone.advance(dt, t)
        t += dt
    for _ in range(400):        # 12 s of full gaz
        seq += 1
        drone.receive_at(f"AT*PCMD={seq},1,0,0,1065353216,0\r".encode(), t)
        drone.advance(dt, t)
        t += dt
    z = drone.plant.altitude_m_and_rate_mps[0]
    assert 1.2 <= z <= 1.5 + 0.1, z
