"""The ablation's cells, what each source was told and the person model's claims (the share of the
oracle's benefit itself: tests/analysis/test_paired.py, gain_share)."""

import numpy as np
import pytest


@pytest.mark.slow
def test_mujoco_cells_meet_mgs_trials(tmp_path):
    """Both worlds on a one-operator, one-trial plan (minutes: every cell is a MuJoCo run): every cell
    is filled and paired with MG's trials."""
    pytest.importorskip("mujoco")
    pytest.importorskip("torch")
    from dataclasses import replace

    from coassist.experiments import pipeline
    from coassist.experiments.ablation import ARBITRATED, ablation_cells, mujoco_sources, run_ablation
    from coassist.experiments.source_training import seed_names
    from coassist.scenario.path_hypotheses import write_calibration

    cfg = replace(pipeline.REPRODUCE_PRESETS["tiny"], ablation_mujoco_trials=1, workers=1, threads=1)
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    # One tool-labelled model stands in for every learned source: the cells' plumbing is what is tested.
    folder, _ = ws.collect("D0", tasks=("curved",), trials=2, seed=1, preset=cfg.application_preset, obstacle="large")
    model = ws.train("m", [folder], init="scratch", epochs=1)
    models = {n: str(model) for s in cfg.learned_sources for n in seed_names(s, cfg.source_seeds)}
    models["paths"] = str(write_calibration(tmp_path / "paths", {}))
    result = run_ablation(ws, models)
    assert not result.skipped
    for obj in ("board", "heavy"):
        assert len(result.pairs[("mujoco", obj)]) == len(cfg.application_users)
        for source in mujoco_sources(cfg):
            assert ("mujoco", obj, ARBITRATED, source) in result.metrics
        for controller, source in ablation_cells(cfg):
            assert ("point-mass", obj, controller, source) in result.metrics


def test_each_cell_says_what_its_source_was_told():
    from coassist.experiments.ablation import SOURCES, told_of

    person, paths = told_of("person"), told_of("paths")
    assert (person.scene, person.family, person.arm, person.label) == (False, "", "measured", "")
    assert paths.scene and paths.family and paths.arm == "assumed"
    assert told_of("lstm-intent-s2") == told_of("lstm-intent")
    assert "intent" in told_of("lstm-intent").label and "tool" in told_of("lstm-tool").label
    assert told_of("nominal").text() == "the plan only"
    assert all(told_of(s).text() for s in SOURCES)  # every source of the tables has its line


def _result(person_gain: float, jerk: float, world: str = "point-mass"):
    """One object's cells: MG, the oracle (gains 2, 3, 3 N / mm) and the person model (gains ``person_gain`` × the
    oracle's per trial), so its shares are ``person_gain`` exactly."""
    from coassist.experiments.ablation import ARBITRATED, AblationResult

    mg_f, gain = np.array([4.0, 5.0, 6.0, 5.0]), np.array([2.0, 3.0, 3.0, 2.0])
    side = [1, -1, 1, -1]

    def cell(f, over, j):
        return {
            "f_rms_trials": list(f),
            "overshoot_trials": list(over),
            "clearance_deficit_trials": [0.0] * 4,
            "jerk_rms": j,
            "f_rms": float(np.mean(f)),
            "overshoot": float(np.mean(over)),
            "side": side,
        }

    mg = cell(mg_f, mg_f / 1e3, 1.0)
    metrics = {
        (world, "board", ARBITRATED, "oracle"): cell(mg_f - gain, (mg_f - gain) / 1e3, 0.9),
        (world, "board", ARBITRATED, "person"): cell(
            mg_f - person_gain * gain, (mg_f - person_gain * gain) / 1e3, jerk
        ),
    }
    return AblationResult(metrics, {(world, "board"): mg}, {}, {}, {}, "x", {})


def test_the_person_models_claims_follow_issue_40s_bars():
    from coassist.experiments.ablation import person_claims

    (good,) = person_claims(_result(0.9, 1.05))
    assert good.holds and "force 90 %" in good.evidence and "1.05× MG" in good.evidence
    assert not person_claims(_result(0.9, 1.15))[0].holds  # jerk over 1.1 × MG
    assert not person_claims(_result(0.6, 1.0))[0].holds  # overshoot share 60 % < 70 %
    (held_out,) = person_claims(_result(0.85, 1.5, world="held-out"))  # no jerk bar there; less overshoot per side
    assert held_out.holds and "held-out population" in held_out.text
    assert not person_claims(_result(0.7, 1.0, world="held-out"))[0].holds  # force 70 % < 80 %
    assert not person_claims(_result(-0.1, 1.0, world="held-out"))[0].holds  # worse than MG on both sides
