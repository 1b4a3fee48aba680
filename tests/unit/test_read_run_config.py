"""A recording summarises its run with the recorder's config (``RunRecorder.config``) instead
of parsing ``config.yaml`` again (``read_run(config=…)``): that config is the one
``config.yaml`` loads back as, for every shipped config, a path run (its copied input file,
a relative log directory) and a sweep of random overrides."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest

from ardrone_nmpc.config.io import dump_config, load_config, load_run_config
from ardrone_nmpc.runs.rundir import CONFIG_FILE, RunRecorder, read_run

CONFIGS = sorted((Path(__file__).resolve().parents[2] / "configs").glob("*.yaml"))


def _same_as_read_back(rec: RunRecorder) -> None:
    loaded = load_run_config(rec.path / CONFIG_FILE)
    assert loaded == rec.config
    assert dump_config(loaded) == dump_config(rec.config)  # every value, the same text
    given = read_run(rec.path, config=rec.config)
    parsed = read_run(rec.path)
    assert (given.config, given.seed, given.version, given.events, given.warnings) == (
        parsed.config, parsed.seed, parsed.version, parsed.events, parsed.warnings)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_the_recorders_config_is_what_config_yaml_loads_back_as(tmp_path, path):
    with RunRecorder.create(tmp_path, load_config(path), seed=3) as rec:
        rec.event(0.0, "note", value=1.5)
    _same_as_read_back(rec)


def test_a_path_run_in_a_relative_log_directory(tmp_path, monkeypatch):
    source = tmp_path / "src" / "lap.csv"
    source.parent.mkdir()
    source.write_text("t_s,x_m,y_m,z_m,psi_rad\n0,0,0,1,0\n4,1,0,1,0\n8,1,1,1,0\n")
    cfg = load_config(overrides=["name=lap", "reference.kind=path",
                                 f"reference.path_file={source}"])
    monkeypatch.chdir(tmp_path)
    with RunRecorder.create(Path("logs"), cfg, seed=None) as rec:
        pass
    assert not rec.path.is_absolute() and os.path.isdir(rec.path)
    _same_as_read_back(rec)


def test_random_overrides(tmp_path):
    rng = random.Random(5)
    for i in range(20):
        sets = [f"duration_s={rng.choice([0.5, 7, 60.0, 1e-3, 12.345678901234567])}",
                f"sim.seed={rng.randint(0, 2**31)}",
                f"controller.horizon_steps={rng.randint(5, 30)}",
                f"controller.dtau_s={rng.uniform(0.01, 0.3)!r}",
                f"sim.settle_s={rng.choice([0.0, 0.1, 2.5])}"]
        cfg = load_config(rng.choice(CONFIGS), sets)
        with RunRecorder.create(tmp_path, cfg, seed=cfg.sim.seed) as rec:
            pass
        _same_as_read_back(rec)
