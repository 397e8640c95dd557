""""Did you mean ...?" for names a user types: scenarios, stations, controllers, solvers, options."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def suggestion(word: str, candidates: Iterable[str], cutoff: float = 0.6) -> str:
    """``" (did you mean 'corridor'?)"`` for the closest candidates (case-insensitive), or ``""``."""
    candidates = list(dict.fromkeys(candidates))
    lowered = {c.lower(): c for c in candidates}
    matches = difflib.get_close_matches(word.lower(), list(lowered), n=2, cutoff=cutoff)
    if not matches:
        return ""
    return " (did you mean " + " or ".join(repr(lowered[m]) for m in matches) + "?)"


def shipped_names() -> list[str]:
    """Every shipped scenario and station name: what a CLI ``SCENARIO`` argument may be."""
    from impact_env.scenario import scenario_names
    from impact_env.station import station_names

    return [*scenario_names(), *station_names()]
