"""What the person at the handle will get, in one line: the controller, the intent source and what it was told.

``coassist drive``, ``ros2`` and ``play`` print it before a run (``assistance: …``), so that
the person running an arm knows whether the robot helps, toward what, and from which
calibration — and, when it has none, how to get one. :func:`assistance_line` writes it from
the controller kind, the ``--intent`` given and the loaded source (a person model says
whose arm and paths it holds); :func:`check_person` refuses a person model that holds no
calibration of the person at the handle (its rows would be the uncalibrated present
estimate's, which overshoots more than manual guidance in the application scenario:
docs/precision.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from coassist.scenario.intent_registry import INTENT_FOLDERS, INTENT_SOURCES, intent_folder_kind
from coassist.scenario.path_model import few_paths

__all__ = ["DEFAULT_INTENT", "assistance_line", "check_person", "check_person_tasks", "check_person_world"]

#: The intent source of every world and command when none is given: the safest measured on the
#: validation seeds of the application scenario without a calibration (docs/precision.md, *The default
#: without a calibration*).
DEFAULT_INTENT = "present-held"

_CALIBRATE = "no calibration: run coassist calibrate"
_NAMED = {
    "nominal": "the planned path (nominal): it pulls toward the plan, through any obstacle on it",
    "present": f"the present estimate from the hand force, extrapolated ({_CALIBRATE})",
    "present-held": f"the present estimate from the hand force ({_CALIBRATE})",
    "present-half": f"the present estimate from the hand force, half extrapolated ({_CALIBRATE})",
    "constant-velocity": f"the tool's constant-velocity extrapolation ({_CALIBRATE})",
    "oracle": "the simulated operator's true intent (the oracle: simulation only)",
}
_CONTROLLERS = {
    "manual": "none: manual guidance (MG), the robot renders its inertia and damping only",
    "manual-probe": (
        "none: a calibration trial, manual guidance plus the probe (a small known push that measures the arm); "
        "fit the trials with coassist calibrate"
    ),
    "impedance": "impedance control (IMP): a spring pulls the tool back onto the planned path",
}


def _ways(sides: np.ndarray) -> str:
    n = int(sides.size)
    left, right = int(np.sum(sides == 1)), int(np.sum(sides == -1))
    # a way shown once or twice is followed from those few paths alone (coassist.scenario.path_model.FEW_PATHS)
    thin = ", ".join(f"{name} from {k} path{'s' if k != 1 else ''} only" for name, k in few_paths(sides).items())
    return f"{n} demonstration{'s' if n != 1 else ''} ({left} left, {right} right{'; ' + thin if thin else ''})"


def reads_scene(controller: str, intent: str) -> bool:
    """Whether a run of ``controller`` toward ``intent`` reads the obstacles it is told (a scene file): an assisting
    controller with a source told the scene (:class:`~coassist.scenario.intent_registry.Told`'s ``scene``: ``paths``,
    a path-hypotheses folder)."""
    if controller in _CONTROLLERS:
        return False
    kind = intent_folder_kind(intent)
    told = INTENT_FOLDERS[kind].told if kind else INTENT_SOURCES[intent].told if intent in INTENT_SOURCES else None
    return bool(told is not None and told.scene)


def _told(obstacles: Sequence[Any], scene: str | None) -> str:
    n = len(obstacles)
    where = f"the scene file {scene}" if scene else "the simulated task"
    return f"{n} obstacle{'s' if n != 1 else ''} of {where}"


def check_person(
    source: Any,
    user: str,
    intent: str,
    fix: str = "name the person at the handle (--person), or calibrate them (coassist calibrate)",
    *,
    by_default: bool = True,
) -> None:
    """ValueError in one line when ``source`` is a person model (``coassist calibrate``) holding no calibration
    of ``user`` (the person at the handle): it names who it holds, and ``fix``, what to do. ``by_default``: a model
    with a default person (a study's own fit names its participant so) serves anyone else with that person's model;
    False: only the people it holds (a study, where the person at the handle is always the participant)."""
    from coassist.scenario.person_intent import PersonPathsIntent

    # the named present-estimate sources are the same class knowing nobody: no person model to check
    fitted = isinstance(source, PersonPathsIntent) and bool(source.arms or source.paths)
    if fitted and user not in source.arms and (source.default_paths is None or not by_default):
        held = ", ".join(sorted(source.arms)) or "nobody"
        raise ValueError(f"intent {intent}: the person model holds no calibration of {user!r} (it holds {held}); {fix}")


def check_person_tasks(source: Any, tasks: Sequence[str], intent: str, fix: str) -> None:
    """ValueError in one line where ``source`` is a person model (``coassist calibrate``) fitted on another path than
    one of ``tasks``: the source gives such a trial the present estimate held (it knows one plan), while the trial and
    the report name the model; ``fix``: what to do. The paths are compared in shape (each from its own start: an arm
    lays its plan out from where its tool stands), as :func:`~coassist.scenario.person_intent.same_plan` compares a
    run's plan with the model's."""
    from coassist.scenario.person_intent import PersonPathsIntent, same_plan
    from coassist.scenario.tasks import TASKS, nominal_path

    if not isinstance(source, PersonPathsIntent):
        return

    def shape(points: Any) -> np.ndarray:
        points = np.asarray(points, dtype=float)[:, :2]
        return points - points[0]

    kinds = {kind: shape(nominal_path(kind).points) for kind in TASKS}
    for person, model in source.paths.items():  # the default person is one of them
        fitted = shape(model.nominal)
        for task in tasks:
            if not same_plan(fitted, kinds[task]):
                known = [k for k, path in kinds.items() if same_plan(fitted, path)]
                on = f"task {known[0]!r}" if known else "a path of none of the tasks"
                raise ValueError(
                    f"{intent}: {person}'s person model was fitted on {on}, not on task {task!r}: its trials of that "
                    f"task would get the present estimate held while the report names the model; {fix}"
                )


def check_person_world(source: Any, origin: str, world: str, intent: str) -> None:
    """ValueError in one line when ``source`` is a person model calibrated on trials of a world that holds the object
    otherwise than the run's (``origin``: the run's ``TrialMeta.origin``; ``world``: its name, for the message): its
    online filter was chosen for those trials (:func:`~coassist.scenario.person_model.person_filter_for`: the yaw
    mode of an object that twists on its mount, or none on the MuJoCo UR5, which holds every object rigidly), and its
    arm and paths were measured there. Driven on the MuJoCo board with the point-mass world's filter, the tool's jerk
    rose to 2.4–3.7 m/s³ against MG's 1.8 (a review, two seeds)."""
    from coassist.scenario.person_intent import PersonPathsIntent
    from coassist.scenario.person_model import origin_kind, person_filter_for

    if not isinstance(source, PersonPathsIntent) or not (source.arms or source.paths):
        return
    # the kind of world its trials came from, where the file records it (a point-mass or browser calibration passed
    # the filter's check to a real arm: a review, 2026-12-07)
    kinds = sorted({origin_kind(o) for o in source.origins})
    if kinds and origin_kind(origin) not in kinds:
        raise ValueError(
            f"intent {intent}: the person model was calibrated on trials of {' and '.join(kinds)}, not of the {world} "
            f"world ({origin_kind(origin)}): its arm, paths and filter are that world's; calibrate the person on "
            f"{world} trials (--controller manual-probe, then coassist calibrate)"
        )
    if source.settings.object_yaw != person_filter_for(origin).object_yaw:
        there = (
            "a world where the object twists on its mount (the point-mass simulation, a real arm)"
            if source.settings.object_yaw
            else "the MuJoCo UR5 (which holds the object rigidly)"
        )
        raise ValueError(
            f"intent {intent}: the person model was calibrated on trials of {there}, not of the {world} world: its arm, "
            f"paths and filter are that world's; calibrate the person on {world} trials (--controller manual-probe, "
            "then coassist calibrate)"
        )


def assistance_line(
    controller: str,
    intent: str,
    source: Any = None,
    *,
    user: str = "",
    path: np.ndarray | None = None,
    obstacles: Sequence[Any] = (),
    scene: str | None = None,
) -> str:
    """``"assistance: …"``: what the person at the handle gets (module docstring).

    controller : the controller kind.  intent : the ``--intent`` given (a name or a folder).
    source : the loaded intent source (a person model is described from it); None: from ``intent`` alone.
    user : the person at the handle (whose calibration a person model uses).  path : (P, 2) the run's
    nominal path, when known (a person model's paths serve only the plan they were recorded on).
    obstacles : what the robot is told (TrialContext.obstacles).  scene : the scene file they came from
    (None: the simulated task's).
    """
    if controller in _CONTROLLERS:
        return f"assistance: {_CONTROLLERS[controller]}"
    head = f"assistance: {controller}, toward "
    if intent in _NAMED:
        return head + _NAMED[intent]
    if intent == "paths" or intent_folder_kind(intent) == "path-hypotheses":
        what = "the path hypotheses" + ("" if intent == "paths" else f" calibrated in {intent}")
        if obstacles and path is not None and callable(getattr(source, "in_the_way", None)):
            way = source.in_the_way(path, tuple(obstacles), user)  # what the source's reset will find
            if not way:
                return head + (
                    f"{what}, but the {_told(obstacles, scene)} {'lies' if len(obstacles) == 1 else 'lie'} clear of "
                    "this run's plan: nothing to go round, "
                    "the present estimate"
                )
            if len(obstacles) > 1:  # one detour a run: the box in the way the plan passes nearest (the line had said
                # "round the 2 obstacles" while the rows ran through the second: a review, 2026-12-07)
                more, clear = len(way) - 1, len(obstacles) - len(way)
                return head + (
                    f"{what} round one of the {_told(obstacles, scene)}, the one in the way its plan passes nearest"
                    + (
                        f"; {more} more in the way {'is' if more == 1 else 'are'} NOT gone round (the predictions run "
                        f"through {'it' if more == 1 else 'them'}: one detour a run)"
                        if more
                        else ""
                    )
                    + (f"; {clear} {'lies' if clear == 1 else 'lie'} clear of the plan" if clear else "")
                    + " (the robot is told the scene)"
                )
        if obstacles:
            return head + f"{what} round the {_told(obstacles, scene)} (the robot is told the scene)"
        return head + f"{what}, but the robot is told no obstacle: the present estimate (give --scene FILE)"
    if intent in INTENT_SOURCES:  # a source registered since (its summary says what it is)
        return head + INTENT_SOURCES[intent].summary
    if intent_folder_kind(intent) == "person-model":
        return head + _person(intent, source, user, path)
    return head + f"the trained model {intent} (coassist train)"


def _person(intent: str, source: Any, user: str, path: np.ndarray | None) -> str:
    from coassist.scenario.person_intent import PersonPathsIntent, same_plan

    name = f"the person model {intent}"
    if not isinstance(source, PersonPathsIntent) or not (source.arms or source.paths):
        return name
    arm = source.arms.get(user, source.default_arm)
    how = (
        "arm measured"
        if arm.method == "probe-iv"
        else "arm ASSUMED (the typical arm: their trials measured none usable)"
    )
    model = source.paths.get(user, source.default_paths)
    if model is None:
        return f"{name} ({user}: {how}, no demonstrations: the present estimate held)"
    # another person's calibration, served as the folder's default (a study's own fit): said whose
    whose = (
        f"{source.default_person}'s calibration, the model's default person: "
        if user not in source.paths and source.default_person is not None
        else ""
    )
    known = f"{user}: {whose}{how}, {_ways(model.sides)}"
    if (user if user in source.paths else source.DEFAULT) in source.held:
        # the calibration's twin check (coassist.sim.person_twin): leading along their paths cost them overshoot
        return (
            f"{name} ({known}; not led along their paths: their calibration's twin overshot more with the lead "
            "than under MG: present-held, every world's default)"
        )
    # the person model's own test of the plan (PersonPathsIntent.reset's)
    if path is not None and not same_plan(model.nominal, path):
        return f"{name} ({known}, recorded on another plan than this run's: the present estimate held, with their arm)"
    return f"{name} ({known})"
