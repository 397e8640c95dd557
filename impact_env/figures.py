"""What every matplotlib figure of the package shares: resolution, colours, layout and where the PNG goes.

Both worlds' plotting modules (:mod:`impact_env.transport.plotting`, :mod:`impact_env.tether.plotting`) and the
planners' figures use the object-oriented API only (:class:`matplotlib.figure.Figure`): no pyplot global
state, no backend selection, nothing shown on screen, so figures work headless and in parallel tests.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from matplotlib.figure import Figure

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes

DPI = 120
ROBOT_COLOUR = "tab:blue"
OBJECT_COLOUR = "tab:orange"  # the impact world's objects and the tether world's cargo
OBSTACLE_COLOUR = "0.45"
REGION_COLOUR = "tab:green"  # regions of the task, the goal box
IMPACT_COLOUR = "red"


def new_figure(width_in: float, height_in: float) -> Figure:
    """A figure of that size (inches) with the constrained layout, registered with no pyplot state."""
    return Figure(figsize=(width_in, height_in), layout="constrained")


def png_path(path: str | Path) -> Path:
    """``path`` with ``.png`` added when it has no suffix (the path :func:`save` writes; check it with
    :func:`impact_env.results_store.check_output_file` before the work that makes the figure)."""
    path = Path(path)
    if not path.suffix:
        path = path.with_suffix(".png")
    return path


def save(fig: Figure, path: str | Path, tight: bool = True) -> Path:
    """Write ``fig`` as a PNG at ``DPI`` (cropped to its content with ``tight``), atomically
    (:func:`impact_env.results_store.atomic_path`: its folders created, a kill leaves no half image), and free
    it; returns the path."""
    from impact_env.results_store import atomic_path

    path = png_path(path)
    with atomic_path(path) as tmp:
        if tight:
            fig.savefig(tmp, dpi=DPI, bbox_inches="tight")
        else:
            fig.savefig(tmp, dpi=DPI)
    fig.clear()  # an OO Figure is not registered with pyplot: clearing and dropping it frees it
    return path


def legend_beside(ax: Axes, handles: Sequence[Artist]) -> None:
    """The legend of ``handles`` outside the axes, to the right, top-aligned."""
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize="small")


def world_axes(ax: Axes, bounds: tuple[float, float, float, float], pad: float) -> None:
    """Metres square on ``ax``: the (xmin, xmax, ymin, ymax) ``bounds`` with ``pad`` around, x and y labelled."""
    xmin, xmax, ymin, ymax = bounds
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
