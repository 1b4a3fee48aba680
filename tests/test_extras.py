"""Every package of the ``test`` extra imports: a broken install fails the suite here, by name,
instead of skipping the tests that need it (the suite has no ``importorskip`` of an extra)."""

from __future__ import annotations

import importlib
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: requirement of the test extra → the module the tests import from it
MODULES = {
    "pytest": "pytest", "hypothesis": "hypothesis", "pytest-timeout": "pytest_timeout",
    "pytest-benchmark": "pytest_benchmark", "casadi": "casadi", "dask": "dask.distributed",
    "matplotlib": "matplotlib", "optuna": "optuna", "motioncapture": "motioncapture",
    "mcap": "mcap", "mcap-protobuf-support": "mcap_protobuf", "foxglove-sdk": "foxglove",
    "pyarrow": "pyarrow", "pandas": "pandas", "tornado": "tornado", "import-linter": "importlinter",
}


def _test_extra() -> list[str]:
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    return [re.match(r"[A-Za-z0-9_.-]+", req).group(0) for req in extras["test"]]


def test_every_requirement_of_the_test_extra_is_listed_here():
    assert sorted(_test_extra()) == sorted(MODULES)


@pytest.mark.parametrize("requirement", sorted(MODULES))
def test_the_test_extra_imports(requirement):
    importlib.import_module(MODULES[requirement])
