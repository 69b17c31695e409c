"""``coassist study report``: one self-contained HTML report and a JSON summary of a study folder.

What it holds (:func:`study_summary` → ``summary.json``, :func:`write_report` → ``report.html``
with every figure embedded as a PNG):

- per participant and pooled: the measures of :mod:`coassist.study.measures` per condition
  (or round), each participant's value the mean over their measured trials (practice trials
  left out);
- paired comparisons between every two conditions (:mod:`coassist.analysis.paired`: Wilcoxon
  signed-rank and paired t, Holm-corrected over the measures × pairs family, effect sizes
  with seeded bootstrap intervals), and the same for the raw TLX and each Likert item (their
  own family);
- order effects: the position's F test beside condition and participant, and the means per
  condition × position;
- for the iterative protocol the in-loop e_RMS per round and the stop criterion (eq. 4.13);
  for transfer and online the collection's e_RMS per trial and the models trained;
- with a calibration block: which conditions (or rounds) ran with the participant's own person
  model, and per participant what each person model was fitted from (the trials per task, the
  arm measured from the probe's trials or assumed, K̂ and Ĉ with their errors, the file's
  SHA-256), what it was told (``Told``) and which blocks' trials ran with it (by that hash), the
  failed attempts with their reasons;
- figures: per-participant lines between conditions, force traces per condition, the
  questionnaire, the learning curves;
- what a sample this size can and cannot show (:func:`sample_limits`), said plainly.

The blinding key is used here (the report is the researcher's): conditions are shown by
name with their label.

The folder is read as evidence: the participant table and every participant's log are
cross-checked first (:meth:`~coassist.study.store.StudyFolder.check_table`,
:meth:`~coassist.study.store.ParticipantFolder.audit`), the answers checked against the
plan's questionnaire as they are read, and a trial file that cannot be read is one
:class:`~coassist.study.store.StudyFolderError` line naming it: a report never averages a
trial twice, drops a condition or a participant without saying so, or takes an answer off
its scale.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from coassist._io import atomic_write_text
from coassist.analysis.paired import holm_family, paired_comparison
from coassist.data import read_dataset
from coassist.data.store import MANIFEST_NAME
from coassist.study.measures import MEASURES, trial_measures
from coassist.study.questionnaires import TLX_ITEMS, Form, form_for, raw_tlx
from coassist.study.stats import order_effect
from coassist.study.store import StudyFolder, StudyFolderError, finite_json

__all__ = ["sample_limits", "study_summary", "write_report"]

#: Power and α of the detectable-effect sentence (a paired t test, two-sided).
POWER, ALPHA = 0.8, 0.05


def _nanmean(values) -> float:
    arr = np.asarray([v for v in values if v is not None], dtype=float)
    arr = arr[np.isfinite(arr)]
    return float(arr.mean()) if arr.size else math.nan


def _blocks(study: StudyFolder, plan) -> list[str]:
    """The blocks compared (conditions in the plan's order), or the rounds for the iterative protocol."""
    if plan.protocol == "iterative":
        return [f"round-{k}" for k in range(plan.iterative.rounds)]
    return list(study.labels)


def _read_block(folder: Path):
    """The block's trials; a file that cannot be read is one line naming it (never a traceback)."""
    try:
        return read_dataset(folder).trials
    except (ValueError, OSError) as exc:  # TrialFileError, ManifestError, FileNotFoundError name the file
        what = " ".join(str(exc).split())  # one line: a parquet reader's message may span several
        raise StudyFolderError(f"{what}; restore it from your backup of the study folder") from None


def _answers(pf, i: int, rec: dict[str, Any], form: Form) -> dict[str, int]:
    """A questionnaire line's answers, checked against the plan's form as they are read."""
    answers = rec.get("answers")
    keys = [item.key for item in form.items]
    try:
        if not isinstance(answers, dict) or sorted(answers) != sorted(keys):
            raise ValueError(f"expected the items {keys}, got {answers!r}")
        return form.check([answers[k] for k in keys])
    except ValueError as exc:
        raise StudyFolderError(
            f"{pf.progress_file}: line {i + 1}: answers off the questionnaire ({exc}; edited by hand?); restore it "
            "from your backup of the study folder"
        ) from None


def _participant_data(study: StudyFolder, pid: str, blocks: list[str], form: Form) -> dict[str, Any]:
    pf = study.participant(pid)
    order = pf.order() or {"steps": []}
    progress = pf.progress()
    pf.audit(order["steps"], progress)
    data: dict[str, Any] = {
        "complete": bool(order["steps"])
        and (len(progress) == len(order["steps"]) or bool(progress and progress[-1].get("stop"))),
        "steps_done": len(progress),
        "steps": len(order["steps"]),
        "blocks": {},
        "answers": {},
        "positions": {},
        "checks": [r for r in progress if r["kind"] == "check"],
    }
    for s in order["steps"]:
        if s["kind"] == "trial" and not s["practice"]:
            data["positions"][s["block"]] = s["position"]
    data["fits"] = [_fit_summary(r, progress) for r in progress if r["kind"] == "fit"]
    for i, r in enumerate(progress):
        if r["kind"] == "questionnaire":
            data["answers"][r["block"]] = _answers(pf, i, r, form)
    for b in [*blocks, "transfer-set", "adaptation"]:
        folder = pf.block(b)
        if not (folder / MANIFEST_NAME).is_file():
            continue
        trials = _read_block(folder)
        per_trial = [trial_measures(t) for t in trials]
        forces = [(t.time - t.time[0], np.linalg.norm(t.wrench[:, :2], axis=1)) for t in trials]
        data["blocks"][b] = {
            "trials": per_trial,
            "forces": forces,
            "means": {k: _nanmean(m[k] for m in per_trial) for k, *_ in MEASURES},
            "models": [t.meta.extra.get("study_model") for t in trials],
        }
    return data


def _fit_summary(rec: dict[str, Any], progress: list[dict[str, Any]]) -> dict[str, Any]:
    """What the report says of one person model's fit (a progress line of kind ``fit``): what it was fitted
    from, what it was told (:class:`~coassist.scenario.intent_registry.Told`: the arm measured or assumed)
    and ``used_in``, the blocks whose trials ran with its files (their lines' ``model_sha256``)."""
    from dataclasses import replace

    from coassist.scenario.intent_registry import INTENT_FOLDERS

    out = {"model": rec.get("model"), "attempt": rec.get("attempt"), "failed": bool(rec.get("failed"))}
    if out["failed"]:
        return {**out, "reason": rec.get("reason"), "redo": rec.get("redo")}
    arm = rec.get("arm") or {}
    digests = set((rec.get("sha256") or {}).values())
    used_in = [
        r["block"]
        for r in progress
        if r["kind"] == "trial" and r.get("model") == rec.get("model") and r.get("model_sha256") in digests
    ]
    told = replace(INTENT_FOLDERS["person-model"].told, arm="measured" if rec.get("arm_measured") else "assumed")
    return {
        **out,
        "told": told.text(),
        "used_in": list(dict.fromkeys(used_in)),
        "base": rec.get("base"),
        "blocks": rec.get("blocks"),
        "trials": {task: len(files) for task, files in (rec.get("demonstrations") or {}).items()},
        "left_out": {task: len(v) for task, v in (rec.get("left_out") or {}).items()},
        "arm": {
            "measured": bool(rec.get("arm_measured")),
            "note": rec.get("arm_note"),
            "from": f"{rec.get('base')}'s" if rec.get("base") else None,
            "trials": arm.get("trials"),
            "stiffness": arm.get("stiffness"),
            "stiffness_se": arm.get("stiffness_se"),
            "damping": arm.get("damping"),
            "damping_se": arm.get("damping_se"),
        },
        "sha256": rec.get("sha256"),
        "fit_seconds": rec.get("fit_seconds"),
    }


def calibrated_blocks(plan) -> list[str]:
    """The conditions (or rounds) that ran with the participant's own person model."""
    from coassist.study.plan import CALIBRATED

    if plan.protocol == "comparison":
        return [c.name for c in plan.conditions if c.intent == CALIBRATED]
    if plan.iterative is not None:
        return [f"round-{k}" for k in range(plan.iterative.rounds)] if plan.iterative.source == CALIBRATED else []
    extra = plan.transfer or plan.online
    return [CALIBRATED] if extra is not None and extra.compare_calibrated else []


def sample_limits(n: int, n_tests: int, simulated: bool) -> list[str]:
    """Plain sentences on what ``n`` participants can and cannot show (module docstring)."""
    from scipy import optimize, stats

    lines = []
    if n == 0:
        return ["No participant has finished a condition yet: nothing to compare."]
    smallest = 2.0 / 2**n
    lines.append(
        f"{n} participant{'s' if n != 1 else ''}: the smallest two-sided p a Wilcoxon signed-rank test can "
        f"give is 2/2^{n} = {smallest:.3g}"
        + (
            " — it cannot reach 0.05 whatever the data; its p values show direction and consistency, not significance."
            if smallest > 0.05
            else "."
        )
    )
    if n >= 3:

        def power(d: float, alpha: float) -> float:
            df, nc = n - 1, d * math.sqrt(n)
            tc = stats.t.ppf(1 - alpha / 2, df)
            p = float(stats.nct.sf(tc, df, nc) + stats.nct.cdf(-tc, df, nc))
            return p if math.isfinite(p) else 1.0  # the noncentral t's tail fails only far past any power asked

        def detectable(alpha: float) -> float:
            hi = 1.0
            while power(hi, alpha) < POWER:
                hi *= 2.0
            return float(optimize.brentq(lambda d: power(d, alpha) - POWER, 1e-3, hi))

        d80, d80h = detectable(ALPHA), detectable(ALPHA / max(n_tests, 1))
        lines.append(
            f"A paired t test on {n} participants detects, with {POWER:.0%} power at α = {ALPHA}, only effects "
            f"of Cohen's d_z ≥ {d80:.2f} (≥ {d80h:.2f} for the smallest p after Holm's correction over "
            f"{n_tests} tests): a smaller difference may be real and go unseen. It also assumes the differences "
            "are roughly normal, which so few cannot check."
        )
    else:
        lines.append(
            "Fewer than three participants: no test has a meaningful null distribution; read the individual lines."
        )
    lines.append(
        "What it can show: whether the differences point the same way for every participant (the lines), "
        "and how large they are, with bootstrap intervals that are wide at this size (and rest on so few "
        "distinct resamples that their ends are coarse)."
    )
    lines.append(
        "What it cannot show: that a result holds for other people (the sample is small and not drawn at "
        "random), interactions between condition and order (a Latin square confounds them), or differences "
        "in rare events (safety stops, missed targets)."
    )
    if simulated:
        lines.append(
            "These participants are simulated operators (coassist study run --simulate): the numbers rehearse "
            "the plan and its analysis; they are not evidence about people, and the questionnaire answers "
            "are a function of the measured force, not opinions."
        )
    return lines


def study_summary(folder: str | Path) -> dict[str, Any]:
    """Everything the report shows, as JSON-ready data (module docstring)."""
    study = StudyFolder(folder)
    plan = study.plan()
    blocks = _blocks(study, plan)
    table = study.check_table()
    form = form_for(plan.questionnaire)
    participants = {pid: _participant_data(study, pid, blocks, form) for pid in sorted(table)}
    labels = study.labels
    measured = {pid: d for pid, d in participants.items() if any(b in d["blocks"] for b in blocks)}
    # per participant (mean over their measured trials) and pooled (mean and sd over participants)
    per_participant = {
        pid: {b: d["blocks"][b]["means"] for b in blocks if b in d["blocks"]} for pid, d in measured.items()
    }
    pooled: dict[str, dict[str, Any]] = {}
    for b in blocks:
        pooled[b] = {}
        for key, *_ in MEASURES:
            vals = np.array([per_participant[p][b][key] for p in per_participant if b in per_participant[p]], float)
            vals = vals[np.isfinite(vals)]
            pooled[b][key] = {
                "mean": float(vals.mean()) if vals.size else None,
                "sd": float(vals.std(ddof=1)) if vals.size > 1 else None,
                "n": int(vals.size),
            }
    comparisons = []
    pairs = [(a, b) for i, a in enumerate(blocks) for b in blocks[i + 1 :]]
    for key, *_ in MEASURES:
        for a, b in pairs:
            va = {p: v[a][key] for p, v in per_participant.items() if a in v}
            vb = {p: v[b][key] for p, v in per_participant.items() if b in v}
            if len(set(va) & set(vb)) >= 1:
                comparisons.append(paired_comparison(key, a, b, va, vb, seed=plan.seed))
    comparisons = holm_family(comparisons)
    # questionnaires: raw TLX and each Likert item, their own family
    q_comparisons = []
    answers = {pid: d["answers"] for pid, d in measured.items()}
    q_keys = ["raw_tlx"] + [f"likert_{i}" for i in range(len(plan.questionnaire.likert))]
    q_pooled: dict[str, dict[str, Any]] = {}
    for b in blocks:
        q_pooled[b] = {}
        for qk in q_keys + [f"tlx_{k}" for k, *_ in TLX_ITEMS]:
            qv = [v for v in (_answer(answers[p].get(b), qk) for p in answers) if math.isfinite(v)]
            q_pooled[b][qk] = {
                "mean": float(np.mean(qv)) if qv else None,
                "n": len(qv),
                "median": float(np.median(qv)) if qv else None,
            }
    for qk in q_keys:
        for a, b in pairs:
            va = {p: _answer(ans.get(a), qk) for p, ans in answers.items()}
            vb = {p: _answer(ans.get(b), qk) for p, ans in answers.items()}
            if any(math.isfinite(v) for v in va.values()) and any(math.isfinite(v) for v in vb.values()):
                q_comparisons.append(paired_comparison(qk, a, b, va, vb, seed=plan.seed))
    q_comparisons = holm_family(q_comparisons)
    order = (
        {
            key: order_effect(
                [
                    (p, b, measured[p]["positions"].get(b, 0), per_participant[p][b][key])
                    for p in per_participant
                    for b in per_participant[p]
                ]
            )
            for key, *_ in MEASURES
        }
        if plan.protocol != "iterative"
        else {}
    )
    n_complete = sum(1 for d in participants.values() if d["complete"])
    simulated = bool(table) and all(r.get("simulated") for r in table.values())
    summary = {
        "study": plan.name,
        "protocol": plan.protocol,
        "world": plan.world,
        "plan_sha256": study.record["plan_sha256"],
        "labels": labels,
        "blocks": blocks,
        "participants": {
            pid: {
                "number": table[pid]["number"],
                "row": table[pid]["row"],
                "simulated": table[pid]["simulated"],
                "complete": d["complete"],
                "steps_done": d["steps_done"],
                "steps": d["steps"],
                "order": [b for b, _ in sorted(d["positions"].items(), key=lambda kv: kv[1]) if b in blocks],
                "means": per_participant.get(pid, {}),
                "answers": d["answers"],
                "checks": d["checks"],
                "person_models": d["fits"],
            }
            for pid, d in participants.items()
        },
        "calibration": None
        if plan.calibration is None
        else {"trials": plan.calibration.trials, "calibrated": calibrated_blocks(plan)},
        "n_participants": len(participants),
        "n_complete": n_complete,
        "pooled": pooled,
        "comparisons": [c.to_json() for c in comparisons],
        "questionnaire": {"pooled": q_pooled, "comparisons": [c.to_json() for c in q_comparisons]},
        "order_effects": order,
        "simulated": simulated,
        "limits": sample_limits(len(per_participant), len(comparisons), simulated),
        "collections": {
            pid: {
                b: {"e_rms": [m["e_rms"] for m in d["blocks"][b]["trials"]], "models": d["blocks"][b]["models"]}
                for b in ("transfer-set", "adaptation")
                if b in d["blocks"]
            }
            for pid, d in participants.items()
        },
        "models": _models(study, participants),
    }
    return finite_json(summary)


def _answer(ans: dict[str, int] | None, key: str) -> float:
    if not ans:
        return math.nan
    if key == "raw_tlx":
        return raw_tlx(ans)
    return float(ans[key]) if key in ans else math.nan


def _models(study: StudyFolder, participants: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for pid in participants:
        folder = study.participant(pid).folder / "models"
        if not folder.is_dir():
            continue
        for m in sorted(p for p in folder.iterdir() if (p / "model.json").is_file()):
            try:
                meta = json.loads((m / "model.json").read_bytes().decode("utf-8"))
                if not isinstance(meta, dict):
                    raise ValueError("not a JSON object")
            except (ValueError, OSError) as exc:
                raise StudyFolderError(
                    f"{m / 'model.json'}: unreadable ({exc}); restore it from your backup of the study folder"
                ) from None
            info = meta.get("info", meta)
            hist = info.get("training_history") or [{}]
            out.setdefault(pid, {})[m.name] = {
                "init": info.get("init"),
                "train_seconds": info.get("train_seconds"),
                "trials": len(info.get("train_trials", [])) + len(info.get("test_trials", [])),
                "test_loss": hist[-1].get("test_loss"),
            }
    return out


# ----------------------------------------------------------------------------- the HTML


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _name(summary: dict[str, Any], block: str) -> str:
    label = summary["labels"].get(block)
    return f"{block} ({label})" if label else block


def _lines_figure(summary: dict[str, Any], keys: list[tuple[str, str, str, float]]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    blocks = summary["blocks"]
    fig, axes = plt.subplots(1, len(keys), figsize=(3.3 * len(keys), 3.2), squeeze=False)
    for ax, (key, label, unit, scale) in zip(axes[0], keys):
        for p in summary["participants"].values():
            ys = [p["means"].get(b, {}).get(key) for b in blocks]
            ys = [np.nan if y is None else y * scale for y in ys]
            ax.plot(range(len(blocks)), ys, "o-", color="0.6", lw=1, ms=3)
        pooled = [summary["pooled"][b][key]["mean"] for b in blocks]
        ax.plot(
            range(len(blocks)),
            [np.nan if v is None else v * scale for v in pooled],
            "s-",
            color="C3",
            lw=2.5,
            label="mean",
        )
        ax.set_xticks(range(len(blocks)), [_name(summary, b) for b in blocks], rotation=20, fontsize=8)
        ax.set_title(f"{label} [{unit}]", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.suptitle("each grey line is one participant (mean over their measured trials)", fontsize=9)
    return _png(fig)


def _force_figure(folder: Path, summary: dict[str, Any]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    study = StudyFolder(folder)
    blocks = summary["blocks"]
    fig, axes = plt.subplots(1, len(blocks), figsize=(3.3 * len(blocks), 2.8), squeeze=False, sharey=True)
    for ax, b in zip(axes[0], blocks):
        for pid in summary["participants"]:
            f = study.participant(pid).block(b)
            if not (f / MANIFEST_NAME).is_file():
                continue
            for t in _read_block(f):
                ax.plot(t.time - t.time[0], np.linalg.norm(t.wrench[:, :2], axis=1), lw=0.6, alpha=0.5)
        ax.set_title(_name(summary, b), fontsize=9)
        ax.set_xlabel("t [s]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("|hand force| [N]")
    fig.suptitle("force traces: every measured trial of every participant", fontsize=9)
    return _png(fig)


def _questionnaire_figure(summary: dict[str, Any], plan) -> str | None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q = summary["questionnaire"]["pooled"]
    blocks = summary["blocks"]
    keys = ([("raw_tlx", "raw TLX (0-100, lower better)")] if plan.questionnaire.tlx else []) + [
        (f"likert_{i}", f"“{t}” (1-{plan.questionnaire.likert_points})")
        for i, t in enumerate(plan.questionnaire.likert)
    ]
    if not keys or not any(q[b][k]["n"] for b in blocks for k, _ in keys):
        return None
    fig, axes = plt.subplots(1, len(keys), figsize=(2.6 * len(keys), 2.8), squeeze=False)
    for ax, (key, title) in zip(axes[0], keys):
        for p in summary["participants"].values():
            ys = [_answer(p["answers"].get(b), key) for b in blocks]
            ax.plot(range(len(blocks)), ys, "o-", color="0.6", lw=1, ms=3)
        ax.plot(
            range(len(blocks)),
            [np.nan if q[b][key]["mean"] is None else q[b][key]["mean"] for b in blocks],
            "s-",
            color="C0",
            lw=2.5,
        )
        ax.set_xticks(range(len(blocks)), [summary["labels"].get(b, b) for b in blocks], fontsize=8)
        ax.set_title(title, fontsize=8)
        ax.grid(alpha=0.3)
    return _png(fig)


def _fmt(v: Any, scale: float = 1.0, digits: int = 2) -> str:
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v * scale:.{digits}f}"


def _p(v: Any) -> str:
    return "—" if v is None else (f"{v:.3f}" if v >= 0.001 else "<0.001")


def _fit_row(e, pid: str, f: dict[str, Any]) -> str:
    if f["failed"]:
        return (
            f"<tr><td>{e(pid)}</td><td>{e(str(f['model']))}</td><td>{f['attempt']}</td>"
            f"<td colspan=7>failed: {e(str(f['reason']))} (run again: {e(str(f['redo'] or '—'))})</td></tr>"
        )
    arm = f["arm"]
    trials = ", ".join(f"{n} {e(task)}" for task, n in f["trials"].items())
    left = sum(f["left_out"].values())
    if arm["from"]:
        source = f"{e(arm['from'])} (not measured again: no pushes in the rounds)"
    elif arm["measured"]:
        source = f"measured ({arm['trials']} trials with pushes)"
    else:
        source = f"assumed: {e(str(arm['note']))}"
    return (
        f"<tr><td>{e(pid)}</td><td>{e(str(f['model']))}</td><td>{f['attempt']}</td><td>{trials} trials"
        f"{f' ({left} left out: not in the target)' if left else ''} of {e(', '.join(f['blocks'] or []))}</td>"
        f"<td>{source}</td><td>{_fmt(arm['stiffness'], 1, 0)} ± {_fmt(arm['stiffness_se'], 1, 0)}</td>"
        f"<td>{_fmt(arm['damping'], 1, 1)} ± {_fmt(arm['damping_se'], 1, 1)}</td>"
        f"<td>{e(f['told'])}</td><td>{e(', '.join(f['used_in']) or '—')}</td>"
        f"<td>{e(' '.join(str(v)[:12] for v in (f['sha256'] or {}).values()))}</td></tr>"
    )


def write_report(folder: str | Path, out: str | Path | None = None) -> tuple[Path, Path]:
    """Write ``report.html`` and ``summary.json`` (into ``out``, default the study folder's ``report/``)."""
    folder = Path(folder)
    study = StudyFolder(folder)
    plan = study.plan()
    summary = study_summary(folder)
    out = Path(out) if out is not None else folder / "report"
    blocks = summary["blocks"]
    e = html.escape
    parts = [
        f"<h1>Study {e(summary['study'])}: {e(summary['protocol'])}, world {e(summary['world'])}</h1>",
        f"<p class=lead>{summary['n_complete']} of {summary['n_participants']} participants complete "
        f"({plan.participants} planned){' — simulated participants' if summary['simulated'] else ''}. "
        + (
            "Conditions (label on the page): " + ", ".join(e(_name(summary, b)) for b in blocks)
            if summary["labels"]
            else "Rounds: " + ", ".join(blocks)
        )
        + "."
        + (
            f" With the participant's own person model (fitted from their {summary['calibration']['trials']} "
            f"calibration trials): {', '.join(e(_name(summary, b)) for b in summary['calibration']['calibrated'])}."
            if summary["calibration"] and summary["calibration"]["calibrated"]
            else ""
        )
        + "</p>",
    ]
    # the first screen: pooled means, the limits, the lines
    head = "".join(f"<th>{e(_name(summary, b))}</th>" for b in blocks)
    rows: list[str] = []
    for key, label, unit, scale in MEASURES:
        cells = "".join(
            f"<td>{_fmt(summary['pooled'][b][key]['mean'], scale)} ± {_fmt(summary['pooled'][b][key]['sd'], scale)}"
            f" <span class=n>(n={summary['pooled'][b][key]['n']})</span></td>"
            for b in blocks
        )
        rows.append(f"<tr><th>{e(label)} [{e(unit)}]</th>{cells}</tr>")
    parts.append(
        f"<table><caption>mean ± sd over participants (each the mean of their measured trials)</caption>"
        f"<tr><th></th>{head}</tr>{''.join(rows)}</table>"
    )
    parts.append(
        "<div class=limits><h2>What this sample can and cannot show</h2><ul>"
        + "".join(f"<li>{e(line)}</li>" for line in summary["limits"])
        + "</ul></div>"
    )
    if summary["pooled"] and any(summary["participants"][p]["means"] for p in summary["participants"]):
        parts.append(
            f"<img src='{_lines_figure(summary, [m for m in MEASURES if m[0] in ('f_rms', 'sigma', 'time_to_target', 'e_rms')])}'>"
        )
    # paired comparisons
    if summary["comparisons"]:
        rows = []  # the paired comparisons' table rows
        for c in summary["comparisons"]:
            scale = next(m[3] for m in MEASURES if m[0] == c["metric"])
            unit = next(m[2] for m in MEASURES if m[0] == c["metric"])
            ci = c["mean_diff_ci"]
            rows.append(
                f"<tr><td>{e(c['metric'])}</td><td>{e(_name(summary, c['a']))} − {e(_name(summary, c['b']))}</td>"
                f"<td>{c['n']}</td><td>{_fmt(c['mean_diff'], scale)} [{_fmt(ci[0], scale)}, {_fmt(ci[1], scale)}] {e(unit)}</td>"
                f"<td>{_fmt(c['dz'])} [{_fmt(c['dz_ci'][0])}, {_fmt(c['dz_ci'][1])}]</td>"
                f"<td>{_fmt(c['rank_biserial'])}</td><td>{_p(c['p_wilcoxon'])} / {_p(c['p_wilcoxon_holm'])}</td>"
                f"<td>{_p(c['p_t'])} / {_p(c['p_t_holm'])}</td></tr>"
            )
        parts.append(
            "<h2>Paired comparisons</h2><table><tr><th>measure</th><th>a − b</th><th>n</th><th>mean difference "
            "[95 % bootstrap]</th><th>d_z [95 % bootstrap]</th><th>rank-biserial r</th><th>Wilcoxon p / Holm</th>"
            "<th>paired t p / Holm</th></tr>" + "".join(rows) + "</table>"
        )
    parts.append(f"<h2>Force traces</h2><img src='{_force_figure(folder, summary)}'>")
    qfig = _questionnaire_figure(summary, plan)
    if qfig:
        text = "".join(
            f"<tr><td>{e(c['metric'])}</td><td>{e(_name(summary, c['a']))} − {e(_name(summary, c['b']))}</td>"
            f"<td>{c['n']}</td><td>{_fmt(c['mean_diff'])}</td><td>{_fmt(c['rank_biserial'])}</td>"
            f"<td>{_p(c['p_wilcoxon'])} / {_p(c['p_wilcoxon_holm'])}</td></tr>"
            for c in summary["questionnaire"]["comparisons"]
        )
        parts.append(
            f"<h2>Questionnaires</h2><img src='{qfig}'><table><tr><th>item</th><th>a − b</th><th>n</th>"
            f"<th>mean difference</th><th>rank-biserial r</th><th>Wilcoxon p / Holm</th></tr>{text}</table>"
        )
    if summary["order_effects"]:
        text = "".join(
            f"<tr><td>{e(k)}</td><td>{_fmt(v['F'])}</td><td>{v['df1']}, {v['df2']}</td><td>{_p(v['p'])}</td></tr>"
            for k, v in summary["order_effects"].items()
        )
        parts.append(
            "<h2>Order effects</h2><p>The position's F test in y ~ participant + condition + position "
            "(a learning or fatigue effect across the session). Condition × position cannot be separated in a "
            f"Latin square; the means per condition and position are in summary.json.</p><table><tr><th>measure</th>"
            f"<th>F</th><th>df</th><th>p</th></tr>{text}</table>"
        )
    checks = [(pid, c) for pid, p in summary["participants"].items() for c in p["checks"]]
    if checks:
        text = "".join(
            f"<tr><td>{e(pid)}</td><td>{c['round']}</td><td>{_fmt(c['e_rms_before'], 1e3)}</td>"
            f"<td>{_fmt(c['e_rms'], 1e3)}</td><td>{_fmt(c['delta'], 1e3)}</td><td>{'met' if c['met'] else 'not met'}"
            f"{' (stopped)' if c['stop'] else ''}</td></tr>"
            for pid, c in checks
        )
        parts.append(
            "<h2>Iterative training: the stop criterion (eq. 4.13)</h2><table><tr><th>participant</th><th>round</th>"
            "<th>e_RMS before [mm]</th><th>e_RMS [mm]</th><th>|Δ| [mm]</th><th>criterion</th></tr>" + text + "</table>"
        )
    if any(summary["collections"].values()):
        text = "".join(
            f"<tr><td>{e(pid)}</td><td>{e(b)}</td><td>{' '.join(_fmt(v, 1e3) for v in c['e_rms'])}</td>"
            f"<td>{e(', '.join(str(m) for m in c['models']))}</td></tr>"
            for pid, cs in summary["collections"].items()
            for b, c in cs.items()
        )
        parts.append(
            "<h2>Collections</h2><table><tr><th>participant</th><th>block</th><th>e_RMS at 0.4 s per trial [mm]"
            "</th><th>model in the loop</th></tr>" + text + "</table>"
        )
    if summary["models"]:
        text = "".join(
            f"<tr><td>{e(pid)}</td><td>{e(name)}</td><td>{e(str(m['init']))}</td><td>{m['trials']}</td>"
            f"<td>{_fmt(m['train_seconds'], 1, 1)}</td></tr>"
            for pid, ms in summary["models"].items()
            for name, m in ms.items()
        )
        parts.append(
            "<h2>Models trained</h2><table><tr><th>participant</th><th>model</th><th>init</th><th>trials</th>"
            "<th>training [s]</th></tr>" + text + "</table>"
        )
    fits = [(pid, f) for pid, p in summary["participants"].items() for f in p["person_models"]]
    if fits:
        parts.append(
            "<h2>Person models</h2><p>Each participant's own, fitted from their calibration trials under manual "
            "guidance with small known pushes (the probe), told no obstacle and no intent label: the arm (K̂, Ĉ) "
            "from the pushes' response, the paths per task from the trials that ended in the target "
            "(docs/study.md).</p><table><tr><th>participant</th><th>model</th><th>attempt</th><th>fitted from</th>"
            "<th>arm</th><th>K̂ [N/m]</th><th>Ĉ [N·s/m]</th><th>told</th><th>used in</th><th>sha256</th></tr>"
            + "".join(_fit_row(e, pid, f) for pid, f in fits)
            + "</table>"
        )
    text = "".join(
        f"<tr><td>{e(pid)}</td><td>{p['number']}</td><td>{'simulated' if p['simulated'] else 'person'}</td>"
        f"<td>{e(' → '.join(summary['labels'].get(b, b) for b in p['order']))}</td>"
        f"<td>{p['steps_done']}/{p['steps']}</td></tr>"
        for pid, p in summary["participants"].items()
    )
    parts.append(
        "<h2>Participants</h2><table><tr><th>id</th><th>#</th><th></th><th>order</th><th>steps done</th></tr>"
        + text
        + "</table>"
    )
    style = (
        "body{font-family:system-ui,sans-serif;margin:1.2em 2em;max-width:1250px;color:#222}"
        "table{border-collapse:collapse;margin:.6em 0;font-size:13px}td,th{border:1px solid #ccc;padding:3px 7px;"
        "text-align:left}caption{text-align:left;font-size:12px;color:#555}.n{color:#888;font-size:11px}"
        ".lead{font-size:15px}.limits{background:#fff8e1;border:1px solid #e0c060;padding:.2em 1em;margin:.8em 0;"
        "font-size:13px}.limits h2{font-size:15px}img{max-width:100%}h1{font-size:22px}h2{font-size:17px}"
    )
    page = (
        f"<!doctype html><html lang=en><head><meta charset=utf-8><title>coassist study {e(summary['study'])}</title>"
        f"<style>{style}</style></head><body>{''.join(parts)}<p class=n>coassist study report · plan sha256 "
        f"{summary['plan_sha256'][:12]}</p></body></html>"
    )
    out.mkdir(parents=True, exist_ok=True)
    html_path = atomic_write_text(out / "report.html", page)
    json_path = atomic_write_text(out / "summary.json", json.dumps(summary, indent=1, allow_nan=False) + "\n")
    return html_path, json_path
