"""Tests of the experiment schema, loading, overrides and dumping (ardrone_nmpc.config.schema)."""

from __future__ import annotations

import json
import math
import pickle
import re
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import BaseModel, ValidationError

from ardrone_nmpc.config.schema import ConfigError, ExperimentConfig, config_from_dict
from ardrone_nmpc.config.io import apply_overrides, config_to_dict, dump_config, load_config
from ardrone_nmpc.config.limits import MAX_COORDINATE_M, MAX_NAME_CHARS, MAX_SPAN_S

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"


def write(tmp_path: Path, text: str, name: str = "exp.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def errors_of(text: str, tmp_path: Path) -> list[str]:
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, text))
    return info.value.messages


# ----------------------------------------------------------------------------- defaults


def test_defaults_are_the_thesis_values_but_the_robust_x_y_weights():
    cfg = load_config()
    assert cfg.controller.kind == "nmpc"
    assert cfg.controller.horizon_steps == 15
    assert cfg.controller.dtau_s == 0.1
    # z and ψ the thesis'; x and y detuned (docs/solver-notes.md §10)
    assert cfg.controller.q[4:] == (5, 10, 13) and cfg.controller.r[::3] == (4, 24)
    assert cfg.controller.q[:4] == (4, 0.5, 4, 0.5) and cfg.controller.r[1:3] == (48, 48)
    assert (cfg.controller.delay_compensation_s, cfg.controller.attitude_gain) == ("auto",
                                                                                   "auto")
    assert cfg.controller.q_terminal == (0,) * 7
    assert cfg.controller.u_min == (-1,) * 4 and cfg.controller.u_max == (1,) * 4
    assert cfg.estimator.kind == "kalman"
    assert cfg.estimator.kalman_q == 2.8559e-4
    assert cfg.estimator.kalman_r == 3.2e-3
    assert cfg.estimator.luenberger_lambda0_per_s == 5.0
    assert cfg.estimator.luenberger_gain is None
    assert cfg.loop.period_s == 0.065
    assert cfg.sim.plant.command_delay_s == 0.26
    assert cfg.drone.euler_angle_max_rad == 0.2094
    assert cfg.sim.noise.mocap_angle_std_rad == pytest.approx(math.radians(0.1))
    assert (cfg.safety.mocap_hold_ms, cfg.safety.mocap_hover_ms, cfg.safety.mocap_land_ms) == (
        100, 250, 1000)


def test_no_file_and_empty_mapping_give_the_defaults_an_empty_file_is_an_error(tmp_path):
    assert load_config() == ExperimentConfig()
    assert load_config(write(tmp_path, "{}\n")) == ExperimentConfig()
    assert config_from_dict({}) == ExperimentConfig()
    with pytest.raises(ConfigError, match=r"empty file \(no settings\); write \{\} in it"):
        load_config(write(tmp_path, "# only a comment\n"))


def test_config_is_frozen():
    cfg = load_config()
    with pytest.raises(ValidationError):
        cfg.controller.horizon_steps = 3  # type: ignore[misc]


def _models(model: type[BaseModel]):
    yield model
    for field in model.model_fields.values():
        annotation = field.annotation
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            yield from _models(annotation)


@pytest.mark.parametrize("model", list(_models(ExperimentConfig)), ids=lambda m: m.__name__)
def test_every_field_is_documented_and_sections_forbid_extras(model):
    assert model.model_config.get("extra") == "forbid"
    assert model.model_config.get("frozen") is True
    for name, field in model.model_fields.items():
        assert field.description and len(field.description) > 5, f"{model.__name__}.{name}"


# ----------------------------------------------------------------------------- rejection


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("bogus: 1\n", "bogus: Extra inputs are not permitted"),
        ("controller:\n  bogus: 1\n", "controller.bogus: Extra inputs are not permitted"),
        ("controller:\n  solver:\n    kmaxx: 3\n",
         "controller.solver.kmaxx: Extra inputs are not permitted"),
        ("sim:\n  plant:\n    drag: 0.5\n", "sim.plant.drag: Extra inputs are not permitted"),
    ],
)
def test_unknown_keys_are_rejected_at_their_path(tmp_path, text, expected):
    with pytest.raises(ConfigError, match=f"^{re.escape(expected)}$"):
        load_config(write(tmp_path, text))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("controller: {dtau_s: -0.1}", "controller.dtau_s: Input should be greater than 0"),
        ("controller: {horizon_steps: 0}",
         "controller.horizon_steps: Input should be greater than or equal to 1"),
        ("controller: {solver: {kmax: 0}}",
         "controller.solver.kmax: Input should be greater than or equal to 1"),
        ("controller: {q: [1, 2, .nan, 4, 5, 6, 7]}",
         "controller.q.2: Input should be a finite number"),
        ("controller: {r: [1, 2, 3, 0]}", "controller.r.3: Input should be greater than 0"),
        ("controller: {q: [1, 2, 3]}", "controller.q: expected 7 values, got 3"),
        ("controller: {q: 5}", "controller.q: Input should be a valid tuple"),
        ("controller: {u_min: [0, -1, -1, -1], u_max: [0, 1, 1, 1]}",
         "controller.u_max: must be greater than u_min at index 0"),
        ("controller: {u_min: [-1, -1, 2, -1]}",
         "controller.u_max: must be greater than u_min at index 2"),
        ("controller: {kind: mpc}", "controller.kind: Input should be 'nmpc' or 'p'"),
        ("controller: 5", "controller: Input should be a valid dictionary"),
        ("duration_s: .inf", "duration_s: Input should be a finite number"),
        ("name: my run", "name: String should match pattern"),
        ("estimator: {luenberger_gain: [10, -1]}",
         "estimator.luenberger_gain.1: Input should be greater than 0"),
        ("reference: {kind: path}", "reference.path_file: required when kind is 'path'"),
        ("reference: {kind: path, path_file: ''}",
         "reference.path_file: String should have at least 1 character"),
        # everything that becomes a count, an allocation or a coordinate is bounded
        ("duration_s: 1e308", "duration_s: Input should be less than or equal to 3600"),
        ("sim: {settle_s: 1e308}", "sim.settle_s: Input should be less than or equal to 3600"),
        ("reference: {kind: square, leg_duration_s: 1e308}",
         "reference.leg_duration_s: Input should be less than or equal to 3600"),
        ("reference: {step_time_s: 3601}",
         "reference.step_time_s: Input should be less than or equal to 3600"),
        ("reference: {period_s: 1e9}", "reference.period_s: Input should be less than or equal"),
        ("reference: {start_m: [100000000, 0, 1]}",
         "reference.start_m.0: Input should be less than or equal to 1000"),
        ("reference: {kind: lorenz, lorenz_time_scale: 1.0}\nduration_s: 300",
         "reference: lorenz_time_scale × duration_s is 300 Lorenz time units; at most 200"),
        ("controller: {obstacles: [{kind: sphere, center_m: [0, -1e9, 1], radius_m: 1}]}",
         "controller.obstacles.0.center_m.1: Input should be greater than or equal to -1000"),
        ("controller: {solver: {max_newton_iterations: 1000000000}}",
         "controller.solver.max_newton_iterations: Input should be less than or equal to 1000"),
        ("safety: {geofence_max_m: [3, 3, 1e300]}",
         "safety.geofence_max_m.2: Input should be less than or equal to 1000"),
        ("sim: {mocap_rate_hz: 1e-300}", "sim.mocap_rate_hz: Input should be greater than or equal to 1"),
        ("drone: {altitude_max_m: 1e308}", "drone.altitude_max_m: Input should be less than or equal to 100"),
        ("name: " + "n" * 201, "name: String should have at most 200 characters"),
        ("mocap: {rate_hz: 100}", "mocap.rate_hz: no longer a setting (removed: nothing read it"),
        ("reference: {kind: square, leg_duration_s: 1e-308}",
         "reference.leg_duration_s: Input should be greater than or equal to 0.001"),
        ("controller: {dtau_s: 1e308}", "controller.dtau_s: Input should be less than or equal to 1"),
        ("sim: {noise: {mocap_angle_std_rad: 1e308}}",
         "sim.noise.mocap_angle_std_rad: Input should be less than or equal to 3.14"),
        ("sim: {plant: {battery_drain_pct_per_min: 1e308}}",
         "sim.plant.battery_drain_pct_per_min: Input should be less than or equal to 100"),
        ("safety: {mocap_hover_ms: 1500}",
         "safety.mocap_land_ms: must be greater than mocap_hover_ms"),
        ("safety: {mocap_hold_ms: 300}",
         "safety.mocap_hover_ms: must be greater than mocap_hold_ms"),
        ("safety: {geofence_max_m: [3, 3, -0.5]}",
         "safety.geofence_max_m: must be greater than geofence_min_m at index 2"),
        ("drone: {keepalive_interval_s: 0.05}",
         "drone.keepalive_interval_s: Input should be less than or equal to 0.03"),
        ("drone: {at_port: 70000}", "drone.at_port: Input should be less than or equal to 65535"),
        ("mocap: {object_name: a_name_longer_than_24_chars}",
         "mocap.object_name: String should have at most 24 characters"),
        ("sim: {plant: {initial_position_m: [0, 0, -1]}}",
         "sim.plant.initial_position_m: z must be ≥ 0"),
    ],
)
def test_bad_values_are_reported_once_at_their_path(tmp_path, text, expected):
    messages = errors_of(text + "\n", tmp_path)
    assert len(messages) == 1, messages
    assert messages[0].startswith(expected), messages


def test_every_error_is_reported_not_just_the_first(tmp_path):
    messages = errors_of(
        "controller: {horizon_steps: 0, dtau_s: 0}\nloop: {period_s: -1}\nbogus: 1\n", tmp_path)
    assert sorted(m.split(":")[0] for m in messages) == [
        "bogus", "controller.dtau_s", "controller.horizon_steps", "loop.period_s"]
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, "loop: {period_s: -1}\nbogus: 1\n"))
    assert str(info.value) == "\n".join(info.value.messages)


def test_scientific_notation_without_a_dot_is_a_float(tmp_path):
    # PyYAML reads `1e-4` as a string; the schema must still take it as a number.
    cfg = load_config(write(tmp_path, "estimator: {kalman_q: 1e-4}\ncontroller: {q: [1e1, 0, 0, 0, 0, 0, 0]}\n"))
    assert cfg.estimator.kalman_q == 1e-4
    assert cfg.controller.q[0] == 10.0


# ----------------------------------------------------------------------------- path_file


def test_relative_path_file_is_resolved_against_the_config_directory(tmp_path, monkeypatch):
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "traj.csv").write_text("t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n1,1,0,1,0\n")
    config = write(sub, "reference: {kind: path, path_file: traj.csv}\n")
    monkeypatch.chdir(tmp_path)  # not the config's directory
    cfg = load_config(config)
    assert Path(cfg.reference.path_file) == (sub / "traj.csv").resolve()
    # given as an override, a relative path is relative to the working directory
    cfg = load_config(None, ["reference.kind=path", "reference.path_file=sub/traj.csv"])
    assert Path(cfg.reference.path_file) == (sub / "traj.csv").resolve()
    # the stored absolute path survives a dump/load round trip
    assert ExperimentConfig.model_validate(yaml.safe_load(dump_config(cfg))) == cfg


def test_the_path_file_is_not_read_when_the_config_loads(tmp_path):
    # Its contents are checked where the trajectory is built (`check`, before a run
    # directory is made), so an old run whose file is gone still loads.
    cfg = load_config(write(tmp_path, "reference: {kind: path, path_file: missing.csv}\n"))
    assert Path(cfg.reference.path_file) == (tmp_path / "missing.csv").resolve()


def test_a_retired_key_is_an_error_in_a_config_and_dropped_from_a_run_directory(tmp_path):
    path = write(tmp_path, "mocap: {rate_hz: 100.0, port: 51002}\n")
    with pytest.raises(ConfigError, match=r"mocap\.rate_hz: no longer a setting"):
        load_config(path)
    assert load_config(path, allow_retired=True).mocap.port == 51002


def test_the_longest_name_and_the_bounds_themselves_are_valid():
    cfg = config_from_dict({"name": "n" * MAX_NAME_CHARS, "duration_s": MAX_SPAN_S,
                            "sim": {"settle_s": MAX_SPAN_S},
                            "reference": {"start_m": [-MAX_COORDINATE_M, MAX_COORDINATE_M, 1]}})
    assert len(cfg.name) == MAX_NAME_CHARS and cfg.duration_s == MAX_SPAN_S


# ----------------------------------------------------------------------------- overrides


def test_overrides_parse_yaml_types_and_create_intermediate_mappings():
    base = {"controller": {"kind": "nmpc", "horizon_steps": 15}}
    out = apply_overrides(base, [
        "controller.horizon_steps=10",
        "controller.dtau_s=0.2",
        "controller.q=[1,2,3,4,5,6,7]",
        "controller.kind=p",
        "estimator.luenberger_gain=null",
        "controller.solver.kmax = 8",
    ])
    assert out == {
        "controller": {"kind": "p", "horizon_steps": 10, "dtau_s": 0.2,
                       "q": [1, 2, 3, 4, 5, 6, 7], "solver": {"kmax": 8}},
        "estimator": {"luenberger_gain": None},
    }
    assert type(out["controller"]["horizon_steps"]) is int
    assert type(out["controller"]["dtau_s"]) is float
    assert base == {"controller": {"kind": "nmpc", "horizon_steps": 15}}  # input untouched


def test_overrides_replace_file_values_and_later_ones_win(tmp_path):
    path = write(tmp_path, "controller: {horizon_steps: 0}\n")  # invalid on its own
    cfg = load_config(path, ["controller.horizon_steps=6", "controller.horizon_steps=7"])
    assert cfg.controller.horizon_steps == 7
    cfg = load_config(path, ["controller.horizon_steps=6", "estimator.luenberger_gain=[8, 16]"])
    assert cfg.estimator.luenberger_gain == (8.0, 16.0)


def test_an_override_to_an_invalid_value_is_reported_at_its_path():
    with pytest.raises(ConfigError, match=r"^controller\.solver\.kmax: Input should be greater"):
        load_config(None, ["controller.solver.kmax=0"])
    with pytest.raises(ConfigError, match=r"^controller\.bogus: Extra inputs are not permitted$"):
        load_config(None, ["controller.bogus=1"])


@pytest.mark.parametrize("override", ["controller.kind", "=5", "a..b=1", " =1", "a.=2"])
def test_malformed_override(override):
    with pytest.raises(ConfigError) as info:
        apply_overrides({}, [override])
    assert info.value.messages == [f"override '{override}': expected dotted.path=value"]


def test_override_through_a_scalar_is_an_error():
    with pytest.raises(ConfigError, match=r"override 'duration_s\.x=1': duration_s is not a"):
        apply_overrides({"duration_s": 5.0}, ["duration_s.x=1"])


# ----------------------------------------------------------------------------- file errors


def test_missing_config_file(tmp_path):
    path = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert info.value.messages == [f"{path}: no such file"]


def test_yaml_syntax_error_reports_the_line(tmp_path):
    path = write(tmp_path, "name: ok\nloop:\n  period_s: 0.1\n   bad: 1\n")
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: invalid YAML \(line 4\): "):
        load_config(path)


def test_duplicate_keys_are_an_error(tmp_path):
    path = write(tmp_path, "controller:\n  horizon_steps: 10\n  horizon_steps: 12\n")
    with pytest.raises(ConfigError, match=r"invalid YAML \(line 3\): duplicate key 'horizon_steps'"):
        load_config(path)


@pytest.mark.parametrize("text", ["- 1\n- 2\n", "just a string\n", "42\n"])
def test_top_level_must_be_a_mapping(tmp_path, text):
    with pytest.raises(ConfigError, match="top level must be a mapping"):
        load_config(write(tmp_path, text))


def test_config_error_survives_pickling():
    err = pickle.loads(pickle.dumps(ConfigError(["a.b: one", "c: two"])))
    assert err.messages == ["a.b: one", "c: two"]
    assert str(err) == "a.b: one\nc: two"


# ----------------------------------------------------------------------------- dumping


def test_dump_load_round_trip_of_a_non_default_config(tmp_path):
    cfg = load_config(None, [
        "name=rt", "controller.kind=p", "controller.q=[1.5,0,2,0,3,0,1e-3]",
        "estimator.luenberger_gain=[12.5, 40]", "sim.noise.mocap_angle_std_rad=0.1",
        "reference.kind=ellipse", "safety.solver_fallback=hover", "drone.navdata_demo=false",
    ])
    data = config_to_dict(cfg)
    assert data["controller"]["q"] == [1.5, 0, 2, 0, 3, 0, 1e-3]
    assert isinstance(data["controller"]["q"], list)
    json.dumps(data)  # JSON-safe
    text = dump_config(cfg)
    assert list(yaml.safe_load(text)) == list(ExperimentConfig.model_fields)  # declared order
    assert ExperimentConfig.model_validate(yaml.safe_load(text)) == cfg
    path = write(tmp_path, dump_config(cfg, header="ardrone-nmpc 0.1.0\nseed 0"))
    assert path.read_text().startswith("# ardrone-nmpc 0.1.0\n# seed 0\n")
    assert load_config(path) == cfg


@settings(max_examples=60, deadline=None)
@given(
    horizon_steps=st.integers(min_value=1, max_value=500),
    dtau_s=st.floats(min_value=1e-6, max_value=1.0, allow_nan=False, allow_infinity=False),
    kmax=st.integers(min_value=1, max_value=200),
)
def test_any_valid_horizon_triple_round_trips_through_overrides(horizon_steps, dtau_s, kmax):
    cfg = load_config(None, [
        f"controller.horizon_steps={horizon_steps}",
        f"controller.dtau_s={dtau_s!r}",
        f"controller.solver.kmax={kmax}",
    ])
    assert (cfg.controller.horizon_steps, cfg.controller.dtau_s, cfg.controller.solver.kmax) == (
        horizon_steps, dtau_s, kmax)
    assert ExperimentConfig.model_validate(yaml.safe_load(dump_config(cfg))) == cfg


# ----------------------------------------------------------------------------- shipped files


SHIPPED = sorted(CONFIG_DIR.glob("*.yaml"))


def test_the_thesis_configs_are_shipped():
    assert {"hover", "step_x", "step_z", "square"} <= {p.stem for p in SHIPPED}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_every_shipped_config_loads(path):
    cfg = load_config(path)
    assert cfg.name == path.stem


def test_shipped_step_configs_match_the_thesis_experiments():
    step_x = load_config(CONFIG_DIR / "step_x.yaml")
    assert step_x.reference.kind == "step"
    assert step_x.reference.start_m == (0, 0, 1) and step_x.reference.target_m == (-1.5, 0, 1)
    assert step_x.reference.step_time_s == 1.0 and step_x.duration_s == 20.0
    step_z = load_config(CONFIG_DIR / "step_z.yaml")
    # "take-off to 1 m": from a low hover after the on-board take-off, up to 1 m
    assert step_z.reference.start_m[2] < 0.5 and step_z.reference.target_m == (0, 0, 1)
    assert step_z.reference.step_time_s > 0.0 and step_z.duration_s >= 10.0
    square = load_config(CONFIG_DIR / "square.yaml")
    assert square.reference.kind == "square" and square.reference.side_m == 1.0
    assert square.reference.start_m[2] == 1.0 and square.reference.leg_duration_s == 5.0
    assert square.duration_s == 25.0


def test_mocap_latency_beyond_what_lockstep_can_represent_is_refused():
    with pytest.raises(ConfigError, match=r"sim\.noise\.mocap_latency_ms:"):
        load_config(None, ["sim.noise.mocap_latency_ms=100"])
