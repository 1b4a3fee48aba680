"""Command-line conventions: --version, shell completion, closed sets of values as choices
(exit 2 on a bad one), the deprecated spellings of the output options."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from ardrone_nmpc import __version__
from ardrone_nmpc.cli.app import app

runner = CliRunner()


def _complete(words: str) -> list[str]:
    """What bash completion offers after ``words`` (click's completion protocol)."""
    parts = words.split(" ")
    env = {"_ARDRONE_NMPC_COMPLETE": "complete_bash", "COMP_WORDS": words,
           "COMP_CWORD": str(len(parts) - 1)}
    result = runner.invoke(app, [], env=env, prog_name="ardrone-nmpc")
    assert result.exit_code == 0, result.output
    return result.output.split()


def test_version():
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0
    assert result.output == f"ardrone-nmpc {__version__}\n"


def test_completion_is_installable_and_completes_commands():
    result = runner.invoke(app, ["--show-completion", "bash"], prog_name="ardrone-nmpc")
    assert result.exit_code == 0 and "_ardrone_nmpc_completion" in result.output
    assert "complete " in result.output            # the script registers itself with bash
    assert _complete("ardrone-nmpc exp") == ["export"]
    assert "mocap-check" in _complete("ardrone-nmpc mo")


@pytest.mark.parametrize("args, message", [
    (["faults", "--faults", "bogus"], "error: --faults: unknown 'bogus'; choose from "),
    (["faults", "--experiments", "hover,loop"], "error: --experiments: unknown 'loop'; "),
    (["export", ".", "--format", "csv"], "error: --format: unknown 'csv'; choose mcap, parquet"),
    (["tune", "configs/step_z.yaml", "--engine", "ray"], "error: --engine: unknown 'ray'"),
    (["plot", ".", "--kind", "pie"], "error: --kind: unknown 'pie'"),
])
def test_a_value_outside_a_closed_set_exits_2_with_one_line(args, message):
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert result.output.startswith(message) and len(result.output.splitlines()) == 1


def test_closed_sets_complete_in_the_shell():
    assert _complete("ardrone-nmpc export run --format ") == ["mcap", "parquet"]
    assert _complete("ardrone-nmpc sweep c.yaml --engine d") == ["dask"]
    assert _complete("ardrone-nmpc faults --experiments hover,s") == ["hover,step",
                                                                     "hover,square"]
    assert "mocap_lost" in _complete("ardrone-nmpc faults --faults mocap_l")


def test_deprecated_spellings_are_rewritten_with_one_warning():
    from ardrone_nmpc.cli.options import modern_spellings

    warnings: list[str] = []
    args = ["c.yaml", "--out", "a", "--out=b", "--jobs", "2", "--", "--out"]
    assert modern_spellings("sweep", args, warnings.append) == [
        "c.yaml", "--output", "a", "--output=b", "--jobs", "2", "--", "--out"]
    assert warnings == ["warning: --out is deprecated; use -o/--output"]
    assert modern_spellings("export", ["--out", "x"], warnings.append) == ["--out", "x"]


@pytest.mark.timeout(120)
def test_sweep_out_still_works_and_says_it_is_deprecated(tmp_path):
    for spelling, where in (("--out", tmp_path / "old"), ("-o", tmp_path / "new")):
        result = runner.invoke(app, ["sweep", "configs/hover.yaml", "--grid", "duration_s=0.3",
                                     "--set", "sim.settle_s=0.2", "--jobs", "1", spelling,
                                     str(where)])
        assert result.exit_code == 0, result.output
        assert (where / "sweep.csv").is_file()
        deprecated = "warning: --out is deprecated; use -o/--output" in result.output
        assert deprecated == (spelling == "--out")


def _commands():
    import typer.main

    return typer.main.get_command(app).commands


def test_the_readme_says_which_commands_take_set():
    import re
    from pathlib import Path

    readme = (Path(__file__).parents[2] / "README.md").read_text(encoding="utf-8")
    para = readme[readme.index("Every command that reads an experiment config takes"):]
    takes, rest = para.split("; the others", 1)
    rest = rest.split("take none", 1)[0]
    said_yes = set(re.findall(r"`([a-z-]+)`", takes))
    said_no = set(re.findall(r"`([a-z-]+)`", rest))
    have = {name for name, cmd in _commands().items()
            if any("--set" in p.opts for p in cmd.params)}
    assert said_yes == have
    assert said_no == set(_commands()) - have


def test_output_options_have_one_spelling():
    """What a command writes is -o/--output; --out survives only as a deprecated spelling."""
    for name, cmd in _commands().items():
        opts = {o for p in cmd.params for o in p.opts}
        assert "--out" not in opts, name
        if "--output" in opts:
            (param,) = [p for p in cmd.params if "--output" in p.opts]
            assert param.opts == ["-o", "--output"], name


def test_the_lab_extra_holds_what_a_lab_needs():
    import tomllib
    from pathlib import Path

    project = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    extras = project["project"]["optional-dependencies"]
    (lab,) = extras["lab"]
    named = set(lab.split("[", 1)[1].rstrip("]").split(","))
    assert lab.startswith("ardrone-nmpc[") and named == {"mocap", "foxglove", "mcap", "tune",
                                                          "plot"}
    assert named <= set(extras)
