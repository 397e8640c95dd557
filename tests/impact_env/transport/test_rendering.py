"""Renderer (pygame-ce) and plotting (matplotlib): real pictures at small size, checked pixel by pixel."""

from __future__ import annotations

import os

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import math  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pygame  # noqa: E402
import pytest  # noqa: E402

from impact_env.geometry import ConvexPolygon  # noqa: E402
from impact_env.transport import rendering  # noqa: E402
from impact_env.transport.rendering import FORCE_SCALE_M_PER_N, HEADER_PX, MARGIN_PX, Renderer, RenderFrame  # noqa: E402
from impact_env.transport.scenario import Body, Region, Scenario, load_scenario  # noqa: E402

SHIPPED = ["corridor", "obstacle_avoidance", "throw_and_catch_exp"]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def small_scenario() -> Scenario:
    """A 4 m x 2 m world with one obstacle, one region, one robot and one object (built directly, no TOML)."""
    robot = Body(name="R1", mass_kg=1.0, radius_m=0.2, inertia_kgm2=0.02, position_m=(1.0, 1.0),
                 final_position_m=(0.5, 0.5), thrust_limit_N=(2.8, 2.8), torque_limit_Nm=0.2)
    obj = Body(name="O1", mass_kg=1.0, radius_m=0.2, inertia_kgm2=0.02, position_m=(2.0, 1.0),
               final_position_m=(2.5, 1.5))
    return Scenario(
        name="small", description="", world_box=(0.0, 4.0, 0.0, 2.0),
        obstacles=(Region("wall", ConvexPolygon.from_box(3.5, 4.0, 0.0, 2.0)),),
        regions=(Region("goal", ConvexPolygon.from_box(2.2, 3.0, 1.2, 1.8)),),
        robots=(robot,), objects=(obj,), restitution=0.5, tf_s=10.0, task="F[0,10] in(O1, goal)",
    )


def frame(scenario: Scenario, force=(0.0, 0.0), impacts=()) -> RenderFrame:
    return RenderFrame(time_s=12.34, robustness=0.412, positions=[b.position_m for b in scenario.bodies],
                       headings=[0.0] * len(scenario.bodies), robot_forces_world=[force] * len(scenario.robots),
                       impacts=list(impacts))


def pixel(renderer: Renderer, image: np.ndarray, x_m: float, y_m: float) -> tuple[int, ...]:
    col, row = renderer.world_to_px(x_m, y_m)
    return tuple(int(c) for c in image[int(row), int(col)])


# ------------------------------------------------------------------------------------------------ rendering


def test_rgb_array_shape_and_metres_square() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array", width_px=600)
    image = renderer.render(frame(scenario))
    assert image.dtype == np.uint8 and image.shape == (renderer.size_px[1], 600, 3)
    world_w_px, world_h_px = 600 - 2 * MARGIN_PX, image.shape[0] - HEADER_PX - MARGIN_PX
    assert world_h_px / world_w_px == pytest.approx(2.0 / 4.0, abs=1.0 / world_w_px)
    # y up: the world's top-left corner is near the image's top-left, below the text band
    assert renderer.world_to_px(0.0, 2.0) == pytest.approx((MARGIN_PX, HEADER_PX))
    assert renderer.world_to_px(4.0, 0.0) == pytest.approx((600 - MARGIN_PX, image.shape[0] - MARGIN_PX), abs=1)
    renderer.close()


def test_bodies_have_their_colour_and_background_does_not() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array")
    image = renderer.render(frame(scenario))
    # half a radius behind the heading line (heading 0 points along +x)
    assert pixel(renderer, image, 1.0 - 0.1, 1.0) == rendering.ROBOT
    assert pixel(renderer, image, 2.0 - 0.1, 1.0) == rendering.OBJECT
    for x, y in [(1.0, 0.3), (2.0, 0.3), (0.5, 1.7)]:
        assert pixel(renderer, image, x, y) == rendering.BACKGROUND
    assert pixel(renderer, image, 3.75, 0.3) == rendering.OBSTACLE
    region_px = pixel(renderer, image, 2.9, 1.3)
    assert region_px != rendering.BACKGROUND and region_px[1] > region_px[0]  # translucent green
    renderer.close()


def test_bodies_move_with_the_frame() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array")
    moved = frame(scenario)
    moved.positions = [(1.0, 0.5), (2.0, 1.0)]
    image = renderer.render(moved)
    assert pixel(renderer, image, 0.9, 0.5) == rendering.ROBOT
    assert pixel(renderer, image, 0.9, 1.0) == rendering.BACKGROUND


def test_thrust_arrow_is_drawn_in_the_world_frame() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array")
    still = renderer.render(frame(scenario))
    pushed = renderer.render(frame(scenario, force=(0.0, 2.0)))  # 2 N along +y: a 0.4 m arrow above R1
    assert not np.array_equal(still, pushed)
    assert pixel(renderer, pushed, 1.0, 1.0 + 0.2 + 0.5 * 2.0 * FORCE_SCALE_M_PER_N) == rendering.THRUST
    assert pixel(renderer, pushed, 1.0, 1.0 - 0.4) == rendering.BACKGROUND  # nothing below
    renderer.close()


def test_impact_flash_appears_and_fades_out() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array")
    calm = renderer.render(frame(scenario))
    fresh = renderer.render(frame(scenario, impacts=[(1.5, 0.5, 0.1)]))
    old = renderer.render(frame(scenario, impacts=[(1.5, 0.5, rendering.IMPACT_FLASH_S + 0.01)]))
    assert not np.array_equal(calm, fresh)
    changed = np.any(calm != fresh, axis=2)
    rows, cols = np.nonzero(changed)
    col, row = renderer.world_to_px(1.5, 0.5)
    assert abs(cols.mean() - col) < 2 and abs(rows.mean() - row) < 2  # a ring centred on the impact
    assert np.array_equal(calm, old)
    renderer.close()


def test_status_line_changes_with_time_and_robustness() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array")
    a = renderer.render(frame(scenario))
    later = frame(scenario)
    later.time_s, later.robustness = 99.9, -1.5
    b = renderer.render(later)
    differ = np.nonzero(np.any(a != b, axis=2))[0]
    assert differ.size and differ.max() < HEADER_PX  # only the text band changed


def test_rgb_array_does_not_touch_the_display() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array")
    renderer.render(frame(scenario))
    assert not pygame.display.get_init()
    renderer.close()


def test_frame_of_the_wrong_shape_is_a_clear_error() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "rgb_array")
    bad = frame(scenario)
    bad.positions = [(1.0, 1.0)]
    with pytest.raises(ValueError, match=r"positions must have shape \(2, 2\)"):
        renderer.render(bad)
    bad = frame(scenario)
    bad.robot_forces_world = [(0.0, 0.0), (1.0, 1.0)]
    with pytest.raises(ValueError, match="robot_forces_world"):
        renderer.render(bad)
    with pytest.raises(ValueError, match="render_mode"):
        Renderer(scenario, "rgb")


def test_human_mode_draws_in_a_window_and_returns_none() -> None:
    scenario = small_scenario()
    renderer = Renderer(scenario, "human", width_px=300, fps=1000)
    assert not pygame.display.get_init()  # nothing until the first render()
    assert renderer.render(frame(scenario)) is None
    assert pygame.display.get_init()
    assert pygame.display.get_surface().get_size() == renderer.size_px
    assert renderer.render(frame(scenario, force=(1.0, 0.0))) is None
    renderer.close()
    assert not pygame.display.get_init()


def test_renders_every_shipped_scenario() -> None:
    for name in SHIPPED:
        scenario = load_scenario(name)
        renderer = Renderer(scenario, "rgb_array", width_px=200)
        f = RenderFrame(0.0, 0.0, [b.position_m for b in scenario.bodies], [b.heading_rad for b in scenario.bodies],
                        [(1.0, -1.0)] * len(scenario.robots), [(*scenario.objects[0].position_m, 0.2)])
        image = renderer.render(f)
        assert image.shape == (renderer.size_px[1], 200, 3)
        body = scenario.robots[0]
        assert pixel(renderer, image, body.position_m[0] - 0.5 * body.radius_m * math.cos(body.heading_rad),
                     body.position_m[1] - 0.5 * body.radius_m * math.sin(body.heading_rad)) == rendering.ROBOT
        renderer.close()


# ------------------------------------------------------------------------------------------------- plotting
# (each test imports impact_env.transport.plotting, and with it matplotlib, when it runs: not to collect)


def straight_run(scenario: Scenario, steps: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Every body moves in a straight line from its start to its final position (or stays put)."""
    times = np.linspace(0.0, scenario.tf_s, steps)
    start = np.array([b.position_m for b in scenario.bodies])
    end = np.array([b.final_position_m or b.position_m for b in scenario.bodies])
    s = (times / scenario.tf_s)[:, None, None]
    return times, start + s * (end - start)


def assert_png(path: Path) -> None:
    assert path.is_file() and path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG_MAGIC


def test_draw_scenario_labels_and_legend() -> None:
    from impact_env.transport.plotting import draw_scenario

    scenario = small_scenario()
    ax = draw_scenario(scenario)
    assert ax.get_aspect() == 1.0
    assert "small" in ax.get_title() and "0.5" in ax.get_title() and "10 s" in ax.get_title()
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["robot", "object", "obstacle", "region", "final position"]
    texts = {t.get_text().strip() for t in ax.texts}
    assert {"R1", "O1", "wall", "goal"} <= texts
    assert len(ax.patches) >= 1 + 1 + 1 + 2 + 2 + 1  # box, obstacle, region, 2 discs, 2 finals, 1 arrow


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scenario_figures_are_written(name: str, tmp_path: Path) -> None:
    from impact_env.transport.plotting import plot_run, save_scenario_figure

    scenario = load_scenario(name)
    assert_png(save_scenario_figure(scenario, tmp_path / f"{name}.png"))
    times, positions = straight_run(scenario)
    impacts = [{"time": 0.3 * scenario.tf_s, "a": "R1", "b": "O1", "impulse": 1.2},
               {"time": 0.6 * scenario.tf_s, "a": "O1", "b": "wall", "impulse": 0.4}]
    assert_png(plot_run(scenario, times, positions, impacts, robustness=0.25, path=tmp_path / "run" / name))


def test_plot_run_rejects_wrong_shapes(tmp_path: Path) -> None:
    from impact_env.transport.plotting import plot_run

    scenario = small_scenario()
    times, positions = straight_run(scenario)
    with pytest.raises(ValueError, match=r"positions must have shape \(T, n_bodies, 2\)"):
        plot_run(scenario, times, positions[:, :1], [], 0.0, tmp_path / "a.png")
    with pytest.raises(ValueError, match="positions"):
        plot_run(scenario, times[:-1], positions, [], 0.0, tmp_path / "b.png")
    with pytest.raises(ValueError, match="times_s"):
        plot_run(scenario, times[:, None], positions, [], 0.0, tmp_path / "c.png")
    with pytest.raises(ValueError, match="impulse"):
        plot_run(scenario, times, positions, [{"time": 1.0, "a": "R1", "b": "O1"}], 0.0, tmp_path / "d.png")
    assert not list(tmp_path.iterdir())  # nothing written on error
