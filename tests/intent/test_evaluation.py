"""The evaluation's comparison with the best baseline: per-trial spread, gain, and what evaluate prints."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import default_real_data, write_dataset
from coassist.intent import evaluate_model, load_trials, split_trials, train_model
from coassist.intent.evaluation import BASELINES, ModelEvaluation, best_baselines, comparison_lines

from .conftest import labeled, make_trial


def test_best_baseline_and_per_trial_spread(trials, tiny):
    from dataclasses import replace

    p = replace(tiny, train=replace(tiny.train, test_fraction=0.4))
    model = train_model(trials, p, p.train)
    assert model.info["baselines"]["ridge"]["tuned"] and model.info["baselines"]["constant_acceleration"]["tuned"]
    res = evaluate_model(model, trials)
    assert len(res.trials) == 2 and res.horizons == (5, 10)
    for h in (5, 10):
        cands = {b: res.results[b][h]["e_rms"] for b in BASELINES}
        best = res.best_baseline[h]
        assert best["name"] == min(cands, key=cands.get) and best["e_rms"] == min(cands.values())
        me = res.results["model"][h]["e_rms"]
        assert best["gain"] == pytest.approx((best["e_rms"] - me) / best["e_rms"])
        per = res.results["model"][h]["e_rms_trials"]
        assert sorted(per) == sorted(res.trials)
        assert res.results["model"][h]["trial_min"] == min(per.values())
        bt = res.results[best["name"]][h]["e_rms_trials"]
        assert best["trials_model_better"] == sum(per[k] < bt[k] for k in per)
    # Pooled e_RMS weighs trials by their scored ticks: it lies within the per-trial range.
    r = res.results["ridge"][10]
    assert r["trial_min"] <= r["e_rms"] <= r["trial_max"]
    assert res.baselines["ridge"]["alpha"] == model.ridge.alpha
    # The JSON record: the layout evaluation.json and summary.json have always had ("5", not 5).
    record = json.loads(json.dumps(res.to_dict()))
    assert list(record) == [
        "trials",
        "skipped",
        "n_ticks",
        "horizons",
        "dt",
        "unit",
        "baselines",
        "results",
        "best_baseline",
        "copies",  # then what is new, at the end
        "against",
    ]
    assert record["horizons"] == [5, 10] and record["results"]["ridge"]["10"]["e_rms"] == r["e_rms"]
    assert record["best_baseline"]["5"]["name"] == res.best_baseline[5]["name"]


def test_comparison_lines_state_the_best_baseline_in_mm():
    results = {
        "model": {5: {"e_rms": 0.0008, "e_rms_trials": {"a": 0.0007, "b": 0.0011}}},
        "ridge": {5: {"e_rms": 0.0010, "e_rms_trials": {"a": 0.0009, "b": 0.0010}}},
        "constant_velocity": {5: {"e_rms": 0.0020, "e_rms_trials": {"a": 0.002, "b": 0.002}}},
    }
    best = best_baselines(results, (5,))
    assert best[5]["gain"] == pytest.approx(0.2)
    res = ModelEvaluation(
        trials=("a", "b"),
        skipped=(),
        n_ticks=10,
        horizons=(5,),
        dt=0.01,
        baselines={"ridge": {"alpha": 1e-3, "tuned": True}},
        results=results,
        best_baseline=best,
    )
    (line,) = comparison_lines(res)
    assert line.startswith("0.05 s: best baseline ridge (α = 1e-03, tuned on validation trials) e_RMS 1 mm")
    assert "model 0.8 mm: 20.0 % better (+0.2 mm), model better on 1 of 2 trials" in line
    # the model named otherwise (the report's "M_TL"): the same line, so named; it gave none before
    (named,) = comparison_lines(res, "M_TL")
    assert named == line.replace("model", "M_TL")


def test_evaluate_prints_the_best_baseline_per_horizon(tmp_path):
    write_dataset([make_trial(i, n=220) for i in range(5)], tmp_path / "D0", "D0")
    runner = CliRunner()
    res = runner.invoke(
        app,
        [
            "train",
            str(tmp_path / "D0"),
            "--out",
            str(tmp_path / "m"),
            "--epochs",
            "1",
            "--threads",
            "1",
            "--batch-size",
            "256",
        ],
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["evaluate", "--model", str(tmp_path / "m"), "--data", str(tmp_path / "D0")], terminal_width=250
    )
    assert res.exit_code == 0, res.output
    out = json.loads((tmp_path / "m" / "evaluation.json").read_text())
    lines = [ln for ln in res.output.splitlines() if "best baseline" in ln]
    assert len(lines) == len(out["horizons"])
    for ln, h in zip(lines, out["horizons"]):
        b = out["best_baseline"][str(h)]
        assert ln.startswith(f"{h * out['dt']:.2f} s: best baseline")
        assert f"e_RMS {1e3 * b['e_rms']:.3g} mm" in ln and f"{abs(100 * b['gain']):.1f} %" in ln
    assert "errors in mm" in " ".join(res.output.split())  # the table says its unit
    # and the scoring shows its progress (a thesis-size model scored for a minute in silence: a review, 2026-12-07)
    assert f"scoring {len(out['trials'])} held-out trials" in res.output


USER_A = default_real_data() / "user-a"


@pytest.mark.real_data
@pytest.mark.skipif(not USER_A.is_dir(), reason=f"real recordings not found at {USER_A}")
def test_tuned_ridge_beats_the_fixed_alpha_on_held_out_user_a():
    """On held-out user-a trials the validation-tuned α is no worse at 0.4 s than the former fixed α = 1."""
    from coassist.intent import RidgeBaseline, WindowSet
    from coassist.intent.baselines import fit_tuned_baselines
    from coassist.intent.presets import MODEL_PRESETS

    w = MODEL_PRESETS["default"].window
    trials = load_trials([USER_A])
    train_idx, test_idx = split_trials([lt.id for lt in trials], 0.2, seed=0)
    train = [trials[i].trial for i in train_idx]
    ws = WindowSet(train, w, 0.008, stride=8)
    sin, sout = ws.fit_scalers()
    tuned, kalman, rec = fit_tuned_baselines(
        train, [trials[i].id for i in train_idx], w, 0.008, sin, sout, seed=0, stride=8
    )
    assert set(rec["validation_trials"]).isdisjoint(trials[i].id for i in test_idx)
    fixed = RidgeBaseline.fit(ws, sin, sout, 1.0)
    test = WindowSet([trials[i].trial for i in test_idx], w, 0.008, stride=4)
    sel = np.arange(len(test))

    def rms50(r):
        x = r.input_scaler.transform(test.raw_inputs(sel))
        from coassist.intent.features import decode_target, unscale_targets

        pose, vel = test.anchors(sel)
        pred = decode_target(unscale_targets(r.target_scaler, r.predict_scaled(x), 50, 2), pose, vel, w, 0.008)
        return float(np.mean(np.sqrt(np.mean(np.sum((pred - test.future(sel)) ** 2, axis=2), axis=1))))

    assert tuned.alpha < 1.0 and rms50(tuned) < rms50(fixed)
    assert kalman.tuned


def test_linear_preset_is_the_tuned_ridge_in_the_model_format(trials, tmp_path):
    from dataclasses import replace

    from coassist.intent import load_model, save_model
    from coassist.intent.presets import MODEL_PRESETS

    lin = MODEL_PRESETS["linear"]
    p = replace(
        lin,
        window=replace(lin.window, history=20, decimation=2, horizon=10),
        train=replace(lin.train, threads=1, train_stride=2),
    )
    model = train_model(trials, p, p.train)
    assert model.net.is_linear and model.net.lstm is None
    hist = model.info["training_history"]
    assert len(hist) == 1 and hist[0]["closed_form"] and hist[0]["lr"] == 0.0
    save_model(model, tmp_path / "lin")
    back = load_model(tmp_path / "lin")
    t = trials[0].trial
    a, b = back.predict_trial(t), model.ridge.predict_trial(t)
    ok = np.isfinite(a[:, 0, 0])
    assert ok.sum() > 200 and np.allclose(a[ok], b[ok], atol=1e-6)  # float32 network vs float64 ridge, positions in m
    res = evaluate_model(back, trials)
    for h in (5, 10):  # same predictions, same ticks: the same error to float32 precision
        assert res.results["model"][h]["e_rms"] == pytest.approx(res.results["ridge"][h]["e_rms"], rel=1e-3)


@pytest.mark.slow
@pytest.mark.real_data
@pytest.mark.skipif(not USER_A.is_dir(), reason=f"real recordings not found at {USER_A}")
def test_default_predictor_is_no_worse_than_the_best_tuned_baseline_on_held_out_user_a():
    """The shipped default against its tuned baselines on user-a's held-out trials (split seed 0; ~2 min).

    Measured (docs/intent-baselines.md): better than the tuned ridge at every horizon in each of
    3 seeds, by 2–5 %; the issue's 15 % at 0.4 s is not reached, and this test does not claim it.
    """
    from dataclasses import replace

    import torch

    from coassist.intent.presets import MODEL_PRESETS

    torch.set_num_threads(1)
    p = MODEL_PRESETS["default"]
    trials = load_trials([USER_A])
    model = train_model(trials, p, replace(p.train, threads=1))
    res = evaluate_model(model, trials)
    assert set(res.trials).isdisjoint(model.info["baselines"]["validation_trials"])
    for h, best in res.best_baseline.items():
        assert best["name"] == "ridge" and best["gain"] > 0, (h, best)


def test_a_scoring_stride_scores_every_predictor_on_every_nth_window(trials, tiny):
    """``stride`` n: the model predicts at the ticks of every n-th window only (the first full history's, then
    every n-th tick after), the same rows there as predicting every tick (the network's batches differ: float32
    rounding), and evaluate_model scores every predictor on those ticks alone."""
    model = train_model(trials, tiny, tiny.train)
    t = trials[-1].trial
    full, thin = model.predict_trial(t), model.predict_trial(t, stride=7)
    done = np.isfinite(full).all(axis=(1, 2))
    first = int(np.flatnonzero(done)[0])
    scored = np.flatnonzero(np.isfinite(thin).all(axis=(1, 2)))
    assert done[first:].all() and scored.tolist() == list(range(first, t.n_samples, 7))
    # float32 network: other batches round its scaled outputs differently, ~1e-7 of outputs that the target
    # scaler turns into centimetres, so nanometres; 1 µm leaves room for any BLAS and still catches a wrong tick
    np.testing.assert_allclose(thin[scored], full[scored], rtol=0, atol=1e-6)
    assert np.isnan(thin[np.setdiff1d(np.arange(t.n_samples), scored)]).all()
    every = evaluate_model(model, trials, held_out_only=False)
    assert evaluate_model(model, trials, held_out_only=False, stride=1).to_dict() == every.to_dict()
    res = evaluate_model(model, trials, held_out_only=False, stride=7)
    horizon = max(res.horizons)
    expect = 0
    for lt in trials:
        n = lt.trial.n_samples
        start = int(np.flatnonzero(np.isfinite(model.predict_trial(lt.trial)).all(axis=(1, 2)))[0])
        expect += len(range(start, max(0, n - horizon), 7))
    assert res.n_ticks == expect < every.n_ticks
    with pytest.raises(ValueError, match="stride"):
        model.predict_trial(t, stride=0)


def test_held_out_only_leaves_out_what_the_starting_model_trained_on(tmp_path, trials, tiny):
    """A model fine-tuned on new trials is not held out from those its parent trained on: once evaluate scored
    them as held out (the sidecar's own train_trials only)."""
    from dataclasses import replace

    from coassist.intent import save_model
    from coassist.intent.model import lineage_train_trials

    cfg = replace(tiny.train, epochs=1)
    parent = train_model(trials, tiny, cfg)
    save_model(parent, tmp_path / "p")
    new = labeled(5, prefix="U", first_seed=100)  # other trials
    ft = train_model(new, tiny, replace(cfg, init=f"finetune:{tmp_path / 'p'}"))
    assert ft.info["parent"]["train_trials"] == parent.info["train_trials"]
    assert lineage_train_trials(ft.info) == {*parent.info["train_trials"], *ft.info["train_trials"]}
    ev = evaluate_model(ft, trials + new, held_out_only=True)
    assert list(ev.trials) == ["T/trial_02", "U/trial_02"]  # the parent's test trial and the model's own
    assert sorted(ev.skipped) == sorted([*parent.info["train_trials"], *ft.info["train_trials"]])
    assert len(evaluate_model(ft, trials + new, held_out_only=False).trials) == 10


def test_a_copy_of_a_training_trial_under_another_name_is_not_held_out(tmp_path, trials, tiny):
    """A model's training trials copied under other names (another dataset folder, a file copied away) were scored
    as held out: evaluate knew them by id alone. Their contents' digests (the sidecar's train_digests, its parent's
    too) leave them out, named apart; a training started from a model moves such copies to its training side."""
    import copy
    from dataclasses import replace

    from coassist.intent import save_model
    from coassist.intent.trials import content_digest

    cfg = replace(tiny.train, epochs=1)
    model = train_model(trials, tiny, cfg)
    trained = set(model.info["train_trials"])
    assert model.info["train_digests"] == [content_digest(lt.trial) for lt in trials if lt.id in trained]
    copies = labeled(5, prefix="C")  # the same trials (the same seeds), named C/…
    ev = evaluate_model(model, copies, held_out_only=True)
    held = [c.id for c, t in zip(copies, trials) if t.id not in trained]
    assert list(ev.trials) == held and len(held) == 1  # the copy of the trial it held out is scored
    assert sorted(ev.copies) == sorted(ev.skipped) == sorted(c.id for c in copies if c.id not in held)
    assert ev.to_dict()["copies"] == list(ev.copies)
    # a value changed is another trial: scored
    moved = copies[0].trial
    other = copies[0]._replace(trial=replace(moved, pose=moved.pose + 1e-9))
    assert content_digest(other.trial) != content_digest(moved)
    assert other.id in evaluate_model(model, [other, *copies[1:]], held_out_only=True).trials
    with pytest.raises(ValueError, match="copies of its training trials"):
        evaluate_model(model, [c for c in copies if c.id not in held], held_out_only=True)
    # a sidecar from before train_digests: by id alone, as then
    old = copy.copy(model)
    old.info = {k: v for k, v in model.info.items() if k != "train_digests"}
    assert evaluate_model(old, copies, held_out_only=True).copies == ()
    # fine-tuning on the copies: none of its held-out trials is one its parent trained on
    save_model(model, tmp_path / "p")
    ft = train_model(copies, tiny, replace(cfg, init=f"finetune:{tmp_path / 'p'}"))
    assert ft.info["parent"]["train_digests"] == model.info["train_digests"]
    test_contents = {content_digest(c.trial) for c in copies if c.id in ft.info["test_trials"]}
    assert not test_contents & set(model.info["train_digests"])
    assert set(ft.info["train_trials"]) >= {c.id for c in copies if c.id not in held}


def test_evaluate_names_copies_of_training_trials(tmp_path, trials, tiny):
    from dataclasses import replace

    from coassist.intent import save_model

    model = train_model(trials, tiny, replace(tiny.train, epochs=1))
    save_model(model, tmp_path / "m")
    write_dataset([lt.trial for lt in trials], tmp_path / "copy", "copy")
    res = CliRunner().invoke(app, ["evaluate", "--model", str(tmp_path / "m"), "--data", str(tmp_path / "copy")])
    assert res.exit_code == 0, res.output
    assert "skipped 4 training trials, 4 of them copies of training trials under other names" in " ".join(
        res.output.split()
    )
    record = json.loads((tmp_path / "m" / "evaluation.json").read_text())
    assert len(record["trials"]) == 1 and len(record["copies"]) == 4


def _with_intent(lt, offset):
    """``lt`` on its plan (reference = pose) with a recorded intent ``offset`` [m] (2,) from the tool."""
    from dataclasses import replace

    t = lt.trial
    return lt._replace(trial=replace(t, reference=t.pose.copy(), intent=t.pose + np.asarray(offset)))


def test_scored_against_the_intent_the_errors_are_the_intents(trials, tiny):
    """against="intent": every predictor's rows against the recorded intent. A tool on its plan exactly, the intent
    5 mm off it: the plan's rows (nominal) err 0 against the tool and 5 mm against the intent at every horizon; an
    intent equal to the tool scores as the tool, bit for bit; a trial without an intent is named."""
    from dataclasses import replace

    model = train_model(trials, tiny, replace(tiny.train, epochs=1))
    off = [_with_intent(lt, (0.003, 0.004)) for lt in trials]
    tool = evaluate_model(model, off, held_out_only=False)
    intent = evaluate_model(model, off, held_out_only=False, against="intent")
    assert tool.against == "tool" and intent.against == "intent" == intent.to_dict()["against"]
    for h in tool.horizons:
        assert tool.results["nominal"][h]["e_rms"] == 0.0
        assert intent.results["nominal"][h]["e_rms"] == pytest.approx(0.005, rel=1e-9)
    same = [lt._replace(trial=replace(lt.trial, intent=lt.trial.pose.copy())) for lt in trials]
    a = evaluate_model(model, same, held_out_only=False, against="intent")
    b = evaluate_model(model, same, held_out_only=False)
    assert a.results == b.results
    with pytest.raises(ValueError, match="trial T/trial_00 records no intent"):
        evaluate_model(model, trials, held_out_only=False, against="intent")
    with pytest.raises(ValueError, match="against must be one of"):
        evaluate_model(model, trials, against="hand")


def test_evaluate_scores_an_intent_model_against_the_intent_where_the_trials_record_it(tmp_path, trials, tiny):
    """coassist evaluate scored an intent-label model's rows against the tool's path without a word. By default it
    scores a model against what it predicts where every trial records it, says against what, and where it cannot
    (a recording: no intent) says that the rows are scored against the tool's path."""
    from dataclasses import replace

    from coassist.intent import save_model

    sim = [_with_intent(lt, (0.003, 0.004)) for lt in trials]
    preset = replace(tiny, window=replace(tiny.window, label="intent"))
    save_model(train_model(sim, preset, replace(tiny.train, epochs=1)), tmp_path / "m")
    write_dataset([lt.trial for lt in sim], tmp_path / "sim", "sim")
    write_dataset([lt.trial for lt in trials], tmp_path / "rec", "rec")

    def run(*args):
        res = CliRunner().invoke(app, ["evaluate", "--model", str(tmp_path / "m"), "--include-training", *args])
        return res.exit_code, " ".join(res.output.split())

    code, out = run("--data", str(tmp_path / "sim"), "--out", str(tmp_path / "a.json"))
    assert code == 0 and "against the person's true intent" in out, out
    assert json.loads((tmp_path / "a.json").read_text())["against"] == "intent"
    code, out = run("--data", str(tmp_path / "rec"), "--out", str(tmp_path / "b.json"))
    assert code == 0 and "against the tool's future path" in out, out
    assert "the model predicts the person's intent (label 'intent')" in out
    assert "scored against the tool's path here" in out
    code, out = run("--data", str(tmp_path / "rec"), "--against", "intent")
    assert code == 2 and "--against intent: trial rec/" in out and "records no intent" in out, out
    code, out = run("--data", str(tmp_path / "rec"), "--against", "pose")
    assert code == 2 and "--against 'pose': no such target (choose from: tool, intent)" in out, out


def test_evaluate_replaces_only_its_own_results(tmp_path, trials, tiny):
    """--out replaced any file: a trial file, the model's own sidecar, a figure (each then unreadable); a name
    without .json wrote a file where a folder was meant. Now only an earlier evaluation is replaced."""
    from dataclasses import replace

    from coassist.intent import save_model

    save_model(train_model(trials, tiny, replace(tiny.train, epochs=1)), tmp_path / "m")
    write_dataset([lt.trial for lt in trials], tmp_path / "D", "D")
    sidecar = (tmp_path / "m" / "model.json").read_bytes()
    trial = (tmp_path / "D" / "trial_00000.parquet").read_bytes()

    def run(*out):
        res = CliRunner().invoke(
            app, ["evaluate", "--model", str(tmp_path / "m"), "--data", str(tmp_path / "D"), "--include-training", *out]
        )
        return res.exit_code, " ".join(res.output.split())

    code, out = run("--out", str(tmp_path / "m" / "model.json"))  # JSON, but not an evaluation
    assert code == 1 and "exists and is not a file this command wrote; give another name (nothing replaced)" in out
    code, out = run("--out", str(tmp_path / "D" / "trial_00000.parquet"))
    assert code == 1 and "give a .json file" in out, out
    assert (tmp_path / "m" / "model.json").read_bytes() == sidecar
    assert (tmp_path / "D" / "trial_00000.parquet").read_bytes() == trial
    code, out = run("--out", str(tmp_path / "results"))
    assert code == 1 and "give a .json file, or an existing folder to write evaluation.json in" in out, out
    assert not (tmp_path / "results").exists()
    assert run()[0] == 0 and run()[0] == 0  # its own evaluation.json, written and then replaced
    (tmp_path / "out").mkdir()
    assert run("--out", str(tmp_path / "out"))[0] == 0 and (tmp_path / "out" / "evaluation.json").is_file()


def test_trials_too_short_for_the_longest_horizon_score_the_shorter_ones_and_too_short_for_any_is_one_line(
    trials, tiny
):
    """`coassist evaluate` on trials longer than the history but shorter than history + the longest horizon raised
    "min() arg is an empty sequence" out of the table (a review, 2026-12-07): the horizons they reach are scored, the
    ticks counted at the longest of those, and trials too short for any horizon are refused in one line."""
    from coassist.intent.evaluation import results_table

    model = train_model(trials, tiny, tiny.train)
    n = 27  # history 20: the 5-sample horizon reaches ticks 19-21 of each trial, the 10-sample one none
    short = labeled(3, n=n, prefix="S", first_seed=50)
    res = evaluate_model(model, short)
    assert set(res.results["model"]) == {5} and set(res.best_baseline) == {5}
    assert res.n_ticks == 3 * (n - 5 - (20 - 1))  # ticks 19 … n-6 of each: a full history, and 5 samples measured
    results_table(res)  # a horizon no trial reached has no best, and its cells say "–"
    with pytest.raises(ValueError, match=r"no held-out trial is long enough to score: .* the longest of the 3 has 22"):
        evaluate_model(model, labeled(3, n=22, prefix="R", first_seed=60))
