"""``tune``'s search space at its edges, against docs/tuning.md and the space module's own
contract: each mistake's one line as documented, the boundaries of every check (a factor of 1,
low = high, an index one past the end, a range holding a single integer), paths three levels
deep, and a config as written resolved against the directory it came from."""

from __future__ import annotations

from pathlib import Path

import pytest

from ardrone_nmpc.config.io import config_to_dict, load_config
from ardrone_nmpc.config.schema import ConfigError
from ardrone_nmpc.experiments.tune.space import (apply_params, config_with, default_space,
                                                 load_space, parse_space, written_config)

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.fixture(scope="module")
def step_z():
    return load_config(CONFIGS / "step_z.yaml")


def _messages(spec, cfg, where="--space s.yaml") -> list[str]:
    with pytest.raises(ConfigError) as err:
        parse_space(spec, cfg, where=where)
    return err.value.messages


@pytest.mark.parametrize("name, entry, message", [
    ("controller.q[-1]", {"factor": 2},
     "expected a dotted config path, optionally with [index]"),
    ("controller.dtau_s[0]", {"factor": 2}, "not a vector with an element 0"),
    ("controller.q[7]", {"factor": 2}, "not a vector with an element 7"),  # q has 7: 0…6
    ("controller.dtau_s", 5, "expected a mapping {low, high[, log, type]} or {factor}"),
    ("controller.dtau_s", {"lo": 1, "hi": 2},
     "unknown key(s) hi, lo; expected factor, high, log, low, type"),
    ("controller.dtau_s", {"low": 0.1, "high": 0.2, "type": "double"},
     "type 'double': choose float or int"),
    ("controller.q", {"low": 1, "high": 2},
     "a vector takes {factor: F}; bound single elements with path[i]: {low, high}"),
    ("controller.dtau_s", {"factor": 2, "high": 0.3}, "give factor or low/high, not both"),
    ("controller.dtau_s", {"factor": 1}, "factor 1: must be a finite number > 1"),
    ("controller.dtau_s", {"low": 0.1, "high": 0.1}, "needs finite numbers low < high"),
])
def test_each_entry_mistake_is_its_documented_line(step_z, name, entry, message):
    messages = _messages({"params": {name: entry}}, step_z)
    assert messages == [f"--space s.yaml: params.{name}: {message}"]


def test_a_factor_needs_a_positive_config_value():
    cfg = load_config(None, ["controller.q=[0, 2, 7, 2, 5, 10, 13]"])
    assert _messages({"params": {"controller.q[0]": {"factor": 2}}}, cfg) == [
        "--space s.yaml: params.controller.q[0]: factor needs a positive config value "
        "(it is 0.0)"]


def test_a_factor_just_above_1_and_an_int_range_holding_one_integer_are_drawable(step_z):
    space = parse_space({"factor": 1.5, "params": {
        "controller.dtau_s": {"factor": 1.5},
        "controller.horizon_steps": {"low": 10.2, "high": 11, "type": "int"},
        "controller.vz_lead_s": {"factor": 2, "type": "int"}}}, step_z)
    q4 = step_z.controller.q[4]
    assert (space["controller.q[4]"].low, space["controller.q[4]"].high) == pytest.approx(
        (q4 / 1.5, q4 * 1.5))
    dt = step_z.controller.dtau_s
    assert (space["controller.dtau_s"].low, space["controller.dtau_s"].high) == pytest.approx(
        (dt / 1.5, dt * 1.5))
    hs = space["controller.horizon_steps"]
    assert (hs.low, hs.high, hs.kind) == (10.2, 11.0, "int")
    assert space["controller.vz_lead_s"].kind == "int"  # a factor keeps the entry's type
    assert space["controller.dtau_s"].kind == "float"
    for name, p in space.items():  # every parameter is filed under its own name
        assert p.name == name


@pytest.mark.parametrize("factor", [1, 0.5])
def test_a_space_factor_of_1_or_less_is_refused(step_z, factor):
    assert _messages({"factor": factor}, step_z) == [
        f"--space s.yaml: factor: {factor!r} must be a finite number > 1"]


def test_a_range_without_log_is_linear(step_z):
    space = parse_space({"params": {"controller.dtau_s": {"low": 0.05, "high": 0.2}}}, step_z)
    assert space["controller.dtau_s"].log is False


def test_no_spec_is_the_default_space_and_messages_name_the_option(step_z):
    assert parse_space(None, step_z) == default_space(step_z)
    with pytest.raises(ConfigError) as err:
        parse_space([1, 2], step_z)
    assert err.value.messages == ["--space: expected a mapping with default, factor, params"]
    with pytest.raises(ConfigError) as err:
        parse_space({"params": [1, 2]}, step_z)
    assert err.value.messages == [
        "--space: params: expected a mapping of config paths to ranges"]


def test_a_factor_beyond_the_doubles_is_one_line_even_with_params(step_z):
    messages = _messages({"factor": 1e308,
                          "params": {"controller.dtau_s": {"low": 0.05, "high": 0.2}}}, step_z)
    assert len(messages) == 1 and messages[0].startswith("--space s.yaml: factor: 1e+308: ")


def test_every_safety_limit_is_refused_and_the_rest_still_checked(step_z):
    messages = _messages({"params": {
        "safety.max_tilt_rad": {"low": 0.1, "high": 0.3},
        "safety.geofence_max_m": {"factor": 2},
        "controller.nope": {"low": 1, "high": 2}}}, step_z)
    why = "the safety limits are not searched (set them with --set; tune the controller, " \
          "not the supervisor)"
    assert messages == [f"--space s.yaml: params.safety.max_tilt_rad: {why}",
                        f"--space s.yaml: params.safety.geofence_max_m: {why}",
                        "--space s.yaml: params.controller.nope: no such config value"]
    # a section merely named like it is not the safety section
    assert "sim.plant.tau_vz_s" in parse_space(
        {"params": {"sim.plant.tau_vz_s": {"factor": 2}}}, step_z)


def test_load_space_reads_the_file_and_names_it(step_z, tmp_path):
    assert load_space(None, step_z) == default_space(step_z)
    good = tmp_path / "s.yaml"
    good.write_text("default: false\nparams:\n  controller.dtau_s: {low: 0.05, high: 0.2}\n")
    assert list(load_space(good, step_z)) == ["controller.dtau_s"]
    bad = tmp_path / "b.yaml"
    bad.write_text("params:\n  controller.nope: {low: 1, high: 2}\n")
    with pytest.raises(ConfigError) as err:
        load_space(bad, step_z)
    assert err.value.messages == [f"--space {bad}: params.controller.nope: no such config value"]
    with pytest.raises(ConfigError) as err:
        load_space(tmp_path / "missing.yaml", step_z)
    assert err.value.messages[0].startswith(f"--space {tmp_path / 'missing.yaml'}: cannot read")


def test_params_three_levels_deep_land_where_their_path_says(step_z):
    resolved = config_to_dict(step_z)
    out = apply_params({"sim": {"seed": 3}}, {"sim.plant.tau_vz_s": 0.7,
                                             "sim.plant.initial_position_m[2]": 1.5},
                       resolved=resolved)
    plant = out["sim"]["plant"]
    assert plant["tau_vz_s"] == 0.7 and out["sim"]["seed"] == 3
    start = list(resolved["sim"]["plant"]["initial_position_m"])
    start[2] = 1.5
    assert plant["initial_position_m"] == start
    assert set(plant) == {"tau_vz_s", "initial_position_m"}  # nothing else copied in
    # a vector the config writes, three levels deep: its other elements are the written ones
    written = apply_params({"sim": {"plant": {"initial_position_m": [0.5, -0.5, 2.0]}}},
                           {"sim.plant.initial_position_m[2]": 1.5}, resolved=resolved)
    assert written["sim"]["plant"] == {"initial_position_m": [0.5, -0.5, 1.5]}
    full = apply_params(resolved, {"sim.plant.tau_vz_s": 0.7})
    assert full["sim"]["plant"] == dict(resolved["sim"]["plant"], tau_vz_s=0.7)


def test_two_elements_of_one_vector_both_stay_set(step_z):
    """The second element of a vector copied from ``resolved`` must not copy it again over
    the first; a vector the config writes keeps its own other elements."""
    resolved = config_to_dict(step_z)
    out = apply_params({}, {"controller.q[4]": 80.0, "controller.q[5]": 9.0},
                       resolved=resolved)
    q = list(step_z.controller.q)
    q[4], q[5] = 80.0, 9.0
    assert out == {"controller": {"q": q}}
    written = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    out = apply_params({"controller": {"q": written}}, {"controller.q[0]": 0.5},
                       resolved=resolved)
    assert out["controller"]["q"] == [0.5, *written[1:]]


def test_config_with_rounds_int_parameters(step_z):
    space = parse_space({"params": {"controller.horizon_steps": {"low": 5, "high": 30,
                                                                  "type": "int"}}}, step_z)
    cfg = config_with(step_z, {"controller.horizon_steps": 11.6}, space)
    assert cfg.controller.horizon_steps == 12


def test_written_config_resolves_files_against_their_own_directories(tmp_path, monkeypatch):
    """Relative files in the config file are its directory's; in ``--set`` the working
    directory's (as :func:`load_config` reads them)."""
    conf = tmp_path / "conf"
    conf.mkdir()
    (conf / "c.yaml").write_text("reference:\n  path_file: p.csv\n"
                                 "sim:\n  plant:\n    profile: prof.yaml\n")
    assert written_config(None, ["sim.seed=5"]) == {"sim": {"seed": 5}}
    data = written_config(conf / "c.yaml", [])
    assert data["reference"]["path_file"] == str((conf / "p.csv").resolve())
    assert data["sim"]["plant"]["profile"] == str((conf / "prof.yaml").resolve())
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    data = written_config(conf / "c.yaml", ["reference.path_file=q.csv",
                                            "sim.plant.profile=other.yml"])
    assert data["reference"]["path_file"] == str((work / "q.csv").resolve())
    assert data["sim"]["plant"]["profile"] == str((work / "other.yml").resolve())
