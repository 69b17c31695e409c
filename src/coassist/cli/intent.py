"""The intent model's commands: ``train``, ``evaluate`` and ``tune``."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import typer
from rich.markup import escape

from coassist.cli._common import (
    BAG_TOPICS_HELP,
    SKIP_BAD_HELP,
    check_device,
    choose,
    console,
    fail,
    file_out,
    folder_out,
    int_list,
    intent_trials,
    lookup,
    typed,
    wrote,
)
from coassist.cli._model_out import check_model_out, continues
from coassist.cli._threads import busy_cores_hint, check_threads, set_torch_threads

# --------------------------------------------------------------------------- intent model


#: The training options as typed, for the fields of TrainConfig / NetworkConfig they set.
TRAIN_OPTIONS = {
    **{
        f"train.{name}": f"--{name.replace('_', '-')}"
        for name in ("epochs", "lr", "batch_size", "seed", "threads", "test_fraction", "init", "device", "optimizer")
    },
    "network.lstm_layers": "--layers",
    "network.hidden": "--hidden",
    "network.fc": "--fc",
    "network.hypotheses": "--hypotheses",
}


AGAINST_HELP = (  # coassist evaluate --against
    "Score every predictor against 'tool' (the tool's future path) or 'intent' (the true intent, simulated trials). "
    "Default: what the model predicts where the trials record it (an intent model on simulated trials), else tool."
)


def _intent_preset(preset: str, *, network: Mapping[str, object] | None = None, **overrides):
    """The intent preset named by --preset, with the training (and network-size) options applied."""
    from dataclasses import replace

    from coassist.intent.presets import MODEL_PRESETS, with_overrides

    chosen = lookup(MODEL_PRESETS, preset, "--preset")
    try:
        p = with_overrides(chosen, **overrides)
        sizes = {k: v for k, v in (network or {}).items() if v is not None}
        if sizes:
            p = replace(p, **sizes)
            p.network(2)  # validates the sizes (NetworkConfig)
        return p
    except ValueError as exc:
        fail(typed(str(exc), TRAIN_OPTIONS), 2)


def _check_start(init: str, preset: str | None) -> None:
    """Refuse in one line a start the training cannot take or would not honour: a linear model (the ridge alone,
    closed form: no network to continue; torch said "optimizer got an empty parameter list") and a --preset whose
    network or label is not the starting model's (the model's were kept without a word). Where model.json cannot be
    read, the reading's error, named --init (it named the file alone)."""
    from coassist.intent.model import ModelFileError, read_sidecar
    from coassist.intent.presets import MODEL_PRESETS

    kind, _, path = init.partition(":")
    if kind not in ("resume", "finetune", "transfer"):
        return  # the preset's own check names what --init may be
    try:
        info = read_sidecar(path)
        layers, label, own = info["network"]["lstm_layers"], info["window"]["label"], info.get("preset")
    except ModelFileError as exc:  # an interrupted run's folder holds its checkpoint beside it, no model yet
        if not continues(Path(path), init):
            fail(f"--init {init}: {exc}", 2)
        if preset is not None:  # it continues on its own settings: another preset was ignored without a word
            from coassist._io import partial_folder

            try:
                own = read_sidecar(partial_folder(Path(path))).get("preset")
            except (ModelFileError, OSError, ValueError):
                own = None
            if preset != own:
                fail(
                    f"--preset {preset}: --init {init} continues an interrupted run on its own settings (preset "
                    f"{own or 'unknown'}): drop --preset, or start a new stage from it with finetune:",
                    2,
                )
        return
    except (OSError, ValueError, KeyError, TypeError):
        return
    if not layers:
        fail(
            f"--init {init}: {path} is a linear model (the tuned ridge alone, closed form): nothing to {kind}; "
            "train it again on the data, or --init scratch",
            2,
        )
    wanted = MODEL_PRESETS.get(preset) if preset is not None else None
    if wanted is not None and (preset == "linear" or wanted.window.label != label):
        fail(
            f"--preset {preset}: --init {kind}: keeps the starting model's network and label ({path}: preset {own}, "
            f"label {label}); there the preset gives the training's settings only: drop --preset, or --init scratch",
            2,
        )


def train(
    data: list[Path] = typer.Argument(
        ...,
        help="Dataset folders, real-recording folders (e.g. .../ur5-thesis/user-a), folders of trial files (drive's runs), bags or single recordings.",
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Model folder to write (weights, model.json, history.json, loss.png)."
    ),
    preset: str = typer.Option(
        None,
        help="Starting configuration: 'default' (LSTM 2×64 learning the residual over the validation-tuned ridge), 'lstm' (the same, skip trained too), 'intent' (lstm learning the simulated operator's true intent: simulated data only), 'linear' (the tuned ridge alone, closed form) or 'thesis' (exact §5.2.2). Default: default. With another --init than scratch, its training settings only (the network and its label are the starting model's).",
    ),
    init: str = typer.Option(
        "scratch", help="scratch | resume:<model> | finetune:<model> | transfer:<model> (LSTM frozen)."
    ),
    epochs: int = typer.Option(None, help="Override the preset's epochs."),
    lr: float = typer.Option(None, help="Override the initial learning rate."),
    batch_size: int = typer.Option(None, help="Override the batch size."),
    seed: int = typer.Option(None, help="Seed of split, init and batch order (default 0)."),
    threads: int = typer.Option(None, help="Torch threads (default 2; at most the cores you may use)."),
    test_fraction: float = typer.Option(None, help="Share of trials held out (default 0.2)."),
    device: str = typer.Option(None, help="Torch device to train on: cpu (default) or cuda."),
    optimizer: str = typer.Option(None, help="Override the optimiser: adam, adamw, rmsprop or sgd."),
    layers: int = typer.Option(None, help="LSTM layers (--init scratch; default: the preset's)."),
    hidden: int = typer.Option(None, help="LSTM hidden size (--init scratch)."),
    fc: str = typer.Option(None, help="Widths of the FC layers after the LSTM, comma-separated (--init scratch)."),
    hypotheses: int = typer.Option(
        None,
        help="Trajectories the network predicts, with a chooser between them (--init scratch; default 1, the thesis); 2 measured no better in the loop (docs/intent-hypotheses.md).",
    ),
    label: str = typer.Option(
        None,
        help="What the model predicts (--init scratch; default: the preset's): tool (the measured future pose, the thesis), hand_alone (the robot's own effort removed: needs trials that log u_r) or intent (the simulated operator's true intent).",
    ),
    overwrite: bool = typer.Option(
        False, help="Replace the model already in --out (only once the new one is complete)."
    ),
    skip_bad_trials: bool = typer.Option(False, help=SKIP_BAD_HELP),
    bag_topics: str = typer.Option(None, help=BAG_TOPICS_HELP),
) -> None:
    """Train the intent predictor (thesis §5.2.2; Algorithm 4.1 with resume:, 4.2 with transfer:).

    After each epoch a checkpoint is kept beside --out (.<name>.partial); if the run is
    stopped, --init resume:<out> continues it where it stopped, with the same result (with
    its own options: one given otherwise is refused); run again without it, it starts again (and
    says so). resume:<out> of a finished model in
    --out is a new stage that replaces it: --overwrite.
    """
    check_model_out(out, overwrite, init)
    folder_out(out, "--out")  # before the slow imports: a bad --out is told at once
    from coassist._io import OutputBusyError, OutputLock
    from coassist.intent.presets import OPTIMIZERS
    from coassist.intent.training import train_model, write_model

    if optimizer is not None:
        choose(optimizer, OPTIMIZERS, "--optimizer", "optimiser")
    check_threads(threads)
    if layers == 0:
        fail("--layers must be >= 1 (a network without its LSTM is the linear predictor: --preset linear)", 2)
    sizes = {
        "lstm_layers": layers,
        "hidden": hidden,
        "fc": None if fc is None else tuple(int_list(fc, "--fc", distinct=False)),
        "hypotheses": hypotheses,
    }
    given = [TRAIN_OPTIONS[f"network.{k}"] for k, v in sizes.items() if v is not None]
    if label is not None:
        from coassist.intent.features import LABELS

        choose(label, LABELS, "--label", "label")
        given.append("--label")
    if given and init != "scratch":
        fail(
            f"{', '.join(given)}: network sizes and the label apply to --init scratch only; {init.partition(':')[0]}: "
            "keeps the starting model's",
            2,
        )
    if init != "scratch":
        _check_start(init, preset)
    p = _intent_preset(
        preset or "default",
        network=sizes,
        epochs=epochs,
        lr=lr,
        batch_size=batch_size,
        seed=seed,
        threads=threads,
        test_fraction=test_fraction,
        init=init,
        device=device,
        optimizer=optimizer,
    )
    if label is not None:
        from dataclasses import replace

        p = replace(p, window=replace(p.window, label=label))
    check_device(device)
    from coassist.data.rosbag_csv import natural_text_key

    # by id, numbers as numbers (trial_2 before trial_10, as a recording's folder is read): the same data given in
    # another order trains the same model (the split already was by id, but the windows and batches followed the
    # order of the arguments: two models from one seed, a review, 2026-12-07)
    trials = sorted(intent_trials(data, skip_bad_trials, bag_topics=bag_topics), key=lambda lt: natural_text_key(lt.id))
    busy_cores_hint(p.train.threads)
    set_torch_threads(p.train.threads)
    try:
        with OutputLock(out):
            if out.is_dir() and any(out.iterdir()) and not overwrite and not continues(out, init):
                # another run wrote a model there since the check above (it held the lock first): not replaced
                fail(
                    f"--out {out}: another coassist run wrote a model there meanwhile; pass --overwrite to replace it",
                    2,
                )
            chosen = {
                "epochs": epochs,
                "lr": lr,
                "batch_size": batch_size,
                "seed": seed,
                "test_fraction": test_fraction,
                "optimizer": optimizer,
            }
            given = [name for name, value in chosen.items() if value is not None]
            model = train_model(trials, p, p.train, progress=True, checkpoint_to=out, given=given)
            write_model(model, out)
    except ValueError as exc:  # mismatched model, unknown init, too-short trials
        fail(typed(str(exc), TRAIN_OPTIONS), 2)
    except OutputBusyError as exc:
        fail(f"{exc}")
    except OSError as exc:
        fail(f"cannot write {exc.filename or out}: {exc.strerror}")
    last = model.info["training_history"][-1]
    console.print(
        f"[green]wrote[/] {escape(str(out))}  train {len(model.info['train_trials'])} / test {len(model.info['test_trials'])} trials, "
        f"final loss (MSE of the scaled targets) train {last['train_loss']:.3e}, test {last['test_loss'] if last['test_loss'] is None else format(last['test_loss'], '.3e')}, "
        f"{model.info['train_seconds']:.0f} s"
    )


def evaluate(
    model: Path = typer.Option(..., "--model", "-m", help="Model folder written by `coassist train`."),
    data: list[Path] = typer.Option(..., "--data", "-d", help="Dataset or recording folders to score on (repeatable)."),
    out: Path = typer.Option(
        None, help="JSON file for the results, or a folder for evaluation.json (default: <model>/evaluation.json)."
    ),
    include_training: bool = typer.Option(
        False, help="Also score trials the model (or the model it was started from) was trained on."
    ),
    skip_bad_trials: bool = typer.Option(False, help=SKIP_BAD_HELP),
    bag_topics: str = typer.Option(None, help=BAG_TOPICS_HELP),
    against: str = typer.Option(None, help=AGAINST_HELP),
) -> None:
    """e_RMS and e_MAX per horizon [mm] for the model and the baselines (nominal, constant velocity, tuned constant
    acceleration and ridge), and the best baseline per horizon with the model's gain over it."""
    if not model.is_dir():
        why = "is a file; give the model's folder (coassist train writes one)" if model.exists() else "no such folder"
        fail(f"--model {model}: {why}", 2)
    import json

    from coassist._io import atomic_write_text
    from coassist.intent import ModelFileError, ModelMismatchError, evaluate_model, load_model, results_table
    from coassist.intent.evaluation import AGAINST, comparison_lines, is_evaluation_file, scoring_target

    dest = file_out(out or model / "evaluation.json", "--out", "evaluation.json", ours=is_evaluation_file, ext=".json")
    from coassist.intent.model import unfinished

    if against is not None:
        choose(against, AGAINST, "--against", "target")
    try:
        m = load_model(model)
    except (ModelFileError, OSError) as exc:
        fail(f"--model {model}: {exc}", 2)
    if why := unfinished(m):  # scored against fewer, untuned baselines it would read better than it is
        fail(f"--model {model}: {why}", 2)
    trials = intent_trials(data, skip_bad_trials, "--data", bag_topics=bag_topics)
    against, note = scoring_target(m.window.label, trials, against)
    try:
        result = evaluate_model(m, trials, held_out_only=not include_training, against=against, progress=True)
    except (ModelMismatchError, ValueError) as exc:
        fail(f"--against {against}: {exc}" if "records no intent" in str(exc) else str(exc), 2)
    title = f"{model}: {len(result.trials)} trials, {result.n_ticks} ticks, against {AGAINST[against]}"
    console.print(results_table(result, title))
    if note:
        console.print(note, markup=False, highlight=False, soft_wrap=True)
    for line in comparison_lines(result):
        console.print(line, highlight=False, soft_wrap=True)
    if result.skipped:
        copied = f", {len(result.copies)} of them copies of training trials under other names" if result.copies else ""
        say = f"skipped {len(result.skipped)} training trials{copied} (use --include-training to score them)"
        console.print(say, markup=False, highlight=False)
    try:
        atomic_write_text(dest, json.dumps({**result.to_dict(), "model": str(model)}, indent=1) + "\n")
    except OSError as exc:
        fail(f"--out {dest}: cannot write ({exc.strerror})")
    wrote(str(dest))


def tune(
    data: list[Path] = typer.Argument(..., help="Dataset or recording folders."),
    preset: str = typer.Option("default", help="Preset whose window and training defaults are searched around."),
    n_trials: int = typer.Option(20, "--trials", help="Optuna trials to run."),
    storage: str = typer.Option("sqlite:///study.db", help="Optuna storage URL (any database URL Optuna accepts)."),
    study_name: str = typer.Option("intent", help="Study name (resumed if it exists and was run on the same trials)."),
    epochs: int = typer.Option(None, help="Epochs per trial (default: the preset's)."),
    seed: int = typer.Option(0, help="Sampler seed."),
    skip_bad_trials: bool = typer.Option(False, help=SKIP_BAD_HELP),
) -> None:
    """Optuna search over optimiser, learning rate and sizes; objective: validation e_RMS at the full horizon.

    Prints the best parameters as the `coassist train` options that use them.
    """
    from sqlalchemy.exc import SQLAlchemyError

    from coassist.intent.tuning import StudyMismatchError, check_storage, run_study, train_options

    for value, option in ((n_trials, "--trials"), (epochs, "--epochs")):
        if value is not None and value < 1:
            fail(f"{option} must be >= 1, got {value}", 2)
    if seed < 0:
        fail(f"--seed must be >= 0, got {seed}", 2)
    try:
        sqlite_file = check_storage(storage)
    except ValueError as exc:
        fail(f"--storage {storage}: {exc}", 2)
    if sqlite_file is not None:
        if sqlite_file.is_dir():  # file_out would write study.db inside: the URL still names the folder
            fail(f"--storage {storage}: {sqlite_file} is a folder; name the database file (e.g. sqlite:///study.db)", 2)
        file_out(sqlite_file, "--storage", "study.db")
        if sqlite_file.is_file() and sqlite_file.stat().st_size > 0:
            with sqlite_file.open("rb") as fh:
                if fh.read(16) != b"SQLite format 3\x00":  # a text file named as the database: refused, kept
                    fail(f"--storage {storage}: {sqlite_file} is not an SQLite database (nothing changed)", 2)
        sqlite_file.parent.mkdir(parents=True, exist_ok=True)  # SQLite makes the file, not its folder
    if not study_name.strip():
        fail("--study-name must not be empty (it names the study in the database)", 2)
    p = _intent_preset(preset)
    trials = intent_trials(data, skip_bad_trials)  # its errors point to --skip-bad-trials, which tune has too
    busy_cores_hint(p.train.threads)
    set_torch_threads(p.train.threads)
    try:
        result = run_study(
            trials,
            p,
            n_trials=n_trials,
            storage=storage,
            study_name=study_name,
            epochs=epochs,
            seed=seed,
            progress=True,
        )
    except StudyMismatchError as exc:
        fail(f"--study-name {study_name}: {exc}", 2)
    except ValueError as exc:
        fail(str(exc), 2)
    except SQLAlchemyError as exc:  # a damaged database file, a server that refuses: one line naming the option
        fail(f"--storage {storage}: {getattr(exc, 'orig', None) or exc}", 2)
    console.print(f"best validation e_RMS {1e3 * result['best_value']:.2f} mm", highlight=False)
    # what the study trained: its preset and epochs too (without them the command trained another configuration)
    setup = [*(["--preset", preset] if preset != "default" else []), *(["--epochs", str(epochs)] if epochs else [])]
    console.print(
        f"train with them: coassist train {' '.join(map(str, data))} --out <model> "
        f"{' '.join([*setup, *train_options(result['best_params'])])}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )
    console.print(f"study {result['study_name']!r} in {result['storage']} ({result['n_trials']} trials)", markup=False)
