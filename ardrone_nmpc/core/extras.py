"""Optional dependencies (pyproject extras): import one, or say in one line what to install.

Heavy or optional libraries (motioncapture, mcap, foxglove-sdk, pyarrow) are imported where a
command needs them, never at CLI start-up, through :func:`import_extra`.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["MissingExtra", "import_extra"]


class MissingExtra(RuntimeError):
    """An optional library is not installed; the message names the extra to install."""


def import_extra(module: str, extra: str, purpose: str) -> ModuleType:
    """``import module``, or raise :class:`MissingExtra`: ``<purpose> needs <module>:
    pip install 'ardrone-nmpc[<extra>]'``."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtra(f"{purpose} needs the {module.split('.')[0]!r} library: "
                           f"pip install 'ardrone-nmpc[{extra}]'") from None
