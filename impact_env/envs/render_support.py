"""Turns the episode state into a :class:`~impact_env.rendering.RenderFrame` (shared by both envs)."""

from __future__ import annotations

from impact_env.envs.core import TransportCore
from impact_env.physics import ImpactEvent

FLASH_S = 1.0  # how long an impact stays visible


def impact_flashes(core: TransportCore, events: list[ImpactEvent]) -> list[tuple[float, float, float]]:
    """(x, y, age_s) of recent impacts: the midpoint of two bodies, or the body for a wall contact.

    Events are logged at separation, so the position is where the bodies are then: a few millimetres
    from the contact point at these speeds, which is all a flash needs.
    """
    names = core.body_names
    state = core._state
    out = []
    for e in events:
        age = core.time_s - e.time_s
        if age > FLASH_S:
            continue
        pts = [state[names.index(n)][:2] for n in (e.a, e.b) if n in names]
        if pts:
            out.append((sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts), age))
    return out


def make_frame(core: TransportCore):
    from impact_env.rendering import RenderFrame

    recent = [e for e in core.log.impacts[-8:]]
    return RenderFrame(
        time_s=core.time_s,
        robustness=core.log.robustness,
        positions=[(s[0], s[1]) for s in core._state],
        headings=[s[4] for s in core._state],
        robot_forces_world=core.robot_forces_world(),
        impacts=impact_flashes(core, recent),
    )


def render(env) -> object:
    """Shared ``render()`` of both environments: builds the pygame renderer on first use, draws a frame."""
    if env._renderer is None:
        from impact_env.rendering import Renderer

        env._renderer = Renderer(env.scenario, env.render_mode, width_px=env.render_width_px,
                                 fps=env.metadata["render_fps"])
    return env._renderer.render(make_frame(env.core))


def close(env) -> None:
    """Shared ``close()``: releases the renderer (and its window in human mode)."""
    if env._renderer is not None:
        env._renderer.close()
        env._renderer = None
