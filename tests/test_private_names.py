"""No module uses another module's private (underscore) names.

A name with a leading underscore is its module's own: another module that imports it
(``from coassist.experiments.ablation_report import _side_text``) or reaches for it through the module
(``spatial._rotation_vector(...)``) depends on what the owner may change at will. A name two
modules share is public in its owner, or lives where both can import it. Private *modules*
(``coassist._io``, ``coassist._checks``: internals shared by the package) are imported freely;
the rule is about the names in a module. Dunder names (``__version__``) are not private.
"""

from __future__ import annotations

import ast
from pathlib import Path

import coassist

SRC = Path(coassist.__file__).parent


def _module_name(path: Path, src: Path) -> str:
    parts = ("coassist", *path.relative_to(src).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(dotted: str, src: Path) -> bool:
    """Whether ``coassist.a.b`` is a module or package of the source tree (not a name in one)."""
    rel = Path(*dotted.split(".")[1:]) if "." in dotted else Path()
    return (src / rel).with_suffix(".py").is_file() or (src / rel / "__init__.py").is_file()


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_uses(path: Path, src: Path) -> list[str]:
    """``file:line: what`` for each use in ``path`` of another coassist module's private name."""
    here = _module_name(path, src)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    where = path.relative_to(src.parent)
    out: list[str] = []
    aliases: dict[str, str] = {}  # local name -> the coassist module it is bound to
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "coassist" and a.asname:
                    aliases[a.asname] = a.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join([*base, *([node.module] if node.module else [])])
            else:
                target = node.module or ""
            if target.split(".")[0] != "coassist":
                continue
            for a in node.names:
                full = f"{target}.{a.name}"
                if _is_module(full, src):  # a module (private ones included): bound as a module
                    aliases[a.asname or a.name] = full
                elif _private(a.name) and target != here:
                    out.append(f"{where}:{node.lineno}: from {target} import {a.name}")
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in aliases
            and _private(node.attr)
            and aliases[node.value.id] != here
            and not _is_module(f"{aliases[node.value.id]}.{node.attr}", src)
        ):
            out.append(f"{where}:{node.lineno}: {aliases[node.value.id]}.{node.attr}")
    return out


def test_no_module_uses_another_modules_private_names():
    found = [use for path in sorted(SRC.rglob("*.py")) for use in private_uses(path, SRC)]
    assert not found, (
        "private names used outside their module (make the name public in its owner, or move it where "
        "both can import it):\n" + "\n".join(found)
    )


def test_the_scan_finds_what_it_should_and_allows_the_rest(tmp_path):
    """On a hand-made package: each kind of private use is found; private modules, dunders and a
    module's own private names are not."""
    src = tmp_path / "coassist"
    (src / "pkg").mkdir(parents=True)
    (src / "__init__.py").write_text("")
    (src / "_io.py").write_text("def atomic(): ...\ndef _temp(): ...\n")
    (src / "pkg" / "__init__.py").write_text("")
    (src / "pkg" / "owner.py").write_text("_SECRET = 1\ndef _helper(): ...\nx = _helper()\n")
    (src / "pkg" / "user.py").write_text(
        "\n".join(
            [
                "from coassist.pkg.owner import _helper",  # 1: found
                "from .owner import _SECRET as S",  # 2: found (relative, renamed)
                "from coassist import _io",  # 3: a private module: allowed
                "import coassist.pkg.owner as own",
                "from coassist.pkg import owner",
                "y = own._helper() + owner._SECRET",  # 6: found twice
                "z = _io.atomic() or _io._temp()",  # 7: _io's private name: found
                "from coassist import __init__ as init_",  # a module: allowed
                "from coassist.pkg.owner import __doc__",  # a dunder: allowed
            ]
        )
        + "\n"
    )
    found = private_uses(src / "pkg" / "user.py", src)
    assert sorted(found) == sorted(
        [
            "coassist/pkg/user.py:1: from coassist.pkg.owner import _helper",
            "coassist/pkg/user.py:2: from coassist.pkg.owner import _SECRET",
            "coassist/pkg/user.py:6: coassist.pkg.owner._helper",
            "coassist/pkg/user.py:6: coassist.pkg.owner._SECRET",
            "coassist/pkg/user.py:7: coassist._io._temp",
        ]
    )
    assert private_uses(src / "pkg" / "owner.py", src) == []  # a module's own private names
