"""One env of a batch as a :class:`~impact_env.transport.rendering.RenderFrame`, drawn by the pymunk envs' renderer.

The frame shows what the pymunk environments' frames show: bodies, headings, each robot's last applied force
(rotated into the world frame by its current heading), the time and the robustness estimate, and a flash
for every contact that ended in the last second, at the two bodies' midpoint (or the body, for a wall or
an obstacle) where they are now, as :func:`impact_env.transport.rendering.impact_flashes` places them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from impact_env.transport.rendering import FLASH_S

if TYPE_CHECKING:
    from impact_env.transport.rendering import RenderFrame

# the world is typed Any here: world.py imports this module (render_rgb), and the import contracts allow no
# cycle inside the package, not even one for type checking only
BatchedTransportWorld = Any


def make_frame(world: BatchedTransportWorld, env_index: int) -> RenderFrame:
    """The picture of env ``env_index`` (0 <= env_index < num_envs)."""
    from impact_env.errors import EnvConfigError
    from impact_env.transport.rendering import RenderFrame

    if isinstance(env_index, bool) or not isinstance(env_index, int) or not 0 <= env_index < world.num_envs:
        raise EnvConfigError(f"env_index must be an integer in 0..{world.num_envs - 1}, got {env_index!r}")
    state = world.body_state()[env_index].double().cpu().numpy()  # [B, 6]
    k = int(world.step_count[env_index])
    wrench = world.last_wrenches[:, :, env_index].double().cpu().numpy()  # [3, R]
    forces = []
    for r in range(world.n_robots):
        c, s = math.cos(state[r, 4]), math.sin(state[r, 4])
        fx, fy = wrench[0, r], wrench[1, r]
        forces.append((c * fx - s * fy, s * fx + c * fy))
    flashes = []
    last = world.last_impact_step[:, env_index].cpu().numpy()
    scene = world.scene
    contacts = [pair for pair in scene.pairs] + [(b,) for _ in range(scene.n_static) for b in range(scene.n_bodies)]
    for bodies, step in zip(contacts, last):
        age = (k - int(step)) * world.dt_s
        if 0.0 <= age <= FLASH_S:
            pts = state[list(bodies), :2]
            flashes.append((float(pts[:, 0].mean()), float(pts[:, 1].mean()), age))
    return RenderFrame(time_s=k * world.dt_s, robustness=float(world.robustness[env_index]),
                       positions=[tuple(p) for p in state[:, :2]], headings=list(state[:, 4]),
                       robot_forces_world=forces, impacts=flashes)


def render_env(world: BatchedTransportWorld, env_index: int, width_px: int = 600) -> np.ndarray:
    """A uint8 (H, W, 3) frame of one env; the renderer is built on first use and kept per width."""
    from impact_env.transport.rendering import Renderer

    renderer = world._renderers.get(width_px)
    if renderer is None:
        fps = round(1.0 / world.dt_s)
        renderer = world._renderers[width_px] = Renderer(world.scenario, "rgb_array", width_px=width_px, fps=fps)
    return renderer.render(make_frame(world, env_index))
