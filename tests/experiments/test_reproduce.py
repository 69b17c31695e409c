"""The whole pipeline on the tiny preset: every stage runs, the report and summary agree,
and every claim's verdict and numbers are recomputed here from the summary.

Also (fast): the seed plan gives no two collections a common trial seed.
"""

import json
import os
import re
from dataclasses import replace
from itertools import pairwise

import numpy as np
import pytest

from coassist.experiments import pipeline, reproduce_config, seed_plan
from coassist.experiments import reproduce as rep
from coassist.experiments.source_training import DRAW_SEED_STEP
from coassist.experiments.transfer import transfer_targets


def _collections(cfg):
    """(name, first seed, trial count) of every simulated collection of a run, from the seed plan."""
    n_tasks = len(pipeline.ITERATION_TASKS)
    base = seed_plan.trial_seed_base(cfg.seed)
    out = [
        (f"D{k}", seed_plan.iteration_seed(base, k), n_tasks * cfg.trials_per_task) for k in range(cfg.iterations + 1)
    ]
    for i, (name, t) in enumerate(transfer_targets(cfg).items()):
        train, test = seed_plan.transfer_seeds(base, i)
        per = len(t.tasks) * len(t.users) * len(t.objects)
        out += [(f"TL {name}", train, per * t.trials), (f"TL {name} test", test, per * t.test_trials)]
    out.append(("TL heavy", seed_plan.heavy_transfer_seed(base), n_tasks * max(1, cfg.transfer_trials // 3)))
    # the path hypotheses' MG trials and the person model's probe trials (draw 0) start at the same seed on purpose
    per_user = max(cfg.calibration_trials, cfg.person_calibration_trials)
    out.append(("calibration", seed_plan.calibration_seed(base), per_user * len(cfg.application_users)))
    for k in range(1, cfg.calibration_draws):  # the person model's further calibrations (draw 0 is the above)
        out.append(
            (
                f"calibration draw {k}",
                seed_plan.calibration_seed(base) + k * DRAW_SEED_STEP,
                cfg.person_calibration_trials * len(cfg.application_users),
            )
        )
    for j in range(2):  # every controller of object j reuses the same seeds on purpose
        out.append(
            (
                f"application {j}",
                seed_plan.application_seed(base, j),
                cfg.application_trials * len(cfg.application_users),
            )
        )
    if cfg.held_out_trials > 0:  # the held-out population's own calibrations and cells
        for k in range(cfg.calibration_draws):
            out.append(
                (
                    f"held-out calibration draw {k}",
                    seed_plan.calibration_seed(base, "held-out") + k * DRAW_SEED_STEP,
                    per_user * len(cfg.application_users),
                )
            )
        for j in range(2):
            out.append(
                (
                    f"held-out application {j}",
                    seed_plan.application_seed(base, j, "held-out"),
                    cfg.held_out_trials * len(cfg.application_users),
                )
            )
    return out


def test_the_held_out_cells_meet_trials_of_their_own():
    # on the thesis cells' seeds the held-out cells were trials seen while settings were chosen (a review): their
    # seeds are their own, and none is a validation base's (precision.py: bases 50000 and 60000)
    cfg = reproduce_config.REPRODUCE_PRESETS["default"]
    assert cfg.held_out_trials > 0
    run = {name: (s, n) for name, s, n in _collections(cfg)}
    held = [(s, n) for name, (s, n) in run.items() if name.startswith("held-out")]
    validation = [
        (f(b, *a), 4 * DRAW_SEED_STEP if f is seed_plan.calibration_seed else 24)
        for b in (50_000, 60_000)
        for f, a in (
            (seed_plan.calibration_seed, ()),
            (seed_plan.application_seed, (0,)),
            (seed_plan.application_seed, (1,)),
        )
    ]
    thesis = [run["application 0"], run["application 1"], run["calibration"]]
    for s, n in held:
        for t, m in validation + thesis:
            assert s + n <= t or t + m <= s, ((s, n), (t, m))


@pytest.mark.parametrize("name", ["default", "tiny", "thesis"])
def test_no_two_collections_share_a_trial_seed(name):
    # one run, and the three runs of `reproduce --seeds 3` (seeds 0, 1, 2) together
    for seeds in ((0,), (0, 1, 2)):
        spans = sorted(
            (c for s in seeds for c in _collections(replace(reproduce_config.REPRODUCE_PRESETS[name], seed=s))),
            key=lambda c: c[1],
        )
        for (a, sa, na), (b, sb, _) in pairwise(spans):
            assert sa + na <= sb, f"{a} (seeds {sa}..{sa + na - 1}) overlaps {b} (from {sb}), run seeds {seeds}"
    # and every run's collections stay inside its own block of trial seeds
    for s in (0, 1, 2):
        for a, sa, na in _collections(replace(reproduce_config.REPRODUCE_PRESETS[name], seed=s)):
            assert s * seed_plan.RUN_SEED_STRIDE <= sa and sa + na <= (s + 1) * seed_plan.RUN_SEED_STRIDE, a


def test_seed_plan_offsets():
    # The offsets as named; a change here changes every dataset of a run.
    assert seed_plan.trial_seed_base(0) == 0 and seed_plan.trial_seed_base(2) == 2_000_000
    assert seed_plan.iteration_seed(7, 2) == 7 + 300_000
    # The transfer targets moved from +500_000 to +600_000: D_4 of a 4-iteration run starts at +500_000.
    assert seed_plan.transfer_seeds(7, 2) == (7 + 640_000, 7 + 650_000)
    assert seed_plan.heavy_transfer_seed(7) == 7 + 800_000
    assert seed_plan.application_seed(7, 1) == 7 + 901_000
    assert seed_plan.calibration_seed(7) == 7 + 880_000
    assert seed_plan.calibration_seed(7, "held-out") == 7 + 975_000
    assert seed_plan.application_seed(7, 1, "held-out") == 7 + 986_000
    assert seed_plan.application_seed(7, 1, "varied") == 7 + 901_000  # the validation populations' as before


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    pytest.importorskip("torch")
    out = tmp_path_factory.mktemp("reproduce")
    config = replace(rep.REPRODUCE_PRESETS["tiny"], workers=1, threads=1)
    summary = rep.run_reproduce(config, out, progress=False)
    return out, summary


def test_every_stage_ran_and_wrote_its_numbers(tiny_run):
    out, summary = tiny_run
    assert set(summary["stage_seconds"]) == {
        "dMPC study",
        "iterative training",
        "transfer learning",
        "application scenario",
        "real recordings",
        "intent ablation",
    }
    # the work done, per stage and in all: this process's CPU seconds (workers=1: no pool)
    assert set(summary["stage_cpu_seconds"]) == set(summary["stage_seconds"])
    cpu = summary["cpu_seconds"]
    stage_main = sum(c["main"] for c in summary["stage_cpu_seconds"].values())
    assert (
        0 < stage_main <= cpu["main"] <= (os.cpu_count() or 1) * summary["total_seconds"] + 1.0
    )  # no more than the cores give
    it = summary["iterative"]
    assert list(it["in_loop_errors"]) == ["nominal", "M0", "M1"]
    for errors in it["in_loop_errors"].values():
        assert set(errors) == {5, 10, 20, 50} and all(v["e_rms"] > 0 for v in errors.values())
    assert len(it["deltas_e_rms_50"]) == 1
    assert it["m0_on_d1_e_rms_50"] > 0
    assert set(summary["transfer"]) >= {"z trajectory", "new users", "board"}
    for target in ("z trajectory", "new users", "board"):
        tiny = rep.REPRODUCE_PRESETS["tiny"]
        assert set(summary["transfer"][target]["e_rms"]) == {
            "M_prev",
            *tiny.transfer_starts,
            "nominal",
            "constant_velocity",
            "constant_acceleration",
            "ridge",
        }
    controllers = ("cooperative", "cooperative-arbitrated", "impedance", "manual")
    assert set(summary["application"]) == {f"{o}/{c}" for o in ("board", "heavy") for c in controllers}
    for result in summary["application"].values():  # the smoothness and stability measures, per trial
        for name in ("f_rms", "sigma", "overshoot", "jerk_rms", "tracking_error_rms", "peak_effort_ratio"):
            tiny = rep.REPRODUCE_PRESETS["tiny"]
            assert len(result[f"{name}_trials"]) == tiny.application_trials * len(tiny.application_users)
            finite = [v for v in result[f"{name}_trials"] if np.isfinite(v)]
            if finite:  # the mean is over the trials' finite values (σ: those that reached the target)
                assert result[name] == pytest.approx(np.mean(finite))
    for key in ("M0", "M1", "TL-board-transfer", "lstm-intent"):
        assert (out / "models" / key / "history.json").is_file()
    # The ablation: every (object, controller, source) cell in the point-mass world (the tiny preset leaves MuJoCo out),
    # each model saying what it predicts.
    from coassist.experiments.ablation_cells import ablation_cells

    ab = summary["ablation"]
    tiny = rep.REPRODUCE_PRESETS["tiny"]
    from coassist.experiments.ablation_cells import ARBITRATED, HELD_OUT_SOURCES

    assert set(ab["cells"]) == {
        f"point-mass/{o}/{c}/{s}" for o in ("board", "heavy") for c, s in ablation_cells(tiny)
    } | {f"held-out/{o}/{ARBITRATED}/{s}" for o in ("board", "heavy") for s in HELD_OUT_SOURCES}
    assert "mujoco" in ab["skipped"]
    labels = {"ridge": "tool", "ridge-intent": "intent", "lstm-tool": "tool", "lstm-intent": "intent"}
    assert set(labels) == set(tiny.learned_sources)
    for source, label in labels.items():
        side = json.loads((out / "models" / source / "model.json").read_text())
        assert side["window"]["label"] == label and side["predicts"]
    # the path hypotheses' calibration: one shape per application operator, fitted to their trials
    calibration = json.loads((out / "models" / "paths" / "path-hypotheses.json").read_text())
    assert set(calibration["shapes"]) == {f"user-{u}" for u in tiny.application_users}
    assert all(v["trials"] == tiny.calibration_trials for v in calibration["shapes"].values())


def inf(x):
    """NaN (no trial reached the target) as +inf, for "smaller than" comparisons."""
    return np.inf if not np.isfinite(x) else x


def _mm(x, digits=1):
    return f"{x * 1000:.{digits}f}"


def _expected_claims(summary):
    """Each claim's verdict and the numbers its evidence must print, recomputed from the summary."""
    out = {}
    obs = summary["dmpc_sweep"]["observations"]
    for key, text in (
        ("higher_alpha_tracks_human_reference", "Higher α"),
        ("lower_R_r_tracks_better", "Lower R_r"),
        ("longer_horizon_tracks_better", "A longer prediction horizon"),
    ):
        out[text] = (bool(obs[key]["holds"]), [])
    it = summary["iterative"]
    err = it["in_loop_errors"]
    models = [k for k in err if k != "nominal"]
    e50 = [err[m][50]["e_rms"] for m in models]
    drops = [a - b for a, b in pairwise(e50)]
    out["Iterating lowers e_RMS"] = (  # "then it settles": a drop after the first to show it
        len(drops) >= 2 and e50[-1] < e50[0] and drops[0] == max(drops) and drops[0] > 0,
        [f"M{k} {_mm(e)} mm" for k, e in enumerate(e50)] + [_mm(err["nominal"][50]["e_rms"])],
    )
    hs = sorted(err["M0"])
    grows = all(err[m][a]["e_rms"] < err[m][b]["e_rms"] for m in models for a, b in pairwise(hs))
    out["e_RMS grows with the prediction horizon"] = (grows, [_mm(err[m][h]["e_rms"]) for m in models for h in hs])
    tr = {k: v for k, v in summary["transfer"].items() if k != "iteration_seconds"}
    out["Transfer with"] = (
        all(r["e_rms"]["transfer"][50] < r["e_rms"]["M_prev"][50] for r in tr.values()),
        [_mm(r["e_rms"][p][50]) for r in tr.values() for p in ("M_prev", "transfer")],
    )
    own = it["final_model_offline_e_rms"][50]
    it_trials = sum(w["trials"] for w in it["work"])
    it_windows = sum(w["windows_trained"] for w in it["work"])
    out["Transfer approaches"] = (
        all(
            r["e_rms"]["transfer"][50] <= 1.25 * own
            and r["work"]["trials"] / it_trials < 0.5
            and r["work"]["windows_trained"] / it_windows < 0.5
            for r in tr.values()
        ),
        [_mm(own), f"{it_trials} trials", f"{it_windows} windows"]
        + [f"{r['work']['trials']} trials" for r in tr.values()],
    )
    out["Freezing the LSTM"] = (
        all(r["e_rms"]["transfer"][50] <= r["e_rms"]["scratch"][50] for r in tr.values()),
        [
            _mm(r["e_rms"][p][50])
            for r in tr.values()
            for p in ("transfer", "finetune_all", "scratch")
            if p in r["e_rms"]
        ],
    )
    app = summary["application"]
    for obj in ("board", "heavy"):
        a, i, m = (app[f"{obj}/{c}"] for c in ("cooperative", "impedance", "manual"))
        forces = [f"{a['f_rms']:.2f} N", f"{m['f_rms']:.2f} N", f"{i['f_rms']:.2f} N"]
        out[f"{obj}: the assistive controller needs less"] = (a["f_rms"] < min(m["f_rms"], i["f_rms"]), forces)
        out[f"{obj}: manual guidance needs less"] = (m["f_rms"] < i["f_rms"], forces)
        out[f"{obj}: the assistive controller reaches"] = (
            bool(
                np.isfinite(a["sigma"])
                and a["sigma"] < inf(m["sigma"])
                and a["sigma"] < inf(i["sigma"])
                and a["reached"] >= max(m["reached"], i["reached"])
            ),
            [f"{a['reached']}/", f"{m['reached']}/"],
        )
        for variant in ("cooperative", "cooperative-arbitrated"):
            v = app[f"{obj}/{variant}"]
            saving = 1 - v["f_rms"] / m["f_rms"]
            out[f"{obj}: {variant} needs ≥"] = (
                bool(
                    saving >= 0.30
                    and np.isfinite(v["sigma"])
                    and v["sigma"] <= inf(m["sigma"])
                    and v["reached"] >= m["reached"]
                    and v["overshoot"] <= m["overshoot"]
                ),
                [f"force {100 * saving:.0f} %", f"{v['jerk_rms']:.2f} vs MG {m['jerk_rms']:.2f}"],
            )
    cells = summary["ablation"]["cells"]
    for key, cell in cells.items():
        world, obj, controller, source = key.split("/")
        if world == "point-mass" and controller == "cooperative-arbitrated" and source in ("lstm-tool", "lstm-intent"):
            f, o = cell["oracle_share_force"][0], cell["oracle_share_overshoot"][0]
            out[f"{obj}: the arbitrated controller with {source} in the loop"] = (
                bool(np.isfinite(f) and np.isfinite(o) and f >= 0.8 and o >= 0.8),
                [],
            )
    # issue 34's goals for the application's source ("paths"), from the summary's cells
    mg_cells = summary["ablation"]["mg"]
    for obj in ("board", "heavy"):
        cell = cells[f"point-mass/{obj}/cooperative-arbitrated/paths"]
        f, o, o_lo = cell["oracle_share_force"][0], cell["oracle_share_overshoot"][0], cell["oracle_share_overshoot"][1]
        out[f"{obj}: with 'paths' the arbitrated controller gets"] = (
            bool(np.isfinite(f) and np.isfinite(o) and np.isfinite(o_lo) and f >= 0.85 and o >= 0.6 and o_lo >= 0.3),
            [],
        )
        for metric, what in (
            ("overshoot", "overshoots the intent"),
            ("clearance_deficit", "passes closer to the obstacle"),
        ):
            sides = cell["by_side"]
            ok = all(
                sides[s][metric]["trials"] >= 2
                and np.isfinite(sides[s][metric]["high"])
                and sides[s][metric]["high"] <= 0.0
                for s in ("left", "right")
            )
            out[f"{obj}: with 'paths' the arbitrated controller {what}"] = (bool(ok), [])
        jerk, jerk_mg = cell["jerk_rms"], mg_cells[f"point-mass/{obj}"]["jerk_rms"]
        out[f"{obj}: with 'paths' the arbitrated controller's jerk"] = (
            bool(jerk <= 1.2 * jerk_mg),
            [f"{jerk:.2f} vs MG {jerk_mg:.2f}"],
        )
    # issue 40's goals for the person model, in the thesis population and the held-out one
    for world, (fb, ob, lb, jb) in {"point-mass": (0.85, 0.7, 0.4, 1.1), "held-out": (0.8, 0.6, 0.3, None)}.items():
        for obj in ("board", "heavy"):
            cell = cells[f"{world}/{obj}/cooperative-arbitrated/person"]
            f, (o, o_lo) = cell["oracle_share_force"][0], cell["oracle_share_overshoot"][:2]
            ok = all(v is not None and np.isfinite(v) for v in (f, o, o_lo)) and f >= fb and o >= ob and o_lo >= lb
            jerk = cell["jerk_rms"] / mg_cells[f"{world}/{obj}"]["jerk_rms"]
            if jb is not None:
                ok = ok and jerk <= jb
            else:
                sides = [cell["by_side"][s]["overshoot"] for s in ("left", "right")]
                ok = ok and all(sd["trials"] >= 1 and sd["vs_mg"] is not None and sd["vs_mg"] <= 0.0 for sd in sides)
            where = "held-out population" if world == "held-out" else "point-mass world"
            out[f"{obj}, {where}: the person model"] = (bool(ok), [f"{jerk:.2f}× MG"])
    # issue 40's goal for every world's default without a calibration: less force and overshoot than MG
    # (shares' lower bounds > 0) on both objects, and no more overshoot on either side
    for world, controller, where in (
        ("point-mass", "cooperative", "point-mass world, the plain cooperative game"),
        ("point-mass", "cooperative-arbitrated", "point-mass world, the arbitrated game"),
        ("held-out", "cooperative-arbitrated", "held-out population, the arbitrated game"),
        ("mujoco", "cooperative-arbitrated", "MuJoCo UR5, the arbitrated game"),
    ):
        if f"{world}/board/{controller}/present-held" not in cells:  # the tiny preset leaves MuJoCo out
            continue
        ok = True
        for obj in ("board", "heavy"):
            cell = cells[f"{world}/{obj}/{controller}/present-held"]
            f_lo, o_lo = cell["oracle_share_force"][1], cell["oracle_share_overshoot"][1]
            ok = ok and all(v is not None and np.isfinite(v) and v > 0.0 for v in (f_lo, o_lo))
            sides = [cell["by_side"][s]["overshoot"] for s in ("left", "right")]
            ok = ok and all(sd["trials"] >= 1 and sd["vs_mg"] is not None and sd["vs_mg"] <= 0.0 for sd in sides)
        out[where] = (bool(ok), [])
    if "user_a" in summary["real"]:
        ev = summary["real"]["user_a"]
        best = ev["best_baseline"]
        out["On held-out real user-a data the model is no worse"] = (
            all(b["gain"] >= 0 for b in best.values()),
            [f"{b['model_e_rms'] * 1e3:.3f} mm" for b in best.values()],
        )
        ridge, model = (
            ev["results"]["ridge"][50]["e_rms"],
            ev["results"]["model"][50]["e_rms"],
        )  # in memory: int horizons
        out["On held-out real user-a data the model beats"] = (
            model <= 0.85 * ridge,
            [f"model {model * 1e3:.3f} mm", f"{ridge * 1e3:.3f} mm", f"{100 * (ridge - model) / ridge:+.1f} %"],
        )
    return out


def test_ablation_cells_meet_the_same_trials(tiny_run):
    """Every (object, controller, source) cell of the ablation ran MG's trials: same operators, same seeds.
    The cells of the application's own source are the application's assistive trials, reused."""
    from coassist.data import read_dataset
    from coassist.experiments.ablation_cells import CONTROLLERS, ablation_cells
    from coassist.experiments.source_training import APPLICATION_SOURCE

    out, summary = tiny_run
    for obj in ("board", "heavy"):
        mg = sorted((t.meta.user, t.meta.seed) for t in read_dataset(out / "datasets" / f"app-{obj}-manual").trials)
        assert mg
        for controller, source in ablation_cells(rep.REPRODUCE_PRESETS["tiny"]):
            reused = source == APPLICATION_SOURCE and controller in CONTROLLERS
            name = f"app-{obj}-{controller}" if reused else f"ablation-{obj}-{controller}-{source}"
            ds = read_dataset(out / "datasets" / name)
            assert sorted((t.meta.user, t.meta.seed) for t in ds.trials) == mg, (obj, controller, source)
        for controller in CONTROLLERS:
            # the reused cell is the application's row: the same numbers
            cell = summary["ablation"]["cells"][f"point-mass/{obj}/{controller}/{APPLICATION_SOURCE}"]
            assert cell["f_rms"] == summary["application"][f"{obj}/{controller}"]["f_rms"]
            assert not (out / "datasets" / f"ablation-{obj}-{controller}-{APPLICATION_SOURCE}").exists()


def test_every_claim_agrees_with_the_summary(tiny_run):
    _, summary = tiny_run
    expected = _expected_claims(summary)
    claims = summary["claims"]
    assert len(claims) == len(expected)
    for prefix, (holds, numbers) in expected.items():
        (claim,) = [c for c in claims if c["claim"].startswith(prefix)]
        assert claim["holds"] is holds, claim["claim"]
        for number in numbers:
            assert number in claim["evidence"], (claim["claim"], number, claim["evidence"])


def test_report_is_complete_and_consistent_with_the_summary(tiny_run):
    out, summary = tiny_run
    html = (out / "report.html").read_text()
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["claims"] == summary["claims"]
    for title in (
        "1. The dMPC study",
        "2. Iterative training",
        "3. Transfer learning",
        "4. Application",
        "5. The real UR5 recordings",
        "6. Which intent makes assistance better?",
    ):
        assert title in html
    # figures as the run had them: the stop criterion (0.25 mm read "0.2 mm"), no NaN interval of a one-trial cell,
    # and every transfer's comparison with its best baseline (empty, "M_TL against its best tuned baseline: </p>")
    assert summary["config"]["tol"] == 2.5e-4 and "0.25 mm at 50 samples" in html
    assert not re.search(r"\bnan\b", html, flags=re.IGNORECASE), re.findall(r".{60}\bnan\b.{20}", html)
    assert "baseline: </p>" not in html and "baseline:</p>" not in html
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
    # numbers the prose derives from the run, not from text
    m0 = summary["iterative"]["m0_on_d1_e_rms_50"]
    assert f"in this run: {m0 * 1000:.1f} mm" in html
    assert "200 N/m spring" in html  # coassist.control.presets.IMPEDANCE_STIFFNESS
    # the first screen answers the question: per object and assistive variant, the force saved against MG and IMP
    answer = html.split("The thesis' claims, checked")[0]
    assert "The answer: does the assistance help?" in answer
    rows = summary["headline"]["table"][2]
    assert [r[:2] for r in rows] == [
        [o, v] for o in ("board", "heavy") for v in ("cooperative", "cooperative-arbitrated")
    ]
    board = summary["application"]["board/cooperative"]["f_rms_trials"]
    mg = summary["application"]["board/manual"]["f_rms_trials"]
    saved = 1.0 - np.asarray(board) / np.asarray(mg)
    assert rows[0][2] == f"{100 * saved.mean():.0f} ± {100 * saved.std():.0f} %"
    assert rows[0][2] in answer


def test_the_held_out_cells_meet_their_own_people(tiny_run):
    """The held-out population's cells ran its MG trials (its operators, the same seeds), and its calibrated
    sources were fitted to those operators' own calibration trials, not the thesis population's."""
    from coassist._io import read_hashed_json
    from coassist.data import read_dataset
    from coassist.experiments.ablation_cells import HELD_OUT_SOURCES

    out, summary = tiny_run
    cfg = rep.REPRODUCE_PRESETS["tiny"]
    people = {f"held-out-user-{u}" for u in cfg.application_users}
    for obj in ("board", "heavy"):
        mg = sorted(
            (t.meta.user, t.meta.seed) for t in read_dataset(out / "datasets" / f"held-out-{obj}-manual").trials
        )
        assert mg and {u for u, _ in mg} == people
        for source in HELD_OUT_SOURCES:
            ds = read_dataset(out / "datasets" / f"held-out-{obj}-{source}")
            assert sorted((t.meta.user, t.meta.seed) for t in ds.trials) == mg, (obj, source)
            assert f"held-out/{obj}/cooperative-arbitrated/{source}" in summary["ablation"]["cells"]
    # the person model: calibration_draws calibrations per population, each of that population's operators
    assert cfg.calibration_draws == 2
    for folder, names in (
        ("person-held-out-draws", people),
        ("person-draws", {f"user-{u}" for u in cfg.application_users}),
    ):
        for k in range(cfg.calibration_draws):
            doc = read_hashed_json(
                out / "models" / folder / f"draw-{k}" / "person-model.json", format="coassist-person-model-2"
            )
            assert set(doc["people"]) == names, (folder, k)
    # and the held-out person cells' intervals resampled (operator, draw) clusters
    assert summary["ablation"]["cells"]["held-out/board/cooperative-arbitrated/person"]["interval_clusters"] >= 1
