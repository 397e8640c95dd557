"""Make the GIFs and figures of the documentation site (``make docs-media``); the outputs are committed.

    python scripts/make_docs_media.py                       # everything, into docs/img/
    python scripts/make_docs_media.py --only throw_and_catch_exp,L --max-steps 30 --out /tmp/media

- ``img/envs/<name>.gif``: one episode per registered environment. Impact scenarios are flown by the expert
  (the committed plan of ``results/baselines/plans/`` or ``--plans``, or a fresh MILP plan, then the replanner
  and the MPC).
  Tether stations are flown by a scripted anchor sequence (:class:`ScriptedAnchors`, below), a hand-written
  rule rather than the tether planners, so that the GIFs show the environment on its own.
- ``img/planners/<scenario>_plan.png`` (the paper's Fig. 4: the plan, its positions and velocities) and
  ``img/planners/<scenario>_execution.png`` (Fig. 6: executed against planned), from the same expert episodes.
- ``img/scenarios/<name>.png``: every shipped scenario and station as ``impact-env show`` draws it.

The episodes are seeded and the nominal environment is deterministic, so the same command makes the same
pictures.
"""

from __future__ import annotations

import argparse
import heapq
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GIF_WIDTH_PX = 360
GIF_FRAMES = 120  # frames per GIF at most (episodes are subsampled to this)
GIF_FPS = 12


class ScriptedAnchors:
    """A hand-written rule for the tether envs: one tether at a time, always toward the anchor that gets the cargo
    closest to the goal along the free space; release inside the goal.

    Distances are geodesic: a Dijkstra pass over a grid of the station's free space (shapely), from the goal.
    Among the anchors in line of sight, it attaches (robot 0, the others idle) to the one whose pull ends (at the
    stop radius) nearest the goal by that distance, or to one whose straight pull crosses the goal box; it
    releases as soon as the cargo centre is inside the goal box by 0.1 m, or when the pull stops gaining.
    """

    name = "scripted"

    def __init__(self, station, cell_m: float = 0.25) -> None:
        from shapely.geometry import Point

        self.station = station
        free = station.free_space()
        xmin, ymin, xmax, ymax = free.bounds
        self._origin, self._cell = np.array([xmin, ymin]), cell_m
        nx, ny = int(math.ceil((xmax - xmin) / cell_m)) + 1, int(math.ceil((ymax - ymin) / cell_m)) + 1
        inside = np.array([[free.contains(Point(xmin + i * cell_m, ymin + j * cell_m)) for j in range(ny)]
                           for i in range(nx)])
        self._dist = self._dijkstra(inside, self._index(station.goal_center_m))
        x0, x1, y0, y1 = station.goal_box
        self._goal = (x0, x1, y0, y1)

    def _index(self, p) -> tuple[int, int]:
        i, j = np.round((np.asarray(p, dtype=float) - self._origin) / self._cell).astype(int)
        return int(i), int(j)

    @staticmethod
    def _dijkstra(inside: np.ndarray, start: tuple[int, int]) -> np.ndarray:
        dist = np.full(inside.shape, np.inf)
        nx, ny = inside.shape
        sx, sy = min(max(start[0], 0), nx - 1), min(max(start[1], 0), ny - 1)
        dist[sx, sy] = 0.0
        heap = [(0.0, sx, sy)]
        steps = [(di, dj, math.hypot(di, dj)) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
        while heap:
            d, i, j = heapq.heappop(heap)
            if d > dist[i, j]:
                continue
            for di, dj, w in steps:
                a, b = i + di, j + dj
                if 0 <= a < nx and 0 <= b < ny and inside[a, b] and d + w < dist[a, b]:
                    dist[a, b] = d + w
                    heapq.heappush(heap, (d + w, a, b))
        return dist

    def geodesic(self, p) -> float:
        i, j = self._index(p)
        nx, ny = self._dist.shape
        window = self._dist[max(i - 2, 0):min(i + 3, nx), max(j - 2, 0):min(j + 3, ny)]
        return float(window.min()) * self._cell if window.size else float("inf")

    def _in_goal(self, p, margin: float = 0.1) -> bool:
        x0, x1, y0, y1 = self._goal
        return x0 + margin <= p[0] <= x1 - margin and y0 + margin <= p[1] <= y1 - margin

    def _crosses_goal(self, p, q) -> bool:
        return any(self._in_goal(p + t * (q - p)) for t in np.linspace(0.0, 1.0, 200))

    def reset(self, env, seed) -> None:
        self._core = env.unwrapped.core
        self._pulling: int | None = None
        self._best = float("inf")

    def act(self, observation, info) -> np.ndarray:
        core, st = self._core, self.station
        n = core.n_robots
        action = np.zeros(n, dtype=np.int64)  # keep
        cargo = np.asarray(core.world.position_m)
        held = core.world.tether_anchor(0)
        if self._in_goal(cargo):
            if held is not None:
                action[0] = 1  # release: the cargo stops (kinematic) inside the goal
            return action
        if held is not None:
            d = self.geodesic(cargo)
            if d < self._best - 1e-3 or core.world.attach_remaining_s(0) > 0:
                self._best = min(self._best, d)
                return action
        here = self.geodesic(cargo)
        best, choice = here - 0.25, None
        for j in np.flatnonzero(core.line_of_sight_mask()):
            a = np.asarray(st.anchors[j].position_m)
            if np.hypot(*(a - cargo)) <= st.stop_radius_m:
                continue
            end = a + (cargo - a) / np.hypot(*(cargo - a)) * st.stop_radius_m
            score = -1.0 if self._crosses_goal(cargo, end) else self.geodesic(end)
            if score < best:
                best, choice = score, j
        if choice is not None and choice != held:
            action[0] = 2 + choice
            self._best = here
        return action


def _gif(frames: list[np.ndarray], path: Path, fps: int = GIF_FPS) -> None:
    import imageio.v3 as iio

    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, np.stack(frames), extension=".gif", duration=1000 / fps, loop=0)


def _episode_frames(env, controller, seed: int, max_steps: int | None):
    obs, info = env.reset(seed=seed)
    controller.reset(env, seed)
    steps = env.unwrapped.horizon_steps if max_steps is None else min(max_steps, env.unwrapped.horizon_steps)
    every = max(1, steps // GIF_FRAMES)
    frames, positions, impacts = [env.render()], [[s[:2] for s in env.unwrapped.core._state]], []
    for k in range(1, steps + 1):
        obs, reward, terminated, truncated, info = env.step(controller.act(obs, info))
        positions.append([s[:2] for s in env.unwrapped.core._state])
        impacts += info.get("impacts", [])
        if k % every == 0 or terminated or k == steps:
            frames.append(env.render())
        if terminated or truncated:
            break
    return frames, np.array(positions), impacts, info


def impact_media(name: str, out: Path, max_steps: int | None, plans: Path) -> None:
    import gymnasium as gym

    from impact_env import GYM_IDS
    from planners.expert import Expert
    from planners.plan import Plan
    from planners.plan.plotting import plot_execution, plot_plan

    env_id = next(i for i, s in GYM_IDS.items() if s == name)
    env = gym.make(env_id, render_mode="rgb_array", render_width_px=GIF_WIDTH_PX)
    committed = plans / f"{name}.json"
    plan = Plan.load(committed) if committed.is_file() else None
    expert = Expert(name, plan=plan)
    frames, positions, impacts, info = _episode_frames(env, expert, 0, max_steps)
    _gif(frames, out / "envs" / f"{name}.gif")
    sc = env.unwrapped.scenario
    plot_plan(sc, expert.plan, out / "planners" / f"{name}_plan.png")
    times = np.arange(len(positions)) * env.unwrapped.dt_s
    plot_execution(sc, expert.plan, times, positions, impacts, info["robustness"],
                   out / "planners" / f"{name}_execution.png")
    print(f"{env_id}: expert robustness {info['robustness']:+.3f} m, {len(frames)} frames", flush=True)
    env.close()


def tether_media(name: str, out: Path, max_steps: int | None) -> None:
    import gymnasium as gym

    from impact_env import TETHER_GYM_IDS

    env_id = next(i for i, s in TETHER_GYM_IDS.items() if s == name)
    env = gym.make(env_id, render_mode="rgb_array", render_width_px=GIF_WIDTH_PX)
    controller = ScriptedAnchors(env.unwrapped.station)
    frames, _, _, info = _episode_frames(env, controller, 0, max_steps)
    _gif(frames, out / "envs" / f"{name}.gif")
    print(f"{env_id}: scripted anchors, robustness {info['robustness']:+.3f} m, {info['switches']} switches, "
          f"{len(frames)} frames", flush=True)
    env.close()


def scenario_figures(names: list[str], out: Path) -> None:
    from impact_env import load_scenario, load_station, scenario_names
    from impact_env.tether.plotting import save_station_figure
    from impact_env.transport.plotting import save_scenario_figure

    for name in names:
        if name in scenario_names():
            save_scenario_figure(load_scenario(name), out / "scenarios" / f"{name}.png")
        else:
            save_station_figure(load_station(name), out / "scenarios" / f"{name}.png")


def main(argv: list[str] | None = None) -> int:
    from impact_env import GYM_IDS, TETHER_GYM_IDS

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "img"), help="output folder (default docs/img)")
    parser.add_argument("--only", default=None, help="comma-separated scenario and station names (default all)")
    parser.add_argument("--max-steps", type=int, default=None, help="cut episodes short (for a quick check)")
    parser.add_argument("--plans", default=str(ROOT / "results" / "baselines" / "plans"),
                        help="the expert's plans, <scenario>.json (default results/baselines/plans)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    names = args.only.split(",") if args.only else [*GYM_IDS.values(), *TETHER_GYM_IDS.values()]
    for name in names:
        if name in GYM_IDS.values():
            impact_media(name, out, args.max_steps, Path(args.plans))
        elif name in TETHER_GYM_IDS.values():
            tether_media(name, out, args.max_steps)
        else:
            parser.error(f"unknown name {name!r}")
    scenario_figures(names, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
