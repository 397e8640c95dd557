"""matplotlib figures of a scenario and of a run: what the README, the planners and the CLI save as PNG.

The conventions of :mod:`impact_env.figures` (object-oriented matplotlib, headless; its DPI and colours).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, FancyArrowPatch, Patch, Polygon, Rectangle

from impact_env import figures
from impact_env.figures import IMPACT_COLOUR, OBJECT_COLOUR, OBSTACLE_COLOUR, REGION_COLOUR, ROBOT_COLOUR

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes

    from impact_env.transport.scenario import Scenario

DPI, _png_path = figures.DPI, figures.png_path  # names of impact_env.transport.plotting (0.2), for that path's release
# trajectory colours per body: blues for robots, oranges/browns for objects, cycled
ROBOT_TRACE_COLOURS = ("tab:blue", "tab:cyan", "tab:purple", "navy", "steelblue")
OBJECT_TRACE_COLOURS = ("tab:orange", "tab:brown", "goldenrod", "tab:red", "chocolate")


def draw_scenario(scenario: Scenario, ax: Axes | None = None) -> Axes:
    """Draw the world box, obstacles, regions, bodies at their start and their final positions (m).

    Bodies are circles of their radius at ``position_m``; a ``final_position_m`` is an 'x' with a dashed
    circle, and robots that have one get an arrow from start to final. A new figure is made when ``ax``
    is None (reach it through ``ax.figure``).
    """
    if ax is None:
        ax = figures.new_figure(*_xy_figsize(scenario)).add_subplot()
    handles = _draw_scenario(scenario, ax)
    ax.set_title(f"{scenario.name}  (restitution e = {scenario.restitution:g}, tf = {scenario.tf_s:g} s)")
    figures.legend_beside(ax, handles)
    return ax


def save_scenario_figure(scenario: Scenario, path: str | Path) -> Path:
    """Draw ``scenario`` (see :func:`draw_scenario`) and save it as a PNG at ``DPI`` dots per inch.

    A path without a suffix gets ``.png``; missing parent folders are created. Returns the written path.
    """
    fig = figures.new_figure(*_xy_figsize(scenario))
    draw_scenario(scenario, fig.add_subplot())
    return figures.save(fig, path)


def count_impacts(scenario: Scenario, impacts: Sequence[dict[str, Any]]) -> tuple[int, int]:
    """(robot-object impacts, all contacts) among ``impacts``: the two numbers every figure and the CLI report."""
    robots, objects = {b.name for b in scenario.robots}, {b.name for b in scenario.objects}
    hits = sum(1 for m in impacts if {m["a"], m["b"]} & robots and {m["a"], m["b"]} & objects)
    return hits, len(impacts)


def impacts_text(scenario: Scenario, impacts: Sequence[dict[str, Any]]) -> str:
    """``"2 robot-object impacts, 5 contacts in all"``: the wording of the CLI's lines and the figures' titles."""
    hits, contacts = count_impacts(scenario, impacts)
    return (f"{hits} robot-object impact{'' if hits == 1 else 's'}, {contacts} contact{'' if contacts == 1 else 's'}"
            " in all")


def plot_run(scenario: Scenario, times_s: np.ndarray, positions: np.ndarray, impacts: Sequence[dict[str, Any]],
             robustness: float, path: str | Path) -> Path:
    """Save a three-panel PNG of one run: the xy view (left), positions and velocities over time (right).

    The same layout and colours as the expert's figure (:func:`planners.plan.plotting.plot_execution`): each body
    keeps its colour (robots blues, objects oranges) in every panel; velocities are finite differences of the
    sampled positions.

    Args:
        scenario: the scenario that was run; drawn underneath the trajectories.
        times_s: (T,) sample times (s), increasing.
        positions: (T, n_bodies, 2) body positions (m), bodies in ``scenario.bodies`` order.
        impacts: impact events as dicts with keys ``'time'`` (s), ``'a'``, ``'b'`` (body or obstacle names,
            or ``"wall"``) and ``'impulse'`` (N s). Robot-object impacts are red stars, drawn on top of the
            discs, at the object's position (interpolated at the impact time) on the left; every impact is a
            dotted vertical line on the right (red for robot-object, grey for any other contact).
        robustness: STL robustness of the run (m), shown in the title with the impact counts.
        path: where to write the PNG (``.png`` is added when there is no suffix).

    Raises:
        ValueError: ``times_s`` or ``positions`` has the wrong shape, or an impact lacks a key.
    """
    times_s = np.asarray(times_s, dtype=float)
    positions = np.asarray(positions, dtype=float)
    bodies = scenario.bodies
    n = len(bodies)
    if times_s.ndim != 1 or times_s.size == 0:
        raise ValueError(f"times_s must be a non-empty 1-D array (T,), got shape {times_s.shape}")
    if positions.shape != (times_s.size, n, 2):
        raise ValueError(f"positions must have shape (T, n_bodies, 2) = ({times_s.size}, {n}, 2) for scenario "
                         f"{scenario.name!r} (bodies {[b.name for b in bodies]}), got {positions.shape}")
    for k, impact in enumerate(impacts):
        missing = [key for key in ("time", "a", "b", "impulse") if key not in impact]
        if missing:
            raise ValueError(f"impacts[{k}] lacks key(s) {missing}; each impact needs 'time', 'a', 'b', 'impulse'")
    path = figures.png_path(path)
    index = {b.name: i for i, b in enumerate(bodies)}
    colours = _trace_colours(scenario)
    objects = {b.name for b in scenario.objects}
    robots = {b.name for b in scenario.robots}

    w, h = _xy_figsize(scenario)
    fig = figures.new_figure(w + 7.5, max(h, 5.5))
    grid = fig.add_gridspec(2, 2, width_ratios=[w, 7.5])
    ax_xy = fig.add_subplot(grid[:, 0])
    ax_p = fig.add_subplot(grid[0, 1])
    ax_v = fig.add_subplot(grid[1, 1], sharex=ax_p)

    handles = _draw_scenario(scenario, ax_xy)
    for i, body in enumerate(bodies):
        (line,) = ax_xy.plot(positions[:, i, 0], positions[:, i, 1], color=colours[i], lw=1.5, zorder=5,
                             label=f"{body.name} path")
        ax_xy.plot(*positions[-1, i], "o", color=colours[i], ms=4, zorder=5)
        handles.append(line)
    hits = [m for m in impacts if {m["a"], m["b"]} & robots and {m["a"], m["b"]} & objects]
    if hits:
        at = [index[m["a"] if m["a"] in objects else m["b"]] for m in hits]
        stars = np.array([[np.interp(m["time"], times_s, positions[:, i, c]) for c in (0, 1)]
                          for m, i in zip(hits, at)])
        handles.append(ax_xy.scatter(stars[:, 0], stars[:, 1], marker="*", s=160, color=IMPACT_COLOUR,
                                     edgecolor="k", linewidth=0.5, zorder=9, label="robot-object impact"))
    ax_xy.set_title("xy view")
    figures.legend_beside(ax_xy, handles)

    velocities = np.gradient(positions, times_s, axis=0) if times_s.size > 1 else np.zeros_like(positions)
    for i, body in enumerate(bodies):
        lw = 2.4 if body.name in objects else 1.3
        for c, ls in ((0, "-"), (1, "--")):
            ax_p.plot(times_s, positions[:, i, c], color=colours[i], lw=lw, ls=ls)
            ax_v.plot(times_s, velocities[:, i, c], color=colours[i], lw=lw, ls=ls)
    time_handles = [Line2D([], [], color=colours[i], lw=2.4 if b.name in objects else 1.3, label=b.name)
                    for i, b in enumerate(bodies)]
    time_handles += [Line2D([], [], color="0.3", ls="-", label="x / vx"), Line2D([], [], color="0.3", ls="--",
                                                                                label="y / vy"),
                     Line2D([], [], color=IMPACT_COLOUR, ls=":", label="robot-object impact"),
                     Line2D([], [], color="0.6", ls=":", label="other contact")]
    for m in impacts:
        hit = {m["a"], m["b"]} & robots and {m["a"], m["b"]} & objects
        for ax in (ax_p, ax_v):
            ax.axvline(m["time"], color=IMPACT_COLOUR if hit else "0.6", ls=":", lw=1.0)
    for ax in (ax_p, ax_v):
        ax.grid(True, alpha=0.3)
    ax_p.set_ylabel("position (m)")
    ax_p.set_title("positions (x solid, y dashed)")
    ax_p.tick_params(labelbottom=False)
    ax_v.set_ylabel("velocity (m/s)")
    ax_v.set_xlabel("time (s)")
    ax_v.set_title("velocities (vx solid, vy dashed); impacts dotted")
    figures.legend_beside(ax_p, time_handles)
    fig.suptitle(f"{scenario.name}: robustness rho = {robustness:.3f} m  ({impacts_text(scenario, impacts)})")
    return figures.save(fig, path, tight=False)


# --------------------------------------------------------------------------------------------- helpers


def _xy_figsize(scenario: Scenario) -> tuple[float, float]:
    """Figure size (in) for the xy view: longest side 7 in, plus room on the right for the legend."""
    xmin, xmax, ymin, ymax = scenario.world_box
    aspect = (ymax - ymin) / (xmax - xmin)
    w, h = (7.0, 7.0 * aspect) if aspect <= 1.0 else (7.0 / aspect, 7.0)
    return max(w, 2.5) + 2.0, max(h, 2.5) + 0.6


def trace_colours(scenario: Scenario) -> list[str]:
    """Each body's colour in every figure, in ``scenario.bodies`` order: robots blues, objects oranges."""
    return _trace_colours(scenario)


def _trace_colours(scenario: Scenario) -> list[str]:
    return ([ROBOT_TRACE_COLOURS[i % len(ROBOT_TRACE_COLOURS)] for i in range(len(scenario.robots))]
            + [OBJECT_TRACE_COLOURS[i % len(OBJECT_TRACE_COLOURS)] for i in range(len(scenario.objects))])


def _draw_scenario(scenario: Scenario, ax: Axes) -> list[Artist]:
    """Draw the scenario on ``ax`` and return legend handles for the kinds of thing present."""
    xmin, xmax, ymin, ymax = scenario.world_box
    ax.add_patch(Rectangle((xmin, ymin), xmax - xmin, ymax - ymin, fill=False, ec="k", lw=1.5, zorder=1))
    for obstacle in scenario.obstacles:
        v = obstacle.polygon.vertices
        ax.add_patch(Polygon(v, closed=True, fc=OBSTACLE_COLOUR, ec="0.2", hatch="//", lw=1.0, zorder=2))
        cx, cy = v.mean(axis=0)
        ax.text(cx, cy, obstacle.name, ha="center", va="center", color="w", fontsize=9, weight="bold", zorder=3,
                bbox={"boxstyle": "round,pad=0.2", "fc": "0.25", "ec": "none"})
    for region in scenario.regions:
        v = region.polygon.vertices
        ax.add_patch(Polygon(v, closed=True, fc=REGION_COLOUR, alpha=0.25, ec=REGION_COLOUR, lw=1.5, zorder=2))
        rxmin, _, _, rymax = region.polygon.bounds
        ax.text(rxmin, rymax, f" {region.name}", ha="left", va="top", color="darkgreen", fontsize=9, zorder=3)
    robot_names = {b.name for b in scenario.robots}
    for body in scenario.bodies:
        colour = ROBOT_COLOUR if body.name in robot_names else OBJECT_COLOUR
        x, y = body.position_m
        ax.add_patch(Circle((x, y), body.radius_m, fc=colour, ec="k", lw=0.8, alpha=0.9, zorder=4))
        ax.text(x + 0.75 * body.radius_m, y + 0.75 * body.radius_m, body.name, fontsize=9, zorder=7)
        if body.final_position_m is None:
            continue
        fx, fy = body.final_position_m
        ax.add_patch(Circle((fx, fy), body.radius_m, fill=False, ec=colour, ls="--", lw=1.0, zorder=4))
        ax.plot(fx, fy, "x", color=colour, ms=7, mew=1.5, zorder=5)
        if body.name in robot_names and np.hypot(fx - x, fy - y) > 1e-9:
            ax.add_patch(FancyArrowPatch((x, y), (fx, fy), arrowstyle="-|>", mutation_scale=12, color=colour,
                                         lw=1.0, alpha=0.7, shrinkA=0, shrinkB=0, zorder=3))
    figures.world_axes(ax, scenario.world_box, pad=0.03 * max(xmax - xmin, ymax - ymin))

    handles: list[Artist] = []
    if scenario.robots:
        handles.append(Patch(fc=ROBOT_COLOUR, ec="k", label="robot"))
    if scenario.objects:
        handles.append(Patch(fc=OBJECT_COLOUR, ec="k", label="object"))
    if scenario.obstacles:
        handles.append(Patch(fc=OBSTACLE_COLOUR, ec="0.2", hatch="//", label="obstacle"))
    if scenario.regions:
        handles.append(Patch(fc=REGION_COLOUR, alpha=0.25, ec=REGION_COLOUR, label="region"))
    if any(b.final_position_m is not None for b in scenario.bodies):
        handles.append(Line2D([], [], color="0.3", marker="x", ls="--", label="final position"))
    return handles
