"""The HTML report is self-contained and carries every claim with its verdict."""

import base64
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from coassist.experiments.report import Claim, Section, render_html, write_report


def test_report_embeds_figures_tables_and_claims(tmp_path):
    s = Section("Study", paragraphs=["What it shows <b>."])
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    s.add_figure(fig, "a line")
    plt.close(fig)
    s.tables.append(("numbers", ["case", "value"], [["a", 0.5], ["b", float("nan")], ["c", 1.23e-5]]))
    s.claims.append(Claim("x falls", True, "0.3 → 0.2"))
    s.claims.append(Claim("y rises", False, "0.3 → 0.2", reason="too few trials"))
    path = write_report(tmp_path / "r.html", "T", "intro", [s])
    text = path.read_text()
    assert "http" not in text.replace("http-equiv", "")  # no external resource
    (png,) = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", text)
    assert base64.b64decode(png)[:4] == b"\x89PNG"
    assert "What it shows &lt;b&gt;." in text  # prose is escaped
    assert text.count("class='holds'") == 2 and text.count("class='fails'") == 2  # summary table + section
    assert "Likely reason: too few trials" in text
    assert "<td>—</td>" in text and "1.230e-05" in text


def test_render_without_claims_has_no_claims_table():
    assert "claims, checked" not in render_html("T", "i", [Section("s")])
