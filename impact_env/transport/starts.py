"""Initial-position noise that respects the scenario's placement rules.

With ``initial_position_noise_m = r`` each object starts uniformly within r of its scenario position, as
before, but a draw whose disc would leave the world box, overlap an obstacle or overlap another body (a
robot at its start, or an object already placed) is rejected and drawn again from the same generator, so
the starts stay a deterministic function of the reset seed and a draw that was valid is unchanged. The
accepted starts are uniform over the part of the noise disc that is clear.

A radius so large that almost no draw is clear is refused up front (:func:`check_noise`): fewer than
:data:`MIN_CLEAR_FRACTION` of 1,000 fixed draws clear for some object is an
:class:`~impact_env.errors.EnvConfigError` naming the object and that share.
"""

from __future__ import annotations

import math

import numpy as np

from impact_env.errors import EnvConfigError
from impact_env.transport.scenario import Scenario

MAX_DRAWS = 1000  # per object and reset; with >= 5 % clear, all fail with probability < 1e-22
MIN_CLEAR_FRACTION = 0.05
_CHECK_DRAWS = 1000


def _clear(scenario: Scenario, radius_m: float, x: float, y: float, others: list[tuple[float, float, float]]) -> bool:
    xmin, xmax, ymin, ymax = scenario.world_box
    if not (xmin + radius_m <= x <= xmax - radius_m and ymin + radius_m <= y <= ymax - radius_m):
        return False
    for obstacle in scenario.obstacles:
        if obstacle.polygon.signed_distance_xy(x, y) > -radius_m:
            return False
    return all(math.hypot(x - ox, y - oy) >= radius_m + orad for ox, oy, orad in others)


def _draw(rng: np.random.Generator, noise_m: float, centre: tuple[float, float]) -> tuple[float, float]:
    r = noise_m * math.sqrt(rng.uniform())
    a = rng.uniform(0.0, 2.0 * math.pi)
    return centre[0] + r * math.cos(a), centre[1] + r * math.sin(a)


def check_noise(scenario: Scenario, noise_m: float) -> None:
    """Refuse a noise radius for which fewer than MIN_CLEAR_FRACTION of the starts of some object are clear."""
    if noise_m <= 0:
        return
    rng = np.random.default_rng(0)
    for body in scenario.objects:
        others = [(b.position_m[0], b.position_m[1], b.radius_m) for b in scenario.bodies if b is not body]
        clear = sum(_clear(scenario, body.radius_m, *_draw(rng, noise_m, body.position_m), others)
                    for _ in range(_CHECK_DRAWS))
        if clear < MIN_CLEAR_FRACTION * _CHECK_DRAWS:
            raise EnvConfigError(f"initial_position_noise_m = {noise_m:g} m: only {100 * clear / _CHECK_DRAWS:.1f}% of "
                                 f"the starts within that radius of {body.name} are clear of the world's walls, the "
                                 f"obstacles and the other bodies (at least {100 * MIN_CLEAR_FRACTION:g}% are "
                                 "needed); use a smaller radius")


def draw_starts(scenario: Scenario, noise_m: float, rng: np.random.Generator) -> dict[str, tuple[float, float]]:
    """Object name -> start (m): each drawn within ``noise_m`` of its scenario position and redrawn until clear."""
    placed = [(b.position_m[0], b.position_m[1], b.radius_m) for b in scenario.robots]
    pending = {b.name: b for b in scenario.objects}
    starts: dict[str, tuple[float, float]] = {}
    for body in scenario.objects:
        del pending[body.name]
        # objects not drawn yet are kept clear of at their scenario positions, so a later object's own start
        # is never blocked by an earlier one
        others = placed + [(b.position_m[0], b.position_m[1], b.radius_m) for b in pending.values()]
        for _ in range(MAX_DRAWS):
            x, y = _draw(rng, noise_m, body.position_m)
            if _clear(scenario, body.radius_m, x, y, others):
                break
        else:
            raise EnvConfigError(f"initial_position_noise_m = {noise_m:g} m: no clear start for {body.name} in "
                                 f"{MAX_DRAWS} draws; use a smaller radius")
        starts[body.name] = (x, y)
        placed.append((x, y, body.radius_m))
    return starts
