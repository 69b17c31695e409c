"""Named, read-only registries (presets of every kind) with one lookup and one error format.

Three kinds of presets live on three layers: control presets (:mod:`coassist.config`,
layer 0, used by ``sim`` and ``robot``), intent-model presets
(:mod:`coassist.intent.training`, layer 3) and reproduce presets
(:mod:`coassist.experiments.pipeline`, layer 6). A single table holding all three would
have to sit above ``experiments`` and so could not be read by ``sim``; instead each kind
is a :class:`Registry` declared next to the type it holds, and this layer-0 module gives
them one type, one lookup (:meth:`Registry.lookup`) and one error message
(:func:`unknown_name_message`, the command line's "did you mean").
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Iterator, Mapping
from types import MappingProxyType
from typing import Generic, TypeVar

from coassist.errors import CoassistError

__all__ = ["Registry", "UnknownNameError", "unknown_name_message"]

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
