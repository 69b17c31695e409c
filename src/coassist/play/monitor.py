"""The page, read-only, on a ``coassist drive`` run: a UR5 in MuJoCo or a real one.

:class:`DriveMonitor` is a :class:`~coassist.play.session.PlaySession` whose trial is
:func:`coassist.robot.drive.drive` instead of the point-mass world: the drive's own loop
calls ``on_tick(k, state, out)`` every period and the monitor turns that into the page's
frame (tool x-y, the measured hand force, the prediction in use, the reference, the robot's
effort, fault flags), at most 125 frames a second. The page only watches: its pointer,
start and abort messages are dropped (counted as ``"watcher"``). The run is written to the
session folder like a played trial, and scored the same way. Stopping the server (Ctrl+C) stops
the arm at the next tick, and the ticks before it are the trial (``ended = "interrupted"``), as
``coassist drive``'s Ctrl-C keeps them; a played trial aborted so is not written.

A simulated arm (the MuJoCo UR5) runs paced to the wall clock (so the page shows it at its
real speed); a real arm is paced by its controller. The task is the drive's (same seed); where the drive
lays the plan out from the arm's start pose (a real UR5), the scene is shifted to match the
first frame's reference.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from coassist.play.session import PlayConfig, PlaySession, TrialResult, arm_frame, points_bounds
from coassist.robot.drive import TASK_HEIGHT, DriveConfig, drive
from coassist.robot.worlds import WORLDS, WorldRequest, build_world
from coassist.runtime.loop import RunInterrupted
from coassist.scenario.tasks import task_for_seed

__all__ = ["DriveMonitor"]

#: Most frames a second sent to the page (a 500 Hz drive sends every 4th tick).
MONITOR_RATE = 125.0


class DriveMonitor(PlaySession):
    """Watch one ``coassist drive`` run (module docstring).

    drive_config : the run.  config : the session (user, out folder; its controllers and
    intent are taken from ``drive_config``).  host : the real arm's address (the worlds that need one).
    confirm : as :func:`~coassist.robot.drive.drive`'s, asked before a real arm moves.
    say : as :func:`~coassist.robot.drive.drive`'s, told what the person will get before the run.
    live : a :class:`~coassist.runtime.live.LiveFeed` that watches the run too (e.g. Foxglove).
    """

    watch_only = True

    def __init__(
        self,
        drive_config: DriveConfig,
        config: PlayConfig,
        *,
        host: str | None = None,
        confirm: Any = None,
        say: Any = None,
        live: Any = None,
    ) -> None:
        if not isinstance(drive_config, DriveConfig):
            raise ValueError(f"drive_config must be a DriveConfig, got {type(drive_config).__name__}")
        self.drive_config, self.robot_host, self.confirm, self.say = drive_config, host, confirm, say
        # The drive builds its own controller and predictor: the session's paced predictor
        # process would start and never be used.
        super().__init__(dataclasses.replace(config, paced=False), live=live)

    def next_task(self):
        c = self.drive_config
        return task_for_seed(c.task, c.seed)

    def start(self) -> bool:
        """Start the drive run (the monitor's only trial)."""
        return self.start_trial(self.drive_config.controller)

    def _run_trial(self, task, name: str, controller) -> TrialResult | None:
        c = self.drive_config
        every = max(1, int(round(c.rate_hz / MONITOR_RATE)))
        shift: list[np.ndarray] = []

        def on_tick(k: int, state, out) -> None:
            if self._abort is not None:  # Ctrl+C or the page: stop the arm now, keep the ticks (as drive's Ctrl-C)
                raise KeyboardInterrupt
            if not shift:  # the plan may be laid out from the arm's start pose: match the scene to it
                shift.append(np.asarray(out.reference[:2], dtype=float) - task.planner.reference(k * c.dt)[:2])
                if np.linalg.norm(shift[0]) > 1e-9:
                    scene = _shifted(self.scene(task), shift[0])
                    self.current = {"controller": name, "scene": scene}
                    self.bounds = points_bounds(np.asarray(scene["path"]))
                    self.publish({"type": "started", "controller": name, "scene": scene, "bounds": self.bounds})
            if k % every:
                return
            frame = arm_frame(
                out, index=len(self.results), k=k, dt=c.dt, controller=name, world=c.world, seq=-1, held=False
            )
            self.frame = frame
            self.publish(frame)

        world = None
        if WORLDS[c.world].simulated:  # paced to the wall clock, so the page shows the run at its real speed
            start = (float(task.start[0]), float(task.start[1]), TASK_HEIGHT)
            world = build_world(
                c.world,
                WorldRequest(c.robot or WORLDS[c.world].arms[0], c.object, c.rate_hz, c.seed, start, realtime=True),
            )
        try:
            trial = drive(
                c,
                world=world,
                host=self.robot_host,
                confirm=self.confirm,
                on_tick=on_tick,
                say=self.say,
                live=self.live,
            )
        except RunInterrupted as stop:  # the server stopping (Ctrl+C) ran the drive on for 10 s, then lost it
            if stop.trial is None:
                raise
            trial = stop.trial
            self._notify({"type": "status", "level": "warn", "text": "stopped: the arm at rest, the ticks so far kept"})
        finally:
            if world is not None:
                world.close()
        trial = _with_controller_name(trial, name)
        return self._save(trial)


def _shifted(scene: dict, d: np.ndarray) -> dict:
    dx, dy = float(d[0]), float(d[1])
    out = dict(scene)
    out["path"] = [[x + dx, y + dy] for x, y in scene["path"]]
    out["start"] = [scene["start"][0] + dx, scene["start"][1] + dy]
    out["target"] = [scene["target"][0] + dx, scene["target"][1] + dy]
    ob = scene["obstacle"]
    out["obstacle"] = {"center": [ob["center"][0] + dx, ob["center"][1] + dy], "size": ob["size"]}
    return out


def _with_controller_name(trial, name: str):
    """The drive's trial with the page's controller name in meta.extra (for the running means)."""
    from dataclasses import replace

    from coassist.data import TrialMeta

    extra = dict(trial.meta.extra)
    extra["controller_name"] = name
    meta = TrialMeta(**{**trial.meta.to_dict(), "extra": extra})
    return replace(trial, meta=meta)
