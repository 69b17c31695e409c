"""The reports' one Jinja2 environment (coassist._render): autoescape on, with html.escape's entities; the
templates' layout rule; the templates shipped as package data; jinja2 a pinned core dependency."""

from __future__ import annotations

import html
import tomllib
from fnmatch import fnmatch
from pathlib import Path

import jinja2
import pytest

import coassist
from coassist._render import cell, environment, fmt, p_value, render
from coassist.experiments.report import Claim, Section, render_html

ROOT = Path(__file__).resolve().parents[1]
TEMPLATES = Path(coassist.__file__).parent / "templates"
NASTY = 'it\'s <b>"bold"</b> & more'


def test_every_value_is_escaped_as_html_escape_escapes_it():
    env = environment()
    assert env.autoescape is True
    page = env.from_string("<p title='{{ v }}'>{{ v }}</p>").render(v=NASTY)
    assert page == f"<p title='{html.escape(NASTY)}'>{html.escape(NASTY)}</p>"
    assert "&#x27;" in page and "&#39;" not in page and "<b>" not in page
    # the experiments report: a claim, a caption, a table cell and a header, escaped the same way
    s = Section(NASTY, paragraphs=[NASTY], tables=[(NASTY, [NASTY], [[NASTY]])])
    s.claims.append(Claim(NASTY, False, NASTY, reason=NASTY))
    out = render_html(NASTY, NASTY, [s])
    # 2 titles, the intro, 2 in the claims table, 8 in the section
    assert NASTY not in out and out.count(html.escape(NASTY)) == 13


def test_an_undefined_name_raises_instead_of_rendering_empty():
    with pytest.raises(jinja2.UndefinedError):
        render("experiments_report.html.j2", {"title": "t", "intro": "i", "sections": []})  # no headline


def test_formats():
    assert [fmt(None), fmt(float("nan")), fmt(0.0123, 1e3), fmt(2.0, 1, 0), fmt(3, 1, 1)] == [
        "—",
        "—",
        "12.30",
        "2",
        "3.0",
    ]
    assert [p_value(None), p_value(float("nan")), p_value(0.04567), p_value(0.001), p_value(0.000999)] == [
        "—",
        "—",
        "0.046",
        "0.001",
        "<0.001",
    ]
    assert [cell(float("nan")), cell(0.0), cell(1e-4), cell(1e5), cell(12.345678), cell(7), cell("x")] == [
        "—",
        "0",
        "1.000e-04",
        "1.000e+05",
        "12.35",
        "7",
        "x",
    ]


def test_a_template_line_break_and_its_indentation_are_not_output():
    page = render_html("T", "intro", [Section("s", paragraphs=["a", "b"])])
    assert "\n" not in page.split("</style>", 1)[1]  # the body: one line, as the f-string pages were
    assert page.endswith("<h2>s</h2><p>a</p><p>b</p></body></html>")
    # the CSS file is included as it is (its line breaks kept)
    assert (TEMPLATES / "experiments_report.css").read_text("utf-8") in page


def test_the_templates_ship_as_package_data_and_jinja2_is_pinned():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text("utf-8"))
    patterns = project["tool"]["setuptools"]["package-data"]["coassist"]
    files = sorted(p.relative_to(TEMPLATES.parent).as_posix() for p in TEMPLATES.iterdir() if p.is_file())
    assert {"templates/base.html.j2", "templates/study_report.html.j2", "templates/experiments_report.html.j2"} <= set(
        files
    )
    assert [f for f in files if not any(fnmatch(f, pat) for pat in patterns)] == []
    deps = project["project"]["dependencies"]
    assert f"jinja2=={jinja2.__version__}" in deps  # core: the study and the main job both render through it
    assert any(d.startswith("markupsafe==") for d in deps)
