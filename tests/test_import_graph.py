"""The import graph of the library: one direction of layers, no cycles between files.

Layers, lowest first: geometries <- edem <- fem_reference <- verification <- reports. A module
may import its own layer or a lower one; the command line (edem/cli.py, edem/__main__.py) is the
one place that sees every layer. Imports are read with ``ast`` (at module top and inside
functions alike, :func:`verification.sources.import_graph`), so a lazy import does not hide an
upward dependency.
"""

from __future__ import annotations

from verification.sources import PACKAGES, import_graph

LAYERS = PACKAGES
COMMAND_LINE = {"edem.cli", "edem.__main__"}


def layer(module: str) -> int:
    return LAYERS.index(module.split(".")[0])


def upward_imports(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    return sorted((a, b) for a, targets in graph.items() if a not in COMMAND_LINE for b in targets if layer(b) > layer(a))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_the_parser_sees_known_imports():
    """The checks below are only as good as the graph: it must hold imports we know exist,
    including relative and function-level ones and ``from package import submodule``."""
    graph = import_graph()
    assert "edem.scene" in graph["edem.solver"]  # from edem.scene import Scene, Viscoelastic
    assert "fem_reference.problem" in graph["fem_reference"]  # from .problem import (...)
    assert "verification.campaigns.stance" in graph["verification.campaigns"]  # from pkg import module
    assert "reports.maps" in graph["reports.html"]  # imported inside a function
    assert {"reports", "verification", "fem_reference"} <= {m.split(".")[0] for m in graph["edem.cli"]}


def test_checks_catch_an_upward_import_and_a_cycle():
    graph = {"geometries.a": {"edem.b"}, "edem.b": {"edem.c"}, "edem.c": {"edem.b"}, "edem.cli": {"reports.x"}, "reports.x": set()}
    assert upward_imports(graph) == [("geometries.a", "edem.b")]  # the command line may look up
    assert cycles(graph) == [["edem.b", "edem.c"]]


def test_no_module_imports_a_higher_layer_outside_the_command_line():
    assert upward_imports(import_graph()) == []


def test_no_two_files_import_each_other_even_through_others():
    assert cycles(import_graph()) == []


def reaches(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module ``start`` imports, directly or through others."""
    seen: set[str] = set()
    todo = [start]
    while todo:
        for target in graph.get(todo.pop(), ()):
            if target not in seen:
                seen.add(target)
                todo.append(target)
    return seen


def test_the_fe_reference_and_the_scene_renders_ask_the_scene_what_a_time_point_means():
    """F's placement and the applied loads per time point belong to the scene (edem.scene.Scene):
    the FE reference and the scene renders do not reach the discrete run (edem.solver)."""
    graph = import_graph()
    clients = [m for m in graph if m.split(".")[0] == "fem_reference"] + ["reports.scene_renders"]
    assert {m: reaches(graph, m) & {"edem.solver"} for m in clients} == {m: set() for m in clients}
