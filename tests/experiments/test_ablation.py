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

    from coassist.experiments import pipeline, reproduce_config
    from coassist.experiments.ablation import run_ablation
    from coassist.experiments.ablation_cells import ARBITRATED, ablation_cells, mujoco_sources
    from coassist.experiments.source_training import calibrate_person, seed_names
    from coassist.scenario.path_hypotheses import write_calibration

    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], ablation_mujoco_trials=1, workers=1, threads=1)
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    # One tool-labelled model stands in for every learned source: the cells' plumbing is what is tested.
    folder, _ = ws.collect("D0", tasks=("curved",), trials=2, seed=1, preset=cfg.application_preset, obstacle="large")
    model = ws.train("m", [folder], init="scratch", epochs=1)
    models = {n: str(model) for s in cfg.learned_sources for n in seed_names(s, cfg.source_seeds)}
    models["paths"] = str(write_calibration(tmp_path / "paths", {}))
    models["person"] = calibrate_person(ws)  # the point-mass cells' (one probe trial per operator in tiny)
    result = run_ablation(ws, models)
    assert not result.skipped
    # the person model of the MuJoCo cells: fitted on the arm to the operator's probe trials, in its own folder,
    # once per calibration draw (the tiny preset's two), each trial meeting the draw of its seed
    from coassist.scenario.calibration_draws import draw_clusters, read_draws

    assert "person" in mujoco_sources(cfg)
    calibrated = read_draws(result.models["person-mujoco"])
    assert len(calibrated.draws) == cfg.calibration_draws == 2
    for draw in calibrated.draws:
        assert set(draw.arms) == {"user-0"} and np.isfinite(draw.arms["user-0"].stiffness)
        assert not draw.settings.object_yaw  # the MuJoCo UR5's board is rigid: the hand moves with the tip
    # each draw fitted to its own probe trial: its own demonstration (the arm of one trial is the assumed one in
    # both: fewer than three trials measure none, scenario.arm_identification.measured_arm)
    first, second = (d.paths["user-0"].weights for d in calibrated.draws)
    assert first.shape == second.shape and not np.array_equal(first, second)
    for obj in ("board", "heavy"):
        assert result.clusters[("mujoco", obj, ARBITRATED, "person")] == draw_clusters(result.pairs[("mujoco", obj)], 2)
    for obj in ("board", "heavy"):
        assert len(result.pairs[("mujoco", obj)]) == len(cfg.application_users)
        # each MuJoCo trial records the simulated operator's way round, the point-mass trial's of the same draws
        sides = {w: dict(zip(result.pairs[(w, obj)], result.mg[(w, obj)]["side"])) for w in ("point-mass", "mujoco")}
        assert all(sides["mujoco"][k] == sides["point-mass"][k] in (1, -1) for k in sides["mujoco"])
        for source in mujoco_sources(cfg):
            assert ("mujoco", obj, ARBITRATED, source) in result.metrics
        for controller, source in ablation_cells(cfg):
            assert ("point-mass", obj, controller, source) in result.metrics
    # the report shows them: the MuJoCo headline's person row, the verdict per object, how it was calibrated
    from coassist.experiments.ablation_report import ablation_section, headline_rows

    _, _, rows = headline_rows(result, "mujoco")
    assert {r[0] for r in rows if r[1].startswith("person model")} == {"board", "heavy"}
    section = ablation_section(result)
    assert sum("MuJoCo UR5: the person model" in c.text for c in section.claims) == 2
    assert any("calibrated on the arm it assists" in p for p in section.paragraphs)
    # the held-out person cells met the tiny preset's two calibration draws: their intervals resample
    # (operator, draw) clusters; the point-mass cells were given one calibration, so their pairs are independent
    assert cfg.calibration_draws == 2
    for obj in ("board", "heavy"):
        (user, seed), *_ = result.pairs[("held-out", obj)]
        assert result.clusters[("held-out", obj, ARBITRATED, "person")] == [(user, seed % 2)]
        assert ("point-mass", obj, ARBITRATED, "person") not in result.clusters
        assert result.summary()["cells"][f"held-out/{obj}/{ARBITRATED}/person"]["interval_clusters"] == 1
    # the held-out table says which people it met: the report's usual three (seen while settings were chosen), or
    # those of another population seed (reproduce.held_out_people)
    assert result.held_out_people == cfg.held_out_people == 0
    for people, says in ((0, "these operators were seen"), (100, "people of seed 100")):
        caption, _, _ = headline_rows(replace(result, held_out_people=people), "held-out")
        assert says in caption and ("no choice" in caption) == bool(people), caption
    assert result.held_out_population == cfg.held_out_population == "held-out"


def test_the_mujoco_cells_run_the_person_model_calibrated_on_the_arm(tmp_path):
    """The default's MuJoCo cells include the person model. Its job drives the point-mass cells' calibration
    trials on the arm first (the same operators, seeds, task and handle, with the probe) and hands MG's trials
    the folder it writes; calibrated in the point-mass world, the cells get the point-mass model, and no
    calibration runs on the arm."""
    from dataclasses import replace

    from coassist.experiments import pipeline, reproduce_config
    from coassist.experiments.ablation import MG_JOB, _drive_batch, calibrate_then_drive, mujoco_task
    from coassist.experiments.ablation_cells import ARBITRATED, mujoco_sources
    from coassist.experiments.source_training import calibration_options
    from coassist.sim.collect import dataset_specs

    cfg = reproduce_config.REPRODUCE_PRESETS["default"]
    assert {"person", "paths", "oracle"} <= set(mujoco_sources(cfg))
    assert cfg.mujoco_person_calibration == "mujoco"
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    fn, (probes, folder, configs, asked) = mujoco_task(ws, "person", {"person": "/point-mass/person"})
    assert fn is calibrate_then_drive and asked == cfg.person_calibration_asked
    assert folder == str(tmp_path / "models" / "person-mujoco")
    # one list of probe trials per calibration draw: the point-mass cells' draws (calibration_draw_options), driven
    # on the arm
    from coassist.experiments.source_training import calibration_draw_options

    assert cfg.calibration_draws == 4 and len(probes) == cfg.calibration_draws
    for draw, options in zip(probes, calibration_draw_options(ws, draws=cfg.calibration_draws).values()):
        point_mass = dataset_specs(**options)
        assert len(draw) == len(cfg.application_users) * cfg.person_calibration_trials
        assert [(c.world, c.controller, c.object, c.task, c.user, c.seed, c.obstacle, c.intent) for c in draw] == [
            ("mujoco", "manual-probe", "handle", s.task, s.user, s.seed, s.obstacle, "nominal") for s in point_mass
        ]
    assert len({c.seed for draw in probes for c in draw}) == sum(map(len, probes))  # no trial twice
    assert [c.seed for c in probes[0]] == [s.seed for s in dataset_specs(**calibration_options(ws, "manual-probe"))]
    _, (mg,) = mujoco_task(ws, MG_JOB, {})
    assert len(configs) == len(mg) == 2 * len(cfg.application_users) * cfg.ablation_mujoco_trials
    assert [(c.object, c.user, c.seed) for c in configs] == [(c.object, c.user, c.seed) for c in mg]
    assert {(c.world, c.controller, c.intent) for c in configs} == {("mujoco", ARBITRATED, folder)}
    assert {(c.controller, c.intent) for c in mg} == {("manual", "nominal")}

    # the filter it is written with: the point-mass world's, told the MuJoCo UR5's rigid board (no yaw mode)
    from coassist.experiments.ablation import mujoco_person_filter
    from coassist.scenario.person_model import PERSON_FILTER

    assert PERSON_FILTER.object_yaw and mujoco_person_filter() == replace(PERSON_FILTER, object_yaw=False)

    ws = pipeline.Workspace(replace(cfg, mujoco_person_calibration="point-mass"), tmp_path, progress=False)
    fn, (configs,) = mujoco_task(ws, "person", {"person": "/point-mass/person"})
    assert fn is _drive_batch and {c.intent for c in configs} == {"/point-mass/person"}


def test_the_mujoco_cells_alone_need_every_model_they_run(tmp_path):
    """run_mujoco_ablation refuses, before any run, sources it has no model or calibration of (the person
    model calibrated on the arm needs none)."""
    pytest.importorskip("mujoco")
    pytest.importorskip("pinocchio")
    from dataclasses import replace

    from coassist.experiments import pipeline, reproduce_config
    from coassist.experiments.ablation import run_mujoco_ablation

    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], ablation_mujoco_trials=1, workers=1)
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    with pytest.raises(ValueError, match="no model or calibration of lstm-intent, paths$"):
        run_mujoco_ablation(ws, {})
    with pytest.raises(ValueError, match="ablation_mujoco_trials is 0"):
        run_mujoco_ablation(pipeline.Workspace(replace(cfg, ablation_mujoco_trials=0), tmp_path, False), {})


def test_mujoco_person_calibration_is_validated():
    from dataclasses import replace

    from coassist.experiments import reproduce_config

    cfg = reproduce_config.REPRODUCE_PRESETS["default"]
    assert replace(cfg, mujoco_person_calibration="point-mass").mujoco_person_calibration == "point-mass"
    for bad in ("pointmass", "", None, 1):
        with pytest.raises(ValueError, match="reproduce.mujoco_person_calibration"):
            replace(cfg, mujoco_person_calibration=bad)


def test_each_cell_says_what_its_source_was_told():
    from coassist.experiments.ablation_cells import SOURCES, told_of

    person, paths = told_of("person"), told_of("paths")
    assert (person.scene, person.family, person.arm, person.label) == (False, "", "measured", "")
    assert paths.scene and paths.family and paths.arm == "assumed"
    # the cells' paths ran with each operator's path-hypotheses calibration: the table said nothing of it
    assert paths.person == "detour shape and side" and "from the person's trials" in paths.text()
    from coassist.experiments.application import told_text

    assert told_text("paths") == paths.text()  # the first screen's caption says the same
    assert told_of("lstm-intent-s2") == told_of("lstm-intent")
    assert "intent" in told_of("lstm-intent").label and "tool" in told_of("lstm-tool").label
    assert told_of("nominal").text() == "the plan only"
    assert all(told_of(s).text() for s in SOURCES)  # every source of the tables has its line


def _cell(f, over, jerk: float, side) -> dict:
    """A cell's metrics as application_metrics gives them: per-trial f_RMS [N] and overshoot [m], their means, the
    jerk, each trial's side of the detour."""
    return {
        "f_rms_trials": list(f),
        "overshoot_trials": list(over),
        "clearance_deficit_trials": [0.0] * len(f),
        "jerk_rms": jerk,
        "f_rms": float(np.mean(f)),
        "overshoot": float(np.mean(over)),
        "side": list(side),
    }


def _result(person_gain: float, jerk: float, world: str = "point-mass"):
    """One object's cells: MG, the oracle (gains 2, 3, 3 N / mm) and the person model (gains ``person_gain`` × the
    oracle's per trial), so its shares are ``person_gain`` exactly."""
    from coassist.experiments.ablation_cells import ARBITRATED, AblationResult

    mg_f, gain = np.array([4.0, 5.0, 6.0, 5.0]), np.array([2.0, 3.0, 3.0, 2.0])
    side = [1, -1, 1, -1]
    mg = _cell(mg_f, mg_f / 1e3, 1.0, side)
    metrics = {
        (world, "board", ARBITRATED, "oracle"): _cell(mg_f - gain, (mg_f - gain) / 1e3, 0.9, side),
        (world, "board", ARBITRATED, "person"): _cell(
            mg_f - person_gain * gain, (mg_f - person_gain * gain) / 1e3, jerk, side
        ),
    }
    return AblationResult(metrics, {(world, "board"): mg}, {}, {}, {}, "x", {})


def test_the_per_side_differences_of_a_cell_with_clusters_are_the_clusters_interval():
    """A cell whose trials share calibrations (clusters) gives each side's difference from MG the clusters' t interval,
    as its shares resample them whole; a cell without clusters the trials' paired t interval."""
    from dataclasses import replace

    from coassist.analysis.paired import clustered_difference, paired_difference
    from coassist.experiments.ablation_cells import ARBITRATED

    side = np.array([1, -1] * 6)
    mg_f = np.linspace(4.0, 6.2, 12)
    # the overshoot saved per trial: mostly its calibration's (0.6, 0.1, 0.35 mm), what its trials share
    saved = np.repeat([0.6, 0.1, 0.35], 4) + 0.02 * np.array([1, 1, -1, -1] * 3)
    over = (mg_f - saved) / 1e3
    plain = _result(0.9, 1.05, world="held-out")
    key = ("held-out", "board", ARBITRATED, "person")
    mg = _cell(mg_f, mg_f / 1e3, 1.0, side)
    metrics = {**plain.metrics, key: _cell(mg_f - 1.0, over, 1.0, side)}
    labels = [("held-out-user-0", k // 4) for k in range(12)]  # three calibrations of four trials each
    result = replace(plain, metrics=metrics, mg={("held-out", "board"): mg}, clusters={key: labels})
    unclustered = replace(result, clusters={})
    for s in (1, -1):
        on = side == s
        want = clustered_difference(over[on], (mg_f / 1e3)[on], [str(c) for c, k in zip(labels, on) if k])
        assert result.by_side(*key, "overshoot")[s][1:] == pytest.approx(want, abs=1e-15)
        assert unclustered.by_side(*key, "overshoot")[s][1:] == pytest.approx(
            paired_difference(over[on], (mg_f / 1e3)[on]), abs=1e-15
        )
        # what a calibration's trials share counts once: three clusters (t with 2 df), not six trials (5 df)
        width = lambda v: v[3] - v[2]  # noqa: E731
        assert width(result.by_side(*key, "overshoot")[s]) > width(unclustered.by_side(*key, "overshoot")[s])


def test_the_person_models_claims_follow_issue_40s_bars():
    from dataclasses import replace

    from coassist.experiments.ablation_report import cell_name, held_out_caption, person_claims

    (good,) = person_claims(_result(0.9, 1.05))
    assert good.holds and "force 90 %" in good.evidence and "1.05× MG" in good.evidence
    assert not person_claims(_result(0.9, 1.15))[0].holds  # jerk over 1.1 × MG
    assert not person_claims(_result(0.6, 1.0))[0].holds  # overshoot share 60 % < 70 %
    (held_out,) = person_claims(_result(0.85, 1.5, world="held-out"))  # no jerk bar there; less overshoot per side
    assert held_out.holds and "held-out population" in held_out.text
    assert not person_claims(_result(0.7, 1.0, world="held-out"))[0].holds  # force 70 % < 80 %
    assert not person_claims(_result(-0.1, 1.0, world="held-out"))[0].holds  # worse than MG on both sides
    # the held-out cells of the families made after every choice (reproduce.held_out_population) say so, claim and table
    unseen = replace(_result(0.85, 1.5, world="held-out"), held_out_population="unseen", held_out_people=7)
    (claim,) = person_claims(unseen)
    assert claim.holds and "board, unseen population: the person model" in claim.text, claim.text
    caption = held_out_caption(unseen.held_out_population, unseen.held_out_people)
    assert caption.startswith("the unseen population's people of seed 7: operators of detour families made after")
    assert "these operators were seen" in held_out_caption("held-out", 0)
    assert "people of seed 100" in held_out_caption("held-out", 100)
    assert cell_name(unseen, "held-out") == "held-out (unseen population)" and cell_name(unseen, "mujoco") == "mujoco"
    assert cell_name(_result(0.85, 1.5, world="held-out"), "held-out") == "held-out"


def test_a_claims_figures_are_printed_on_their_side_of_its_bar():
    """Rounded to whole points, a force share of 84.96 % read "85 %" beside a claim of ≥ 85 % that failed: a figure a
    claim is judged on keeps as many decimals as it takes to stay on its side of the bar (hand-checked cases)."""
    from coassist.experiments.ablation_report import person_claims, shown

    assert shown(84.96, 0, 85.0) == "84.96" and shown(85.0, 0, 85.0) == "85" and shown(84.4, 0, 85.0) == "84"
    assert shown(85.4, 0, 85.0) == "85" and shown(84.96, 0) == "85"  # no bar: plain rounding
    assert shown(0.3, 0, 0.0, strict=True) == "0.3" and shown(-0.3, 0, 0.0, strict=True) == "-0"  # "> 0" bars
    assert shown(0.04, 1, 0.0, strict=True, signed=True) == "+0.04" and shown(1.1004, 2, 1.1, strict=True) == "1.1004"
    # an interval printed beside such a share stays on its side too: "84.9 % [85, 85]" missed its own share
    from coassist.experiments.ablation_report import share_text

    assert share_text((0.84856, 0.84856, 0.84856), 0.85) == "84.9 % [84.9, 84.9]"
    assert share_text((0.9, 0.84856, 0.95), 0.85) == "90 % [84.9, 95]"
    assert share_text((0.9, 0.7, 0.95), 0.85, lower_bar=0.7) == "90 % [70, 95]"
    (claim,) = person_claims(_result(0.8496, 1.05))  # both shares 84.96 % exactly (_result)
    assert not claim.holds and "force 84.96 %" in claim.evidence and "overshoot 85 %" in claim.evidence


def test_a_side_no_trial_went_round_says_so():
    """A side of the detour no trial of the cell went round cannot be compared with MG: the held-out claim fails saying
    that (not a behavioural reason), and a side with one trial shows its difference from MG without an interval."""
    from coassist.experiments.ablation_report import person_claims

    result = _result(0.85, 1.5, world="held-out")
    for cell in (*result.metrics.values(), *result.mg.values()):
        cell["side"] = np.array([-1, -1, -1, -1])  # everyone went right
    (claim,) = person_claims(result)
    assert not claim.holds and "left — (no trial)" in claim.evidence
    assert claim.reason.startswith("too few of the cell's trials went round the detour on the left (0)")
    for cell in (*result.metrics.values(), *result.mg.values()):
        cell["side"] = np.array([1, -1, -1, -1])
    (claim,) = person_claims(result)
    # trial 0 went left: MG 4 mm, the person model 4 − 0.85 × 2 = 2.3 mm, so −1.7 mm, no interval from one pair
    assert claim.holds and "left 2.3 (-1.7, one trial: no interval) mm vs MG" in claim.evidence


def test_the_person_models_mujoco_claim_needs_the_direction_with_an_interval():
    """On the MuJoCo UR5 the claim is the direction: less force and overshoot than MG, each paired difference's
    95 % upper bound below zero; its evidence gives the shares with their intervals."""
    from coassist.analysis.paired import paired_difference
    from coassist.experiments.ablation_report import mujoco_person_claims, person_claims

    (good,) = person_claims(_result(0.5, 1.3, world="mujoco"))  # no share or jerk bar there: the direction
    assert good.holds and "MuJoCo UR5" in good.text and "force 50 % [" in good.evidence and "1.30× MG" in good.evidence
    assert "4 paired trials" in good.evidence
    # the interval the evidence states is the Student-t one of the paired differences (gains 0.5 × 2, 3, 3, 2 N)
    d, lo, hi, _ = paired_difference(np.array([-1.0, -1.5, -1.5, -1.0]), np.zeros(4))
    assert f"({d:+.2f} [{lo:+.2f}, {hi:+.2f}])" in good.evidence
    assert not mujoco_person_claims(_result(-0.1, 1.0, world="mujoco"))[0].holds  # worse than MG
    assert not mujoco_person_claims(_result(0.0, 1.0, world="mujoco"))[0].holds  # the same as MG: bound 0
    assert mujoco_person_claims(_result(0.9, 1.0)) == []  # no MuJoCo cells: no claim
    one = _result(0.5, 1.0, world="mujoco")  # one paired trial: no interval, so no verdict for the direction
    for cell in (*one.metrics.values(), *one.mg.values()):
        for k in ("f_rms_trials", "overshoot_trials"):
            cell[k] = cell[k][:1]
    (single,) = mujoco_person_claims(one)
    assert not single.holds and "no interval" in single.evidence and "nan" not in single.evidence


def _default_result(gain_share: float, worlds=(("point-mass", "cooperative-arbitrated"),), side_worse: float = 0.0):
    """Both objects' cells of the default (present-held) beside MG and the oracle for each (world, controller), its
    gains ``gain_share`` × the oracle's per trial (so both shares are ``gain_share`` exactly, and so are their
    bootstrap bounds, where ``side_worse`` is 0); ``side_worse`` [m] adds overshoot to its left-side trials only."""
    from coassist.experiments.ablation_cells import AblationResult
    from coassist.scenario.assistance import DEFAULT_INTENT

    # eight trials (the pattern of _result twice): the bootstrap's bounds close enough to the share to test a side
    mg_f, gain = np.tile([4.0, 5.0, 6.0, 5.0], 2), np.tile([2.0, 3.0, 3.0, 2.0], 2)
    side = np.tile([1, -1, 1, -1], 2)

    metrics, mg = {}, {}
    for world, controller in worlds:
        for obj in ("board", "heavy"):
            mg[(world, obj)] = _cell(mg_f, mg_f / 1e3, 1.0, side)
            metrics[(world, obj, controller, "oracle")] = _cell(mg_f - gain, (mg_f - gain) / 1e3, 1.0, side)
            f = mg_f - gain_share * gain
            metrics[(world, obj, controller, DEFAULT_INTENT)] = _cell(f, f / 1e3 + side_worse * (side == 1), 1.0, side)
    return AblationResult(metrics, mg, {}, {}, {}, "x", {})


def test_the_defaults_claims_need_less_force_and_overshoot_than_mg_with_an_interval_and_on_each_side():
    """Issue 40's goal for every world's default: per cell where it ran, on both objects, both shares' bootstrap
    lower bounds above zero and no side with more overshoot than MG."""
    from dataclasses import replace

    from coassist.experiments.ablation_report import DEFAULT_CELLS, default_claims

    cells = [(w, c) for w, c, _ in DEFAULT_CELLS]
    claims = default_claims(_default_result(0.4, cells))
    assert [c.holds for c in claims] == [True] * len(DEFAULT_CELLS)
    assert all("force 40 % [40, 40]" in c.evidence and "right" in c.evidence for c in claims)
    assert "drive's default" in claims[0].text and "MuJoCo UR5" in claims[-1].text
    assert claims[2].text.startswith("held-out population, the arbitrated game: without a calibration")
    # the held-out cells of the families made after every choice say so (reproduce.held_out_population)
    unseen = default_claims(replace(_default_result(0.4, cells), held_out_population="unseen"))
    assert unseen[2].text.startswith("unseen population, the arbitrated game: without a calibration")
    assert [c.text for i, c in enumerate(unseen) if i != 2] == [c.text for i, c in enumerate(claims) if i != 2]
    assert not default_claims(_default_result(0.0))[0].holds  # the same as MG: a lower bound of 0
    assert not default_claims(_default_result(-0.1))[0].holds  # worse than MG
    # less overshoot than MG in all (share and its lower bound > 0), but 0.1 mm more than MG on the left (+0.4 and
    # −0.2 mm there, −1.8 and −1.2 on the right): each side must be no worse
    worse = _default_result(0.6, side_worse=0.0016)
    assert worse.shares("point-mass", "board", "cooperative-arbitrated", "present-held")["overshoot"][1] > 0.0
    assert not default_claims(worse)[0].holds
    assert default_claims(_result(0.9, 1.0)) == []  # no cells of the default: no claim


def test_a_single_pair_prints_its_difference_without_an_interval():
    """One paired trial has no interval (NaN bounds): the tables printed "(-0.25 [+nan, +nan])"."""
    from coassist.experiments.application import paired_text

    assert paired_text([0.003], [0.0025], 1e3, 2) == "+0.50, one trial: no interval"
    text = paired_text([0.003, 0.004, 0.002], [0.001, 0.001, 0.001], 1e3, 1)
    assert text.startswith("+2.0 [") and "nan" not in text
