"""Optional dependencies, found without importing them.

``pytest.importorskip("stable_baselines3")`` at the top of a test module imports torch while the suite is
being collected (about a second, ray.rllib most of another), for every run, even one that selects none of
those tests. :func:`requires` is a skip mark that only looks the packages up on the path; the tests import
them when they run.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest


def installed(name: str) -> bool:
    """Whether the module ``name`` (dotted names too, e.g. ``ray.rllib``) can be imported, without importing
    it or its parent package."""
    top, _, rest = name.partition(".")
    spec = importlib.util.find_spec(top)
    if spec is None or not rest:
        return spec is not None
    for folder in spec.submodule_search_locations or ():
        path = Path(folder).joinpath(*rest.split("."))
        if (path / "__init__.py").is_file() or path.with_suffix(".py").is_file():
            return True
    return False


def requires(*names: str) -> pytest.MarkDecorator:
    """A mark that skips the test (or, as ``pytestmark``, the module) unless every module in ``names`` is
    installed."""
    missing = [name for name in names if not installed(name)]
    return pytest.mark.skipif(bool(missing), reason=f"needs {', '.join(missing)}, which is not installed")
