"""Every client message is validated; anything else is refused with a reason."""

from __future__ import annotations

import json

import pytest

from coassist.play.protocol import (
    MAX_MESSAGE_BYTES,
    Abort,
    InvalidMessage,
    Ping,
    Pointer,
    Start,
    parse_message,
)

BOUNDS = (-0.2, 0.5, -0.9, -0.3)
CONTROLLERS = ("manual", "cooperative")


def parse(obj):
    return parse_message(obj if isinstance(obj, str) else json.dumps(obj), BOUNDS, CONTROLLERS)


def test_the_four_messages_parse():
    assert parse({"type": "pointer", "x": 0.1, "y": -0.6, "down": True, "seq": 3}) == Pointer(0.1, -0.6, True, 3)
    assert parse({"type": "pointer", "x": 0, "y": -0.5, "down": False, "seq": 0}) == Pointer(0.0, -0.5, False, 0)
    assert parse({"type": "start", "controller": "cooperative"}) == Start("cooperative")
    assert parse({"type": "abort"}) == Abort()
    assert parse({"type": "ping", "seq": 12}) == Ping(12)


HOSTILE = [
    "",
    "not json",
    "[1, 2]",
    "null",
    "42",
    '"pointer"',
    "{",
    '{"type": "pointer"',
    '{"type": "pointer", "x": NaN, "y": -0.6, "down": true, "seq": 1}',
    '{"type": "pointer", "x": Infinity, "y": -0.6, "down": true, "seq": 1}',
    '{"type": "pointer", "x": 1e999, "y": -0.6, "down": true, "seq": 1}',
    '{"type": "pointer", "x": 1' + "0" * 400 + ', "y": -0.6, "down": true, "seq": 1}',  # once an OverflowError
    {"type": "pointer", "x": 0.6, "y": -0.6, "down": True, "seq": 1},  # outside the view
    {"type": "pointer", "x": 0.1, "y": 5.0, "down": True, "seq": 1},
    {"type": "pointer", "x": True, "y": -0.6, "down": True, "seq": 1},  # a bool is not a number
    {"type": "pointer", "x": "0.1", "y": -0.6, "down": True, "seq": 1},
    {"type": "pointer", "x": 0.1, "y": -0.6, "down": 1, "seq": 1},
    {"type": "pointer", "x": 0.1, "y": -0.6, "down": True, "seq": -1},
    {"type": "pointer", "x": 0.1, "y": -0.6, "down": True, "seq": 1.5},
    {"type": "pointer", "x": 0.1, "y": -0.6, "down": True, "seq": 2**60},
    {"type": "pointer", "x": 0.1, "y": -0.6, "down": True},  # missing field
    {"type": "pointer", "x": 0.1, "y": -0.6, "down": True, "seq": 1, "path": "../../etc/passwd"},  # extra field
    {"type": "start", "controller": "oracle"},
    {"type": "start", "controller": ["manual"]},
    {"type": "start", "controller": "manual", "out": "/tmp/x"},
    {"type": "save", "file": "../x.parquet"},
    {"type": {"nested": 1}},
    {"x": 1},
    "[" * 100000,  # too long (and too deep)
    json.dumps({"type": "abort", "pad": "x" * MAX_MESSAGE_BYTES}),
]


@pytest.mark.parametrize("message", HOSTILE, ids=range(len(HOSTILE)))
def test_malformed_or_hostile_messages_are_refused(message):
    with pytest.raises(InvalidMessage):
        parse(message)


def test_binary_frames_and_deep_nesting_are_refused():
    with pytest.raises(InvalidMessage, match="text"):
        parse_message(b'{"type": "abort"}', BOUNDS, CONTROLLERS)
    with pytest.raises(InvalidMessage):
        parse_message("[" * 400 + "]" * 400, BOUNDS, CONTROLLERS)  # under the size limit: valid JSON, not an object
