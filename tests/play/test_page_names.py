"""The page names every controller it may offer, and never offers the calibration probe as assistance."""

import re
from pathlib import Path

import coassist.play
from coassist.control.presets import CONTROLLER_KINDS

PAGE = Path(coassist.play.__file__).with_name("static") / "play.js"


def _names() -> dict[str, str]:
    text = PAGE.read_text("utf-8")
    block = text[text.index("const NAMES = {") : text.index("};", text.index("const NAMES = {"))]
    return {k.strip('"'): v for k, v in re.findall(r'("[\w-]+"|\w+):\s*"([^"]*)"', block)}


def test_every_controller_has_a_name_and_the_probe_is_no_assistance():
    names = _names()
    assert set(CONTROLLER_KINDS) <= set(names), set(CONTROLLER_KINDS) - set(names)
    assert "no assistance" in names["manual-probe"] and "assistive" not in names["manual-probe"]
    assert all("assistive" in names[k] for k in CONTROLLER_KINDS if k.startswith("cooperative"))
