"""Old import paths of the modules that moved in 0.3.0, kept for one release with a ``DeprecationWarning``.

0.3.0 gave each world family its folder (``impact_env/transport/``, ``impact_env/tether/``) and the planners'
plan and expert theirs (``planners/plan/``, ``planners/expert/``). Code, pickles and model files that name an
old path (``impact_env.scenario``, ``planners.offline.sr_planner``) still import: a finder on
``sys.meta_path`` answers for exactly the paths registered with :func:`register`, imports the new module and
files it under the old name too, so both names are the same module object (classes are identical, pickles
written before the move load, ``isinstance`` holds across the two paths).

Why a finder and not a stub file per old module: the stubs would sit in the folders next to the new layout
(28 of them) and hide the architecture the move is meant to show; the finder is one table, and it goes, with
its table, in the next release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
import warnings

REMOVED_IN = "0.4.0"


class _Alias(importlib.abc.Loader):
    """Loads an old path as the module at its new path (the same object)."""

    def __init__(self, new: str) -> None:
        self.new = new
        self._spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        module = importlib.import_module(self.new)
        self._spec = module.__spec__  # the import system overwrites __spec__ with the old name's: put it back
        return module

    def exec_module(self, module: types.ModuleType) -> None:
        module.__spec__ = self._spec


class _MovedFinder(importlib.abc.MetaPathFinder):
    def __init__(self) -> None:
        self.moves: dict[str, str] = {}

    def find_spec(self, fullname: str, path=None, target=None) -> importlib.machinery.ModuleSpec | None:
        new = self.moves.get(fullname)
        if new is None:
            return None
        warnings.warn(f"{fullname} has moved to {new}; the old path will be removed in {REMOVED_IN}",
                      DeprecationWarning, stacklevel=2)  # warnings skips importlib's frames
        return importlib.util.spec_from_loader(fullname, _Alias(new), is_package=False)



_FINDER = _MovedFinder()


def register(moves: dict[str, str]) -> None:
    """Answer for each old module path (key) with the module at its new path (value)."""
    _FINDER.moves.update(moves)
    if _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)


def moves() -> dict[str, str]:
    """Every old path registered so far -> its new path (the CHANGELOG's table of moves)."""
    return dict(_FINDER.moves)
