"""The public ways to run a trial are the table of docs/architecture.md (*Ways to run a trial*):
each function named there is public in the module named, each module named as its caller uses
it, and every public ``run_*`` / ``drive*`` / ``submit_*`` / ``collect_*`` function of the
packages that run trials (runtime, sim, robot) is in the table, so a new one fails until it
is documented."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import coassist

ROOT = Path(__file__).resolve().parents[1]
SRC = Path(coassist.__file__).parent
#: The packages whose modules run trials (the layers below play, experiments and the CLI).
RUNNING_PACKAGES = ("runtime", "sim", "robot")
RUNNING_NAME = re.compile(r"(run|drive|submit|collect)(_\w+)?")


def _table() -> dict[str, str]:
    """``module.function`` → the row's "who calls it" cell."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    start = text.index("### Ways to run a trial")
    section = text[start : text.index("\n## ", start)]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and re.fullmatch(r"`[\w.]+`", cells[0]):
            rows[cells[0].strip("`")] = cells[2]
    return rows


def _names_used(path: Path) -> set[str]:
    """Every name a module's code reads, imports or reaches as an attribute."""
    used = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Name):
            used.add(node.id)
        elif isinstance(node, ast.Attribute):
            used.add(node.attr)
        elif isinstance(node, ast.ImportFrom):
            used.update(a.name for a in node.names)
    return used


def _module_path(dotted: str) -> Path | None:
    """The source file of ``coassist.<dotted>``, or None where it names no module."""
    base = SRC.joinpath(*dotted.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _defined_running_functions() -> set[str]:
    found = set()
    for package in RUNNING_PACKAGES:
        for path in sorted((SRC / package).rglob("*.py")):
            module = ".".join(path.relative_to(SRC).with_suffix("").parts)
            for node in ast.parse(path.read_text(encoding="utf-8")).body:
                if isinstance(node, ast.FunctionDef) and RUNNING_NAME.fullmatch(node.name):
                    found.add(f"{module}.{node.name}")
    return found


def test_the_table_names_public_functions_of_their_modules():
    rows = _table()
    assert len(rows) >= 10, sorted(rows)
    for qual in rows:
        module_name, name = qual.rsplit(".", 1)
        assert not name.startswith("_"), qual
        module = importlib.import_module(f"coassist.{module_name}")
        function = getattr(module, name, None)
        assert callable(function), f"{qual}: no such function"
        # defined there, not a name re-exported from elsewhere: the table gives each function's home
        assert function.__module__ == f"coassist.{module_name}", (qual, function.__module__)
        assert name in getattr(module, "__all__", [name]), f"{qual}: not in its module's __all__"


def test_each_caller_the_table_names_uses_the_function():
    checked = 0
    for qual, callers in _table().items():
        name = qual.rsplit(".", 1)[1]
        for dotted in re.findall(r"`(?:coassist\.)?([a-z_]+(?:\.[a-z_]+)*)`", callers):
            path = _module_path(dotted)
            if path is None:  # a function or class named beside the module, e.g. (`Episode.run`)
                continue
            assert name in _names_used(path), f"{qual}: {dotted} does not use it"
            checked += 1
    assert checked >= 13, checked


def test_every_public_running_function_is_in_the_table():
    defined = _defined_running_functions()
    # the scan sees the package (run_loop, drive, run_trials, …), so an empty set cannot pass
    assert {"runtime.loop.run_loop", "robot.drive.drive", "sim.trial_runner.run_trials"} <= defined
    missing = defined - set(_table())
    assert not missing, f"public ways to run a trial missing from docs/architecture.md's table: {sorted(missing)}"


def test_the_table_parser_and_the_scan_see_what_they_should(tmp_path):
    """The checks above can fail: a row with a private or re-exported name, and a module whose
    public run_* function the table lacks."""
    assert "runtime.loop.run_loop" in _table()
    assert "runtime.episode" in _table()["runtime.loop.run_loop"]
    assert _module_path("sim.trial_runner") is not None and _module_path("no.such_module") is None
    # `sim` re-exports run_trial from sim.trial_runner: its home is not `sim`
    import coassist.sim

    assert coassist.sim.run_trial.__module__ == "coassist.sim.trial_runner"
    # a module with a public running function, a private one and an unrelated one
    fake = tmp_path / "m.py"
    fake.write_text("def run_x():\n    pass\ndef _run_y():\n    pass\ndef runner():\n    pass\n")
    names = [n.name for n in ast.parse(fake.read_text()).body if isinstance(n, ast.FunctionDef)]
    assert [n for n in names if RUNNING_NAME.fullmatch(n)] == ["run_x"]
