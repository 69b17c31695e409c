"""Named, read-only registries (presets of every kind) with one lookup and one error format.

Three kinds of presets live on three layers: control presets (:mod:`coassist.config`,
layer 0, used by ``sim`` and ``robot``), intent-model presets
(:mod:`coassist.intent.training`, layer 3) and reproduce presets
(:mod:`coassist.experiments.pipeline`, layer 6). A single table holding all three would
have to sit above ``experiments`` and so could not be read by ``sim``; instead each kind
is a :class:`Registry` declared next to the type it holds, and this layer-0 module gives
them one type, one lookup (:meth:`Registry.lookup`) and one error message
(:func:`unknown_name_message`, the command line's "did you mean").

The registries of what a run plugs in (the arm worlds, :mod:`coassist.robot.worlds`; the
named intent sources, :mod:`coassist.scenario.intent_registry`) name what each entry builds
by an *entry point*, ``"package.module:attribute"`` (gymnasium's ``register(entry_point=...)``
convention), imported only when the entry is built (:func:`load_entry_point`): a world whose
optional extra is not installed is still listed and explained, and registering one is one line.
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Iterable, Iterator, Mapping
from types import MappingProxyType
from typing import Any, Generic, TypeVar

from coassist.errors import CoassistError

__all__ = ["Registry", "UnknownNameError", "is_entry_point", "load_entry_point", "unknown_name_message"]

T = TypeVar("T")


def unknown_name_message(value: str, choices: Iterable[str], what: str) -> str:
    """``'<value>': no such <what>; did you mean '<closest>'? (choose from: a, b, …)``.

    The "did you mean" part is given when a choice is close enough
    (:func:`difflib.get_close_matches`, cutoff 0.5), and left out otherwise.
    """
    choices = list(choices)
    close = difflib.get_close_matches(value, choices, n=1, cutoff=0.5)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"{value!r}: no such {what}{hint} (choose from: {', '.join(choices)})"


class UnknownNameError(CoassistError, KeyError, ValueError):
    """A name that is not in a :class:`Registry`; ``str()`` is :func:`unknown_name_message`'s line.

    A ``KeyError`` (``registry[name]`` semantics) and a ``ValueError`` (bad input) at once.
    """

    def __init__(self, message: str, name: str) -> None:
        super().__init__(message)
        self.message = message
        self.name = name

    def __str__(self) -> str:  # KeyError would quote the message
        return self.message


class Registry(Mapping[str, T], Generic[T]):
    """A read-only mapping from names to entries of one kind (``what``, e.g. "control preset").

    Entries keep their declaration order. ``registry[name]`` and :meth:`lookup` raise
    :class:`UnknownNameError` for an unknown name.
    """

    def __init__(self, what: str, entries: Mapping[str, T]) -> None:
        if not isinstance(what, str) or not what:
            raise ValueError(f"registry kind must be a non-empty string, got {what!r}")
        for name in entries:
            if not isinstance(name, str) or not name:
                raise ValueError(f"{what} names must be non-empty strings, got {name!r}")
        self.what = what
        self._entries: Mapping[str, T] = MappingProxyType(dict(entries))

    def lookup(self, name: str) -> T:
        """The entry called ``name``; :class:`UnknownNameError` naming the closest one if there is none."""
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise UnknownNameError(unknown_name_message(str(name), self._entries, self.what), str(name)) from None

    def __getitem__(self, name: str) -> T:
        return self.lookup(name)

    def __contains__(self, name: object) -> bool:
        # Mapping's default goes through __getitem__, which would build the did-you-mean message on every miss.
        try:
            return name in self._entries
        except TypeError:  # an unhashable name is in no registry
            return False

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.what!r}, names={tuple(self._entries)!r})"


def is_entry_point(value: object) -> bool:
    """Whether ``value`` is written as an entry point: ``"package.module:attribute"``, one colon, both
    parts named (the registries' entries check it when built, :func:`load_entry_point` when used)."""
    if not isinstance(value, str) or value.count(":") != 1:
        return False
    module_name, _, attribute = value.partition(":")
    return bool(module_name and attribute)


def load_entry_point(entry_point: str) -> Any:
    """The object an entry point ``"package.module:attribute"`` names, imported now.

    Raises ValueError for a malformed entry point and for a module without that attribute;
    an ImportError of the module (an optional extra not installed) goes to the caller, who
    knows which extra to name.
    """
    if not is_entry_point(entry_point):
        raise ValueError(f"an entry point is 'package.module:attribute', got {entry_point!r}")
    module_name, _, attribute = entry_point.partition(":")
    module = importlib.import_module(module_name)
    try:
        return getattr(module, attribute)
    except AttributeError:
        raise ValueError(f"entry point {entry_point!r}: {module_name} has no {attribute!r}") from None
