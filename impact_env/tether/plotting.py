"""matplotlib figures of a station and of a tether run (``impact-env show`` / ``run`` for stations).

The conventions of :mod:`impact_env.figures` (object-oriented matplotlib, headless; its DPI and colours).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Rectangle
from matplotlib.patches import Polygon as PolygonPatch

from impact_env import figures
from impact_env.figures import OBJECT_COLOUR, REGION_COLOUR

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from impact_env.tether.station import Station

# names of impact_env.tether.plotting (0.2), for that path's release (planners' tether figures import them)
DPI, _png_path = figures.DPI, figures.png_path  # 0.2 names, kept for the old module path

WALL_COLOUR = "0.15"
ANCHOR_COLOUR = "tab:blue"
FAN_COLOUR = "lightsteelblue"
FREE_COLOUR = "0.55"
EVENT_MARKERS = {"snagged": ("X", "red"), "arrived": ("o", "tab:green"), "attached": ("^", "tab:purple"),
                 "released": ("v", "0.4"), "blocked": ("s", "red")}


def draw_station(station: Station, ax: Axes | None = None, fan: bool = True) -> Axes:
    """Draw the walls, the free space (dashed), anchors (numbered), the goal box, the cargo at its start and,
    with ``fan``, the line-of-sight fan from the start to every visible anchor. Returns the axes."""
    if ax is None:
        ax = _figure(station).add_subplot()
    handles = draw_station_layers(station, ax, fan)
    ax.set_title(f"station {station.name}  (k = {station.k} of {station.n_robots} robots, "
                 f"w = {station.pull_speed_mps:g} m/s, {station.n_anchors} anchors)")
    figures.legend_beside(ax, handles)
    return ax


def save_station_figure(station: Station, path: str | Path) -> Path:
    """Draw ``station`` (see :func:`draw_station`) into a PNG; returns the written path (``.png`` added if none)."""
    fig = _figure(station)
    draw_station(station, fig.add_subplot())
    return figures.save(fig, path)


def plot_tether_run(station: Station, positions: np.ndarray, events: Sequence[dict[str, Any]], robustness: float,
                    path: str | Path) -> Path:
    """PNG of one run: the station, the cargo's path and its tether events (``time``, ``kind``, ``anchor``).

    ``positions`` is (T, 2) or (T, 1, 2) cargo centres (m), one per control step from t = 0. An event is marked
    at the cargo's position at its time (the nearest step).
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim == 3 and p.shape[1] == 1:
        p = p[:, 0]
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise ValueError(f"positions must have shape (T, 2) or (T, 1, 2), got {np.shape(positions)}")
    path = figures.png_path(path)
    fig = _figure(station)
    ax = fig.add_subplot()
    handles = draw_station_layers(station, ax, fan=False)
    (line,) = ax.plot(p[:, 0], p[:, 1], color=OBJECT_COLOUR, lw=1.8, label="cargo path")
    handles.append(line)
    dt = station.control_period_s
    for kind, (marker, colour) in EVENT_MARKERS.items():
        at = np.array([p[min(len(p) - 1, int(round(e["time"] / dt)))] for e in events if e["kind"] == kind])
        if len(at):
            handles.append(ax.scatter(at[:, 0], at[:, 1], marker=marker, color=colour, s=50, zorder=6, label=kind))
    ax.set_title(f"station {station.name}: robustness {robustness:+.3f} m")
    figures.legend_beside(ax, handles)
    return figures.save(fig, path)


def _figure(station: Station) -> Figure:
    xmin, xmax, ymin, ymax = station.bounds
    scale = 8.0 / max(xmax - xmin, ymax - ymin)
    return figures.new_figure(max(2.5, (xmax - xmin) * scale) + 2.5, max(2.5, (ymax - ymin) * scale) + 0.6)


def draw_station_layers(station: Station, ax: Axes, fan: bool) -> list:
    """Draw the station's walls, free space, anchors (and their line-of-sight fans) and goal on ``ax``; returns
    the legend handles, for figures that draw more on top (the tether planners' plan figure)."""
    handles: list = []
    ax.add_patch(PolygonPatch(station.polygon, closed=True, facecolor="0.94", edgecolor=WALL_COLOUR, lw=2.0))
    handles.append(Line2D([], [], color=WALL_COLOUR, lw=2.0, label="walls"))
    free = station.free_space()
    for piece in getattr(free, "geoms", [free]):
        xs, ys = piece.exterior.xy
        ax.plot(xs, ys, color=FREE_COLOUR, lw=0.8, ls="--")
    handles.append(Line2D([], [], color=FREE_COLOUR, lw=0.8, ls="--", label="free space of the cargo centre"))
    x0, x1, y0, y1 = station.goal_box
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor=REGION_COLOUR, alpha=0.35, edgecolor=REGION_COLOUR))
    handles.append(Patch(facecolor=REGION_COLOUR, alpha=0.35, label="goal"))
    start = station.cargo.start_m
    anchors = station.anchor_positions
    if fan and len(anchors):
        for a in anchors[station.line_of_sight(start)]:
            ax.plot([start[0], a[0]], [start[1], a[1]], color=FAN_COLOUR, lw=0.7, zorder=1)
        handles.append(Line2D([], [], color=FAN_COLOUR, lw=0.7, label="line of sight from the start"))
    ax.scatter(anchors[:, 0], anchors[:, 1], s=18, color=ANCHOR_COLOUR, zorder=5)
    handles.append(Line2D([], [], marker="o", ls="", color=ANCHOR_COLOUR, label="anchors (index)"))
    xmin, xmax, ymin, ymax = station.bounds
    size = 0.012 * max(xmax - xmin, ymax - ymin)
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])
    for a in station.anchors:
        p = np.array(a.position_m)
        d = centre - p
        p = p + 2.0 * size * d / max(np.linalg.norm(d), 1e-9)
        ax.annotate(str(a.index), p, fontsize=6, ha="center", va="center", color=ANCHOR_COLOUR)
    ax.add_patch(Circle(start, station.cargo.radius_m, facecolor=OBJECT_COLOUR, edgecolor="k", zorder=6))
    handles.append(Patch(facecolor=OBJECT_COLOUR, edgecolor="k", label="cargo at its start"))
    figures.world_axes(ax, station.bounds, pad=0.5)
    return handles


_draw = draw_station_layers  # the 0.2 name, kept for the old module path (impact_env.tether.plotting)
