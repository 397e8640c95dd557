"""The config convention (docs/contributing.md) as a test: every ``*Config`` class (and ``SolverOptions``) of
impact_env, planners and baselines is a frozen dataclass, every field has a docstring under it, and a bad value
of every field raises the layer's typed error naming ``Class.field``.

The classes are found by reading the sources, so a new config that breaks the rule fails here without being
listed; only a config with required fields needs an entry in ``REQUIRED`` (the test says so)."""

from __future__ import annotations

import ast
import dataclasses
import functools
import importlib
import math
import re
import warnings

import numpy as np
import pytest

from impact_env import config_checks
from impact_env.errors import ImpactEnvError
from planners.errors import PlannerError
from tests.paths import ROOT

PACKAGES = ("impact_env", "planners", "baselines")
LAYER_ERRORS = {"impact_env": ImpactEnvError, "planners": PlannerError, "baselines": ImpactEnvError}
REQUIRED = {  # valid values of required fields
    "TrainConfig": {"algo": "ppo", "scenario": "corridor"},
    "RLlibTrainConfig": {"scenario": "corridor"},
    "BCConfig": {"scenario": "corridor"},
    "DAggerConfig": {"scenario": "corridor"},
    "Sb3PpoConfig": {"scenario": "corridor"},
    "FamilyPpoConfig": {"family": "throw_and_catch"},
    "MarlConfig": {"algorithm": "mappo", "task": "corridor"},
    "TaskBCConfig": {"family": "throw_and_catch"},
    "BcRlConfig": {"scenario": "corridor", "policy": "runs/bc_corridor"},
    "ResidualConfig": {"scenario": "corridor"},
}


def _sources() -> list[tuple[str, str]]:
    """(module, source text) of every module of the three layers."""
    out = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            out.append((".".join(path.relative_to(ROOT).with_suffix("").parts), path.read_text(encoding="utf-8")))
    return out


@functools.cache
def _config_nodes() -> dict[tuple[str, str], ast.ClassDef]:
    """(module, class name) -> class node of every class named ``*Config`` or ``*Options``, from the sources
    (importing every module at once is not possible: highspy and CasADi's HiGHS plugin cannot share a process)."""
    found = {}
    for module, text in _sources():
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef) and re.search(r"(Config|Options)$", node.name):
                found[(module, node.name)] = node
    return found


# The same classes found by a scan of the text, which is all that collecting the tests needs (parsing every
# source takes most of a second); test_the_walk_finds_every_config_of_the_three_layers checks they agree.
CLASS_LINE = re.compile(r"^[ \t]*class[ \t]+(\w*(?:Config|Options))\b", re.MULTILINE)
CLASSES = [(module, name) for module, text in _sources() for name in CLASS_LINE.findall(text)]


def _class(module: str, name: str) -> type:
    return getattr(importlib.import_module(module), name)


def _documented_fields(node: ast.ClassDef) -> dict[str, bool]:
    """Each annotated field of the class body -> whether a string (its docstring) follows it directly."""
    out = {}
    for stmt, after in zip(node.body, node.body[1:] + [None]):
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.target.id != "_":
            out[stmt.target.id] = (isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                                   and isinstance(after.value.value, str) and bool(after.value.value.strip()))
    return out


def _example(cls: type):
    missing = [f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING and f.name not in REQUIRED.get(cls.__name__, {})]
    assert not missing, f"{cls.__name__} has required fields {missing}: add valid values to REQUIRED"
    return cls(**REQUIRED.get(cls.__name__, {}))


def _bad_value(field: dataclasses.Field):
    """A value the field's annotation rules out."""
    parts = {p.strip() for p in str(field.type).split("|")}
    if parts & {"int", "float"}:
        return math.nan
    if "bool" in parts:
        return "yes"
    if "str" in parts:
        return 3
    if any(p.startswith("tuple[") for p in parts):
        return ("x",)
    if any(p.startswith("dict[") for p in parts):
        return "not a dict"
    return 3


def test_the_walk_finds_every_config_of_the_three_layers():
    assert sorted(CLASSES) == sorted(_config_nodes())
    names = {name for _, name in CLASSES}
    assert {"EngineConfig", "PlannerConfig", "IRPlannerConfig", "SolverOptions", "MissionConfig", "ExpertConfig",
            "IdentificationConfig", "MPCConfig", "ReachabilityConfig", "SmtConfig", "TrainConfig",
            "RLlibTrainConfig", "BCConfig"} <= names


@pytest.mark.parametrize("module, name", CLASSES, ids=[name for _, name in CLASSES])
def test_a_config_is_a_frozen_dataclass_with_every_field_documented(module, name):
    cls = _class(module, name)
    assert dataclasses.is_dataclass(cls), f"{module}.{name} is not a dataclass"
    assert cls.__dataclass_params__.frozen, f"{module}.{name} is not frozen: @dataclass(frozen=True)"
    documented = {}
    for base in reversed(cls.__mro__):  # a field is documented where it is (re)declared
        if dataclasses.is_dataclass(base):
            base_node = _config_nodes().get((base.__module__, base.__name__))
            documented.update(_documented_fields(base_node) if base_node is not None else {})
    for field in dataclasses.fields(cls):
        assert documented.get(field.name), f"{name}.{field.name} has no docstring line under it"


@pytest.mark.parametrize("module, name", CLASSES, ids=[name for _, name in CLASSES])
def test_a_bad_value_of_every_field_is_the_layers_typed_error_naming_class_and_field(module, name):
    cls = _class(module, name)
    error = LAYER_ERRORS[module.split(".")[0]]
    example = _example(cls)
    for field in dataclasses.fields(cls):
        bad = _bad_value(field)
        with pytest.raises(error) as info:
            dataclasses.replace(example, **{field.name: bad})
        assert f"{name}.{field.name}" in str(info.value), (field.name, str(info.value))
        assert " must be " in str(info.value) and "got" in str(info.value)


def test_a_message_names_the_class_the_field_what_is_allowed_and_the_value():
    from planners.offline.config import PlannerConfig
    from planners.online.mission import MissionConfig

    with pytest.raises(PlannerError, match=r"^MissionConfig\.reach_tolerance_m must be a finite number >= 0, "
                                           r"got -1$"):
        MissionConfig(reach_tolerance_m=-1)
    with pytest.raises(PlannerError, match=r"^PlannerConfig\.intervals must be None \(the scenario's hint, else "
                                           r"10\) or an integer >= 2, got 1\.5$"):
        PlannerConfig(intervals=1.5)


# ------------------------------------------------------------------------------- deprecated keywords
def _warns(make):
    with pytest.warns(DeprecationWarning, match="deprecated and will be removed in 0.4.0"):
        return make()


def test_the_solver_budget_is_declared_once_and_the_old_keywords_still_reach_it():
    from planners.offline.config import IRPlannerConfig, PlannerConfig, SolverOptions
    from planners.online.mission import MissionConfig

    # a planner's warm start is a Plan, from which it makes the solver's warm-start vector
    budget = {f.name for f in dataclasses.fields(SolverOptions)} - {"warm_start"}
    for cls in (PlannerConfig, IRPlannerConfig, MissionConfig):
        assert not budget & {f.name for f in dataclasses.fields(cls)}, cls.__name__
    config = _warns(lambda: PlannerConfig(time_limit_s=5.0, threads=2, seed=3))
    assert config.solver_options == SolverOptions(time_limit_s=5.0, threads=2, seed=3, node_limit=20_000)
    assert _warns(lambda: PlannerConfig(threads=None)).solver_options.threads is None
    assert _warns(lambda: IRPlannerConfig(time_limit_s=None)).solver_options.time_limit_s is None
    assert _warns(lambda: MissionConfig(threads=2)).solver_options == SolverOptions(node_limit=200, time_limit_s=60.0,
                                                                                    threads=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # work by default, a time limit only as a safety net; the impact-robust planner's own node budget
        assert PlannerConfig().solver_options == SolverOptions(time_limit_s=600.0, node_limit=20_000, threads=2)
        assert IRPlannerConfig().solver_options == SolverOptions(time_limit_s=600.0, node_limit=10_000, threads=2)
        replaced = dataclasses.replace(config, intervals=4)
    assert replaced.solver_options == config.solver_options and replaced.intervals == 4


def test_optional_parts_are_their_config_or_none_and_the_old_switches_still_work():
    from planners.expert import ExpertConfig
    from planners.online.identification import IdentificationConfig
    from planners.online.mission import MissionConfig

    paper = ExpertConfig.paper()
    assert paper.identification is None and paper.mission is None
    assert _warns(lambda: ExpertConfig.paper(identification=True)) == ExpertConfig.paper(
        identification=IdentificationConfig())
    assert _warns(lambda: ExpertConfig(identification=False, mission_replanning=False)) == ExpertConfig(
        identification=None, mission=None)
    assert _warns(lambda: ExpertConfig.paper(mission_replanning=True)).mission == MissionConfig()
    own = IdentificationConfig(significance=2)
    assert _warns(lambda: ExpertConfig(identification_config=own)).identification is own
    assert _warns(lambda: ExpertConfig(identification=False, identification_config=own)).identification is None
    with pytest.raises(PlannerError, match="ExpertConfig.mission_replanning must be True or False"):
        _warns(lambda: ExpertConfig(mission_replanning="no"))


def test_the_stacks_are_the_papers_and_what_each_part_adds():
    from planners.expert import STACKS, ExpertConfig, stack_config

    assert STACKS == ("paper", "+id", "+mission", "all")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        configs = {name: stack_config(name) for name in STACKS}
    assert configs["paper"] == ExpertConfig.paper() and configs["all"] == ExpertConfig()
    assert configs["+id"].identification is not None and configs["+id"].mission is None
    assert configs["+mission"].mission is not None and configs["+mission"].identification is None
    assert stack_config("+mission", allow_side_switches=True).mission.allow_side_switches
    assert stack_config("paper", allow_side_switches=True) == configs["paper"]
    with pytest.raises(PlannerError, match="unknown expert stack 'plus'"):
        stack_config("plus")


# ------------------------------------------------------------------------------------ the helpers
@pytest.mark.parametrize("value, finite", [(1, True), (-2.5, True), (np.float32(3), True), (np.int64(4), True),
                                           (True, False), (math.nan, False), (math.inf, False), (10 ** 400, False),
                                           ("1", False), (None, False)])
def test_one_finite_number(value, finite):
    assert config_checks.is_finite_number(value) is finite


def test_the_rule_in_words_and_the_value_cut_short():
    assert config_checks.number_rule(0, low_open=True) == "a finite number > 0"
    assert config_checks.number_rule(0, 1, low_open=True) == "a finite number in (0, 1]"
    assert config_checks.number_rule(1, integer=True) == "an integer >= 1"
    assert config_checks.number_rule(0, 2**31 - 1, integer=True) == "an integer in [0, 2147483647]"
    assert config_checks.brief("x" * 100) == repr("x" * 100)[:57] + "..."
    assert config_checks.brief(list(range(5))) == "[0, 1, 2, 3, 4]"
    with pytest.raises(ValueError, match=r"^w must be None \(off\) or an integer >= 2, got 1$"):
        config_checks.check_value("w", 1, ValueError, low=2, integer=True, none="off")
    config_checks.check_value("w", None, ValueError, low=2, integer=True, none="off")


@pytest.mark.parametrize("widths, lists, ok", [((64, 64), False, True), ((8,), False, True), ([64, 64], True, True),
                                               ([64, 64], False, False), ((), False, False), ((64, 0), False, False),
                                               ((64, True), False, False), ((64, 2.0), False, False),
                                               ("64", True, False), (None, False, False)])
def test_layer_widths(widths, lists, ok):
    net = type("Net", (), {"hidden": widths})()
    if ok:
        config_checks.check_widths(net, "hidden", ValueError, lists=lists)
    else:
        rule = r"^Net\.hidden must be a non-empty tuple of integers >= 1 \(layer widths\)"
        with pytest.raises(ValueError, match=rule):
            config_checks.check_widths(net, "hidden", ValueError, lists=lists)
