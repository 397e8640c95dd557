"""impact_env/errors.py's promise as a contract: one list of typed errors, every exception class the packages
define is in it, and the fuzzers (tests/fuzz/) accept exactly those as the outcome of a bad input."""

from __future__ import annotations

import ast
from pathlib import Path

from impact_env.errors import TYPED_ERRORS, ImpactEnvError
from planners.errors import PLANNER_ERRORS
from tests.fuzz.invariant import ACCEPTED
from tests.paths import ROOT

ERROR_MODULES = {ROOT / "impact_env" / "errors.py", ROOT / "planners" / "errors.py"}


def exception_classes() -> dict[str, Path]:
    """Every class defined in impact_env/, planners/ and baselines/ whose bases name an error or exception,
    found by reading the source (importing every module at once is not possible: highspy and CasADi's HiGHS
    plugin cannot share a process)."""
    known = {"Exception", "ValueError", "KeyError", "TypeError", "RuntimeError", "ImportError", "OSError",
             "LookupError", "ArithmeticError"} | {c.__name__ for c in TYPED_ERRORS + PLANNER_ERRORS}
    found: dict[str, Path] = {}
    for package in ("impact_env", "planners", "baselines"):
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef):
                    bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
                    if (bases & known or node.name.endswith("Error")) and not internal_signal(node.name, tree):
                        found[node.name] = path
    return found


def internal_signal(name: str, tree: ast.Module) -> bool:
    """A private exception its own module raises and catches (impact_env.stl.compiled's ``_NotCompilable``:
    "fall back to the Python monitor"): control flow inside one module, never what a caller sees."""
    caught = {n.id for h in ast.walk(tree) if isinstance(h, ast.ExceptHandler) and h.type is not None
              for n in ast.walk(h.type) if isinstance(n, ast.Name)}
    return name.startswith("_") and name in caught


def test_every_exception_class_is_defined_in_an_errors_module_and_listed():
    listed = {c.__name__ for c in TYPED_ERRORS + PLANNER_ERRORS}
    for name, path in exception_classes().items():
        assert path in ERROR_MODULES, f"{name} is defined in {path.relative_to(ROOT)}; typed errors live in " \
                                      "impact_env/errors.py or planners/errors.py"
        assert name in listed, f"{name} is not listed in TYPED_ERRORS or PLANNER_ERRORS"


def test_every_listed_error_is_an_impact_env_error_and_the_lists_are_complete():
    for cls in TYPED_ERRORS + PLANNER_ERRORS:
        assert issubclass(cls, ImpactEnvError)
    defined = exception_classes()
    assert {c.__name__ for c in TYPED_ERRORS} == {n for n, p in defined.items() if p.parent.name == "impact_env"}
    assert {c.__name__ for c in PLANNER_ERRORS} == {n for n, p in defined.items() if p.parent.name == "planners"}


def test_the_fuzzers_accept_exactly_the_listed_errors():
    assert set(ACCEPTED) == set(TYPED_ERRORS + PLANNER_ERRORS)


def test_moved_errors_are_still_importable_from_their_old_modules():
    from impact_env.controllers import ControllerError
    from impact_env.errors import ControllerError as C2
    from impact_env.errors import EnvConfigError as E2
    from impact_env.transport.core import EnvConfigError

    assert ControllerError is C2 and EnvConfigError is E2
