"""pygame-ce renderer of a tether episode: station, anchors, line-of-sight fan, tethers and cargo.

The conventions of :mod:`impact_env.rendering` (metres square, y up, a text band above the world, no pygame state
until the first frame, ``rgb_array`` off-screen without ``pygame.display``, ``human`` in a window capped at
``fps``). Picture:

- the station's interior (light) and walls (dark), the goal box (translucent green);
- anchors as small dots, filled when in line of sight of the cargo centre;
- the line-of-sight fan: a thin line from the cargo centre to every visible anchor;
- tethers: a thick line from the cargo to each held anchor, solid while pulling, light while attaching;
- the cargo as an orange disc of its radius;
- the line ``t = 12 s  rho = 0.412 m  kinematic`` in the band above.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from impact_env.rendering import BACKGROUND, BODY_EDGE, HEADER_PX, MARGIN_PX, OBJECT, REGION, REGION_EDGE, TEXT

if TYPE_CHECKING:
    from impact_env.envs.tether_core import TetherCore
    from impact_env.station import Station

RENDER_MODES = ("human", "rgb_array")
INTERIOR = (226, 230, 236)
WALL = (40, 40, 40)
ANCHOR = (90, 90, 90)
ANCHOR_VISIBLE = (20, 120, 200)
FAN = (150, 190, 225)
TETHER = (200, 0, 160)
TETHER_ATTACHING = (230, 160, 215)


@dataclass
class TetherFrame:
    """What one picture shows."""

    time_s: float
    robustness: float
    cargo_m: tuple[float, float]
    tethers: Sequence[tuple[int, bool]]  # (anchor index, pulling) of each held tether
    line_of_sight: Sequence[bool]  # per anchor
    label: str = ""


def frame_of(core: TetherCore) -> TetherFrame:
    """The frame of a tether environment's current state."""
    world = core.world
    tethers = [(world.tether_anchor(r), world.is_pulling(r)) for r in range(core.n_robots)
               if world.tether_anchor(r) is not None]
    return TetherFrame(time_s=core.time_s, robustness=core.robustness, cargo_m=world.position_m, tethers=tethers,
                       line_of_sight=core.line_of_sight_mask().tolist(), label=core.fidelity)


class TetherRenderer:
    """Draws :class:`TetherFrame` s of one station, in a window (``human``) or to an array (``rgb_array``)."""

    def __init__(self, station: Station, render_mode: str, width_px: int = 600, fps: int = 10) -> None:
        if render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be one of {RENDER_MODES}, got {render_mode!r}")
        if int(width_px) != width_px or width_px < 2 * MARGIN_PX + 40:
            raise ValueError(f"width_px must be an integer >= {2 * MARGIN_PX + 40}, got {width_px!r}")
        if not fps > 0:
            raise ValueError(f"fps must be > 0, got {fps!r}")
        self.station = station
        self.render_mode = render_mode
        self.fps = fps
        xmin, xmax, ymin, ymax = station.bounds
        self.scale_px_per_m = (int(width_px) - 2 * MARGIN_PX) / (xmax - xmin)
        self.size_px = (int(width_px), HEADER_PX + round((ymax - ymin) * self.scale_px_per_m) + MARGIN_PX)
        self._pygame: Any = None
        self._static: Any = None
        self._canvas: Any = None
        self._font: Any = None
        self._window: Any = None
        self._clock: Any = None

    def world_to_px(self, x_m: float, y_m: float) -> tuple[float, float]:
        """World point (m) -> pixel (column, row), row 0 at the top."""
        xmin, _, _, ymax = self.station.bounds
        return (MARGIN_PX + (x_m - xmin) * self.scale_px_per_m, HEADER_PX + (ymax - y_m) * self.scale_px_per_m)

    def render(self, frame: TetherFrame) -> np.ndarray | None:
        """Draw ``frame``. Returns a uint8 (H, W, 3) image in ``rgb_array`` mode, None in ``human`` mode."""
        n = self.station.n_anchors
        if len(frame.line_of_sight) != n:
            raise ValueError(f"TetherFrame.line_of_sight must have one entry per anchor ({n}), "
                             f"got {len(frame.line_of_sight)}")
        for anchor, _ in frame.tethers:
            if not 0 <= anchor < n:
                raise ValueError(f"TetherFrame.tethers names anchor {anchor}; anchors are 0..{n - 1}")
        if self._pygame is None:
            self._start()
        pygame = self._pygame
        canvas = self._canvas
        canvas.blit(self._static, (0, 0))
        cargo = self.world_to_px(*frame.cargo_m)
        anchors = [self.world_to_px(*a.position_m) for a in self.station.anchors]
        for anchor, visible in zip(anchors, frame.line_of_sight):
            if visible:
                pygame.draw.line(canvas, FAN, cargo, anchor, 1)
        for anchor, visible in zip(anchors, frame.line_of_sight):
            pygame.draw.circle(canvas, ANCHOR_VISIBLE if visible else ANCHOR, anchor, 4 if visible else 3)
        for anchor, pulling in frame.tethers:
            pygame.draw.line(canvas, TETHER if pulling else TETHER_ATTACHING, cargo, anchors[anchor], 3)
        radius_px = max(2.0, self.station.cargo.radius_m * self.scale_px_per_m)
        pygame.draw.circle(canvas, OBJECT, cargo, radius_px)
        pygame.draw.circle(canvas, BODY_EDGE, cargo, radius_px, 1)
        status = f"t = {frame.time_s:.0f} s  rho = {frame.robustness:.3f} m  {frame.label}".rstrip()
        text = self._font.render(status, True, TEXT)
        canvas.blit(text, (MARGIN_PX, (HEADER_PX - text.get_height()) // 2))
        if self.render_mode == "rgb_array":
            width, height = self.size_px
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
        self._pygame = self._static = self._canvas = self._font = None
        self._window = self._clock = None

    def _start(self) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame

        self._pygame = pygame
        pygame.font.init()
        self._font = pygame.font.Font(None, max(14, self.size_px[0] // 24))
        surface = pygame.Surface(self.size_px)
        surface.fill(BACKGROUND)
        outline = [self.world_to_px(x, y) for x, y in self.station.polygon]
        pygame.draw.polygon(surface, INTERIOR, outline)
        overlay = pygame.Surface(self.size_px, pygame.SRCALPHA)
        x0, x1, y0, y1 = self.station.goal_box
        goal = [self.world_to_px(x, y) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
        pygame.draw.polygon(overlay, REGION, goal)
        surface.blit(overlay, (0, 0))
        pygame.draw.polygon(surface, REGION_EDGE, goal, 2)
        pygame.draw.polygon(surface, WALL, outline, 3)
        self._static = surface
        self._canvas = pygame.Surface(self.size_px)
        if self.render_mode == "human":
            from impact_env.rendering import prepare_display

            prepare_display()
            pygame.display.init()
            self._window = pygame.display.set_mode(self.size_px)
            pygame.display.set_caption(f"impact_env: station {self.station.name}")
            self._clock = pygame.time.Clock()
