"""``coassist study report``: one self-contained HTML report and a JSON summary of a study folder.

What it shows is computed in :mod:`coassist.study.summarise` (:func:`~coassist.study.summarise.summarise_study`
→ a :class:`~coassist.study.summary.StudySummary`, written as ``summary.json``); here it is drawn
(the figures: per-participant lines between conditions, force traces per condition, the
questionnaire, each embedded as a PNG) and rendered through the reports' Jinja2 templates
(:mod:`coassist._render`, ``templates/study_report.html.j2``) into ``report.html``.

The blinding key is used here (the report is the researcher's): conditions are shown by
name with their label.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from coassist._io import atomic_write_text
from coassist._render import png_data, render
from coassist.study.folder import StudyFolder
from coassist.study.measures import MEASURES
from coassist.study.summarise import (
    answer_value,
    calibrated_blocks,
    force_traces,
    sample_limits,
    study_summary,
    summarise_study,
)
from coassist.study.summary import ForceTrace, StudySummary

__all__ = [
    "calibrated_blocks",
    "person_figures",
    "render_report",
    "sample_limits",
    "study_summary",
    "summarise_study",
    "write_report",
]

#: The measures of the first screen's figure (keys of :data:`~coassist.study.measures.MEASURES`).
LINE_MEASURES = ("f_rms", "sigma", "time_to_target", "e_rms")


def _png(fig) -> str:
    """The figure as a ``data:`` URI (PNG, 100 dpi), closed."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + png_data(buf.getvalue())


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _lines_figure(s: StudySummary, keys: list[tuple[str, str, str, float]]) -> str:
    plt = _pyplot()
    blocks = s.blocks
    fig, axes = plt.subplots(1, len(keys), figsize=(3.3 * len(keys), 3.2), squeeze=False)
    for ax, (key, label, unit, scale) in zip(axes[0], keys):
        for p in s.participants.values():
            ys = [p.means.get(b, {}).get(key) for b in blocks]
            ax.plot(range(len(blocks)), [np.nan if y is None else y * scale for y in ys], "o-", color="0.6", lw=1, ms=3)
        pooled = [s.pooled[b][key].mean for b in blocks]
        ax.plot(
            range(len(blocks)),
            [np.nan if v is None else v * scale for v in pooled],
            "s-",
            color="C3",
            lw=2.5,
            label="mean",
        )
        ax.set_xticks(range(len(blocks)), [s.name(b) for b in blocks], rotation=20, fontsize=8)
        ax.set_title(f"{label} [{unit}]", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle("each grey line is one participant (mean over their measured trials)", fontsize=9)
    return _png(fig)


def _force_figure(s: StudySummary, traces: dict[str, list[ForceTrace]]) -> str:
    plt = _pyplot()
    blocks = s.blocks
    fig, axes = plt.subplots(1, len(blocks), figsize=(3.3 * len(blocks), 2.8), squeeze=False, sharey=True)
    for ax, b in zip(axes[0], blocks):
        for t in traces[b]:
            ax.plot(t.time, t.force, lw=0.6, alpha=0.5)
        ax.set_title(s.name(b), fontsize=9)
        ax.set_xlabel("t [s]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("|hand force| [N]")
    fig.suptitle("force traces: every measured trial of every participant", fontsize=9)
    return _png(fig)


def _questionnaire_figure(s: StudySummary, plan) -> str | None:
    q = s.questionnaire.pooled
    blocks = s.blocks
    keys = ([("raw_tlx", "raw TLX (0-100, lower better)")] if plan.questionnaire.tlx else []) + [
        (f"likert_{i}", f"“{t}” (1-{plan.questionnaire.likert_points})")
        for i, t in enumerate(plan.questionnaire.likert)
    ]
    if not keys or not any(q[b][k].n for b in blocks for k, _ in keys):
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(keys), figsize=(2.6 * len(keys), 2.8), squeeze=False)
    for ax, (key, title) in zip(axes[0], keys):
        for p in s.participants.values():
            ys = [answer_value(p.answers.get(b), key) for b in blocks]
            ax.plot(range(len(blocks)), ys, "o-", color="0.6", lw=1, ms=3)
        means = [q[b][key].mean for b in blocks]
        ax.plot(range(len(blocks)), [np.nan if m is None else m for m in means], "s-", color="C0", lw=2.5)
        ax.set_xticks(range(len(blocks)), [s.labels.get(b, b) for b in blocks], fontsize=8)
        ax.set_title(title, fontsize=8)
        ax.grid(alpha=0.3)
    return _png(fig)


def person_figures(folder: str | Path, s: StudySummary) -> list[tuple[str, str]]:
    """Each participant's person model as its calibration drew it (``models/<model>/<task>/person-model.png``, written
    with the fit: :mod:`coassist.study.calibration`), for the report: (caption, ``data:`` URI), in the participants'
    order, each model once (its folder holds the last fit's)."""
    from coassist.experiments.person_figure import PERSON_FIGURE_FILE
    from coassist.study.calibration import person_model_folder

    study = StudyFolder(folder)
    out = []
    for pid, p in s.participants.items():
        for model in dict.fromkeys(f.model for f in p.person_models if not f.failed and f.model):
            tasks = dict.fromkeys(t for f in p.person_models if f.model == model and not f.failed for t in f.trials)
            for task in tasks:
                png = person_model_folder(study.participant(pid).folder / "models" / model, task) / PERSON_FIGURE_FILE
                if png.is_file():
                    out.append((f"{pid}, {model}, {task}", "data:image/png;base64," + png_data(png.read_bytes())))
    return out


def render_report(
    s: StudySummary,
    plan,
    traces: dict[str, list[ForceTrace]],
    calibrations: list[tuple[str, str]] | None = None,
) -> str:
    """The report page of the summary ``s`` of a study run under ``plan`` (its questionnaire, the participants
    planned), its force figure drawn from ``traces`` (:func:`~coassist.study.summarise.force_traces`) and the
    person models' figures ``calibrations`` (:func:`person_figures`)."""
    measured = bool(s.pooled) and any(p.means for p in s.participants.values())
    lines = _lines_figure(s, [m for m in MEASURES if m[0] in LINE_MEASURES]) if measured else None
    return render(
        "study_report.html.j2",
        {
            "s": s,
            "planned": plan.participants,
            "measures": MEASURES,
            "units": {key: (unit, scale) for key, _, unit, scale in MEASURES},
            "lines": lines,
            "forces": _force_figure(s, traces),
            "questionnaire": _questionnaire_figure(s, plan),
            "calibrations": calibrations or [],
        },
    )


def write_report(folder: str | Path, out: str | Path | None = None) -> tuple[Path, Path]:
    """Write ``report.html`` and ``summary.json`` (into ``out``, default the study folder's ``report/``)."""
    folder = Path(folder)
    plan = StudyFolder(folder).plan()
    s = summarise_study(folder)
    page = render_report(s, plan, force_traces(folder, s), person_figures(folder, s))
    out = Path(out) if out is not None else folder / "report"
    out.mkdir(parents=True, exist_ok=True)
    html_path = atomic_write_text(out / "report.html", page)
    json_path = atomic_write_text(out / "summary.json", json.dumps(s.to_json(), indent=1, allow_nan=False) + "\n")
    return html_path, json_path
