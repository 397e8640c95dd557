"""The pygame-ce canvas both worlds' renderers draw on: frame layout, colours, window and image output.

A :class:`Canvas` maps a world rectangle (metres square, y up) onto an image ``width_px`` wide, with a text band
of ``HEADER_PX`` above the world and ``MARGIN_PX`` around it. It is cheap to build (only arithmetic) and
creates no pygame state until the first :meth:`Canvas.render`, so an environment can build it in ``__init__``
whatever the render mode. ``rgb_array`` draws onto an off-screen ``pygame.Surface`` only and never initialises
``pygame.display``; ``human`` opens a window, pumps events and caps the frame rate at ``fps``. A renderer
(:class:`impact_env.transport.rendering.Renderer`, :class:`impact_env.tether.rendering.TetherRenderer`) draws
the picture that does not change once (``_draw_static``), then each frame over it (``_draw_frame``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

RENDER_MODES = ("human", "rgb_array")
MARGIN_PX = 10  # around the world box (left, right, bottom)
HEADER_PX = 30  # text band above the world box

BACKGROUND = (246, 246, 241)
BORDER = (40, 40, 40)
TEXT = (20, 20, 20)
REGION = (60, 180, 75, 80)  # RGBA: blended over the background
REGION_EDGE = (40, 140, 55)
REGION_TEXT = (20, 100, 35)
ROBOT = (60, 110, 220)
OBJECT = (245, 150, 40)
BODY_EDGE = (30, 30, 30)


@dataclass
class Frame:
    """What every picture shows in its text band; a renderer's frame adds what it draws of the world."""

    time_s: float
    robustness: float  # current STL robustness estimate (m)


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


class Canvas:
    """Draws frames of one world, in a window (``human``) or to an array (``rgb_array``).

    Args:
        bounds: (xmin, xmax, ymin, ymax) of the world rectangle shown (m).
        render_mode: ``"human"`` or ``"rgb_array"``.
        width_px: image width; the height follows from the rectangle's aspect ratio (see :attr:`size_px`).
        fps: frame-rate cap of the ``human`` window (frames per second).
    """

    def __init__(self, bounds: tuple[float, float, float, float], render_mode: str, width_px: int = 600,
                 fps: int = 10) -> None:
        if render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be one of {RENDER_MODES}, got {render_mode!r}")
        if int(width_px) != width_px or width_px < 2 * MARGIN_PX + 40:
            raise ValueError(f"width_px must be an integer >= {2 * MARGIN_PX + 40}, got {width_px!r}")
        if not fps > 0:
            raise ValueError(f"fps must be > 0, got {fps!r}")
        self.render_mode = render_mode
        self.fps = fps
        self._bounds = bounds
        xmin, xmax, ymin, ymax = bounds
        self.scale_px_per_m = (int(width_px) - 2 * MARGIN_PX) / (xmax - xmin)
        self.size_px = (int(width_px), HEADER_PX + round((ymax - ymin) * self.scale_px_per_m) + MARGIN_PX)
        # pygame state, created by the first render()
        self._pygame: Any = None
        self._static: Any = None  # what does not change between frames: drawn once
        self._canvas: Any = None
        self._status_font: Any = None
        self._window: Any = None
        self._clock: Any = None

    def world_to_px(self, x_m: float, y_m: float) -> tuple[float, float]:
        """World point (m) -> pixel (column, row) of the image, row 0 at the top."""
        xmin, _, _, ymax = self._bounds
        return (MARGIN_PX + (x_m - xmin) * self.scale_px_per_m, HEADER_PX + (ymax - y_m) * self.scale_px_per_m)

    # ------------------------------------------------------------------------------ what a renderer adds

    def _checked(self, frame: Any) -> Any:
        """What :meth:`_draw_frame` draws of ``frame``, or ValueError for a frame that does not fit the world."""
        return frame

    def _draw_static(self, pygame: Any) -> Any:
        """The surface of what does not change between frames (called once, by the first render)."""
        raise NotImplementedError

    def _draw_frame(self, canvas: Any, drawn: Any) -> None:
        raise NotImplementedError

    def _status(self, frame: Any) -> str:
        """The line in the text band above the world."""
        raise NotImplementedError

    def _caption(self) -> str:
        """The title of the ``human`` window."""
        raise NotImplementedError

    # ------------------------------------------------------------------------------------------ public

    def render(self, frame: Any) -> np.ndarray | None:
        """Draw ``frame``. Returns a uint8 (H, W, 3) image in ``rgb_array`` mode, None in ``human`` mode."""
        drawn = self._checked(frame)
        if self._pygame is None:
            self._start()
        pygame = self._pygame
        canvas = self._canvas
        canvas.blit(self._static, (0, 0))
        self._draw_frame(canvas, drawn)
        text = self._status_font.render(self._status(frame), True, TEXT)
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

    def _start(self) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame

        self._pygame = pygame
        pygame.font.init()  # works without a display
        self._status_font = pygame.font.Font(None, max(14, self.size_px[0] // 24))
        self._static = self._draw_static(pygame)
        self._canvas = pygame.Surface(self.size_px)
        if self.render_mode == "human":
            prepare_display()
            pygame.display.init()
            self._window = pygame.display.set_mode(self.size_px)
            pygame.display.set_caption(self._caption())
            self._clock = pygame.time.Clock()
