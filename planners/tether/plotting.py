"""Figures of tether plans: the reachable levels or the thesis's regions, the anchors used, the path.

Built on :mod:`impact_env.tether.plotting` (the station drawing); object-oriented matplotlib, headless.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.patches import Polygon as PolygonPatch

from impact_env.figures import png_path
from impact_env.results_store import atomic_path
from impact_env.tether.plotting import draw_station_layers
from impact_env.tether.station import Station
from impact_env.transport.plotting import DPI
from planners.tether.geometry import polygons_of
from planners.tether.plan import TetherPlan

PATH_COLOUR = "tab:red"
TETHER_COLOUR = "tab:purple"


def _draw_plan(ax, station: Station, plan: TetherPlan, handles: list) -> None:
    pts = plan.waypoints()
    (line,) = ax.plot(pts[:, 0], pts[:, 1], color=PATH_COLOUR, lw=2.0, marker="o", ms=4, zorder=7,
                      label=f"plan: {plan.switches} pulls, {plan.path_length_m:.1f} m")
    handles.append(line)
    for p in plan.pulls:
        a = station.anchor_positions[p.anchor]
        ax.plot([p.start_m[0], a[0]], [p.start_m[1], a[1]], color=TETHER_COLOUR, lw=0.8, ls=":", zorder=6)
        ax.scatter([a[0]], [a[1]], s=60, facecolor="none", edgecolor=TETHER_COLOUR, lw=1.5, zorder=8)
    handles.append(Line2D([], [], color=TETHER_COLOUR, lw=0.8, ls=":", marker="o", mfc="none",
                          label="tether of each pull, anchor used"))


def plot_tether_plan(station: Station, plan: TetherPlan, path: str | Path, levels=None, regions=None) -> Path:
    """PNG of ``plan``: the backward-reachable levels (``levels``, from the exact planner) or the thesis's
    extended regions (``regions``), the anchors used with their tethers, and the path."""
    path = png_path(path)
    xmin, xmax, ymin, ymax = station.bounds
    scale = 8.0 / max(xmax - xmin, ymax - ymin)
    fig = Figure(figsize=(max(2.5, (xmax - xmin) * scale) + 3.0, max(2.5, (ymax - ymin) * scale) + 0.6),
                 layout="constrained")
    ax = fig.add_subplot()
    handles = draw_station_layers(station, ax, fan=False)
    if levels:
        cmap = colormaps["Greens_r"]
        for n in range(len(levels) - 1, -1, -1):
            colour = cmap(0.2 + 0.6 * n / max(1, len(levels)))
            for poly in polygons_of(levels[n]):
                ax.add_patch(PolygonPatch(np.asarray(poly.exterior.coords), closed=True, facecolor=colour,
                                          alpha=0.45, edgecolor="none", zorder=2))
        handles.append(Patch(facecolor=cmap(0.4), alpha=0.45, label=f"reachable in n pulls (n = 0..{len(levels) - 1}, "
                                                                    "darker = fewer)"))
    if regions:
        cmap = colormaps["tab10"]
        for r in regions:
            ax.add_patch(PolygonPatch(np.asarray(r.polygon.exterior.coords), closed=True, facecolor=cmap(r.index % 10),
                                      alpha=0.18, edgecolor=cmap(r.index % 10), lw=1.2, zorder=2))
            c = r.piece.representative_point()
            ax.annotate(f"R{r.index}", (c.x, c.y), fontsize=8, ha="center", color=cmap(r.index % 10))
        handles.append(Patch(facecolor="0.7", alpha=0.3, label="MP3 regions, extended (Sec. 4.1-4.2)"))
    _draw_plan(ax, station, plan, handles)
    ax.set_title(f"station {station.name}: {plan.method}, {plan.switches} pulls, "
                 f"{plan.travel_time_s(1):.0f} s with k = 1")
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize="small")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, bbox_inches="tight")
    fig.clear()
    return path
