"""pygame-ce renderer of a scenario's state: the picture behind ``render()`` of the transport environments.

One :class:`Renderer` per environment, on the shared :class:`~impact_env.canvas.Canvas` (metres square, y up,
a text band above the world, no pygame state before the first frame). Picture:

- the world box border, obstacles (filled, dark red-grey, named), regions (translucent green, named);
- bodies as discs of their radius (robots blue, objects orange, named) with a line from the centre to the
  rim along the heading;
- each robot's applied force as an arrow starting at the disc's rim, ``FORCE_SCALE_M_PER_N`` metres of
  arrow per newton (0.2 m/N: the 2.8 N thrust limit is a 0.56 m arrow);
- every impact younger than ``IMPACT_FLASH_S`` as a red ring that grows and fades with the impact's age;
- the line ``t = 12.3 s  rho = 0.412 m`` (time and current STL robustness) in the band above the world.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from impact_env.canvas import (  # noqa: F401 - the colours and layout of impact_env.transport.rendering (0.2)
    BACKGROUND,
    BODY_EDGE,
    BORDER,
    HEADER_PX,
    MARGIN_PX,
    OBJECT,
    REGION,
    REGION_EDGE,
    REGION_TEXT,
    RENDER_MODES,
    ROBOT,
    TEXT,
    Canvas,
    Frame,
    prepare_display,
)

if TYPE_CHECKING:
    from impact_env.transport.core import TransportCore
    from impact_env.transport.physics import ImpactEvent
    from impact_env.transport.scenario import Scenario

FORCE_SCALE_M_PER_N = 0.2  # thrust arrow length per newton of applied force
IMPACT_FLASH_S = 1.0  # how long an impact ring stays visible
FLASH_S = IMPACT_FLASH_S  # how long an impact is reported to the renderer

OBSTACLE = (110, 72, 72)
OBSTACLE_EDGE = (60, 38, 38)
OBSTACLE_TEXT = (250, 250, 250)
HEADING = TEXT  # the line from a disc's centre along its heading
THRUST = (200, 0, 160)
IMPACT = (230, 30, 30)


@dataclass
class RenderFrame(Frame):
    """What one picture shows. Per-body sequences follow ``scenario.bodies`` (robots first, then objects)."""

    positions: Sequence[tuple[float, float]]  # per body, world frame (m)
    headings: Sequence[float]  # per body (rad, counter-clockwise from +x)
    robot_forces_world: Sequence[tuple[float, float]]  # per robot, applied force in the world frame (N)
    impacts: Sequence[tuple[float, float, float]]  # recent impacts: (x_m, y_m, age_s)


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


def frame_of(core: TransportCore) -> RenderFrame:
    """The frame of a transport environment's current state."""
    recent = [e for e in core.log.impacts[-8:]]
    return RenderFrame(
        time_s=core.time_s,
        robustness=core.log.robustness,
        positions=[(s[0], s[1]) for s in core._state],
        headings=[s[4] for s in core._state],
        robot_forces_world=core.robot_forces_world(),
        impacts=impact_flashes(core, recent),
    )


# impact_env.transport.rendering's names (0.2), for that old path's release
make_frame = frame_of


def render(env: Any) -> np.ndarray | None:
    """``env.render()``'s drawing, as ``impact_env.transport.rendering.render`` (0.2) named it."""
    return env._draw()


def close(env: Any) -> None:
    """``env.close()``, as ``impact_env.transport.rendering.close`` (0.2) named it."""
    env.close()


class Renderer(Canvas):
    """Draws :class:`RenderFrame` s of one scenario, in a window (``human``) or to an array (``rgb_array``).

    Args:
        scenario: the scenario whose world, obstacles, regions and bodies are drawn.
        render_mode: ``"human"`` or ``"rgb_array"``.
        width_px: image width; the height follows from the world box's aspect ratio (see :attr:`size_px`).
        fps: frame-rate cap of the ``human`` window (frames per second).
    """

    def __init__(self, scenario: Scenario, render_mode: str, width_px: int = 600, fps: int = 10) -> None:
        super().__init__(scenario.world_box, render_mode, width_px, fps)
        self.scenario = scenario
        self._body_labels: list[Any] = []

    def close(self) -> None:
        super().close()
        self._body_labels = []

    def _status(self, frame: RenderFrame) -> str:
        return f"t = {frame.time_s:.1f} s  rho = {frame.robustness:.3f} m"

    def _caption(self) -> str:
        return f"impact_env: {self.scenario.name}"

    def _draw_frame(self, canvas: Any, drawn: tuple[np.ndarray, np.ndarray, np.ndarray, Any]) -> None:
        positions, headings, forces, impacts = drawn
        self._draw_bodies(canvas, positions, headings, forces)
        self._draw_impacts(canvas, impacts)

    # ----------------------------------------------------------------------------------------- drawing

    def _checked(self, frame: RenderFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
        n_bodies, n_robots = len(self.scenario.bodies), len(self.scenario.robots)
        positions = np.asarray(frame.positions, dtype=float)
        headings = np.asarray(frame.headings, dtype=float)
        forces = np.asarray(frame.robot_forces_world, dtype=float)
        if positions.shape != (n_bodies, 2):
            raise ValueError(f"RenderFrame.positions must have shape ({n_bodies}, 2) (one (x, y) per body of "
                             f"{self.scenario.name!r}), got {positions.shape}")
        if headings.shape != (n_bodies,):
            raise ValueError(f"RenderFrame.headings must have shape ({n_bodies},), got {headings.shape}")
        if forces.shape != (n_robots, 2):
            raise ValueError(f"RenderFrame.robot_forces_world must have shape ({n_robots}, 2) (one (fx, fy) per "
                             f"robot), got {forces.shape}")
        # far-off bodies (a diverging simulation) are drawn off-screen, not at coordinates pygame rejects
        xmin, xmax, ymin, ymax = self.scenario.world_box
        reach = 10.0 * max(xmax - xmin, ymax - ymin)
        positions = np.clip(positions, (xmin - reach, ymin - reach), (xmax + reach, ymax + reach))
        magnitudes = np.hypot(forces[:, 0], forces[:, 1])
        longest_N = reach / FORCE_SCALE_M_PER_N
        forces = forces * np.minimum(1.0, longest_N / np.maximum(magnitudes, 1e-300))[:, None]
        return positions, headings, forces, frame.impacts

    def _polygon_px(self, vertices: np.ndarray) -> list[tuple[float, float]]:
        return [self.world_to_px(x, y) for x, y in vertices]

    def _draw_static(self, pygame: Any) -> Any:
        font = pygame.font.Font(None, max(12, self.size_px[0] // 28))
        self._body_labels = [font.render(b.name, True, TEXT) for b in self.scenario.bodies]
        surface = pygame.Surface(self.size_px)
        surface.fill(BACKGROUND)
        overlay = pygame.Surface(self.size_px, pygame.SRCALPHA)  # regions are translucent
        for region in self.scenario.regions:
            pygame.draw.polygon(overlay, REGION, self._polygon_px(region.polygon.vertices))
        surface.blit(overlay, (0, 0))
        for region in self.scenario.regions:
            pts = self._polygon_px(region.polygon.vertices)
            pygame.draw.polygon(surface, REGION_EDGE, pts, 2)
            label = font.render(region.name, True, REGION_TEXT)
            xmin, _, _, ymax = region.polygon.bounds
            col, row = self.world_to_px(xmin, ymax)
            surface.blit(label, (col + 4, row + 4))
        for obstacle in self.scenario.obstacles:
            pts = self._polygon_px(obstacle.polygon.vertices)
            pygame.draw.polygon(surface, OBSTACLE, pts)
            pygame.draw.polygon(surface, OBSTACLE_EDGE, pts, 2)
            label = font.render(obstacle.name, True, OBSTACLE_TEXT)
            col, row = self.world_to_px(*obstacle.polygon.vertices.mean(axis=0))
            surface.blit(label, label.get_rect(center=(round(col), round(row))))
        xmin, xmax, ymin, ymax = self.scenario.world_box
        left, top = self.world_to_px(xmin, ymax)
        right, bottom = self.world_to_px(xmax, ymin)
        pygame.draw.rect(surface, BORDER, pygame.Rect(round(left) - 1, round(top) - 1,
                                                      round(right - left) + 2, round(bottom - top) + 2), 2)
        return surface

    def _draw_bodies(self, canvas: Any, positions: np.ndarray, headings: np.ndarray, forces: np.ndarray) -> None:
        pygame = self._pygame
        n_robots = len(self.scenario.robots)
        for i, body in enumerate(self.scenario.bodies):
            x, y = positions[i]
            centre = self.world_to_px(x, y)
            radius_px = max(2.0, body.radius_m * self.scale_px_per_m)
            pygame.draw.circle(canvas, ROBOT if i < n_robots else OBJECT, centre, radius_px)
            pygame.draw.circle(canvas, BODY_EDGE, centre, radius_px, 1)
            rim = self.world_to_px(x + body.radius_m * math.cos(headings[i]), y + body.radius_m * math.sin(headings[i]))
            pygame.draw.line(canvas, HEADING, centre, rim, 2)
            label = self._body_labels[i]
            offset = radius_px * 0.7
            canvas.blit(label, (centre[0] + offset, centre[1] - offset - label.get_height()))
        for i, body in enumerate(self.scenario.robots):
            fx, fy = forces[i]
            magnitude = math.hypot(fx, fy)
            if magnitude * FORCE_SCALE_M_PER_N * self.scale_px_per_m < 1.0:
                continue
            ux, uy = fx / magnitude, fy / magnitude
            x, y = positions[i]
            start = (x + body.radius_m * ux, y + body.radius_m * uy)
            end = (start[0] + fx * FORCE_SCALE_M_PER_N, start[1] + fy * FORCE_SCALE_M_PER_N)
            self._draw_arrow(canvas, self.world_to_px(*start), self.world_to_px(*end))

    def _draw_arrow(self, canvas: Any, start: tuple[float, float], end: tuple[float, float]) -> None:
        pygame = self._pygame
        dx, dy = end[0] - start[0], end[1] - start[1]
        length = math.hypot(dx, dy)
        ux, uy = dx / length, dy / length
        head = min(12.0, 0.5 * length)
        base = (end[0] - head * ux, end[1] - head * uy)
        pygame.draw.line(canvas, THRUST, start, base, 3)
        half = 0.5 * head
        pygame.draw.polygon(canvas, THRUST, [end, (base[0] - half * uy, base[1] + half * ux),
                                             (base[0] + half * uy, base[1] - half * ux)])

    def _draw_impacts(self, canvas: Any, impacts: Sequence[tuple[float, float, float]]) -> None:
        pygame = self._pygame
        xmin, xmax, ymin, ymax = self.scenario.world_box
        for x, y, age_s in impacts:
            if not (0.0 <= age_s < IMPACT_FLASH_S and xmin - 1.0 <= x <= xmax + 1.0 and ymin - 1.0 <= y <= ymax + 1.0):
                continue
            fraction = age_s / IMPACT_FLASH_S
            radius_px = max(4, round((0.1 + 0.5 * fraction) * self.scale_px_per_m))
            width_px = max(2, round(4 * (1.0 - fraction)))
            ring = pygame.Surface((2 * radius_px + 2, 2 * radius_px + 2), pygame.SRCALPHA)
            alpha = round(255 * (1.0 - fraction))
            pygame.draw.circle(ring, (*IMPACT, alpha), (radius_px + 1, radius_px + 1), radius_px, width_px)
            col, row = self.world_to_px(x, y)
            canvas.blit(ring, (round(col) - radius_px - 1, round(row) - radius_px - 1))
