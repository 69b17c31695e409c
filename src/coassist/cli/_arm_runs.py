"""What ``drive``, ``ros2`` (and ``study run`` on an arm) share: the trial file a run writes, the
question asked before an arm moves, and the run's files once it ended."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import click
import typer
from rich.markup import escape

from coassist.cli._common import (
    console,
    err_console,
    fail,
    file_out,
    need_bags,
    wrote,
)

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
    "DriveConfig.way": "--ask-way",
    "SafetyLimits.tool_speed": "--tool-speed",
    "SafetyLimits.contact_force": "--contact-force",
}


def run_out(out: Path, overwrite: bool, mcap: bool, plot: bool) -> Path:
    """The trial file of a drive/ros2 run: a recorded run (its trial, or the MCAP beside it) is not
    replaced without --overwrite, nor a figure at <out>.png the run would write (``plot``), checked
    before the robot moves."""
    out = file_out(out, "--out", "trial.parquet")
    if out.suffix == ".mcap":
        fail(f"--out {out}: give the trial file (e.g. trial.parquet); --mcap writes the .mcap beside it", 2)
    if out.suffix.lower() != ".parquet":  # a trial file is Parquet whatever its name: a .csv name would hide that
        fail(
            f"--out {out}: a trial is written as Parquet: give a .parquet name (e.g. {out.with_suffix('.parquet')})", 2
        )
    if not overwrite:
        for path in (out, out.with_suffix(".mcap")) + ((out.with_suffix(".png"),) if plot else ()):
            if path.exists() or path.is_symlink():  # a recorded run, or its figure, is not replaced silently
                also = "" if path.suffix != ".png" else " (or --no-plot to write no figure)"
                fail(f"--out {out}: {path} exists; pass --overwrite to replace the run{also}", 2)
    if mcap:
        need_bags("--mcap")
    return out


def intent_option(intent: str) -> None:
    """Fail naming --intent unless it is a registered source or an intent folder (one line, exit 2), before a world
    is built: a missing folder was said as "intent 'models/x' is neither…", not naming the option."""
    from coassist.scenario.intent_registry import check_intent

    try:
        check_intent(intent)
    except ValueError as exc:
        fail(f"--intent {exc}", 2)


def confirm_move(yes: bool, stop_hint: str):
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


def write_run(
    trial,
    out: Path,
    *,
    mcap: bool,
    plot: bool,
    joint_names: Sequence[str] | None,
    frame_id: str = "base",
) -> None:
    """Write a drive/ros2 run: the trial file, how it ended, and <out>.mcap / <out>.png on request (the
    MCAP's ``/alpha`` is the trial's own α, tick by tick).
    ``joint_names``: the arm's, in the trial's joint order (None: joint_1 … joint_n in the MCAP);
    ``frame_id``: the robot's base frame, the MCAP's poses' frame (``coassist ros2 --base-frame``)."""
    from coassist.data.run_pair import write_run_pair

    # the trial and its MCAP as one pair: no crash leaves a trial beside another run's MCAP
    path, mcap_path = write_run_pair(trial, out, mcap=mcap, joint_names=joint_names, frame_id=frame_id)
    extra = trial.meta.extra
    wrote(f"{path}: {trial.n_samples} ticks, ended: {extra['ended']}")
    if extra.get("stop_message"):
        console.print(f"[yellow]{escape(extra['stop_message'])}[/]", highlight=False)
    if extra.get("log_note"):
        console.print(f"[yellow]{escape(extra['log_note'])}[/]", highlight=False)
    if mcap_path is not None:
        wrote(str(mcap_path))
    if plot:
        from coassist.sim.monitor import plot_trial

        wrote(str(plot_trial(trial, path.with_suffix(".png"))))


def write_interrupted(stop: Any, write: Callable[[Any], None]) -> NoReturn:
    """Ctrl-C during a drive/ros2 run (``stop``: :class:`~coassist.runtime.loop.RunInterrupted`, the arm already
    stopped): the ticks before it written by ``write`` (the run's :func:`write_run`), a line saying so, exit 130.
    A Ctrl-C once the run was over (``stop.after_end``) or while it is written: the whole trial, said so."""
    from coassist.runtime.loop import InterruptsHeld

    if stop.trial is None:
        err_console.print("interrupted (Ctrl-C) before the first tick: nothing to write", markup=False)
        raise typer.Exit(130)
    if stop.after_end:
        write_finished(stop.trial, write, interrupted=True)  # says so, exits 130
    with InterruptsHeld():
        write(stop.trial)
    err_console.print("interrupted (Ctrl-C): the ticks before it are written", markup=False)
    raise typer.Exit(130)


def write_finished(trial: Any, write: Callable[[Any], None], *, interrupted: bool = False) -> None:
    """Write a drive/ros2 run that ran to its end with ``write`` (:func:`write_run`), Ctrl-C held until it is
    written (a KeyboardInterrupt in the writing lost the trial, no line said so); one that came then, or before
    (``interrupted``: held while the world closed): a line, exit 130."""
    from coassist.runtime.loop import InterruptsHeld

    with InterruptsHeld() as held:
        write(trial)
    if held.pending or interrupted:
        err_console.print("Ctrl-C after the trial ended: the whole trial is written", markup=False)
        raise typer.Exit(130)
