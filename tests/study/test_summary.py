"""The study's summary as a typed result (coassist.study.summary) and the report rendered from it through the
templates (coassist.study.report), computed by coassist.study.summarise: the JSON keeps its keys and round-trips, and every table of the page holds
the summary's numbers formatted as the f-string report (before issue 43) formatted them, recomputed here from
summary.json with those rules."""

from __future__ import annotations

import json
import math
from html.parser import HTMLParser
from pathlib import Path

import pytest

from coassist.analysis.paired import PairedComparison
from coassist.study.measures import MEASURES
from coassist.study.report import write_report
from coassist.study.summarise import study_summary, summarise_study
from coassist.study.summary import AnswerStat, OrderEffect, ParticipantRow, PooledMeasure, StudySummary

from .conftest import comparison_plan

#: summary.json's keys as the report has written them since the study's first report (issue 26 on).
KEYS = [
    "study",
    "protocol",
    "world",
    "plan_sha256",
    "labels",
    "blocks",
    "participants",
    "calibration",
    "n_participants",
    "n_complete",
    "pooled",
    "comparisons",
    "questionnaire",
    "order_effects",
    "simulated",
    "limits",
    "collections",
    "models",
    "conditions",  # added with the table of what each condition was
    "trials",  # added with the counts of trials that reached the target
]
PARTICIPANT_KEYS = [
    "number",
    "row",
    "simulated",
    "complete",
    "steps_done",
    "steps",
    "order",
    "means",
    "answers",
    "checks",
    "person_models",
    "trials",  # added with the counts of trials that reached the target
]


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    """Four simulated participants through the three conditions, one measured trial each (a few seconds)."""
    from coassist.study.folder import init_study
    from coassist.study.runner import ParticipantRun

    root = tmp_path_factory.mktemp("summary")
    s = init_study(comparison_plan(root / "plans", per_condition=1, practice=0), root / "study")
    for pid in ("S01", "S02", "S03", "S04"):
        with ParticipantRun(s, pid, simulate=True) as run:
            assert run.run()
    return s.folder


@pytest.fixture(scope="module")
def written(study) -> tuple[str, dict]:
    html_path, json_path = write_report(study)
    return html_path.read_text("utf-8"), json.loads(json_path.read_text("utf-8"))


def test_the_summary_is_typed_and_its_json_keeps_its_keys_and_round_trips(study, written):
    _, on_disk = written
    s = summarise_study(study)
    assert isinstance(s, StudySummary) and list(s.participants) == ["S01", "S02", "S03", "S04"]
    p = s.participants["S02"]
    assert isinstance(p, ParticipantRow) and p.complete and len(p.order) == 3
    assert isinstance(s.pooled["manual"]["f_rms"], PooledMeasure) and s.pooled["manual"]["f_rms"].n == 4
    assert all(isinstance(c, PairedComparison) for c in s.comparisons)
    assert isinstance(s.questionnaire.pooled["manual"]["raw_tlx"], AnswerStat)
    assert isinstance(s.order_effects["f_rms"], OrderEffect)
    data = s.to_json()
    assert list(data) == KEYS and list(data["participants"]["S01"]) == PARTICIPANT_KEYS
    assert data == on_disk == study_summary(study)  # what write_report wrote, and the dict the callers read
    assert StudySummary.from_json(on_disk).to_json() == on_disk  # summary.json back into the typed result
    again = StudySummary.from_json(json.loads(json.dumps(data, allow_nan=False)))
    assert again.participants == s.participants and again.pooled == s.pooled and again.limits == s.limits
    # a test with no result is null in the JSON and NaN again in the typed comparison
    nan_fields = [(i, k) for i, c in enumerate(on_disk["comparisons"]) for k, v in c.items() if v is None]
    for i, k in nan_fields:
        assert math.isnan(getattr(again.comparisons[i], k))
    # the pooled mean is the mean of the participants' means, their sd the sample sd (ddof = 1)
    vals = [data["participants"][q]["means"]["manual"]["f_rms"] for q in data["participants"]]
    m = sum(vals) / 4
    assert data["pooled"]["manual"]["f_rms"]["mean"] == pytest.approx(m, rel=1e-12)
    assert data["pooled"]["manual"]["f_rms"]["sd"] == pytest.approx(
        math.sqrt(sum((v - m) ** 2 for v in vals) / 3), rel=1e-12
    )


class _Tables(HTMLParser):
    """The page's tables as lists of rows of cell texts (th and td alike; a span's text is its cell's)."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[list[list[str]]] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append("".join(self._cell))
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _fmt(v, scale=1.0, digits=2):  # the f-string report's _fmt
    return "—" if v is None else f"{v * scale:.{digits}f}"


def _p(v):  # the f-string report's _p
    return "—" if v is None else (f"{v:.3f}" if v >= 0.001 else "<0.001")


def _zeros(c):  # the Wilcoxon test's pairs where zero differences were dropped (added with n_wilcoxon)
    k = c["n"] - c["n_wilcoxon"]
    return f" (n={c['n_wilcoxon']}: {k} zero difference{'s' if k != 1 else ''} dropped)" if k else ""


def test_every_table_holds_the_summary_formatted_as_the_f_string_report_did(written):
    page, j = written
    parser = _Tables()
    parser.feed(page)
    tables = parser.tables
    blocks, labels = j["blocks"], j["labels"]

    def name(b):
        return f"{b} ({labels[b]})" if labels.get(b) else b

    pooled = [["", *[name(b) for b in blocks]]] + [
        [f"{label} [{unit}]"]
        + [
            f"{_fmt(j['pooled'][b][key]['mean'], scale)} ± {_fmt(j['pooled'][b][key]['sd'], scale)} "
            f"(n={j['pooled'][b][key]['n']})"
            for b in blocks
        ]
        for key, label, unit, scale in MEASURES
    ]
    units = {key: (unit, scale) for key, _, unit, scale in MEASURES}
    comparisons = [
        [
            "measure",
            "a − b",
            "n",
            "a; b",  # added with the means over each comparison's own pairs (the table of means may pool more)
            "mean difference [95 % paired t]",  # was "[95 % bootstrap]": the interval is the paired t one now
            "d_z",  # was "d_z [95 % bootstrap]": a percentile bootstrap of a few pairs covers far less than 95 %
            "rank-biserial r",
            "Wilcoxon p / Holm",
            "paired t p / Holm",
        ]
    ] + [
        [
            c["metric"],
            f"{name(c['a'])} − {name(c['b'])}",
            str(c["n"]),
            f"{_fmt(c['mean_a'], units[c['metric']][1])}; {_fmt(c['mean_b'], units[c['metric']][1])} "
            f"{units[c['metric']][0]}",
            f"{_fmt(c['mean_diff'], units[c['metric']][1])} [{_fmt(c['mean_diff_ci'][0], units[c['metric']][1])}, "
            f"{_fmt(c['mean_diff_ci'][1], units[c['metric']][1])}] {units[c['metric']][0]}",
            _fmt(c["dz"]),
            _fmt(c["rank_biserial"]),
            f"{_p(c['p_wilcoxon'])} / {_p(c['p_wilcoxon_holm'])}{_zeros(c)}",
            f"{_p(c['p_t'])} / {_p(c['p_t_holm'])}",
        ]
        for c in j["comparisons"]
    ]
    questionnaire = [["item", "a − b", "n", "mean difference", "rank-biserial r", "Wilcoxon p / Holm"]] + [
        [
            c["metric"],
            f"{name(c['a'])} − {name(c['b'])}",
            str(c["n"]),
            _fmt(c["mean_diff"]),
            _fmt(c["rank_biserial"]),
            f"{_p(c['p_wilcoxon'])} / {_p(c['p_wilcoxon_holm'])}{_zeros(c)}",
        ]
        for c in j["questionnaire"]["comparisons"]
    ]
    order = [["measure", "F", "df", "p"]] + [
        [k, _fmt(v["F"]), f"{v['df1']}, {v['df2']}", _p(v["p"])] for k, v in j["order_effects"].items()
    ]
    participants = [["id", "#", "", "order", "steps done"]] + [
        [
            pid,
            str(p["number"]),
            "simulated" if p["simulated"] else "person",
            " → ".join(labels.get(b, b) for b in p["order"]),
            f"{p['steps_done']}/{p['steps']}",
        ]
        for pid, p in j["participants"].items()
    ]
    conditions = [["condition", "controller", "intent", "intent sha256"]] + [
        [name(b), c["controller"], c["intent"], "—"] for b, c in j["conditions"].items()
    ]
    assert conditions[1:] == [
        [name("assistive"), "cooperative", "present-held", "—"],
        [name("impedance"), "impedance", "nominal", "—"],
        [name("manual"), "manual", "nominal", "—"],
    ]
    reached = (
        [["", *[name(b) for b in blocks]]]
        + [
            [
                pid,
                *[
                    f"{c['reached']} of {c['n']}" + (f" ({c['missed']} missed)" if c["missed"] else "")
                    for c in (p["trials"][b] for b in blocks)
                ],
            ]
            for pid, p in j["participants"].items()
        ]
        + [
            [
                "all",
                *[
                    f"{j['trials'][b]['reached']} of {j['trials'][b]['n']} (missed {j['trials'][b]['missed']}, "
                    f"{_fmt(j['trials'][b]['miss_rate'], 100, 0)} %)"
                    for b in blocks
                ],
            ]
        ]
    )
    # a comparison study with the questionnaire: these seven tables, in this order, and no other (the conditions'
    # and the trials' were added to the five of the f-string report)
    assert tables == [conditions, pooled, reached, comparisons, questionnaire, order, participants]
    # not vacuous: 3 pairs × every measure, 3 pairs × (raw TLX + the Likert items), 4 participants
    assert len(comparisons) == 1 + 3 * len(MEASURES) and len(participants) == 5 and len(questionnaire) > 1
    assert any(row[-1] != "— / —" for row in comparisons[1:])  # the paired t ran on some measure
    # the lead paragraph and the limits, as the f-string report wrote them
    lead = (
        f"<p class=lead>4 of 4 participants complete (4 planned) — simulated participants. Conditions (label on "
        f"the page): {', '.join(name(b) for b in blocks)}.</p>"
    )
    assert lead in page
    assert "".join(f"<li>{line}</li>" for line in j["limits"]).replace("'", "&#x27;") in page
    assert page.count("<img src='data:image/png;base64,") == 3  # the lines, the force traces, the questionnaire
    assert not any("leave out participants" in line for line in j["limits"])  # all four in every comparison


def test_a_summary_missing_a_key_is_refused_naming_it(written):
    _, on_disk = written
    broken = {k: v for k, v in on_disk.items() if k != "order_effects"}
    with pytest.raises(ValueError, match=r"\['order_effects'\]"):
        StudySummary.from_json(broken)
    comparison = {k: v for k, v in on_disk["comparisons"][0].items() if k != "p_t_holm"}
    with pytest.raises(ValueError, match=r"\['p_t_holm'\]"):
        StudySummary.from_json({**on_disk, "comparisons": [comparison]})


def test_a_block_stopped_before_its_last_trial_stays_out_of_the_pooled_numbers(tmp_path):
    """A participant stopped mid-condition has a block of fewer trials, of other tasks than the other blocks': its
    mean is not paired with theirs. The pooled mean is the other participant's alone, the comparisons do not count
    it, and a line names the block (before, "4.29 ± 1.49 (n=2)" pooled a half block as a whole one)."""
    from coassist.study.folder import init_study
    from coassist.study.runner import ParticipantRun

    s = init_study(comparison_plan(tmp_path / "plans", per_condition=2, practice=0), tmp_path / "study")
    with ParticipantRun(s, "S01", simulate=True) as run:
        assert run.run()
    with ParticipantRun(s, "S02", simulate=True) as run:
        trials = [k for k, step in enumerate(run.steps) if step["kind"] == "trial"]
        block = run.steps[trials[0]]["block"]
        assert run.steps[trials[1]]["block"] == block  # two trials a block
        run.steps = run.steps[: trials[1]]  # stopped before the block's second trial
        assert run.run()
    summary = summarise_study(s.folder)
    assert not summary.participants["S02"].complete
    assert block not in summary.participants["S02"].means
    s01 = summary.participants["S01"].means[block]["f_rms"]
    pooled = summary.pooled[block]["f_rms"]
    assert pooled.n == 1 and pooled.mean == s01
    assert all(c.n == 1 for c in summary.comparisons if block in (c.a, c.b))  # S01's pair alone
    assert any(f"S02: {block}" in line for line in summary.limits)
    assert summary.n_participants == 2 and summary.to_json()["limits"] == list(summary.limits)


def test_the_summary_and_the_report_say_what_each_condition_was(tmp_path):
    """Each condition's controller and intent, and for a folder the hash study init recorded of it (before, the
    report listed names and labels only: what a condition was could not be read from it)."""
    import hashlib

    from coassist.scenario.path_hypotheses import write_calibration
    from coassist.study.folder import StudyFolder, init_study
    from coassist.study.runner import ParticipantRun

    calibration = write_calibration(tmp_path / "calibration", {})
    marker = next(p for p in Path(calibration).iterdir() if p.suffix == ".json")
    plan = comparison_plan(tmp_path / "plans", per_condition=1, practice=0)
    plan.write_text(
        plan.read_text().replace(
            'controller = "impedance"', f'controller = "cooperative-arbitrated"\nintent = "{calibration}"'
        )
    )
    study = init_study(plan, tmp_path / "study")
    with ParticipantRun(study, "S01", simulate=True) as run:
        assert run.run()
    digest = hashlib.sha256(marker.read_bytes()).hexdigest()
    assert StudyFolder(study.folder).record["models"] == {str(calibration): digest}
    html_path, json_path = write_report(study.folder)
    assert json.loads(json_path.read_text())["conditions"] == {
        "assistive": {"controller": "cooperative", "intent": "present-held", "intent_sha256": None},
        "impedance": {"controller": "cooperative-arbitrated", "intent": str(calibration), "intent_sha256": digest},
        "manual": {"controller": "manual", "intent": "nominal", "intent_sha256": None},
    }
    parser = _Tables()
    parser.feed(html_path.read_text())
    labels = study.labels
    assert parser.tables[0] == [
        ["condition", "controller", "intent", "intent sha256"],
        [f"assistive ({labels['assistive']})", "cooperative", "present-held", "—"],
        [f"impedance ({labels['impedance']})", "cooperative-arbitrated", str(calibration), digest[:12]],
        [f"manual ({labels['manual']})", "manual", "nominal", "—"],
    ]


def test_trials_that_never_reached_the_target_are_counted_not_silently_dropped(tmp_path):
    """A 4 mm target ball: the simulated participant reaches it in one of the two trials of every condition (the
    curved path misses). σ, overshoot and time to target are undefined for the miss and left out of the means; the
    summary and the report count the miss and say how many trials each mean is over (before, nothing did)."""
    from coassist.study.folder import init_study
    from coassist.study.measures import trial_measures
    from coassist.study.runner import ParticipantRun
    from coassist.study.summarise import read_block

    timing = "motion_time = 3.0\ndwell = 1.0\narrive_radius = 0.004\ntime_limit = 8.0"
    s = init_study(comparison_plan(tmp_path / "plans", per_condition=2, practice=0, timing=timing), tmp_path / "study")
    with ParticipantRun(s, "S01", simulate=True) as run:
        assert run.run()
    html_path, json_path = write_report(s.folder)
    j = json.loads(json_path.read_text())
    covered = {"f_rms": 2, "sigma": 1, "overshoot": 1, "jerk": 2, "time_to_target": 1, "e_rms": 2}
    # the trial that reached the 4 mm ball left it again and ended at the time limit: unfinished, and said so
    count = {"n": 2, "reached": 1, "missed": 1, "miss_rate": 0.5, "covered": covered, "repeated": 0, "unfinished": 1}
    blocks = ["assistive", "impedance", "manual"]
    assert j["participants"]["S01"]["trials"] == {b: count for b in blocks}
    assert j["trials"] == {b: count for b in blocks}
    for b in blocks:  # the mean is the reached trial's alone
        ttt = [trial_measures(t)["time_to_target"] for t in read_block(s.participant("S01").block(b))]
        assert sum(math.isnan(v) for v in ttt) == 1
        assert j["participants"]["S01"]["means"][b]["time_to_target"] == pytest.approx(
            next(v for v in ttt if not math.isnan(v)), rel=1e-12
        )
    assert [t.meta.extra["ended"] for b in blocks for t in read_block(s.participant("S01").block(b))] == [
        "time_limit"
    ] * 6
    assert j["limits"][-1] == (
        "3 of 6 measured trials ended otherwise than held in the target for the dwell, at the time limit or a stop "
        "(assistive: 1 of 2; impedance: 1 of 2; manual: 1 of 2): one whose tool entered the target's ball and left it "
        "again counts as reached, and its σ and time to target are those of a trial that did not finish."
    )
    assert j["limits"][-2] == (
        "3 of 6 measured trials never reached the target (assistive: 1 of 2; impedance: 1 of 2; manual: 1 of 2): "
        "their σ, overshoot and time to target are undefined and left out of those means (each participant's mean "
        "is over the trials that reached it; the counts are in the table of trials), so a condition that misses "
        "more can look better on them than it is; f_RMS and jerk are over every trial."
    )
    parser = _Tables()
    parser.feed(html_path.read_text())
    name = {b: f"{b} ({s.labels[b]})" for b in blocks}
    assert parser.tables[2] == [
        ["", *name.values()],
        ["S01", *["1 of 2 (1 missed); 1 unfinished"] * 3],
        ["all", *["1 of 2 (missed 1, 50 %; 1 ended at the time limit or a stop)"] * 3],
    ]


def test_a_participant_who_left_after_one_condition_is_out_of_the_limits_and_named(tmp_path):
    """Three participants complete, S04 leaves after their first condition: every comparison is over the three with
    both conditions, so the limits are of three (2/2^3 = 0.25), not four (2/2^4 = 0.125, what they said before);
    the table of means pools S04 into their condition, so a line names S04 and the comparisons carry their own
    means (over S01–S03, by hand here), which differ from the table's there."""
    import numpy as np

    from coassist.study.folder import init_study
    from coassist.study.runner import ParticipantRun

    s = init_study(comparison_plan(tmp_path / "plans", per_condition=1, practice=0), tmp_path / "study")
    for pid in ("S01", "S02", "S03"):
        with ParticipantRun(s, pid, simulate=True) as run:
            assert run.run()
    with ParticipantRun(s, "S04", simulate=True) as run:
        first = next(step["block"] for step in run.steps if step["kind"] == "trial")
        run.steps = run.steps[
            : next(k for k, step in enumerate(run.steps) if step["kind"] == "trial" and step["block"] != first)
        ]
        assert run.run()
    summary = summarise_study(s.folder)
    means = {pid: p.means for pid, p in summary.participants.items()}
    assert list(means["S04"]) == [first] and summary.pooled[first]["f_rms"].n == 4
    assert {c.n for c in summary.comparisons} == {3} and len(summary.comparisons) == 3 * len(MEASURES)
    assert all(math.isfinite(c.p_t) for c in summary.comparisons)  # Holm's m: all 18
    assert summary.limits[0] == (
        "3 participants: the smallest two-sided p a Wilcoxon signed-rank test can give is 2/2^3 = 0.25 — it cannot "
        "reach 0.05 whatever the data; its p values show direction and consistency, not significance."
    )
    assert summary.limits[1].startswith("A paired t test on 3 participants") and "over 18 tests" in summary.limits[1]
    assert (
        "The table of means pools each condition over every participant with a value in it; a comparison is over "
        f"those with both conditions (its n). 12 of 18 comparisons leave out participants the table includes (S04: "
        f"{first} only): for those, a difference of the table's means is not the comparison's mean difference, and "
        "the table of comparisons gives each one's means over its own pairs."
    ) in summary.limits
    for c in summary.comparisons:
        if c.metric == "f_rms" and first in (c.a, c.b):
            three = np.mean([means[p][first]["f_rms"] for p in ("S01", "S02", "S03")])
            four = np.mean([means[p][first]["f_rms"] for p in ("S01", "S02", "S03", "S04")])
            own = c.mean_a if c.a == first else c.mean_b
            assert own == pytest.approx(three, rel=1e-12) and summary.pooled[first]["f_rms"].mean == pytest.approx(four)
            assert abs(three - four) > 1e-6  # the table's mean is not the comparison's
    html_path, _ = write_report(s.folder)
    assert "S04: " + first + " only" in html_path.read_text()
