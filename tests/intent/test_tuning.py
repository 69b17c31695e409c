"""The Optuna study (coassist.intent.tuning) on small synthetic trials: seconds, not hours."""

from __future__ import annotations

from dataclasses import replace

import pytest

optuna = pytest.importorskip("optuna", reason="the 'learn' extra (torch, optuna) is not installed")

from coassist.intent.evaluation import evaluate_model  # noqa: E402
from coassist.intent.features import split_trials  # noqa: E402
from coassist.intent.training import train_model  # noqa: E402
from coassist.intent.tuning import StudyMismatchError, check_storage, run_study  # noqa: E402

from .conftest import TINY, labeled  # noqa: E402

N_TRIALS = 3
EPOCHS = 1
# The space of thesis §5.2.2 as run_study documents it: optimiser, learning rate, LSTM
# depth and width, FC width.
SPACE = {
    "optimizer": optuna.distributions.CategoricalDistribution(["adam", "adamw", "rmsprop"]),
    "lr": optuna.distributions.FloatDistribution(1e-4, 1e-2, log=True),
    "lstm_layers": optuna.distributions.IntDistribution(1, 3),
    "hidden": optuna.distributions.CategoricalDistribution([32, 64, 128, 256]),
    "fc": optuna.distributions.CategoricalDistribution([32, 64, 128, 256]),
}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    trials = labeled(6, n=220)
    storage = f"sqlite:///{tmp_path_factory.mktemp('tuning') / 'study.db'}"
    # (about 8 s for the three trials on the 2-core project machine)
    result = run_study(trials, TINY, n_trials=N_TRIALS, storage=storage, study_name="tiny", epochs=EPOCHS, seed=0)
    return trials, result, optuna.load_study(study_name="tiny", storage=storage)


def test_a_tiny_study_completes_every_trial(study):
    _, result, loaded = study
    assert result["n_trials"] == N_TRIALS == len(loaded.trials)
    assert all(t.state == optuna.trial.TrialState.COMPLETE for t in loaded.trials)
    assert result["storage"].startswith("sqlite:///") and result["study_name"] == "tiny"


def test_every_trial_stays_in_the_search_space(study):
    _, _, loaded = study
    for trial in loaded.trials:
        assert trial.distributions == SPACE
        p = trial.params
        assert p["optimizer"] in ("adam", "adamw", "rmsprop")
        assert 1e-4 <= p["lr"] <= 1e-2
        assert p["lstm_layers"] in (1, 2, 3)
        assert p["hidden"] in (32, 64, 128, 256) and p["fc"] in (32, 64, 128, 256)


def test_best_is_the_minimum_of_the_trials(study):
    _, result, loaded = study
    values = [t.value for t in loaded.trials]
    assert result["best_value"] == min(values) > 0
    best = loaded.trials[values.index(min(values))]
    assert result["best_params"] == best.params


def test_the_search_never_sees_the_test_trials(study):
    trials, result, _ = study
    ids = [lt.id for lt in trials]
    train_idx, test_idx = split_trials(ids, TINY.train.test_fraction, TINY.train.seed)
    fit, val = set(result["fit_trials"]), set(result["validation_trials"])
    assert fit and val and not fit & val
    assert fit | val == {ids[i] for i in train_idx}
    assert not (fit | val) & {ids[i] for i in test_idx}


def test_the_best_parameters_reproduce_the_best_value(study):
    # Train once more, outside the study, with the recorded best parameters on the fit
    # trials and score the validation trials: the same e_RMS, so the parameters recorded
    # are the ones that were used.
    trials, result, _ = study
    best = result["best_params"]
    by_id = {lt.id: lt for lt in trials}
    fit = [by_id[i] for i in result["fit_trials"]]
    val = [by_id[i] for i in result["validation_trials"]]
    preset = replace(
        TINY,
        lstm_layers=best["lstm_layers"],
        hidden=best["hidden"],
        fc=(best["fc"],),
        train=replace(TINY.train, test_fraction=0.0, epochs=EPOCHS, seed=0, optimizer=best["optimizer"], lr=best["lr"]),
    )
    model = train_model(fit, preset, preset.train)
    horizon = TINY.window.horizon
    scored = evaluate_model(model, val, horizons=(horizon,), held_out_only=False)
    assert scored.results["model"][horizon]["e_rms"] == pytest.approx(result["best_value"], rel=1e-9)


def test_a_study_on_other_trials_is_not_resumed(study):
    _, result, _ = study
    other = labeled(6, n=220, prefix="U")
    with pytest.raises(StudyMismatchError, match=r"study 'tiny' .* was run on other trials \(datasets T\)"):
        run_study(other, TINY, n_trials=1, storage=result["storage"], study_name="tiny", epochs=EPOCHS)


def test_a_study_without_a_data_record_is_not_resumed(tmp_path):
    storage = f"sqlite:///{tmp_path / 'foreign.db'}"
    foreign = optuna.create_study(storage=storage, study_name="intent")
    foreign.add_trial(optuna.trial.create_trial(value=1.0))
    with pytest.raises(StudyMismatchError, match="already has 1 trials and no record of its data"):
        run_study(labeled(6, n=220), TINY, n_trials=1, storage=storage, study_name="intent", epochs=EPOCHS)


@pytest.mark.parametrize(
    "kwargs, trials, message",
    [
        (dict(n_trials=0), 6, "n_trials must be >= 1, got 0"),
        (dict(n_trials=1), 2, "needs at least two training trials"),
    ],
)
def test_bad_requests_fail_before_any_training(kwargs, trials, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        run_study(labeled(trials, n=220), TINY, storage=f"sqlite:///{tmp_path / 's.db'}", **kwargs)


def test_check_storage(tmp_path):
    assert check_storage(f"sqlite:///{tmp_path / 'study.db'}") == tmp_path / "study.db"
    assert check_storage("sqlite:///:memory:") is None
    with pytest.raises(ValueError, match=r"unknown database kind 'bogus'"):
        check_storage("bogus://x")
    with pytest.raises(ValueError, match="not a database URL"):
        check_storage("study.db")


def test_a_resumed_study_draws_new_points_and_keeps_its_setup(tmp_path, study):
    """Resumed, the study's sampler was seeded as at its start: TPE drew its first points again (trials 0 and 3 the
    same parameters, the same value); another preset or epochs count was run into the same study (review, 2026-12-06)."""
    trials, result, _ = study
    storage = f"sqlite:///{tmp_path / 'resumed.db'}"
    run_study(trials, TINY, n_trials=2, storage=storage, study_name="r", epochs=EPOCHS, seed=0)
    run_study(trials, TINY, n_trials=1, storage=storage, study_name="r", epochs=EPOCHS, seed=0)
    params = [t.params for t in optuna.load_study(study_name="r", storage=storage).trials]
    assert len(params) == 3 and params[2] not in params[:2]
    with pytest.raises(
        StudyMismatchError, match=r"study 'r' .* was run with preset tiny, 1 epochs a trial \(this run: tiny, 2\)"
    ):
        run_study(trials, TINY, n_trials=1, storage=storage, study_name="r", epochs=2, seed=0)
