"""Docstrings match signatures (in the spirit of python-control's ``docstrings_test.py``).

For every public function, method and class of ``coassist`` whose docstring has a
numpydoc ``Parameters`` section, the names it documents must be the signature's
parameters, in the signature's order (``self``/``cls`` aside). The project writes the
section two ways, both understood here::

    Parameters
    ----------
    q : array_like, shape (6,)          # numpydoc: name : type, description indented
        Joint positions, rad.
    dt : the control period [s].        # the project's: name : description
    clock, sleep : the wall clock …     # several names sharing one entry

An entry starts at the section's indentation with ``name[, name …] :`` (a space before
the colon, so prose such as "Note: …" is not taken for one); the section ends at the
next heading (any line underlined with dashes). Docstrings without a Parameters section
are not checked.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
from pathlib import Path

import pytest

import coassist

# Known mismatches left alone, each with why. An entry that no longer mismatches fails
# the test (remove it then), so the list cannot go stale.
ALLOWED_MISMATCHES: dict[str, str] = {}

_PACKAGE_DIR = Path(coassist.__file__).parent
_UNDERLINE = re.compile(r"^-{3,}$")
_ENTRY = re.compile(r"^(\*{0,2}[A-Za-z_]\w*(?:\s*,\s*\*{0,2}[A-Za-z_]\w*)*)\s+:(?:\s|$)")


def _module_names() -> list[str]:
    names = []
    for path in sorted(_PACKAGE_DIR.rglob("*.py")):
        parts = path.relative_to(_PACKAGE_DIR.parent).with_suffix("").parts
        if parts[-1] == "__main__":
            continue  # importing it would run the program
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names.append(".".join(parts))
    return names


MODULES = _module_names()


def documented_parameters(doc: str | None) -> list[str] | None:
    """The names a docstring's Parameters section documents, in order; None without one."""
    if not doc:
        return None
    lines = inspect.cleandoc(doc).splitlines()
    heading = [i for i in range(len(lines) - 1) if lines[i].strip() and _UNDERLINE.match(lines[i + 1].strip())]
    names: list[str] | None = None
    for n, i in enumerate(heading):
        if lines[i].strip() != "Parameters":
            continue
        names = [] if names is None else names
        indent = len(lines[i]) - len(lines[i].lstrip())
        end = heading[n + 1] if n + 1 < len(heading) else len(lines)
        for line in lines[i + 2 : end]:
            text = line.strip()
            if not text or len(line) - len(line.lstrip()) != indent:
                continue  # a description's continuation, or a blank line
            match = _ENTRY.match(text)
            if match:
                names += [name.strip().lstrip("*") for name in match.group(1).split(",")]
    return names


def signature_parameters(obj) -> list[str] | None:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):  # a builtin without a signature
        return None
    return [p.name for p in sig.parameters.values() if p.name not in ("self", "cls")]


def mismatch(obj) -> str | None:
    """Why ``obj``'s Parameters section disagrees with its signature; None if it agrees."""
    documented = documented_parameters(obj.__doc__)
    if documented is None:
        return None
    actual = signature_parameters(obj)
    if actual is None:
        return "has a Parameters section but no signature"
    if documented == actual:
        return None
    undocumented = [p for p in actual if p not in documented]
    unknown = [p for p in documented if p not in actual]
    duplicated = sorted({p for p in documented if documented.count(p) > 1})
    parts = []
    if undocumented:
        parts.append(f"undocumented {undocumented}")
    if unknown:
        parts.append(f"documented but not in the signature {unknown}")
    if duplicated:
        parts.append(f"documented twice {duplicated}")
    if not parts:
        parts.append(f"order: documented {documented}, signature {actual}")
    return "; ".join(parts)


def public_callables(module):
    """(qualified name, object) of the module's own public functions, classes and methods."""
    for name, obj in vars(module).items():
        if name.startswith("_") or getattr(obj, "__module__", None) != module.__name__:
            continue
        if inspect.isfunction(obj):
            yield f"{module.__name__}.{name}", obj
        elif inspect.isclass(obj):
            yield f"{module.__name__}.{name}", obj
            for attr_name, attr in vars(obj).items():
                if attr_name.startswith("_") and attr_name not in ("__init__", "__call__"):
                    continue
                if isinstance(attr, (staticmethod, classmethod)):
                    attr = attr.__func__
                if inspect.isfunction(attr):
                    yield f"{module.__name__}.{name}.{attr_name}", attr


def _import(name: str):
    try:
        return importlib.import_module(name)
    except ImportError as exc:  # an optional extra that is not installed
        if exc.name and not exc.name.startswith("coassist"):
            pytest.skip(f"{name} needs {exc.name!r}, not installed (an optional extra)")
        raise


@pytest.mark.parametrize("module_name", MODULES)
def test_parameters_sections_match_signatures(module_name):
    module = _import(module_name)
    found = {qual: why for qual, obj in public_callables(module) if (why := mismatch(obj)) is not None}
    unexpected = {qual: why for qual, why in found.items() if qual not in ALLOWED_MISMATCHES}
    assert not unexpected, "docstring Parameters disagree with the signature:\n" + "\n".join(
        f"  {qual}: {why}" for qual, why in unexpected.items()
    )


def test_allowed_mismatches_still_exist():
    """Every allow-list entry names a real callable that still mismatches (else remove it)."""
    stale = []
    for qual in ALLOWED_MISMATCHES:
        module_name, _, attr = qual.rpartition(".")
        try:
            obj = getattr(importlib.import_module(module_name), attr)
        except ImportError as exc:
            pytest.skip(f"{module_name} needs {exc.name!r}, not installed")
        except AttributeError:
            stale.append(f"{qual}: no such callable")
            continue
        if mismatch(obj) is None:
            stale.append(f"{qual}: now matches its signature")
    assert not stale, "remove from ALLOWED_MISMATCHES:\n" + "\n".join(stale)


def test_the_walk_sees_the_package():
    """The check is not vacuous: it reaches the documented API across the package."""
    assert "coassist.model.impedance" in MODULES and "coassist.scenario.objects" in MODULES
    checked = []
    for name in (
        "coassist.model.impedance",
        "coassist.metrics",
        "coassist.scenario.objects",
        "coassist.sim.trial_runner",
        "coassist.runtime.wrench",
        "coassist.runtime.safety",
    ):
        module = importlib.import_module(name)
        checked += [qual for qual, obj in public_callables(module) if documented_parameters(obj.__doc__) is not None]
    # ImpedanceModel, the metrics' functions, CarriedObject, ForceSensor, run_trial, …
    assert {
        "coassist.model.impedance.ImpedanceModel",
        "coassist.metrics.prediction_errors",
        "coassist.scenario.objects.CarriedObject",
        "coassist.scenario.objects.ForceSensor",
        "coassist.sim.trial_runner.run_trial",
        "coassist.runtime.wrench.payload_wrench",
    } <= set(checked)
    assert len(checked) >= 12


# ---------------------------------------------------------------- the checker itself


def _numpydoc(a, b, *, c=1):
    """Numpydoc form.

    Parameters
    ----------
    a : float
        First. Note: a colon in prose is not an entry.
    b : array_like, shape (3,)

    c : int, optional
        Third.

    Returns
    -------
    x : float
        Not a parameter.
    """


def _project_form(model, hand, start, *, clock=None, sleep=None):
    """Project form, with shared entries and a heading that carries a remark.

    Parameters
    ----------
    model : the model.
    hand : anything with ``force(x) -> f`` [N].
    start : (2,) the start [m].
    clock, sleep : the clock and how to wait.

    Attributes (read after each period)
    ----------
    x, y : not parameters.
    """


def _missing_one(a, b, c):
    """Parameters
    ----------
    a : first.
    c : third.
    """


def _out_of_order(a, b):
    """Parameters
    ----------
    b : second.
    a : first.
    """


def _unknown_name(a):
    """Parameters
    ----------
    a : first.
    gone : a parameter that was removed.
    """


@dataclasses.dataclass(frozen=True)
class _Fields:
    """A dataclass: its fields are the signature.

    Parameters
    ----------
    mass : [kg].
    size : (a, b) [m].
    """

    mass: float = 0.0
    size: tuple = (0.0, 0.0)


def test_parser_reads_both_styles():
    assert documented_parameters(_numpydoc.__doc__) == ["a", "b", "c"]
    assert documented_parameters(_project_form.__doc__) == ["model", "hand", "start", "clock", "sleep"]
    assert documented_parameters("No sections here.\n\n    a : not a section") is None
    assert mismatch(_numpydoc) is None and mismatch(_project_form) is None and mismatch(_Fields) is None


@pytest.mark.parametrize(
    "func, message",
    [
        (_missing_one, r"undocumented \['b'\]"),
        (_out_of_order, "order"),
        (_unknown_name, r"not in the signature \['gone'\]"),
    ],
)
def test_checker_reports_each_kind_of_mismatch(func, message):
    assert re.search(message, mismatch(func))


#: A repository file a module cites: ``docs/…``, ``benchmarks/…`` or ``tests/…`` (up to the last word character).
_CITED_FILE = re.compile(r"(?<![\w/.-])((?:docs|benchmarks|tests)/[\w./-]*\w)")


def cited_files_missing(src: Path, root: Path) -> list[str]:
    """``module: cited`` for every file of the repository ``root`` cited under ``src`` that is not there,
    and every citation of DESIGN (the project's design notes live outside the repository)."""
    out = []
    for path in sorted(src.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        where = path.relative_to(src.parent)
        out += [f"{where}: {m.group(1)}" for m in _CITED_FILE.finditer(text) if not (root / m.group(1)).exists()]
        out += [f"{where}: DESIGN" for _ in re.finditer(r"\bDESIGN\b", text)]
    return out


def test_docstrings_cite_only_files_the_repository_has():
    root = _PACKAGE_DIR.parent.parent
    if not (root / "pyproject.toml").is_file():
        pytest.skip("coassist is installed, not checked out: the repository's docs are not beside it")
    missing = cited_files_missing(_PACKAGE_DIR, root)
    assert not missing, "cited files the repository lacks:\n" + "\n".join(missing)


def test_the_citation_check_catches_a_missing_file_and_design(tmp_path):
    src = tmp_path / "src" / "coassist"
    src.mkdir(parents=True)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "here.md").write_text("")
    (src / "mod.py").write_text(
        '"""See docs/here.md, docs/intent-results.md and DESIGN §7; not a citation: my_docs/x.md."""\n'
    )
    assert cited_files_missing(src, tmp_path) == ["coassist/mod.py: docs/intent-results.md", "coassist/mod.py: DESIGN"]
