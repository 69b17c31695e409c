"""The package's layers: a module imports only from layers below its own (docs/architecture.md, *Layers*).

Parses every module's imports (function-local ones included, since a lazy import is
still a dependency) and fails when a layer imports one above it, or a sibling on the
same layer. The layers, bottom up, with what each is for:
"""

from __future__ import annotations

import ast
from pathlib import Path

import coassist

LAYERS: tuple[tuple[str, ...], ...] = (
    ("(root)", "errors", "_checks", "_io", "_progress", "_cpu", "interfaces", "config", "spatial", "registry"),  # shared vocabulary and rigid-body math
    ("model", "data", "metrics"),  # the impedance model; trials on disk; metrics
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
    ("config", "_checks"), ("spatial", "_checks"), ("interfaces", "_checks"), ("config", "registry"),
    ("_io", "errors"), ("registry", "errors"),
}  # fmt: skip

#: Imports a layer rule would allow but that are forbidden: the arm worlds and the page share
#: nothing with the point-mass simulator but what sits below all three (scenario, control's
#: presets, runtime's episode assembly), so `sim` is not a hub.
FORBIDDEN: set[tuple[str, str]] = {("robot", "sim"), ("play", "sim")}

RANK = {name: i for i, layer in enumerate(LAYERS) for name in layer}
SRC = Path(coassist.__file__).parent


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
                bad.append(f"{path.relative_to(src.parent)}:{line}: {here} (layer {RANK[here]}) imports {mod} (layer {RANK[there]})")
            elif (here, there) in FORBIDDEN:
                bad.append(f"{path.relative_to(src.parent)}:{line}: {here} imports {mod} (forbidden: {here} must not import {there})")
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
    (src / "control" / "law.py").write_text("def f():\n    from coassist.sim import world\n")
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
    (src / "robot" / "drive.py").write_text("from coassist.sim.world import run_trial\n")
    (src / "play" / "session.py").write_text("def f():\n    from coassist.sim import world\nfrom coassist.scenario import tasks\n")
    bad = layering_violations(src)
    assert len(bad) == 2
    assert "play/session.py:2: play imports coassist.sim (forbidden" in bad[0]
    assert "robot/drive.py:1: robot (layer 6) imports coassist.sim.world (layer 6)" in bad[1]


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
            target = getattr(entry, field).partition(":")[0]
            assert target.startswith("coassist."), f"{module_name}.{table}[{name!r}] names {target}, outside coassist"
            there = _package(tuple(target.split(".")[1:]))
            if RANK[there] > RANK[here] or (RANK[there] == RANK[here] and there != here):
                bad.append(f"{module_name}.{table}[{name!r}]: {here} (layer {RANK[here]}) names {target} (layer {RANK[there]})")
    assert not bad, "entry points against the layering:\n" + "\n".join(bad)
