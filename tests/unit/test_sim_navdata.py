"""The simulated drone's firmware (served over UDP by the loopback drone server, flown in
lockstep by the same object) encodes a flight state as the plant's state alone says: the same
ctrl_state and flight bits as a packet encoded from the plant (tests/standins/navdata_packets)."""

from __future__ import annotations

import pytest

from ardrone_nmpc.config.schema import ExperimentConfig
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.protocol.at import AtCommand, Config, Pcmd
from ardrone_nmpc.protocol.navdata import CtrlCodes, DroneState, decode_navdata
from ardrone_nmpc.sim.drone_server import DroneServer
from ardrone_nmpc.sim.plant import AirframePlant
from tests.standins.navdata_packets import plain_packet

FLIGHT_BITS = DroneState.FLY | DroneState.EMERGENCY | DroneState.VBAT_LOW


def _drive(plant: AirframePlant, mode: FlightMode) -> None:
    """Bring a landed plant into ``mode`` with its own transitions."""
    if mode is FlightMode.LANDED:
        return
    if mode is FlightMode.EMERGENCY:
        plant.emergency()
        return
    plant.takeoff()
    if mode is FlightMode.TAKING_OFF:
        plant.advance(0.1)
        return
    while plant.mode is FlightMode.TAKING_OFF:
        plant.advance(0.05)
    if mode is FlightMode.LANDING:
        plant.land()
        plant.advance(0.05)


@pytest.mark.parametrize("codes", list(CtrlCodes))
@pytest.mark.parametrize("mode", list(FlightMode))
@pytest.mark.parametrize("moving", [False, True])
def test_server_and_wire_sensors_report_a_state_alike(mode, moving, codes):
    cfg = ExperimentConfig()
    plant = AirframePlant.from_config(cfg.sim, cfg.drone, seed=2)
    server = DroneServer(plant, ctrl_codes=codes, clock=lambda: 100.0)  # threads not started
    try:
        server.handle_at_datagram(AtCommand(1, Config.of("general:navdata_demo", True)).encode())
        _drive(plant, mode)
        assert plant.mode is mode
        pcmd = Pcmd.move(0.1, 0.0, 0.0, 0.0) if moving else Pcmd.hover()
        server.handle_at_datagram(AtCommand(2, pcmd).encode())   # the server sets the plant's
        served = decode_navdata(server._packet(100.0))
        wired = decode_navdata(plain_packet(plant, 7, codes))
    finally:
        server.stop()
    assert served.demo.ctrl_state == wired.demo.ctrl_state
    assert served.state & FLIGHT_BITS == wired.state & FLIGHT_BITS
    if mode is FlightMode.FLYING:
        assert served.demo.ctrl_major == (3 if moving else 4)
    if mode is FlightMode.TAKING_OFF:
        assert served.demo.ctrl_major == codes.takeoff_major
    assert [o.tag for o in served.options] == [o.tag for o in wired.options] == [16]
