"""The project's HTML pages, rendered through Jinja2 templates: one environment for every report.

The templates are package data (``coassist/templates``): ``base.html.j2`` is the page every report
extends (doctype, head, style, body), ``experiments_report.html.j2`` the main job's report
(:mod:`coassist.experiments.report`), ``study_report.html.j2`` the study's
(:mod:`coassist.study.report`). The code that fills them computes nothing: it hands a template
its data (sections, a :class:`~coassist.study.summary.StudySummary`) and the figures as PNG.

Escaping: autoescape is on, and every ``{{ value }}`` is escaped as :func:`html.escape` escapes
(``&``, ``<``, ``>``, ``"`` as ``&quot;``, ``'`` as ``&#x27;``; the environment's ``finalize``),
so the pages keep the bytes they had when they were written with f-strings and ``html.escape``.
Markup a template builds (a macro's output) is not escaped again. Jinja2's own ``join`` filter
would escape its items with MarkupSafe's entities instead; the templates join in loops.

Layout: in an ``.html.j2`` template a line break and the indentation after it are not output
(the pages are one line, as before); a space that separates words across a line break is
written before the break. Other templates (the experiments report's CSS) are output as they are.
"""

from __future__ import annotations

import base64
import functools
import html
import math
import re
from collections.abc import Callable, Mapping
from typing import Any

import jinja2
from markupsafe import Markup

__all__ = ["cell", "environment", "fmt", "p_value", "png_data", "render"]

_BREAK = re.compile(r"\n[ \t]*")


class _Loader(jinja2.PackageLoader):
    """``coassist/templates``, with an ``.html.j2`` template's line breaks and indentation dropped (module docstring)."""

    def get_source(self, environment: jinja2.Environment, template: str) -> tuple[str, str, Callable[[], bool] | None]:
        source, filename, uptodate = super().get_source(environment, template)
        if template.endswith(".html.j2"):
            source = _BREAK.sub("", source)
        return source, filename, uptodate


def _escape(value: Any) -> Any:
    """What ``{{ value }}`` outputs: ``str(value)`` escaped by :func:`html.escape` (Markup as it is)."""
    if isinstance(value, Markup):
        return value
    return Markup(html.escape(str(value)))


def fmt(v: Any, scale: float = 1.0, digits: int = 2) -> str:
    """``v · scale`` with ``digits`` decimals; "—" where ``v`` is None or not finite."""
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v * scale:.{digits}f}"


def p_value(v: Any) -> str:
    """A p value to three decimals, "<0.001" below; "—" where it is None or NaN (no test)."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.3f}" if v >= 0.001 else "<0.001"


def cell(value: Any) -> str:
    """A table cell of the experiments report: a float to four significant digits (scientific outside
    [1e-3, 1e5)), NaN as "—"; anything else as ``str``."""
    if isinstance(value, float):
        if value != value:  # NaN
            return "—"
        if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e5):
            return f"{value:.3e}"
        return f"{value:.4g}"
    return str(value)


def png_data(png: bytes) -> str:
    """PNG bytes as a ``data:`` URI's base64 payload."""
    return base64.b64encode(png).decode("ascii")


@functools.cache
def environment() -> jinja2.Environment:
    """The one Jinja2 environment of the reports (module docstring); undefined names raise."""
    env = jinja2.Environment(
        loader=_Loader("coassist", "templates"),
        autoescape=True,
        finalize=_escape,
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,  # an included file (the CSS) is output whole
    )
    env.filters.update(fmt=fmt, p=p_value, cell=cell, png_data=png_data)
    return env


def render(template: str, context: Mapping[str, Any]) -> str:
    """The page ``template`` (a name under ``coassist/templates``) filled with ``context``."""
    return environment().get_template(template).render(context)
