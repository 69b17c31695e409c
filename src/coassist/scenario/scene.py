"""A scene file a lab writes: the obstacles the robot is told of on an arm (``--scene FILE``).

In a simulated world the robot may be told the task's obstacle (the simulated operator goes
round it); at a real arm nobody tells it anything, so the ``paths`` source there is the present
estimate alone. A lab that knows what stands on the table writes it down, as boxes in the
robot's base frame [m] (the frame the arm's TCP pose is read in, the plan's frame on an arm)::

    # scene.toml
    frame = "base"                      # optional; the only frame there is
    [[obstacle]]
    center = [0.45, 0.10]               # x, y [m]; a third number (z) is allowed and not used
    size = [0.12, 0.12]                 # width along x, depth along y [m] (a third, the height, likewise)
    name = "fixture"                    # optional, for the log

or the same as JSON (``{"obstacle": [{"center": [...], "size": [...]}]}``). The task is
planar: each box is told as its x-y footprint (:attr:`coassist.interfaces.TrialContext.obstacles`).
A trial run with a scene records it (``TrialMeta.extra["scene"]``), so that results with the
robot told the scene are reported apart from those without.

:func:`read_scene` reads and validates a file; every error names the file and the field.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from coassist._io import no_duplicate_keys
from coassist.errors import CoassistError

__all__ = ["MAX_BOXES", "Scene", "SceneBox", "SceneError", "read_scene"]

#: The most boxes a scene holds (the path-hypotheses source uses the one the path passes nearest).
MAX_BOXES = 16
#: [m] the largest |coordinate| and size: beyond any arm's reach.
REACH = 3.0
_BOX_KEYS = ("center", "size", "name")
_TOP_KEYS = ("frame", "obstacle")


class SceneError(CoassistError, ValueError):
    """A scene file that cannot be used (the message names the file and the field)."""


@dataclass(frozen=True)
class SceneBox:
    """One obstacle: its x-y centre and size [m] in the robot's base frame, and a name."""

    center: tuple[float, float]
    size: tuple[float, float]
    name: str = ""

    def told(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """As :attr:`TrialContext.obstacles <coassist.interfaces.TrialContext>` holds it."""
        return (self.center, self.size)


@dataclass(frozen=True)
class Scene:
    """The boxes of a scene file and the file's name (for the log and the one-line statement)."""

    boxes: tuple[SceneBox, ...]
    source: str = ""

    def told(self) -> tuple[tuple[tuple[float, float], tuple[float, float]], ...]:
        """Every box as :attr:`TrialContext.obstacles <coassist.interfaces.TrialContext>` holds them."""
        return tuple(b.told() for b in self.boxes)

    def to_extra(self) -> dict[str, Any]:
        """What a trial records of it (``TrialMeta.extra["scene"]``)."""
        return {
            "file": self.source,
            "frame": "base",
            "obstacles": [{"center": list(b.center), "size": list(b.size), "name": b.name} for b in self.boxes],
        }


def _numbers(value: Any, where: str, *, positive: bool) -> tuple[float, float]:
    what = "2 or 3 numbers > 0 [m]" if positive else "2 or 3 numbers [m]"
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)) or len(value) not in (2, 3):
        raise SceneError(f"{where} must be {what}, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(f"{where} must be {what}, got {value!r}")
        try:  # a 400-digit integer overflows a float: no length in metres either
            v = float(v)
        except OverflowError:
            v = math.inf
        if not math.isfinite(v):
            raise SceneError(f"{where} must be {what}, got {value!r}")
        if (positive and not 0.0 < v <= REACH) or abs(v) > REACH:
            raise SceneError(f"{where} must be {what} within ±{REACH:g} m (an arm's reach), got {value!r}")
        out.append(v)
    return (out[0], out[1])


def _scene_from(doc: Any, where: str) -> Scene:
    if not isinstance(doc, dict):
        raise SceneError(f"{where}: must be a table with an 'obstacle' list, got {type(doc).__name__}")
    for key in doc:
        if key not in _TOP_KEYS:
            raise SceneError(f"{where}: unknown field {key!r} (fields: {', '.join(_TOP_KEYS)})")
    frame = doc.get("frame", "base")
    if frame != "base":
        raise SceneError(f"{where}: frame must be 'base' (the robot's base frame), got {frame!r}")
    boxes = doc.get("obstacle")
    if not isinstance(boxes, list) or not 1 <= len(boxes) <= MAX_BOXES:
        raise SceneError(f"{where}: obstacle must list 1 to {MAX_BOXES} boxes, got {boxes!r}")
    out = []
    for i, box in enumerate(boxes):
        at = f"{where}: obstacle[{i}]"
        if not isinstance(box, dict):
            raise SceneError(f"{at} must be a table with center and size, got {box!r}")
        for key in box:
            if key not in _BOX_KEYS:
                raise SceneError(f"{at}: unknown field {key!r} (fields: {', '.join(_BOX_KEYS)})")
        for key in ("center", "size"):
            if key not in box:
                raise SceneError(f"{at}.{key} is missing")
        name = box.get("name", "")
        if not isinstance(name, str) or len(name) > 64:
            raise SceneError(f"{at}.name must be a string of at most 64 characters, got {name!r}")
        out.append(
            SceneBox(
                _numbers(box["center"], f"{at}.center", positive=False),
                _numbers(box["size"], f"{at}.size", positive=True),
                name,
            )
        )
    return Scene(tuple(out), where)


def read_scene(path: str | Path) -> Scene:
    """The :class:`Scene` of a TOML (``.toml``) or JSON (``.json``) file (module docstring); errors name the
    file and the field."""
    path = Path(path)
    if path.suffix not in (".toml", ".json"):
        raise SceneError(f"{path}: a scene file is .toml or .json")
    try:
        text = path.read_text("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or exc})") from None
    kind = path.suffix[1:].upper()
    try:
        doc = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text, object_pairs_hook=no_duplicate_keys)
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        raise SceneError(f"{path}: not valid {kind} ({exc})") from None
    except RecursionError:  # thousands of nested brackets: both parsers recurse once a level
        raise SceneError(f"{path}: not valid {kind} (nested too deeply for a scene)") from None
    except Exception as exc:  # whatever else a parser raises: one line naming the file, not a traceback
        raise SceneError(f"{path}: not valid {kind} ({type(exc).__name__}: {' '.join(str(exc).split())})") from None
    return _scene_from(doc, str(path))
