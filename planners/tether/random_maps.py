"""Random orthogonal stations for the planners' test sweeps and benchmarks.

A map is a polyomino grown cell by cell on a grid of ``cell_m`` squares (a random neighbour of the cells so far
is added while the union stays a simple polygon without holes), until its boundary has the requested number of
notches (an orthogonal polygon with ``n`` notches has ``2 n + 4`` vertices). Anchors follow the spacing rule,
the start and the goal are the centres of two random cells, so some maps have no plan (e.g. when the spacing
leaves a dead end without an anchor that pulls out of it): the sweeps check that the planner proves it.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import Polygon, box

from impact_env.tether.station import Station, station_from_dict


def orthogonal_polygon(rng: np.random.Generator, notches: int, cell_m: float = 3.0, max_tries: int = 200
                       ) -> tuple[list[tuple[float, float]], list[tuple[int, int]]]:
    """A random simple orthogonal polygon with exactly ``notches`` notches (CCW vertices) and its grid cells."""
    if notches < 0:
        raise ValueError(f"notches must be >= 0, got {notches}")
    for _ in range(max_tries):
        cells = {(0, 0)}
        poly: Polygon = box(0, 0, cell_m, cell_m)
        for _ in range(40 * (notches + 2)):
            count = (len(poly.exterior.coords) - 1 - 4) // 2
            if count == notches:
                coords = [(float(x), float(y)) for x, y in poly.exterior.coords[:-1]]
                return coords, sorted(cells)
            frontier = sorted({(i + di, j + dj) for i, j in cells for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))}
                              - cells)
            i, j = frontier[rng.integers(len(frontier))]
            cand = shapely.union(poly, box(i * cell_m, j * cell_m, (i + 1) * cell_m, (j + 1) * cell_m))
            cand = shapely.simplify(cand, 0.0)
            if cand.geom_type != "Polygon" or len(cand.interiors) or not cand.is_valid:
                continue
            ring = cand.exterior.coords[:-1]
            if len(set(ring)) != len(ring):  # cells touching at a corner only: not a simple polygon
                continue
            new_count = (len(ring) - 4) // 2
            if new_count > notches:
                continue
            poly, cells = shapely.orient_polygons(cand), cells | {(i, j)}
    raise RuntimeError(f"no orthogonal polygon with {notches} notches after {max_tries} tries")


def random_station(seed: int, notches: int, cell_m: float = 3.0, spacing_m: float = 2.5, k: int = 2,
                   walls: list[int] | None = None) -> Station:
    """A station on a random orthogonal polygon; start and goal at the centres of two different random cells.

    ``walls`` restricts the anchors to those walls (indices into the polygon's counter-clockwise walls): the
    sweeps' infeasible variants put them all on one wall."""
    rng = np.random.default_rng(seed)
    polygon, cells = orthogonal_polygon(rng, notches, cell_m)
    pick = rng.choice(len(cells), size=2, replace=False)
    (si, sj), (gi, gj) = cells[pick[0]], cells[pick[1]]
    name = f"random_{seed}_{notches}" + ("" if walls is None else "_walls_" + "_".join(map(str, walls)))
    data = {
        "name": name, "restitution": 0.2, "tf_s": 600.0,
        "station": {"polygon": [list(p) for p in polygon]},
        "anchors": {"spacing_m": spacing_m} if walls is None else {"spacing_m": spacing_m, "walls": list(walls)},
        "cargo": {"mass_kg": 20.0, "radius_m": 0.3, "start_m": [(si + 0.5) * cell_m, (sj + 0.5) * cell_m]},
        "goal": {"center_m": [(gi + 0.5) * cell_m, (gj + 0.5) * cell_m], "half_size_m": 0.5},
        "robots": {"count": 3, "max_active": k, "pull_speed_mps": 0.1, "winch_force_limit_N": 1.0,
                   "stop_radius_m": 0.6, "switch_time_s": 5.0},
    }
    return station_from_dict(data, source=name)
