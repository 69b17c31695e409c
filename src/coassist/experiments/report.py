"""A self-contained HTML report: sections of prose, tables, embedded figures and checked claims.

The report has no external references (figures are inlined as base64 PNG), so one
file can be mailed or archived as it is. Every claim carries the numbers it was
judged on, and a claim that does not hold says so, with its likely reason.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coassist._io import atomic_write_text


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


def _cell(value: Any) -> str:
    if isinstance(value, float):
        if value != value:  # NaN
            return "—"
        if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e5):
            return f"{value:.3e}"
        return f"{value:.4g}"
    return html.escape(str(value))


_STYLE = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1{border-bottom:2px solid #333}h2{margin-top:2em;border-bottom:1px solid #bbb}
table{border-collapse:collapse;margin:0.8em 0;font-size:0.92em}th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f1f1f1}td:first-child,th:first-child{text-align:left}caption{font-weight:600;text-align:left;padding:4px 0}
figure{margin:1em 0}figure img{max-width:100%;border:1px solid #ddd}figcaption{font-size:0.9em;color:#555}
.holds{color:#17663a;font-weight:600}.fails{color:#a4161a;font-weight:600}.claim{margin:0.4em 0;padding:0.4em 0.6em;background:#fafafa;border-left:4px solid #ccc}
"""


def _tables(parts: list[str], tables) -> None:
    for caption, header, rows in tables:
        parts.append(f"<table><caption>{html.escape(caption)}</caption><tr>")
        parts.extend(f"<th>{html.escape(str(h))}</th>" for h in header)
        parts.append("</tr>")
        for row in rows:
            parts.append("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in row) + "</tr>")
        parts.append("</table>")


def render_html(title: str, intro: str, sections: Sequence[Section], headline: Section | None = None) -> str:
    """The report page: title, intro, the ``headline`` (the answer, first screen), the
    claims table, then every section."""
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>"
    ]
    parts.append(f"<h1>{html.escape(title)}</h1><p>{html.escape(intro)}</p>")
    if headline is not None:
        parts.append(f"<h2>{html.escape(headline.title)}</h2>")
        _tables(parts, headline.tables)
        parts.extend(f"<p>{html.escape(p)}</p>" for p in headline.paragraphs)
    all_claims = [c for s in sections for c in s.claims]
    if all_claims:
        parts.append(
            "<h2>The thesis' claims, checked</h2><table><tr><th>claim</th><th>verdict</th><th>evidence</th></tr>"
        )
        for c in all_claims:
            verdict = "<span class='holds'>holds</span>" if c.holds else "<span class='fails'>does not hold</span>"
            parts.append(f"<tr><td>{html.escape(c.text)}</td><td>{verdict}</td><td>{html.escape(c.evidence)}</td></tr>")
        parts.append("</table>")
    for s in sections:
        parts.append(f"<h2>{html.escape(s.title)}</h2>")
        parts.extend(f"<p>{html.escape(p)}</p>" for p in s.paragraphs)
        for c in s.claims:
            verdict = "<span class='holds'>holds</span>" if c.holds else "<span class='fails'>does not hold</span>"
            reason = f" Likely reason: {html.escape(c.reason)}" if (c.reason and not c.holds) else ""
            parts.append(
                f"<div class='claim'>{html.escape(c.text)} — {verdict}. {html.escape(c.evidence)}{reason}</div>"
            )
        _tables(parts, s.tables)
        for caption, png in s.figures:
            data = base64.b64encode(png).decode("ascii")
            parts.append(
                f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,{data}'><figcaption>{html.escape(caption)}</figcaption></figure>"
            )
    parts.append("</body></html>")
    return "".join(parts)


def write_report(
    path: Path, title: str, intro: str, sections: Sequence[Section], headline: Section | None = None
) -> Path:
    """Write the report atomically; returns its path."""
    atomic_write_text(Path(path), render_html(title, intro, sections, headline))
    return Path(path)
