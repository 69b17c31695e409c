"""Where the controller's estimate of the operator's intent ŷ_ref,h comes from: every intent source, by name.

The world asks an :class:`~coassist.interfaces.IntentSource` once per tick for the
operator's desired positions over the next ``horizon`` ticks, from the last ``history``
samples of what the robot measures. This is the interface the LSTM predictor (thesis §4.1,
Fig. 4.1) implements; the world builds the controller's human reference from it::

    ref_h[i] = [p̂(k+1+i) − x0,  (p̂(k+1+i) − p̂(k+i)) / dt]      i = 0 … H−1

(positions shifted into the controller's Δx frame; velocities by finite differences
along the prediction, the first row using the second row's difference). The history
features and the fallback on a bad prediction are :mod:`coassist.interfaces`'.

What ``--intent`` (and ``TrialSpec.intent``, ``DriveConfig.intent``, ``PlayConfig.intent``)
may name, and the one place each is registered:

- a name of :data:`INTENT_SOURCES`, one entry per source: ``nominal``, ``constant-velocity``,
  ``oracle``, ``present``, ``paths``. Each entry names the class (or function) that builds
  the source from the horizon by its entry point (:func:`coassist.registry.load_entry_point`),
  imported when a run loads it;
- a folder of a kind in :data:`INTENT_FOLDERS`, told apart by the file that marks it: a
  path-hypotheses calibration (``path-hypotheses.json``, :mod:`coassist.scenario.path_hypotheses`)
  or an intent model written by ``coassist train`` (``model.json``; any other existing folder is
  tried as one, so that the model loader's error says what is wrong with it).

A string that is neither a name nor an existing folder (a typo of ``paths``) is refused in one
line that says so, lists the names and suggests the closest.

The loop (:func:`load_intent_source`, :func:`shared_intent_source`), ``coassist collect``,
``drive``, ``ros2``, ``play`` and their help texts (:func:`intent_choices`, :func:`check_intent`)
all read these two tables. docs/architecture.md, *Add an intent source*, is the recipe.

Model-backed sources travel to worker processes as a path, never as an object: the intent
package provides ``coassist.intent.load_model_intent(path) -> IntentSource``, imported lazily
so that the simulator works without the learning stack.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from coassist.interfaces import NETWORK_BACKENDS, IntentSource
from coassist.registry import Registry, is_entry_point, load_entry_point

__all__ = [
    "INTENT_FOLDERS",
    "SIMULATED_FAMILY",
    "Told",
    "INTENT_SOURCES",
    "NAMED_INTENTS",
    "IntentFolderKind",
    "IntentSourceEntry",
    "check_intent",
    "intent_choices",
    "intent_folder_kind",
    "is_path_hypotheses",
    "load_intent_source",
    "needs_network",
    "shared_intent_source",
]


@dataclass(frozen=True)
class Told:
    """What an intent source is told besides what an arm measures (the report says it beside its figures).

    scene : it is told where the obstacles are (TrialContext.obstacles; a simulated world, or a lab's
        scene file).
    family : the model of people's paths it was built on ("": none; ``paths``: the simulated
        operator's own detour family). A source with none may not import the simulated person
        (tests/test_layers.py follows its imports).
    arm : the person's arm it assumes: "none" (not used), "assumed" (a typical arm) or "measured"
        (identified from the person's calibration trials).
    label : what it learnt to predict from trials ("": it learnt nothing; "the simulated operator's
        intent" needs a simulation to train).
    person : what it learnt from the person's own trials ("": nothing); a measured arm is learnt from them too, and
        the line says so ("… and the arm"; where a calibration fell back to the typical arm, it does not).
    """

    scene: bool = False
    family: str = ""
    arm: str = "none"
    label: str = ""
    person: str = ""

    def __post_init__(self) -> None:
        if self.arm not in ("none", "assumed", "measured"):
            raise ValueError(f"Told.arm must be 'none', 'assumed' or 'measured', got {self.arm!r}")

    def text(self) -> str:
        """One line: e.g. "scene; family: the simulated operator's detours; arm assumed"."""
        parts = ["scene" if self.scene else "", f"family: {self.family}" if self.family else ""]
        parts += [f"arm {self.arm}" if self.arm != "none" else "", f"label: {self.label}" if self.label else ""]
        person = f"{self.person} and the arm" if self.person and self.arm == "measured" else self.person
        parts += [f"from the person's trials: {person}" if person else ""]
        return "; ".join(p for p in parts if p) or "the plan only"


@dataclass(frozen=True)
class IntentSourceEntry:
    """One named intent source.

    source : entry point ``"package.module:attribute"`` of what builds it: called as
        ``attribute(horizon, **options)`` and returning an :class:`~coassist.interfaces.IntentSource`.
    summary : what it predicts, a phrase (the command line's help and docs/architecture.md).
    options : keyword arguments the name fixes besides the horizon, as (name, value) pairs
        (``present`` is the person model's source knowing no person: the present estimate of a
        typical arm at constant velocity).
    simulation_only : it reads what only a simulation knows (``TrialContext.true_intent``):
        refused on a real arm and with a person at the handle.
    told : what it is told besides what an arm measures (:class:`Told`).
    ablation : the main job's ablation runs it too, after the sources of its tables
        (:data:`coassist.experiments.ablation_cells.SOURCES`, which name the project's own).
    """

    source: str
    summary: str
    options: tuple[tuple[str, Any], ...] = ()
    simulation_only: bool = False
    told: Told = Told()
    ablation: bool = False

    def __post_init__(self) -> None:
        if not is_entry_point(self.source):
            raise ValueError(f"IntentSourceEntry.source must be 'package.module:attribute', got {self.source!r}")
        if not isinstance(self.summary, str) or not self.summary:
            raise ValueError(f"IntentSourceEntry.summary must be a non-empty string, got {self.summary!r}")
        for flag in ("ablation", "simulation_only"):  # "False" is truthy: a real arm's guard would be off
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"IntentSourceEntry.{flag} must be True or False, got {getattr(self, flag)!r}")

    def build(self, horizon: int) -> IntentSource:
        """A new source of this kind predicting ``horizon`` rows."""
        return load_entry_point(self.source)(horizon, **dict(self.options))


#: The detour family ``paths`` (and ``present``, its class) is built on: the simulated operator's.
SIMULATED_FAMILY = "the simulated operator's detours"
#: The named intent sources (module docstring), in the order the help lists them.
INTENT_SOURCES: Registry[IntentSourceEntry] = Registry(
    "intent source",
    {
        "nominal": IntentSourceEntry(
            "coassist.scenario.reference_intents:NominalIntent", "the planner's nominal path (no prediction, eq. 4.7)"
        ),
        "constant-velocity": IntentSourceEntry(
            "coassist.scenario.constant_velocity:ConstantVelocityIntent", "the tool's constant-velocity extrapolation"
        ),
        "oracle": IntentSourceEntry(
            "coassist.scenario.reference_intents:OracleIntent",
            "the simulated operator's true intent",
            simulation_only=True,
            told=Told(label="the simulated operator's intent, read directly"),
        ),
        "present": IntentSourceEntry(
            "coassist.scenario.person_intent:PersonPathsIntent",
            "the present estimate from the hand force",
            options=(("model_id", "present"),),
            told=Told(arm="assumed"),
        ),
        "present-held": IntentSourceEntry(
            "coassist.scenario.person_intent:PersonPathsIntent",
            "the present estimate from the hand force, held over the horizon (no extrapolation)",
            options=(("extrapolation", 0.0), ("model_id", "present-held")),
            told=Told(arm="assumed"),
        ),
        "present-half": IntentSourceEntry(
            "coassist.scenario.person_intent:PersonPathsIntent",
            "the present estimate from the hand force at half the tool's velocity",
            options=(("extrapolation", 0.5), ("model_id", "present-half")),
            told=Told(arm="assumed"),
        ),
        "paths": IntentSourceEntry(
            "coassist.scenario.path_hypotheses:PathHypothesesIntent",
            "the path hypotheses round the obstacles the robot is told of",
            told=Told(scene=True, family=SIMULATED_FAMILY, arm="assumed"),
        ),
    },
    entry_type=IntentSourceEntry,
)
#: Their names as declared here: the sources computed in the tick, with no network to evaluate. A
#: consumer that must see sources registered later (:meth:`~coassist.registry.Registry.register`)
#: reads :data:`INTENT_SOURCES` itself.
NAMED_INTENTS: tuple[str, ...] = tuple(INTENT_SOURCES)


@dataclass(frozen=True)
class IntentFolderKind:
    """A kind of folder ``--intent`` may name.

    marker : the file that marks a folder of this kind.  summary : what it is (the help).
    load : ``load(folder, horizon, network)`` → the source.  network : it evaluates a
    network (a model): the drive runs it off the control thread on a real arm.
    module : the module ``load`` reads the folder with (tests/test_layers.py follows its imports).
    told : what such a source is told besides what an arm measures (:class:`Told`).
    """

    marker: str
    summary: str
    load: Callable[[str, int, str], IntentSource]
    network: bool
    module: str = ""
    told: Told = Told()


def _load_calibration(folder: str, horizon: int, network: str) -> IntentSource:
    from coassist.scenario.path_hypotheses import read_calibration

    return read_calibration(folder, horizon)


def folder_told(kind: str, folder: str | Path) -> Told:
    """What the source of a ``kind`` folder (:data:`INTENT_FOLDERS`; the folder's own marker decides where it has
    one) was told: its kind's :class:`Told`, with the arm "assumed" unless every person model in it measured its
    person's arm (a calibration that fell back to the typical arm for someone did not learn theirs; the report said
    "arm measured" of models that held the typical arm)."""
    kind = intent_folder_kind(str(folder)) or kind
    told = INTENT_FOLDERS[kind].told
    if told.arm != "measured":
        return told
    source = INTENT_FOLDERS[kind].load(str(folder), 2, "auto")
    people = getattr(source, "draws", (source,))
    arms = [arm for person in people for arm in getattr(person, "arms", {}).values()]
    return told if arms and all(arm.method != "assumed" for arm in arms) else replace(told, arm="assumed")


def _load_person_model(folder: str, horizon: int, network: str) -> IntentSource:
    from coassist.scenario.person_model import read_person_model

    return read_person_model(folder, horizon)


def _load_draws(folder: str, horizon: int, network: str) -> IntentSource:
    from coassist.scenario.calibration_draws import read_draws

    return read_draws(folder, horizon)


def _load_model(folder: str, horizon: int, network: str) -> IntentSource:
    try:
        from coassist.intent import load_model_intent
    except ImportError as exc:
        raise ValueError(
            f"intent {folder!r} is a model path, but coassist.intent.load_model_intent is not available ({exc})"
        ) from None
    try:
        return load_model_intent(folder, backend=network)
    except (OSError, ValueError) as exc:  # missing folder, bad sidecar, features or dt that do not match
        raise ValueError(f"intent {folder!r} could not be loaded as a model: {exc}") from None


#: The kinds of folder ``--intent`` may name, the first whose marker a folder holds wins; a
#: string that is neither a name nor such a folder is tried as a model (its loader says why not).
INTENT_FOLDERS: Registry[IntentFolderKind] = Registry(
    "intent folder kind",
    {
        "path-hypotheses": IntentFolderKind(
            "path-hypotheses.json",
            "a path-hypotheses calibration folder",
            _load_calibration,
            network=False,
            module="coassist.scenario.path_hypotheses",
            told=Told(scene=True, family=SIMULATED_FAMILY, arm="assumed", person="detour shape and side"),
        ),
        "person-model": IntentFolderKind(
            "person-model.json",
            "a person model folder (coassist calibrate)",
            _load_person_model,
            network=False,
            module="coassist.scenario.person_model",
            told=Told(arm="measured", person="paths round obstacles"),
        ),
        "calibration-draws": IntentFolderKind(
            "calibration-draws.json",
            "a calibration-draws folder (person models of several calibrations)",
            _load_draws,
            network=False,
            module="coassist.scenario.calibration_draws",
            told=Told(arm="measured", person="paths round obstacles"),
        ),
        "model": IntentFolderKind(
            "model.json",
            "a model folder (coassist train)",
            _load_model,
            network=True,
            module="coassist.intent",
            told=Told(label="what the model was trained on (its sidecar: the tool's future or the intent)"),
        ),  # intent.model.SIDECAR
    },
    entry_type=IntentFolderKind,
)


def intent_folder_kind(spec: str) -> str | None:
    """The :data:`INTENT_FOLDERS` kind of the folder ``spec`` (by its marker file); None for a name or any other string."""
    if not isinstance(spec, str) or not spec or spec in INTENT_SOURCES:
        return None
    folder = Path(spec)
    return next((name for name, kind in INTENT_FOLDERS.items() if (folder / kind.marker).is_file()), None)


def is_path_hypotheses(spec: str) -> bool:
    """Whether ``spec`` is a folder holding a calibrated ``paths`` source (not a trained model)."""
    return intent_folder_kind(spec) == "path-hypotheses"


def needs_network(spec: str) -> bool:
    """Whether the source ``spec`` names evaluates a network (a model folder, or a string tried as one)."""
    if spec in INTENT_SOURCES:
        return False
    return INTENT_FOLDERS[intent_folder_kind(spec) or "model"].network


def intent_choices(*, simulation: bool = True) -> str:
    """What ``--intent`` may be, for the help: ``"nominal | … | paths | a model folder (coassist train) | …"``.

    ``simulation`` False: without the sources only a simulation can run (a real arm, a person).
    """
    names = [name for name, entry in INTENT_SOURCES.items() if simulation or not entry.simulation_only]
    return " | ".join([*names, *(kind.summary for kind in INTENT_FOLDERS.values())])


def check_intent(spec: str, *, simulation: bool = True) -> None:
    """ValueError in one line unless ``spec`` is a name of :data:`INTENT_SOURCES` (one a real arm can
    run, without ``simulation``) or a folder of a kind in :data:`INTENT_FOLDERS` (by its marker file)."""
    if isinstance(spec, str) and spec in INTENT_SOURCES:
        if not simulation and INTENT_SOURCES[spec].simulation_only:
            raise ValueError(f"{spec!r} is {INTENT_SOURCES[spec].summary}: a simulation alone knows it")
        return
    if intent_folder_kind(spec) is None:
        names = [name for name, entry in INTENT_SOURCES.items() if simulation or not entry.simulation_only]
        folders = " or ".join(f"{kind.summary} ({kind.marker})" for kind in INTENT_FOLDERS.values())
        raise ValueError(f"{spec!r}: not one of {', '.join(names)}, {folders}{_close_name(spec, names)}")


def _close_name(spec: object, names: list[str]) -> str:
    """``"; did you mean 'paths'?"`` when ``spec`` is close to one of ``names`` (else ""), as
    :func:`coassist.registry.unknown_name_message` words it (difflib, cutoff 0.5)."""
    close = difflib.get_close_matches(str(spec), names, n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


def load_intent_source(spec: str, horizon: int = 50, network: str = "auto") -> IntentSource:
    """An intent source from its name or folder (module docstring).

    A name of :data:`INTENT_SOURCES` → its entry's source (``"nominal"`` →
    :class:`~coassist.scenario.reference_intents.NominalIntent`, …); a path-hypotheses
    calibration folder → the calibrated
    :class:`~coassist.scenario.path_hypotheses.PathHypothesesIntent`; any other existing path is a
    model path handed to ``coassist.intent.load_model_intent`` (imported lazily, so the
    simulator works without the learning stack), its network evaluated by ``network``
    (:data:`~coassist.interfaces.NETWORK_BACKENDS`).
    """
    if not isinstance(spec, str) or not spec:
        raise ValueError(f"intent must be one of {', '.join(INTENT_SOURCES)} or a folder, got {spec!r}")
    if network not in NETWORK_BACKENDS:
        raise ValueError(f"network must be one of {NETWORK_BACKENDS}, got {network!r}")
    if spec in INTENT_SOURCES:
        return INTENT_SOURCES[spec].build(horizon)
    kind = intent_folder_kind(spec)
    if kind is None and not Path(spec).exists():
        names = list(INTENT_SOURCES)
        raise ValueError(
            f"intent {spec!r} is neither a source name ({', '.join(names)}) nor an existing folder"
            f"{_close_name(spec, names)}"
        )
    return INTENT_FOLDERS[kind or "model"].load(spec, horizon, network)


def shared_intent_source(
    spec: str, horizon: int, cache: dict[tuple[str, int, str], IntentSource] | None, network: str = "auto"
) -> IntentSource:
    """:func:`load_intent_source` through ``cache`` ((spec, horizon, network) → source), for runs in
    lockstep: a source with a ``batcher`` (a loaded model: stateless) is loaded once and
    shared, so one network call per tick serves every run; the others keep per-run state
    and are loaded per call. ``cache`` None: always loaded."""
    key = (spec, horizon, network)
    shared = None if cache is None else cache.get(key)
    if shared is not None:
        return shared
    source = load_intent_source(spec, horizon=horizon, network=network)
    if cache is not None and getattr(source, "batcher", None) is not None:
        cache[key] = source
    return source
