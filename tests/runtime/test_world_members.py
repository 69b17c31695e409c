"""Every member the runtime reads of a world is declared: in the ``World`` protocol, or in
``OptionalWorldMembers`` with its default, and docs/architecture.md's "Add a world" recipe names it.

The reads are found in the source's syntax trees, not listed by hand: an attribute of a
``world`` (``world.n_joints``, ``self.world.read()``, ``episode.world.n_joints``) in the
runtime, and every ``getattr`` / ``hasattr`` / ``optional_member`` of a world in the runtime and
the robot package. A new probe of a world without a declaration fails here.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import coassist
from coassist.runtime.world import OPTIONAL_WORLD_MEMBERS, OptionalWorldMembers, World, optional_member

SRC = Path(coassist.__file__).parent
DOCS = SRC.parents[1] / "docs" / "architecture.md"
PROBES = ("getattr", "hasattr", "optional_member")
#: Where the protocols and the helper are defined (its getattr is the one read by name).
DEFINITION = SRC / "runtime" / "world.py"


def _is_world(node: ast.expr) -> bool:
    """``world``, ``x.world`` or ``type(world)``/``type(x.world)``: an expression naming a world."""
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "type" and node.args:
        node = node.args[0]
    return (isinstance(node, ast.Name) and node.id == "world") or (
        isinstance(node, ast.Attribute) and node.attr == "world"
    )


def world_reads(source: str, attributes: bool) -> set[str]:
    """The member names ``source`` reads of a world: probes by name (``getattr(world, "x", …)``,
    ``hasattr``, ``optional_member``) and, where ``attributes``, plain ``world.x`` accesses."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in PROBES
            and len(node.args) >= 2
            and _is_world(node.args[0])
        ):
            name = node.args[1]
            # a name computed at run time (robot.worlds.missing_members walks a protocol's own members)
            # reads nothing undeclared: only a literal name is a probe
            if isinstance(name, ast.Constant) and isinstance(name.value, str):
                names.add(name.value)
        elif attributes and isinstance(node, ast.Attribute) and _is_world(node.value):
            names.add(node.attr)
    return names


def _reads_in(package: str, attributes: bool) -> dict[str, set[str]]:
    return {
        str(path.relative_to(SRC)): world_reads(path.read_text(encoding="utf-8"), attributes)
        for path in sorted((SRC / package).rglob("*.py"))
        if path != DEFINITION
    }


def _members(protocol: type) -> set[str]:
    """A protocol's own declared members: annotated attributes, methods and properties."""
    names = set(getattr(protocol, "__annotations__", {}))
    names |= {n for n, v in vars(protocol).items() if callable(v) or isinstance(v, property)}
    return {n for n in names if not n.startswith("_")}


def _recipe() -> str:
    text = DOCS.read_text(encoding="utf-8")
    start = text.index("### Add a world")
    return text[start : text.index("\n### ", start + 1)]


def test_the_scanner_finds_probes_and_attribute_reads():
    src = (
        "def f(world, self):\n"
        "    getattr(self.world, 'a', None); hasattr(type(world), 'b'); optional_member(world, 'c')\n"
        "    world.d; self.world.e(); getattr(self, 'not_a_world'); other.f\n"
    )
    assert world_reads(src, attributes=True) == {"a", "b", "c", "d", "e"}
    assert world_reads(src, attributes=False) == {"a", "b", "c"}


def test_every_member_the_runtime_reads_of_a_world_is_declared():
    required, optional = _members(World), _members(OptionalWorldMembers)
    reads = _reads_in("runtime", attributes=True)
    for path, names in _reads_in("robot", attributes=False).items():
        reads.setdefault(path, set()).update(names)
    seen = set().union(*reads.values())
    # not vacuous: the loop's and the episode's reads are found
    assert {"read", "apply", "stop", "n_joints", "command_space", "last_overrun", "stop_detail"} <= seen
    assert {"hand_force", "hand_wrench"} <= seen
    undeclared = {
        path: sorted(names - required - optional) for path, names in reads.items() if names - required - optional
    }
    assert not undeclared, f"declare these in runtime.world.World or OptionalWorldMembers: {undeclared}"


def test_optional_members_have_defaults_and_are_read_through_the_helper():
    assert set(OPTIONAL_WORLD_MEMBERS) == _members(OptionalWorldMembers)
    assert not _members(OptionalWorldMembers) & _members(World)
    # outside runtime/world.py nothing probes a world by getattr/hasattr: optional_member does
    for package in ("runtime", "robot"):
        for path in sorted((SRC / package).rglob("*.py")):
            if path == DEFINITION:
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            raw = [
                ast.unparse(n)
                for n in ast.walk(tree)
                if isinstance(n, ast.Call)
                and isinstance(n.func, ast.Name)
                and n.func.id in ("getattr", "hasattr")
                and len(n.args) >= 2
                and _is_world(n.args[0])
                and isinstance(n.args[1], ast.Constant)
            ]
            assert not raw, f"{path.relative_to(SRC)}: read through optional_member: {raw}"


def test_optional_member_reads_the_value_or_the_default_and_refuses_an_undeclared_name():
    class Bare:
        pass

    class Real:
        last_overrun = 0.003
        stop_detail = "protective stop: clear it on the pendant"

        @property
        def hand_wrench(self):
            raise AssertionError("computed")  # a class-level lookup must not compute the property

    assert all(optional_member(Bare(), n) is None for n in OPTIONAL_WORLD_MEMBERS)
    assert optional_member(Real(), "last_overrun") == 0.003
    assert optional_member(Real(), "stop_detail").startswith("protective stop")
    assert isinstance(optional_member(Real, "hand_wrench"), property)
    assert optional_member(Real(), "hand_force") is None
    with pytest.raises(ValueError, match="name must be one of"):
        optional_member(Real(), "joint_temperatures")


def test_the_world_recipe_names_every_member():
    recipe = _recipe()
    for name in sorted(_members(World) | _members(OptionalWorldMembers)):
        assert re.search(rf"\b{name}\b", recipe), f"docs/architecture.md's 'Add a world' does not name {name}"
    assert "OptionalWorldMembers" in recipe and "optional_member" in recipe
