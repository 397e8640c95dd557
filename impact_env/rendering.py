"""pygame-ce renderer of a scenario's state: the picture behind ``render()`` of every environment.

One :class:`Renderer` per environment. It is cheap to build (only arithmetic) and creates no pygame state
until the first :meth:`Renderer.render` call, so environments can build it in ``__init__`` whatever the
render mode.

Picture (metres square, y up; the world box scaled to ``width_px`` minus a small margin, with a text band
above it):

- the world box border, obstacles (filled, dark red-grey, named), regions (translucent green, named);
- bodies as discs of their radius (robots blue, objects orange, named) with a line from the centre to the
  rim along the heading;
- each robot's applied force as an arrow starting at the disc's rim, ``FORCE_SCALE_M_PER_N`` metres of
  arrow per newton (0.2 m/N: the 2.8 N thrust limit is a 0.56 m arrow);
- every impact younger than ``IMPACT_FLASH_S`` as a red ring that grows and fades with the impact's age;
- the line ``t = 12.3 s  rho = 0.412 m`` (time and current STL robustness) in the band above the world.

``rgb_array`` draws onto an off-screen ``pygame.Surface`` only and never initialises ``pygame.display``;
``human`` opens a window (``pygame.display``), pumps events and caps the frame rate at ``fps``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from impact_env.scenario import Scenario

RENDER_MODES = ("human", "rgb_array")
FORCE_SCALE_M_PER_N = 0.2  # thrust arrow length per newton of applied force
IMPACT_FLASH_S = 1.0  # how long an impact ring stays visible
MARGIN_PX = 10  # around the world box (left, right, bottom)
HEADER_PX = 30  # text band above the world box

BACKGROUND = (246, 246, 241)
BORDER = (40, 40, 40)
TEXT = (20, 20, 20)
OBSTACLE = (110, 72, 72)
OBSTACLE_EDGE = (60, 38, 38)
OBSTACLE_TEXT = (250, 250, 250)
REGION = (60, 180, 75, 80)  # RGBA: blended over the background
REGION_EDGE = (40, 140, 55)
REGION_TEXT = (20, 100, 35)
ROBOT = (60, 110, 220)
OBJECT = (245, 150, 40)
BODY_EDGE = (30, 30, 30)
HEADING = (20, 20, 20)
THRUST = (200, 0, 160)
IMPACT = (230, 30, 30)


def prepare_display() -> None:
    """Quiet, working SDL set-up before ``pygame.display.init()`` (human mode).

    SDL prints ``error: XDG_RUNTIME_DIR is invalid or not set in the environment`` when that variable does not
    name a folder, which is the rule on servers and in containers: give it a private temporary folder then. On
    Linux without ``DISPLAY`` or ``WAYLAND_DISPLAY`` there is no screen to open a window on: SDL's ``offscreen``
    driver is used (the frames are drawn, nothing is shown) with one warning that says so, unless
    ``SDL_VIDEODRIVER`` is set already.
    """
    import sys
    import tempfile

    runtime = os.environ.get("XDG_RUNTIME_DIR")
    if not runtime or not os.path.isdir(runtime):
        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="impact_env_xdg_")
    headless = sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if headless and "SDL_VIDEODRIVER" not in os.environ:
        import gymnasium

        os.environ["SDL_VIDEODRIVER"] = "offscreen"
        gymnasium.logger.warn("no display (DISPLAY and WAYLAND_DISPLAY are unset): render_mode='human' draws "
                              "off-screen; use render_mode='rgb_array' to get the frames")


@dataclass
class RenderFrame:
    """What one picture shows. Per-body sequences follow ``scenario.bodies`` (robots first, then objects)."""

    time_s: float
    robustness: float  # current STL robustness estimate (m)
    positions: Sequence[tuple[float, float]]  # per body, world frame (m)
    headings: Sequence[float]  # per body (rad, counter-clockwise from +x)
    robot_forces_world: Sequence[tuple[float, float]]  # per robot, applied force in the world frame (N)
    impacts: Sequence[tuple[float, float, float]]  # recent impacts: (x_m, y_m, age_s)


class Renderer:
    """Draws :class:`RenderFrame` s of one scenario, in a window (``human``) or to an array (``rgb_array``).

    Args:
        scenario: the scenario whose world, obstacles, regions and bodies are drawn.
        render_mode: ``"human"`` or ``"rgb_array"``.
        width_px: image width; the height follows from the world box's aspect ratio (see :attr:`size_px`).
        fps: frame-rate cap of the ``human`` window (frames per second).
    """

    def __init__(self, scenario: Scenario, render_mode: str, width_px: int = 600, fps: int = 10) -> None:
        if render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be one of {RENDER_MODES}, got {render_mode!r}")
        if int(width_px) != width_px or width_px < 2 * MARGIN_PX + 40:
            raise ValueError(f"width_px must be an integer >= {2 * MARGIN_PX + 40}, got {width_px!r}")
        if not fps > 0:
            raise ValueError(f"fps must be > 0, got {fps!r}")
        self.scenario = scenario
        self.render_mode = render_mode
        self.fps = fps
        xmin, xmax, ymin, ymax = scenario.world_box
        self.scale_px_per_m = (int(width_px) - 2 * MARGIN_PX) / (xmax - xmin)
        self.size_px = (int(width_px), HEADER_PX + round((ymax - ymin) * self.scale_px_per_m) + MARGIN_PX)
        # pygame state, created by the first render()
        self._pygame: Any = None
        self._static: Any = None  # background, regions, obstacles, border: drawn once
        self._canvas: Any = None
        self._status_font: Any = None
        self._body_labels: list[Any] = []
        self._window: Any = None
        self._clock: Any = None

    # ------------------------------------------------------------------------------------ coordinates

    def world_to_px(self, x_m: float, y_m: float) -> tuple[float, float]:
        """World point (m) -> pixel (column, row) of the image, row 0 at the top."""
        xmin, _, _, ymax = self.scenario.world_box
        return (MARGIN_PX + (x_m - xmin) * self.scale_px_per_m, HEADER_PX + (ymax - y_m) * self.scale_px_per_m)

    # ------------------------------------------------------------------------------------------ public

    def render(self, frame: RenderFrame) -> np.ndarray | None:
        """Draw ``frame``. Returns a uint8 (H, W, 3) image in ``rgb_array`` mode, None in ``human`` mode."""
        positions, headings, forces = self._check(frame)
        if self._pygame is None:
            self._start()
        pygame = self._pygame
        canvas = self._canvas
        canvas.blit(self._static, (0, 0))
        self._draw_bodies(canvas, positions, headings, forces)
        self._draw_impacts(canvas, frame.impacts)
        status = f"t = {frame.time_s:.1f} s  rho = {frame.robustness:.3f} m"
        text = self._status_font.render(status, True, TEXT)
        canvas.blit(text, (MARGIN_PX, (HEADER_PX - text.get_height()) // 2))
        if self.render_mode == "rgb_array":
            width, height = self.size_px
            # tobytes is row-major already: (H, W, 3) without the transpose surfarray would need
            return np.frombuffer(pygame.image.tobytes(canvas, "RGB"), dtype=np.uint8).reshape(height, width, 3).copy()
        self._window.blit(canvas, (0, 0))
        pygame.event.pump()
        pygame.display.flip()
        self._clock.tick(self.fps)
        return None

    def close(self) -> None:
        """Release pygame state and close the window (if any). Rendering again starts afresh."""
        if self._pygame is not None and self._window is not None:
            self._pygame.display.quit()
        self._pygame = self._static = self._canvas = self._status_font = None
        self._window = self._clock = None
        self._body_labels = []

    # ----------------------------------------------------------------------------------------- drawing

    def _check(self, frame: RenderFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
        return positions, headings, forces

    def _start(self) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame

        self._pygame = pygame
        pygame.font.init()  # works without a display
        width = self.size_px[0]
        self._status_font = pygame.font.Font(None, max(14, width // 24))
        label_font = pygame.font.Font(None, max(12, width // 28))
        self._body_labels = [label_font.render(b.name, True, TEXT) for b in self.scenario.bodies]
        self._static = self._draw_static(label_font)
        self._canvas = pygame.Surface(self.size_px)
        if self.render_mode == "human":
            prepare_display()
            pygame.display.init()
            self._window = pygame.display.set_mode(self.size_px)
            pygame.display.set_caption(f"impact_env: {self.scenario.name}")
            self._clock = pygame.time.Clock()

    def _polygon_px(self, vertices: np.ndarray) -> list[tuple[float, float]]:
        return [self.world_to_px(x, y) for x, y in vertices]

    def _draw_static(self, font: Any) -> Any:
        pygame = self._pygame
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
