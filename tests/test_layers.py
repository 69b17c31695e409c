"""The package's layers: a module imports only from layers below its own (docs/architecture.md, *Layers*).

Parses every module's imports (function-local ones included, since a lazy import is
still a dependency) and fails when a layer imports one above it, or a sibling on the
same layer, and when modules import each other in a circle (inside a package too). The
layers, bottom up, with what each is for:
"""

from __future__ import annotations

import ast
from pathlib import Path

import coassist

LAYERS: tuple[tuple[str, ...], ...] = (
    (
        "(root)",
        "errors",
        "_checks",
        "_io",
        "_progress",
        "_cpu",
        "_render",
        "_rows",
        "interfaces",
        "config",
        "spatial",
        "registry",
    ),  # shared vocabulary and rigid-body math; the reports' HTML templates (_render); the array twins' per-set constants (_rows)
    ("model", "data", "metrics", "analysis"),  # the impedance model; trials on disk; metrics; paired statistics
    ("control",),  # games, baselines, guarded controllers (pure control laws)
    ("intent",),  # the predictor
    ("scenario",),  # what every world runs: tasks, objects, simulated operators and hand, intent sources, seeds
    ("runtime",),  # the control tick and loop, wrench pipeline, safety, one episode assembly for every world
    ("sim", "robot"),  # the worlds: the point-mass simulator; arms in MuJoCo or real (neither imports the other)
    ("experiments", "play"),  # thesis experiments, reports; a person in the loop (the live page)
    ("study",),  # people in the loop, end to end: plans, protocols, the study folder, statistics, reports
    ("cli",),  # the command line
)
#: Imports between packages of the same layer that are allowed.
SIBLINGS_ALLOWED: set[tuple[str, str]] = {
    ("config", "_checks"),
    ("spatial", "_checks"),
    ("interfaces", "_checks"),
    ("config", "registry"),
    ("_io", "errors"),
    ("registry", "errors"),
}

#: Imports a layer rule would allow but that are forbidden: the arm worlds and the page share
#: nothing with the point-mass simulator but what sits below all three (scenario, control's
#: presets, runtime's episode assembly), so `sim` is not a hub.
FORBIDDEN: set[tuple[str, str]] = {("robot", "sim"), ("play", "sim")}

RANK = {name: i for i, layer in enumerate(LAYERS) for name in layer}
SRC = Path(coassist.__file__).parent


#: Import circles between modules known and left alone, each with why. An entry that is no
#: longer a circle fails the test (remove it then), so the list cannot go stale.
KNOWN_CIRCLES: dict[frozenset[str], str] = {
    frozenset(
        {"coassist.experiments.application", "coassist.experiments.source_training"}
    ): "source_training reads application's OBSTACLE; experiments/ is being reworked (issue 36)",
}


def _package(parts: tuple[str, ...]) -> str:
    return parts[0] if parts and parts[0] != "__init__" else "(root)"


def _imports(path: Path, src: Path) -> list[tuple[str, int]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = []
    pkg_parts = path.relative_to(src).with_suffix("").parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:  # relative import: resolve against this module's package
                base = pkg_parts[: len(pkg_parts) - node.level + 1]
                mod = ".".join(("coassist", *base, *(node.module.split(".") if node.module else ())))
            else:
                mod = node.module or ""
            out.append((mod, node.lineno))
        elif isinstance(node, ast.Import):
            out.extend((a.name, node.lineno) for a in node.names)
    return [(m, line) for m, line in out if m == "coassist" or m.startswith("coassist.")]


def layering_violations(src: Path) -> list[str]:
    """Every import under the package folder ``src`` that goes up a layer, sideways, or is :data:`FORBIDDEN`."""
    bad = []
    for path in sorted(src.rglob("*.py")):
        here = _package(path.relative_to(src).with_suffix("").parts)
        for mod, line in _imports(path, src):
            there = _package(tuple(mod.split(".")[1:]))
            if there == here:
                continue
            if RANK[there] > RANK[here] or (RANK[there] == RANK[here] and (here, there) not in SIBLINGS_ALLOWED):
                bad.append(
                    f"{path.relative_to(src.parent)}:{line}: {here} (layer {RANK[here]}) imports {mod} (layer {RANK[there]})"
                )
            elif (here, there) in FORBIDDEN:
                bad.append(
                    f"{path.relative_to(src.parent)}:{line}: {here} imports {mod} (forbidden: {here} must not import {there})"
                )
    return bad


def test_every_package_has_a_layer():
    packages = {_package(p.relative_to(SRC).with_suffix("").parts) for p in SRC.rglob("*.py")}
    assert packages <= set(RANK), f"packages without a layer: {sorted(packages - set(RANK))}"


def test_no_layer_imports_one_above_it():
    bad = layering_violations(SRC)
    assert not bad, "imports against the layering:\n" + "\n".join(bad)


def test_the_checker_catches_upward_lazy_and_sideways_imports(tmp_path):
    # The test above must be able to fail: a package tree with one upward import (lazy,
    # inside a function), one sideways import and one allowed downward import.
    src = tmp_path / "coassist"
    (src / "control").mkdir(parents=True)
    (src / "intent").mkdir()
    (src / "control" / "law.py").write_text("def f():\n    from coassist.sim import trial_runner\n")
    (src / "intent" / "net.py").write_text("from coassist.runtime import tick\nfrom coassist.model import impedance\n")
    bad = layering_violations(src)
    assert len(bad) == 2
    assert "control (layer 2) imports coassist.sim" in bad[0] and "law.py:2" in bad[0]
    assert "intent (layer 3) imports coassist.runtime" in bad[1]


def test_the_checker_forbids_the_arm_worlds_and_the_page_from_importing_the_simulator(tmp_path):
    # robot and sim share a layer (sideways: caught by the rank rule); play sits above sim, so
    # only FORBIDDEN catches it. Both must be reported, lazy or not; scenario stays allowed.
    src = tmp_path / "coassist"
    (src / "robot").mkdir(parents=True)
    (src / "play").mkdir()
    (src / "robot" / "drive.py").write_text("from coassist.sim.trial_runner import run_trial\n")
    (src / "play" / "session.py").write_text(
        "def f():\n    from coassist.sim import trial_runner\nfrom coassist.scenario import tasks\n"
    )
    bad = layering_violations(src)
    assert len(bad) == 2
    assert "play/session.py:2: play imports coassist.sim (forbidden" in bad[0]
    assert "robot/drive.py:1: robot (layer 6) imports coassist.sim.trial_runner (layer 6)" in bad[1]


def _module_name(path: Path, src: Path) -> str:
    parts = path.relative_to(src.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_graph(src: Path) -> dict[str, set[str]]:
    """Module → the modules it imports (function-local imports included; ``from pkg import module``
    names the module), for every module under the package folder ``src``."""
    paths = {_module_name(p, src): p for p in src.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    mod = ".".join((*base, *(node.module.split(".") if node.module else ())))
                else:
                    mod = node.module or ""
                for alias in node.names:  # `from pkg import module` names the module itself
                    targets.add(f"{mod}.{alias.name}" if f"{mod}.{alias.name}" in paths else mod)
            elif isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
        graph[name] = {t for t in targets if t in paths and t != name}
    return graph


def import_closure(graph: dict[str, set[str]], module: str) -> set[str]:
    """Every module ``module`` reaches through its imports (a package's own ``__init__`` being run first
    is not counted: what the module's code depends on, not what Python happens to load)."""
    seen, todo = {module}, [module]
    while todo:
        for nxt in graph.get(todo.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def import_circles(src: Path) -> list[list[str]]:
    """The import circles between the modules under the package folder ``src``: each a sorted list
    of the modules that reach one another through their imports (function-local ones included;
    a package's own ``__init__`` being run first is not counted), found as the strongly
    connected components of the module graph (Tarjan)."""
    graph = module_graph(src)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return circles


def test_no_modules_import_each_other_in_a_circle():
    """Old code: sim.trial_runner <-> sim.array_runner (a lazy import of PointMassWorld) and robot.arms <->
    robot.kinematics (a lazy import of ARMS) besides the known one; now only the known one."""
    circles = {frozenset(c) for c in import_circles(SRC)}
    new = [sorted(c) for c in circles - set(KNOWN_CIRCLES)]
    assert not new, "modules importing each other in a circle:\n" + "\n".join(" <-> ".join(c) for c in new)
    gone = [sorted(c) for c in set(KNOWN_CIRCLES) - circles]
    assert not gone, f"no longer circles, remove them from KNOWN_CIRCLES: {gone}"


def test_the_circle_finder_sees_lazy_and_package_relative_imports(tmp_path):
    # a -> b at the top and b -> a inside a function: a circle; c -> a alone is none; e and f
    # import each other relatively (`from .f import y`, `from . import e`): a second circle.
    src = tmp_path / "coassist"
    (src / "pkg").mkdir(parents=True)
    (src / "__init__.py").write_text("")
    (src / "pkg" / "__init__.py").write_text("")
    (src / "pkg" / "a.py").write_text("from coassist.pkg import b\n")
    (src / "pkg" / "b.py").write_text("def f():\n    from coassist.pkg.a import x\n")
    (src / "pkg" / "c.py").write_text("import coassist.pkg.a\n")
    (src / "pkg" / "e.py").write_text("from .f import y\n")
    (src / "pkg" / "f.py").write_text("from . import e\n")
    assert sorted(import_circles(src)) == [["coassist.pkg.a", "coassist.pkg.b"], ["coassist.pkg.e", "coassist.pkg.f"]]


#: The registries whose entries name what they build by an entry point ("package.module:attribute"),
#: imported at run time where the import checker above cannot see it, and the attribute holding it.
ENTRY_POINT_REGISTRIES = {
    "coassist.robot.worlds": ("WORLDS", "build"),
    "coassist.scenario.intent_registry": ("INTENT_SOURCES", "source"),
}


def test_registry_entry_points_respect_the_layers():
    """An entry point is an import too: each may name a module of its registry's layer or below."""
    import importlib

    bad = []
    for module_name, (table, field) in ENTRY_POINT_REGISTRIES.items():
        here = _package(tuple(module_name.split(".")[1:]))
        for name, entry in getattr(importlib.import_module(module_name), table).items():
            if getattr(entry, field) is None:  # a point-mass world: nothing built through the table
                continue
            target = getattr(entry, field).partition(":")[0]
            assert target.startswith("coassist."), f"{module_name}.{table}[{name!r}] names {target}, outside coassist"
            there = _package(tuple(target.split(".")[1:]))
            if RANK[there] > RANK[here] or (RANK[there] == RANK[here] and there != here):
                bad.append(
                    f"{module_name}.{table}[{name!r}]: {here} (layer {RANK[here]}) names {target} (layer {RANK[there]})"
                )
    assert not bad, "entry points against the layering:\n" + "\n".join(bad)


#: The simulated person: what a source that may run on an arm and claims no model of people's paths
#: (``Told.family`` empty) must not import, directly or through anything it imports.
SIMULATED_PERSON = ("coassist.scenario.operator", "coassist.scenario.detours", "coassist.scenario.populations")


def _arm_sources() -> dict[str, str]:
    """Name → module of every registered intent source a person or an arm may run that claims no model of
    people's paths: named sources not simulation-only, and the folder kinds."""
    import inspect

    from coassist.scenario.intent_registry import INTENT_FOLDERS, INTENT_SOURCES

    for name, kind in INTENT_FOLDERS.items():  # the module a kind declares is the one its loader reads with
        assert kind.module and kind.module in inspect.getsource(kind.load), name
    out = {
        name: entry.source.partition(":")[0]
        for name, entry in INTENT_SOURCES.items()
        if not entry.simulation_only and not entry.told.family
    }
    out.update({f"folder:{name}": kind.module for name, kind in INTENT_FOLDERS.items() if not kind.told.family})
    return out


def test_no_source_an_arm_may_run_imports_the_simulated_person():
    graph = module_graph(SRC)
    sources = _arm_sources()
    assert "folder:person-model" in sources and "present" in sources  # the person model, the safe default
    bad = {
        name: sorted(import_closure(graph, module) & set(SIMULATED_PERSON))
        for name, module in sources.items()
        if import_closure(graph, module) & set(SIMULATED_PERSON)
    }
    assert not bad, f"sources that claim no model of people's paths import the simulated person: {bad}"


def test_the_closure_finds_a_simulated_person_behind_another_module(tmp_path):
    # The test above must be able to fail: a source that reaches the operator through a helper, lazily.
    src = tmp_path / "coassist"
    (src / "scenario").mkdir(parents=True)
    (src / "scenario" / "operator.py").write_text("X = 1\n")
    (src / "scenario" / "helper.py").write_text("def f():\n    from coassist.scenario.operator import X\n")
    (src / "scenario" / "source.py").write_text("from coassist.scenario import helper\n")
    graph = module_graph(src)
    assert "coassist.scenario.operator" in import_closure(graph, "coassist.scenario.source")
