"""The layers of docs/design.md#layout, read from the code's own imports (module level and
inside functions): each package of the core imports only from the layers below it and the
helpers every layer may use; fem/'s sub-packages keep their order; no modules and no rooms
(a package's sub-packages and modules) import each other in a circle."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "granular_material"

#: docs/design.md's layer table: a package imports from lower numbers only
LAYERS = {"dem": 1, "fem": 1, "procedures": 2, "multiscale": 3, "results": 4, "runs": 5,
          "studies": 6, "cli": 7}
#: top-level modules that every layer may import (the input checks import the DEM core and
#: the packing procedure's defaults themselves)
EVERYWHERE = {"checks", "filesafe"}
#: within fem/: the materials and the boundary-value problems import neither each other nor
#: the solver, which imports both
FORBIDDEN = {("fem.materials", "fem.boundary_value"), ("fem.boundary_value", "fem.materials"),
             ("fem.materials", "fem.solver"), ("fem.boundary_value", "fem.solver")}


def _modules() -> dict[str, Path]:
    """Dotted name (without ``granular_material.``) -> file, ``__init__`` as the package."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _target(module: str, name: str | None) -> str:
    """The module an ``import`` names: ``from pkg import sub`` is the sub-module where one
    exists, else the package (a name it re-exports)."""
    if name is not None and f"{module}.{name}" in MODULES:
        return f"{module}.{name}"
    return module


def _imports() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = defaultdict(set)
    for module, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [a.name for a in node.names]
                base = node.module
            elif isinstance(node, ast.Import):
                names, base = [None], None
            else:
                continue
            for alias, name in zip(node.names, names, strict=True):
                dotted = base if base is not None else alias.name
                if dotted != "granular_material" and not dotted.startswith("granular_material."):
                    continue
                target = _target(dotted.removeprefix("granular_material").lstrip("."), name)
                if target and target != module:
                    graph[module].add(target)
    return graph


GRAPH = _imports()


def _room(module: str) -> str:
    """A package's sub-package or module: ``fem.solver.newton`` -> ``fem.solver``."""
    parts = module.split(".")
    return ".".join(parts[:2])


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One circle of ``graph`` (its nodes in order), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        state[node] = 2
        stack.pop()
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_the_graph_is_read() -> None:
    # the reader must see what it checks: the solver imports the materials' protocol
    assert "fem.materials.protocol" in GRAPH["fem.solver.newton"]
    assert "dem.kernels.step" in GRAPH["dem.kernels.sets"]


def test_every_package_imports_only_from_below() -> None:
    wrong = []
    for module, targets in GRAPH.items():
        top = module.split(".")[0]
        if top not in LAYERS:
            continue
        for target in targets:
            other = target.split(".")[0]
            if other == top or other in EVERYWHERE or other not in LAYERS:
                continue
            if LAYERS[other] >= LAYERS[top]:
                wrong.append(f"{module} -> {target}")
    assert not wrong, "imports from a layer that is not below (docs/design.md#layout): " + \
        ", ".join(sorted(wrong))


def test_base_modules_import_no_layer() -> None:
    base = [m for m in MODULES if "." not in m and m and m not in LAYERS
            and m not in EVERYWHERE]
    wrong = [f"{m} -> {t}" for m in base for t in GRAPH.get(m, ())
             if t.split(".")[0] in LAYERS]
    assert base and not wrong, wrong


def test_fem_sub_packages_keep_their_order() -> None:
    wrong = [f"{m} -> {t}" for m, targets in GRAPH.items() for t in targets
             if (_room(m), _room(t)) in FORBIDDEN]
    assert not wrong, wrong


@pytest.mark.parametrize("level", ["modules", "rooms"])
def test_no_import_circle(level: str) -> None:
    if level == "modules":
        graph = GRAPH
    else:
        graph = defaultdict(set)
        for module, targets in GRAPH.items():
            for target in targets:
                # a package's __init__ re-exports what its rooms define: it is no room
                if module.count(".") and target.count(".") and _room(module) != _room(target):
                    graph[_room(module)].add(_room(target))
    assert _cycle(graph) is None, f"an import circle: {' -> '.join(_cycle(graph))}"


def test_no_package_is_a_crowd() -> None:
    # a module of dem/, fem/ or runs/ sits beside at most 12 siblings (modules and
    # sub-packages): a package that outgrows that gets sub-packages by concept
    for package in ("dem", "fem", "runs"):
        entries = [p for p in (ROOT / package).iterdir()
                   if (p.suffix == ".py" and p.stem != "__init__")
                   or (p.is_dir() and (p / "__init__.py").exists())]
        assert len(entries) <= 13, (package, sorted(p.name for p in entries))
