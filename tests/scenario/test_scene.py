"""A lab's scene file (coassist.scenario.scene): boxes in the robot's base frame, validated with the field named."""

import json

import pytest

from coassist.scenario.scene import MAX_BOXES, Scene, SceneBox, SceneError, read_scene

TOML = """
frame = "base"
[[obstacle]]
center = [0.45, 0.10, 0.2]
size = [0.12, 0.08, 0.3]
name = "fixture"

[[obstacle]]
center = [0.30, -0.05]
size = [0.04, 0.04]
"""


def test_toml_and_json_give_the_same_scene(tmp_path):
    toml = tmp_path / "scene.toml"
    toml.write_text(TOML)
    doc = {
        "obstacle": [
            {"center": [0.45, 0.10], "size": [0.12, 0.08], "name": "fixture"},
            {"center": [0.30, -0.05], "size": [0.04, 0.04]},
        ]
    }
    js = tmp_path / "scene.json"
    js.write_text(json.dumps(doc))
    a, b = read_scene(toml), read_scene(js)
    assert isinstance(a, Scene) and a.boxes == b.boxes
    assert a.boxes[0] == SceneBox((0.45, 0.10), (0.12, 0.08), "fixture")  # the height (z) is not the task's
    # as an intent source is told them: ((x, y) centre, (width, depth) size)
    assert a.told() == (((0.45, 0.10), (0.12, 0.08)), ((0.30, -0.05), (0.04, 0.04)))
    assert a.source == str(toml)
    extra = a.to_extra()
    assert extra["frame"] == "base" and extra["obstacles"][0] == {
        "center": [0.45, 0.10],
        "size": [0.12, 0.08],
        "name": "fixture",
    }


@pytest.mark.parametrize(
    "text, words",
    [
        ("[[obstacle]]\ncenter = [0.4, 0.1]\n", "obstacle[0].size is missing"),
        ("[[obstacle]]\ncenter = [0.4, 0.1]\nsize = [0.1, -0.1]\n", "obstacle[0].size must be 2 or 3 numbers > 0"),
        ("[[obstacle]]\ncenter = [0.4]\nsize = [0.1, 0.1]\n", "obstacle[0].center must be 2 or 3 numbers [m]"),
        ("[[obstacle]]\ncenter = [40.0, 0.1]\nsize = [0.1, 0.1]\n", "obstacle[0].center must be 2 or 3 numbers"),
        ("[[obstacle]]\ncenter = ['a', 0.1]\nsize = [0.1, 0.1]\n", "obstacle[0].center must be"),
        (
            "[[obstacle]]\ncenter = [0.4, 0.1]\nsize = [0.1, 0.1]\ncolour = 'red'\n",
            "obstacle[0]: unknown field 'colour'",
        ),
        ("frame = 'tool'\n[[obstacle]]\ncenter = [0.4, 0.1]\nsize = [0.1, 0.1]\n", "frame must be 'base'"),
        ("boxes = []\n", "unknown field 'boxes'"),
        ("", "obstacle must list 1 to 16 boxes"),
        ("[[obstacle]\n", "not valid TOML"),
        ("[[obstacle]]\ncenter = [1" + "0" * 400 + ", 0.1]\nsize = [0.1, 0.1]\n", "obstacle[0].center must be"),
    ],
)
def test_a_bad_scene_is_refused_naming_the_file_and_the_field(tmp_path, text, words):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        read_scene(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and words in message and "\n" not in message


def test_too_many_boxes_a_wrong_suffix_and_a_missing_file(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps({"obstacle": [{"center": [0, 0], "size": [0.1, 0.1]}] * (MAX_BOXES + 1)}))
    with pytest.raises(SceneError, match="obstacle must list 1 to 16 boxes"):
        read_scene(path)
    with pytest.raises(SceneError, match=r"scene.yaml: a scene file is .toml or .json"):
        read_scene(tmp_path / "scene.yaml")
    with pytest.raises(SceneError, match=r"absent.toml: cannot read"):
        read_scene(tmp_path / "absent.toml")


@pytest.mark.parametrize(
    "text, field",
    [
        # plain json.loads kept the last: the robot was told the second list only
        (
            '{"obstacle": [{"center": [0.1, 0.1], "size": [0.1, 0.1]}],'
            ' "obstacle": [{"center": [1.0, 0.1], "size": [0.1, 0.1]}]}',
            "obstacle",
        ),
        ('{"obstacle": [{"center": [0.1, 0.1], "size": [0.1, 0.1], "center": [0.9, 0.9]}]}', "center"),
        ('{"frame": "base", "frame": "base", "obstacle": [{"center": [0.1, 0.1], "size": [0.1, 0.1]}]}', "frame"),
    ],
)
def test_a_field_given_twice_in_json_is_refused_naming_it(tmp_path, text, field):
    path = tmp_path / "scene.json"
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        read_scene(path)
    assert str(info.value) == f"{path}: not valid JSON (the key {field!r} appears twice)"


def test_a_field_given_twice_in_toml_is_refused_by_toml_itself(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("[[obstacle]]\ncenter = [0.1, 0.1]\ncenter = [0.9, 0.9]\nsize = [0.1, 0.1]\n")
    with pytest.raises(SceneError, match=r"scene.toml: not valid TOML \(Cannot overwrite a value"):
        read_scene(path)


@pytest.mark.parametrize(
    "name, text",
    [
        ("scene.json", '{"obstacle": ' + "[" * 3000 + "]" * 3000 + "}"),
        ("scene.toml", "obstacle = " + "[" * 3000 + "]" * 3000 + "\n"),
    ],
)
def test_a_file_nested_too_deeply_is_one_line_naming_it(tmp_path, name, text):
    # the parsers recurse once a level: RecursionError's traceback, not a scene error
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(SceneError) as info:
        read_scene(path)
    kind = path.suffix[1:].upper()
    assert str(info.value) == f"{path}: not valid {kind} (nested too deeply for a scene)"


def test_anything_else_a_parser_raises_is_one_line_naming_the_file(tmp_path, monkeypatch):
    # (no input known to make json raise other than ValueError / RecursionError: one is made to)
    import coassist.scenario.scene as scene_module

    def broken(text, object_pairs_hook=None):
        raise MemoryError("out of\nmemory")

    monkeypatch.setattr(scene_module.json, "loads", broken)
    path = tmp_path / "scene.json"
    path.write_text("{}")
    with pytest.raises(SceneError) as info:
        read_scene(path)
    assert str(info.value) == f"{path}: not valid JSON (MemoryError: out of memory)"
