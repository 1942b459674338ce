"""The one house style of every report figure (matplotlib, Agg) and how it is written.

Figures are made with `subplots` (constrained layout, the style below applied while the
figure is built) and written with `save` in the format its path names: PNG for a quick
look, SVG or PDF for a paper (`--format`). Vector files carry no creation date and fixed
element ids, so the same session writes the same bytes.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: the bench machines have no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..errors import UserError  # noqa: E402

PNG_DPI = 150
# Applied while a figure is built (a notebook's own rcParams stay untouched): print-sized
# text, a light grid under the data, no top/right frame, thin lines that markers do not bury.
STYLE = {
    "font.size": 9.0, "axes.titlesize": 9.5, "figure.titlesize": 11.0, "axes.labelsize": 9.0,
    "legend.fontsize": 8.0, "xtick.labelsize": 8.0, "ytick.labelsize": 8.0,
    "axes.grid": True, "grid.color": "0.88", "grid.linewidth": 0.6, "axes.axisbelow": True,
    "axes.spines.top": False, "axes.spines.right": False,
    "lines.linewidth": 1.2, "lines.markersize": 3.5, "legend.framealpha": 0.9,
    "savefig.bbox": "tight", "savefig.pad_inches": 0.05,
    "svg.hashsalt": "hydrojet-bench",  # fixed SVG element ids: reruns write the same file
}
# Vector files without a date: reruns give identical files.
_NO_DATE = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}
SWEEP_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "*")


def sweep_colour(sweep: int) -> str:
    """The colour of sweep ``sweep`` in every figure (matplotlib's tab10 cycle)."""
    return f"C{int(sweep) % 10}"


def sweep_marker(sweep: int) -> str:
    """A marker per sweep, so sweeps stay apart in greyscale print too."""
    return SWEEP_MARKERS[int(sweep) % len(SWEEP_MARKERS)]


def styled(draw: Callable[..., Any]) -> Callable[..., Any]:
    """Decorator: run a figure-drawing function under `STYLE`."""

    @functools.wraps(draw)
    def wrapper(*args, **kwargs):
        with plt.rc_context(STYLE):
            return draw(*args, **kwargs)

    return wrapper


def subplots(rows: int = 1, columns: int = 1, **options) -> tuple[Any, Any]:
    """`plt.subplots` in the house layout (constrained, so titles and legends never overlap)."""
    return plt.subplots(rows, columns, layout="constrained", **options)


def zero_line(axis) -> None:
    axis.axhline(0.0, color="0.55", linewidth=0.7, zorder=1)


def sweep_boundaries(axis, sweep: np.ndarray) -> None:
    """Vertical grey lines between consecutive sweeps on a step-index axis."""
    for boundary in np.flatnonzero(np.diff(sweep)) + 0.5:
        axis.axvline(boundary, color="0.75", linewidth=0.8, zorder=1)


def figure_legend(figure, handles, **options) -> None:
    """One legend for the whole figure, in a row under the panels (never over a title)."""
    options = {"ncols": min(len(handles), 6), **options}
    figure.legend(handles=handles, loc="outside lower center", **options)


def create_folder(folder: Path) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserError(f"cannot create report folder {folder}: {error.strerror}") from None


def save(figure, path: Path) -> Path:
    """Write ``figure`` to ``path`` in the format its suffix names and close it."""
    fmt = path.suffix.lstrip(".").lower()
    try:
        with plt.rc_context(STYLE):
            figure.savefig(path, dpi=PNG_DPI, metadata=_NO_DATE.get(fmt))
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror}") from None
    finally:
        plt.close(figure)
    return path
