"""Every exception coassist defines (warnings aside) derives from CoassistError and keeps its built-in base."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import coassist
from coassist.errors import CoassistError


def _coassist_exceptions() -> list[type[BaseException]]:
    found = []
    for info in pkgutil.walk_packages(coassist.__path__, "coassist."):
        if info.name.endswith(".__main__"):  # a script (python -m …): importing it runs it
            continue
        try:
            module = importlib.import_module(info.name)
        except ImportError:  # an optional extra that is absent (its own tests skip)
            continue
        for _, obj in inspect.getmembers(module, inspect.isclass):
            if issubclass(obj, BaseException) and not issubclass(obj, Warning) and obj.__module__ == info.name:
                found.append(obj)
    return found


def test_every_coassist_exception_derives_from_the_base():
    found = _coassist_exceptions()
    assert len(found) >= 8  # the scan itself must find the known ones
    # an interrupt is no error: it stays a KeyboardInterrupt alone, so that no `except Exception` swallows a Ctrl-C
    interrupts = [c for c in found if issubclass(c, KeyboardInterrupt)]
    assert [c.__qualname__ for c in interrupts] == ["RunInterrupted"]
    assert not any(issubclass(c, Exception) for c in interrupts)
    found = [c for c in found if c not in interrupts]
    assert [c.__qualname__ for c in found if not issubclass(c, CoassistError)] == []
    # and none is only a CoassistError: callers that catch the built-in keep working
    assert [c.__qualname__ for c in found if c.__mro__[1:] == (CoassistError, Exception, BaseException, object)] == []


def test_the_old_built_in_bases_still_catch():
    from coassist.data.datasets import ManifestError
    from coassist.registry import UnknownNameError

    with pytest.raises(ValueError):
        raise ManifestError("x")
    with pytest.raises(KeyError):
        raise UnknownNameError("x", "x")
    with pytest.raises(CoassistError):
        raise ManifestError("x")
