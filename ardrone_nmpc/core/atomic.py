"""Write a file all at once: into a temporary file of our own beside it, renamed into place.

Whatever stops the writer — an error, a full disk, Ctrl-C, a signal — the target is left as
it was (a previous version intact, or no file at all), and only the temporary file, which
this module created, is removed. A reader never sees half a file, and a library that deletes
its output on failure (pyarrow does) only ever deletes our temporary file.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

__all__ = ["atomic_path", "atomic_write", "write_text_atomic"]

_PART = ".part"


def _temporary(path: Path) -> Path:
    """A new, empty file beside ``path`` that nobody else has (created here, exclusively;
    its mode follows the umask like any new file)."""
    stem = path.name[:120]  # room for the prefix and suffix within a file name's 255 bytes
    while True:
        tmp = path.with_name(f".{stem}.{secrets.token_hex(4)}{_PART}")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return tmp
        except FileExistsError:
            continue


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield the path of an empty temporary file beside ``path`` to write; on leaving the
    block normally it replaces ``path``, on any exception (interrupts included) it is
    removed and ``path`` is untouched."""
    path = Path(path)
    tmp = _temporary(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_write(path: str | Path, mode: str = "w", **open_kwargs: Any) -> Iterator[IO]:
    """:func:`atomic_path` as an open file (``mode`` ``"w"`` or ``"wb"``; text defaults to
    UTF-8), flushed to the disk before it replaces ``path``."""
    if "b" not in mode:
        open_kwargs.setdefault("encoding", "utf-8")
    with atomic_path(path) as tmp:
        with open(tmp, mode, **open_kwargs) as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` at once (:func:`atomic_write`); returns the path."""
    with atomic_write(path) as stream:
        stream.write(text)
    return Path(path)
