"""What ``coassist study report`` shows, computed: a study folder read into one typed
:class:`~coassist.study.summary.StudySummary`.

:func:`summarise_study` reads the folder as evidence and computes everything the report shows
(:mod:`coassist.study.report` renders it, and writes its JSON as ``summary.json``):

- per participant and pooled: the measures of :mod:`coassist.study.measures` per condition
  (or round), each participant's value the mean over their measured trials (practice trials
  left out); pooled, the mean and sample sd (ddof = 1) of those means over participants;
- paired comparisons between every two conditions (:mod:`coassist.analysis.paired`: Wilcoxon
  signed-rank and paired t, Holm-corrected over the measures × pairs family, the mean difference
  with its paired t interval, d_z and r), and the same for the raw TLX and each Likert item (their
  own family);
- order effects: the position's F test beside condition and participant, and the means per
  condition × position (:func:`coassist.study.stats.order_effect`);
- for the iterative protocol the in-loop e_RMS per round and the stop criterion (eq. 4.13);
  for transfer and online the collection's e_RMS per trial and the models trained;
- with a calibration block: which conditions (or rounds) ran with the participant's own person
  model, and per participant what each person model was fitted from (the trials per task, the
  arm measured from the probe's trials or assumed, K̂ and Ĉ with their standard errors, the
  file's SHA-256), what it was told (``Told``) and which blocks' trials ran with it (by that
  hash), the failed attempts with their reasons;
- per participant × block and pooled per block, the measured trials that reached the target and those
  that missed (σ, overshoot and time to target are undefined for a miss: left out of those means), and
  per measure the trials its mean is over (:class:`~coassist.study.summary.TrialCount`);
- what each compared condition was: its controller, intent and, for a folder, the hash ``study init``
  recorded (:class:`~coassist.study.summary.ConditionInfo`);
- what a sample this size can and cannot show (:func:`sample_limits`), said plainly, of the comparisons' own n
  (the participants with both conditions; the range where it differs between comparisons) and Holm's m the
  comparisons with a p value (:func:`comparison_limits`); where the table of means pools participants some
  comparison leaves out (one who left after some conditions), a line names them: the comparisons carry the means of
  their own pairs.

The folder is read as evidence: the participant table and every participant's log are
cross-checked first (:meth:`~coassist.study.folder.StudyFolder.check_table`,
:meth:`~coassist.study.folder.ParticipantFolder.audit`), the answers checked against the
plan's questionnaire as they are read, and a trial file that cannot be read is one
:class:`~coassist.study.folder.StudyFolderError` line naming it: a summary never averages a
trial twice, drops a condition or a participant without saying so, or takes an answer off
its scale.
"""

from __future__ import annotations

import collections
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from coassist.analysis.paired import PairedComparison, holm_family, paired_comparison
from coassist.data import read_dataset
from coassist.data.datasets import MANIFEST_NAME
from coassist.study.folder import ORDER_NAME, STUDY_NAME, StudyFolder, StudyFolderError, finite_json
from coassist.study.measures import MEASURES, trial_measures
from coassist.study.questionnaires import TLX_ITEMS, Form, form_for, raw_tlx
from coassist.study.stats import order_effect
from coassist.study.summary import (
    AnswerStat,
    ArmFit,
    Calibration,
    Collection,
    ConditionInfo,
    CriterionCheck,
    ForceTrace,
    OrderEffect,
    ParticipantRow,
    PersonModelFit,
    PooledMeasure,
    QuestionnaireSummary,
    StudySummary,
    TrainedModel,
    TrialCount,
    finite_number,
)

__all__ = [
    "ALPHA",
    "POWER",
    "answer_value",
    "calibrated_blocks",
    "comparison_limits",
    "force_traces",
    "read_block",
    "sample_limits",
    "study_summary",
    "summarise_study",
]

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


def read_block(folder: Path):
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
    """One participant's log and trials read (audited first): the working data :func:`summarise_study` pools."""
    pf = study.participant(pid)
    order = pf.order() or {"steps": []}
    progress = pf.progress()
    pf.audit(order["steps"], progress)
    key = study.labels
    for s in order["steps"]:  # the blinding key against the labels the page showed (what each trial records)
        if s.get("label") and s.get("condition") in key and key[s["condition"]] != s["label"]:
            raise StudyFolderError(
                f"{study.folder / STUDY_NAME}: its blinding key gives condition {s['condition']!r} the label "
                f"{key[s['condition']]!r}, but {pf.folder / ORDER_NAME} showed {pid} {s['label']!r} for it "
                f"(edited by hand?); restore it from your backup of the study folder"
            )
    data: dict[str, Any] = {
        "complete": bool(order["steps"])
        and (len(progress) == len(order["steps"]) or bool(progress and progress[-1].get("stop"))),
        "steps_done": len(progress),
        "steps": len(order["steps"]),
        "blocks": {},
        "answers": {},
        "positions": {},
        "checks": [CriterionCheck.from_json(finite_json(r)) for r in progress if r["kind"] == "check"],
    }
    planned: dict[str, int] = {}  # measured trials per block, as ordered (asked calibration trials included)
    for s in order["steps"]:
        if s["kind"] == "trial" and not s["practice"]:
            data["positions"][s["block"]] = s["position"]
            planned[s["block"]] = planned.get(s["block"], 0) + 1
    data["fits"] = [_fit_summary(r, progress) for r in progress if r["kind"] == "fit"]
    for i, r in enumerate(progress):
        if r["kind"] == "questionnaire":
            data["answers"][r["block"]] = _answers(pf, i, r, form)
    for b in [*blocks, "transfer-set", "adaptation"]:
        folder = pf.block(b)
        if not (folder / MANIFEST_NAME).is_file():
            continue
        trials = read_block(folder)
        per_trial = [trial_measures(t) for t in trials]
        data["blocks"][b] = {
            "trials": per_trial,
            "means": {k: _nanmean(m[k] for m in per_trial) for k, *_ in MEASURES},
            # the model in the loop: one the study trained, by its name; else what the trial records (a model folder
            # the plan names, e.g. a transfer's source: its name and hash)
            "models": [t.meta.extra.get("study_model") or t.meta.model_id or None for t in trials],
            "count": _count(
                per_trial,
                [int(t.meta.extra.get("attempts", 1)) for t in trials],
                [t.meta.extra.get("ended") for t in trials],
            ),
            # a block cut short (the participant stopped mid-condition) has fewer trials, of other tasks: its
            # mean is not paired with the other blocks' and stays out of the pooled numbers
            "partial": len(trials) < planned.get(b, 0),
        }
    return data


def _count(per_trial: list[dict[str, float]], attempts: list[int], ended: list[Any]) -> TrialCount:
    """A block's trials counted: how many, how many reached the target (a finite time to target), per measure
    how many gave a finite value (what its mean is over), how many were started more than once (``attempts``:
    each trial's starts, ``meta.extra["attempts"]``; 1 where a trial does not record it) and how many of those that
    reached it ended otherwise than held there (``ended``: each trial's ``meta.extra["ended"]``; None where not
    recorded)."""
    return TrialCount(
        n=len(per_trial),
        reached=sum(1 for m in per_trial if math.isfinite(m["time_to_target"])),
        covered={k: sum(1 for m in per_trial if math.isfinite(m[k])) for k, *_ in MEASURES},
        repeated=sum(1 for a in attempts if a > 1),
        # entered the ball, and yet ended otherwise than held there: counted reached, a trial that did not finish
        unfinished=sum(
            1 for m, e in zip(per_trial, ended) if math.isfinite(m["time_to_target"]) and e not in (None, "target")
        ),
    )


def _total(counts: list[TrialCount]) -> TrialCount:
    """Counts summed (a block over participants)."""
    return TrialCount(
        n=sum(c.n for c in counts),
        reached=sum(c.reached for c in counts),
        covered={k: sum(c.covered.get(k, 0) for c in counts) for k, *_ in MEASURES},
        repeated=sum(c.repeated for c in counts),
        unfinished=sum(c.unfinished for c in counts),
    )


#: The lines that count the measured trials a block's :class:`TrialCount` field flags ({k} of {n}, {where}: per block).
_COUNT_NOTES = {
    "missed": (
        "{k} of {n} measured trials never reached the target ({where}): their σ, overshoot and time to target are "
        "undefined and left out of those means (each participant's mean is over the trials that reached it; the "
        "counts are in the table of trials), so a condition that misses more can look better on them than it is; "
        "f_RMS and jerk are over every trial."
    ),
    "unfinished": (
        "{k} of {n} measured trials ended otherwise than held in the target for the dwell, at the time limit or a "
        "stop ({where}): one whose tool entered the target's ball and left it again counts as reached, and its σ and "
        "time to target are those of a trial that did not finish."
    ),
    "repeated": (
        "{k} of {n} measured trials were started again after the person aborted them or their hand left ({where}): "
        "only the attempt that ran to its end is measured, so a condition people break off more often may look "
        "better than its first attempts were."
    ),
}


def _count_note(totals: Mapping[str, TrialCount], what: str) -> tuple[str, ...]:
    """The line of :data:`_COUNT_NOTES` for the field ``what`` (``missed``, ``unfinished``, ``repeated``) of the blocks' counts; none
    where no trial has it."""
    some = {b: getattr(c, what) for b, c in totals.items() if getattr(c, what)}
    if not some:
        return ()
    where = "; ".join(f"{b}: {k} of {totals[b].n}" for b, k in some.items())
    return (_COUNT_NOTES[what].format(k=sum(some.values()), n=sum(c.n for c in totals.values()), where=where),)


def _conditions(study: StudyFolder, plan) -> dict[str, ConditionInfo]:
    """What each compared condition was (the comparison protocol's, from the plan; the others: none): controller,
    intent and, for a folder, the hash ``study init`` recorded of it."""
    hashes = study.record.get("models") or {}
    return {
        c.name: ConditionInfo(controller=c.controller, intent=c.intent, intent_sha256=hashes.get(c.intent))
        for c in plan.conditions
    }


def _fit_summary(rec: dict[str, Any], progress: list[dict[str, Any]]) -> PersonModelFit:
    """What the report says of one person model's fit (a progress line of kind ``fit``): what it was fitted
    from, what it was told (:class:`~coassist.scenario.intent_registry.Told`: the arm measured or assumed)
    and ``used_in``, the blocks whose trials ran with its files (their lines' ``model_sha256``)."""
    from dataclasses import replace

    from coassist.experiments.person_calibration import thin_ways
    from coassist.scenario.intent_registry import INTENT_FOLDERS
    from coassist.study.calibration import lead_lines

    model, attempt = rec.get("model"), rec.get("attempt")
    if rec.get("failed"):
        return PersonModelFit(model=model, attempt=attempt, failed=True, reason=rec.get("reason"), redo=rec.get("redo"))
    arm = rec.get("arm") or {}
    digests = set((rec.get("sha256") or {}).values())
    used_in = [
        r["block"]
        for r in progress
        if r["kind"] == "trial" and r.get("model") == model and r.get("model_sha256") in digests
    ]
    told = replace(INTENT_FOLDERS["person-model"].told, arm="measured" if rec.get("arm_measured") else "assumed")
    blocks = rec.get("blocks")
    sha256 = rec.get("sha256")
    return PersonModelFit(
        model=model,
        attempt=attempt,
        failed=False,
        told=told.text(),
        used_in=tuple(dict.fromkeys(used_in)),
        base=rec.get("base"),
        blocks=None if blocks is None else tuple(blocks),
        trials={task: len(files) for task, files in (rec.get("demonstrations") or {}).items()},
        left_out={task: len(v) for task, v in (rec.get("left_out") or {}).items()},
        arm=ArmFit(
            measured=bool(rec.get("arm_measured")),
            note=rec.get("arm_note"),
            from_=f"{rec.get('base')}'s" if rec.get("base") else None,
            trials=arm.get("trials"),
            stiffness=finite_number(arm.get("stiffness")),
            stiffness_se=finite_number(arm.get("stiffness_se")),
            damping=finite_number(arm.get("damping")),
            damping_se=finite_number(arm.get("damping_se")),
        ),
        sha256=None if sha256 is None else dict(sha256),
        fit_seconds=finite_number(rec.get("fit_seconds")),
        thin_ways={
            task: note
            for task, paths in (rec.get("paths") or {}).items()
            if (note := thin_ways(np.asarray(paths.get("sides", []), dtype=int)))
        },
        lead=lead_lines(rec),
    )


def calibrated_blocks(plan) -> list[str]:
    """The conditions (or rounds) that ran with the participant's own person model."""
    from coassist.study.plan import CALIBRATED

    if plan.protocol == "comparison":
        return [c.name for c in plan.conditions if c.intent == CALIBRATED]
    if plan.iterative is not None:
        return [f"round-{k}" for k in range(plan.iterative.rounds)] if plan.iterative.source == CALIBRATED else []
    extra = plan.transfer or plan.online
    return [CALIBRATED] if extra is not None and extra.compare_calibrated else []


def sample_limits(
    n: int | Sequence[int],
    n_tests: int,
    simulated: bool,
    ranked: int | Sequence[int] | None = None,
    n_ranked_tests: int = 1,
) -> list[str]:
    """Plain sentences on what ``n`` participants can and cannot show.

    ``n``: the participants each comparison is over (those with both conditions: its pairs), or one count for
    all; where the comparisons' counts differ (a participant who left after some conditions, a measure undefined
    for some), the sentences give the range. ``n_tests``: the comparisons with a paired t p value, Holm's m.
    ``ranked``: the pairs each comparison's Wilcoxon test ranks (its non-zero differences; ``n`` where omitted).
    ``n_ranked_tests``: the comparisons whose Wilcoxon test gave a p, that column's Holm m: the smallest
    Holm-adjusted p is m times the smallest p, so at least m·2/2^k for the most pairs k any test ranks.

    The smallest two-sided p of the exact Wilcoxon signed-rank test on k ranked pairs is 2/2^k (a zero difference
    is dropped, so six pairs with one zero can give no p below 2/2^5 = 0.0625); the smallest
    Cohen's d_z a two-sided paired t test detects with :data:`POWER` at :data:`ALPHA` (and at α/n_tests,
    Holm's smallest threshold) solves 1 − β = P(|T| > t_{1−α/2, n−1}), T noncentral t with n − 1 degrees of
    freedom and noncentrality d_z √n.
    """
    from scipy import optimize, stats

    each = [n] if isinstance(n, int) else [int(k) for k in n]
    counts = sorted(set(each) - {0})
    lines = []
    if not counts:
        return ["No participant has finished two conditions yet: nothing to compare."]
    lo, hi = counts[0], counts[-1]
    # the Wilcoxon test's floor is of the pairs it ranks: where a difference is zero, fewer than the participants
    each_ranked = each if ranked is None else [ranked] if isinstance(ranked, int) else [int(k) for k in ranked]
    if len(each_ranked) != len(each):
        raise ValueError(f"sample_limits: {len(each_ranked)} ranked counts for {len(each)} comparisons")
    ranks = sorted(set(each_ranked) - {0})
    dropped = any(r < k for r, k in zip(each_ranked, each, strict=True) if k > 0)
    over = " (over the pairs it ranks: a zero difference is dropped)" if dropped else ""
    no_floor = (
        " — it cannot reach 0.05 whatever the data; its p values show direction and consistency, not significance."
    )
    head = (
        f"{hi} participant{'s' if hi != 1 else ''}"
        if lo == hi
        else f"The comparisons are over {lo} to {hi} participants (those with both conditions; each comparison's n "
        "is in its table)"
    )
    if not ranks:
        lines.append(f"{head}: no comparison has a non-zero difference for a Wilcoxon signed-rank test to rank.")
    elif ranks[0] == ranks[-1]:
        k = ranks[0]
        lines.append(
            f"{head}: the smallest two-sided p a Wilcoxon signed-rank test can give is 2/2^{k} = {2.0 / 2**k:.3g}"
            + over
            + (no_floor if 2.0 / 2**k > 0.05 else ".")
        )
    else:
        wlo, whi = ranks[0], ranks[-1]
        lines.append(
            f"{head}: the smallest two-sided p a Wilcoxon signed-rank test can give is 2/2^{wlo} = "
            f"{2.0 / 2**wlo:.3g} with {wlo}, 2/2^{whi} = {2.0 / 2**whi:.3g} with {whi}"
            + over
            + (
                no_floor
                if 2.0 / 2**whi > 0.05
                else " — with five or fewer it cannot reach 0.05 whatever the data: those p values show direction "
                "and consistency, not significance."
                if 2.0 / 2**wlo > 0.05
                else "."
            )
        )

    def power(d: float, alpha: float, n: int) -> float:
        df, nc = n - 1, d * math.sqrt(n)
        tc = stats.t.ppf(1 - alpha / 2, df)
        # scipy's noncentral t gives NaN for the far lower tail at a large noncentrality (from d_z ≈ 2.6 at six
        # participants and α/18): that tail, P(T < −t_c) ≤ P(Z < −nc) = Φ(−nc) < 1e-10 there, counts as 0 (taken
        # as power 1 before, the Holm threshold's d_z came out too small: 3.74 for 5.74 at four and 18 tests)
        lower = float(stats.nct.cdf(-tc, df, nc))
        return float(stats.nct.sf(tc, df, nc)) + (lower if math.isfinite(lower) else 0.0)

    def detectable(alpha: float, n: int) -> float:
        hi = 1.0
        while power(hi, alpha, n) < POWER:
            hi *= 2.0
        return float(optimize.brentq(lambda d: power(d, alpha, n) - POWER, 1e-3, hi))

    if ranks and 2.0 / 2 ** ranks[-1] <= 0.05 < n_ranked_tests * 2.0 / 2 ** ranks[-1]:
        k = ranks[-1]
        lines.append(
            f"After Holm's correction over the {n_ranked_tests} Wilcoxon tests, the smallest adjusted p is at least "
            f"{n_ranked_tests}·2/2^{k} = {min(1.0, n_ranked_tests * 2.0 / 2**k):.3g}: that column cannot reach 0.05 "
            "whatever the data; read it for direction and consistency, the paired t test for significance."
        )
    tested = [k for k in (hi, lo) if k >= 3]
    if tested:
        d80 = [(detectable(ALPHA, k), detectable(ALPHA / max(n_tests, 1), k)) for k in dict.fromkeys(tested)]
        k = tested[0]
        lines.append(
            f"A paired t test on {k} participants detects, with {POWER:.0%} power at α = {ALPHA}, only effects "
            f"of Cohen's d_z ≥ {d80[0][0]:.2f} (≥ {d80[0][1]:.2f} for the smallest p after Holm's correction over "
            f"{n_tests} tests)"
            + (f"; on {lo}, d_z ≥ {d80[1][0]:.2f} (≥ {d80[1][1]:.2f})" if len(d80) > 1 else "")
            + (f"; on {lo}, fewer than three, no test has a meaningful null distribution" if lo < 3 else "")
            + ": a smaller difference may be real and go unseen. It also assumes the differences "
            "are roughly normal, which so few cannot check."
        )
    else:
        lines.append(
            "Fewer than three participants: no test has a meaningful null distribution; read the individual lines."
        )
    lines.append(
        "What it can show: whether the differences point the same way for every participant (the lines), "
        "and how large they are: the mean difference with its paired t interval (95 % if the differences are "
        "roughly normal). d_z and r are shown without an interval: a percentile bootstrap of so few pairs covers "
        "far less than it claims (74–88 % for a nominal 95 % at 3–8 participants)."
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


def comparison_limits(comparisons: Sequence[PairedComparison], simulated: bool) -> list[str]:
    """:func:`sample_limits` of the measures' comparisons: over each one's own n (the participants with both
    conditions, not everyone with some block), the Wilcoxon floor over the pairs each ranks (its non-zero
    differences), Holm's m the comparisons whose paired t test gave a p value."""
    return sample_limits(
        [c.n for c in comparisons],
        sum(1 for c in comparisons if math.isfinite(c.p_t)),
        simulated,
        ranked=[c.n_wilcoxon for c in comparisons],
        n_ranked_tests=sum(1 for c in comparisons if math.isfinite(c.p_wilcoxon)),
    )


def summarise_study(folder: str | Path) -> StudySummary:
    """Everything the report shows, computed from the study folder ``folder`` (module docstring)."""
    study = StudyFolder(folder)
    plan = study.plan()
    blocks = _blocks(study, plan)
    table = study.check_table()
    form = form_for(plan.questionnaire)
    participants = {pid: _participant_data(study, pid, blocks, form) for pid in sorted(table)}
    # per participant (mean over their measured trials of each whole block) and pooled (mean and sd over
    # participants); a block cut short is left out of both, of the comparisons and of the order effects
    partial = {pid: [b for b in blocks if d["blocks"].get(b, {}).get("partial")] for pid, d in participants.items()}
    measured = {
        pid: d for pid, d in participants.items() if any(b in d["blocks"] and b not in partial[pid] for b in blocks)
    }
    per_participant: dict[str, dict[str, dict[str, float]]] = {
        pid: {b: d["blocks"][b]["means"] for b in blocks if b in d["blocks"] and b not in partial[pid]}
        for pid, d in measured.items()
    }
    counts = {pid: {b: measured[pid]["blocks"][b]["count"] for b in means} for pid, means in per_participant.items()}
    totals = {b: _total([c[b] for c in counts.values() if b in c]) for b in blocks}
    pooled: dict[str, dict[str, PooledMeasure]] = {}
    for b in blocks:
        pooled[b] = {}
        for key, *_ in MEASURES:
            vals = np.array([per_participant[p][b][key] for p in per_participant if b in per_participant[p]], float)
            vals = vals[np.isfinite(vals)]
            pooled[b][key] = PooledMeasure(
                mean=float(vals.mean()) if vals.size else None,
                sd=float(vals.std(ddof=1)) if vals.size > 1 else None,
                n=int(vals.size),
            )
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
    q_pooled: dict[str, dict[str, AnswerStat]] = {}
    for b in blocks:
        q_pooled[b] = {}
        for qk in q_keys + [f"tlx_{k}" for k, *_ in TLX_ITEMS]:
            qv = [v for v in (answer_value(answers[p].get(b), qk) for p in answers) if math.isfinite(v)]
            q_pooled[b][qk] = AnswerStat(
                mean=float(np.mean(qv)) if qv else None,
                n=len(qv),
                median=float(np.median(qv)) if qv else None,
            )
    for qk in q_keys:
        for a, b in pairs:
            va = {p: answer_value(ans.get(a), qk) for p, ans in answers.items()}
            vb = {p: answer_value(ans.get(b), qk) for p, ans in answers.items()}
            if any(math.isfinite(v) for v in va.values()) and any(math.isfinite(v) for v in vb.values()):
                q_comparisons.append(paired_comparison(qk, a, b, va, vb, seed=plan.seed))
    q_comparisons = holm_family(q_comparisons)
    order = (
        {
            key: OrderEffect.from_json(
                finite_json(
                    order_effect(
                        [
                            (p, b, measured[p]["positions"].get(b, 0), per_participant[p][b][key])
                            for p in per_participant
                            for b in per_participant[p]
                        ]
                    )
                )
            )
            for key, *_ in MEASURES
        }
        if plan.protocol != "iterative"
        else {}
    )
    # any, not all: one person beside simulated operators (a folder of an older version) keeps the caveat
    simulated = any(r.get("simulated") for r in table.values())
    return StudySummary(
        study=plan.name,
        protocol=plan.protocol,
        world=plan.world,
        plan_sha256=study.record["plan_sha256"],
        labels=study.labels,
        blocks=tuple(blocks),
        participants={
            pid: ParticipantRow(
                number=table[pid]["number"],
                row=table[pid]["row"],
                simulated=table[pid]["simulated"],
                complete=d["complete"],
                steps_done=d["steps_done"],
                steps=d["steps"],
                order=tuple(b for b, _ in sorted(d["positions"].items(), key=lambda kv: kv[1]) if b in blocks),
                means={b: {k: finite_number(v) for k, v in m.items()} for b, m in per_participant.get(pid, {}).items()},
                answers=d["answers"],
                checks=tuple(d["checks"]),
                person_models=tuple(d["fits"]),
                trials=counts.get(pid, {}),
            )
            for pid, d in participants.items()
        },
        calibration=None
        if plan.calibration is None
        else Calibration(
            trials=plan.calibration.trials, calibrated=tuple(calibrated_blocks(plan)), asked=plan.calibration.asked
        ),
        n_participants=len(participants),
        n_complete=sum(1 for d in participants.values() if d["complete"]),
        pooled=pooled,
        comparisons=tuple(comparisons),
        questionnaire=QuestionnaireSummary(pooled=q_pooled, comparisons=tuple(q_comparisons)),
        order_effects=order,
        simulated=simulated,
        limits=tuple(comparison_limits(comparisons, simulated))
        + _roster_note(
            table,
            [pid for pid, v in per_participant.items() if all(b in v for b in blocks)],
            len(study.record.get("latin_square") or ()) if plan.protocol != "iterative" and len(blocks) > 1 else 0,
            study.numbers_issued(),
        )
        + _unpaired_note(comparisons, pooled, per_participant, blocks)
        + _count_note(totals, "missed")
        + _count_note(totals, "unfinished")
        + _count_note(totals, "repeated")
        + _partial_note({pid: bs for pid, bs in partial.items() if bs}),
        collections={
            pid: {
                b: Collection(
                    e_rms=tuple(finite_number(m["e_rms"]) for m in d["blocks"][b]["trials"]),
                    models=tuple(d["blocks"][b]["models"]),
                )
                for b in ("transfer-set", "adaptation")
                if b in d["blocks"]
            }
            for pid, d in participants.items()
        },
        models=_models(study, participants),
        conditions=_conditions(study, plan),
        trials=totals,
    )


def _unpaired_note(
    comparisons: Sequence[PairedComparison],
    pooled: Mapping[str, Mapping[str, PooledMeasure]],
    per_participant: Mapping[str, Mapping[str, Mapping[str, float]]],
    blocks: Sequence[str],
) -> tuple[str, ...]:
    """The line that says the table of means pools participants some comparisons leave out (none: no line).

    The table pools, per condition, everyone with a whole block of it and a finite value; a comparison is over
    those with both conditions (its n). Where the two differ (a participant who left after some conditions, a
    measure undefined in one of a participant's blocks), a difference of the table's means is not a comparison's
    mean difference: the line names who is in the table but not in every comparison, and why; the table of
    comparisons gives each one's means over its own pairs (``mean_a``, ``mean_b``)."""
    short = [c for c in comparisons if c.n < max(pooled[c.a][c.metric].n, pooled[c.b][c.metric].n)]
    if not short:
        return ()

    def value(pid: str, block: str, metric: str) -> float:
        return per_participant[pid].get(block, {}).get(metric, math.nan)

    why: dict[str, list[str]] = {}
    for pid in sorted(per_participant):
        out = [c for c in short if math.isfinite(value(pid, c.a, c.metric)) != math.isfinite(value(pid, c.b, c.metric))]
        if not out:
            continue
        has = [b for b in blocks if b in per_participant[pid]]
        undefined: dict[str, list[str]] = {}
        for c in out:
            for x in (c.a, c.b):
                if x in has and not math.isfinite(value(pid, x, c.metric)) and x not in undefined.get(c.metric, []):
                    undefined.setdefault(c.metric, []).append(x)
        why[pid] = ([f"{', '.join(has)} only"] if len(has) < len(blocks) else []) + [
            f"{metric} undefined in {', '.join(xs)}" for metric, xs in undefined.items()
        ]
    named = "; ".join(f"{pid}: {', '.join(what)}" for pid, what in why.items())
    return (
        "The table of means pools each condition over every participant with a value in it; a comparison is over "
        f"those with both conditions (its n). {len(short)} of {len(comparisons)} comparisons leave out participants "
        f"the table includes ({named}): for those, a difference of the table's means is not the comparison's mean "
        "difference, and the table of comparisons gives each one's means over its own pairs.",
    )


def _partial_note(partial: Mapping[str, list[str]]) -> tuple[str, ...]:
    """The line that names the blocks cut short and left out of the pooled numbers (none: no line)."""
    if not partial:
        return ()
    cut = "; ".join(f"{pid}: {', '.join(bs)}" for pid, bs in sorted(partial.items()))
    return (
        f"Left out of the pooled numbers, the comparisons and the order effects: blocks stopped before their last "
        f"trial ({cut}). Their trials are in the study folder; a block's mean over some of its trials is of "
        "other tasks than the other blocks' and would not pair with them.",
    )


def _roster_note(
    table: Mapping[str, Mapping[str, Any]], compared: Sequence[str], rows: int, issued: int = 0
) -> tuple[str, ...]:
    """The lines on who the numbers are of (none where nothing is amiss): simulated operators beside people (a
    folder of an older version: ``study run`` now keeps one kind a folder); numbers up to ``issued`` (the highest the
    study gave) in no participant's record (a participant taken out of the table, withdrawn); and, where ``rows`` > 0 (the Latin square's rows: conditions
    counterbalanced), whether the participants ``compared`` (every block whole) took every row equally often."""
    lines = []
    sims = sorted(pid for pid, r in table.items() if r.get("simulated"))
    if sims and len(sims) < len(table):
        lines.append(
            f"{len(sims)} of {len(table)} participants are simulated operators ({', '.join(sims)}), pooled here with "
            "people: nothing of this report is evidence about people until they are reported apart."
        )
    numbers = {int(r["number"]) for r in table.values()}
    gone = [k for k in range(1, max(issued, *numbers, 0) + 1) if k not in numbers]
    if gone:
        lines.append(
            f"Number{'s' if len(gone) > 1 else ''} {', '.join(map(str, gone))} {'are' if len(gone) > 1 else 'is'} "
            "in no participant's record: taken out of the study (withdrawn?)"
            + (
                f", with their row of the Latin square ({', '.join(str((k - 1) % rows) for k in gone)})."
                if rows > 0
                else "."
            )
        )
    if rows > 0 and compared:
        took = collections.Counter(int(table[pid]["row"]) % rows for pid in compared)
        if len(took) < rows or len(set(took.values())) > 1:
            lines.append(
                f"The order of conditions is not counterbalanced over the {len(compared)} participants with every "
                f"block: rows 0–{rows - 1} of the Latin square were taken by "
                f"{', '.join(str(took.get(r, 0)) for r in range(rows))} of them; order and condition are balanced "
                "only when every row is taken equally often."
            )
    return tuple(lines)


def study_summary(folder: str | Path) -> dict[str, Any]:
    """:func:`summarise_study` as JSON-ready data (``summary.json``)."""
    return summarise_study(folder).to_json()


def answer_value(ans: Mapping[str, int] | None, key: str) -> float:
    """A score from one block's answers: ``raw_tlx`` (the mean of the six TLX items, 0–100), or one item
    (``tlx_<item>``, ``likert_<i>``); NaN where the block was not answered or the item not asked."""
    if not ans:
        return math.nan
    if key == "raw_tlx":
        return raw_tlx(dict(ans))
    return float(ans[key]) if key in ans else math.nan


def _models(study: StudyFolder, participants: Mapping[str, Any]) -> dict[str, dict[str, TrainedModel]]:
    out: dict[str, dict[str, TrainedModel]] = {}
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
            out.setdefault(pid, {})[m.name] = TrainedModel(
                init=info.get("init"),
                train_seconds=finite_number(info.get("train_seconds")),
                trials=len(info.get("train_trials", [])) + len(info.get("test_trials", [])),
                test_loss=finite_number(hist[-1].get("test_loss")),
            )
    return out


def force_traces(folder: str | Path, summary: StudySummary) -> dict[str, list[ForceTrace]]:
    """Block → every measured trial's planar hand force, of every participant in ``summary`` (the report's
    force figure); the trials read from the study folder ``folder`` as :func:`summarise_study` reads them."""
    study = StudyFolder(folder)
    out: dict[str, list[ForceTrace]] = {}
    for b in summary.blocks:
        out[b] = []
        for pid in summary.participants:
            f = study.participant(pid).block(b)
            if not (f / MANIFEST_NAME).is_file():
                continue
            out[b].extend(
                ForceTrace(time=t.time - t.time[0], force=np.linalg.norm(t.wrench[:, :2], axis=1))
                for t in read_block(f)
            )
    return out
