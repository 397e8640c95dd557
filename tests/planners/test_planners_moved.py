"""The planners' layout move (0.3.0) keeps what users have working: every old module path imports, with a
DeprecationWarning, as the same module object as its new path; the public names and the controller entry
point are where they were; plan files written before the move load and check, to the same fingerprint; and
the plan noun has no import circle."""

from __future__ import annotations

import ast
import importlib
import importlib.metadata
import sys
import warnings
from pathlib import Path

import pytest

import planners  # noqa: F401  (registers the old paths)
from impact_env import moved_modules
from impact_env.scenario import load_scenario
from tests.paths import ROOT

MOVES = {old: new for old, new in moved_modules.moves().items() if old.startswith("planners.")}
# written by 0.2 (before the move): an SR plan of the learned-baselines benchmark, an IR plan of the
# impact-robust benchmark, and their fingerprints as 0.2 computed them
PLANS_0_2 = {"throw_and_catch_exp__sr_plan.json": "7edbbbdbd915", "throw_and_catch_exp__ir_plan.json": "f30dbbded679"}


def test_the_planners_moves_are_registered():
    assert MOVES == {
        "planners.funnels": "planners.plan.funnels",
        "planners.plan_files": "planners.plan.files",
        "planners.plan_schema": "planners.plan.schema",
        "planners.plotting": "planners.plan.plotting",
        "planners.wrappers": "planners.expert.wrappers",
        "planners.offline.sr_planner": "planners.offline.spatially_robust",
        "planners.offline.ir_planner": "planners.offline.impact_robust",
    }
    for new in MOVES.values():
        assert (ROOT / (new.replace(".", "/") + ".py")).is_file(), new


@pytest.mark.parametrize("old", sorted(MOVES))
def test_an_old_path_imports_with_a_warning_as_the_same_module(old):
    new = importlib.import_module(MOVES[old])
    sys.modules.pop(old, None)  # as in a fresh process
    with pytest.warns(DeprecationWarning, match=f"{old} has moved to {MOVES[old]}; the old path will be removed"):
        module = importlib.import_module(old)
    assert module is new and sys.modules[old] is new


def test_public_names_keep_their_old_paths():
    from planners.expert import Expert, ExpertConfig, make_expert
    from planners.expert.expert import Expert as E2
    from planners.offline.config import IRPlannerConfig, PlannerConfig
    from planners.offline.impact_robust import plan_impact_robust
    from planners.offline.spatially_robust import plan_spatially_robust
    from planners.plan import BodyPlan, ImpactCopies, ObjectFunnel, Plan, PlannedImpact, Segment, types

    with warnings.catch_warnings():  # the warning is the test above's; here, the names
        warnings.simplefilter("ignore", DeprecationWarning)
        from planners.offline.ir_planner import IRPlannerConfig as IR2
        from planners.offline.ir_planner import plan_impact_robust as ir2
        from planners.offline.sr_planner import PlannerConfig as P2
        from planners.offline.sr_planner import plan_spatially_robust as sr2
    assert (ir2, sr2, IR2, P2) == (plan_impact_robust, plan_spatially_robust, IRPlannerConfig, PlannerConfig)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from planners.funnels import ImpactCopies as C2
        from planners.funnels import ObjectFunnel as F2
    assert (C2, F2) == (ImpactCopies, ObjectFunnel) == (types.ImpactCopies, types.ObjectFunnel)
    assert (BodyPlan, PlannedImpact, Segment) == (types.BodyPlan, types.PlannedImpact, types.Segment)
    assert Plan.__module__ == "planners.plan.plan" and E2 is Expert and ExpertConfig.__module__ == E2.__module__
    (entry,) = [e for e in importlib.metadata.entry_points(group="impact_env.controllers") if e.name == "expert"]
    assert entry.load() is make_expert


def test_the_impact_law_is_one_module_every_layer_imports():
    from planners import impact_law
    from planners.offline.milp import impacts
    from planners.online import impact_model

    assert impacts.mass_fractions is impact_law.mass_fractions and impacts.point_mass_law is impact_law.point_mass_law
    assert impact_model.disc_impact is impact_law.disc_impact
    for path in ("planners/plan/funnels.py", "planners/offline/guarantee.py", "planners/online/impact_model.py",
                 "planners/offline/milp/copies.py"):
        text = (ROOT / path).read_text()
        assert "from planners.impact_law import" in text and "milp.impacts import mass_fractions" not in text, path
    vr, vo = impact_law.point_mass_law(impact_law.mass_fractions(2.0, 1.0, 0.5), (1.0, 0.0), (0.0, 0.0))
    assert 2.0 * vr[0] + 1.0 * vo[0] == pytest.approx(2.0)  # momentum
    assert vo[0] - vr[0] == pytest.approx(0.5)  # restitution: separation = e * approach


@pytest.mark.parametrize("name", sorted(PLANS_0_2))
def test_a_plan_file_written_before_the_move_loads_checks_and_flies_the_same(name):
    from planners.plan import Plan

    plan = Plan.load(ROOT / "tests" / "data" / "plans_0.2" / name)
    plan.check(load_scenario(plan.scenario), tol=1e-5)
    assert plan.fingerprint() == PLANS_0_2[name]
    assert plan.planner == name.split("__")[1].split("_")[0]
    assert Plan.from_dict(plan.to_dict()).fingerprint() == PLANS_0_2[name]


def _imports(path: Path) -> set[str]:
    """Every planners module ``path`` imports, at any level (type-checking and function-level imports too)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {name for name in out if name.startswith("planners")}


def test_the_plan_noun_has_no_import_circle():
    """Within planners/plan/, types <- funnels <- checks <- plan, and no module imports the package itself."""
    folder = ROOT / "planners" / "plan"
    modules = {f"planners.plan.{p.stem}": p for p in folder.glob("*.py") if p.stem != "__init__"}
    graph = {m: {d for d in _imports(p) if d in modules} for m, p in modules.items()}
    for m, p in modules.items():  # the package imports all but plotting, so they must not import it back
        assert m == "planners.plan.plotting" or "planners.plan" not in _imports(p), m
    seen: set[str] = set()

    def visit(m: str, path: tuple[str, ...]) -> None:
        assert m not in path, f"import circle: {' -> '.join(path + (m,))}"
        if m in seen:
            return
        for d in graph[m]:
            visit(d, path + (m,))
        seen.add(m)

    for m in graph:
        visit(m, ())
    assert "planners.plan.plan" not in _imports(folder / "funnels.py") | _imports(folder / "checks.py")
