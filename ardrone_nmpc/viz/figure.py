"""What every figure shares: an Agg-backed Figure, saving it, and the one plotting error.

Every ``figure_*`` function builds a :class:`matplotlib.figure.Figure` with the object-oriented
API and an Agg canvas attached — no ``pyplot``, no global state, so they are safe in tests, in
worker processes and on headless CI machines. matplotlib is imported inside the functions only:
the viz modules (and the sweep-table reader) import without it, and ``ardrone-nmpc --help``
never pays for it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ardrone_nmpc.errors import UserError

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["PlotError", "new_figure", "save_figure"]


class PlotError(UserError, ValueError):
    """Data that cannot be plotted, or a plot request that makes no sense (one line)."""


def new_figure(width_in: float, height_in: float) -> Figure:
    """A Figure (constrained layout) with an Agg canvas: rendering never needs a display."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 100) -> Path:
    """Write ``fig`` to ``path`` (format from the suffix; parents created) and return the path.

    The image is exactly ``figsize × dpi`` pixels (no tight bounding box), so callers and tests
    know its size.
    """
    from ardrone_nmpc.core.atomic import atomic_path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fmt = path.suffix[1:].lower() or None
    with atomic_path(path) as tmp:  # a figure interrupted half-drawn leaves nothing
        fig.savefig(tmp, dpi=dpi, format=fmt)
    return path
