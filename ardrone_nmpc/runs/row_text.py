"""The text of a ``log.csv`` row: the cells of one tick printed as the run directory keeps them
(:mod:`ardrone_nmpc.runs.rundir`, whose module docstring gives the format and the speed).

Numbers are the shortest decimal that reads back to the same double (Ryu, through orjson),
NaN and ±inf ``nan``/``inf``/``-inf``, string cells as they are. :func:`_plain_line` prints a
row of plain cells in one orjson call; :func:`_fast_line` takes the cells one by one into
orjson (numpy scalars widened by :func:`_as_float`); the recorder's careful path
(:func:`careful_line`, :func:`format_number` per cell) takes the rest and refuses what cannot
be written. :func:`block_text` prints a block of rows :class:`BlockCheck` admits in one orjson
call (a lockstep recording's; the same text as :func:`_plain_line` row by row).
"""

from __future__ import annotations

import functools
import itertools
import math
import operator
import re
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np
import orjson

from ardrone_nmpc.runs.lazy_columns import LazyColumns
from ardrone_nmpc.runs.log_columns import LOG_COLUMNS, STRING_COLUMNS, TICK_CELL_KEYS

__all__ = ["format_number"]

_INDEX = {name: i for i, name in enumerate(LOG_COLUMNS)}
_COLUMN_SET = frozenset(LOG_COLUMNS)
_FORBIDDEN = re.compile(r'[,"\r\n]')


def format_number(value: Any) -> str:
    """The text of a numeric cell: ``repr(float(value))`` without a trailing ``.0``.

    The shortest decimal that reads back (``float()``) to the same double; ints beyond 2**53
    are rounded to a double first. Raises TypeError for str/bytes (a number is expected).
    """
    if isinstance(value, (str, bytes)):
        raise TypeError(f"expected a number, got {type(value).__name__}")
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


# ----------------------------------------------------------------------------- fast rows
def _as_float(value: Any) -> float:
    """orjson's fallback for numpy scalars: widen exactly to a Python float (a float32 is
    written as the double it equals, not as its own shortest text)."""
    if isinstance(value, (np.floating, np.integer)):
        return float(value)
    raise TypeError(f"{type(value).__name__} is not a number")


def _fast_line(cells: list, quotes: int) -> bytes | None:
    """The CSV line of ``cells`` (numbers and str, "" for an empty cell) via one orjson call.

    orjson prints floats as the shortest text that reads back to the same double (Ryu), so
    rows replay bit for bit. ``quotes``: how many ``"`` the string and empty cells account
    for — any other count means a string sat in a numeric column. NaN, ±inf and None, which
    orjson writes as ``null``, are printed as text first (:func:`_print_non_finite`). None
    when a cell needs :meth:`RunRecorder._careful_line` (orjson writes bools as
    ``true``/``false``; lists and dicts are refused there).
    """
    try:
        text = orjson.dumps(cells, default=_as_float)[1:-1]
        if b"null" in text:  # NaN, ±inf or None (a lockstep row's nav_state_bits, every tick)
            quotes += _print_non_finite(cells)
            text = orjson.dumps(cells, default=_as_float)[1:-1]
    except TypeError:
        return None
    # plain `in` tests: ~5× cheaper than one regex with alternatives on a 600-byte row
    if (text.count(b'"') != quotes or b"null" in text or b"true" in text or b"false" in text
            or b"[" in text or b"{" in text):
        return None
    return text.replace(b'"', b"") + b"\n"


_EMPTY_CELLS = ("",) * len(LOG_COLUMNS)  # a missing key: an empty cell
_STRING_CELLS = operator.itemgetter(*(_INDEX[c] for c in LOG_COLUMNS if c in STRING_COLUMNS))
#: The cell types :func:`_plain_line` prints: orjson writes an np.float64 as the float it is
#: (the same Ryu text); other numpy scalars are widened first (:func:`_as_float`), bools and
#: the rest refused — those rows take :func:`_fast_line` or the careful path.
_PLAIN_TYPES = frozenset({float, int, str, np.float64, type(None)})
_STR_ONLY = frozenset({str})
_SEPARATORS = len(LOG_COLUMNS) - 1


def _plain_line(cells: list, quotes: int) -> bytes | None:
    """The line :func:`_fast_line` prints for ``cells`` (one per :data:`LOG_COLUMNS` name,
    ``""`` for a missing key), in one orjson call without a Python call per cell; None for
    any row that is not plain (a cell of another type, a string column holding something
    else, a string orjson would escape or that holds a ``,``, or that :func:`_fast_line`
    would send to the careful path) — the caller then takes the per-cell way.

    NaN, ±inf and None come out of orjson as ``null`` and are printed in place as
    :func:`_print_non_finite` prints them (``nan``, ``inf``, ``-inf``).
    """
    if not (set(map(type, cells)) <= _PLAIN_TYPES
            and set(map(type, _STRING_CELLS(cells))) <= _STR_ONLY):
        return None
    try:
        text = orjson.dumps(cells, option=orjson.OPT_SERIALIZE_NUMPY)[1:-1]
    except TypeError:  # an int beyond 64 bits
        return None
    # no escape (a '"', '\\' or control character in a string), no ',' inside a string, and
    # strings only where the string and empty cells are
    if (b"\\" in text or text.count(b",") != _SEPARATORS
            or text.count(b'"') != quotes):
        return None
    text = _print_nulls(text, cells)
    if text is None:
        return None
    # what _fast_line leaves to the careful path: a string cell holding these
    if b"true" in text or b"false" in text or b"[" in text or b"{" in text:
        return None
    return text.replace(b'"', b"") + b"\n"


def _print_nulls(text: bytes, cells: list) -> bytes | None:
    """``text`` (orjson's cells, ``,``-separated, no string holding a ``,``) with each
    ``null`` — a NaN, ±inf or None cell (a lockstep row's nav_state_bits, every tick) —
    printed as :func:`format_number` prints it (None is ``nan``); None if a string holds
    ``null`` (:func:`_fast_line`'s careful path takes that row)."""
    at = text.find(b"null")
    while at >= 0:
        c = cells[text.count(b",", 0, at)]  # the cell: the number of ',' before it
        if c.__class__ is str:
            return None
        cell = b"nan" if c is None else format_number(c).encode("ascii")
        text = text[:at] + cell + text[at + 4:]
        at = text.find(b"null", at + len(cell))
    return text


# ----------------------------------------------------------------------------- blocks of rows
#: What a string cell of a row printed in a block must not hold: anything orjson escapes or
#: that makes :func:`_plain_line` or :func:`_fast_line` look twice (``,``, ``"``, ``\``,
#: control characters, brackets and braces, ``null``/``true``/``false``). A false alarm
#: (``"nu" + "ll"`` across two cells) only sends the row the one-by-one way.
#: A lone surrogate (``\udcff``, a path decoded with ``surrogateescape``) cannot be encoded:
#: :func:`careful_line` refuses it (UnicodeEncodeError), so the row must not be held.
_SUSPECT = re.compile(r'[,"\\\[\]{}\x00-\x1f\x7f\ud800-\udfff]|null|true|false')
#: The ints a held row may hold: those orjson prints (an int beyond, printed cell by cell
#: through ``float()``, may overflow it — OverflowError — and is refused at write_row).
_INT_LIMIT = 2 ** 63
_INT_MIN = -_INT_LIMIT  # (negated once: a big int's negation is a new object)
#: The string cells of a row (one per string column; ``""`` for a missing key).
_N_STRING_COLUMNS = sum(1 for c in LOG_COLUMNS if c in STRING_COLUMNS)
_INFINITIES = frozenset({math.inf, -math.inf})  # an np.float64 ±inf hashes and equals alike
_STATE_BITS = _INDEX["nav_state_bits"]


class BlockCheck:
    """Whether a row may be printed in a block (:func:`block_text`): plain cells
    (:data:`_PLAIN_TYPES`), str in every string column and in no numeric column that the
    row's key set has, no string cell holding :data:`_SUSPECT` text, ints within 64 bits
    (:data:`_INT_LIMIT`). Such a row's line is :func:`_plain_line`'s, and writing it cannot
    fail. The cell types and the string cells repeat from tick to tick: each distinct pattern
    is judged once (a few hundred kept)."""

    _LIMIT = 256

    def __init__(self) -> None:
        self._types: dict[tuple, tuple | bool] = {}  # (cell types, n_str) → int slots
        self._tick_types: dict[tuple, tuple | bool] = {}  # tick_cells' numbers' types → …
        self._tick_last: list = []  # the types of tick_cells' last row, and its judgement
        self._tick_last_slots: tuple | bool = False
        self._strings: set[tuple] = set()
        self._tick_texts: set[tuple] = set()  # tick_cells' text cells that passed

    def __call__(self, cells: list, n_str: int) -> bool:
        """Whether the row may be printed in a block. ``n_str``: the str cells a plain row
        of its key set holds (one per string column, one per missing numeric key)."""
        key = (tuple(map(type, cells)), n_str)
        int_slots = self._types.get(key)  # False: not plain; else the int cells' slots
        if int_slots is None:
            types = key[0]
            ok = (set(types) <= _PLAIN_TYPES and types.count(str) == n_str
                  and set(map(type, _STRING_CELLS(cells))) <= _STR_ONLY)
            int_slots = (tuple(i for i, t in enumerate(types) if t is int) if ok
                         else False)
            if len(self._types) >= self._LIMIT:
                self._types.clear()
            self._types[key] = int_slots
        if int_slots is False:
            return False
        for i in int_slots:  # a lockstep row's two iteration counts
            if not _INT_MIN <= cells[i] < _INT_LIMIT:
                return False
        return self._plain_strings(_STRING_CELLS(cells))

    def tick_cells(self, cells: list) -> bool:
        """:meth:`__call__` for a :func:`~ardrone_nmpc.runs.log_columns.tick_cells` row (its
        truth put), whose plan is known: its numeric cells plain numbers, its string cells
        str without :data:`_SUSPECT` text, its other cells the ``""`` tick_cells put (a row
        with anything else there takes ``write_row``, which drops those cells, as one row
        a write does). True only for rows :meth:`__call__` passes (it may refuse more)."""
        types = list(map(type, cells))  # one pass: the key holds the text cells' types
        if types == self._tick_last:  # as a rule the last row's (compared without a hash)
            int_slots = self._tick_last_slots
        else:
            int_slots = self._tick_slots(tuple(types))
            self._tick_last, self._tick_last_slots = types, int_slots
        if int_slots is False:
            return False
        for i in int_slots:  # the iteration counts
            if not _INT_MIN <= cells[i] < _INT_LIMIT:
                return False
        texts = _TICK_TEXTS(cells)
        return texts in self._tick_texts or self._plain_tick_texts(texts)

    def _tick_slots(self, types: tuple) -> tuple | bool:
        """:meth:`tick_cells`' judgement of a row whose cells have ``types``: False (not
        plain) or the slots of its int cells."""
        int_slots = self._tick_types.get(types)
        if int_slots is None:
            int_slots = (tuple(i for i in _TICK_NUMBER_SLOTS if types[i] is int)
                         if (set(_TICK_NUMBERS(types)) <= _NUMBER_TYPES
                             and set(_TICK_TEXTS(types)) <= _STR_ONLY) else False)
            if len(self._tick_types) >= self._LIMIT:
                self._tick_types.clear()
            self._tick_types[types] = int_slots
        return int_slots

    def _plain_tick_texts(self, texts: tuple) -> bool:
        """A tick_cells row's text cells (:data:`_TICK_TEXTS`): its string cells without
        :data:`_SUSPECT` text, its other cells ``""`` (each tuple passed is remembered)."""
        if (texts[_N_STRING_COLUMNS:] != _TICK_OTHER_EMPTY
                or _SUSPECT.search("".join(texts[:_N_STRING_COLUMNS])) is not None):
            return False
        if len(self._tick_texts) >= self._LIMIT:
            self._tick_texts.clear()
        self._tick_texts.add(texts)
        return True

    def _plain_strings(self, strings: tuple) -> bool:
        """No :data:`_SUSPECT` text in the row's string cells (each tuple seen is remembered)."""
        if strings not in self._strings:
            if _SUSPECT.search("".join(strings)) is not None:
                return False
            if len(self._strings) >= self._LIMIT:
                self._strings.clear()
            self._strings.add(strings)
        return True


#: The numeric cells of a tick_cells row (its absent columns hold tick_cells' own "").
_TICK_NUMBER_SLOTS = tuple(sorted(_INDEX[k] for k in TICK_CELL_KEYS if k not in STRING_COLUMNS))
_TICK_NUMBERS = operator.itemgetter(*_TICK_NUMBER_SLOTS)
#: The other cells of a tick_cells row: its string columns', then those it leaves ``""``.
_TICK_TEXT_SLOTS = (tuple(_INDEX[c] for c in LOG_COLUMNS if c in STRING_COLUMNS)
                    + tuple(i for i, c in enumerate(LOG_COLUMNS)
                            if c not in STRING_COLUMNS and c not in TICK_CELL_KEYS))
_TICK_TEXTS = operator.itemgetter(*_TICK_TEXT_SLOTS)
_TICK_OTHER_EMPTY = ("",) * (len(_TICK_TEXT_SLOTS) - _N_STRING_COLUMNS)
_NUMBER_TYPES = _PLAIN_TYPES - {str}


def block_text(rows: list[list]) -> bytes | None:
    """The lines :func:`_plain_line` prints for each of ``rows`` (cells :class:`BlockCheck`
    passed), joined: an orjson call a row (~0.7 µs a row where :func:`_plain_line` costs
    ~5 µs), the rows' texts joined by line breaks and their brackets and quotes dropped in one
    pass — no string cell holds one (BlockCheck). None when a cell is ±inf (orjson prints it
    ``null``, as NaN and None, which print ``nan``: the caller then prints the rows one by
    one) or an int does not fit in 64 bits.

    A NaN or None ``nav_state_bits`` (every lockstep tick) goes to orjson as the string
    ``"nan"`` — its text once the quotes are dropped — and back into its row after: a
    ``null`` left is another cell's NaN, None or ±inf."""
    swapped = []
    dumps, option = orjson.dumps, orjson.OPT_SERIALIZE_NUMPY
    try:
        for r in rows:
            c = r[_STATE_BITS]
            if c is None or c != c:
                swapped.append((r, c))
                r[_STATE_BITS] = "nan"
        # a call a row and one join: cheaper than one call's text split into its rows
        lines = [dumps(r, option=option) for r in rows]
        lines.append(b"")  # the last line's break
        text = b"\n".join(lines)
        # (a 'u' first: one byte is found at memchr's speed, and no number's text holds one)
        if b"u" in text and b"null" in text:  # no string holds one (BlockCheck)
            if not _INFINITIES.isdisjoint(itertools.chain.from_iterable(rows)):
                return None
            text = text.replace(b"null", b"nan")  # NaN and None cells
    except TypeError:  # an int beyond 64 bits
        return None
    finally:  # the rows as they were (they are kept)
        for r, c in swapped:
            r[_STATE_BITS] = c
    return text.translate(None, b'"[]')  # an empty or string cell: no quotes


def _print_non_finite(cells: list) -> int:
    """Replace each NaN, ±inf and None cell of ``cells`` by its text as
    :meth:`RunRecorder._careful_line` prints it (``nan``, ``inf``, ``-inf``; None is NaN);
    returns the ``"`` those strings add."""
    added = 0
    for i, c in enumerate(cells):
        if c is None:
            cells[i] = "nan"
        elif isinstance(c, (float, np.floating)) and not math.isfinite(c):
            cells[i] = format_number(c)
        else:
            continue
        added += 2
    return added


# ----------------------------------------------------------------------------- row plans
def _getter(names: list[str]) -> Callable[[Mapping[str, Any]], tuple]:
    """``row -> tuple(row[n] for n in names)`` at C speed."""
    if len(names) > 1:
        return operator.itemgetter(*names)
    if names:
        name = names[0]
        return lambda row: (row[name],)
    return lambda row: ()


def row_plan(keys: tuple) -> tuple:
    """How rows with these keys (in this order) are printed: ``(template, slots, getter,
    string_slots, quotes, n_str)`` — the empty cells, the slot of each present column, a
    getter of their values, the string columns' slots, the ``"`` of the empty and string
    cells, the str cells of a plain row. Raises ValueError for an unknown key."""
    unknown = [k for k in keys if k not in _COLUMN_SET]
    if unknown:
        raise ValueError(f"unknown log column(s) {', '.join(map(repr, unknown))}; "
                         f"expected names from LOG_COLUMNS")
    present = [c for c in LOG_COLUMNS if c in set(keys)]
    template = ["" for _ in LOG_COLUMNS]  # "" = an empty cell
    slots = [_INDEX[c] for c in present]
    string_slots = [_INDEX[c] for c in present if c in STRING_COLUMNS]
    # each empty cell and each string cell prints as "…": two quotes apiece
    quotes = 2 * (len(LOG_COLUMNS) - len(present) + len(string_slots))
    # the str cells of a plain row: one per string column, one per missing numeric key
    n_str = _N_STRING_COLUMNS + sum(1 for c in LOG_COLUMNS
                                    if c not in set(keys) and c not in STRING_COLUMNS)
    return (template, slots, _getter(present), string_slots, quotes, n_str)


def careful_line(row: Mapping[str, Any]) -> bytes:
    """The row line cell by cell (the recorder's careful path): "" is an empty cell, a bad
    value a precise ValueError."""
    cells = []
    for name in LOG_COLUMNS:
        if name not in row:
            cells.append("")
            continue
        v = row[name]
        if name in STRING_COLUMNS:
            if v is None or (isinstance(v, float) and math.isnan(v)):
                cells.append("")
                continue
            if not isinstance(v, str):
                raise ValueError(f"log column {name}: {v!r} is not a string")
            if _FORBIDDEN.search(v):
                raise ValueError(f"log column {name}: {v!r} contains ',', '\"' or a "
                                 f"line break")
            cells.append(str.__str__(v))
        elif isinstance(v, str) and v == "":
            cells.append("")
        else:
            try:
                cells.append(format_number(math.nan if v is None else v))
            except (TypeError, ValueError):
                raise ValueError(f"log column {name}: {v!r} is not a number") from None
    return (",".join(cells) + "\n").encode("utf-8")


# ----------------------------------------------------------------------------- kept rows
_STRING_SLOTS = frozenset(_INDEX[c] for c in STRING_COLUMNS)


def _cells_of_line(line: bytes) -> list:
    """The cells of a written line as read back: numbers as float ("" → NaN), strings as text."""
    return [t if i in _STRING_SLOTS else (math.nan if t == "" else float(t))
            for i, t in enumerate(line[:-1].decode("utf-8").split(","))]


def _floats(cells: tuple, n: int) -> np.ndarray:
    """A numeric column of kept cells (float, np.float64, int, None, "" for an empty cell) as
    read back: float64, every NaN the one ``nan`` reads as."""
    # a column no row filled: "" all through (no == per cell: numpy's scalar compare is slow)
    if not cells or (cells[0].__class__ is str and set(map(type, cells)) <= _STR_ONLY):
        return np.full(n, math.nan)
    try:
        arr = np.array(cells, dtype=np.float64)  # None is NaN; ints exact as their text reads
    except (TypeError, ValueError):  # empty cells among the numbers
        arr = np.fromiter((math.nan if c is None or c.__class__ is str else c for c in cells),
                          dtype=np.float64, count=n)
    nan = np.isnan(arr)
    if nan.any():
        arr[nan] = math.nan  # a NaN's sign and payload are not written
    return arr


class KeptRows:
    """The cells of the rows a recorder wrote, so that the run's summary needs not parse
    ``log.csv`` back: :meth:`columns` gives what :func:`~ardrone_nmpc.runs.rundir.read_run`
    parses from the file, bit for bit (every number's text reads back to the double it was
    printed from). Only the first ``limit`` rows are kept: a longer run is read back from its
    file, and its memory stays bounded."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._rows: list[list] | None = []

    def add(self, cells: list | None, line: bytes) -> None:
        """One written row: the cells :func:`_plain_line` printed as ``line``, or None for a
        line printed cell by cell (its cells are then read back from the text)."""
        rows = self._rows
        if rows is None:
            return
        if len(rows) >= self.limit:
            self._rows = None  # too long to keep: read back from the file
            return
        rows.append(cells if cells is not None else _cells_of_line(line))

    def extend(self, rows: Iterable[list]) -> None:
        """:meth:`add` of each of ``rows``' cells (plain rows, written); a list that fits
        under the limit in one ``list.extend`` (a block of rows: no call per row)."""
        kept = self._rows
        if kept is not None and rows.__class__ is list and len(kept) + len(rows) <= self.limit:
            kept.extend(rows)
            return
        for cells in rows:
            self.add(cells, b"")

    def columns(self) -> Mapping[str, np.ndarray] | None:
        """Every :data:`LOG_COLUMNS` name → its values over the rows (float64; object arrays
        of str for :data:`STRING_COLUMNS`; each made when first read: :class:`LazyColumns`),
        or None when the rows were not all kept."""
        rows = self._rows
        if rows is None:
            return None
        n = len(rows)
        cells = dict(zip(LOG_COLUMNS, zip(*rows) if n else [()] * len(LOG_COLUMNS)))
        return LazyColumns(cells, functools.partial(_kept_column, n=n))


def _kept_column(name: str, cells: tuple, n: int) -> np.ndarray:
    """A column of kept cells as :func:`~ardrone_nmpc.runs.rundir.read_run` parses it."""
    if name in STRING_COLUMNS:
        arr = np.empty(n, dtype=object)
        arr[:] = list(cells)
        return arr
    return _floats(cells, n)
