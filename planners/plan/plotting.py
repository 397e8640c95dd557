"""A figure of a plan after the paper's Fig. 4 (spatially robust) or Fig. 5 (impact-robust): the xy view, and
positions and velocities over time. An impact-robust plan adds the objects' funnels (their state boxes swept
along the path, and bands around their positions and velocities over time) and the robots' copies.

Only the object-oriented matplotlib API is used (no pyplot), like :mod:`impact_env.transport.plotting`, whose
:func:`~impact_env.transport.plotting.draw_scenario` draws the world underneath the planned paths.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.transforms import blended_transform_factory

from impact_env.figures import png_path
from impact_env.results_store import atomic_path
from impact_env.transport.plotting import DPI, IMPACT_COLOUR, OBJECT_TRACE_COLOURS, ROBOT_TRACE_COLOURS, draw_scenario

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from impact_env.transport.scenario import Scenario
    from planners.plan import BodyPlan, Plan

ROBOT_LW = 1.3
OBJECT_LW = 2.6


def plot_plan(scenario: Scenario, plan: Plan, path: str | Path | None = None, samples: int = 400) -> Figure:
    """Draw ``plan`` on ``scenario``; save a PNG at ``DPI`` if ``path`` is given (``.png`` added if no suffix).

    Left: the xy view with the scenario underneath, each body's planned path, the robots' Bezier control
    points (small faint dots) and the impacts (red stars I1, I2, ... at their positions). Right, sharing
    the time axis: positions (x solid, y dashed) and velocities (vx solid, vy dashed) over time, objects
    drawn thicker; each segment is sampled on its own and lines are broken at impacts, so a velocity jump
    is a vertical gap. Impact times are dotted vertical lines labelled like the stars. For an impact-robust
    plan (the paper's Fig. 5): each object's box at every knot and its sweep between knots (the funnel) in
    the xy view, with the impacting robots' four copies (thin dashed) around each impact; over time, bands
    of the position and velocity half-widths around the object's nominal values.

    Args:
        samples: sample points per body over [0, tf] (spread over its segments, at least 2 per segment).

    Returns the Figure with three axes: xy view, positions, velocities.
    """
    colours = _colours(scenario)
    xmin, xmax, ymin, ymax = scenario.world_box
    aspect = (ymax - ymin) / (xmax - xmin)
    # the xy view gets ~6 in along its longer side, its legend 2.4 in on its right; the time panels 7.5 in
    xy_w, xy_h = (6.0, 6.0 * aspect) if aspect <= 1.0 else (6.0 / aspect, 6.0)
    fig = Figure(figsize=(xy_w + 2.4 + 7.5, max(5.5, xy_h + 1.3)), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=[xy_w + 2.4, 7.5])
    ax_xy = fig.add_subplot(grid[:, 0])
    ax_pos = fig.add_subplot(grid[0, 1])
    ax_vel = fig.add_subplot(grid[1, 1], sharex=ax_pos)

    if plan.funnels:
        _draw_funnels_xy(plan, ax_xy, colours)
        _draw_copies_xy(plan, ax_xy, colours)
        _draw_funnel_bands(plan, ax_pos, ax_vel, colours)
    _draw_xy(scenario, plan, ax_xy, colours, samples)
    _draw_time(scenario, plan, ax_pos, ax_vel, colours, samples)

    gap = f", gap {100 * plan.mip_gap:.2f}%" if plan.mip_gap > 1e-3 else ""
    what = (f"delta = {plan.delta_mps:.4f} m/s, nominal rho = {plan.robustness:.3f} m" if plan.planner == "ir"
            else f"robustness rho = {plan.robustness:.3f} m")
    fig.suptitle(f"{plan.scenario}: planner \"{plan.planner}\", {what}  "
                 f"({plan.solver}, {plan.solve_time_s:.1f} s{gap}; {len(plan.impacts)} impacts)")
    if path is not None:
        with atomic_path(png_path(path)) as tmp:
            fig.savefig(tmp, dpi=DPI)
    return fig


def _colours(scenario: Scenario) -> dict[str, str]:
    out = {b.name: ROBOT_TRACE_COLOURS[i % len(ROBOT_TRACE_COLOURS)] for i, b in enumerate(scenario.robots)}
    out.update({b.name: OBJECT_TRACE_COLOURS[i % len(OBJECT_TRACE_COLOURS)] for i, b in enumerate(scenario.objects)})
    return out


def _sample(body: BodyPlan, samples: int, what: str, break_at: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """Times (T,) and values (T, 2) of ``body.<what>``, each segment sampled on its own (so the value at a
    knot is the left segment's end, then the right segment's start); a NaN row is inserted after every
    segment that ends at one of ``break_at`` so that matplotlib leaves a gap there."""
    per_segment = max(2, samples // len(body.segments) + 1)
    times, values = [], []
    for seg in body.segments:
        t = np.linspace(seg.t0_s, seg.t1_s, per_segment)
        times.append(t)
        values.append(getattr(seg, what)(t))
        if any(abs(seg.t1_s - tb) < 1e-9 for tb in break_at):
            times.append(np.array([seg.t1_s]))
            values.append(np.full((1, 2), np.nan))
    return np.concatenate(times), np.concatenate(values)


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise) of 2-D points (Andrew's monotone chain)."""
    pts = sorted(map(tuple, np.round(points, 12)))
    if len(pts) <= 2:
        return np.array(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, ...]] = []
    upper: list[tuple[float, ...]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _corners(centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    return centre + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half


def _draw_funnels_xy(plan: Plan, ax: Axes, colours: dict[str, str]) -> None:
    """Each object's position box at every knot (outlined) and the hull of consecutive boxes (filled): the
    set its straight flights can sweep."""
    from matplotlib.patches import Polygon

    for name, funnel in plan.funnels.items():
        body = plan.bodies[name]
        knots = funnel.knots_s
        centres = body.position(knots)
        half = np.asarray(funnel.position_halfwidth_m)
        colour = colours[name]
        for k in range(len(knots) - 1):
            pts = np.vstack([_corners(centres[k], half[k]), _corners(centres[k + 1], half[k + 1])])
            ax.add_patch(Polygon(_hull(pts), closed=True, fc=colour, ec="none", alpha=0.15, zorder=3))
        for k in range(1, len(knots)):
            if np.any(half[k] > 1e-9):
                ax.add_patch(Polygon(_corners(centres[k], half[k]), closed=True, fill=False, ec=colour, lw=0.8,
                                     alpha=0.7, zorder=4))


def _draw_copies_xy(plan: Plan, ax: Axes, colours: dict[str, str], samples: int = 40) -> None:
    """The robots' four copies over each impact's window (thin dashed)."""
    s = np.linspace(0.0, 1.0, samples)
    from planners import bezier

    for c in plan.copies:
        for j in range(len(c.signs)):
            segments = list(np.asarray(c.before[j])) + list(np.asarray(c.after[j]))
            xy = np.concatenate([bezier.evaluate(cps, s) for cps in segments])
            ax.plot(xy[:, 0], xy[:, 1], ls="--", lw=0.7, color=colours[c.robot], alpha=0.8, zorder=4)


def _draw_funnel_bands(plan: Plan, ax_pos: Axes, ax_vel: Axes, colours: dict[str, str]) -> None:
    """Bands: nominal position +- the position half-width (linear between knots, a bound since a zonotope's
    half-width is convex in time) and nominal velocity +- the velocity half-width (constant per interval)."""
    for name, funnel in plan.funnels.items():
        body = plan.bodies[name]
        colour = colours[name]
        t = np.linspace(funnel.knots_s[0], funnel.knots_s[-1], 400)
        centre, half = body.position(t), funnel.position_halfwidth(t)
        for axis in range(2):
            ax_pos.fill_between(t, centre[:, axis] - half[:, axis], centre[:, axis] + half[:, axis], color=colour,
                                alpha=0.18 if axis == 0 else 0.10, lw=0)
        for k, seg in enumerate(body.segments):
            tk = np.array([seg.t0_s, seg.t1_s])
            v = seg.velocity(seg.t0_s)[0]
            hv = funnel.velocity_halfwidth_mps[k]
            for axis in range(2):
                ax_vel.fill_between(tk, v[axis] - hv[axis], v[axis] + hv[axis], color=colour,
                                    alpha=0.18 if axis == 0 else 0.10, lw=0)


def _draw_xy(scenario: Scenario, plan: Plan, ax: Axes, colours: dict[str, str], samples: int) -> None:
    draw_scenario(scenario, ax)
    legend = ax.get_legend()
    handles = list(legend.legend_handles) if legend is not None else []
    for body in scenario.bodies:
        bp = plan.bodies[body.name]
        _, xy = _sample(bp, samples, "position", [])
        lw = OBJECT_LW if bp.kind == "object" else ROBOT_LW
        (line,) = ax.plot(xy[:, 0], xy[:, 1], color=colours[body.name], lw=lw, zorder=5,
                          label=f"{body.name} planned path")
        handles.append(line)
        if bp.kind == "robot":
            cps = np.concatenate([s.control_points for s in bp.segments])
            ax.scatter(cps[:, 0], cps[:, 1], s=7, color=colours[body.name], alpha=0.35, lw=0, zorder=5)
    if any(b.kind == "robot" for b in plan.bodies.values()):
        handles.append(Line2D([], [], ls="", marker="o", ms=3, color="0.4", alpha=0.5,
                              label="robot Bezier control points"))
    if plan.funnels:
        from matplotlib.patches import Patch

        handles.append(Patch(fc="0.5", alpha=0.3, ec="0.3", label=f"object funnel (delta = {plan.delta_mps:.4f} m/s)"))
        handles.append(Line2D([], [], ls="--", lw=0.7, color="0.3", label="robot copies (Lemma 1)"))
    if plan.impacts:
        pts = np.array([imp.position for imp in plan.impacts])
        handles.append(ax.scatter(pts[:, 0], pts[:, 1], marker="*", s=170, color=IMPACT_COLOUR, edgecolor="k",
                                  linewidth=0.5, zorder=8, label="impact"))
        for k, imp in enumerate(plan.impacts, start=1):
            ax.annotate(f"I{k}", imp.position, xytext=(6, -13), textcoords="offset points", fontsize=9,
                        color=IMPACT_COLOUR, weight="bold", zorder=9,
                        bbox={"boxstyle": "round,pad=0.1", "fc": "w", "ec": "none", "alpha": 0.7})
    ax.set_title("xy view")
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
              fontsize="small")


def _draw_time(scenario: Scenario, plan: Plan, ax_pos: Axes, ax_vel: Axes, colours: dict[str, str],
               samples: int) -> None:
    handles = []
    for body in scenario.bodies:
        bp = plan.bodies[body.name]
        lw = OBJECT_LW if bp.kind == "object" else ROBOT_LW
        breaks = [imp.time_s for imp in plan.impacts_of(body.name)]
        t, pos = _sample(bp, samples, "position", [])  # positions are continuous: no gaps
        for axis, ls in ((0, "-"), (1, "--")):
            ax_pos.plot(t, pos[:, axis], color=colours[body.name], lw=lw, ls=ls)
        t, vel = _sample(bp, samples, "velocity", breaks)
        for axis, ls in ((0, "-"), (1, "--")):
            ax_vel.plot(t, vel[:, axis], color=colours[body.name], lw=lw, ls=ls)
        handles.append(Line2D([], [], color=colours[body.name], lw=lw, label=body.name))
    handles += [Line2D([], [], color="0.3", ls="-", label="x / vx"), Line2D([], [], color="0.3", ls="--",
                                                                           label="y / vy")]
    for ax in (ax_pos, ax_vel):
        label_at = blended_transform_factory(ax.transData, ax.transAxes)
        for k, imp in enumerate(plan.impacts, start=1):
            ax.axvline(imp.time_s, color=IMPACT_COLOUR, ls=":", lw=1.0)
            ax.text(imp.time_s, 0.98, f" I{k}", transform=label_at, ha="left", va="top", fontsize=8,
                    color=IMPACT_COLOUR)
        ax.grid(True, alpha=0.3)
    ax_pos.set_xlim(0.0, plan.tf_s)
    ax_pos.set_ylabel("position (m)")
    ax_pos.set_title("positions (x solid, y dashed)")
    ax_pos.tick_params(labelbottom=False)
    ax_vel.set_ylabel("velocity (m/s)")
    ax_vel.set_xlabel("time (s)")
    ax_vel.set_title("velocities (vx solid, vy dashed); impacts dotted")
    ax_pos.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                  fontsize="small")


def plot_execution(scenario: Scenario, plan: Plan, times_s: np.ndarray, positions: np.ndarray,
                   impacts: list[dict], robustness: float, path: str | Path | None = None) -> Figure:
    """The paper's Fig. 6 view: executed (solid) against planned (dotted) paths, and each object's
    position and velocity over time with the planned and the executed impacts.

    ``positions`` is (T, n_bodies, 2) in scenario body order, sampled at ``times_s`` (T,).
    """
    positions = np.asarray(positions, dtype=float)
    times_s = np.asarray(times_s, dtype=float)
    names = [b.name for b in scenario.bodies]
    if positions.ndim != 3 or positions.shape[1:] != (len(names), 2) or len(times_s) != len(positions):
        raise ValueError(f"positions must be (T, {len(names)}, 2) matching times_s (T,), got {positions.shape} "
                         f"and {times_s.shape}")
    colours = _colours(scenario)
    fig = Figure(figsize=(13, 6.5), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=[1, 1.4])
    ax = fig.add_subplot(grid[:, 0])
    draw_scenario(scenario, ax)
    t_plan = np.linspace(0.0, plan.tf_s, 600)
    for i, name in enumerate(names):
        ax.plot(*plan.position(name, t_plan).T, ":", color=colours[name], lw=1.2)
        ax.plot(positions[:, i, 0], positions[:, i, 1], "-", color=colours[name], lw=1.8, label=f"{name} executed")
    for k, imp in enumerate(plan.impacts):  # on top of the discs (zorder 4) and paths
        ax.plot(*imp.position, "*", color=IMPACT_COLOUR, ms=12, mec="k", mew=0.5, zorder=9,
                label="planned impact" if k == 0 else None)
    ax.plot([], [], ":", color="0.3", label="planned paths (dotted)")
    ax.set_title("executed (solid) vs planned (dotted)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)

    ax_p, ax_v = fig.add_subplot(grid[0, 1]), fig.add_subplot(grid[1, 1])
    dt = np.gradient(times_s)
    for i, name in enumerate(names):
        if name not in {o.name for o in scenario.objects}:
            continue
        planned_v = np.array([plan.velocity(name, t) for t in times_s])
        executed_v = np.gradient(positions[:, i], axis=0) / dt[:, None]
        for axis, style in ((0, "-"), (1, "--")):
            ax_p.plot(times_s, positions[:, i, axis], style, color=colours[name], lw=1.8,
                      label=f"{name} {'xy'[axis]} executed")
            ax_p.plot(times_s, plan.position(name, times_s)[:, axis], style, color="grey", lw=1.0,
                      label=f"{name} {'xy'[axis]} planned")
            ax_v.plot(times_s, executed_v[:, axis], style, color=colours[name], lw=1.5)
            ax_v.plot(times_s, planned_v[:, axis], style, color="grey", lw=1.0)
    for imp in plan.impacts:
        for a in (ax_p, ax_v):
            a.axvline(imp.time_s, color=IMPACT_COLOUR, ls=":", lw=1.0)
    for event in impacts:
        if {event["a"], event["b"]} <= set(names):
            for a in (ax_p, ax_v):
                a.axvline(event["time"], color="k", ls="-", lw=0.6, alpha=0.5)
    ax_p.set_ylabel("object position (m)")
    ax_p.legend(fontsize=7, ncol=2)
    ax_v.set_ylabel("object velocity (m/s)")
    ax_v.set_xlabel("time (s); impacts: planned red dotted, executed black")
    for a in (ax_p, ax_v):
        a.grid(alpha=0.3)
    from impact_env.transport.plotting import impacts_text

    fig.suptitle(f"{scenario.name}: executed robustness {robustness:+.3f} m (planned {plan.robustness:.3f} m); "
                 f"{impacts_text(scenario, impacts)} ({len(plan.impacts)} planned)")
    if path is not None:
        with atomic_path(png_path(path)) as tmp:
            fig.savefig(tmp, dpi=DPI)
    return fig
