"""Tables on narrow terminals: a ``rich`` table that does not fit the console's width is shown
as one block per row — ``header value`` pairs wrapped to the width — instead of columns
squeezed into ``…`` cells (an 80-column terminal and the tune table's 19 columns)."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    from rich.console import Console, RenderableType
    from rich.table import Table

__all__ = ["fit", "stacked"]

_INDENT = "    "


def _plain(cell) -> str:
    from rich.text import Text

    if isinstance(cell, Text):
        return cell.plain
    return Text.from_markup(str(cell)).plain


def _wrap(pairs: list[str], width: int, first: str) -> list[str]:
    """``pairs`` after ``first`` on lines of at most ``width`` characters (a pair is never
    split; one longer than the width has a line of its own)."""
    lines, line = [], first
    for pair in pairs:
        if line.strip() and len(line) + 2 + len(pair) > width:
            lines.append(line)
            line = _INDENT + pair
        else:
            line = f"{line}  {pair}" if line.strip() else line + pair
    lines.append(line)
    return lines


def stacked(table: Table, width: int) -> RenderableType:
    """``table`` as blocks: per row, its first cell, then ``header value`` of the others,
    wrapped to ``width``; empty cells are left out."""
    from rich.console import Group
    from rich.text import Text

    headers = [_plain(c.header) for c in table.columns]
    columns = [[_plain(cell) for cell in c.cells] for c in table.columns]
    parts: list = []
    if table.title:
        parts.append(Text(_plain(table.title), style="bold"))
    for values in zip(*columns):
        head = f"{headers[0]} {values[0]}".strip()
        pairs = [f"{h} {v}" for h, v in zip(headers[1:], values[1:]) if v.strip()]
        lines = _wrap(pairs, width, head)
        block = Text("\n".join(lines))
        block.stylize("bold", 0, len(head))
        parts.append(block)
    if table.caption:
        parts.append(Text(_plain(table.caption)))
    return Group(*parts)


def fit(table: Table, console: Console) -> RenderableType:
    """``table`` as it is when it fits ``console``'s width, else :func:`stacked`."""
    unclamped = console.options.update_width(100_000)   # a measure is clamped to the width
    if console.measure(table, options=unclamped).maximum <= console.width:
        return table
    return stacked(table, console.width)
