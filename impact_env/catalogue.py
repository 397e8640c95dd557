"""The catalogue of shipped task files, and "did you mean ...?" for every name a user types.

Each world family ships its TOML files in a resource folder: impact scenarios in
``impact_env/transport/scenarios/``, tether stations in ``impact_env/tether/stations/``. The catalogue knows
both folders by name only, so a family can ask which family a shipped name belongs to (``"L"`` given to the
scenario loader is a station) without importing the other family.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from importlib import resources

# kind of task file -> the resource package holding its shipped files
SHIPPED = {"scenario": "impact_env.transport.scenarios", "station": "impact_env.tether.stations"}


def suggestion(word: str, candidates: Iterable[str], cutoff: float = 0.6) -> str:
    """``" (did you mean 'corridor'?)"`` for the closest candidates (case-insensitive), or ``""``."""
    candidates = list(dict.fromkeys(candidates))
    lowered = {c.lower(): c for c in candidates}
    matches = difflib.get_close_matches(word.lower(), list(lowered), n=2, cutoff=cutoff)
    if not matches:
        return ""
    return " (did you mean " + " or ".join(repr(lowered[m]) for m in matches) + "?)"


def names_of(kind: str) -> list[str]:
    """The shipped files of one kind (``"scenario"`` or ``"station"``), by name, sorted."""
    files = resources.files(SHIPPED[kind])
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def shipped_text(kind: str, name: str) -> str:
    """The text of the shipped file ``name`` of ``kind`` (a name that :func:`names_of` lists)."""
    return resources.files(SHIPPED[kind]).joinpath(f"{name}.toml").read_text(encoding="utf-8")


def shipped_names() -> list[str]:
    """Every shipped scenario and station name: what a CLI ``SCENARIO`` argument may be."""
    return [name for kind in SHIPPED for name in names_of(kind)]
