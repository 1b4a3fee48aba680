"""A navdata packet of a plant's state, encoded from the plant alone (docs/protocol.md §4): the
state a drone without any AT client reports — the bits that echo a client's commands (REF
start, ACK, com watchdog, link lost) clear. The tests' yardstick for what the simulated
drone's firmware sends."""

from __future__ import annotations

from ardrone_nmpc.protocol.navdata import CtrlCodes, DroneStatus, encode_drone_navdata

VBAT_LOW_PCT = 20.0  # the simulated drones set state bit 15 (VBAT_LOW) below this charge (%)


def plain_packet(plant, sequence: int, codes: CtrlCodes = CtrlCodes.SDK) -> bytes:
    """The demo packet ``plant`` sends now, numbered ``sequence``."""
    status = DroneStatus(plant.mode.value, moving=plant.moving,
                         battery_low=plant.battery_pct < VBAT_LOW_PCT)
    return encode_drone_navdata(status, sequence, plant.navdata(), codes=codes, t_s=plant.t_s)
