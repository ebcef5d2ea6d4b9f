"""No import cycle anywhere in `hrc_drake`, imports inside functions included: a module that
needs another only at call time still depends on it, and a cycle means neither can be read,
tested or moved without the other. Read from the source (ast), nothing is imported."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

PACKAGE = Path(__file__).resolve().parents[1] / "hrc_drake"


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imported(tree: ast.AST, here: str, is_package: bool, modules: set[str]) -> set[str]:
    """The package's modules that `tree` imports, at any depth: `import a.b` counts a.b;
    `from a import b` counts the submodule a.b if there is one, else a (b is a name in it)."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name in modules}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                package = here.split(".") if is_package else here.split(".")[:-1]
                package = package[: len(package) - (node.level - 1)]
                base = ".".join([*package, base] if base else package)
            for alias in node.names:
                if f"{base}.{alias.name}" in modules:
                    found.add(f"{base}.{alias.name}")
                elif base in modules:
                    found.add(base)
    return found


def import_graph() -> nx.DiGraph:
    """Module -> the package's modules it imports."""
    modules = _modules()
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        for other in _imported(tree, name, path.name == "__init__.py", set(modules)):
            if other != name and not name.startswith(f"{other}."):
                graph.add_edge(name, other)
    return graph


def test_the_graph_sees_the_package():
    """The graph is not empty and sees an import made inside a function (the CLI loads the
    cell's commands when they run) and a package's `__init__`."""
    graph = import_graph()
    assert len(graph) > 50 and graph.number_of_edges() > 100
    assert graph.has_edge("hrc_drake.cli.app", "hrc_drake.cli.simulate")
    assert graph.has_edge("hrc_drake.cli", "hrc_drake.cli.app")


def test_no_import_cycle():
    """Every strongly connected part of the import graph is one module."""
    parts = nx.strongly_connected_components(import_graph())
    cycles = sorted(sorted(part) for part in parts if len(part) > 1)
    assert cycles == [], "import cycles (the modules that import one another): " + "; ".join(
        ", ".join(cycle) for cycle in cycles
    )


def _between(graph: nx.DiGraph, room: str, other: str) -> list[tuple[str, str]]:
    return sorted(
        (a, b) for a, b in graph.edges if a.startswith(f"{room}") and b.startswith(f"{other}")
    )


def test_the_controller_and_the_simulated_station_import_nothing_of_each_other():
    """The port boundary: the controller reads only what the station's ports carry (types in
    `hrc_drake.cell.ports`, the person model in `hrc_drake.cell.person`), so it runs against a
    real cell as against the simulator; and the station never asks the controller."""
    graph = import_graph()
    controller, station = "hrc_drake.cell.controller", "hrc_drake.cell.station"
    assert any(n.startswith(f"{controller}.") for n in graph), "no controller room"
    assert any(n.startswith(f"{station}.") for n in graph), "no station room"
    assert _between(graph, controller, station) == []
    assert _between(graph, station, controller) == []
    # Nor through anything they import: the controller's modules reach no station module.
    reached = set().union(*(nx.descendants(graph, n) for n in graph if n.startswith(controller)))
    assert sorted(n for n in reached if n.startswith(station)) == []
