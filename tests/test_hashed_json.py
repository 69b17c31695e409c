"""coassist._io's hashed JSON files: a file that carries the SHA-256 of its own content (issue 42).

The mechanism of the path-hypotheses calibration and of any other file a person could edit by
hand and the robot would then obey: the hash against hashlib on the canonical JSON written out
here by hand, every way a file can be wrong refused in one line naming the file.
"""

from __future__ import annotations

import hashlib
import json

import pytest

from coassist._io import HASH_KEY, HashedJsonError, json_sha256, read_hashed_json, write_hashed_json

FORMAT = "coassist-test-1"


def test_the_hash_is_sha256_of_the_canonical_json():
    # sorted keys, no spaces, ASCII escapes: written out by hand
    doc = {"b": [1, 2.5], "a": {"é": 0.001}}
    canonical = '{"a":{"\\u00e9":0.001},"b":[1,2.5]}'
    assert json_sha256(doc) == hashlib.sha256(canonical.encode("ascii")).hexdigest()
    assert json_sha256({"b": (1, 2.5), "a": {"é": 0.001}}) == json_sha256(doc)  # a tuple is the list read back
    with pytest.raises(ValueError):
        json_sha256({"x": float("nan")})


def test_a_written_file_reads_back_and_holds_its_hash(tmp_path):
    doc = {"shapes": {"p01": {"clearance": 0.03}}, "grid": (0.6, 1.0)}
    path = write_hashed_json(tmp_path / "c.json", doc, format=FORMAT)
    raw = json.loads(path.read_text())
    assert raw["format"] == FORMAT and raw[HASH_KEY] == json_sha256({k: v for k, v in raw.items() if k != HASH_KEY})
    assert read_hashed_json(path, format=FORMAT) == {"shapes": {"p01": {"clearance": 0.03}}, "grid": [0.6, 1.0]}
    for bad, match in (({"format": "x"}, "may not hold 'format'"), ({HASH_KEY: "0"}, "may not hold 'sha256'")):
        with pytest.raises(ValueError, match=match):
            write_hashed_json(tmp_path / "d.json", bad, format=FORMAT)
    with pytest.raises(ValueError):
        write_hashed_json(tmp_path / "d.json", {"x": float("inf")}, format=FORMAT)
    assert not (tmp_path / "d.json").exists()


def _edit(path, text: str) -> None:
    path.write_text(text)


@pytest.mark.parametrize(
    "content, what",
    [
        (None, "not found"),
        ("{", "malformed JSON"),
        ("[1, 2]", "must hold a JSON object, got list"),
        ('{"format": "other-1"}', "format 'other-1', expected 'coassist-test-1'"),
        ('{"format": "coassist-test-1", "x": 1}', "carries no 'sha256'"),
        ('{"format": "coassist-test-1", "x": NaN, "sha256": "0"}', "NaN is not a number a file may hold"),
        ('{"format": "coassist-test-1", "x": 1, "x": 2, "sha256": "0"}', "the key 'x' appears twice"),
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
        (b"\xff\xfe", "not UTF-8"),
    ],
)
def test_a_file_that_cannot_be_used_is_refused_in_one_line_naming_it(tmp_path, content, what):
    path = tmp_path / "c.json"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    with pytest.raises(HashedJsonError) as info:
        read_hashed_json(path, format=FORMAT)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and what in message and "\n" not in message
    assert isinstance(info.value, ValueError)


def test_an_edit_after_writing_is_refused_and_so_is_a_file_too_large(tmp_path):
    path = write_hashed_json(tmp_path / "c.json", {"stiffness": 800.0}, format=FORMAT)
    text = path.read_text()
    for edited in (text.replace("800.0", "1e-300"), text.replace("800.0", "800")):  # even 800.0 → 800
        _edit(path, edited)
        with pytest.raises(HashedJsonError, match=r"does not match its 'sha256' \(edited after it was written\?\)"):
            read_hashed_json(path, format=FORMAT)
    _edit(path, text)  # restored: read again
    assert read_hashed_json(path, format=FORMAT) == {"stiffness": 800.0}
    with pytest.raises(HashedJsonError, match=f"larger than {len(text) - 1} bytes"):
        read_hashed_json(path, format=FORMAT, max_bytes=len(text) - 1)


def test_a_reader_may_take_several_formats_and_names_them_when_refusing(tmp_path):
    path = tmp_path / "m.json"
    write_hashed_json(path, {"a": 1}, format="thing-1")
    assert read_hashed_json(path, format=("thing-2", "thing-1")) == {"a": 1}  # an older format a reader still takes
    with pytest.raises(HashedJsonError, match="format 'thing-1', expected 'thing-3' or 'thing-2'") as err:
        read_hashed_json(path, format=("thing-3", "thing-2"))
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    for bad in ((), ("thing-1", ""), ("thing-1", 2)):
        with pytest.raises(ValueError, match="format must be a name"):
            read_hashed_json(path, format=bad)  # type: ignore[arg-type]
