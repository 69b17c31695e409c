"""The ablation's share of the oracle's benefit, by hand and against a naive bootstrap."""

import numpy as np
import pytest

from coassist.experiments.ablation import BOOTSTRAP, oracle_share


def test_share_by_hand():
    # MG − X = (1, 1, 2), mean 4/3; MG − oracle = (2, 3, 3), mean 8/3: half the oracle's benefit.
    mg, x, oracle = [4.0, 5.0, 6.0], [3.0, 4.0, 4.0], [2.0, 2.0, 3.0]
    share, lo, hi = oracle_share(mg, x, oracle)
    assert share == pytest.approx(0.5, rel=1e-15)
    assert lo <= share <= hi
    # Per-trial ratios lie in [1/3, 2/3]; a ratio of resampled means cannot leave their range.
    assert 1 / 3 - 1e-12 <= lo and hi <= 2 / 3 + 1e-12
    assert (share, lo, hi) == oracle_share(mg, x, oracle)  # seeded: the same interval every time


def test_interval_is_the_naive_percentile_bootstrap():
    rng = np.random.default_rng(5)
    mg = rng.normal(5.0, 0.5, 18)
    oracle = mg - rng.normal(2.0, 0.4, 18)
    x = mg - rng.normal(1.5, 0.6, 18)
    share, lo, hi = oracle_share(mg, x, oracle, seed=3)
    # The same resamples drawn one by one, in a loop.
    draw = np.random.default_rng(3).integers(0, 18, (BOOTSTRAP, 18))
    ratios = [np.mean(mg[i] - x[i]) / np.mean(mg[i] - oracle[i]) for i in draw]
    assert (lo, hi) == pytest.approx(tuple(np.quantile(ratios, [0.025, 0.975])), rel=1e-12)
    assert share == pytest.approx(np.mean(mg - x) / np.mean(mg - oracle), rel=1e-14)


def test_undefined_share_and_bad_input():
    assert all(np.isnan(v) for v in oracle_share([1.0, 2.0], [0.5, 1.0], [1.0, 2.0]))  # the oracle gains nothing
    share, _, _ = oracle_share([4.0, np.nan, 6.0], [3.0, 1.0, 4.0], [2.0, 2.0, 4.0])  # the NaN trial is left out
    assert share == pytest.approx((1.0 + 2.0) / (2.0 + 2.0))
    with pytest.raises(ValueError, match="one shape"):
        oracle_share([1.0, 2.0], [1.0], [1.0, 2.0])


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
