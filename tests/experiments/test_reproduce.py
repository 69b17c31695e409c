"""The whole pipeline on the tiny preset: every stage runs, the report and summary agree."""

import json
import re
from dataclasses import replace

import pytest

from coassist.experiments import reproduce as rep


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    pytest.importorskip("torch")
    out = tmp_path_factory.mktemp("reproduce")
    config = replace(rep.PRESETS["tiny"], workers=1, threads=1)
    summary = rep.run_reproduce(config, out, progress=False)
    return out, summary


def test_every_stage_ran_and_wrote_its_numbers(tiny_run):
    out, summary = tiny_run
    assert set(summary["stage_seconds"]) == {"dMPC study", "iterative training", "transfer learning", "application scenario", "real recordings"}
    it = summary["iterative"]
    assert list(it["in_loop_errors"]) == ["nominal", "M0", "M1"]
    for errors in it["in_loop_errors"].values():
        assert set(errors) == {5, 10, 20, 50} and all(v["e_rms"] > 0 for v in errors.values())
    assert len(it["deltas_e_rms_50"]) == 1
    assert set(summary["transfer"]) >= {"z trajectory", "new users", "board"}
    for target in ("z trajectory", "new users", "board"):
        assert set(summary["transfer"][target]["e_rms"]) == {"M_prev", "transfer", "finetune_all", "scratch", "nominal", "constant_velocity", "constant_acceleration", "ridge"}
    controllers = ("cooperative", "cooperative-arbitrated", "impedance", "manual")
    assert set(summary["application"]) == {f"{o}/{c}" for o in ("board", "heavy") for c in controllers}
    for result in summary["application"].values():  # the smoothness and stability measures, per trial
        for name in ("f_rms", "sigma", "overshoot", "jerk_rms", "tracking_error_rms", "peak_effort_ratio"):
            assert len(result[f"{name}_trials"]) == rep.PRESETS["tiny"].application_trials
    for key in ("M0", "M1", "TL-board-transfer", "TL-heavy-transfer"):
        assert (out / "models" / key / "history.json").is_file()


def test_report_is_complete_and_consistent_with_the_summary(tiny_run):
    out, summary = tiny_run
    html = (out / "report.html").read_text()
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["claims"] == summary["claims"]
    for title in ("1. The dMPC study", "2. Iterative training", "3. Transfer learning", "4. Application", "5. The real UR5 recordings"):
        assert title in html
    claims = summary["claims"]
    assert len(claims) >= 10
    for c in claims:
        assert c["claim"].replace("'", "&#x27;") in html
        assert isinstance(c["holds"], bool) and c["evidence"]
    # the summary table at the top lists each claim once with its verdict
    top = html.split("<h2>1. The dMPC study")[0]
    assert top.count("class='holds'") == sum(c["holds"] for c in claims)
    assert top.count("class='fails'") == sum(not c["holds"] for c in claims)
    assert len(re.findall(r"data:image/png;base64,", html)) >= 6
