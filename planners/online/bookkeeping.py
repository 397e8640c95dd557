"""Impact bookkeeping: which planned impacts the environment has reported, and which contacts nobody planned.

The environment reports every contact (``info["impacts"]``: time, the two names, velocities before and
after). A report of a robot and an object within half a grid interval of one of their planned impacts
marks that impact done (the closest one, each at most once). Every other contact (robot-wall,
robot-robot, robot-obstacle, object-wall, a second touch of a planned pair) is counted per pair as an
*unplanned contact*; the expert's report gives these counts, and the safe segments exist to keep them 0.
"""

from __future__ import annotations

from collections import Counter

from planners.plan import PlannedImpact


def pair_key(a: str, b: str) -> str:
    """A pair's name in the report, order-free: ``"R1-wall"``, ``"O1-R2"`` (sorted)."""
    return "-".join(sorted((a, b)))


class ImpactBook:
    """Done planned impacts (indices into ``impacts``) and unplanned contacts per pair.

    Args:
        impacts: the plan's impacts (the list is read, never copied: after a mission replan call
            :meth:`replace`).
        tolerance_s: how far from its planned time a reported contact still counts as that impact.
    """

    def __init__(self, impacts: list[PlannedImpact], tolerance_s: float) -> None:
        self.impacts = impacts
        self.tolerance_s = float(tolerance_s)
        self.done: set[int] = set()
        self.unplanned: Counter[str] = Counter()
        self.observed: list[dict] = []  # every robot-object contact reported, planned or not

    def reset(self) -> None:
        self.done = set()
        self.unplanned = Counter()
        self.observed = []

    def replace(self, impacts: list[PlannedImpact], done: set[int]) -> None:
        """Switch to a new impact list (a spliced plan) with the given impacts already done."""
        self.impacts = impacts
        self.done = set(done)

    def observe(self, events: list[dict], robots: set[str], objects: set[str]) -> list[int]:
        """Record the reported contacts; returns the indices of the planned impacts they completed."""
        completed = []
        for ev in events:
            a, b = ev["a"], ev["b"]
            pair = {a, b}
            robot_object = bool(pair & robots) and bool(pair & objects)
            if robot_object:
                self.observed.append(ev)
            candidates = [(abs(imp.time_s - ev["time"]), k) for k, imp in enumerate(self.impacts)
                          if robot_object and k not in self.done and pair == {imp.robot, imp.object}
                          and abs(imp.time_s - ev["time"]) <= self.tolerance_s]
            if candidates:
                k = min(candidates)[1]
                self.done.add(k)
                completed.append(k)
            else:
                self.unplanned[pair_key(a, b)] += 1
        return completed

    def pending(self, robot: str, t: float, late_grace_s: float) -> list[PlannedImpact]:
        """The robot's impacts not yet observed whose time is later than ``t - late_grace_s``."""
        return [imp for k, imp in enumerate(self.impacts)
                if imp.robot == robot and k not in self.done and imp.time_s > t - late_grace_s]
