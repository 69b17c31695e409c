"""Named, read-only registries (presets of every kind) with one lookup and one error format.

Three kinds of presets live on three layers: control presets (:mod:`coassist.config`,
layer 0, used by ``sim`` and ``robot``), intent-model presets
(:mod:`coassist.intent.presets`, layer 3) and reproduce presets
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
    """A mapping from names to entries of one kind (``what``, e.g. "control preset"), read-only
    but for :meth:`register`.

    Entries keep their declaration order. ``registry[name]`` and :meth:`lookup` raise
    :class:`UnknownNameError` for an unknown name. ``entry_type``: the class every entry is
    (checked for the declared entries and for each one registered later; None: not checked).
    """

    def __init__(self, what: str, entries: Mapping[str, T], *, entry_type: type | None = None) -> None:
        if not isinstance(what, str) or not what:
            raise ValueError(f"registry kind must be a non-empty string, got {what!r}")
        self.what = what
        self.entry_type = entry_type
        for name, entry in entries.items():
            self._check(name, entry)
        self._entries: dict[str, T] = dict(entries)
        self._declared = frozenset(self._entries)

    def _check(self, name: object, entry: object) -> None:
        if not isinstance(name, str) or not name:
            raise ValueError(f"{self.what} names must be non-empty strings, got {name!r}")
        if self.entry_type is not None and not isinstance(entry, self.entry_type):
            raise ValueError(f"{self.what} {name!r} must be a {self.entry_type.__name__}, got {type(entry).__name__}")
        own = getattr(entry, "name", name)
        if isinstance(own, str) and own != name:
            # an entry that names itself (a preset: trials record its name) is registered under that name, or the
            # recorded name is none the registry knows
            raise ValueError(f"{self.what} {name!r}: its entry is named {own!r}; register it under that name")

    def register(self, name: str, entry: T) -> None:
        """Add ``entry`` as ``name`` (after the declared ones) from any module: a plug-in's, a test's.

        Every consumer that reads the registry sees it from then on, in this process; a worker
        process sees it only if it imports the module that registers it (the simulator's
        workers are spawned: run such trials with ``workers=1``, or register in an imported
        module). ValueError for a name already taken (an entry is never replaced) and for an
        entry not of ``entry_type``.
        """
        self._check(name, entry)
        if name in self._entries:
            raise ValueError(f"{self.what} {name!r} is already registered")
        self._entries[name] = entry

    def is_declared(self, name: str) -> bool:
        """Whether ``name`` is one of the entries the registry was made with (not one :meth:`register` added)."""
        return name in self._declared

    def unregister(self, name: str) -> None:
        """Remove an entry :meth:`register` added; the declared entries stay (ValueError)."""
        if name in self._declared:
            raise ValueError(f"{self.what} {name!r} is declared with the registry; only registered ones are removed")
        if name not in self._entries:
            raise UnknownNameError(unknown_name_message(str(name), self._entries, self.what), str(name))
        del self._entries[name]

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
