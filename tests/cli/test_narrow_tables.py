"""Tables on an 80-column terminal: a table that does not fit is shown as one block per row,
every value whole (no `…` cell), every line within the width; one that fits is unchanged."""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from ardrone_nmpc.cli.narrow import fit


def _wide_table() -> Table:
    table = Table(title="best 2 of 40 trials")
    for head in ("#", "trial", "score", "status", *(f"q[{i}]" for i in range(7)),
                 *(f"r[{i}]" for i in range(4)), "track_m", "settle_s", "over_%"):
        table.add_column(head)
    table.add_row("1", "17", "58.38", "[green]ok[/]", *(f"{10.05 + i:.4g}" for i in range(11)),
                  "0.3076", "—", "0")
    table.add_row("2", "3", "98.68", "aborted", *(f"{1234.5678 + i:.4g}" for i in range(11)),
                  "0.2191", "9.049", "")
    return table


def _render(renderable, width: int) -> list[str]:
    console = Console(width=width, record=True, color_system=None)
    console.print(renderable)
    return console.export_text().splitlines()


def test_a_wide_table_becomes_blocks_with_whole_values():
    console = Console(width=80)
    lines = _render(fit(_wide_table(), console), 80)
    text = "\n".join(lines)
    assert "…" not in text and all(len(line) <= 80 for line in lines)
    assert lines[0] == "best 2 of 40 trials"
    assert lines[1].startswith("# 1  trial 17  score 58.38  status ok  q[0] 10.05")
    for value in ("1235", "0.2191", "9.049", "settle_s —", "q[6] 1241", "r[3] 1245"):
        assert value in text
    assert "over_% " not in text.split("# 2", 1)[1]      # an empty cell is left out
    assert sum(line.startswith("# ") for line in lines) == 2


def test_a_table_that_fits_is_left_as_it_is():
    table = Table()
    table.add_column("axis")
    table.add_column("value")
    table.add_row("z", "1.05")
    assert fit(table, Console(width=80)) is table
    wide = _wide_table()
    assert fit(wide, Console(width=400)) is wide
