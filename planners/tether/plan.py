"""The tether plan: a sequence of pulls, each one robot reeling the cargo in toward one anchor.

Both tether planners (the exact reachability planner and the thesis's z3 pipeline) write a :class:`TetherPlan`;
the tether expert flies it and the plotter draws it. A pull is a straight segment from its start to its switch
point toward its anchor (Eq. 5 with one active anchor). ``switches`` counts the attachments, as the tether
environment's ``info["switches"]`` does.

Travel time with ``k`` robots (:meth:`TetherPlan.travel_time_s`): the pulls at ``w`` plus the attach time
``t_switch``: with ``k = 1`` the one robot re-attaches at every switch point and the cargo waits ``t_switch``
there each time; with ``k >= 2`` the next robot attaches ``t_switch`` before the switch point while the current
one still pulls, so only the first attachment is waited for. Pulling on several anchors at once can be faster
still; :mod:`~planners.tether.timing` computes that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from impact_env.config_checks import brief
from impact_env.geometry import MAX_COORDINATE_M
from impact_env.tether.station import Station
from planners.errors import PlannerError
from planners.plan import schema
from planners.plan.files import read_plan_json, write_plan_json
from planners.tether.errors import TetherPlanCheckError

FORMAT = "impact_env.tether_plan/2"  # /2 adds the hold schedule; /1 files (none) still load
FORMATS = ("impact_env.tether_plan/1", FORMAT)
MAX_PULLS = 1000  # a plan file with more is refused (the planners need a few; a check costs time per pull)
CHECK_SAMPLES = 200_000  # the most cargo positions TetherPlan.check tests: it coarsens its spacing beyond


@dataclass(frozen=True)
class Pull:
    """One robot pulls the cargo from ``start_m`` to ``end_m`` (m) toward anchor ``anchor`` (its index)."""

    anchor: int
    start_m: tuple[float, float]
    end_m: tuple[float, float]

    @property
    def length_m(self) -> float:
        return math.dist(self.start_m, self.end_m)

    def to_dict(self) -> dict:
        return {"anchor": self.anchor, "start_m": list(self.start_m), "end_m": list(self.end_m)}


@dataclass(frozen=True)
class HoldSchedule:
    """How the last pull ends: the cargo comes to rest at ``stop_m`` (the last pull's end, in the goal box),
    stopped by a held tether toward ``brake_anchor``, an anchor behind the motion (the expert attaches it
    ``t_switch`` ahead, holds it, and holds the pulling tether when the cargo is its braking distance from the
    stop point). ``brake_anchor`` None: no anchor lies behind; the pull's own tether is held at the stop."""

    stop_m: tuple[float, float]
    brake_anchor: int | None

    def to_dict(self) -> dict:
        return {"stop_m": list(self.stop_m), "brake_anchor": self.brake_anchor}


@dataclass
class TetherPlan:
    """Pulls from ``start_m`` into ``goal_box`` (xmin, xmax, ymin, ymax), at pulling speed ``pull_speed_mps``."""

    station: str
    start_m: tuple[float, float]
    goal_box: tuple[float, float, float, float]
    pulls: list[Pull]
    pull_speed_mps: float
    switch_time_s: float
    method: str = ""
    solve_time_s: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)
    hold: HoldSchedule | None = None

    @property
    def switches(self) -> int:
        """Attachments (one per pull), as the environment counts them."""
        return len(self.pulls)

    @property
    def anchors(self) -> list[int]:
        return [p.anchor for p in self.pulls]

    @property
    def path_length_m(self) -> float:
        return float(sum(p.length_m for p in self.pulls))

    @property
    def end_m(self) -> tuple[float, float]:
        return self.pulls[-1].end_m if self.pulls else self.start_m

    def waypoints(self) -> np.ndarray:
        """(n_pulls + 1, 2): the start and every switch point."""
        return np.array([self.start_m] + [p.end_m for p in self.pulls], dtype=float)

    def travel_time_s(self, k: int = 1) -> float:
        """Pulling plus waiting for attachments with ``k`` robots (see the module docstring), s."""
        if k < 1:
            raise PlannerError(f"k must be >= 1, got {k}")
        if not self.pulls:
            return 0.0
        waits = len(self.pulls) if k == 1 else 1
        return self.path_length_m / self.pull_speed_mps + waits * self.switch_time_s

    # --------------------------------------------------------------------------------------- check
    def check(self, station: Station, spacing_m: float = 0.01, tol_m: float = 1e-6) -> None:
        """Sample every pull each ``spacing_m``: the disc inside the station, the anchor in line of sight, the
        motion straight toward the anchor and outside its stop radius, pulls joined end to start, the last end in
        the goal box, and the hold schedule (its brake anchor in sight of the stop point, outside its stop radius,
        behind the motion). Raises :class:`TetherPlanCheckError` listing every violation.

        Bounded in time: at most :data:`CHECK_SAMPLES` positions in all (the spacing grows for a longer plan), each
        test vectorised over a pull's samples, and a plan of more than :data:`MAX_PULLS` pulls is refused.
        """
        bad: list[str] = []
        if station.name != self.station:
            bad.append(f"the plan is for station {self.station!r}, not {station.name!r}")
        if len(self.pulls) > MAX_PULLS:
            raise TetherPlanCheckError([f"the plan has {len(self.pulls)} pulls; at most {MAX_PULLS} are checked"])
        numbers = [*self.start_m] + [v for p in self.pulls for v in (*p.start_m, *p.end_m)]
        if not all(math.isfinite(v) and abs(v) <= MAX_COORDINATE_M for v in numbers):
            raise TetherPlanCheckError([f"the plan has a coordinate that is not a finite number within "
                                        f"+-{MAX_COORDINATE_M:g} m"])
        total = sum(p.length_m for p in self.pulls)
        spacing = max(spacing_m, total / CHECK_SAMPLES)
        x0, x1, y0, y1 = station.goal_box
        here = self.start_m
        for i, p in enumerate(self.pulls):
            if not 0 <= p.anchor < station.n_anchors:
                bad.append(f"pull {i}: anchor {p.anchor} does not exist (0..{station.n_anchors - 1})")
                continue
            if math.dist(here, p.start_m) > tol_m:
                bad.append(f"pull {i} starts at {list(p.start_m)}, {math.dist(here, p.start_m):.3g} m from where the "
                           f"previous one ended")
            a = station.anchor_positions[p.anchor]
            s, e = np.asarray(p.start_m), np.asarray(p.end_m)
            d0, d1 = np.linalg.norm(a - s), np.linalg.norm(a - e)
            side = abs((a[0] - s[0]) * (e[1] - s[1]) - (a[1] - s[1]) * (e[0] - s[0])) / max(d0, 1e-12)
            if side > tol_m or d1 > d0 + tol_m:
                bad.append(f"pull {i} does not move straight toward anchor {p.anchor} ({side:.3g} m off its line)")
            if d1 < station.stop_radius_m - tol_m:
                bad.append(f"pull {i} ends {d1:.3g} m from anchor {p.anchor}, inside its stop radius "
                           f"{station.stop_radius_m} m")
            n = max(2, int(math.ceil(p.length_m / spacing)) + 1)
            xs = s + np.linspace(0.0, 1.0, n)[:, None] * (e - s)
            inside = station.cargo_inside_many(xs, tol_m=tol_m)
            if not inside.all():
                bad.append(f"pull {i}: the cargo disc at {xs[int(np.argmin(inside))].round(4).tolist()} is not inside "
                           "the station")
            else:
                seen = _sees_from(station, xs, p.anchor)
                if not seen.all():
                    bad.append(f"pull {i}: anchor {p.anchor} is not in line of sight from "
                               f"{xs[int(np.argmin(seen))].round(4).tolist()}")
            here = p.end_m
        if not (x0 - tol_m <= here[0] <= x1 + tol_m and y0 - tol_m <= here[1] <= y1 + tol_m):
            bad.append(f"the plan ends at {list(here)}, outside the goal box {list(station.goal_box)}")
        if self.hold is not None:
            bad += self._check_hold(station, self.hold, here, tol_m)
        if bad:
            raise TetherPlanCheckError(bad)

    def _check_hold(self, station: Station, hold: HoldSchedule, here: tuple[float, float], tol_m: float) -> list[str]:
        bad: list[str] = []
        if math.dist(hold.stop_m, here) > tol_m:
            bad.append(f"the hold's stop point {list(hold.stop_m)} is not where the last pull ends ({list(here)})")
        b = hold.brake_anchor
        if b is None:
            return bad
        if not 0 <= b < station.n_anchors:
            return bad + [f"the hold's brake anchor {b} does not exist (0..{station.n_anchors - 1})"]
        stop = np.asarray(hold.stop_m, dtype=float)
        pos = station.anchor_positions[b]
        if not station.line_of_sight(stop, [b])[0]:
            bad.append(f"the hold's brake anchor {b} is not in line of sight from the stop point")
        if float(np.linalg.norm(pos - stop)) <= station.stop_radius_m:
            bad.append(f"the stop point is inside the stop radius of the brake anchor {b}")
        if self.pulls:
            last = self.pulls[-1]
            motion = np.asarray(last.end_m) - np.asarray(last.start_m)
            behind = pos - stop
            if np.linalg.norm(motion) > 0 and float(motion @ behind) >= 0:
                bad.append(f"the hold's brake anchor {b} is not behind the last pull's motion")
        return bad

    # ------------------------------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "station": self.station, "start_m": list(self.start_m),
                "goal_box": list(self.goal_box), "pull_speed_mps": self.pull_speed_mps,
                "switch_time_s": self.switch_time_s, "method": self.method, "solve_time_s": self.solve_time_s,
                "pulls": [p.to_dict() for p in self.pulls], "stats": _jsonable(self.stats),
                "hold": None if self.hold is None else self.hold.to_dict(),
                "summary": {"switches": self.switches, "path_length_m": self.path_length_m,
                            "travel_time_s": {str(k): self.travel_time_s(k) for k in (1, 2, 3)}}}

    def save(self, path: str | Path) -> Path:
        return write_plan_json(path, self.to_dict(), indent=2)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TetherPlan:
        """Build a plan from its JSON form, every field checked (the readers of :mod:`planners.plan.schema`);
        a :class:`PlannerError` lists every missing, unknown or malformed field by its path."""
        if not isinstance(data, dict):
            raise PlannerError(f"not a tether plan: a JSON {type(data).__name__}, expected an object with format "
                               f"{FORMAT!r}")
        if data.get("format") not in FORMATS:
            raise PlannerError(f"not a tether plan: format is {brief(data.get('format'))}, expected {FORMAT!r}")
        problems: list[str] = []
        fields = schema.read(data, _PLAN_FIELDS, "", problems)
        if fields is not schema.INVALID:
            targets = fields["stats"].get("targets")
            if targets is not None and (not isinstance(targets, list) or len(targets) != len(fields["pulls"])
                                        or not all(type(t) is int and t >= 0 for t in targets)):
                problems.append(f"stats.targets must be a list of {len(fields['pulls'])} integers >= 0 (one level "
                                f"per pull), got {brief(targets)}")
        if problems or fields is schema.INVALID:  # INVALID comes with its problems
            raise PlannerError("malformed tether plan:\n  " + "\n  ".join(problems))
        pulls = [Pull(p["anchor"], p["start_m"], p["end_m"]) for p in fields["pulls"]]
        hold = fields["hold"]
        if hold is not None:
            hold = HoldSchedule(stop_m=hold["stop_m"], brake_anchor=hold["brake_anchor"])
        return cls(station=fields["station"], start_m=fields["start_m"], goal_box=fields["goal_box"], pulls=pulls,
                   pull_speed_mps=fields["pull_speed_mps"], switch_time_s=fields["switch_time_s"],
                   method=fields["method"], solve_time_s=fields["solve_time_s"], stats=fields["stats"], hold=hold)

    @classmethod
    def load(cls, path: str | Path) -> TetherPlan:
        """Read a plan file written by :meth:`save`; any problem is a :class:`PlannerError` naming it."""
        return cls.from_dict(read_plan_json(path, PlannerError, what="tether plan"))


def _goal_box(value: Any, where: str, problems: list[str]) -> Any:
    if not isinstance(value, list) or len(value) != 4:
        problems.append(f"{where} must be [xmin, xmax, ymin, ymax] (m), got {brief(value)}")
        return schema.INVALID
    box = [schema.number(v, f"{where}[{i}]", problems, -MAX_COORDINATE_M, MAX_COORDINATE_M)
           for i, v in enumerate(value)]
    if schema.INVALID in box:
        return schema.INVALID
    if not (box[0] <= box[1] and box[2] <= box[3]):
        problems.append(f"{where} = {box} must have xmin <= xmax and ymin <= ymax")
        return schema.INVALID
    return tuple(box)


def _anchor(value: Any, where: str, problems: list[str]) -> Any:
    if type(value) is not int or not 0 <= value <= 10_000:
        problems.append(f"{where} must be an anchor index (an integer >= 0), got {brief(value)}")
        return schema.INVALID
    return value


def _brake_anchor(value: Any, where: str, problems: list[str]) -> Any:
    return None if value is None else _anchor(value, where, problems)


def _positive(value: Any, where: str, problems: list[str]) -> Any:
    x = schema.number(value, where, problems, 0.0)
    if x is not schema.INVALID and x <= 0.0:
        problems.append(f"{where} must be > 0, got {brief(value)}")
        return schema.INVALID
    return x


def _summary(value: Any, where: str, problems: list[str]) -> Any:
    """What :meth:`TetherPlan.to_dict` writes for readers of the file; recomputed from the pulls, never read."""
    return schema.json_data(value, where, problems)


_PULL_FIELDS = {"anchor": schema.Field(_anchor), "start_m": schema.Field(schema.vec2),
                "end_m": schema.Field(schema.vec2)}
_read_pull_list = schema.table_list(_PULL_FIELDS, non_empty=False)


def _pulls(value: Any, where: str, problems: list[str]) -> Any:
    """The pulls, at most :data:`MAX_PULLS` of them (counted before any is read)."""
    if isinstance(value, list) and len(value) > MAX_PULLS:
        problems.append(f"{where}: {len(value)} pulls; at most {MAX_PULLS} are supported")
        return schema.INVALID
    return _read_pull_list(value, where, problems)


_HOLD_FIELDS = {"stop_m": schema.Field(schema.vec2), "brake_anchor": schema.Field(_brake_anchor)}


def _hold(value: Any, where: str, problems: list[str]) -> Any:
    """The hold schedule (format /2): None, or ``{"stop_m": [x, y], "brake_anchor": index or None}``."""
    return None if value is None else schema.read(value, _HOLD_FIELDS, where, problems)


_PLAN_FIELDS = {
    "format": schema.Field(schema.text),
    "station": schema.Field(schema.text),
    "start_m": schema.Field(schema.vec2),
    "goal_box": schema.Field(_goal_box),
    "pull_speed_mps": schema.Field(_positive),
    "switch_time_s": schema.Field(schema.time_s),
    "method": schema.Field(schema.text, ""),
    "solve_time_s": schema.Field(schema.non_negative, 0.0),
    "pulls": schema.Field(_pulls),
    "stats": schema.Field(schema.stats_object, {}),
    "hold": schema.Field(_hold, None),
    "summary": schema.Field(_summary, None),
}


def _sees_from(station: Station, points: np.ndarray, anchor: int) -> np.ndarray:
    """Whether ``anchor`` is in line of sight from each of (n, 2) points (bool, n), in one shapely call."""
    a = station.anchor_positions[anchor]
    coords = np.stack([np.broadcast_to(a, points.shape), points], axis=1)
    return np.asarray(shapely.covers(station._sight_polygon, shapely.linestrings(coords)), dtype=bool)


def is_tether_plan_file(path: str | Path) -> bool:
    """Whether ``path`` holds a tether plan (the expert's dispatch test)."""
    try:
        data = read_plan_json(path, PlannerError, what="tether plan")
    except PlannerError:
        return False
    return isinstance(data, dict) and data.get("format") in FORMATS


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value
