"""Commands on recorded trials: ``calibrate`` (a person model per person) and ``show`` (one trial's figure)."""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np
import typer

from coassist.cli._common import (
    BAG_TOPICS_HELP,
    SKIP_BAD_HELP,
    console,
    fail,
    file_out,
    folder_out,
    intent_trials,
    wrote,
)


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
    demonstrations per way round, a way shown in too few trials, the fit's time; draws their
    paths and arm beside the model (person-model.png). Drive, ros2 and play take the folder
    as --intent FOLDER. Trials recorded with --ask-way add their path to that way, not to the
    person's preference between the ways.
    """
    from coassist.scenario.person_model import PERSON_MODEL_FILE

    if min_trials < 1:
        fail(f"--min-trials must be >= 1, got {min_trials}", 2)
    if out.exists() and not out.is_dir():
        fail(f"--out {out}: is a file; give a folder for the person model", 2)
    if (out / PERSON_MODEL_FILE).exists() and not overwrite:
        fail(f"--out {out}: already holds a person model; pass --overwrite to replace it", 2)
    from coassist.scenario.intent_registry import INTENT_FOLDERS
    from coassist.scenario.person_model import origin_kind, person_filter_for, write_person_model

    for name in INTENT_FOLDERS:  # --intent reads a folder by the first marker it holds: the model would be hidden
        kind = INTENT_FOLDERS[name]
        if kind.marker != PERSON_MODEL_FILE and (out / kind.marker).exists():
            fail(
                f"--out {out}: holds {kind.marker} ({kind.summary}); --intent would read the folder as that, not the "
                "person model: give the person model a folder of its own",
                2,
            )
    folder_out(out, "--out")
    from coassist._io import atomic_write_bytes
    from coassist.experiments.person_calibration import CalibrationError, calibrate_people, summary_line
    from coassist.experiments.person_figure import PERSON_FIGURE_FILE, calibration_panels, person_figure_png

    trials = intent_trials(data, skip_bad_trials, bag_topics=bag_topics)
    # the world the trials come from says how the person's hand holds the object (the online filter's yaw mode: on
    # the MuJoCo UR5, which holds every object rigidly, none) and what measured their arm (a simulated operator, the
    # browser's pointer spring, a person at a real handle): worlds of one kind (a UR's exported bags, "real", beside
    # its drive trials, "ur5") go together; a simulation's beside an arm's went into one model (a review, 2026-12-07)
    origins = {it.trial.meta.origin for it in trials}
    if len({origin_kind(o) for o in origins}) > 1:
        first = {o: next(it.id for it in trials if it.trial.meta.origin == o) for o in sorted(origins)}
        fail(
            "the trials come from more than one world ("
            + ", ".join(f"{o}: {tid}" for o, tid in first.items())
            + "), whose hands hold the object and measure the arm otherwise: calibrate each world's trials into a "
            "model of its own",
            2,
        )
    try:
        people = calibrate_people(trials, task=task, min_trials=min_trials)
    except CalibrationError as exc:
        message = str(exc)
        if message.endswith(f"a person model needs at least {min_trials}"):  # the option that sets it, named
            message += " (--min-trials)"
        if task is not None and message.startswith("no trial of task"):  # the option that asked for it, named
            message = f"--task {task}: {message}"
        fail(message, 2)
    for c in people:
        console.print(summary_line(c), markup=False, highlight=False, soft_wrap=True)
    no_way = [c for c in people if not np.any(c.fit.paths.sides != 0)]
    if no_way:  # their curves would hold the tool to the plan: worse than pulling to it with nominal
        c = no_way[0]
        fail(
            f"{c.person}: none of their {len(c.trials)} trials went round the obstacle (no way round to learn; "
            f"first: {c.trials[0]}); record them with the obstacle in place (--obstacle), or leave the person out",
            2,
        )
    figure = out / PERSON_FIGURE_FILE
    if figure.is_dir():
        fail(f"--out {out}: {figure} is a folder; the person model's figure is written there", 2)
    # the figure drawn in memory, the model written, then the figure (each file whole or not at all): a model that
    # cannot be written leaves the folder as it was; a figure that cannot be written after it is said
    png = person_figure_png(calibration_panels(people))
    try:
        write_person_model(
            out,
            {c.person: c.fit for c in people},
            settings=person_filter_for(next(iter(origins))),
            origins=sorted(origins),
        )
    except (OSError, ValueError) as exc:
        fail(
            f"--out {out}: cannot write {PERSON_MODEL_FILE} ({getattr(exc, 'strerror', None) or exc}); nothing changed"
        )
    try:
        atomic_write_bytes(figure, png)
    except OSError as exc:
        fail(f"--out {out}: the person model is written, but not its figure {figure.name} ({exc.strerror})")
    wrote(f"{out / PERSON_MODEL_FILE}: {len(people)} person(s); drive with --intent {shlex.quote(str(out))}")
    wrote(f"{figure}: each person's paths and arm, to look at before they assist")


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

    # a trial file's stem (run.parquet → run.png, as drive names its figure), a folder's name
    named = path.resolve()
    name = f"{named.stem if named.is_file() else named.name}{'' if index == 0 else f'_{index}'}.png"
    out = file_out(Path(name) if out is None else out, "--out", name)
    kinds = ("png", "pdf", "svg", "jpg", "jpeg")  # what the monitor's figure is written as
    if out.suffix.lower().lstrip(".") not in kinds:
        folder = "" if out.suffix else "no such folder (make it first for the figure to go in it), or "
        fail(f"--out {out}: {folder}give a file ending in .{', .'.join(kinds)} (the figure's format)", 2)
    trials = intent_trials([path], skip_bad_trials, option="PATH", bag_topics=bag_topics)
    if not 0 <= index < len(trials):
        fail(f"--index {index}: {path} holds {len(trials)} trial(s), so it must be in 0 … {len(trials) - 1}", 2)
    try:
        written = plot_trial(trials[index].trial, out)
    except OSError as exc:
        fail(f"--out {out}: cannot write ({exc.strerror})")
    wrote(str(written))
