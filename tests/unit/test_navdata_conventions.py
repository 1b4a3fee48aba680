"""Navdata signs and units checked against the SDK's documented conventions, not against our
simulator: packets are packed here with ``struct`` from the SDK's ``navdata_demo_t`` layout,
and the expected values come from what the SDK documents and the ROS driver ardrone_autonomy
does with them (``src/ardrone_driver.cpp``: REP 103 x forward / y left / z up gets
``linear.y = -vy``, ``linear.z = -vz``, pitch ``-theta``, yaw ``-psi``, all from millidegrees
and mm): the drone's body frame is x forward, y **right**, z **down**; theta > 0 nose up, psi >
0 clockwise seen from above.
"""

import math
import struct

import pytest

from ardrone_nmpc.core.types import FlightMode, NavdataSample
from ardrone_nmpc.links.drone_link import flight_mode_of, navdata_sample_of
from ardrone_nmpc.protocol.navdata import DroneState, decode_navdata
from ardrone_nmpc.runtime.tick import navdata_velocity_world


def packet(*, state=0, ctrl=(4, 0), battery=70, theta_mdeg=0.0, phi_mdeg=0.0, psi_mdeg=0.0,
           altitude_mm=0, v_mmps=(0.0, 0.0, 0.0)) -> bytes:
    """One demo packet as the drone sends it (header, demo option 148 bytes, checksum)."""
    body = struct.pack("<IIIi", 0x55667788, state | (1 << 10), 7, 0)
    demo = struct.pack("<HHIIfffifffI", 0, 148, ctrl[0] << 16 | ctrl[1], battery, theta_mdeg,
                       phi_mdeg, psi_mdeg, altitude_mm, *v_mmps, 0)
    body += demo + bytes(148 - len(demo))
    return body + struct.pack("<HHI", 0xFFFF, 8, sum(body) & 0xFFFFFFFF)


def sample(**kw) -> NavdataSample:
    return navdata_sample_of(decode_navdata(packet(**kw)), 3.0)


def test_units_and_signs_of_one_sample():
    s = sample(state=1, theta_mdeg=2500.0, phi_mdeg=-1500.0, psi_mdeg=-45000.0,
               altitude_mm=1234, v_mmps=(300.0, -200.0, 100.0), battery=64, ctrl=(3, 1))
    assert s.t_s == 3.0 and s.mode is FlightMode.FLYING and s.battery_pct == 64.0
    assert s.pitch_deg == pytest.approx(2.5)    # nose up positive, as the wire
    assert s.roll_deg == pytest.approx(-1.5)    # right wing down positive, as the wire
    assert s.yaw_deg == pytest.approx(-45.0)    # clockwise positive, as the wire
    assert s.altitude_m == pytest.approx(1.234)
    assert (s.vx_body_mps, s.vy_body_mps, s.vz_mps) == pytest.approx((0.3, -0.2, 0.1))
    assert s.ctrl_state == 3 << 16 | 1


@pytest.mark.parametrize("psi_mdeg, expected", [(190000.0, -170.0), (-190000.0, 170.0),
                                                 (180000.0, 180.0), (-180000.0, 180.0),
                                                 (540000.0, 180.0), (359000.0, -1.0)])
def test_yaw_is_wrapped_to_the_half_open_interval(psi_mdeg, expected):
    assert sample(psi_mdeg=psi_mdeg).yaw_deg == pytest.approx(expected)


def test_a_non_finite_yaw_becomes_nan_not_an_exception():
    assert math.isnan(sample(psi_mdeg=math.inf).yaw_deg)


def test_a_bootstrap_packet_has_no_sample():
    body = struct.pack("<IIIi", 0x55667788, 1 << 11, 1, 0)
    data = body + struct.pack("<HHI", 0xFFFF, 8, sum(body))
    assert navdata_sample_of(decode_navdata(data), 0.0) is None


# ROS REP 103 body velocity (forward, left) = (vx, -vy): world = Rz(ψ) · body, ψ CCW
@pytest.mark.parametrize("psi, v_body, world", [
    (0.0, (1.0, 0.0), (1.0, 0.0)),                  # forward along +x
    (0.0, (0.0, 1.0), (0.0, -1.0)),                 # SDK vy > 0 is to the right: −y
    (math.pi / 2, (1.0, 0.0), (0.0, 1.0)),          # facing +y: forward is +y
    (math.pi / 2, (0.0, 1.0), (1.0, 0.0)),          # facing +y: right is +x
    (math.pi, (0.5, 0.0), (-0.5, 0.0)),
    (-math.pi / 2, (0.0, 0.3), (-0.3, 0.0)),        # facing −y: right is −x
    (math.radians(30), (0.4, -0.2),
     (0.4 * math.cos(math.radians(30)) - 0.2 * math.sin(math.radians(30)),
      0.4 * math.sin(math.radians(30)) + 0.2 * math.cos(math.radians(30)))),
])
def test_navdata_velocity_world_follows_the_sdk_body_frame(psi, v_body, world):
    nav = sample(v_mmps=(v_body[0] * 1000.0, v_body[1] * 1000.0, 0.0))
    assert navdata_velocity_world(nav, psi) == pytest.approx(world, abs=1e-6)


def test_a_drone_flying_forward_at_heading_psi_moves_along_psi():
    """The ẏ sign flip of issue 17 drifted a step_x run 2.26 m in y: at every heading, flying
    straight ahead must come out along the heading, not mirrored."""
    for k in range(12):
        psi = -math.pi + k * math.pi / 6 + 0.1
        vx, vy = navdata_velocity_world(sample(v_mmps=(1000.0, 0.0, 0.0)), psi)
        assert (vx, vy) == pytest.approx((math.cos(psi), math.sin(psi)), abs=1e-6)
        vx, vy = navdata_velocity_world(sample(v_mmps=(0.0, 1000.0, 0.0)), psi)
        # right of the heading: the heading turned clockwise by 90°
        assert (vx, vy) == pytest.approx((math.cos(psi - math.pi / 2),
                                          math.sin(psi - math.pi / 2)), abs=1e-6)


@pytest.mark.parametrize("state, ctrl, mode", [
    (1, (4, 0), FlightMode.FLYING), (1, (3, 2), FlightMode.FLYING),
    (0, (2, 0), FlightMode.LANDED), (1, (6, 0), FlightMode.TAKING_OFF),
    (1, (7, 0), FlightMode.TAKING_OFF), (1, (8, 0), FlightMode.LANDING),
    (1, (9, 0), FlightMode.LANDING), (1 << 31, (0, 0), FlightMode.EMERGENCY),
    (1 | 1 << 31, (4, 0), FlightMode.EMERGENCY), (0, (4, 0), FlightMode.LANDING),
    (1, (2, 0), FlightMode.LANDING), (0, (1, 0), FlightMode.LANDING),
    (0, (7, 0), FlightMode.TAKING_OFF),
])
def test_flight_mode_from_the_packet(state, ctrl, mode):
    assert sample(state=state, ctrl=ctrl).mode is mode
    assert flight_mode_of(DroneState(state), ctrl[0]) is mode
