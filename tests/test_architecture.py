"""The package-level import graph of ``billiards/`` has no cycle.

Units: every top-level module (``billiards.files``, ``billiards.domain``, ``billiards.render``,
``billiards.evaluation`` ...) and every subpackage (``billiards.physics``, ``billiards.envs``,
``billiards.rl``, ``billiards.search``, ``billiards.rm``, ``billiards.campaign``) is one node;
an edge A -> B means some module of A imports something of B.

Every import statement counts, wherever it is: at module level, inside a function (a lazy
import is still a dependency, only a later one), and under ``if TYPE_CHECKING:`` (a type a
module names is part of its interface; counting it keeps the graph honest for whoever turns it
into a runtime import). ``importlib.import_module("billiards....")`` with a literal absolute
name counts too; the relative lazy imports of ``billiards.envs`` and ``billiards.search``
(``import_module(".x", __name__)``) stay inside their package.

The allowed direction: a unit imports only units of lower layers (:data:`LAYERS`, lowest
first; an import inside one layer is a cycle waiting to happen and is not allowed either)::

    cli -> apps -> web -> campaign -> offline -> bench -> pictures, report, league, exit -> search -> rl
      -> evaluation -> envs -> render, rm, baselines -> domain, app_config -> physics, provenance -> files, device
      -> protocol

``search`` may import ``rl`` (a trained policy as a proposer); ``rl`` never imports ``search``.
``render`` only draws (physics, domain): playing an inning for a picture is ``pictures``'.
``envs`` may import ``render`` (the gymnasium env's frames) and ``rm`` (the reward-model bonus).
``rm`` loads a model without ``rl`` and without Hydra (what a fresh interpreter imports for it:
tests/test_fresh_interpreter.py).
"""

from __future__ import annotations

import ast
import sys
from collections import defaultdict
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "billiards"


def _unit(module: str) -> str:
    """``billiards.search.run`` -> ``billiards.search``; ``billiards.files`` stays."""
    return ".".join(module.split(".")[:2])


def _module_name(path: Path) -> tuple[str, str]:
    """(module, package) of a file under billiards/: the package is what ``from . import``
    means there."""
    parts = path.relative_to(REPO).with_suffix("").parts
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), ".".join(parts[:-1])
    return ".".join(parts), ".".join(parts[:-1])


def _is_subunit(name: str) -> bool:
    """``billiards.<name>`` is a module or subpackage (not a name defined in billiards/__init__)."""
    return (PACKAGE / f"{name}.py").is_file() or (PACKAGE / name / "__init__.py").is_file()


def _imported(node: ast.AST, package: str) -> list[str]:
    """The absolute module names an import node (or a literal ``import_module`` call) reaches."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if isinstance(node, ast.ImportFrom):
        if node.level:
            base = package.split(".")[: len(package.split(".")) - node.level + 1]
            module = ".".join(base + ([node.module] if node.module else []))
        else:
            module = node.module or ""
        if module == "billiards":  # from billiards import domain, render: the submodules
            return [f"billiards.{a.name}" if _is_subunit(a.name) else "billiards" for a in node.names]
        return [module]
    if (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
            and not node.args[0].value.startswith(".")):
        return [node.args[0].value]
    return []


def package_graph() -> dict[str, dict[str, list[str]]]:
    """{unit: {imported unit: ["path:line", ...]}} over every module of billiards/."""
    graph: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for path in sorted(PACKAGE.rglob("*.py")):
        module, package = _module_name(path)
        source = _unit(module)
        graph[source]  # every unit is a node, even one that imports nothing of billiards
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            for target in _imported(node, package):
                if (target == "billiards" or target.startswith("billiards.")) and _unit(target) != source:
                    graph[source][_unit(target)].append(f"{path.relative_to(REPO)}:{node.lineno}")
    return graph


def find_cycle(graph: dict[str, dict[str, list[str]]]) -> list[str] | None:
    """One cycle [a, b, ..., a] of the graph, or None (depth-first search, three colours)."""
    colour: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        colour[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, {})):
            if colour.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in colour and (found := visit(nxt)):
                return found
        stack.pop()
        colour[node] = 2
        return None

    for start in sorted(graph):
        if start not in colour and (found := visit(start)):
            return found
    return None


def describe_cycle(graph, cycle: list[str]) -> str:
    return "\n".join(f"  {a} -> {b}   ({', '.join(graph[a][b])})" for a, b in zip(cycle, cycle[1:]))


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_the_package_import_graph_is_acyclic():
    graph = package_graph()
    assert {"billiards.physics", "billiards.envs", "billiards.rl", "billiards.search", "billiards.render"} <= set(graph)
    assert "billiards.physics" in graph["billiards.envs"]  # the walk sees imports at all
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle between billiards packages:\n" + describe_cycle(graph, cycle)


LAYERS = [  # lowest first; a new top-level module or subpackage takes its place here
    ("billiards.protocol",),  # the protocols' registry: every layer asks it, it imports nothing
    ("billiards", "billiards.files", "billiards.device", "billiards.numerics", "billiards.stats", "billiards.shaping"),
    ("billiards.physics", "billiards.provenance", "billiards.tables"),
    ("billiards.domain", "billiards.app_config", "billiards.compat"),
    ("billiards.render", "billiards.rm", "billiards.baselines"),
    ("billiards.envs",),
    ("billiards.evaluation",),
    ("billiards.rl",),
    ("billiards.search",),
    ("billiards.pictures", "billiards.report", "billiards.league", "billiards.exit"),  # exit: search labels, rl learns
    ("billiards.bench",),
    ("billiards.offline",),  # datasets played by any agent the benchmark adapts
    ("billiards.campaign",),
    ("billiards.web",),  # the viewer: plays agents (bench), leagues and runs, on top of everything
    ("billiards.apps",),  # the Hydra apps (train, search, evaluate, match) the scripts and the console command run
    ("billiards.cli",),  # the console command `sagu`: names the apps and tools by module, imports them when asked
]


def module_graph() -> dict[str, dict[str, list[str]]]:
    """{module: {imported module: ["path:line", ...]}} over every module of billiards/ (a package
    is its ``__init__``; ``from .x import y`` reaches the module ``x.y`` where there is one)."""
    modules = {_module_name(path)[0] for path in PACKAGE.rglob("*.py")}
    graph: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for path in sorted(PACKAGE.rglob("*.py")):
        module, package = _module_name(path)
        graph[module]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            targets = _imported(node, package)
            if isinstance(node, ast.ImportFrom):  # a name of the module, or a submodule of it
                targets = [f"{t}.{a.name}" if f"{t}.{a.name}" in modules else t for t in targets for a in node.names]
            for target in targets:
                if target in modules and target != module:
                    graph[module][target].append(f"{path.relative_to(REPO)}:{node.lineno}")
    return graph


def test_no_import_circle_between_modules():
    """No two files of the package import each other, directly or round a loop, counting imports
    inside functions and under TYPE_CHECKING: a loop held apart only by a late import is a loop."""
    graph = module_graph()
    assert "billiards.physics.core" in graph["billiards.physics.api"]  # the walk sees imports at all
    cycle = find_cycle(graph)
    assert cycle is None, "import circle between billiards modules:\n" + describe_cycle(graph, cycle)


@pytest.mark.slow
def test_every_import_goes_down_the_layers():
    layer = {unit: i for i, units in enumerate(LAYERS) for unit in units}
    graph = package_graph()
    unplaced = sorted(set(graph) - set(layer))
    assert not unplaced, f"place {unplaced} in LAYERS (tests/test_architecture.py)"
    upward = [f"{a} -> {b} ({', '.join(where)})" for a, targets in graph.items() for b, where in targets.items()
              if layer[b] >= layer[a]]
    assert not upward, "imports that do not go down the layers:\n  " + "\n  ".join(upward)


FORBIDDEN = [  # (importer, imported, why)
    ("billiards.render", "billiards.envs", "render only draws; playing an inning is billiards.pictures'"),
    ("billiards.render", "billiards.rl", "render only draws; loading a player is billiards.pictures'"),
    ("billiards.render", "billiards.search", "render only draws; loading a player is billiards.pictures'"),
    ("billiards.rl", "billiards.search", "the policy -> proposer adapter lives in billiards.search"),
    ("billiards.rm", "billiards.rl", "a reward model loads without the trainer"),
    ("billiards.files", "billiards.physics", "files sits below the simulator: the standard library and the protocol registry only"),
]


@pytest.mark.slow
@pytest.mark.parametrize("importer,imported,why", FORBIDDEN, ids=[f"{a}->{b}" for a, b, _ in FORBIDDEN])
def test_forbidden_edges(importer, imported, why):
    where = package_graph()[importer].get(imported)
    assert not where, f"{importer} imports {imported} ({', '.join(where)}): {why}"


def test_the_walk_finds_lazy_type_checking_and_literal_imports(tmp_path, monkeypatch):
    """The graph builder itself: an import inside a function, under TYPE_CHECKING and through
    import_module all make edges, and a two-module loop is reported as a cycle."""
    pkg = tmp_path / "billiards"
    (pkg / "low").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "low" / "__init__.py").write_text("def f():\n    from billiards.high import g\n")
    (pkg / "high.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .low import f\n")
    (pkg / "other.py").write_text("import importlib\nimportlib.import_module('billiards.high')\nfrom billiards import low\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", pkg)
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    graph = package_graph()
    assert graph["billiards.low"]["billiards.high"] == ["billiards/low/__init__.py:2"]
    assert graph["billiards.high"]["billiards.low"] == ["billiards/high.py:3"]
    assert set(graph["billiards.other"]) == {"billiards.high", "billiards.low"}
    assert find_cycle(graph) == ["billiards.high", "billiards.low", "billiards.high"]
    (pkg / "high.py").write_text("")
    assert find_cycle(package_graph()) is None


def test_no_module_gives_one_name_two_top_level_definitions():
    """A second ``def``/``class`` of a name at a module's top level replaces the first for every
    caller, including the functions above it that use it (ruff's F811 sees only a redefinition
    of an unused name): each top-level name of the package and the entry points is defined once."""
    twice = []
    for path in sorted([*(REPO / "billiards").rglob("*.py"), *REPO.glob("*.py")]):
        seen: dict[str, int] = {}
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                if node.name in seen:
                    twice.append(f"{path.relative_to(REPO)}: {node.name} (lines {seen[node.name]} and {node.lineno})")
                seen[node.name] = node.lineno
    assert not twice, twice
