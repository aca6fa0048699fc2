"""The rooms of the package and what each may import (docs/architecture.md), checked on
the source with `ast`, so a rule broken in a function body fails as surely as one broken
at the top of a file:

- no import circles between modules (a function-local import is an edge too: hiding a
  circle inside a function keeps it a circle);
- the pure rooms (vision, surface, cam) import none of hw, daemon, web or sim;
- the web imports no device code (hw): the web service has no device access;
- nothing outside sim/ and commands/ imports the simulator.

The last tests build small graphs by hand to show that the checker catches each kind
of violation, so a green run means the package obeys the rules, not that the checker
looks away.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "appliance"
PURE = ("vision", "surface", "cam")
FORBIDDEN = {room: ("hw", "daemon", "web", "sim") for room in PURE}
FORBIDDEN["web"] = ("hw", "sim")
MAY_USE_SIM = ("sim", "commands")


# -- building the graph --------------------------------------------------------------------------


def module_name(rel: Path) -> str:
    """appliance/daemon/runner.py -> appliance.daemon.runner; a package's __init__ is the package."""
    parts = ["appliance", *rel.with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(module: str, is_package: bool, tree: ast.AST, modules) -> set[str]:
    """The modules of the package that `module` imports, anywhere in it (relative imports
    resolved). `from X import y` lands in X.y when that is a module, else in X; X itself
    (its __init__ runs) counts too unless it is a package `module` lives in, which Python
    has always loaded first."""
    package = module.split(".") if is_package else module.split(".")[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(resolve(alias.name, modules) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            origin = ".".join(base + ([node.module] if node.module else []))
            for alias in node.names:
                full = f"{origin}.{alias.name}"
                found.add(full if full in modules else resolve(origin, modules))
            if not (module + ".").startswith(origin + "."):
                found.add(resolve(origin, modules))
    return {m for m in found if m and m != module}


def resolve(name: str, modules) -> str | None:
    """The module of the package that an imported name lands in (the longest known prefix)."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in modules:
            return candidate
    return None


def graph_of(sources: dict[str, tuple[bool, str]]) -> dict[str, set[str]]:
    """{module: (is_package, source)} -> {module: modules of the package it imports}."""
    return {
        module: imported_modules(module, is_package, ast.parse(text), sources)
        for module, (is_package, text) in sources.items()
    }


def package_sources() -> dict[str, tuple[bool, str]]:
    return {
        module_name(p.relative_to(PACKAGE)): (p.name == "__init__.py", p.read_text())
        for p in sorted(PACKAGE.rglob("*.py"))
    }


def package_graph() -> dict[str, set[str]]:
    return graph_of(package_sources())


# -- the rules -------------------------------------------------------------------------------------


def room(module: str) -> str:
    """appliance.daemon.runner -> daemon; top-level modules (appliance.process) are their own room."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected group of two or more modules, each as one circle through it."""
    index, low, stack, on_stack, groups = {}, {}, [], set(), []

    def visit(v):  # Tarjan, iterative enough for a package this size
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(group)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_circle_through(graph, set(g)) for g in groups]


def _circle_through(graph, group: set[str]) -> list[str]:
    """One concrete circle inside a strongly connected group, start = end, for the message."""
    start = min(group)
    paths = {start: [start]}
    frontier = [start]
    while frontier:  # breadth first: the shortest way back to start
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & group):
                if w == start:
                    return paths[v] + [start]
                if w not in paths:
                    paths[w] = paths[v] + [w]
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"{group} is not strongly connected")


def room_violations(graph: dict[str, set[str]]) -> list[str]:
    out = []
    for module, targets in sorted(graph.items()):
        here = room(module)
        for target in sorted(targets):
            there = room(target)
            if there in FORBIDDEN.get(here, ()):
                out.append(f"{module} imports {target}: the {here} room may not use {there}")
            elif there == "sim" and here not in MAY_USE_SIM:
                out.append(f"{module} imports {target}: production code never imports the simulator")
    return out


# -- the package obeys them ---------------------------------------------------------------------------


def test_no_module_of_the_package_is_part_of_an_import_circle():
    found = cycles(package_graph())
    assert found == [], "import circles:\n" + "\n".join(" -> ".join(c) for c in found)


def test_every_room_imports_only_what_it_may():
    found = room_violations(package_graph())
    assert found == [], "\n".join(found)


def test_the_graph_sees_the_whole_package():
    graph = package_graph()
    assert "appliance.daemon.service" in graph and "appliance.web.app" in graph and "appliance" in graph
    assert "appliance.daemon.runner" in graph["appliance.daemon.service"]
    assert "appliance.web.auth" in graph["appliance.web.pages"]  # relative, at the top
    assert "appliance.daemon.importing" in graph["appliance.daemon.service"]  # inside a function


# -- the checker catches what it should (small graphs made up for the purpose) ------------------------


def _graph(**files: str) -> dict[str, set[str]]:
    """Made-up modules: keyword a__b__c is appliance/a/b/c.py (c = init: the package a/b)."""
    sources = {}
    for key, text in files.items():
        parts = key.split("__")
        is_package = parts[-1] == "init"
        sources[".".join(["appliance", *(parts[:-1] if is_package else parts)])] = (is_package, text)
    return graph_of(sources)


def test_a_circle_through_function_local_imports_is_found_and_printed():
    graph = _graph(
        daemon__init="",
        daemon__runner="from .levels import plan\n",
        daemon__levels="def f():\n    from . import processing\n",
        daemon__processing="def g():\n    from .runner import Cancelled\n",
        daemon__store="from . import levels\n",
    )
    assert cycles(graph) == [
        [
            "appliance.daemon.levels",
            "appliance.daemon.processing",
            "appliance.daemon.runner",
            "appliance.daemon.levels",
        ]
    ]


def test_two_modules_importing_each_other_by_absolute_and_relative_names_are_a_circle():
    graph = _graph(
        web__init="",
        web__app="import appliance.web.pages\n",
        web__pages="def login():\n    from .app import client_address\n",
    )
    assert cycles(graph) == [["appliance.web.app", "appliance.web.pages", "appliance.web.app"]]


def test_a_graph_without_circles_passes():
    graph = _graph(
        errors="",
        vision__init="",
        vision__types="from ..errors import InkSliceError\n",
        surface__init="",
        surface__fit="from ..vision import types\nfrom ..vision.types import W\n",
    )
    assert cycles(graph) == [] and room_violations(graph) == []


def test_a_pure_room_importing_a_device_the_daemon_the_web_or_the_simulator_is_refused():
    graph = _graph(
        hw__init="",
        hw__usb="",
        daemon__init="",
        daemon__calibration="",
        web__init="",
        web__app="",
        sim__init="",
        sim__render="",
        vision__printboard="def board():\n    from ..daemon.calibration import BOARD\n",
        surface__reference="from appliance.sim.render import render_frame\n",
        cam__jobs="from ..web.app import create_app\n",
        cam__posts="from ..hw.usb import copy_verified\n",
    )
    assert room_violations(graph) == [
        "appliance.cam.jobs imports appliance.web.app: the cam room may not use web",
        "appliance.cam.posts imports appliance.hw.usb: the cam room may not use hw",
        "appliance.surface.reference imports appliance.sim.render: the surface room may not use sim",
        "appliance.vision.printboard imports appliance.daemon.calibration: the vision room may not use daemon",
    ]


def test_the_web_importing_device_code_is_refused():
    graph = _graph(
        hw__init="",
        hw__usb="",
        web__init="",
        web__app="def create_app():\n    from ..hw.usb import UsbExporter\n",
    )
    assert room_violations(graph) == [
        "appliance.web.app imports appliance.hw.usb: the web room may not use hw"
    ]


def test_production_code_importing_the_simulator_is_refused_but_commands_may():
    graph = _graph(
        sim__init="",
        sim__fakes="",
        daemon__init="",
        commands__init="",
        daemon__main="import appliance.sim.fakes\n",
        commands__demo="from ..sim import fakes\n",
        process="from .sim.fakes import SimBench\n",
    )
    assert room_violations(graph) == [
        "appliance.daemon.main imports appliance.sim.fakes: production code never imports the simulator",
        "appliance.process imports appliance.sim.fakes: production code never imports the simulator",
    ]
