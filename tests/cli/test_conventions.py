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
