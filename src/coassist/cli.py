"""The ``coassist`` command: a thin shell over the experiments and tools.

Each command parses and validates its options, then calls one function of the
library; no computation lives here.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import NoReturn, TypeVar

import click
import typer
from rich.console import Console
from rich.markup import escape

from coassist.config import APPLICATION_PRESET, COLLECTION_PRESET
from coassist.interfaces import NETWORK_BACKENDS
from coassist.registry import Registry, UnknownNameError, unknown_name_message
from coassist.robot.worlds import WORLDS, arm_choices, world_choices
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.intent_registry import INTENT_SOURCES, check_intent, intent_choices

T = TypeVar("T")

app = typer.Typer(
    help="coassist — assistive pHRI: cooperative game-theoretic MPC with learned human intent.",
    no_args_is_help=True,
    add_completion=False,
    # Plain click help: rich markup would swallow bracketed text ("[s]", "coassist[cluster]"),
    # and its boxed layout leaves a narrow column for the help text at 80 columns.
    rich_markup_mode=None,
)
console = Console()
err_console = Console(stderr=True, highlight=False)


@app.callback()
def main() -> None:
    """coassist — assistive pHRI: cooperative game-theoretic MPC with learned human intent."""


# --------------------------------------------------------------------------- shared checks
# Each runs before any work starts and ends in one line that names the option as typed.


def _fail(message: str, code: int = 1) -> NoReturn:
    """Print ``error: <message>`` on stderr (as plain text: brackets stay) and exit with ``code``."""
    err_console.print(f"error: {message}", markup=False, soft_wrap=True)
    raise typer.Exit(code)


def _typed(message: str, options: Mapping[str, str]) -> str:
    """``message`` with config field names (``train.epochs``) replaced by the options typed (``--epochs``)."""
    for name in sorted(options, key=len, reverse=True):
        message = re.sub(rf"(?<![\w.-]){re.escape(name)}(?![\w])", options[name], message)
    return message


def _choose(value: str, choices: Iterable[str], option: str, what: str) -> str:
    """``value`` if it is one of ``choices``, else fail naming the option, with a "did you mean"
    (for a controller's former name, its kind: ``coassist.control.presets.FORMER_NAMES``)."""
    choices = list(choices)
    if value in choices:
        return value
    if what == "controller":
        from coassist.control.presets import FORMER_NAMES

        if FORMER_NAMES.get(value) in choices:
            _fail(f"{option} {value!r} is now called {FORMER_NAMES[value]!r} (choose from: {', '.join(choices)})", 2)
    _fail(f"{option} {unknown_name_message(value, choices, what)}", 2)


def _lookup(registry: Registry[T], name: str, option: str) -> T:
    """The preset ``name`` of ``registry`` (any kind), else fail naming the option, with a "did you mean"."""
    try:
        return registry.lookup(name)
    except UnknownNameError as exc:
        _fail(f"{option} {exc}", 2)


def _existing_ancestor(path: Path) -> Path:
    """The nearest of ``path`` and its parents that exists (``.`` at worst)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path.parent != path:
        path = path.parent
    return path


def _folder_out(path: Path, option: str, typed: Path | None = None) -> Path:
    """Fail now unless ``path`` is, or can be made, a folder this user can write in.

    ``typed``: what the user gave, when ``path`` is derived from it (a file's folder).
    """
    shown = f"{option} {path if typed is None else typed}"
    if path.exists() and not path.is_dir():
        _fail(f"{shown}: {path} is a file, not a folder")
    base = _existing_ancestor(path)
    if not base.is_dir():
        _fail(f"{shown}: {base} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        _fail(f"{shown}: {base} is not writable (permission denied)")
    return path


def _file_out(path: Path, option: str, default_name: str) -> Path:
    """The file to write for ``--out path``: ``path`` itself, or ``path/default_name`` if it is a folder.

    Fails now (not after the work) if the file's folder cannot be created or written.
    """
    if path.is_dir():
        path = path / default_name
    if path.is_dir():
        _fail(f"{option} {path}: is a folder; give a file name")
    _folder_out(path.parent, option, typed=path)
    if path.exists() and not os.access(path, os.W_OK):
        _fail(f"{option} {path}: is not writable (permission denied)")
    return path


def _check_device(device: str | None, option: str = "--device") -> None:
    """Fail now if the torch device cannot be used here (not after loading the data)."""
    if device is None:
        return
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        _fail(f"{option} {device!r}: not a torch device (use cpu, cuda or cuda:<n>)", 2)
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            built = "built with CUDA, but no GPU is visible" if torch.backends.cuda.is_built() else "built without CUDA"
            _fail(
                f"{option} {device}: CUDA is not available here (torch {torch.__version__} {built}); use --device cpu"
            )
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            _fail(f"{option} {device}: this machine has {torch.cuda.device_count()} CUDA device(s)")
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        _fail(f"{option} {device}: Apple MPS is not available here; use --device cpu")
    elif dev.type not in ("cpu", "cuda", "mps"):
        _fail(f"{option} {device}: use cpu, cuda or cuda:<n>", 2)


def _set_torch_threads(threads: int) -> None:
    """Torch's intra-op thread count for this process: the command's choice (the library never sets it)."""
    import torch

    torch.set_num_threads(threads)


def _wrote(text: str) -> None:
    console.print(f"[green]wrote[/] {escape(text)}", highlight=False, soft_wrap=True)  # paths stay whole


# --------------------------------------------------------------------------- the live view (--foxglove)
#: The bare ``--foxglove`` port of the commands without a page (the Foxglove app's default), and of
#: play and study run, whose page listens on 8765.
FOXGLOVE_PORT, FOXGLOVE_PAGE_PORT = 8765, 8766
_LIVE_HELP = (
    "Serve the run live to the Foxglove app on this port (bare --foxglove: {port}; the viz extra): "
    "ws://127.0.0.1:PORT, the MCAP file's topics and the scene at 30 Hz (docs/foxglove.md)."
)


def _live_command(port: int) -> type:
    """A command class whose ``--foxglove`` takes an optional port: bare (followed by nothing, another
    option or an argument that is not a number) it means ``port`` (typer has no optional values)."""
    from typer.core import TyperCommand

    class LiveCommand(TyperCommand):
        def parse_args(self, ctx, args):
            out = list(args)
            for i, arg in enumerate(out):
                if arg == "--":
                    break
                if arg == "--foxglove" and not (i + 1 < len(out) and re.fullmatch(r"[+-]?\d+", out[i + 1])):
                    out[i] = f"--foxglove={port}"
            return super().parse_args(ctx, out)

    return LiveCommand


def _open_live(port: int | None, page_port: int | None = None):
    """The live view's feed on ``port`` (None: no --foxglove), or one line saying why not: a port out
    of range, the page's own, one in use, the viz extra missing. Started before anything moves."""
    if port is None:
        return None
    if not 0 <= port <= 65535:
        _fail(f"--foxglove must be a port in 1 … 65535 (0: any free one), got {port}", 2)
    if page_port is not None and port == page_port and port != 0:
        _fail(
            f"--foxglove {port}: the page listens on it (--port); give the live view another, e.g. --foxglove {port + 1}",
            2,
        )
    from coassist.runtime.foxglove import LiveServerError, open_foxglove

    try:
        feed, sink = open_foxglove(port)
    except ImportError as exc:
        _fail(f"--foxglove: {exc}", 2)
    except (LiveServerError, ValueError) as exc:
        _fail(f"--foxglove {port}: {exc}", 2)
    console.print(
        f"live view: open {sink.url} in Foxglove (Open connection, Foxglove WebSocket)",
        highlight=False,
        markup=False,
        soft_wrap=True,
    )
    return feed


def _close_live(feed) -> None:
    """Publish the last tick and stop the live view; say so if publishing failed on the way."""
    if feed is None:
        return
    feed.close()
    if feed.failures:
        err_console.print(f"live view: {feed.failures} tick(s) not published ({feed.last_error})", markup=False)


@app.command()
def sweep(
    out: Path = typer.Option(Path("runs/sweep"), help="Output folder for the figure grid and summary.json."),
    duration: float = typer.Option(10.0, help="Simulated time per case [s]."),
    position_scale: float = typer.Option(
        None,
        help="Output scaling of positions in the cost (see README). Default: the one that reproduces the thesis' figures.",
    ),
) -> None:
    """The dMPC study of thesis §5.2.1 (Fig. 5.2–5.4): α, R_r and horizon swept on sinusoidal references."""
    from coassist.experiments import dmpc_study

    kwargs = {} if position_scale is None else {"position_scale": position_scale}
    try:
        config = dmpc_study.SweepConfig(duration=duration, **kwargs)
    except ValueError as exc:
        _fail(_typed(str(exc), {"duration": "--duration", "position_scale": "--position-scale"}), 2)
    _folder_out(out, "--out")
    result = dmpc_study.run_sweep(config, out, progress=True)
    dmpc_study.print_summary(result, console)
    _wrote(f"{out / 'summary.json'} and {out / 'dmpc_sweep.png'}")


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
}


def _intent_preset(preset: str, *, network: Mapping[str, object] | None = None, **overrides):
    """The intent preset named by --preset, with the training (and network-size) options applied."""
    from dataclasses import replace

    from coassist.intent.training import MODEL_PRESETS, with_overrides

    chosen = _lookup(MODEL_PRESETS, preset, "--preset")
    try:
        p = with_overrides(chosen, **overrides)
        sizes = {k: v for k, v in (network or {}).items() if v is not None}
        if sizes:
            p = replace(p, **sizes)
            p.network(2)  # validates the sizes (NetworkConfig)
        return p
    except ValueError as exc:
        _fail(_typed(str(exc), TRAIN_OPTIONS), 2)


SKIP_BAD_HELP = "Leave out trials that cannot be read, saying which and why (default: stop at the first)."


def _need_bags(option: str) -> None:
    """Refuse ``option`` before any work when rosbags (the bags extra) is missing."""
    try:
        import rosbags  # noqa: F401
    except ImportError:
        _fail(f"{option} needs the bags extra (rosbags): pip install 'coassist[bags]'", 2)


BAG_TOPICS_HELP = (
    "Topics of bags, where they differ from the thesis' (/current_pose, /current_velocity, /human_wrench, "
    "/robot_ref_pos): e.g. wrench=/ft/wrench,pose=/tcp_pose."
)


def _bag_topics(text: str | None) -> dict[str, str] | None:
    """``--bag-topics field=/topic,…`` checked before any work."""
    if text is None:
        return None
    from coassist.data.bags import resolve_topics

    pairs = [item.partition("=") for item in text.split(",") if item.strip()]
    if not pairs or any(not sep for _, sep, _ in pairs):
        _fail(f"--bag-topics: expected field=/topic pairs separated by commas, got {text!r}", 2)
    topics = {k.strip(): v.strip() for k, _, v in pairs}
    try:
        resolve_topics(topics)
    except ValueError as exc:
        _fail(f"--bag-topics: {exc}", 2)
    return topics


def _intent_trials(paths: list[Path], skip_bad: bool = False, option: str = "DATA", bag_topics: str | None = None):
    import warnings

    from coassist.data import RecordingError, TrialFileError
    from coassist.data.store import ManifestError
    from coassist.intent import load_trials

    def skipped(where: str, reason: str) -> None:
        reason = reason.removeprefix(f"{where}: ")  # the reason usually names the file already
        console.print(f"[yellow]skipped[/] {where}: {reason}", highlight=False)

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            trials = load_trials(paths, on_bad=skipped if skip_bad else None, bag_topics=_bag_topics(bag_topics))
    except ImportError as exc:  # a bag without the bags extra
        _fail(f"{option}: {exc}", 2)
    except (FileNotFoundError, ValueError) as exc:
        one_trial = isinstance(exc, (TrialFileError, RecordingError)) and not isinstance(exc, ManifestError)
        hint = " (--skip-bad-trials leaves unreadable trials out)" if one_trial and not skip_bad else ""
        _fail(f"{option}: {exc}{hint}", 2)
    for w in caught:
        console.print(f"[yellow]warning:[/] {w.message}", highlight=False)
    return trials


def _check_model_out(out: Path, overwrite: bool, init: str) -> None:
    """Refuse before any work an --out that is a file, or an existing model without --overwrite."""
    bad_parent = next((p for p in reversed(out.parents) if p.exists() and not p.is_dir()), None)
    if bad_parent is not None:
        _fail(f"--out {out}: {bad_parent} is a file, not a folder", 2)
    if out.exists() and not out.is_dir():
        _fail(f"--out {out}: is a file; give a folder for the model", 2)
    continuing = init.startswith("resume:") and Path(init.partition(":")[2]).absolute() == out.absolute()
    if out.is_dir() and any(out.iterdir()) and not (overwrite or continuing):
        _fail(
            f"--out {out}: already holds files; pass --overwrite to replace it (the old model stays until the new "
            "one is complete)",
            2,
        )


@app.command()
def train(
    data: list[Path] = typer.Argument(
        ..., help="Dataset folders, real-recording folders (e.g. .../ur5-thesis/user-a) or single recordings."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Model folder to write (weights, model.json, history.json, loss.png)."
    ),
    preset: str = typer.Option(
        "default",
        help="Starting configuration: 'default' (LSTM 2×64 learning the residual over the validation-tuned ridge), 'lstm' (the same, skip trained too), 'intent' (lstm learning the simulated operator's true intent: simulated data only), 'linear' (the tuned ridge alone, closed form) or 'thesis' (exact §5.2.2).",
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
    stopped, --init resume:<out> continues it where it stopped, with the same result.
    """
    _check_model_out(out, overwrite, init)
    _folder_out(out, "--out")  # before the slow imports: a bad --out is told at once
    from coassist._io import OutputBusyError, OutputLock
    from coassist.intent.training import OPTIMIZERS, train_model, write_model

    if optimizer is not None:
        _choose(optimizer, OPTIMIZERS, "--optimizer", "optimiser")
    sizes = {"lstm_layers": layers, "hidden": hidden, "fc": None if fc is None else tuple(_int_list(fc, "--fc"))}
    given = [TRAIN_OPTIONS[f"network.{k}"] for k, v in sizes.items() if v is not None]
    if label is not None:
        from coassist.intent.features import LABELS

        _choose(label, LABELS, "--label", "label")
        given.append("--label")
    if given and init != "scratch":
        _fail(
            f"{', '.join(given)}: network sizes and the label apply to --init scratch only; {init.partition(':')[0]}: "
            "keeps the starting model's",
            2,
        )
    p = _intent_preset(
        preset,
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
    _check_device(device)
    trials = _intent_trials(data, skip_bad_trials, bag_topics=bag_topics)
    _set_torch_threads(p.train.threads)
    try:
        with OutputLock(out):
            model = train_model(trials, p, p.train, progress=True, checkpoint_to=out)
            write_model(model, out)
    except ValueError as exc:  # mismatched model, unknown init, too-short trials
        _fail(_typed(str(exc), TRAIN_OPTIONS), 2)
    except OutputBusyError as exc:
        _fail(f"{exc}")
    except OSError as exc:
        _fail(f"cannot write {exc.filename or out}: {exc.strerror}")
    last = model.info["training_history"][-1]
    console.print(
        f"[green]wrote[/] {escape(str(out))}  train {len(model.info['train_trials'])} / test {len(model.info['test_trials'])} trials, "
        f"final loss (MSE of the scaled targets) train {last['train_loss']:.3e}, test {last['test_loss'] if last['test_loss'] is None else format(last['test_loss'], '.3e')}, "
        f"{model.info['train_seconds']:.0f} s"
    )


@app.command()
def evaluate(
    model: Path = typer.Option(..., "--model", "-m", help="Model folder written by `coassist train`."),
    data: list[Path] = typer.Option(..., "--data", "-d", help="Dataset or recording folders to score on (repeatable)."),
    out: Path = typer.Option(
        None, help="JSON file for the results, or a folder for evaluation.json (default: <model>/evaluation.json)."
    ),
    include_training: bool = typer.Option(False, help="Also score trials the model was trained on."),
    skip_bad_trials: bool = typer.Option(False, help=SKIP_BAD_HELP),
    bag_topics: str = typer.Option(None, help=BAG_TOPICS_HELP),
) -> None:
    """e_RMS and e_MAX per horizon [mm] for the model and the baselines (nominal, constant velocity, tuned constant
    acceleration and ridge), and the best baseline per horizon with the model's gain over it."""
    if not model.exists():
        _fail(f"--model {model}: no such folder", 2)
    dest = _file_out(out or model / "evaluation.json", "--out", "evaluation.json")
    import json

    from coassist._io import atomic_write_text
    from coassist.intent import ModelFileError, ModelMismatchError, evaluate_model, load_model, results_table
    from coassist.intent.evaluation import comparison_lines

    try:
        m = load_model(model)
    except (ModelFileError, OSError) as exc:
        _fail(f"--model {model}: {exc}", 2)
    trials = _intent_trials(data, skip_bad_trials, "--data", bag_topics=bag_topics)
    try:
        result = evaluate_model(m, trials, held_out_only=not include_training)
    except (ModelMismatchError, ValueError) as exc:
        _fail(str(exc), 2)
    console.print(results_table(result, f"{model}: {len(result.trials)} trials, {result.n_ticks} ticks"))
    for line in comparison_lines(result):
        console.print(line, highlight=False, soft_wrap=True)
    if result.skipped:
        console.print(f"skipped {len(result.skipped)} training trials (use --include-training to score them)")
    try:
        atomic_write_text(dest, json.dumps({**result.to_dict(), "model": str(model)}, indent=1) + "\n")
    except OSError as exc:
        _fail(f"--out {dest}: cannot write ({exc.strerror})")
    _wrote(str(dest))


@app.command()
def tune(
    data: list[Path] = typer.Argument(..., help="Dataset or recording folders."),
    preset: str = typer.Option("default", help="Preset whose window and training defaults are searched around."),
    n_trials: int = typer.Option(20, "--trials", help="Optuna trials to run."),
    storage: str = typer.Option("sqlite:///study.db", help="Optuna storage URL (any database URL Optuna accepts)."),
    study_name: str = typer.Option("intent", help="Study name (resumed if it exists and was run on the same trials)."),
    epochs: int = typer.Option(None, help="Epochs per trial (default: the preset's)."),
    seed: int = typer.Option(0, help="Sampler seed."),
) -> None:
    """Optuna search over optimiser, learning rate and sizes; objective: validation e_RMS at the full horizon.

    Prints the best parameters as the `coassist train` options that use them.
    """
    from coassist.intent.tuning import StudyMismatchError, check_storage, run_study, train_options

    for value, option in ((n_trials, "--trials"), (epochs, "--epochs")):
        if value is not None and value < 1:
            _fail(f"{option} must be >= 1, got {value}", 2)
    if seed < 0:
        _fail(f"--seed must be >= 0, got {seed}", 2)
    try:
        sqlite_file = check_storage(storage)
    except ValueError as exc:
        _fail(f"--storage {storage}: {exc}", 2)
    if sqlite_file is not None:
        _file_out(sqlite_file, "--storage", "study.db")
    p = _intent_preset(preset)
    trials = _intent_trials(data)
    _set_torch_threads(p.train.threads)
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
        _fail(f"--study-name {study_name}: {exc}", 2)
    except ValueError as exc:
        _fail(str(exc), 2)
    console.print(f"best validation e_RMS {1e3 * result['best_value']:.2f} mm", highlight=False)
    console.print(
        f"train with them: coassist train {' '.join(map(str, data))} --out <model> "
        f"{' '.join(train_options(result['best_params']))}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )
    console.print(f"study {result['study_name']!r} in {result['storage']} ({result['n_trials']} trials)", markup=False)


def _int_list(text: str, option: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        _fail(f"{option} must be comma-separated integers, got {text!r}", 2)
    if not values or any(v < 0 for v in values):
        _fail(f"{option} must list integers >= 0, got {text!r}", 2)
    return values


def _name_list(text: str, option: str, allowed: tuple[str, ...], what: str) -> list[str]:
    values = [v.strip() for v in text.split(",") if v.strip()]
    if not values:
        _fail(f"{option} must list one or more of {', '.join(allowed)}; got {text!r}", 2)
    return [_choose(v, allowed, option, what) for v in values]


def _print_forces(folder: Path) -> None:
    """The hand's and the robot's f_RMS (eq. 5.9) over a dataset: how much the robot helped."""
    import numpy as np

    from coassist.data.store import manifest_files, read_dataset_trial
    from coassist.metrics import f_rms

    # one trial in memory at a time: the summary's memory does not grow with the dataset
    hand, robot = [], []
    for i in range(len(manifest_files(folder))):
        trial = read_dataset_trial(folder, i)
        hand.append(f_rms(trial.wrench))
        robot.append(f_rms(trial.effort_r))
    console.print(
        f"f_RMS (eq. 5.9), mean over {len(hand)} trials: hand {float(np.mean(hand)):.2f} N, "
        f"robot {float(np.mean(robot)):.2f} N",
        highlight=False,
    )


ARM_CONTROLLER_HELP = (
    "cooperative (the assistive controller: the cooperative game) | cooperative-arbitrated (α set every tick "
    "by the target law) | cooperative-damped (arbitrated, damped while the tool slows) | impedance (IMP) | "
    "manual (MG, manual guidance) | manual-probe (a calibration trial, no assistance: MG plus a small known "
    "push that measures the arm; fit the trials with coassist calibrate)."
)
INTENT_DEFAULT_HELP = (
    f"Default {DEFAULT_INTENT}: {INTENT_SOURCES[DEFAULT_INTENT].summary}, the safest measured without a "
    "calibration (docs/precision.md); with one, the person-model folder coassist calibrate wrote."
)
PERSON_HELP = (
    "The person at the handle, a pseudonymous id (e.g. P07): the trial's user and whose calibration a person "
    "model (--intent FOLDER) uses (default: operator on a real arm, user-<user> in MuJoCo)."
)
SCENE_HELP = (
    "A scene file (TOML or JSON: the obstacles as boxes in the robot's base frame, docs/robots.md). It tells "
    "the robot the scene (the paths source goes round them); the trial records it, to be reported apart."
)


def _scene(path: Path | None):
    """The scene of --scene, read and validated before anything moves (None: none given)."""
    if path is None:
        return None
    from coassist.scenario.scene import SceneError, read_scene

    try:
        return read_scene(path)
    except SceneError as exc:
        _fail(f"--scene {exc}", 2)


def _say(line: str) -> None:
    """A run's one-line statement (what the person will get), as plain text."""
    console.print(line, markup=False, highlight=False, soft_wrap=True)


@app.command(cls=_live_command(FOXGLOVE_PORT))
def collect(
    out: Path = typer.Option(..., help="Dataset folder to write (trial Parquet files + manifest.json)."),
    controller: str = typer.Option(
        "cooperative",
        help="cooperative | cooperative-arbitrated | cooperative-damped | impedance | manual | manual-probe (calibration trials: MG plus the probe, for coassist calibrate).",
    ),
    users: str = typer.Option("0", help="Simulated operators, comma-separated (0 = the thesis' author)."),
    tasks: str = typer.Option("linear,curved,sinusoidal", help="Nominal paths: linear, curved, sinusoidal, z."),
    objects: str = typer.Option("handle", help="Objects: handle, board, heavy."),
    trials: int = typer.Option(20, help="Trials per user, object and task."),
    seed: int = typer.Option(0, help="Seed of the first trial; trial i uses seed + i."),
    preset: str = typer.Option(
        COLLECTION_PRESET,
        help=f"Control preset: {COLLECTION_PRESET} (the main job's for collection), {APPLICATION_PRESET} (the main job's with a learned model in the loop), thesis-application-dm, or one without -dm (SI units: the robot barely helps).",
    ),
    intent: str = typer.Option(
        DEFAULT_INTENT,
        help=f"Intent source: {intent_choices()}. {INTENT_DEFAULT_HELP} The thesis' dataset D0 (Algorithm 4.1) is --intent nominal.",
    ),
    obstacle: str = typer.Option(
        "small",
        help="The obstacle the operators go around: small (the evaluation's box) or large (the application's 12 cm box, no path shown).",
    ),
    population: str = typer.Option(
        "thesis",
        help="Who the simulated operators are: thesis (the main job's: user 0 the thesis' author), varied (detour families to tune on), held-out (other kinds of detour, to report only); docs/realism.md.",
    ),
    population_seed: int = typer.Option(0, help="Seed of the population the users are drawn from."),
    dataset_id: str = typer.Option(None, help="Dataset id (default: the folder's name)."),
    workers: int = typer.Option(None, help="Local worker processes (default: one per CPU)."),
    ray_address: str = typer.Option(None, help="Run on a Ray cluster at this address (needs coassist[cluster])."),
    overwrite: bool = typer.Option(
        False, help="Replace an existing dataset folder (only once the new one is complete)."
    ),
    lockstep: bool = typer.Option(
        True,
        "--lockstep/--per-trial",
        help="Advance each worker's trials together: one controller call and, with a model in the loop, one network call per tick for all (~6x faster with a model, ~2x without; with a model equal to the per-trial run to the network's float32 rounding, without it bit for bit). --per-trial: every trial alone, bit for bit the same whatever else runs (e.g. across a resumed collection).",
    ),
    network: str = typer.Option(
        "auto",
        help="What evaluates a model's network: onnx (ONNX Runtime, 1.6-1.9x faster at the loop's batch sizes; the onnx extra), torch, or auto (onnx where installed). The two agree to float32 rounding; each trial records which ran.",
    ),
    foxglove: int = typer.Option(
        None,
        metavar="[PORT]",
        help=_LIVE_HELP.format(port=FOXGLOVE_PORT)
        + " Shows the first trial still to run, which then runs first, in this process.",
    ),
) -> None:
    """Simulate trials and write them as a dataset (thesis §5.2.2: 60 trials; D0 with --intent nominal).

    Each trial is written as it finishes; if the run is stopped, the same command
    continues where it stopped.
    """
    from coassist._io import OutputBusyError
    from coassist.config import CONTROL_PRESETS
    from coassist.control.presets import CONTROLLER_KINDS
    from coassist.scenario import OBJECTS, OBSTACLES, POPULATIONS, TASK_KINDS
    from coassist.sim.collect import collect_dataset

    _choose(controller, CONTROLLER_KINDS, "--controller", "controller")
    _choose(population, POPULATIONS, "--population", "population")
    _choose(obstacle, OBSTACLES, "--obstacle", "obstacle")
    _choose(network, NETWORK_BACKENDS, "--network", "network backend")
    _lookup(CONTROL_PRESETS, preset, "--preset")
    for value, option, minimum in (
        (trials, "--trials", 1),
        (seed, "--seed", 0),
        (workers, "--workers", 1),
        (population_seed, "--population-seed", 0),
    ):
        if value is not None and value < minimum:
            _fail(f"{option} must be >= {minimum}, got {value}", 2)
    user_list = _int_list(users, "--users")
    task_list = _name_list(tasks, "--tasks", TASK_KINDS, "task")
    object_list = _name_list(objects, "--objects", tuple(OBJECTS), "object")
    try:
        check_intent(intent)
    except ValueError as exc:
        _fail(f"--intent {exc}", 2)
    _folder_out(out, "--out")
    live = _open_live(foxglove)
    try:
        folder = collect_dataset(
            out,
            dataset_id=dataset_id,
            workers=workers,
            progress=True,
            ray_address=ray_address,
            overwrite=overwrite,
            controller=controller,
            users=user_list,
            tasks=task_list,
            objects=object_list,
            trials=trials,
            seed=seed,
            preset=preset,
            obstacle=obstacle,
            lockstep=lockstep,
            network=network,
            intent=intent,
            population=population,
            population_seed=population_seed,
            say=lambda line: console.print(line, highlight=False),
            live=live,
        )
    except (ValueError, FileExistsError, NotADirectoryError, RuntimeError, OutputBusyError) as exc:
        _fail(f"{exc}")
    except OSError as exc:
        _fail(f"cannot write {exc.filename or out}: {exc.strerror}")
    finally:
        _close_live(live)
    _wrote(str(folder))
    _print_forces(Path(folder))


#: drive's options as typed, for the DriveConfig / SafetyLimits fields they set.
DRIVE_OPTIONS = {
    **{
        f"DriveConfig.{name}": f"--{name.replace('_', '-')}"
        for name in (
            "world",
            "controller",
            "task",
            "preset",
            "intent",
            "user",
            "seed",
            "obstacle",
            "full_pose",
            "time_limit",
            "predictor_backend",
            "robot",
            "population",
            "person",
            "scene",
        )
    },
    "DriveConfig.object": "--object",
    "DriveConfig.rate_hz": "--rate",
    "SafetyLimits.tool_speed": "--tool-speed",
    "SafetyLimits.contact_force": "--contact-force",
}


@app.command(cls=_live_command(FOXGLOVE_PORT))
def drive(
    out: Path = typer.Option(
        Path("runs/drive/trial.parquet"),
        help="Trial file to write (the same format as collect's trials, plus joint columns).",
    ),
    world: str = typer.Option("mujoco", help=f"{world_choices()}."),
    robot: str = typer.Option(None, help=f"The arm: {arm_choices()}; default the world's first."),
    controller: str = typer.Option("cooperative", help=ARM_CONTROLLER_HELP),
    task: str = typer.Option("linear", help="Nominal path: linear, curved, sinusoidal, z."),
    obj: str = typer.Option("handle", "--object", help="Carried object: handle, board, heavy."),
    intent: str = typer.Option(
        DEFAULT_INTENT,
        help=f"Intent source: {intent_choices()} ("
        + ", ".join(n for n, e in INTENT_SOURCES.items() if e.simulation_only)
        + f" in a simulated world only). {INTENT_DEFAULT_HELP}",
    ),
    person: str = typer.Option(None, help=PERSON_HELP),
    scene: Path = typer.Option(None, help=SCENE_HELP),
    realtime_intent: bool = typer.Option(
        None,
        help="Run the model off the control thread, never waiting for it (default: on for a real arm, off in a simulated world, where runs are then deterministic).",
    ),
    predictor_backend: str = typer.Option(
        "process",
        help="Where a real-time model runs: process (own worker process), onnx (ONNX Runtime thread) or torch (thread).",
    ),
    preset: str = typer.Option(
        APPLICATION_PRESET,
        help=f"Control preset (default: the main job's application preset, {APPLICATION_PRESET}, safe with a learned model in the loop; the -dm presets ring with one).",
    ),
    user: int = typer.Option(0, help="Simulated operator (MuJoCo world)."),
    population: str = typer.Option(
        "thesis", help="The simulated operator's population: thesis, varied or held-out (docs/realism.md)."
    ),
    seed: int = typer.Option(0, help="Seed of the task, the simulated operator and the sensor noise."),
    obstacle: str = typer.Option(
        "small", help="The obstacle the simulated operator goes around: small or large (the application's)."
    ),
    rate: int = typer.Option(125, help="Control rate in Hz: 125 (UR CB3) or 500 (e-Series)."),
    full_pose: bool = typer.Option(False, help="Control all 6 DOFs instead of the x-y plane."),
    time_limit: float = typer.Option(None, help="Longest run in seconds (default: 2 x the plan + 10 s)."),
    tool_speed: float = typer.Option(0.25, help="Safety: largest tool speed in m/s."),
    contact_force: float = typer.Option(120.0, help="Safety: hand force in N that makes a protective stop."),
    host: str = typer.Option(
        None,
        help="The real arm's address: "
        + ", ".join(f"{e.host} (--world {n})" for n, e in WORLDS.items() if e.host)
        + ".",
    ),
    yes: bool = typer.Option(False, "--yes", help="Do not ask for confirmation before a real arm moves (scripts)."),
    view: bool = typer.Option(False, help="Open MuJoCo's passive viewer (needs a display) and run in real time."),
    plot: bool = typer.Option(True, help="Also write the monitor figure (<out>.png)."),
    mcap: bool = typer.Option(
        False,
        help="Also write the run as <out>.mcap: ROS 2 messages (poses, wrench, prediction, alpha, faults) that Foxglove opens and train reads.",
    ),
    overwrite: bool = typer.Option(False, help="Replace an existing trial file at --out."),
    foxglove: int = typer.Option(None, metavar="[PORT]", help=_LIVE_HELP.format(port=FOXGLOVE_PORT)),
) -> None:
    """Run the assistive controller, IMP or MG on an arm (UR5, Panda): in MuJoCo, or on a real one."""
    from coassist.config import CONTROL_PRESETS
    from coassist.control.presets import CONTROLLER_KINDS
    from coassist.robot.drive import DriveConfig
    from coassist.robot.drive import drive as run_drive
    from coassist.runtime.safety import SafetyLimits

    _choose(world, WORLDS, "--world", "world")
    _choose(controller, CONTROLLER_KINDS, "--controller", "controller")
    _lookup(CONTROL_PRESETS, preset, "--preset")
    try:
        limits = SafetyLimits(tool_speed=tool_speed, contact_force=contact_force)
        config = DriveConfig(
            world=world,
            controller=controller,
            task=task,
            object=obj,
            preset=preset,
            intent=intent,
            user=user,
            seed=seed,
            obstacle=obstacle,
            rate_hz=rate,
            full_pose=full_pose,
            time_limit=time_limit,
            limits=limits,
            realtime_intent=realtime_intent,
            predictor_backend=predictor_backend,
            robot=robot,
            population=population,
            person=person,
            scene=_scene(scene),
        )
    except ValueError as exc:
        _fail(_typed(str(exc), DRIVE_OPTIONS), 2)
    out = _run_out(out, overwrite, mcap)
    if intent not in INTENT_SOURCES:
        _set_torch_threads(1)  # one core for a model run in this process (the tick's own thread stays free)

    confirm = _confirm_move(yes, "the teach pendant's emergency stop")
    live = _open_live(foxglove)
    try:
        trial = run_drive(
            config, host=host, view=view, confirm=None if WORLDS[world].simulated else confirm, live=live, say=_say
        )
    except (ValueError, RuntimeError, ImportError, ConnectionError, OSError) as exc:
        _fail(str(exc))
    finally:
        _close_live(live)
    from coassist.robot.ros2_world import UR_JOINT_NAMES  # (no rclpy needed for the names)

    # The UR's joint names; another arm's joints are named joint_1 … joint_n in the MCAP.
    names = UR_JOINT_NAMES if config.robot == "ur5" else None
    _write_run(
        trial, out, alpha=_run_alpha(preset, controller) if mcap else None, mcap=mcap, plot=plot, joint_names=names
    )


def _run_out(out: Path, overwrite: bool, mcap: bool) -> Path:
    """The trial file of a drive/ros2 run: a recorded run (its trial, or the MCAP beside it) is not
    replaced without --overwrite, checked before the robot moves."""
    out = _file_out(out, "--out", "trial.parquet")
    if out.suffix == ".mcap":
        _fail(f"--out {out}: give the trial file (e.g. trial.parquet); --mcap writes the .mcap beside it", 2)
    if not overwrite:
        for path in (out, out.with_suffix(".mcap")):
            if path.exists() or path.is_symlink():  # a recorded run is not replaced silently
                _fail(f"--out {out}: {path} exists; pass --overwrite to replace the run", 2)
    if mcap:
        _need_bags("--mcap")
    return out


def _run_alpha(preset: str, controller: str) -> float | None:
    """The game's α of a drive/ros2 run (the assistive controller's preset), None for IMP and MG."""
    from coassist.config import CONTROL_PRESETS

    return CONTROL_PRESETS.lookup(preset).game.alpha if controller == "cooperative" else None


def _confirm_move(yes: bool, stop_hint: str):
    """The question drive and ros2 ask before an arm moves: the limits in force, then "Move the robot?".

    Only a person at a terminal answers it: with stdin closed or not a terminal (a script, a
    service) and no ``--yes`` the arm does not move, and the reason is one line (a RuntimeError
    the command prints as its error), not a prompt cut off by an empty error.
    """

    def confirm(text: str) -> bool:
        console.print(
            "[bold]Limits in force[/] (coassist's safety layer, on top of the robot's own safety system):", markup=True
        )
        console.print(text, markup=False)
        console.print(f"Keep {stop_hint} within reach.", markup=False)
        if yes:
            return True
        if not _stdin_is_terminal():
            raise RuntimeError(
                "the robot was not moved: 'Move the robot?' needs an answer from the person at it, and stdin is not "
                "a terminal (closed or redirected); run the command at a terminal, or pass --yes to move it without asking"
            )
        try:
            return typer.confirm("Move the robot?", default=False)
        except click.exceptions.Abort:  # Ctrl+D or Ctrl+C at the prompt
            console.print("", markup=False)
            raise RuntimeError("the robot was not moved: no answer to 'Move the robot?'") from None

    return confirm


def _stdin_is_terminal() -> bool:
    try:
        return sys.stdin is not None and not sys.stdin.closed and sys.stdin.isatty()
    except (ValueError, OSError):
        return False


def _write_run(
    trial, out: Path, *, alpha: float | None, mcap: bool, plot: bool, joint_names: Sequence[str] | None
) -> None:
    """Write a drive/ros2 run: the trial file, how it ended, and <out>.mcap / <out>.png on request.
    ``joint_names``: the arm's, in the trial's joint order (None: joint_1 … joint_n in the MCAP)."""
    from coassist.data.run_pair import write_run_pair

    # the trial and its MCAP as one pair: no crash leaves a trial beside another run's MCAP
    path, mcap_path = write_run_pair(trial, out, mcap=mcap, alpha=alpha, joint_names=joint_names)
    extra = trial.meta.extra
    _wrote(f"{path}: {trial.n_samples} ticks, ended: {extra['ended']}")
    if extra.get("stop_message"):
        console.print(f"[yellow]{escape(extra['stop_message'])}[/]", highlight=False)
    if extra.get("log_note"):
        console.print(f"[yellow]{escape(extra['log_note'])}[/]", highlight=False)
    if mcap_path is not None:
        _wrote(str(mcap_path))
    if plot:
        from coassist.sim.monitor import plot_trial

        _wrote(str(plot_trial(trial, path.with_suffix(".png"))))


ROS2_OPTIONS = {
    **DRIVE_OPTIONS,
    **{
        f"Ros2Config.{name}": f"--{name.replace('_', '-')}"
        for name in (
            "wrench_topic",
            "joint_state_topic",
            "command_topic",
            "base_frame",
            "joint_names",
            "domain_id",
            "stale_after",
            "tcp_offset",
            "node_name",
            "namespace",
            "connect_timeout",
            "wrench_frame",
        )
    },
    "Ros2Config.rate_hz": "--rate",
}


def _floats(text: str | None, option: str) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        _fail(f"{option}: expected comma-separated numbers, got {text!r}", 2)


@app.command(cls=_live_command(FOXGLOVE_PORT))
def ros2(
    out: Path = typer.Option(Path("runs/ros2/trial.parquet"), help="Trial file to write (as coassist drive writes)."),
    controller: str = typer.Option("cooperative", help=ARM_CONTROLLER_HELP),
    task: str = typer.Option(
        "linear", help="Nominal path, laid out from where the tool is: linear, curved, sinusoidal, z."
    ),
    obj: str = typer.Option("handle", "--object", help="Carried object: handle, board, heavy."),
    intent: str = typer.Option(
        DEFAULT_INTENT, help=f"Intent source: {intent_choices(simulation=False)}. {INTENT_DEFAULT_HELP}"
    ),
    person: str = typer.Option(None, help=PERSON_HELP),
    scene: Path = typer.Option(None, help=SCENE_HELP),
    predictor_backend: str = typer.Option(
        "process", help="Where a model runs: process (own worker process), onnx or torch (thread)."
    ),
    preset: str = typer.Option(
        APPLICATION_PRESET,
        help=f"Control preset (default: the main job's application preset, {APPLICATION_PRESET}, safe with a learned model in the loop; the -dm presets ring with one).",
    ),
    rate: int = typer.Option(125, help="Control rate in Hz: 125 (UR CB3) or 500 (e-Series)."),
    full_pose: bool = typer.Option(False, help="Control all 6 DOFs instead of the x-y plane."),
    time_limit: float = typer.Option(None, help="Longest run in seconds (default: 2 x the plan + 10 s)."),
    tool_speed: float = typer.Option(0.25, help="Safety: largest tool speed in m/s."),
    contact_force: float = typer.Option(120.0, help="Safety: hand force in N that makes a protective stop."),
    wrench_topic: str = typer.Option(
        "/force_torque_sensor_broadcaster/wrench",
        help="geometry_msgs/WrenchStamped in: the F/T reading (sensor frame).",
    ),
    joint_state_topic: str = typer.Option("/joint_states", help="sensor_msgs/JointState in."),
    command_topic: str = typer.Option(
        "/forward_velocity_controller/commands", help="std_msgs/Float64MultiArray out: joint velocities."
    ),
    joint_names: str = typer.Option(
        None,
        help="Joint order of the commands, comma-separated (default: the UR's, shoulder_pan_joint … wrist_3_joint).",
    ),
    base_frame: str = typer.Option(
        "base", help="frame_id of the published poses (a wrench in it is rotated into the sensor's)."
    ),
    wrench_frame: str = typer.Option(
        "tool0",
        help="frame_id of a wrench in the sensor frame (the flange's axes); a wrench in any other frame but --base-frame stops the run.",
    ),
    wrench_in_base: bool = typer.Option(False, help="Kept for scripts: each wrench message's frame_id says its frame."),
    tcp_offset: str = typer.Option(None, help="TCP in the flange frame: x,y,z,rx,ry,rz [m, rad] (default 0)."),
    node_name: str = typer.Option("coassist", help="The node's name (monitor topics go to /<node>/…)."),
    namespace: str = typer.Option("", help="The node's namespace."),
    domain_id: int = typer.Option(None, help="ROS_DOMAIN_ID (default: the environment's)."),
    stale_after: float = typer.Option(
        0.1, help="A wrench or joint state older than this (s, at most 0.5) stops the arm."
    ),
    connect_timeout: float = typer.Option(5.0, help="Wait this long (s) for the first messages."),
    lockstep: bool = typer.Option(
        False, help="A simulated robot that steps once per command: wait for its answer every tick."
    ),
    yes: bool = typer.Option(False, "--yes", help="Do not ask for confirmation before the robot moves (scripts)."),
    mcap: bool = typer.Option(False, help="Also write the run as <out>.mcap (ROS 2 messages Foxglove opens)."),
    plot: bool = typer.Option(True, help="Also write the monitor figure (<out>.png)."),
    overwrite: bool = typer.Option(False, help="Replace an existing run at --out (its trial and its .mcap)."),
    foxglove: int = typer.Option(None, metavar="[PORT]", help=_LIVE_HELP.format(port=FOXGLOVE_PORT)),
) -> None:
    """Run the assistive controller, IMP or MG as a ROS 2 node: ros2_control's forward velocity controller."""
    try:
        import rclpy  # noqa: F401  (the ros2 extra, checked before anything starts)
    except ImportError as exc:
        _fail(f"coassist ros2 needs the ros2 extra ({exc.name} missing): pip install 'coassist[ros2]'", 2)
    from coassist.robot.drive import DriveConfig
    from coassist.robot.drive import drive as run_drive
    from coassist.robot.ros2_world import UR_JOINT_NAMES, Ros2Config, Ros2World
    from coassist.runtime.safety import SafetyLimits

    try:
        limits = SafetyLimits(tool_speed=tool_speed, contact_force=contact_force)
        config = DriveConfig(
            world="ros2",
            controller=controller,
            task=task,
            object=obj,
            preset=preset,
            intent=intent,
            rate_hz=rate,
            full_pose=full_pose,
            time_limit=time_limit,
            limits=limits,
            predictor_backend=predictor_backend,
            person=person,
            scene=_scene(scene),
        )
        rcfg = Ros2Config(
            node_name=node_name,
            namespace=namespace,
            wrench_topic=wrench_topic,
            joint_state_topic=joint_state_topic,
            command_topic=command_topic,
            base_frame=base_frame,
            wrench_frame=wrench_frame,
            joint_names=UR_JOINT_NAMES if joint_names is None else tuple(n.strip() for n in joint_names.split(",")),
            wrench_in_base=wrench_in_base,
            rate_hz=float(rate),
            stale_after=stale_after,
            connect_timeout=connect_timeout,
            lockstep=lockstep,
            pace=not lockstep,
            domain_id=domain_id,
            tcp_offset=_floats(tcp_offset, "--tcp-offset") or (0.0,) * 6,
        )
    except ValueError as exc:
        _fail(_typed(str(exc), ROS2_OPTIONS), 2)
    out = _run_out(out, overwrite, mcap)

    confirm = _confirm_move(yes, "the emergency stop")
    alpha = _run_alpha(preset, controller)
    live = _open_live(foxglove)
    try:
        world = Ros2World(rcfg, alpha=alpha)
        try:
            trial = run_drive(
                config,
                world=world,
                confirm=confirm,
                on_tick=world.publish_monitor,
                live=live,
                joint_names=rcfg.joint_names,
                say=_say,
            )
        finally:
            world.close()
    except (ValueError, RuntimeError, ImportError, ConnectionError, OSError) as exc:
        _fail(str(exc))
    finally:
        _close_live(live)
    _write_run(trial, out, alpha=alpha, mcap=mcap, plot=plot, joint_names=rcfg.joint_names)


@app.command("ros2-watchdog")
def ros2_watchdog(
    input_topic: str = typer.Option(
        "/coassist/joint_velocity_command",
        "--input",
        help="Where coassist ros2 sends its commands (its --command-topic).",
    ),
    output_topic: str = typer.Option(
        "/forward_velocity_controller/commands", "--output", help="The forward velocity controller's command topic."
    ),
    joints: int = typer.Option(6, help="Joints per command."),
    timeout: float = typer.Option(0.05, help="Seconds without a command after which zeros are sent (at most 0.5)."),
    period: float = typer.Option(0.008, help="How often (s) the silence is checked and zeros repeated."),
    domain_id: int = typer.Option(None, help="ROS_DOMAIN_ID (default: the environment's)."),
) -> None:
    """Relay commands to ros2_control's forward velocity controller; send zeros when they stop (run it beside the controller)."""
    try:
        import rclpy  # noqa: F401  (the ros2 extra, checked before anything starts)
    except ImportError as exc:
        _fail(f"coassist ros2-watchdog needs the ros2 extra ({exc.name} missing): pip install 'coassist[ros2]'", 2)
    import time

    from coassist.robot.ros2_watchdog import CommandWatchdog, WatchdogConfig

    options = {
        "WatchdogConfig.input_topic": "--input",
        "WatchdogConfig.output_topic": "--output",
        "WatchdogConfig.n_joints": "--joints",
        "WatchdogConfig.timeout": "--timeout",
        "WatchdogConfig.period": "--period",
        "WatchdogConfig.domain_id": "--domain-id",
    }
    try:
        config = WatchdogConfig(
            input_topic=input_topic,
            output_topic=output_topic,
            n_joints=joints,
            timeout=timeout,
            period=period,
            domain_id=domain_id,
        )
    except ValueError as exc:
        _fail(_typed(str(exc), options), 2)
    console.print(
        f"relaying {input_topic} -> {output_topic}; zeros after {timeout:g} s without a command (Ctrl-C ends it)",
        markup=False,
    )
    with CommandWatchdog(config) as dog:
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        console.print(
            f"forwarded {dog.forwarded} commands, {dog.timeouts} silences, {dog.malformed} malformed", markup=False
        )


@app.command("ur-sim")
def ur_sim(
    host: str = typer.Option("127.0.0.1", help="Address to listen on (another 127.x.y.z for a second simulator)."),
    series: str = typer.Option("e-series", help="e-series (500 Hz, PolyScope 5) or cb3 (125 Hz, PolyScope 3)."),
    software: str = typer.Option(
        None, help="The software version it reports, e.g. 5.11.1.108318 (default: the series')."
    ),
    obj: str = typer.Option("handle", "--object", help="Carried object: handle, board, heavy."),
    start: str = typer.Option(None, help="x,y,z [m] of the TCP at the start, tool down (default: the tasks' start)."),
    seed: int = typer.Option(0, help="Seed of the sensor noise and of the jitter fault."),
    unlock_delay: float = typer.Option(5.0, help="Seconds after a protective stop before it can be unlocked."),
    rt_priority: int = typer.Option(
        None, help="SCHED_FIFO priority 1-99 for its threads (needs root or CAP_SYS_NICE)."
    ),
) -> None:
    """A UR controller (dashboard, script and RTDE ports) with the MuJoCo UR5 behind it: drive it with --world ur.

    Reads faults on stdin, one a line: protective-stop, emergency-stop, release-emergency-stop,
    pendant-stop, stall, unstall, delay LATE [JITTER], remote on|off, drop [REFUSE_FOR],
    push FX FY FZ, release, status, quit (docs/robots.md).
    """
    from coassist.robot.ur_sim import URSimConfig
    from coassist.robot.ur_sim.process import serve

    names = ("host", "series", "seed", "start", "unlock_delay")
    options = {f"URSimConfig.{n}": f"--{n.replace('_', '-')}" for n in names}
    options.update(
        {
            "URSimConfig.version": "--software",
            "URSimConfig.tool": "--object",
            "URSimConfig.rt_priority": "--rt-priority",
        }
    )
    fields: dict = {"host": host, "series": series, "tool": obj, "seed": seed, "unlock_delay": unlock_delay}
    fields["rt_priority"] = rt_priority
    if software is not None:
        try:
            fields["version"] = tuple(int(v) for v in software.split("."))
        except ValueError:
            _fail(f"--software {software!r}: give four numbers, e.g. 5.11.1.108318", 2)
    if start is not None:
        fields["start"] = _floats(start, "--start")
    try:
        config = URSimConfig(**fields)
        serve(config)
    except (ValueError, OSError) as exc:
        _fail(_typed(str(exc), options), 2 if isinstance(exc, ValueError) else 1)


@app.command()
def calibrate(
    data: list[Path] = typer.Argument(
        ...,
        help="Recorded trials: datasets (collect, play), trial files (drive, ros2), recording folders or bags.",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Person-model folder to write (person-model.json)."),
    task: str = typer.Option(
        None, help="Fit only the trials of this task (default: every person's trials must be of one task)."
    ),
    min_trials: int = typer.Option(3, help="The fewest trials a person is calibrated from."),
    overwrite: bool = typer.Option(False, help="Replace the person model already in --out."),
    skip_bad_trials: bool = typer.Option(False, help=SKIP_BAD_HELP),
    bag_topics: str = typer.Option(None, help=BAG_TOPICS_HELP),
) -> None:
    """Fit a person model per person from their calibration trials (record them with --controller manual-probe).

    Prints one line per person: the arm (measured by the probe, or assumed), the
    demonstrations per way round, the fit's time. Drive, ros2 and play take the folder as
    --intent FOLDER.
    """
    from coassist.scenario.person_model import PERSON_MODEL_FILE

    if min_trials < 1:
        _fail(f"--min-trials must be >= 1, got {min_trials}", 2)
    if out.exists() and not out.is_dir():
        _fail(f"--out {out}: is a file; give a folder for the person model", 2)
    if (out / PERSON_MODEL_FILE).exists() and not overwrite:
        _fail(f"--out {out}: already holds a person model; pass --overwrite to replace it", 2)
    _folder_out(out, "--out")
    from coassist.experiments.person_calibration import CalibrationError, calibrate_people, summary_line
    from coassist.scenario.person_model import write_person_model

    trials = _intent_trials(data, skip_bad_trials, bag_topics=bag_topics)
    try:
        people = calibrate_people(trials, task=task, min_trials=min_trials)
    except CalibrationError as exc:
        _fail(str(exc), 2)
    for c in people:
        console.print(summary_line(c), markup=False, highlight=False, soft_wrap=True)
    try:
        write_person_model(out, {c.person: c.fit for c in people})
    except OSError as exc:
        _fail(f"--out {out}: cannot write ({exc.strerror})")
    _wrote(f"{out / PERSON_MODEL_FILE}: {len(people)} person(s); drive with --intent {out}")


@app.command()
def show(
    path: Path = typer.Argument(
        ...,
        help="What train and evaluate read: a dataset folder, a folder of trial_* recordings, one recording folder or one trial file.",
    ),
    out: Path = typer.Option(
        None, help="PNG to write, or a folder for it (default: <name>.png in the current folder)."
    ),
    index: int = typer.Option(0, help="Which trial of a dataset or folder of recordings (0 = the first)."),
    skip_bad_trials: bool = typer.Option(False, help=SKIP_BAD_HELP + " --index then counts the readable ones."),
    bag_topics: str = typer.Option(None, help=BAG_TOPICS_HELP),
) -> None:
    """The monitor view of a trial (thesis Fig. 5.7–5.8) and its force over time."""
    from coassist.sim.monitor import plot_trial

    name = f"{path.resolve().name}{'' if index == 0 else f'_{index}'}.png"
    out = _file_out(Path(name) if out is None else out, "--out", name)
    trials = _intent_trials([path], skip_bad_trials, option="PATH", bag_topics=bag_topics)
    if not 0 <= index < len(trials):
        _fail(f"--index {index}: {path} holds {len(trials)} trial(s), so it must be in 0 … {len(trials) - 1}", 2)
    try:
        written = plot_trial(trials[index].trial, out)
    except OSError as exc:
        _fail(f"--out {out}: cannot write ({exc.strerror})")
    _wrote(str(written))


def _simulation_only(intent: str) -> bool:
    """Whether ``intent`` names a source only a simulation can run (the oracle)."""
    return intent in INTENT_SOURCES and INTENT_SOURCES[intent].simulation_only


@app.command(cls=_live_command(FOXGLOVE_PAGE_PORT))
def play(
    user: str = typer.Option(
        "me", help="Your id (letters, digits, - and _): it names your session folder <out>/<user>."
    ),
    out: Path = typer.Option(
        Path("runs/play"), help="Parent folder of the session folders (each a dataset coassist train reads)."
    ),
    controller: str = typer.Option(
        "manual,impedance,cooperative",
        help="Controllers the page offers, comma-separated: manual (MG), impedance (IMP), cooperative (assistive), cooperative-arbitrated, cooperative-damped, manual-probe (calibration trials: MG plus the probe, no assistance).",
    ),
    intent: str = typer.Option(
        DEFAULT_INTENT,
        help=f"Intent source (its prediction is drawn live): {intent_choices(simulation=False)}. {INTENT_DEFAULT_HELP}",
    ),
    preset: str = typer.Option(
        APPLICATION_PRESET,
        help=f"Control preset (default: the main job's application preset, {APPLICATION_PRESET}, safe with a learned model in the loop; also thesis-evaluation[-dm], thesis-application[-dm]).",
    ),
    tasks: str = typer.Option("linear,curved,sinusoidal,z", help="The protocol's paths, in order (repeated)."),
    seed: int = typer.Option(0, help="Trial i's obstacle is drawn from seed + i."),
    motion_time: float = typer.Option(
        None, help="Planned motion time of every path in seconds (default: the thesis' per path)."
    ),
    host: str = typer.Option("127.0.0.1", help="Address to listen on; anything but this machine needs --token."),
    port: int = typer.Option(8765, help="Port to listen on (0: any free port)."),
    token: str = typer.Option(None, help="Token the page must present (made for you on a non-local --host)."),
    open_browser: bool = typer.Option(True, "--open/--no-open", help="Open the page in your web browser."),
    drive: str = typer.Option(
        None,
        help=f"Watch a coassist drive run instead (read-only): {' | '.join(WORLDS)}; uses the first --controller and --tasks.",
    ),
    robot_host: str = typer.Option(
        None,
        help="The real arm's address: "
        + ", ".join(f"{e.host} (--drive {n})" for n, e in WORLDS.items() if e.host)
        + ".",
    ),
    mcap: bool = typer.Option(
        False, help="Also write each trial as <trial>.mcap beside its Parquet file (ROS 2 messages Foxglove opens)."
    ),
    scene: Path = typer.Option(None, help=f"With --drive: {SCENE_HELP}"),
    foxglove: int = typer.Option(None, metavar="[PORT]", help=_LIVE_HELP.format(port=FOXGLOVE_PAGE_PORT)),
) -> None:
    """Be the operator: a live page where your mouse, touch screen or gamepad is the hand on the robot."""
    try:
        import starlette  # noqa: F401  (the web extra, checked before anything starts)
        import uvicorn  # noqa: F401

        from coassist.play.server import PlayServer, check_token, is_loopback, new_token
        from coassist.play.session import PlayConfig, PlaySession
    except ImportError as exc:
        _fail(f"coassist play needs the web extra ({exc.name} missing): pip install 'coassist[web]'")
    if not 0 <= port <= 65535:
        raise typer.BadParameter(f"must be 0..65535, got {port}", param_hint="--port")
    if mcap:
        _need_bags("--mcap")
    if scene is not None and drive is None:
        _fail("--scene: the page's own world tells the robot its obstacle; a scene file is for --drive (an arm)", 2)
    told = _scene(scene)
    if token is None and not is_loopback(host):
        token = new_token()
    try:
        check_token(token, host)
    except ValueError as exc:
        _fail(f"{exc}", 2)
    live = _open_live(foxglove, page_port=port)  # stopped with the process when a line below fails
    try:
        from coassist.config import CONTROL_PRESETS
        from coassist.control.presets import CONTROLLER_KINDS
        from coassist.scenario import TASK_KINDS

        _lookup(CONTROL_PRESETS, preset, "--preset")
        config = PlayConfig(
            user=user,
            out=out,
            controllers=tuple(_name_list(controller, "--controller", tuple(CONTROLLER_KINDS), "controller")),
            intent="nominal" if drive and _simulation_only(intent) else intent,
            preset=preset,
            tasks=tuple(_name_list(tasks, "--tasks", TASK_KINDS, "task")),
            seed=seed,
            motion_time=motion_time,
            mcap=mcap,
        )
        if drive is None:
            session = PlaySession(config, live=live)
            _say(_page_assistance(session))
        else:
            from coassist.play.monitor import DriveMonitor
            from coassist.robot.drive import DriveConfig

            def confirm(text: str) -> bool:
                console.print(text, markup=False)
                return typer.confirm("Keep the emergency stop within reach. Move the robot?", default=False)

            session = DriveMonitor(
                DriveConfig(
                    world=drive,
                    controller=config.controllers[0],
                    task=config.tasks[0],
                    intent=intent,
                    preset=preset,
                    seed=seed,
                    # at a real arm the page's user is the person at the handle (in MuJoCo, the simulated one)
                    person=None if drive not in WORLDS or WORLDS[drive].simulated else user,
                    scene=told,
                ),
                config,
                host=robot_host,
                confirm=confirm,
                say=_say,
                live=live,
            )
        server = PlayServer(session, host=host, port=port, token=token)
    except (ValueError, OSError) as exc:
        _fail(f"{exc}")
    console.print(
        f"coassist play: open [bold]{server.url}[/] (Ctrl+C to stop); trials go to {config.folder}", highlight=False
    )
    if open_browser:
        import webbrowser

        webbrowser.open(server.url)
    if drive is not None:
        session.start()
    server.run()
    _close_live(live)


def _page_assistance(session) -> str:
    """The one-line statement of a play page: what its assisting controller (the first offered) will give."""
    from coassist.scenario.assistance import assistance_line

    cfg = session.config
    kinds = cfg.controllers
    controller = next((c for c in kinds if c.startswith("cooperative")), kinds[0])
    task = session.next_task()
    line = assistance_line(
        controller,
        cfg.intent,
        session.source,
        user=cfg.user,
        path=task.path.points,
        obstacles=(task.obstacle.to_dict(),),
    )
    others = [c for c in kinds if c != controller]
    return line + (f" (the page also offers {', '.join(others)})" if others else "")


@app.command()
def realism(
    out: Path = typer.Option(Path("docs/realism.md"), help="Markdown report to write."),
    real: Path = typer.Option(
        None, help="Folder of real trial_* recordings (default: $COASSIST_REAL_DATA/user-a; see README)."
    ),
    trials: int = typer.Option(10, help="Simulated trials per task and preset."),
    seed: int = typer.Option(0, help="Seed of the first simulated trial."),
    workers: int = typer.Option(None, help="Local worker processes (default: one per CPU)."),
    population: list[str] = typer.Option(
        [],
        "--population",
        help="Also a population's users against user-a (repeatable): thesis, varied or held-out.",
    ),
    population_users: str = typer.Option("0,1,2,3,4,5", help="The users of each --population."),
    population_trials: int = typer.Option(3, help="Trials per --population user and task."),
) -> None:
    """Simulated trials (user 0, handle, cooperative, nominal intent) side by side with real user-a trials."""
    from coassist.data import default_real_data
    from coassist.experiments import realism as realism_exp
    from coassist.scenario import POPULATIONS

    for value, option, minimum in (
        (trials, "--trials", 1),
        (seed, "--seed", 0),
        (workers, "--workers", 1),
        (population_trials, "--population-trials", 1),
    ):
        if value is not None and value < minimum:
            _fail(f"{option} must be >= {minimum}, got {value}", 2)
    for name in population:
        _choose(name, POPULATIONS, "--population", "population")
    users = _int_list(population_users, "--population-users")
    real = real or default_real_data() / "user-a"
    if not real.is_dir():
        _fail(f"--real {real}: no such folder (set COASSIST_REAL_DATA to the folder holding user-a/)", 2)
    out = _file_out(out, "--out", "realism.md")
    try:
        result = realism_exp.run_realism(
            real,
            trials_per_task=trials,
            seed=seed,
            workers=workers,
            progress=True,
            populations=population,
            population_users=users,
            population_trials=population_trials,
        )
    except ValueError as exc:
        _fail(str(exc))
    console.print(realism_exp.summary_table(result))
    if result.populations:
        console.print(realism_exp.population_table(result))
        console.print(realism_exp.family_table(result))
    _wrote(str(realism_exp.write_report(result, out, realism_exp.NOTES)))


@app.command("compare-intents")
def compare_intents(
    source: list[str] = typer.Option(
        ...,
        help="LABEL=INTENT, repeatable: a named source (present, paths, …), a model "
        "folder or a calibration folder; paths alone is calibrated on each base's trials, person alone is "
        "each operator's person model fitted to their probe trials of each base.",
    ),
    out: Path = typer.Option(Path("runs/compare-intents"), help="Folder for the datasets, table.md and summary.json."),
    bases: str = typer.Option(
        "50000,60000", help="Validation seed bases (application_seed(base, j); never the report's 0)."
    ),
    damped: str = typer.Option(
        "", help="Labels to run with the cooperative-damped controller instead of the arbitrated one."
    ),
    cooperative: str = typer.Option(
        "", help="Labels to run with the plain cooperative controller (α fixed; drive's default) instead."
    ),
    trials: int = typer.Option(4, help="Trials per operator, object and base."),
    workers: int = typer.Option(2, help="Simulation processes."),
) -> None:
    """Intent sources in the loop on validation seeds, paired against MG and the oracle (docs/precision.md)."""
    import json

    from coassist._io import atomic_write_text
    from coassist.experiments.precision import compare_intents as run
    from coassist.experiments.precision import comparison_table
    from coassist.experiments.reproduce import jsonable

    pairs = {}
    for item in source:
        label, sep, spec = item.partition("=")
        if not sep or not label or not spec:
            _fail(f"--source {item!r}: expected LABEL=INTENT", 2)
        if label in pairs:
            _fail(f"--source {label}: given twice", 2)
        pairs[label] = spec
    seeds = _int_list(bases, "--bases")
    chosen: dict[str, str] = {}
    for option, text, kind in (
        ("--damped", damped, "cooperative-damped"),
        ("--cooperative", cooperative, "cooperative"),
    ):
        for label in (d for d in text.split(",") if d):
            if label not in pairs:
                _fail(f"{option} {label}: not a --source label", 2)
            if label in chosen:
                _fail(f"{option} {label}: also given another controller", 2)
            chosen[label] = kind
    for value, option in ((trials, "--trials"), (workers, "--workers")):
        if value < 1:
            _fail(f"{option} must be >= 1, got {value}", 2)
    out = _folder_out(out, "--out")
    try:
        result = run(
            pairs,
            out,
            bases=seeds,
            controllers=chosen,
            trials=trials,
            workers=workers,
        )
    except ValueError as exc:
        _fail(str(exc), 2)
    table = comparison_table(result)
    console.print(table, markup=False, highlight=False)
    atomic_write_text(out / "table.md", table + "\n")
    atomic_write_text(out / "summary.json", json.dumps(jsonable(result.summary()), indent=1, allow_nan=True))
    _wrote(str(out / "table.md"))


@app.command()
def reproduce(
    out: Path = typer.Option(
        Path("runs/reproduce"), help="Output folder: report.html, summary.json, datasets, models."
    ),
    preset: str = typer.Option(
        "default",
        help="default (about 6 min on 2 CPU cores), full (the pre-issue-35 default: more training data), "
        "tiny (smoke run) or thesis (thesis sizes; GPU).",
    ),
    seed: int = typer.Option(0, help="Seed of every dataset and training."),
    seeds: str = typer.Option(
        None,
        help="Run on several seeds instead: a count N (seeds 0 … N-1) or a list like 0,1,2; "
        "one report says on how many seeds each claim holds.",
    ),
    workers: int = typer.Option(None, help="Simulation processes (default: the preset's)."),
    device: str = typer.Option(None, help="Torch device for training, e.g. cpu or cuda (default: the preset's)."),
    real_data: Path = typer.Option(
        None, help="Folder with user-a/ and user-b/ recordings (default: $COASSIST_REAL_DATA; see README)."
    ),
) -> None:
    """The thesis' experiments end to end in simulation (dMPC study, iterative training, transfer, application, real data): one HTML report."""
    from dataclasses import replace

    from coassist.experiments import reproduce as rep
    from coassist.experiments import seeds as multi

    seed_list = None
    if seeds is not None:
        if seed != 0:
            _fail("give --seed or --seeds, not both", 2)
        try:
            seed_list = multi.parse_seeds(seeds)
        except ValueError as exc:
            _fail(str(exc), 2)

    chosen = _lookup(rep.REPRODUCE_PRESETS, preset, "--preset")
    _check_device(device)
    changes = {"seed": seed}
    if workers is not None:
        changes["workers"] = workers
    if device is not None:
        changes["device"] = device
    if real_data is not None:
        if not real_data.is_dir():
            _fail(f"--real-data {real_data}: no such folder", 2)
        if not (real_data / "user-a").is_dir():
            _fail(f"--real-data {real_data}: has no user-a/ folder of recordings", 2)
        changes["real_data"] = str(real_data)
    try:
        config = replace(chosen, **changes)
    except ValueError as exc:
        _fail(
            _typed(
                str(exc), {"reproduce.seed": "--seed", "reproduce.workers": "--workers", "reproduce.device": "--device"}
            ),
            2,
        )
    _folder_out(out, "--out")
    _set_torch_threads(config.threads)  # training runs in this process
    if seed_list is not None:
        across = multi.run_seeds(
            config, seed_list, out, progress=True, say=lambda line: console.print(line, highlight=False)
        )
        console.print(f"claims: {across['robust']} of {across['n_claims']} hold on every seed")
        for c in across["claims"]:
            mark = {"robust": "[green]robust[/]", "seed-dependent": "[yellow]seed-dependent[/]"}.get(
                c["status"], "[red]not holding[/]"
            )
            console.print(f"  {mark} ({c['holds_on']} of {c['checked_on']})  {escape(c['claim'])}", highlight=False)
        _wrote(f"{out / 'report.html'} and {out / 'summary.json'} in {across['total_seconds']:.0f} s")
        return
    summary = rep.run_reproduce(config, out, progress=True, say=lambda line: console.print(line, highlight=False))
    held = sum(1 for c in summary["claims"] if c["holds"])
    console.print(f"claims: {held} of {len(summary['claims'])} hold")
    for c in summary["claims"]:
        mark = "[green]holds[/]" if c["holds"] else "[red]does not hold[/]"
        console.print(f"  {mark}  {escape(c['claim'])}", highlight=False)
    _wrote(f"{out / 'report.html'} and {out / 'summary.json'} in {summary['total_seconds']:.0f} s")


# --------------------------------------------------------------------------- study

study_app = typer.Typer(
    help="Run a study with people (or simulated participants): plan, run, report.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(study_app, name="study")


@study_app.command("init")
def study_init(
    plan: Path = typer.Argument(..., help="The study plan (TOML; docs/study.md)."),
    out: Path = typer.Option(..., "--out", "-o", help="The study folder to make (e.g. studies/<name>)."),
) -> None:
    """Check a study plan whole (every field, model and calibration; the session's time and memory) and make its
    study folder (the plan, its hash, the blinding key, the Latin square)."""
    from coassist.study.plan import PlanError
    from coassist.study.store import StudyFolderError, init_study

    _folder_out(out, "--out")
    try:
        study = init_study(plan, out)
    except PlanError as exc:
        _fail(f"{plan}: {exc}", 2)
    except StudyFolderError as exc:
        _fail(str(exc), 2)
    rec = study.record
    console.print(
        f"study {rec['name']!r}: protocol {rec['protocol']}, world {rec['world']}"
        + (f", conditions shown as {', '.join(sorted(rec['labels'].values()))}" if rec["labels"] else ""),
        highlight=False,
        markup=False,
    )
    estimate = study.estimate()
    for line in estimate.lines() if estimate is not None else ():
        console.print(line, highlight=False, markup=False, soft_wrap=True)
    if "rehearsal" in out.name:
        advice = f"rehearse it: coassist study run {out} --simulate --participant S01"
    else:
        rehearsal = out.with_name(out.name + "-rehearsal")
        advice = (
            "rehearse it before anyone sits down (a simulated participant, in a folder of its own): coassist study "
            f"init {plan} --out {rehearsal} && coassist study run {rehearsal} --simulate --participant S01"
        )
    console.print(advice, highlight=False, markup=False, soft_wrap=True)
    _wrote(str(out))


@study_app.command("amend")
def study_amend(
    folder: Path = typer.Argument(..., help="The study folder."),
    plan: Path = typer.Argument(..., help="The amended plan (TOML): the study's plan with safe fields changed."),
    reason: str = typer.Option(..., "--reason", help="Why (one line, recorded in study.json with the change)."),
) -> None:
    """Amend the plan's safe fields (rests, the stop criterion, planned participants, id pattern, training threads)
    after trials have run; the change and its reason are recorded, the old plan kept in plans/."""
    from coassist.study.plan import PlanError
    from coassist.study.store import StudyFolderError, amend_study

    try:
        amendment = amend_study(folder, plan, reason)
    except PlanError as exc:
        _fail(f"{plan}: {exc}", 2)
    except StudyFolderError as exc:
        _fail(str(exc), 2)
    for name, (old, new) in amendment["fields"].items():
        console.print(f"{name}: {old!r} -> {new!r}", highlight=False, markup=False)
    _wrote(f"{folder} (plan {amendment['to_sha256'][:12]}; the old plan in plans/{amendment['from_sha256']}.toml)")


@study_app.command("run", cls=_live_command(FOXGLOVE_PAGE_PORT))
def study_run(
    folder: Path = typer.Argument(..., help="The study folder (coassist study init)."),
    participant: str = typer.Option(
        None,
        "--participant",
        "-p",
        help="The participant's pseudonymous id (e.g. P07; nothing personal). With --simulate, default: every planned participant, S01, S02, …",
    ),
    simulate: bool = typer.Option(
        False, help="Simulated participants from the operator population stand in for people (a dry run)."
    ),
    page: bool = typer.Option(
        None, "--page/--no-page", help="Serve the page (default: on for a person, off with --simulate)."
    ),
    realtime: bool = typer.Option(False, help="Pace simulated participants to the wall clock, as a person's trials."),
    host: str = typer.Option("127.0.0.1", help="Address the page listens on; anything but this machine needs --token."),
    port: int = typer.Option(8765, help="Port of the page (0: any free port)."),
    token: str = typer.Option(None, help="Token the page must present (made for you on a non-local --host)."),
    robot_host: str = typer.Option(None, help="The real arm's address (world ur or franka)."),
    open_browser: bool = typer.Option(True, "--open/--no-open", help="Open the page in your web browser."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask before a real arm moves (scripts)."),
    foxglove: int = typer.Option(
        None,
        metavar="[PORT]",
        help=_LIVE_HELP.format(port=FOXGLOVE_PAGE_PORT)
        + " For the experimenter: alpha and the prediction tell the conditions apart.",
    ),
) -> None:
    """Run a participant's steps in their recorded order (continuing where they stopped)."""
    from coassist._io import OutputBusyError
    from coassist.study.plan import PlanError
    from coassist.study.runner import ParticipantRun, simulated_ids
    from coassist.study.store import StudyFolder, StudyFolderError

    if not 0 <= port <= 65535:
        _fail(f"--port must be 0..65535, got {port}", 2)
    use_page = (not simulate) if page is None else page
    try:
        study = StudyFolder(folder)
        plan = study.plan()
    except (StudyFolderError, PlanError) as exc:
        _fail(str(exc), 2)
    if participant is None and not simulate:
        _fail("--participant is needed for a person (a pseudonymous id such as P07)", 2)
    ids = [participant] if participant is not None else simulated_ids(plan.participants)
    if use_page:
        try:
            import starlette  # noqa: F401  (the web extra)

            from coassist.play.server import is_loopback, new_token
        except ImportError as exc:
            _fail(f"the page needs the web extra ({exc.name} missing): pip install 'coassist[web]'")
        if token is None and not is_loopback(host):
            token = new_token()
    confirm = _confirm_move(yes, "the emergency stop") if plan.world in ("ur", "franka") else None
    live = _open_live(foxglove, page_port=port if use_page else None)  # stopped with the process on a failure
    for pid in ids:
        try:
            with ParticipantRun(
                study,
                pid,
                simulate=simulate,
                page=(host, port, token) if use_page else None,
                realtime=realtime,
                host=robot_host,
                confirm=confirm,
                say=lambda line: console.print(line, highlight=False, markup=False),
                live=live,
            ) as run:
                if run.complete:
                    console.print(f"{pid}: already complete", highlight=False)
                    continue
                if run.url is not None:
                    console.print(f"{pid}: open {run.url} (Ctrl+C stops; the same command continues)", highlight=False)
                    if open_browser:
                        import webbrowser

                        webbrowser.open(run.url)
                run.run()
        except KeyboardInterrupt:
            _fail(f"{pid}: stopped; what finished is kept, and the same command continues where it stopped", 130)
        except (StudyFolderError, PlanError, OutputBusyError) as exc:
            _fail(f"{pid}: {exc}")
        except Exception as exc:  # whatever failed, the participant is resumable: say so in one line
            what = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            _fail(
                f"{pid}: {what} ({type(exc).__name__}); what finished is kept: fix the cause (coassist study "
                "amend changes the plan's safe fields) and the same command continues where it stopped"
            )
        console.print(f"{pid}: complete", highlight=False)
    _close_live(live)
    _wrote(str(folder))


@study_app.command("report")
def study_report(
    folder: Path = typer.Argument(..., help="The study folder."),
    out: Path = typer.Option(None, help="Folder for report.html and summary.json (default: <folder>/report)."),
) -> None:
    """The study's report: per participant and pooled measures, paired tests, questionnaires, order effects."""
    from coassist.study.plan import PlanError
    from coassist.study.report import write_report
    from coassist.study.store import StudyFolderError

    if out is not None:
        _folder_out(out, "--out")
    try:
        html_path, json_path = write_report(folder, out)
    except (StudyFolderError, PlanError, OSError) as exc:
        _fail(str(exc), 2)
    _wrote(f"{html_path} and {json_path}")


if __name__ == "__main__":  # pragma: no cover
    app()
