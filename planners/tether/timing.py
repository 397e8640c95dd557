"""Time-optimal refinement along a plan's route with ``k`` robots (CasADi, IPOPT).

The exact planner's pulls use one robot at a time; with ``k`` robots the cargo can be pulled toward several
anchors at once (Eq. 5 sums their unit vectors), which is faster. Along the plan's route this module
minimises the sum of the phase durations over the activations ``u_{j,i}(t)`` in [0, 1] of each phase's
anchors, at most ``k`` at once, with the cargo inside a corridor around each pull that every anchor of the
phase sees whole (multiple shooting, one RK4 step per interval). Relaxing ``u`` to [0, 1] makes it a smooth
NLP; :attr:`TimingResult.bang_bang_fraction` reports how close the optimum comes to a schedule real robots
can fly. With ``k = 1`` the optimum is the plan itself at full speed; the times are the kinematic model's.
The problem in full: ``docs/planner_design.md#time-optimal-refinement``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import shapely

from impact_env.tether.station import Station
from planners.errors import PlannerError
from planners.tether.automaton import half_planes
from planners.tether.geometry import free_space_polygon, visibility_polygon
from planners.tether.plan import TetherPlan


@dataclass
class TimingResult:
    """The refined schedule: per phase its duration (s), anchors, activations ``(N, m)`` and states ``(N+1, 2)``."""

    k: int
    total_s: float
    plan_s: float  # the plan's pulling time at w with one robot (no attach waits)
    durations_s: list[float]
    anchors: list[list[int]]
    activations: list[np.ndarray]
    states: list[np.ndarray]
    bang_bang_fraction: float
    solve_s: float
    status: str
    stats: dict = field(default_factory=dict)


def _corridor(free, vis, seg: np.ndarray, anchor_pos: np.ndarray, stop_m: float, width_m: float):
    """The widest rectangle (half-width <= width_m) around ``seg`` inside ``free`` and ``vis`` and outside the
    anchor's stop disc; a thin one if the segment runs along a boundary."""
    line = shapely.LineString(seg)
    half = width_m
    for _ in range(12):
        rect = line.buffer(half, cap_style="flat") if half > 1e-4 else line.buffer(1e-4, cap_style="flat")
        rect = shapely.oriented_envelope(rect)
        ok = free.buffer(1e-9).covers(rect) and vis.buffer(1e-9).covers(rect)
        ok = ok and rect.distance(shapely.Point(anchor_pos)) >= stop_m
        if ok:
            return rect
        half *= 0.5
    return shapely.oriented_envelope(line.buffer(1e-4, cap_style="flat"))


def refine_timing(station: Station, plan: TetherPlan, k: int, nodes: int = 20, width_m: float = 0.5,
                  clearance_m: float = 0.02, max_anchors: int = 12) -> TimingResult:
    """Solve the relaxed time-optimal problem along ``plan`` with ``k`` robots (see the module docstring)."""
    import casadi as ca

    if k < 1:
        raise PlannerError(f"k must be >= 1, got {k}")
    if not plan.pulls:
        return TimingResult(k, 0.0, 0.0, [], [], [], [], 1.0, 0.0, "empty plan")
    t0 = time.perf_counter()
    w = station.pull_speed_mps
    free = free_space_polygon(station, clearance_m)
    stop_m = station.stop_radius_m + 0.05
    vis = {a: visibility_polygon(station, a) for a in range(station.n_anchors)}
    corridors, phase_anchors = [], []
    for p in plan.pulls:
        seg = np.array([p.start_m, p.end_m])
        rect = _corridor(free, vis[p.anchor], seg, station.anchor_positions[p.anchor], stop_m, width_m)
        corridors.append(rect)
        # the anchors that see the whole corridor and stay outside their stop radius: the plan's own first
        usable = [a for a in range(station.n_anchors) if a != p.anchor and vis[a].buffer(1e-9).covers(rect)
                  and rect.distance(shapely.Point(station.anchor_positions[a])) >= stop_m]
        direction = seg[1] - seg[0]
        direction /= max(np.linalg.norm(direction), 1e-12)
        mid = seg.mean(axis=0)
        usable.sort(key=lambda a: -float(np.dot((station.anchor_positions[a] - mid)
                                               / np.linalg.norm(station.anchor_positions[a] - mid), direction)))
        phase_anchors.append([p.anchor] + usable[: max_anchors - 1])
    x0, x1, y0, y1 = station.goal_box
    m = 0.15
    goal = shapely.box(x0 + m, y0 + m, x1 - m, y1 - m) if x1 - x0 > 2 * m and y1 - y0 > 2 * m else \
        shapely.box(x0, y0, x1, y1)

    opti = ca.Opti()
    durations: list[ca.MX] = []
    controls: list[ca.MX] = []
    states: list[ca.MX] = []
    cost: ca.MX | int = 0
    start = np.asarray(plan.start_m, float)
    for j, (rect, anchors) in enumerate(zip(corridors, phase_anchors)):
        T = opti.variable()
        X = opti.variable(2, nodes + 1)
        U = opti.variable(len(anchors), nodes)
        A = np.asarray(station.anchor_positions[anchors], float).T  # (2, m)
        h = T / nodes

        def f(x, u, A=A):
            d = A - ca.repmat(x, 1, A.shape[1])
            n = ca.sqrt(ca.sum1(d ** 2))
            return w * ca.mtimes(d / ca.repmat(n, 2, 1), u)

        for i in range(nodes):
            x, u = X[:, i], U[:, i]
            k1 = f(x, u)
            k2 = f(x + 0.5 * h * k1, u)
            k3 = f(x + 0.5 * h * k2, u)
            k4 = f(x + h * k3, u)
            opti.subject_to(X[:, i + 1] == x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
        rows = np.array(half_planes(rect))
        for i in range(nodes + 1):
            opti.subject_to(ca.mtimes(rows[:, :2], X[:, i]) <= rows[:, 2])
        opti.subject_to(opti.bounded(0, ca.vec(U), 1))
        opti.subject_to(ca.sum1(U) <= k)
        opti.subject_to(T >= 0)
        if j == 0:
            opti.subject_to(X[:, 0] == start)
        else:
            opti.subject_to(X[:, 0] == states[-1][:, nodes])
        if j + 1 < len(corridors):
            nxt = np.array(half_planes(corridors[j + 1]))
            opti.subject_to(ca.mtimes(nxt[:, :2], X[:, nodes]) <= nxt[:, 2])
        else:
            g = np.array(half_planes(goal))
            opti.subject_to(ca.mtimes(g[:, :2], X[:, nodes]) <= g[:, 2])
        # the plan as the initial guess: full pull on its anchor, straight at w
        p = plan.pulls[j]
        opti.set_initial(T, p.length_m / w)
        opti.set_initial(X, np.linspace(p.start_m, p.end_m, nodes + 1).T)
        guess = np.zeros((len(anchors), nodes))
        guess[0] = 1.0
        opti.set_initial(U, guess)
        durations.append(T)
        controls.append(U)
        states.append(X)
        cost = cost + T
    opti.minimize(cost)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes", "max_iter": 500, "tol": 1e-7})
    try:
        sol = opti.solve()
        status = "optimal"
        get = sol.value
    except RuntimeError:
        status = "not converged: " + opti.stats().get("return_status", "?")
        get = opti.debug.value
    Ts = [float(get(T)) for T in durations]
    Us = [np.atleast_2d(np.asarray(get(U))).reshape(len(a), nodes).T for U, a in zip(controls, phase_anchors)]
    Xs = [np.asarray(get(X)).T for X in states]
    weights = np.concatenate([np.full(U.size, Tj / nodes) for U, Tj in zip(Us, Ts)])
    values = np.concatenate([U.reshape(-1) for U in Us])
    near = (np.abs(values) <= 0.05) | (np.abs(values - 1.0) <= 0.05)
    bang = float(np.sum(weights * near) / max(np.sum(weights), 1e-12))
    plan_s = plan.path_length_m / w
    return TimingResult(k=k, total_s=float(sum(Ts)), plan_s=plan_s, durations_s=Ts, anchors=phase_anchors,
                        activations=Us, states=Xs, bang_bang_fraction=bang, solve_s=time.perf_counter() - t0,
                        status=status, stats={"nodes": nodes, "corridor_area_m2": [float(c.area) for c in corridors]})
