"""pygame-ce renderer of a tether episode: station, anchors, line-of-sight fan, tethers and cargo.

On the shared :class:`~impact_env.canvas.Canvas` (metres square, y up, a text band above the world, no pygame
state until the first frame, ``rgb_array`` off-screen without ``pygame.display``, ``human`` in a window capped
at ``fps``). Picture:

- the station's interior (light) and walls (dark), the goal box (translucent green);
- anchors as small dots, filled when in line of sight of the cargo centre;
- the line-of-sight fan: a thin line from the cargo centre to every visible anchor;
- tethers: a thick line from the cargo to each held anchor, solid while pulling, light while attaching;
- the cargo as an orange disc of its radius;
- the line ``t = 12 s  rho = 0.412 m  kinematic`` in the band above.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from impact_env.canvas import (  # noqa: F401 - RENDER_MODES: a name of impact_env.tether.rendering (0.2)
    BACKGROUND,
    BODY_EDGE,
    OBJECT,
    REGION,
    REGION_EDGE,
    RENDER_MODES,
    Canvas,
    Frame,
)

if TYPE_CHECKING:
    from impact_env.tether.core import TetherCore
    from impact_env.tether.station import Station


@dataclass
class TetherFrame(Frame):
    """What one picture shows."""

    cargo_m: tuple[float, float]
    tethers: Sequence[tuple[int, bool]]  # (anchor index, pulling) of each held tether
    line_of_sight: Sequence[bool]  # per anchor
    label: str = ""


def frame_of(core: TetherCore) -> TetherFrame:
    """The frame of a tether environment's current state."""
    world = core.world
    tethers = []
    for r in range(core.n_robots):
        anchor = world.tether_anchor(r)
        if anchor is not None:
            tethers.append((anchor, world.is_pulling(r)))
    return TetherFrame(time_s=core.time_s, robustness=core.robustness, cargo_m=world.position_m, tethers=tethers,
                       line_of_sight=core.line_of_sight_mask().tolist(), label=core.fidelity)


INTERIOR = (226, 230, 236)
WALL = (40, 40, 40)
ANCHOR = (90, 90, 90)
ANCHOR_VISIBLE = (20, 120, 200)
FAN = (150, 190, 225)
TETHER = (200, 0, 160)
TETHER_ATTACHING = (230, 160, 215)


class TetherRenderer(Canvas):
    """Draws :class:`TetherFrame` s of one station, in a window (``human``) or to an array (``rgb_array``)."""

    def __init__(self, station: Station, render_mode: str, width_px: int = 600, fps: int = 10) -> None:
        super().__init__(station.bounds, render_mode, width_px, fps)
        self.station = station

    def _checked(self, frame: TetherFrame) -> TetherFrame:
        n = self.station.n_anchors
        if len(frame.line_of_sight) != n:
            raise ValueError(f"TetherFrame.line_of_sight must have one entry per anchor ({n}), "
                             f"got {len(frame.line_of_sight)}")
        for anchor, _ in frame.tethers:
            if not 0 <= anchor < n:
                raise ValueError(f"TetherFrame.tethers names anchor {anchor}; anchors are 0..{n - 1}")
        return frame

    def _status(self, frame: TetherFrame) -> str:
        return f"t = {frame.time_s:.0f} s  rho = {frame.robustness:.3f} m  {frame.label}".rstrip()

    def _caption(self) -> str:
        return f"impact_env: station {self.station.name}"

    def _draw_frame(self, canvas: Any, frame: TetherFrame) -> None:
        pygame = self._pygame
        cargo = self.world_to_px(*frame.cargo_m)
        anchors = [self.world_to_px(*a.position_m) for a in self.station.anchors]
        for anchor_px, visible in zip(anchors, frame.line_of_sight):
            if visible:
                pygame.draw.line(canvas, FAN, cargo, anchor_px, 1)
        for anchor_px, visible in zip(anchors, frame.line_of_sight):
            pygame.draw.circle(canvas, ANCHOR_VISIBLE if visible else ANCHOR, anchor_px, 4 if visible else 3)
        for anchor, pulling in frame.tethers:
            pygame.draw.line(canvas, TETHER if pulling else TETHER_ATTACHING, cargo, anchors[anchor], 3)
        radius_px = max(2.0, self.station.cargo.radius_m * self.scale_px_per_m)
        pygame.draw.circle(canvas, OBJECT, cargo, radius_px)
        pygame.draw.circle(canvas, BODY_EDGE, cargo, radius_px, 1)

    def _draw_static(self, pygame: Any) -> Any:
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
        return surface
