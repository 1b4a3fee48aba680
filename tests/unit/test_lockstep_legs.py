"""The direct sensor path's compiled tick (sim/lockstep_legs.py, sim/sensor_step.py) gives the
Python path's bits: two lockstep drones of one seed, one with the compiled legs and one
without, flown with the same commands, hold the same samples, truth and plant state on every
tick — through a zig-zag, climbs into the altitude cap, turbulence, the second-order
attitude, the watchdogs of a silent link, a draining battery, a scripted target and a
take-off after a self-landing — and through the automatic take-off and landing, whose
ends (the climb settled, the touch-down) the kernel flies too (or hands back: a take-off
whose battery empties)."""

import math

import numpy as np
import pytest

from ardrone_nmpc.config.io import load_config
from ardrone_nmpc.core.types import FlightMode
from ardrone_nmpc.sim.lockstep_drone import LockstepDrone

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
KIT = "sim.plant.profile=thesis_kit"


def _value(v):
    """A comparable form of a sample's field: its type and bits."""
    if isinstance(v, np.ndarray):
        return ("array", v.dtype.str, v.shape, v.tobytes(), v.flags.writeable)
    if isinstance(v, float):
        return (type(v).__name__, np.float64(v).tobytes())
    return (type(v).__name__, v)


def _record(obj):
    if obj is None:
        return None
    return tuple((name, _value(getattr(obj, name))) for name in obj.__slots__)


def _snapshot(drone, t_s):
    inputs = drone.inputs(t_s)
    plant = drone.sim.plant
    fw = drone.sim.firmware
    return (drone.truth_cells(), inputs.t_s, inputs.pose_rx_t_s, inputs.navdata_rx_t_s,
            inputs.target_rx_t_s, _record(inputs.pose), _record(inputs.navdata), _record(inputs.target),
            _record(drone.truth), plant._state, plant._tilt_aux, plant._steps,
            plant._pending_s, plant._battery, plant._yaw_bias_deg, plant._vel_bias,
            plant._gust_mps, plant._fifo.head, plant._fifo.rows.tobytes(),
            getattr(plant, "_kit", np.zeros(0)).tobytes(), fw.comwdg_latched,
            fw.lost_com_hover, fw.alt_capped, fw.applied, drone.self_landing,
            # what the PCMD chain (or CompiledLegs.command in its place) leaves
            plant._current, plant._mode, fw.pcmd, fw._applied_pcmd, fw.last_seq, fw.last_cmd_t,
            fw.link_lost, fw.ref_start, tuple(vars(drone.sim.counters).items()),  # (a copy:
            drone._seq)  # the counters of this tick, not the flight's last)


def _light(drone, t_s):
    """What a tick reads of the drone (no plant attribute: the compiled legs keep holding
    its state, sim/held_state.py)."""
    inputs = drone.inputs(t_s)
    return (drone.truth_cells(), _record(drone.truth), _record(inputs.pose),
            _record(inputs.navdata), drone.sim.firmware.comwdg_latched)


def _fly(cfg, legs: bool, ticks: int, command, every: int = 1, takeoff_command=None):
    """``takeoff_command(k)``: a PCMD sent on the take-off's k-th tick too (None: none)."""
    drone = LockstepDrone(cfg)
    # compiled runs, of them stopped before the last leg: flying, taking off or landing;
    used = [0, 0, 0, 0, 0, 0, 0]  # ticks on which the arrays held the state; runs that flew
    compiled = drone.sensors._legs  # a take-off's or landing's end; REF land held again by
    # CompiledLegs.land_again
    if not legs:  # the Python path: neither the sampler nor the AT sender (land) has legs
        drone.sensors._legs = drone._legs = None
    elif compiled is not None:
        run = compiled.run

        def counted(t_s):
            mode = drone.sim.plant.mode
            i = 0 if mode is FlightMode.FLYING else 2
            left = run(t_s)
            if left is not None:  # (None: not the kernel's tick, nothing done)
                used[i] += 1
                used[i + 1] += left[1]
                used[5] += drone.sim.plant.mode is not mode
            return left
        compiled.run = counted
        land_again = compiled.land_again

        def counted_landing(seq):
            done = land_again(seq)
            used[6] += done
            return done
        compiled.land_again = counted_landing
    period = cfg.loop.period_s
    drone.connect()
    drone.takeoff()
    shots = []
    while drone.truth.mode is not FlightMode.FLYING:
        drone.advance_to(drone.truth.t_s + period)
        shots.append(_snapshot(drone, drone.truth.t_s))
        if takeoff_command is not None:
            drone.set_command(*takeoff_command(len(shots)))
    t_first = drone.truth.t_s
    drone.start_experiment(t_first)
    for k in range(ticks):
        t = t_first + k * period
        drone.advance_to(t, k * period)
        if k % every == 0:  # every attribute (the arrays give them back)
            shots.append(_snapshot(drone, t))
        else:
            if legs and compiled is not None and compiled.held():
                used[4] += 1
            shots.append(_light(drone, t))
        cmd = command(k)
        if cmd == "silent":  # no command: the firmware's watchdogs
            pass
        elif cmd == "takeoff":
            drone.takeoff()
        elif cmd is None:
            drone.hover()
        else:
            drone.set_command(*cmd)
    drone.land()
    for k in range(ticks, ticks + 100):  # as runtime/lockstep._land: REF land held
        if drone.truth.mode is FlightMode.LANDED:
            break
        t = t_first + k * period
        drone.advance_to(t, k * period)
        drone.land()
        shots.append(_snapshot(drone, t))
    return shots, used


def _zigzag(k):
    return (0.05 * ((k // 50) % 3 - 1), 0.02, 0.01 * ((k // 30) % 2), 0.01)


# name: (overrides, command of tick k, the compiled run must stop before a leg sometimes)
CASES = {
    "square": (["duration_s=60"], _zigzag, False),
    "climb_into_cap": (["drone.altitude_max_m=1.3"],
                       lambda k: (0.0, 0.01, 0.6 if (k // 40) % 2 == 0 else -0.2, 0.0), True),
    "turbulence": (["sim.plant.turbulence_std_mps=0.5"], _zigzag, False),
    "sag": (["sim.battery_sag_frac=0.3", "sim.vz_gain=0.9"], _zigzag, False),
    "second_order": (["sim.plant.attitude_model=second_order"], _zigzag, False),
    "hover_and_silence": ([], lambda k: None if k % 7 == 0 else (0.01, -0.02, 0.0, 0.0), False),
    "watchdogs": ([], lambda k: "silent" if 150 < k < 200 or k % 40 > 35 else _zigzag(k),
                  False),
    # fractions beyond ±1 (the plant clips them), a −0.0
    "saturated": ([], lambda k: (1.7 if (k // 20) % 2 else -1.3, -1.0000000000000002, 0.0,
                                 2.5 if k % 3 else -0.0), False),
    "battery_empties": (["sim.plant.battery_start_pct=21",
                         "sim.plant.battery_drain_pct_per_min=100"],
                        lambda k: "takeoff" if k % 25 == 0 else _zigzag(k), True),
    # the thesis_kit plant: its channels' dynamics in the kernel (sim/plant_kit)
    "kit": ([KIT], _zigzag, False),
    "kit_climb_into_cap": ([KIT, "drone.altitude_max_m=1.3"],
                           lambda k: (0.0, 0.01, 0.6 if (k // 40) % 2 == 0 else -0.2, 0.0), True),
    "kit_sag": ([KIT, "sim.plant.turbulence_std_mps=0.5", "sim.battery_sag_frac=0.3",
                 "sim.vz_gain=0.9"], _zigzag, False),
    "kit_battery_empties": ([KIT, "sim.plant.battery_start_pct=21",
                             "sim.plant.battery_drain_pct_per_min=100"],
                            lambda k: "takeoff" if k % 25 == 0 else _zigzag(k), True),
}


def _count_compiled_calls(monkeypatch):
    """Calls of CompiledLegs.run and .land_again, on any instance, since: a reference flight
    must make none (the comparison would be the compiled path against itself)."""
    from ardrone_nmpc.sim.lockstep_legs import CompiledLegs

    calls = {"run": 0, "land_again": 0}
    for name in calls:
        method = getattr(CompiledLegs, name)

        def counted(self, *a, _name=name, _method=method):
            calls[_name] += 1
            return _method(self, *a)
        monkeypatch.setattr(CompiledLegs, name, counted)
    return calls


@pytest.mark.parametrize("name", sorted(CASES))
def test_compiled_legs_give_the_python_paths_bits(name, monkeypatch):
    overrides, command, stops = CASES[name]
    kind = name.removeprefix("kit_")  # (a kit case asserts as its airframe twin)
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), overrides)
    calls = _count_compiled_calls(monkeypatch)
    python, _ = _fly(cfg, False, 400, command)
    assert calls == {"run": 0, "land_again": 0}  # the reference is the Python path's own
    compiled, (used, stopped, auto_used, auto_stopped, _, ends, lands_again) = _fly(
        cfg, True, 400, command)
    assert calls["run"] > 100 and (calls["land_again"] > 20 or kind == "battery_empties")
    assert used > 100  # the compiled path flew many ticks
    assert (stopped > 0) == stops  # … and handed legs to the Python path where it must
    assert auto_stopped >= 1 or kind != "battery_empties"  # a take-off's run handed back
    # to the Python path (the battery might empty on the way: sensor_step._leg)
    assert auto_used > 20 and ends >= 1  # take-off, landing: their ends too (both,
    assert ends == 2 or kind in ("sag", "battery_empties")  # but a take-off the link-loss
    # watchdog's tick or an emptying battery ends)
    assert lands_again > 20 or kind == "battery_empties"  # REF land held again, written
    # out (but after a landing of its own)
    assert len(python) == len(compiled)
    for i, (a, b) in enumerate(zip(python, compiled)):
        assert a == b, f"tick {i}"


@pytest.mark.parametrize("name", ["square", "climb_into_cap", "turbulence", "second_order",
                                  "watchdogs", "sag", "kit", "kit_sag"])
def test_the_state_held_in_the_arrays_gives_the_python_paths_bits(name):
    """Every attribute read only every 23rd tick: between those the compiled legs hold the
    plant's state in their arrays run after run — the PCMD chain, the truth and the samples
    read from them — and what the plant's attributes then give back is the Python path's."""
    overrides, command, _ = CASES[name]
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), overrides)
    python, _ = _fly(cfg, False, 400, command, every=23)
    compiled, used = _fly(cfg, True, 400, command, every=23)
    assert used[4] > 150  # ticks flown with the state held
    assert len(python) == len(compiled)
    for i, (a, b) in enumerate(zip(python, compiled)):
        assert a == b, f"tick {i}"


def test_a_held_attribute_read_or_written_between_runs():
    """While the arrays hold the plant's state its attributes are out of the instance's
    dict; a read gives them all back (the value the Python path would hold), a write —
    a battery fault, say — is kept over the arrays' older value and taken up by the next
    run: the same flight as the Python path's."""
    from ardrone_nmpc.sim.plant import AirframePlant

    from tests.unit.test_held_state import CFG, _flying

    period = CFG.loop.period_s
    shots = []
    for legs in (False, True):
        drone = _flying(legs)  # three ticks aloft (held, with the legs)
        plant, compiled = drone.sim.plant, drone.sensors._legs
        t0 = drone.truth.t_s - 3 * period
        if legs:
            assert "_next_nav_k" not in vars(drone.sensors)
        state = plant._state  # a read: everything back
        if legs:
            assert not compiled.held() and {"_battery", "_fifo", "_current"} <= set(vars(plant))
            assert "_next_nav_k" in vars(drone.sensors)
        for k in range(4, 8):
            drone.advance_to(t0 + k * period)
            drone.set_command(0.1, -0.05, 0.1, 0.02)
        if legs:
            assert compiled.held()
        plant.set_battery_pct(50.0)  # a write while held (no read first)
        for k in range(8, 12):
            drone.advance_to(t0 + k * period)
            drone.set_command(-0.1, 0.05, 0.0, 0.0)
        shots.append((state, _snapshot(drone, drone.truth.t_s)))
    assert shots[0] == shots[1]
    with pytest.raises(AttributeError):  # not set, not held: an attribute error as ever
        AirframePlant.__new__(AirframePlant)._state


def test_the_kernels_entry_point_for_the_legs_own_arrays_only():
    """The legs call the kernel's compiled entry point for the array kinds they build (the
    dispatcher's choice for them); any other kind goes through the dispatcher."""
    from ardrone_nmpc.sim import lockstep_legs, sensor_step

    cfg, drone = _square_drone_aloft()
    legs = drone.sensors._legs
    x, rows, blocks = legs._held[0], legs._held[2], legs._blocks
    assert legs.held() and legs._kernel is not sensor_step.lockstep_run
    assert lockstep_legs._kernel_for(x, rows, blocks) is legs._kernel
    run = sensor_step.lockstep_run
    assert lockstep_legs._kernel_for(np.zeros(20)[::2], rows, blocks) is run
    assert lockstep_legs._kernel_for(x, np.asfortranarray(np.zeros((3, 5))), blocks) is run
    assert lockstep_legs._kernel_for(x, rows, (*blocks[:3], blocks[3].astype(np.float32))) is run


def test_the_kernels_one_buffer_and_what_one_unpack_reads_of_a_run():
    """The kernel's counters, state, parameters and output are views of one array (its one
    argument for them, none spilling into another); what the legs read of a run — the
    floats of out a tick reads, then iv's done, events and kinds — are those arrays' values,
    bit for bit."""
    from ardrone_nmpc.sim import lockstep_legs, sensor_step as ks

    cfg, drone = _square_drone_aloft()
    legs = drone.sensors._legs
    assert legs.held() and legs.live_out is not None
    views = {"out": (legs.out, ks.OUT_SIZE), "iv": (legs.iv, ks.IV_SIZE),
             "sv": (legs.sv, ks.SV_SIZE), "p": (legs.p, ks.P_SIZE)}
    for name, (view, size) in views.items():
        assert view.size == size and np.shares_memory(view, legs.buf), name
        assert not any(np.shares_memory(view, other) for other, _ in views.values()
                       if other is not view), name
    assert legs.iv.dtype == np.int64 and legs.out.dtype == legs.p.dtype == np.float64
    assert legs.p[ks.P_K:ks.P_KIT_K].tolist() == list(drone.sim.plant.params.rhs_coefficients)
    assert not legs.p[ks.P_KIT_K:].any()  # (the kit's coefficients: a kit plant's only)
    o, read = legs.live_out, lockstep_legs._RUN_READ
    assert len(set(read)) == len(read) == len(o) - 4 and max(read) < ks.OUT_SIZE
    assert np.array(o[:len(read)]).tobytes() == legs.out[list(read)].tobytes()
    assert o[len(read):] == tuple(legs.iv[ks.I_DONE:ks.I_KIND1 + 1].tolist())
    assert o[len(read)] > o[len(read) + 1]  # all legs done: more than the events
    # the truth's cells, and the times the PCMD chain and a REF read, are among them
    assert lockstep_legs.TRUTH_CELLS_OF(o) == tuple(legs.out[[ks.O_STATE + i for i in
                                                               (0, 1, 2, 8, 5)]].tolist())
    assert legs.t_s() == legs.out[ks.O_T] and legs.truth().t_s == legs.out[ks.O_T]


def test_the_legs_leave_a_tick_they_cannot_fly_untouched():
    """On the ground (and before any PCMD) the kernel's preconditions fail: run does nothing,
    holds nothing, and the Python path flies the tick."""
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])
    drone = LockstepDrone(cfg)
    legs = drone.sensors._legs
    assert drone.truth.mode is FlightMode.LANDED
    assert legs.run(0.1) is None and not legs.held()
    drone.advance_to(0.1)
    assert not legs.held() and drone.sensors.nav is not None


def test_a_ref_held_every_tick_leaves_the_legs_holding_the_state():
    """A landing holds REF land every tick: its time is the legs' last run's (the plant's
    own), read without releasing the state they hold — which the Python path would write
    back and the next run take again."""
    cfg, drone = _square_drone_aloft()
    legs = drone.sensors._legs
    for k in range(80, 84):
        drone.land()
        drone.advance_to(k * cfg.loop.period_s)
    assert legs.held() and drone.sim.plant.mode is FlightMode.LANDING
    t_s = legs.t_s()
    drone.land()  # as runtime/lockstep._land, every tick
    assert legs.held() and legs.t_s() == t_s
    legs.release()
    assert drone.sim.plant.t_s == t_s


def test_compiled_legs_with_a_scripted_target():
    cfg = load_config(str(ROOT / "configs" / "follow_car.yaml"), [])
    python, _ = _fly(cfg, False, 300, _zigzag)
    compiled, (used, *_) = _fly(cfg, True, 300, _zigzag)
    assert used > 100
    assert python == compiled


def test_the_kit_plant_flies_the_compiled_legs():
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [KIT])
    assert LockstepDrone(cfg).sensors._legs is not None


@pytest.mark.parametrize("kit", [False, True], ids=["airframe", "kit"])
@pytest.mark.parametrize("name", ["navdata", "mocap_pose", "advance", "_substep",
                                  "_advance_biases", "_motors_on_step", "truth",
                                  "_auto_command", "_at_rest", "_flying_advance"])
def test_a_plant_that_overrides_what_the_kernel_does_keeps_the_python_path(name, kit):
    """The compiled tick does the airframe's (or the kit's) dynamics, sensors and state in the
    plant's place: a subclass overriding any of them (a test emulator with a biased navdata,
    say) would see its override skipped aloft, so it flies the Python path; the airframe and
    the kit plant themselves are eligible."""
    from ardrone_nmpc.config.sim import NoiseConfig
    from ardrone_nmpc.sim.lockstep_legs import CompiledLegs
    from ardrone_nmpc.sim.plant import AirframePlant, PlantParams
    from ardrone_nmpc.sim.plant_kit import KitPlant

    plant = KitPlant if kit else AirframePlant
    base = getattr(plant, name)
    override = property(lambda self: base.fget(self)) if isinstance(base, property) else (
        lambda self, *a, **k: base(self, *a, **k))
    Overriding = type("Overriding", (plant,), {name: override})
    assert CompiledLegs.eligible(plant(PlantParams(), NoiseConfig(), seed=1))
    assert not CompiledLegs.eligible(Overriding(PlantParams(), NoiseConfig(), seed=1))


@pytest.mark.parametrize("owner,name", [("drone", "execute_pcmd"), ("drone", "_at_lost"),
                                        ("firmware", "execute_pcmd"), ("firmware", "_accept"),
                                        ("firmware", "apply_command"), ("plant", "command")])
def test_a_drone_that_overrides_the_pcmd_chain_keeps_it(owner, name):
    """CompiledLegs.command writes out the PCMD chain: a subclass overriding a link of it (a
    firmware with another sequence rule, say) keeps the chain, so its override runs."""
    from ardrone_nmpc.sim.drone import SimulatedDrone
    from ardrone_nmpc.sim.drone_firmware import DroneFirmware
    from ardrone_nmpc.sim.lockstep_legs import CompiledLegs
    from ardrone_nmpc.sim.plant import AirframePlant

    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])
    drone = LockstepDrone(cfg)
    legs = drone.sensors._legs
    assert legs.takes_commands and CompiledLegs.commands_eligible(drone.sim)
    obj = {"drone": drone.sim, "firmware": drone.sim.firmware, "plant": drone.sim.plant}[owner]
    base = {"drone": SimulatedDrone, "firmware": DroneFirmware, "plant": AirframePlant}[owner]
    method = getattr(base, name)
    obj.__class__ = type("Overriding", (base,), {name: lambda self, *a, **k: method(self, *a,
                                                                                     **k)})
    assert not CompiledLegs.commands_eligible(drone.sim)


def test_a_drone_with_injected_faults_keeps_the_pcmd_chain():
    """An injected AT loss drops datagrams in SimulatedDrone._at_lost: the chain stays."""
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), ["faults.at_loss.probability=0.3"])
    drone = LockstepDrone(cfg)
    assert drone.sim.faults is not None
    assert drone.sensors._legs is None or not drone.sensors._legs.takes_commands


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_command_is_refused_as_the_chain_refuses_it(bad):
    """A non-finite fraction: the plant's ValueError either way, and the same state after."""
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])
    shots = []
    for legs in (False, True):
        drone = LockstepDrone(cfg)
        if not legs:
            drone.sensors._legs = None
        drone.connect()
        drone.takeoff()
        while drone.truth.mode is not FlightMode.FLYING:
            drone.advance_to(drone.truth.t_s + 0.06)
        drone.set_command(0.1, 0.0, 0.2, 0.0)
        with pytest.raises(ValueError):
            drone.set_command(0.1, bad, 0.2, 0.0)
        drone.advance_to(drone.truth.t_s + 0.06)
        shots.append(_snapshot(drone, drone.truth.t_s))
    assert shots[0] == shots[1]


@pytest.mark.parametrize("owner,name", [
    ("firmware", "advance"), ("firmware", "watchdogs"), ("firmware", "silence"),
    ("firmware", "apply_command"), ("firmware", "_climb_may_reach_cap"),
    ("sensors", "_run_to"), ("sensors", "_direct_events"), ("sensors", "took_pose"),
    ("sensors", "took_navdata"),
    ("plant", "altitude_m_and_rate_mps"), ("plant", "t_s")])
def test_a_firmware_or_sampler_that_overrides_what_the_kernel_does_keeps_the_python_path(
        owner, name, monkeypatch):
    """The compiled tick stands in for the firmware's advance (its watchdogs, its altitude
    cap's checks) and the sampler's legs too, reading the plant's height and clock from its
    state: a firmware, sampler or plant class overriding one of those flies the Python path,
    so its override runs."""
    from ardrone_nmpc.sim import drone as drone_module
    from ardrone_nmpc.sim import lockstep_drone as lockstep_module
    from ardrone_nmpc.sim.drone_firmware import DroneFirmware
    from ardrone_nmpc.sim.plant import AirframePlant
    from ardrone_nmpc.sim.sensors import LockstepSensors

    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])
    assert LockstepDrone(cfg).sensors._legs is not None
    base = {"firmware": DroneFirmware, "sensors": LockstepSensors, "plant": AirframePlant}[owner]
    member = base.__dict__[name]
    override = (property(member.fget) if isinstance(member, property)
                else lambda self, *a, _m=member, **k: _m(self, *a, **k))
    kind = type("Overriding", (base,), {name: override})
    if owner == "firmware":
        monkeypatch.setattr(drone_module, "DroneFirmware", kind)
        drone = LockstepDrone(cfg)
    elif owner == "sensors":
        monkeypatch.setattr(lockstep_module, "LockstepSensors", kind)
        drone = LockstepDrone(cfg)
    else:
        drone = LockstepDrone(cfg, plant=kind.from_config(cfg.sim, cfg.drone))
    assert isinstance({"firmware": drone.sim.firmware, "sensors": drone.sensors,
                       "plant": drone.sim.plant}[owner], kind)
    assert drone.sensors._legs is None


def _square_drone_aloft():
    """The square's config and its lockstep drone, taken off and run 79 ticks (held)."""
    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])
    drone = LockstepDrone(cfg)
    drone.connect()
    drone.takeoff()
    for k in range(1, 80):
        drone.advance_to(k * cfg.loop.period_s)
    return cfg, drone


def test_a_mode_whose_guard_is_deferred_is_one_the_take_off_guard_lets_pass():
    """LockstepDrone._guard_ignores(mode) lets the compiled run show the guard a sample of a
    new mode only after the run: right only if the guard would do nothing on it. For every
    mode the firmware reports — every REF held, every history of the guard since the
    take-off, the firmware's status variants (moving or not, lost com, the altitude cap,
    fault bits, both ctrl codes) — a deferred mode's status makes the guard (and
    _on_navdata) do nothing; and the modes the guard acts on are not deferred."""
    import itertools

    from ardrone_nmpc.config.faults import DRONE_FAULT_BITS
    from ardrone_nmpc.links.drone_commands import TakeoffGuard
    from ardrone_nmpc.protocol.at import Ref
    from ardrone_nmpc.protocol.navdata import CtrlCodes, DroneState

    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])
    drone = LockstepDrone(cfg)
    drone.sensors._legs = drone._legs = None  # the plant's attributes set as they are
    fw, plant = drone.sim.firmware, drone.sim.plant
    faults = sum(int(DroneState[name]) for name in DRONE_FAULT_BITS)
    refs = (None, Ref.takeoff(), Ref.landing(), Ref.emergency())
    histories = ((False, False), (True, False), (True, True))  # seen airborne, flying
    variants = list(itertools.product(refs, (None, "landed by itself"), histories,
                                 ((0, 0.0, 0.0, 0.0, 0.0), (1, 0.1, 0.0, 0.2, 0.0)),
                                 (False, True), (False, True), (0, faults), CtrlCodes))
    deferred, acted = set(), set()
    for mode in FlightMode:
        for ref, landing, (airborne, flying), pcmd, lost, capped, bits, codes in variants:
            plant._mode, drone._ref, drone.self_landing = mode, ref, landing
            fw.pcmd, fw.lost_com_hover, fw.alt_capped = pcmd, lost, capped
            fw.fault_bits, fw.ctrl_codes = bits, codes
            status = fw.status(plant.t_s)
            state, major = status.state_bits(), status.ctrl_state(codes) >> 16
            guard = TakeoffGuard()
            guard.seen_airborne, guard.seen_flying = airborne, flying
            drone._guard = guard
            said = _copy_guard(guard).observe(state, major)  # (drone._guard's history kept)
            if drone._guard_ignores(mode):
                deferred.add(mode)
                if drone._guard_on():
                    assert said is None, (mode, ref, airborne, flying, pcmd, lost, codes)
                drone._on_navdata(state, major)
                assert drone._ref is ref and drone.self_landing == landing, mode
            elif said is not None:
                acted.add(mode)
    assert {FlightMode.LANDING, FlightMode.LANDED, FlightMode.EMERGENCY} <= acted
    assert not acted & {FlightMode.TAKING_OFF, FlightMode.FLYING}
    assert deferred == set(FlightMode)  # (every mode, with no take-off REF held)


def _copy_guard(guard):
    from ardrone_nmpc.links.drone_commands import TakeoffGuard

    copy = TakeoffGuard()
    copy.seen_airborne, copy.seen_flying = guard.seen_airborne, guard.seen_flying
    return copy


@pytest.mark.parametrize("start_s", [0.5, 3.0, 7.33])
def test_a_self_landing_under_the_compiled_legs_gives_the_python_paths_bits(start_s,
                                                                               monkeypatch):
    """The drone lands by itself while REF take-off is held: the take-off guard sees the
    landing's first sample inside a compiled run (LockstepDrone._guard_ignores says it must
    not be deferred) and holds REF land at once — the firmware's last_cmd_t, its com
    watchdog latch, the link's _seq and the counters, every tick, as the Python path's."""
    cfg = load_config(str(ROOT / "configs" / "square.yaml"),
                      [f"faults.self_land.start_s={start_s}"])
    calls = _count_compiled_calls(monkeypatch)
    python, _ = _fly(cfg, False, 200, _zigzag)
    assert calls == {"run": 0, "land_again": 0}
    compiled, (used, *_) = _fly(cfg, True, 200, _zigzag)
    assert used > 5 and calls["run"] > 5
    for shots in (python, compiled):  # the guard caught it (drone.self_landing, snapshotted)
        assert "the drone began to land (ctrl_state major 8)" in shots[-1]
    assert len(python) == len(compiled)
    for i, (a, b) in enumerate(zip(python, compiled)):
        assert a == b, f"tick {i}"


def test_a_take_off_handed_back_with_changing_commands_queued(monkeypatch):
    """A take-off whose climb settles while a climbing PCMD is held is handed back to the
    Python path (sensor_step._auto_leg: flown, found to end, undone). Commands that change
    every tick of the take-off leave rows unlike each other in the delay queue at the
    hand-back: the plant's queue and state, every tick, as the Python path's. (A queue left
    shifted by the undone leg would not show here — the Python path re-flies the leg, queuing
    the command over those rows before it reads them: the next test checks the kernel.)"""
    from ardrone_nmpc.sim.lockstep_legs import CompiledLegs

    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])

    def rising(k):  # gaz > 0: the firmware watches the cap, the take-off's end handed back
        return (0.01 * (k % 5), -0.02 * (k % 3), 0.3 + 0.05 * (k % 4), 0.01 * (k % 7))

    queued_at_hand_back = []
    run = CompiledLegs.run

    def watched(self, t_s):
        mode = self.plant.mode
        left = run(self, t_s)
        if left is not None and left[1] and mode is FlightMode.TAKING_OFF:
            rows = self.plant._fifo.rows  # (released: the plant's own)
            queued_at_hand_back.append(len(np.unique(rows, axis=0)))
        return left
    monkeypatch.setattr(CompiledLegs, "run", watched)
    python, _ = _fly(cfg, False, 60, _zigzag, takeoff_command=rising)
    assert queued_at_hand_back == []  # the reference is the Python path's own
    compiled, (used, _, auto_used, auto_stopped, *_) = _fly(cfg, True, 60, _zigzag,
                                                             takeoff_command=rising)
    assert auto_used > 5 and auto_stopped >= 1 and used > 20
    assert queued_at_hand_back and min(queued_at_hand_back) > 1  # rows that differ
    assert len(python) == len(compiled)
    for i, (a, b) in enumerate(zip(python, compiled)):
        assert a == b, f"tick {i}"


def test_a_take_offs_leg_handed_back_leaves_the_delay_queue_as_it_was():
    """sensor_step._auto_leg flies a take-off's leg in place and, finding that it ends the
    climb where the run may not fly the end (``sv[S_ENDS]`` 0), undoes it: the state and the
    delay queue as they were. The kernel run on the legs' own arrays, a queue of rows unlike
    each other and the command: after the run the queue is the one the legs it kept left
    (each of their steps queued the command at the head), no row more — the flight test above
    cannot see a row more, as the Python path re-flies the leg and queues the same command
    over it before reading it (an auto step ignores what it pops)."""
    from ardrone_nmpc.sim import sensor_step as ks

    cfg = load_config(str(ROOT / "configs" / "square.yaml"), [])
    drone = LockstepDrone(cfg)
    drone.connect()
    drone.takeoff()
    legs = drone.sensors._legs
    for k in range(1, 4):  # the take-off's first ticks, compiled (the arrays hold them)
        drone.advance_to(k * cfg.loop.period_s)
    assert legs.held() and legs.sv[ks.S_MODE] == ks.MODE_TAKING_OFF
    iv, sv, ring = legs.iv, legs.sv, legs._args[1]
    m = ring.shape[0]
    assert m > 2
    ring[:] = np.arange(m * 5, dtype=np.float64).reshape(m, 5) / 100.0 + 1.0
    command = (0.1, -0.2, 0.3, -0.4, 1.0)
    sv[ks.S_ROLL:ks.S_HOLD + 1] = command
    sv[ks.S_ENDS] = 0.0  # the end handed back
    sv[ks.S_T] += 10.0  # far beyond the climb's end
    rows, head, steps = ring.copy(), int(iv[ks.I_HEAD]), int(iv[ks.I_STEPS])
    legs._kernel(*legs._args)
    assert iv[ks.I_DONE] <= iv[ks.I_EVENTS]  # stopped before a leg: handed back
    assert sv[ks.S_MODE] == ks.MODE_TAKING_OFF
    kept = int(iv[ks.I_STEPS]) - steps  # the steps of the legs it kept
    assert kept < m and int(iv[ks.I_HEAD]) == (head + kept) % m
    for i in range(kept):
        rows[(head + i) % m] = command
    assert ring.tobytes() == rows.tobytes()
