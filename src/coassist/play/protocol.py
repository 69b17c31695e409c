"""The page ↔ server messages, and the validation every client message passes.

Client → server (JSON text frames of at most :data:`MAX_MESSAGE_BYTES`)::

    {"type": "pointer", "x": m, "y": m, "down": bool, "seq": int}   where the hand is (task plane)
    {"type": "start", "controller": name}                            start the next trial
    {"type": "abort"}                                                stop the trial, keep nothing
    {"type": "ping", "seq": int}                                     answered with a pong (latency floor)
    {"type": "answers", "step": int, "values": [number, …]}          a study's questionnaire, in its items' order
    {"type": "next", "step": int}                                    a study's rest is over: go on

A message that is not exactly one of these — not JSON, too long, an unknown type, a
missing or extra field, a wrong type, a non-finite or out-of-view number — raises
:class:`InvalidMessage`; the server drops it, counts it and goes on. No message names a
file or a folder: where trials are written is fixed when the server starts.

Server → client: ``init`` (the scene and the session), ``frame`` (the live state, once
per control period), ``result`` (a trial's f_RMS and σ and the running averages),
``status`` and ``pong``; see :mod:`coassist.play.server`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from coassist._checks import is_integer, is_real_number
from coassist.errors import CoassistError

__all__ = [
    "MAX_ANSWERS",
    "MAX_MESSAGE_BYTES",
    "Abort",
    "Answers",
    "InvalidMessage",
    "Next",
    "Ping",
    "Pointer",
    "Start",
    "parse_message",
]

#: Longest client message accepted [bytes]; a pointer message is about 70.
MAX_MESSAGE_BYTES = 512
_MAX_SEQ = 2**53  # JavaScript's largest exact integer
#: Most answers one questionnaire message may carry (six TLX subscales and twelve Likert items fit).
MAX_ANSWERS = 32


class InvalidMessage(CoassistError, ValueError):
    """A client message that is dropped; the text says why (counted per reason)."""


@dataclass(frozen=True)
class Pointer:
    x: float
    y: float
    down: bool
    seq: int


@dataclass(frozen=True)
class Start:
    controller: str


@dataclass(frozen=True)
class Abort:
    pass


@dataclass(frozen=True)
class Ping:
    seq: int


@dataclass(frozen=True)
class Answers:
    step: int
    values: tuple[float, ...]


@dataclass(frozen=True)
class Next:
    step: int


_FIELDS = {
    "pointer": {"type", "x", "y", "down", "seq"},
    "start": {"type", "controller"},
    "abort": {"type"},
    "ping": {"type", "seq"},
    "answers": {"type", "step", "values"},
    "next": {"type", "step"},
}


def _number(value, name: str, lo: float, hi: float) -> float:
    if not is_real_number(value):
        raise InvalidMessage(f"{name} is not a number")
    try:  # JSON reads a 400-digit integer exactly: no float holds it
        v = float(value)
    except OverflowError:
        raise InvalidMessage(f"{name} out of range") from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise InvalidMessage(f"{name} out of range")
    return v


def _seq(value) -> int:
    if not is_integer(value) or not 0 <= value < _MAX_SEQ:
        raise InvalidMessage("seq is not an int in [0, 2^53)")
    return int(value)


def parse_message(text, bounds: tuple[float, float, float, float], controllers: tuple[str, ...]):
    """The validated message (module docstring) or :class:`InvalidMessage`.

    bounds : (x_min, x_max, y_min, y_max) [m] a pointer may be in (the page's view).
    controllers : the names a ``start`` may ask for.

    A study's answers are numbers in [0, 100] (a TLX subscale or a Likert point); whether they
    fit the questionnaire asked is the study's check.
    """
    if not isinstance(text, str):
        raise InvalidMessage("not a text frame")
    if len(text) > MAX_MESSAGE_BYTES or len(text.encode("utf-8", "surrogatepass")) > MAX_MESSAGE_BYTES:
        raise InvalidMessage("too long")
    try:
        msg = json.loads(text, parse_constant=_reject_constant)
    except (ValueError, RecursionError):
        raise InvalidMessage("not JSON") from None
    if not isinstance(msg, dict):
        raise InvalidMessage("not a JSON object")
    kind = msg.get("type")
    if not isinstance(kind, str) or kind not in _FIELDS:
        raise InvalidMessage("unknown type")
    if set(msg) != _FIELDS[kind]:
        raise InvalidMessage(f"{kind}: wrong fields")
    if kind == "pointer":
        x = _number(msg["x"], "x", bounds[0], bounds[1])
        y = _number(msg["y"], "y", bounds[2], bounds[3])
        if not isinstance(msg["down"], bool):
            raise InvalidMessage("down is not a boolean")
        return Pointer(x, y, msg["down"], _seq(msg["seq"]))
    if kind == "start":
        name = msg["controller"]
        if not isinstance(name, str) or name not in controllers:
            raise InvalidMessage("start: unknown controller")
        return Start(name)
    if kind == "ping":
        return Ping(_seq(msg["seq"]))
    if kind == "answers":
        values = msg["values"]
        if not isinstance(values, list) or len(values) > MAX_ANSWERS:
            raise InvalidMessage(f"answers: values is not a list of at most {MAX_ANSWERS}")
        return Answers(_seq(msg["step"]), tuple(_number(v, "answer", 0.0, 100.0) for v in values))
    if kind == "next":
        return Next(_seq(msg["step"]))
    return Abort()


def _reject_constant(name: str):
    raise ValueError(f"{name} is not JSON")
