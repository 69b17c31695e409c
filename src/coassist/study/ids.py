"""Pseudonymous participant ids by construction: what a study accepts as a person's id.

An id names the participant's folder and is every one of their trials' ``user``: it must say
nothing about the person and must name one folder on every file system. :func:`check_id`
refuses, each in one line saying why:

- what cannot be a portable folder name: anything but 1–32 letters, digits, ``-``, ``_``
  starting with a letter or digit, and the names Windows reserves for devices (``CON``,
  ``PRN``, ``AUX``, ``NUL``, ``COM0``–``COM9``, ``LPT0``–``LPT9``, in any case);
- what looks like a name (:func:`looks_like_name`): a run of four or more letters
  (``Smith``, ``jane``), two runs of two or more (``Jo_Li``, ``JaneDoe`` split at its
  capital), or a run of three in title case (``Tom``); codes such as ``P07``, ``SUB12`` or
  ``ab3`` pass;
- what holds a date (:func:`looks_like_date`): a valid day of 1900–2099 written as
  ``YYYY-MM-DD``, ``DD.MM.YYYY`` (any of ``-``, ``_``, ``.`` or none between the parts; two-
  digit years with separators only);
- for a person, what does not match the lab's pattern whole (``[study] id_pattern``, a
  regular expression; default :data:`DEFAULT_ID_PATTERN`, a letter and 1–4 digits);
- an id that differs from a registered one in case only (``s01`` beside ``S01``: on a
  case-insensitive file system the two would share a folder).

Simulated participants (``--simulate``) are S01, S02, …: the same checks but the lab's
pattern (they are not people, and a rehearsal must run whatever the pattern).
"""

from __future__ import annotations

import datetime as _dt
import re
from collections.abc import Iterable

from coassist.errors import CoassistError

__all__ = [
    "DEFAULT_ID_PATTERN",
    "RESERVED_IDS",
    "IdError",
    "check_id",
    "compile_id_pattern",
    "looks_like_date",
    "looks_like_name",
]

#: The default id format: a letter and 1–4 digits (P07, S12, A1234).
DEFAULT_ID_PATTERN = "[A-Za-z][0-9]{1,4}"
#: Names Windows reserves for devices (a folder of that name cannot be made there).
RESERVED_IDS = frozenset({"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(10)), *(f"LPT{i}" for i in range(10))})
_FOLDER_SAFE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,31}")
_MAX_PATTERN = 200
_WORD = re.compile(r"[A-Z][a-z]+|[a-z]+|[A-Z]+(?![a-z])")


class IdError(CoassistError, ValueError):
    """An id (or id pattern) a study does not accept; one line saying why."""


def compile_id_pattern(pattern: object) -> re.Pattern[str]:
    """``pattern`` compiled (IdError for a non-string, an empty or over-long one, or bad syntax)."""
    if not isinstance(pattern, str) or not pattern or len(pattern) > _MAX_PATTERN:
        raise IdError(f"must be a regular expression of 1-{_MAX_PATTERN} characters, got {pattern!r}")
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise IdError(f"{pattern!r} is not a regular expression ({exc})") from None


def looks_like_name(pid: str) -> bool:
    """Whether ``pid`` holds a word (module docstring): a letter run of >= 4, two runs of >= 2, a title-case run of 3."""
    words = _WORD.findall(pid)
    if any(len(w) >= 4 for w in words) or sum(len(w) >= 2 for w in words) >= 2:
        return True
    return any(len(w) == 3 and w[0].isupper() and w[1:].islower() for w in words)


def _valid_day(year: int, month: int, day: int) -> bool:
    try:
        _dt.date(year, month, day)
    except ValueError:
        return False
    return 1900 <= year <= 2099


_SEP = r"[-_.]"
_DATES = (
    (re.compile(rf"(?<!\d)(\d{{4}}){_SEP}?(\d{{1,2}}){_SEP}?(\d{{1,2}})(?!\d)"), "ymd"),
    (re.compile(rf"(?<!\d)(\d{{1,2}}){_SEP}?(\d{{1,2}}){_SEP}?(\d{{4}})(?!\d)"), "dmy"),
    (re.compile(rf"(?<!\d)(\d{{1,2}}){_SEP}(\d{{1,2}}){_SEP}(\d{{2}})(?!\d)"), "dmy2"),
    (re.compile(rf"(?<!\d)(\d{{2}}){_SEP}(\d{{1,2}}){_SEP}(\d{{1,2}})(?!\d)"), "ymd2"),
)


def looks_like_date(pid: str) -> bool:
    """Whether ``pid`` holds a valid day written as a date (module docstring), day-month or month-day."""
    for pattern, order in _DATES:
        for m in pattern.finditer(pid):
            a, b, c = (int(g) for g in m.groups())
            if order == "ymd":
                days = [(a, b, c), (a, c, b)]
            elif order == "dmy":
                days = [(c, b, a), (c, a, b)]
            elif order == "dmy2":
                days = [(1900 + c, b, a), (2000 + c, b, a), (1900 + c, a, b), (2000 + c, a, b)]
            else:
                days = [(1900 + a, b, c), (2000 + a, b, c)]
            if any(_valid_day(*d) for d in days):
                return True
    return False


def check_id(
    pid: object, pattern: str = DEFAULT_ID_PATTERN, registered: Iterable[str] = (), *, simulated: bool = False
) -> str:
    """``pid`` if a study accepts it as a new or registered participant's id (module docstring), else
    :class:`IdError` in one line. ``registered``: the ids the study has; ``simulated``: the lab's pattern
    does not apply."""
    hint = "a pseudonym such as P07 (the key from pseudonym to person stays outside the study folder)"
    if not isinstance(pid, str) or not _FOLDER_SAFE.fullmatch(pid):
        raise IdError(
            f"--participant must be 1-32 letters, digits, '-' or '_' (it names a folder): {hint}; got {pid!r}"
        )
    if pid.upper() in RESERVED_IDS:
        raise IdError(f"--participant {pid}: a name Windows reserves for a device (no folder can have it); use {hint}")
    if looks_like_date(pid):
        raise IdError(f"--participant {pid} holds a date (a birthday is personal data); use {hint}")
    if looks_like_name(pid):
        raise IdError(f"--participant {pid} looks like a name (it has a word in it); use {hint}")
    registered = list(registered)
    if pid not in registered:
        clash = next((r for r in registered if r.casefold() == pid.casefold()), None)
        if clash is not None:
            raise IdError(
                f"--participant {pid}: the study has {clash}, which differs in case only (on a case-insensitive "
                f"file system the two would share a folder); give {clash} to continue them, or another id"
            )
    if not simulated and not compile_id_pattern(pattern).fullmatch(pid):
        raise IdError(
            f"--participant {pid} does not match the study's id_pattern {pattern!r} (its plan's [study]); use {hint}"
        )
    return pid
