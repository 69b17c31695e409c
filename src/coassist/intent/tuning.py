"""Hyper-parameter search with Optuna (thesis §5.2.2: optimiser and learning rate).

The search never sees the test trials: the training trials of the usual split are split
again into fit and validation trials, and the objective is the validation e_RMS at the
model's full horizon (m). Studies live in any database Optuna accepts; the default is
SQLite (``sqlite:///study.db``), so a search can be stopped and resumed. A study records
the trials it fits and validates on; resuming it on other data is refused
(:class:`StudyMismatchError`), since its trials would not be comparable.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from coassist.errors import CoassistError
from coassist.intent.evaluation import evaluate_model
from coassist.intent.features import split_trials, validation_split
from coassist.intent.presets import Preset
from coassist.intent.training import train_model
from coassist.intent.trials import LabeledTrial

__all__ = ["StudyMismatchError", "check_storage", "run_study", "train_options"]

_DATA_KEY = "coassist_trials"  # study user attribute: the fit and validation trial ids
_SETUP_KEY = "coassist_setup"  # study user attribute: the preset and the epochs a trial (a study before it: none)


class StudyMismatchError(CoassistError, ValueError):
    """An existing study was run on other trials than the ones given."""


def check_storage(url: str) -> Path | None:
    """Check an Optuna storage URL before any work; return the SQLite file it names, if any.

    Raises ``ValueError`` saying what is wrong (not a URL, an unknown database kind, a
    driver that is not installed).
    """
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError):
        raise ValueError("not a database URL (e.g. sqlite:///study.db or postgresql://user@host/db)") from None
    try:
        parsed.get_dialect()
    except NoSuchModuleError:
        raise ValueError(f"unknown database kind {parsed.drivername!r} (e.g. sqlite:///study.db)") from None
    except ImportError as exc:
        raise ValueError(f"the database driver for {parsed.drivername!r} is not installed ({exc.name})") from None
    if parsed.get_backend_name() == "sqlite" and parsed.database not in (None, "", ":memory:"):
        return Path(parsed.database)
    return None


def train_options(best_params: dict[str, Any]) -> list[str]:
    """The ``coassist train`` options that reproduce a study's best parameters."""
    names = {"optimizer": "--optimizer", "lr": "--lr", "lstm_layers": "--layers", "hidden": "--hidden", "fc": "--fc"}
    out: list[str] = []
    for key, option in names.items():
        if key in best_params:
            value = best_params[key]
            out += [option, f"{value:.4g}" if isinstance(value, float) else str(value)]
    return out


def run_study(
    trials: Sequence[LabeledTrial],
    preset: Preset,
    *,
    n_trials: int = 20,
    storage: str = "sqlite:///study.db",
    study_name: str = "intent",
    epochs: int | None = None,
    seed: int = 0,
    progress: bool = False,
) -> dict[str, Any]:
    """Search optimiser, learning rate, LSTM depth and width, FC width.

    Returns ``{"best_params", "best_value", "n_trials", "storage", "study_name"}``.
    """
    import optuna

    if n_trials < 1:
        raise ValueError(f"n_trials must be >= 1, got {n_trials}")
    ids = [lt.id for lt in trials]
    train_idx, _ = split_trials(ids, preset.train.test_fraction, preset.train.seed)
    pool = [trials[i] for i in train_idx]
    if len(pool) < 2:
        raise ValueError("tuning needs at least two training trials (one to fit, one to validate)")
    fit_idx, val_idx = validation_split([lt.id for lt in pool], seed)
    fit = [pool[i] for i in fit_idx]
    val = [pool[i] for i in val_idx]
    horizon = preset.window.horizon

    def objective(trial: optuna.Trial) -> float:
        params = {
            "optimizer": trial.suggest_categorical("optimizer", ["adam", "adamw", "rmsprop"]),
            "lr": trial.suggest_float("lr", 1e-4, 1e-2, log=True),
        }
        p = replace(
            preset,
            lstm_layers=trial.suggest_int("lstm_layers", 1, 3),
            hidden=trial.suggest_categorical("hidden", [32, 64, 128, 256]),
            fc=(trial.suggest_categorical("fc", [32, 64, 128, 256]),),
            train=replace(preset.train, test_fraction=0.0, epochs=epochs or preset.train.epochs, seed=seed, **params),
        )
        model = train_model(fit, p, p.train)
        result = evaluate_model(model, val, horizons=(horizon,), held_out_only=False)
        return result.results["model"][horizon]["e_rms"]

    sampler = optuna.samplers.TPESampler(seed=seed)
    study = optuna.create_study(
        storage=storage, study_name=study_name, direction="minimize", sampler=sampler, load_if_exists=True
    )
    # a resumed study draws on from where it stopped (its sampler seeded past the trials it holds: seeded as at its
    # start, TPE drew its first points again, a repeat of trials already run)
    study.sampler = optuna.samplers.TPESampler(seed=seed + len(study.trials))
    data = {"fit": [lt.id for lt in fit], "validation": [lt.id for lt in val]}
    setup = {"preset": preset.name, "epochs": int(epochs or preset.train.epochs)}
    held = study.user_attrs.get(_SETUP_KEY)
    if held is not None and held != setup:
        raise StudyMismatchError(
            f"study {study_name!r} in {storage} was run with preset {held['preset']}, {held['epochs']} epochs a trial "
            f"(this run: {setup['preset']}, {setup['epochs']}): resuming it would mix incomparable results; give "
            "the same, or another study name"
        )
    recorded = study.user_attrs.get(_DATA_KEY)
    if recorded is None and study.trials:
        raise StudyMismatchError(
            f"study {study_name!r} in {storage} already has {len(study.trials)} trials and no record of its data; "
            "give another study name"
        )
    if recorded is not None and recorded != data:
        datasets = sorted({i.rsplit("/", 1)[0] for i in recorded["fit"] + recorded["validation"]})
        raise StudyMismatchError(
            f"study {study_name!r} in {storage} was run on other trials (datasets {', '.join(datasets)}); "
            "resuming it would mix incomparable results: give another study name or storage"
        )
    if recorded is None:
        study.set_user_attr(_DATA_KEY, data)
    if held is None:
        study.set_user_attr(_SETUP_KEY, setup)
    study.optimize(objective, n_trials=n_trials, show_progress_bar=progress)
    return {
        "best_params": study.best_params,
        "best_value": study.best_value,
        "n_trials": len(study.trials),
        "storage": storage,
        "study_name": study_name,
        "fit_trials": [lt.id for lt in fit],
        "validation_trials": [lt.id for lt in val],
    }
