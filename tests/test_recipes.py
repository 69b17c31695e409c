"""The recipes of docs/architecture.md ("Add a world", "Add an intent source") are what the
repository does: the files each names exist, and the one registry entry each shows is in its
registry (compared as a syntax tree: the formatter may wrap the entry over several lines)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _recipe(title: str) -> str:
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    start = text.index(f"### {title}")
    ends = [i for i in (text.find("\n## ", start), text.find("\n### ", start + 1)) if i > 0]
    return text[start : min(ends, default=len(text))]


def _same_entry(line: str, source: str) -> bool:
    """Whether the registry entry ``line`` (``"name": Entry(...),`` as a recipe shows it) is an item
    of a dict literal in ``source``, key and value the same syntax trees."""
    entry = ast.parse("{" + line + "}", mode="eval").body
    assert isinstance(entry, ast.Dict) and len(entry.keys) == 1, line
    want = (ast.dump(entry.keys[0]), ast.dump(entry.values[0]))
    return any(
        (ast.dump(k), ast.dump(v)) == want
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.Dict)
        for k, v in zip(node.keys, node.values)
        if k is not None
    )


def _check(title: str, folder: str, registry: str, entry_class: str) -> str:
    """The recipe's named files exist, the registry is one of them, and its one added entry is in it."""
    recipe = _recipe(title)
    files = re.findall(rf"`(src/coassist/{folder}/[\w/]+\.py)`", recipe)
    assert registry in files, files
    for f in files:
        assert (ROOT / f).is_file(), f
    added = [ln[1:].strip() for ln in recipe.splitlines() if ln.startswith("+") and f"{entry_class}(" in ln]
    assert len(added) == 1, added
    assert _same_entry(added[0], (ROOT / registry).read_text(encoding="utf-8")), added[0]
    return "\n".join(files) + "\n" + added[0]


def test_the_world_recipe_is_what_the_repository_does():
    shown = _check("Add a world", "robot", "src/coassist/robot/worlds.py", "WorldEntry")
    assert "src/coassist/robot/ros2_world.py" in shown and '"ros2": WorldEntry(' in shown


def test_the_intent_source_recipe_is_what_the_repository_does():
    shown = _check("Add an intent source", "scenario", "src/coassist/scenario/intent_registry.py", "IntentSourceEntry")
    assert "src/coassist/scenario/constant_velocity.py" in shown
    assert (
        '"constant-velocity": IntentSourceEntry("coassist.scenario.constant_velocity:ConstantVelocityIntent"' in shown
    )


def test_an_entry_that_differs_is_not_found():
    # the check is not vacuous: another summary, or another class, is a different entry
    source = 'T = {"a": E("m:C", "one"), "b": E("m:D", "two")}'
    assert _same_entry('"a": E("m:C", "one"),', source)
    assert not _same_entry('"a": E("m:C", "another"),', source)
    assert not _same_entry('"b": E("m:C", "two"),', source)
