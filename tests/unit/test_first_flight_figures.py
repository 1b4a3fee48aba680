"""docs/figures/make_first_flight_figures.py draws the pictures docs/first-flight.md shows:
it runs headless, writes both, and the committed ones are the same size (regenerate them with
the script after changing it)."""

from __future__ import annotations

import importlib.util
import struct
from pathlib import Path

ROOT = Path(__file__).parents[2]
SCRIPT = ROOT / "docs" / "figures" / "make_first_flight_figures.py"


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    return struct.unpack(">II", data[16:24])


def test_the_figures_are_drawn_and_committed(tmp_path):
    spec = importlib.util.spec_from_file_location("make_first_flight_figures", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    written = module.main(tmp_path)
    assert [p.name for p in written] == list(module.FIGURES)
    page = (ROOT / "docs" / "first-flight.md").read_text(encoding="utf-8")
    for path in written:
        committed = ROOT / "docs" / "figures" / path.name
        assert _png_size(path) == _png_size(committed), path.name
        assert path.stat().st_size > 20_000            # a drawing, not an empty canvas
        assert f"figures/{path.name}" in page           # and the page shows it


def test_the_checklist_fits_a_printed_page_and_names_real_commands():
    page = (ROOT / "docs" / "first-flight-checklist.md").read_text(encoding="utf-8")
    lines = page.splitlines()
    assert len(lines) <= 60 and max(len(line) for line in lines) <= 100   # one A4 page
    assert sum(line.lstrip().startswith("- [ ]") for line in lines) >= 20
    import re

    import typer.main

    from ardrone_nmpc.cli.app import app

    commands = set(typer.main.get_command(app).commands)
    used = set(re.findall(r"`ardrone-nmpc ([a-z][a-z-]*)", page))
    assert used and used <= commands
