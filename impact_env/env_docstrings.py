"""Reads the environments' docstrings: their ``## Section`` blocks and the arguments table.

An environment's class docstring is its documentation page (Gymnasium's classic-control style): sections
headed ``## Description``, ``## Action space``, ... ``## Version history``. The ``## Arguments`` section lists one
bullet per constructor keyword (``* ``name``: what it does``). :func:`arguments` joins those descriptions with
the constructor's signature (type annotation, default), so the table the documentation site shows can never
disagree with the code; the tests check that every keyword is documented and nothing else is.
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass

_BULLET = re.compile(r"^\* ``(\w+)``: ?(.*)$")


@dataclass(frozen=True)
class Argument:
    name: str
    annotation: str  # as written in the signature, e.g. "float | None"
    default: str  # repr of the default, or "required"
    description: str


def sections(cls: type) -> dict[str, str]:
    """``{"Description": "...", "Action space": "...", ...}`` from the class docstring, text dedented."""
    doc = inspect.getdoc(cls) or ""
    out: dict[str, str] = {}
    title = "Summary"
    lines: list[str] = []
    for line in doc.splitlines():
        if line.startswith("## "):
            out[title] = "\n".join(lines).strip()
            title, lines = line[3:].strip(), []
        else:
            lines.append(line)
    out[title] = "\n".join(lines).strip()
    return out


def documented_arguments(cls: type) -> dict[str, str]:
    """Keyword -> description from the ``## Arguments`` bullets (continuation lines joined)."""
    out: dict[str, str] = {}
    current = None
    for line in sections(cls).get("Arguments", "").splitlines():
        match = _BULLET.match(line)
        if match:
            current = match.group(1)
            out[current] = match.group(2).strip()
        elif current is not None and line.startswith("  "):
            out[current] += " " + line.strip()
        else:
            current = None
    return out


def arguments(cls: type) -> list[Argument]:
    """The constructor's keywords in signature order, with their type, default and documented description."""
    described = documented_arguments(cls)
    out = []
    # the class's own constructor, read (not called): mypy's warning is about calling it on an instance
    for name, param in inspect.signature(cls.__init__).parameters.items():  # type: ignore[misc]
        if name == "self" or param.kind in (param.VAR_POSITIONAL, param.VAR_KEYWORD):
            continue
        annotation = param.annotation if isinstance(param.annotation, str) else inspect.formatannotation(
            param.annotation)
        default = "required" if param.default is param.empty else repr(param.default)
        if name in ("scenario", "station") and param.default is None:
            default = "required (set by the scenario ids)"
        out.append(Argument(name, annotation, default, described.get(name, "")))
    return out
