"""The questionnaires asked on the page after each condition: raw NASA-TLX and Likert items.

Raw NASA-TLX (Hart 2006, "NASA-TLX: 20 years later": the unweighted variant): six
subscales rated 0–100 in steps of 5; the raw TLX score is their mean. Performance is
anchored *perfect* (0) to *failure* (100), so for every subscale lower is better.

Likert items (plan ``questionnaire.likert``, default the issue's four): a statement rated
1 (strongly disagree) … ``likert_points`` (strongly agree).

A form is sent to the page as JSON (:meth:`Form.to_page`: the items' texts and ranges,
never a condition's name); the answers come back as one list of numbers in the form's
item order and are checked here (:meth:`Form.check`): a wrong count, a value out of range
or off the scale is refused, and the page asks again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from coassist._checks import is_real_number
from coassist.study.plan import QuestionnairePlan

__all__ = ["TLX_ITEMS", "Form", "Item", "form_for"]

#: (key, title, question) of the six TLX subscales (NASA Task Load Index, paper-and-pencil version).
TLX_ITEMS = (
    ("mental", "Mental demand", "How mentally demanding was the task?"),
    ("physical", "Physical demand", "How physically demanding was the task?"),
    ("temporal", "Temporal demand", "How hurried or rushed was the pace of the task?"),
    (
        "performance",
        "Performance",
        "How successful were you in accomplishing what you were asked to do? (0 perfect, 100 failure)",
    ),
    ("effort", "Effort", "How hard did you have to work to accomplish your level of performance?"),
    ("frustration", "Frustration", "How insecure, discouraged, irritated, stressed and annoyed were you?"),
)
TLX_STEP = 5


@dataclass(frozen=True)
class Item:
    """One question: ``key`` (stored), ``text`` (shown), integer answers ``lo`` … ``hi`` in steps of ``step``."""

    key: str
    text: str
    lo: int
    hi: int
    step: int = 1
    scale: str = "likert"  # "tlx" or "likert"


@dataclass(frozen=True)
class Form:
    """The questionnaire of one condition."""

    items: tuple[Item, ...]

    def to_page(self) -> dict[str, Any]:
        return {
            "items": [
                {"key": i.key, "text": i.text, "lo": i.lo, "hi": i.hi, "step": i.step, "scale": i.scale}
                for i in self.items
            ]
        }

    def check(self, values: Any) -> dict[str, int]:
        """The answers as ``{key: value}``; ValueError (one line) when they do not fit the form."""
        if not isinstance(values, (list, tuple)) or len(values) != len(self.items):
            raise ValueError(f"expected {len(self.items)} answers, got {values!r}")
        out = {}
        for item, v in zip(self.items, values):
            if not is_real_number(v) or not math.isfinite(v) or v != int(v):
                raise ValueError(f"{item.key}: not a whole number: {v!r}")
            v = int(v)
            if not item.lo <= v <= item.hi or (v - item.lo) % item.step:
                raise ValueError(f"{item.key}: {v} is not on the scale {item.lo} … {item.hi} (step {item.step})")
            out[item.key] = v
        return out


def form_for(plan: QuestionnairePlan) -> Form:
    """The form the plan asks for: the six TLX subscales (if ``tlx``), then the Likert items."""
    items = []
    if plan.tlx:
        items += [Item(f"tlx_{k}", f"{title}: {q}", 0, 100, TLX_STEP, "tlx") for k, title, q in TLX_ITEMS]
    items += [Item(f"likert_{i}", text, 1, plan.likert_points, 1, "likert") for i, text in enumerate(plan.likert)]
    return Form(tuple(items))


def raw_tlx(answers: dict[str, int]) -> float:
    """The raw TLX score: the mean of the six subscales (0–100, lower is better); NaN without them."""
    vals = [answers[f"tlx_{k}"] for k, _, _ in TLX_ITEMS if f"tlx_{k}" in answers]
    return float(sum(vals) / len(vals)) if len(vals) == len(TLX_ITEMS) else math.nan
