"""What the commands share: the console, the checks that run before any work (each ends in one
line naming the option as typed), the readers of list options and trial folders, and the help
texts several commands show."""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import NoReturn, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from coassist._checks import is_ascii_integer
from coassist._io import json_object_with
from coassist.registry import Registry, UnknownNameError, unknown_name_message
from coassist.robot.worlds import WORLDS
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.intent_registry import INTENT_SOURCES

T = TypeVar("T")

console = Console()
err_console = Console(stderr=True, highlight=False)


# --------------------------------------------------------------------------- shared checks
# Each runs before any work starts and ends in one line that names the option as typed.


def fail(message: str, code: int = 1) -> NoReturn:
    """Print ``error: <message>`` on stderr (as plain text: brackets stay) and exit with ``code``."""
    err_console.print(f"error: {message}", markup=False, soft_wrap=True)
    raise typer.Exit(code)


def typed(message: str, options: Mapping[str, str]) -> str:
    """``message`` with config field names (``train.epochs``) replaced by the options typed (``--epochs``)."""
    for name in sorted(options, key=len, reverse=True):
        message = re.sub(rf"(?<![\w.-]){re.escape(name)}(?![\w])", options[name], message)
    return message


def choose(value: str, choices: Iterable[str], option: str, what: str) -> str:
    """``value`` if it is one of ``choices``, else fail naming the option, with a "did you mean"
    (for a controller's former name, its kind: ``coassist.control.presets.FORMER_NAMES``)."""
    choices = list(choices)
    if value in choices:
        return value
    if what == "controller":
        from coassist.control.presets import FORMER_NAMES

        if FORMER_NAMES.get(value) in choices:
            fail(f"{option} {value!r} is now called {FORMER_NAMES[value]!r} (choose from: {', '.join(choices)})", 2)
    fail(f"{option} {unknown_name_message(value, choices, what)}", 2)


def lookup(registry: Registry[T], name: str, option: str) -> T:
    """The preset ``name`` of ``registry`` (any kind), else fail naming the option, with a "did you mean"."""
    try:
        return registry.lookup(name)
    except UnknownNameError as exc:
        fail(f"{option} {exc}", 2)


def _existing_ancestor(path: Path) -> Path:
    """The nearest of ``path`` and its parents that exists (``.`` at worst)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path.parent != path:
        path = path.parent
    return path


def folder_out(path: Path, option: str, typed: Path | None = None) -> Path:
    """Fail now unless ``path`` is, or can be made, a folder this user can write in.

    ``typed``: what the user gave, when ``path`` is derived from it (a file's folder).
    """
    shown = f"{option} {path if typed is None else typed}"
    if path.exists() and not path.is_dir():
        fail(f"{shown}: {path} is a file, not a folder")
    base = _existing_ancestor(path)
    if not base.is_dir():
        fail(f"{shown}: {base} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        fail(f"{shown}: {base} is not writable (permission denied)")
    import tempfile

    try:  # a read-only or virtual file system (/proc passes os.access for root): found after the work, a traceback
        with tempfile.NamedTemporaryFile(dir=base, prefix=".coassist-probe-"):
            pass
    except OSError as exc:
        fail(f"{shown}: cannot write in {base} ({exc.strerror})")
    _check_names(base, Path(os.path.abspath(path)).parts[len(base.parts) :], shown)
    return path


def _check_names(base: Path, names: Iterable[str], shown: str) -> None:
    """Fail now where one of ``names`` (to be made below ``base``) is too long for the hidden siblings written beside
    it (the temporary and partial names of coassist._io): found only after the work, it was a traceback."""
    from coassist._io import temp_name

    try:
        limit = os.pathconf(base, "PC_NAME_MAX")
    except (AttributeError, OSError, ValueError):  # no pathconf (Windows), or the file system does not say
        limit = 255
    for name in names:
        extra = len(os.fsencode(temp_name(name, "partial"))) - len(os.fsencode(name))
        if len(os.fsencode(name)) + extra > limit:
            fail(f"{shown}: the name {name[:20]}… is too long: at most {limit - extra} characters here")


def file_out(
    path: Path, option: str, default_name: str, *, ours: Callable[[Path], bool] | None = None, ext: str = ""
) -> Path:
    """The file to write for ``--out path``: ``path`` itself, or ``path/default_name`` if it is a folder.

    Fails now (not after the work) if the file's folder cannot be created or written. ``ours``: a file already there
    is replaced only where ``ours(file)`` says this command wrote it (an earlier result), never another file (a trial,
    a model's sidecar, a figure); ``ext``: a file name must end with it (``results`` is no file of ``.json``).
    """
    if path.is_dir():
        path = path / default_name
    if path.is_dir():
        fail(f"{option} {path}: is a folder; give a file name")
    if ext and path.suffix.lower() != ext:
        fail(f"{option} {path}: give a {ext} file, or an existing folder to write {default_name} in")
    folder_out(path.parent, option, typed=path)
    _check_names(_existing_ancestor(path.parent), (path.name,), f"{option} {path}")  # its folder: probed above
    if path.exists() and not os.access(path, os.W_OK):
        fail(f"{option} {path}: is not writable (permission denied)")
    if ours is not None and path.exists() and not ours(path):
        fail(f"{option} {path}: exists and is not a file this command wrote; give another name (nothing replaced)")
    return path


def results_out(out: Path, option: str, names: Sequence[str], marks: Sequence[Sequence[str]]) -> Path:
    """``--out`` of a command that writes the files ``names`` (its ``summary.json`` first) into a folder: fail now
    where one of them is there but that ``summary.json`` is not one this command wrote (a JSON object holding every
    key of one of ``marks``): another program's summary or page would be replaced."""
    folder_out(out, option)
    present = [name for name in names if (out / name).exists()]
    if present and not any(json_object_with(out / names[0], keys) for keys in marks):
        fail(
            f"{option} {out}: holds {', '.join(present)} that this command did not write (nothing replaced); give an "
            "empty or new folder",
            2,
        )
    return out


def check_device(device: str | None, option: str = "--device") -> None:
    """Fail now if the torch device cannot be used here (not after loading the data)."""
    if device is None:
        return
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        fail(f"{option} {device!r}: not a torch device (use cpu, cuda or cuda:<n>)", 2)
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            built = "built with CUDA, but no GPU is visible" if torch.backends.cuda.is_built() else "built without CUDA"
            fail(f"{option} {device}: CUDA is not available here (torch {torch.__version__} {built}); use --device cpu")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            fail(f"{option} {device}: this machine has {torch.cuda.device_count()} CUDA device(s)")
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        fail(f"{option} {device}: Apple MPS is not available here; use --device cpu")
    elif dev.type not in ("cpu", "cuda", "mps"):
        fail(f"{option} {device}: use cpu, cuda or cuda:<n>", 2)


def wrote(text: str) -> None:
    console.print(f"[green]wrote[/] {escape(text)}", highlight=False, soft_wrap=True)  # paths stay whole


SKIP_BAD_HELP = "Leave out trials that cannot be read, saying which and why (default: stop at the first)."


def need_bags(option: str) -> None:
    """Refuse ``option`` before any work when rosbags (the bags extra) is missing."""
    try:
        import rosbags  # noqa: F401
    except ImportError:
        fail(f"{option} needs the bags extra (rosbags): pip install 'coassist[bags]'", 2)


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
        fail(f"--bag-topics: expected field=/topic pairs separated by commas, got {text!r}", 2)
    topics = {k.strip(): v.strip() for k, _, v in pairs}
    if len(topics) != len(pairs):  # the last would win, silently
        twice = next(k.strip() for k, _, _ in pairs if sum(1 for j, _, _ in pairs if j.strip() == k.strip()) > 1)
        fail(f"--bag-topics names {twice!r} twice: {text!r}", 2)
    try:
        resolve_topics(topics)
    except ValueError as exc:
        fail(f"--bag-topics: {exc}", 2)
    return topics


def intent_trials(paths: list[Path], skip_bad: bool = False, option: str = "DATA", bag_topics: str | None = None):
    import warnings

    from coassist.data import RecordingError, TrialFileError
    from coassist.data.datasets import ManifestError
    from coassist.intent import load_trials

    def skipped(where: str, reason: str) -> None:
        reason = reason.removeprefix(f"{where}: ")  # the reason usually names the file already
        console.print(f"[yellow]skipped[/] {where}: {reason}", highlight=False)

    _refuse_copies(paths, option)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            trials = load_trials(paths, on_bad=skipped if skip_bad else None, bag_topics=_bag_topics(bag_topics))
    except ImportError as exc:  # a bag without the bags extra
        fail(f"{option}: {exc}", 2)
    except (FileNotFoundError, ValueError) as exc:
        one_trial = isinstance(exc, (TrialFileError, RecordingError)) and not isinstance(exc, ManifestError)
        hint = " (--skip-bad-trials leaves unreadable trials out)" if one_trial and not skip_bad else ""
        fail(f"{option}: {exc}{hint}", 2)
    for w in caught:
        console.print(f"[yellow]warning:[/] {w.message}", highlight=False)
    return trials


def _refuse_copies(paths: list[Path], option: str) -> None:
    """A file given beside a folder given that holds it (a dataset and one of its own files: ids labA/trial_00001
    and Dx/trial_00001, trained on one copy and tested on the other; review, 2026-12-06): refused naming both."""
    folders = [(p, p.resolve()) for p in paths if p.is_dir()]
    for p in paths:
        if not p.is_file():
            continue
        here = p.resolve()
        for folder, where in folders:
            if here.is_relative_to(where):
                fail(f"{option}: {p} is one of the trials of {folder}, given too: give each trial once", 2)


def _items(text: str, option: str, distinct: bool) -> list[str]:
    """The comma-separated items of ``text``: an empty item (``a,,b``, a trailing comma) is refused, and with
    ``distinct`` a repeated one (``--users 0,0`` once collected user 0 twice under ``users=[0]``)."""
    items = [v.strip() for v in text.split(",")]
    if not any(items):
        return []
    if not all(items):
        fail(f"{option} has an empty item (two commas, or one at an end): {text!r}", 2)
    if distinct and len(set(items)) != len(items):
        twice = next(v for v in items if items.count(v) > 1)
        fail(f"{option} lists {twice!r} twice: {text!r}", 2)
    return items


def int_list(text: str, option: str, *, distinct: bool = True) -> list[int]:
    """``text``'s comma-separated integers >= 0 (``distinct``: each once), or a one-line refusal naming ``option``."""
    items = _items(text, option, False)
    if not all(is_ascii_integer(v) for v in items):
        fail(f"{option} must be comma-separated integers, got {text!r}", 2)
    values = [int(v) for v in items]
    if not values or any(v < 0 for v in values):
        fail(f"{option} must list integers >= 0, got {text!r}", 2)
    if distinct and len(set(values)) != len(values):
        twice = next(v for v in values if values.count(v) > 1)
        fail(f"{option} lists {twice} twice: {text!r}", 2)
    return values


def name_list(text: str, option: str, allowed: tuple[str, ...], what: str, *, distinct: bool = True) -> list[str]:
    """``text``'s comma-separated names, each one of ``allowed`` (``distinct``: each once), or a one-line refusal."""
    values = _items(text, option, distinct)
    if not values:
        fail(f"{option} must list one or more of {', '.join(allowed)}; got {text!r}", 2)
    return [choose(v, allowed, option, what) for v in values]


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

STABILITY_HELP = (
    "The stability guard on the assistive controllers (x-y): once the hand force, low-passed over 0.5 s, passes "
    "20 N while it turns (an oscillation, not a push held one way) the robot becomes a damper for the rest of the "
    "run (a stiff person behind a long reflex delay can fall into a limit cycle with assistance that follows their "
    "force; docs/robots.md). Off: the controller as it is. Not with --full-pose (it watches x-y control): the "
    "assistance line says so."
)


ASK_WAY_HELP = (
    "left | right: the person is asked to go round the obstacle that way in this run (a calibration trial for a way "
    "coassist calibrate says was shown too seldom). The trial records it, and the person model counts its path but "
    "not as their preference; a simulated operator goes that way. Default: the person chooses."
)


def way_option(name: str | None) -> int:
    """DriveConfig.way for --ask-way: +1 left, −1 right, 0 (not given) the person chooses."""
    from coassist.scenario.path_model import WAY_SIGNS

    if name is None:
        return 0
    return WAY_SIGNS[choose(name, tuple(WAY_SIGNS), "--ask-way", "way round")]


def stability_option(on: bool):
    """DriveConfig.stability for --stability-guard / --no-stability-guard: the guard's defaults, or None (off)."""
    from coassist.control.stability import StabilityGuardParameters

    return StabilityGuardParameters() if on else None


def simulation_only_sources() -> str:
    """The intent sources only a simulated world runs (the oracle), comma-separated, for the help."""
    return ", ".join(n for n, e in INTENT_SOURCES.items() if e.simulation_only)


def real_arm_hosts(option: str) -> str:
    """Each real arm's default address and the ``option`` value that names its world, for the help."""
    return ", ".join(f"{e.host} ({option} {n})" for n, e in WORLDS.items() if e.host)


def scene_option(path: Path | None, controller: str, intent: str):
    """The scene of --scene, read and validated before anything moves (None: none given); refused where the run's
    controller and source read no scene (the trial would record a scene the robot never used, reported apart as if
    it had been told one)."""
    if path is None:
        return None
    from coassist.scenario.assistance import reads_scene
    from coassist.scenario.scene import SceneError, read_scene

    if not reads_scene(controller, intent):
        fail(
            f"--scene {path}: {controller} toward {intent} reads no scene (the path hypotheses do: an assisting "
            "controller with --intent paths or a path-hypotheses folder); drop --scene",
            2,
        )

    try:
        return read_scene(path)
    except SceneError as exc:
        fail(f"--scene {exc}", 2)


def say(line: str) -> None:
    """A run's one-line statement (what the person will get), as plain text."""
    console.print(line, markup=False, highlight=False, soft_wrap=True)


def floats(text: str | None, option: str) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        fail(f"{option}: expected comma-separated numbers, got {text!r}", 2)
