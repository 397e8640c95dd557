"""The import contract (setup.cfg, ``[importlinter]``): the layers impact_env < planners < baselines <
benchmarks (nothing imports a layer above it), the two world families independent of each other, and no
import cycle, checked by import-linter on the source (imports inside functions and under TYPE_CHECKING
count). A second check, with grimp (import-linter's graph), asks for more than import-linter's
``acyclic_siblings``: no cycle between any two modules at all, a package and its own modules included."""

from __future__ import annotations

import configparser
import subprocess
import sys
from pathlib import Path

from tests.paths import ROOT

PACKAGES = ("impact_env", "planners", "baselines", "benchmarks")


def test_the_contracts_are_the_layers_the_independent_worlds_and_no_cycles():
    """The contracts in setup.cfg are these (weakening one fails here, not silently)."""
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg")
    contracts = {name.split(":")[-1]: config[name] for name in config.sections()
                 if name.startswith("importlinter:contract:")}
    assert config["importlinter"]["root_packages"].split() == list(PACKAGES)
    assert set(contracts) == {"layers", "worlds", "acyclic"}
    assert contracts["layers"]["type"] == "layers"
    assert contracts["layers"]["layers"].split() == list(reversed(PACKAGES))  # highest first
    assert contracts["worlds"]["type"] == "independence"
    assert contracts["worlds"]["modules"].split() == ["impact_env.transport", "impact_env.tether"]
    assert contracts["acyclic"]["type"] == "acyclic_siblings"
    assert contracts["acyclic"]["ancestors"].split() == list(PACKAGES)
    for contract in contracts.values():
        assert "ignore_imports" not in contract and "exclude_type_checking_imports" not in contract


def test_lint_imports_keeps_every_contract():
    """``lint-imports`` (import-linter's command, installed beside this Python) from the repository root."""
    command = Path(sys.executable).with_name("lint-imports")
    done = subprocess.run([str(command), "--config", "setup.cfg", "--no-cache", "--no-logo"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr  # the report names each broken contract's imports
    assert "Contracts: 3 kept, 0 broken." in done.stdout


def cycles(edges: dict[str, list[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module of the graph ``module -> imported modules``
    (Tarjan's algorithm, iterative: a deep chain of imports cannot hit the recursion limit)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []
    for root in sorted(edges):
        if root in index:
            continue
        index[root] = low[root] = len(index)
        stack.append(root)
        work = [(root, iter(edges[root]))]
        while work:
            module, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    work.append((child, iter(edges.get(child, ()))))
                elif child in stack:
                    low[module] = min(low[module], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[module])
            if low[module] == index[module]:
                component = []
                while True:
                    member = stack.pop()
                    component.append(member)
                    if member == module:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_the_cycle_finder_finds_cycles():
    assert cycles({"a": ["b"], "b": ["c"], "c": []}) == []
    assert cycles({"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}) == [["a", "b", "c"]]
    assert sorted(cycles({"p": ["p.x"], "p.x": ["p"], "q": ["r"], "r": ["q", "p"]})) == [["p", "p.x"], ["q", "r"]]


def test_no_module_imports_itself_through_others():
    """The module graph of the four packages has no cycle, a package and its own modules included."""
    import grimp

    graph = grimp.build_graph(*PACKAGES, include_external_packages=False)
    edges = {m: sorted(graph.find_modules_directly_imported_by(m)) for m in graph.modules}
    found = cycles(edges)
    details = [[(a, b, graph.get_import_details(importer=a, imported=b)) for a in cycle for b in edges[a]
                if b in cycle] for cycle in found]
    assert not found, details
