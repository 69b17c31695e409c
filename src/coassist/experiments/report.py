"""A self-contained HTML report: sections of prose, tables, embedded figures and checked claims.

The report has no external references (figures are inlined as base64 PNG), so one
file can be mailed or archived as it is. Every claim carries the numbers it was
judged on, and a claim that does not hold says so, with its likely reason. The page is
rendered through the reports' Jinja2 templates (:mod:`coassist._render`), as the study's is.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coassist._io import atomic_write_text
from coassist._render import render


@dataclass(frozen=True)
class Claim:
    """A statement of the thesis checked against measurements."""

    text: str
    holds: bool
    evidence: str  # the numbers it was judged on
    reason: str = ""  # when it does not hold: the likely reason

    def to_dict(self) -> dict[str, Any]:
        return {"claim": self.text, "holds": self.holds, "evidence": self.evidence, "reason": self.reason}


@dataclass
class Section:
    title: str
    paragraphs: list[str] = field(default_factory=list)
    tables: list[tuple[str, Sequence[str], Sequence[Sequence[Any]]]] = field(default_factory=list)
    figures: list[tuple[str, bytes]] = field(default_factory=list)  # (caption, PNG bytes)
    claims: list[Claim] = field(default_factory=list)

    def add_figure(self, fig, caption: str, dpi: int = 100) -> None:
        """Render a matplotlib figure to PNG and attach it."""
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        self.figures.append((caption, buf.getvalue()))


def render_html(title: str, intro: str, sections: Sequence[Section], headline: Section | None = None) -> str:
    """The report page: title, intro, the ``headline`` (the answer, first screen), the
    claims table, then every section (the template ``experiments_report.html.j2``, :mod:`coassist._render`)."""
    return render(
        "experiments_report.html.j2", {"title": title, "intro": intro, "sections": sections, "headline": headline}
    )


def write_report(
    path: Path, title: str, intro: str, sections: Sequence[Section], headline: Section | None = None
) -> Path:
    """Write the report atomically; returns its path."""
    atomic_write_text(Path(path), render_html(title, intro, sections, headline))
    return Path(path)
