"""Mocap sources behind one interface: the libmotioncapture conversion (checked against scipy's
rotations), the freshness rules shared with the Vicon UDP link, and the source's lifecycle
with stand-ins of the library written from its documented API (connect(type, options),
waitForNextFrame(), rigidBodies: name → position, rotation.w/x/y/z)."""

from __future__ import annotations

import math
import socket
import sys
import threading

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.extras import MissingExtra
from ardrone_nmpc.links.mocap_link import MocapLink
from ardrone_nmpc.links.mocap_factory import open_mocap_source
from ardrone_nmpc.links.mocap_source import MocapConnectError
from ardrone_nmpc.links.motioncapture_source import (
    MotionCaptureSource,
    library_options,
    quaternion_to_xyz_rad,
    rigid_body_pose,
)
from ardrone_nmpc.protocol.mocap import MocapFrame, MocapObjectPose, encode_mocap
from ardrone_nmpc.sim.loopback import free_udp_port

from tests.integration.test_links import wait_until


def _wxyz(rot: Rotation) -> tuple[float, float, float, float]:
    x, y, z, w = rot.as_quat()
    return w, x, y, z


# ----------------------------------------------------------------------------- conversion


def test_quaternion_angles_match_scipy_xyz_euler(rng):
    rots = Rotation.random(500, random_state=7)
    for rot in rots:
        got = quaternion_to_xyz_rad(*_wxyz(rot))
        np.testing.assert_allclose(got, rot.as_euler("XYZ"), atol=1e-9)


def test_heading_of_a_converted_body_is_the_nose_direction(rng):
    for rot in Rotation.random(200, random_state=3):
        pose = rigid_body_pose("b", (1.0, 2.0, 3.0), _wxyz(rot))
        nose = rot.apply([1.0, 0.0, 0.0])
        # ψ = atan2(R[1,0], R[0,0]): the heading of the body's x axis seen from above
        assert math.isclose(pose.psi_rad, math.atan2(nose[1], nose[0]), abs_tol=1e-9)
        assert pose.position_m == pytest.approx((1.0, 2.0, 3.0), abs=1e-12)


def test_a_45_degree_yaw_is_psi_pi_over_4():
    c, s = math.cos(math.pi / 8), math.sin(math.pi / 8)
    pose = rigid_body_pose("ardrone", (0.5, -0.25, 1.0), (c, 0.0, 0.0, s))
    assert pose.psi_rad == pytest.approx(math.pi / 4, abs=1e-12)
    assert pose.fresh


def test_float32_quaternions_are_normalised():
    q = np.array(_wxyz(Rotation.from_euler("z", 0.3)), dtype=np.float32) * np.float32(1.0000003)
    pose = rigid_body_pose("b", np.float32([1, 2, 3]), q)
    assert pose.psi_rad == pytest.approx(0.3, abs=1e-6)


def test_zero_or_nan_quaternion_is_not_fresh():
    assert not rigid_body_pose("b", (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 0.0)).fresh
    assert not rigid_body_pose("b", (math.nan, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0)).fresh


def test_y_up_frame_turns_into_z_up():
    # OptiTrack's default: x, y up, z (right-handed). Ours: x, y left, z up.
    pose = rigid_body_pose("b", (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), y_up=True)
    assert pose.position_m == pytest.approx((1.0, -3.0, 2.0))
    # a CCW turn about the vertical (+y there) is a CCW turn about +z here
    turn = rigid_body_pose("b", (1.0, 2.0, 3.0), _wxyz(Rotation.from_rotvec([0, 0.7, 0])),
                           y_up=True)
    assert turn.psi_rad == pytest.approx(0.7, abs=1e-12)
    # any rotation R becomes C R Cᵀ with C = +90° about x
    c = Rotation.from_euler("x", 90, degrees=True)
    for rot in Rotation.random(100, random_state=5):
        got = rigid_body_pose("b", (0.0, 0.0, 1.0), _wxyz(rot), y_up=True)
        want = (c * rot * c.inv()).as_euler("XYZ")
        np.testing.assert_allclose(got.rotation_xyz_rad, want, atol=1e-9)


def test_library_options_are_text_the_library_reads():
    opts = library_options("10.0.0.5", {"enable_objects": True, "port_command": 1510,
                                        "enable_pointcloud": False, "frequency": 99.5})
    assert opts == {"enable_objects": "true", "port_command": "1510",
                    "enable_pointcloud": "false", "frequency": "99.5", "hostname": "10.0.0.5"}


def test_up_axis_defaults_per_system():
    assert load_config(None, ["mocap.system=optitrack"]).mocap.vertical_axis == "y"
    assert load_config(None, ["mocap.system=vicon"]).mocap.vertical_axis == "z"
    assert load_config(None, ["mocap.system=optitrack",
                              "mocap.up_axis=z"]).mocap.vertical_axis == "z"


# ----------------------------------------------------------------------------- library stand-ins


class Quaternion:
    def __init__(self, w, x, y, z):
        self.w, self.x, self.y, self.z = w, x, y, z


class Body:
    def __init__(self, name, position, rotation: Rotation):
        self.name = name
        self.position = np.asarray(position, dtype=np.float64)
        self.rotation = Quaternion(*_wxyz(rotation))


class ScriptedMotionCapture:
    """A connected system whose frames the test hands over one at a time."""

    def __init__(self):
        self.frames: list[dict] = []
        self.current: dict = {}
        self.ready = threading.Semaphore(0)

    def push(self, *bodies: Body) -> None:
        self.frames.append({b.name: b for b in bodies})
        self.ready.release()

    def waitForNextFrame(self):  # noqa: N802 - the library's name
        self.ready.acquire()
        self.current = self.frames.pop(0)

    @property
    def rigidBodies(self):  # noqa: N802 - the library's name
        return self.current


class Library:
    def __init__(self, mc=None, error: Exception | None = None, block: threading.Event = None):
        self.mc, self.error, self.block, self.calls = mc, error, block, []

    def connect(self, system, options):
        self.calls.append((system, dict(options)))
        if self.block is not None:
            self.block.wait()
        if self.error is not None:
            raise self.error
        return self.mc


def waking(src: MotionCaptureSource, mc: ScriptedMotionCapture) -> threading.Thread:
    """A thread that wakes ``src``'s receiver (blocked in ``waitForNextFrame``, as the
    library's is between frames) with empty frames until it has ended — so a close that comes
    waits for a state, not for its join timeout."""
    def wake():
        idle = threading.Event()
        for _ in range(1000):
            if not src._thread.is_alive():
                return
            mc.push()
            idle.wait(0.01)

    waker = threading.Thread(target=wake, daemon=True)
    waker.start()
    return waker


def finally_closed(src: MotionCaptureSource, mc: ScriptedMotionCapture) -> None:
    """Close ``src`` (its thread woken) and check that the thread ended."""
    waker = waking(src, mc)
    src.close()
    assert not src._thread.is_alive()                      # close returns once it has ended
    waker.join()


def _source(mc, **kw) -> MotionCaptureSource:
    ticks = iter(range(1, 10_000))
    return MotionCaptureSource("vicon", {"hostname": "lab"}, object_name="ardrone",
                               library=Library(mc), clock=lambda: float(next(ticks)), **kw)


def test_frames_from_a_connected_library_keep_the_newest_pose():
    mc = ScriptedMotionCapture()
    src = _source(mc, other_objects=("car",))
    frames = src.frames_from(mc)
    mc.push(Body("ardrone", (1.0, 2.0, 0.5), Rotation.from_euler("z", 0.4)),
            Body("car", (3.0, 0.0, 0.0), Rotation.identity()))
    src.receive_bodies(*next(frames))
    pose, rx = src.latest()
    assert rx == 1.0 and pose.position_m.tolist() == pytest.approx([1.0, 2.0, 0.5])
    assert pose.psi_rad == pytest.approx(0.4)
    assert src.latest_of("car")[0].position_m[0] == pytest.approx(3.0)
    assert src.names_seen == ("ardrone", "car") and src.stats.packets == 1


def test_occluded_zero_and_frozen_poses_are_not_fresh():
    mc = ScriptedMotionCapture()
    src = _source(mc)
    frames = src.frames_from(mc)
    yaw = Rotation.from_euler("z", 0.1)
    mc.push(Body("ardrone", (1.0, 0.0, 1.0), yaw))
    src.receive_bodies(*next(frames))                        # t = 1: fresh
    mc.push(Body("wand", (0.0, 0.0, 0.0), yaw))               # occluded: left out of the frame
    src.receive_bodies(*next(frames))
    mc.push(Body("ardrone", (0.0, 0.0, 0.0), Rotation.from_quat([0, 0, 0, 1])))  # all zero
    src.receive_bodies(*next(frames))
    for _ in range(3):                                        # bit-identical: frozen on the 3rd
        mc.push(Body("ardrone", (1.5, 0.0, 1.0), yaw))
        src.receive_bodies(*next(frames))
    assert (src.missing, src.zero_poses, src.repeats, src.poses) == (1, 1, 1, 3)
    pose, rx = src.latest()
    assert rx == 5.0 and pose.position_m[0] == pytest.approx(1.5)
    assert src.age_ms(7.0) == pytest.approx(2000.0)


def test_same_frames_give_the_same_readings_as_the_vicon_udp_link(rng):
    """One frame sequence through both sources: the Vicon UDP link (datagrams) and the
    motioncapture source (quaternions): same counts, same poses to rounding."""
    link = MocapLink("127.0.0.1", 0, object_name="ardrone", other_objects=("car",))
    mc = ScriptedMotionCapture()
    src = _source(mc, other_objects=("car",))
    frames = src.frames_from(mc)
    for k in range(1, 60):
        items = []
        if k % 7:  # every 7th frame the drone is occluded
            xyz = rng.normal(size=3)
            rot = rng.normal(scale=0.3, size=3)
            if k % 11 == 0:
                xyz, rot = np.zeros(3), np.zeros(3)       # the zero pose of some trackers
            items.append(MocapObjectPose.from_si("ardrone", xyz, rot))
        items.append(MocapObjectPose.from_si("car", rng.normal(size=3), (0.0, 0.0, 0.2)))
        link.feed(encode_mocap(MocapFrame.of(k, items)), float(k))
        mc.push(*(Body(p.name, p.position_m, Rotation.from_euler("XYZ", p.rotation_xyz_rad))
                  for p in items))
        bodies, _ = next(frames)
        src.receive_bodies(bodies, float(k))
        a, b = link.latest(), src.latest()
        assert a[1] == b[1]
        np.testing.assert_allclose(a[0].position_m, b[0].position_m, atol=1e-12)
        assert a[0].psi_rad == pytest.approx(b[0].psi_rad, abs=1e-12)
        np.testing.assert_allclose(link.latest_of("car")[0].position_m,
                                   src.latest_of("car")[0].position_m, atol=1e-12)
    assert (link.missing, link.zero_poses, link.poses) == (src.missing, src.zero_poses, src.poses)
    assert src.missing > 0 and src.zero_poses > 0


def _vicon_frames(link: MocapLink):
    """Deliver ``[(name, position_m, rotation_xyz_rad)]`` frames as datagrams at t = 1, 2, …"""
    k = 0

    def deliver(bodies):
        nonlocal k
        k += 1
        items = [MocapObjectPose.from_si(n, p, r) for n, p, r in bodies]
        link.feed(encode_mocap(MocapFrame.of(k, items)), float(k))
    return deliver


def _library_frames(src: MotionCaptureSource):
    k = 0

    def deliver(bodies):
        nonlocal k
        k += 1
        src.receive_bodies([(n, p, _wxyz(Rotation.from_euler("XYZ", r))) for n, p, r in bodies],
                           float(k))
    return deliver


@pytest.mark.parametrize("kind", ["vicon_udp", "motioncapture"])
def test_a_followed_object_is_kept_only_from_fresh_poses(kind):
    """The other objects (a followed car) obey the same freshness as the drone: an all-zero or
    non-finite pose of the car must not replace its last good one (it would drive the follow
    reference to the origin), and before its first fresh pose there is none."""
    if kind == "vicon_udp":
        src = MocapLink("127.0.0.1", 0, object_name="ardrone", other_objects=("car",))
        deliver = _vicon_frames(src)
    else:
        src = _source(ScriptedMotionCapture(), other_objects=("car",))
        deliver = _library_frames(src)
    drone = ("ardrone", (0.0, 0.0, 1.0), (0.0, 0.0, 0.1))
    deliver([drone, ("car", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))])          # t = 1: zero car
    assert src.latest_of("car") == (None, -math.inf) and src.fresh_count("car") == 0
    deliver([drone, ("car", (3.0, -1.0, 0.0), (0.0, 0.0, 0.5))])         # t = 2: fresh
    deliver([drone, ("car", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))])          # t = 3: zero
    deliver([drone, ("car", (math.nan, 1.0, 0.0), (0.0, 0.0, 0.5))])     # t = 4: NaN
    car, rx = src.latest_of("car")
    assert rx == 2.0 and car.position_m.tolist() == pytest.approx([3.0, -1.0, 0.0])
    assert car.psi_rad == pytest.approx(0.5) and src.fresh_count("car") == 1
    deliver([drone, ("car", (3.5, -1.0, 0.0), (0.0, 0.0, 0.5))])         # t = 5: fresh
    assert src.latest_of("car")[1] == 5.0 and src.fresh_count("car") == 2


# ----------------------------------------------------------------------------- lifecycle


@pytest.mark.timeout(10)
def test_start_runs_the_receiver_thread_until_close():
    mc = ScriptedMotionCapture()
    lib = Library(mc)
    src = MotionCaptureSource("qualisys", library_options("h", {}), object_name="ardrone",
                              library=lib)
    with src:
        mc.push(Body("ardrone", (1.0, 1.0, 1.0), Rotation.identity()))
        deadline = threading.Event()
        for _ in range(200):
            if src.poses:
                break
            deadline.wait(0.01)
        assert src.poses == 1 and src.where == "qualisys@h"
        assert lib.calls == [("qualisys", {"hostname": "h"})]
        waker = waking(src, mc)                            # the exit closes: it must be seen
    assert not src._thread.is_alive()                      # …before the exit returns
    waker.join()


@pytest.mark.timeout(10)
def test_a_failing_connect_is_one_line():
    src = MotionCaptureSource("vicon", {"hostname": "nowhere"},
                              library=Library(error=RuntimeError("Unknown host")))
    with pytest.raises(MocapConnectError, match=r"^mocap: cannot connect to vicon@nowhere: "
                                                r"Unknown host$"):
        src.start()


@pytest.mark.timeout(10)
def test_a_connect_that_never_returns_times_out():
    block = threading.Event()
    src = MotionCaptureSource("vicon", {"hostname": "silent"}, connect_timeout_s=0.2,
                              library=Library(ScriptedMotionCapture(), block=block))
    # the connect returns once the source gives up (as the child process's ends when it is
    # killed), so the source's close need not wait out its join timeout
    threading.Thread(target=lambda: block.set() if src._stop.wait(10.0) else None,
                     daemon=True).start()
    try:
        with pytest.raises(MocapConnectError, match="no connection to vicon@silent within 0.2 s"):
            src.start()
    finally:
        block.set()


def test_open_mocap_source_picks_the_kind():
    cfg = load_config(None, [])
    udp = open_mocap_source(cfg.mocap, other_objects=("car",), port=5)
    assert isinstance(udp, MocapLink) and udp.port == 5 and udp.other_objects == ("car",)
    mc_cfg = load_config(None, ["mocap.kind=motioncapture", "mocap.system=mock",
                                "mocap.hostname=h", "mocap.options.frequency=50"]).mocap
    src = open_mocap_source(mc_cfg)
    assert isinstance(src, MotionCaptureSource)
    assert src.options == {"frequency": "50", "hostname": "h"} and src.repeat_limit is None
    vicon = open_mocap_source(load_config(None, ["mocap.kind=motioncapture"]).mocap)
    assert vicon.repeat_limit == 3 and not vicon.y_up


def test_a_missing_library_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "motioncapture", None)   # import fails
    src = open_mocap_source(load_config(None, ["mocap.kind=motioncapture"]).mocap)
    with pytest.raises(MissingExtra, match=r"pip install 'ardrone-nmpc\[mocap\]'"):
        src.start()


def test_library_options_must_be_scalars():
    from ardrone_nmpc.config.schema import ConfigError

    with pytest.raises(ConfigError) as err:
        load_config(None, ["mocap.options.port=[1,2]"])
    assert err.value.messages == ["mocap.options: port: expected a string, number or boolean, "
                                  "got list"]


# ----------------------------------------------------------------------------- more edges


def test_quaternions_of_any_length_give_the_unit_quaternions_angles():
    """The library's quaternion need not be unit (float32, a hand-made mock body): scaled by 3
    or by 1/4 it is the same rotation (scipy normalises too)."""
    for rot in Rotation.random(50, random_state=11):
        want = rot.as_euler("XYZ")
        for scale in (3.0, 0.25):
            got = quaternion_to_xyz_rad(*(scale * q for q in _wxyz(rot)))
            np.testing.assert_allclose(got, want, atol=1e-9)


@pytest.mark.parametrize("pitch_deg", [90.0, -90.0])
def test_a_pitch_of_exactly_90_degrees_gives_angles_not_an_error(pitch_deg):
    """At ±90° the sine of the pitch rounds to ±1.0000000000000002 for most roll angles: the
    angles must still come out, finite, with that pitch (roll and yaw are then ill-defined —
    gimbal lock — and a drone there has long crashed; the heading is not used)."""
    for rx in np.linspace(-3.0, 3.0, 61):
        rot = Rotation.from_euler("XYZ", [rx, math.radians(pitch_deg), 0.3])
        got = quaternion_to_xyz_rad(*_wxyz(rot))
        assert all(math.isfinite(a) for a in got)
        assert got[1] == pytest.approx(math.radians(pitch_deg))


def test_from_config_takes_every_field_of_the_config():
    cfg = load_config(None, ["mocap.kind=motioncapture", "mocap.system=optitrack",
                             "mocap.hostname=10.0.0.5", "mocap.object_name=drone7",
                             "mocap.connect_timeout_s=2.5"]).mocap
    mc = ScriptedMotionCapture()
    lib = Library(mc)
    src = MotionCaptureSource.from_config(cfg, other_objects=("car",), clock=lambda: 17.25,
                                          library=lib)
    assert (src.system, src.where, src.object_name, src.other_objects) == (
        "optitrack", "optitrack@10.0.0.5", "drone7", ("car",))
    assert src.y_up is True and src.connect_timeout_s == 2.5 and src.repeat_limit == 3
    src.start()
    assert lib.calls == [("optitrack", {"hostname": "10.0.0.5"})]
    assert src._thread.name == "mocap-rx" and src._thread.daemon   # never holds the exit
    mc.push(Body("drone7", (1.0, 2.0, 3.0), Rotation.identity()))      # Y up
    assert wait_until(lambda: src.poses == 1)
    pose, rx = src.latest()
    assert rx == 17.25 and pose.position_m.tolist() == pytest.approx([1.0, -3.0, 2.0])
    finally_closed(src, mc)
    cfg_z = load_config(None, ["mocap.kind=motioncapture", "mocap.system=optitrack",
                               "mocap.up_axis=z"]).mocap
    assert MotionCaptureSource.from_config(cfg_z).y_up is False


def test_the_factory_passes_host_port_name_others_and_clock():
    port = free_udp_port()
    cfg = load_config(None, ["mocap.bind_host=127.0.0.1", f"mocap.port={port}",
                             "mocap.object_name=drone7"]).mocap
    link = open_mocap_source(cfg, other_objects=("car",), clock=lambda: 3.5)
    assert (link.bind_host, link.port, link.object_name, link.other_objects) == (
        "127.0.0.1", port, "drone7", ("car",))
    with link, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        tx.sendto(encode_mocap(MocapFrame.of(1, [MocapObjectPose(
            "drone7", (1.0, 2.0, 3.0), (0.0, 0.0, 0.1))])), ("127.0.0.1", port))
        assert wait_until(lambda: link.poses == 1)
        assert link.latest()[1] == 3.5                     # stamped with the clock given
    mc_cfg = load_config(None, ["mocap.kind=motioncapture", "mocap.object_name=drone7"]).mocap
    src = open_mocap_source(mc_cfg, other_objects=("car",), clock=lambda: 4.5)
    assert src.object_name == "drone7" and src.other_objects == ("car",)
    mc = ScriptedMotionCapture()
    mc.push(Body("drone7", (1.0, 2.0, 3.0), Rotation.identity()))
    assert next(src.frames_from(mc))[1] == 4.5


def test_the_factory_refuses_an_unknown_kind_naming_the_known_ones():
    from types import SimpleNamespace

    with pytest.raises(ValueError) as err:
        open_mocap_source(SimpleNamespace(kind="optical"))
    assert str(err.value) == "unknown mocap.kind 'optical'; choose one of vicon_udp, motioncapture"


class _FailingOnce(ScriptedMotionCapture):
    """A system whose first waitForNextFrame raises (the library's RuntimeError on a lost
    connection), then delivers."""

    def __init__(self):
        super().__init__()
        self.failed = False

    def waitForNextFrame(self):  # noqa: N802 - the library's name
        if not self.failed:
            self.failed = True
            raise RuntimeError("frame lost")
        super().waitForNextFrame()


@pytest.mark.timeout(10)
def test_a_frame_the_library_fails_to_deliver_is_counted_and_the_next_one_read():
    mc = _FailingOnce()
    src = _source(mc)
    mc.push(Body("ardrone", (1.0, 2.0, 3.0), Rotation.identity()))
    bodies, t_s = next(src.frames_from(mc))
    assert [b[0] for b in bodies] == ["ardrone"] and t_s == 1.0
    assert src.frame_errors == 1 and src.last_error == "mocap: vicon@lab: frame lost"


def test_received_bodies_are_turned_y_up_and_malformed_ones_counted():
    src = MotionCaptureSource("optitrack", {"hostname": "h"}, y_up=True, repeat_limit=None)
    src.receive_bodies([("ardrone", (1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0)),
                        ("car", (1.0, 2.0), (1.0, 0.0, 0.0, 0.0))], 1.0)
    assert src.latest()[0].position_m.tolist() == pytest.approx([1.0, -3.0, 2.0])
    assert src.stats.malformed == 1
    assert src.last_error == ("mocap: body 'car': not enough values to unpack "
                              "(expected 3, got 2)")


@pytest.mark.timeout(10)
def test_start_is_once_only():
    mc = ScriptedMotionCapture()
    src = _source(mc)
    src.close()                                            # never started: nothing to stop
    src = _source(mc)
    src.start()
    with pytest.raises(RuntimeError,
                       match=r"^MotionCaptureSource already started \(or closed\)$"):
        src.start()
    finally_closed(src, mc)
    with pytest.raises(RuntimeError,
                       match=r"^MotionCaptureSource already started \(or closed\)$"):
        src.start()                                        # nor after close


def test_the_missing_library_message_names_the_setting_and_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "motioncapture", None)
    src = MotionCaptureSource("vicon", {"hostname": "h"})
    with pytest.raises(MissingExtra) as err:
        src.start()
    assert str(err.value) == ("mocap.kind 'motioncapture' needs the 'motioncapture' library: "
                              "pip install 'ardrone-nmpc[mocap]'")


def test_other_objects_are_stamped_with_their_receipt_time():
    src = _source(ScriptedMotionCapture(), other_objects=("car",))
    src.receive_bodies([("car", (1.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))], 7.5)
    car, rx = src.latest_of("car")
    assert car.t_s == rx == 7.5


def test_the_longest_gap_and_the_fresh_count_of_the_object():
    src = _source(ScriptedMotionCapture(), repeat_limit=None)
    body = lambda x: [("ardrone", (x, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0))]  # noqa: E731
    src.receive_bodies(body(1.0), 1.0)
    assert src.max_gap_s == 0.0 and src.fresh_count("ardrone") == 1
    src.receive_bodies(body(1.1), 2.0)
    src.receive_bodies([], 3.0)                            # occluded: no fresh pose
    src.receive_bodies([("ardrone", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0))], 4.0)  # zero
    src.receive_bodies(body(1.2), 4.5)
    assert src.max_gap_s == 2.5 and src.fresh_count("ardrone") == src.poses == 3
    assert src.fresh_count("car") == 0


def test_the_shared_rules_refuse_a_nameless_object_and_a_repeat_limit_below_2():
    from ardrone_nmpc.links.mocap_source import MocapSource

    base = MocapSource()
    assert base.object_name == "ardrone" and base.repeat_limit == 3   # docs/mocap-stream.md
    assert base.last_error is None and base.names_seen == () and base.max_gap_s == 0.0
    for name in ("", 5):
        with pytest.raises(ValueError, match=r"^object_name must be a non-empty string$"):
            MocapSource(object_name=name)
    assert MocapSource(repeat_limit=2).repeat_limit == 2
    with pytest.raises(ValueError, match=r"^repeat_limit must be >= 2 \(or None\), got 1$"):
        MocapSource(repeat_limit=1)


def test_the_connect_timeout_default_is_the_configs():
    assert MotionCaptureSource("vicon").connect_timeout_s == \
        load_config(None, []).mocap.connect_timeout_s


def test_the_frame_rate_is_measured_over_the_last_second():
    """100 Hz for 2 s, then 10 Hz: a second later the rate is the stream's 10 Hz (a longer
    window would still mix in the 100 Hz)."""
    src = _source(ScriptedMotionCapture(), repeat_limit=None)
    body = [("ardrone", (1.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0))]
    for k in range(200):
        src.receive_bodies(body, 0.01 * k)
    for k in range(1, 11):
        src.receive_bodies(body, 2.0 + 0.1 * k)
    assert src.stats.rate_hz == pytest.approx(10.0)
