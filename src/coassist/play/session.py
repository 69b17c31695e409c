"""A person's session: the thesis' protocol of trials, each run through the control tick and saved.

One session belongs to one user id and one folder, ``<out>/<user>/``, which is a
dataset (:mod:`coassist.data.datasets`: ``trial_*.parquet`` + ``manifest.json``, id
``play-<user>``) that ``coassist train`` reads as it is. Restarting ``coassist play``
with the same folder and user resumes the session: trials are appended.

Protocol (thesis §5.2.2, for a person): trial i follows the path ``tasks[i mod n]``
(linear, curved, sinusoidal, Z) with a box obstacle at a random place along it (seed
``seed + i``); the planner's reference moves along the path at the thesis' pace, and
the trial ends once that motion is over and the tool has stayed within
``arrive_radius`` of the target for ``dwell`` seconds (or at the time limit, or on a
safety stop). The person picks the controller before each trial.

Each trial runs on :class:`~coassist.play.world.PlayWorld` through the same episode
assembly (:mod:`coassist.runtime.episode`: the tick, :func:`~coassist.runtime.loop.run_loop`,
the Trial) as every other world, in its own thread, paced at 1/dt. After it, the session writes
the trial and scores it (thesis §5.2.4)::

    f_RMS = (1/T) Σ_k ‖w(k)‖                     eq. 5.9, w the measured hand wrench [N]
    σ     = mean of ‖x(i) − x_final‖ over τ = 3 s from first entering the ε-ball   eq. 5.10–5.11 [m]

and keeps the running means per controller over the user's trials in the folder.

A trial whose hand was gone (the page closed or the link dropped) for longer than
``grace`` seconds is aborted and not written; so is one the person aborts.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coassist._checks import check_int, check_positive_scalar
from coassist._io import OutputLock
from coassist.config import APPLICATION_PRESET
from coassist.control.presets import CONTROLLERS, FORMER_NAMES, get_preset, make_controller
from coassist.data import Trial, append_to_dataset, write_dataset
from coassist.data.datasets import MANIFEST_NAME, manifest_files, read_dataset
from coassist.interfaces import FEATURES, fault_names
from coassist.metrics import f_rms, precision_sigma
from coassist.play.hand import BrowserHand, SpringDamper
from coassist.play.world import PlayWorld
from coassist.runtime.episode import (
    POINT_MASS_LIMITS,
    POINT_MASS_WRENCH,
    EpisodeLabels,
    build_episode,
    episode_ticks,
    plan_grid,
)
from coassist.runtime.intent import RealtimeIntent, WindowIntent
from coassist.runtime.loop import run_loop
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.wrench import WrenchPipeline
from coassist.scenario.assistance import DEFAULT_INTENT, check_person, check_person_world
from coassist.scenario.intent_registry import INTENT_SOURCES, check_intent, load_intent_source
from coassist.scenario.path_model import ASKED_WAY, WAY_NAMES, check_way
from coassist.scenario.tasks import MOTION_TIME_RANGE, TASK_KINDS, TASKS, Task, nominal_path, task_for_seed

__all__ = ["PlayConfig", "PlaySession", "TrialResult", "view_bounds"]

_USER = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,31}$")
#: σ's averaging window τ [s] (thesis eq. 5.11).
SIGMA_TAU = 3.0
#: Every how many rows of the (H, 2) prediction a frame carries (H = 50 → 11 points).
PREDICTION_STRIDE = 5


def arm_frame(out, *, index: int, k: int, dt: float, controller: str, world: str, seq: int, held: bool) -> dict:
    """The page's ``frame`` of an arm world's tick k (``coassist drive``'s tick output ``out``: pose,
    velocity, wrench, u_r, reference, prediction, fault); the point-mass play world writes its own."""
    pred = out.prediction
    return {
        "type": "frame",
        "index": index,
        "k": k + 1,
        "t": (k + 1) * dt,
        "x": float(out.pose[0]),
        "y": float(out.pose[1]),
        "vx": float(out.velocity[0]),
        "vy": float(out.velocity[1]),
        "fh": [float(out.wrench[0]), float(out.wrench[1])],
        "ur": [float(v) for v in out.u_r[:2]],
        "ref": [float(v) for v in out.reference[:2]],
        "prediction": [] if pred is None else np.vstack([pred[::PREDICTION_STRIDE], pred[-1:]]).tolist(),
        "predicted": pred is not None,
        "faults": fault_names(int(out.fault)),
        "seq": seq,
        "held": held,
        "controller": controller,
        "misses": 0,
        "world": world,
    }


@dataclass(frozen=True)
class PlayConfig:
    """One person's session (every field validated; errors name ``PlayConfig.<field>``).

    user : the person's id: letters, digits, ``-`` and ``_``, at most 32 (it names the folder).
    out : the parent folder; the session lives in ``out/user``.
    controllers : the controllers the page offers (:data:`coassist.control.presets.CONTROLLERS`).
    intent : a source a person's run can use (:data:`~coassist.scenario.intent_registry.INTENT_SOURCES`
        but the simulation-only oracle), or a folder (a person model written by ``coassist calibrate``,
        whose calibration of ``user`` it must hold; a model written by ``coassist train``); default
        :data:`coassist.scenario.assistance.DEFAULT_INTENT`.
    preset : control preset (default :data:`coassist.config.APPLICATION_PRESET`, the main job's
        application preset, safe with a learned predictor in the loop).
    tasks : the protocol's paths, in order (repeated).
    seed : the obstacle of trial i is drawn from seed + i.
    motion_time : [s] the planner's motion time for every path; None: the thesis' per path.
    arrive_radius : [m] the target ball (σ's ε).  dwell : [s] inside it that ends a trial.
    time_limit : [s] per trial; None: 2 × the plan's end + 10 s.
    grace : [s] a trial waits this long for a hand that left before it is aborted.
    arm : the virtual arm between pointer and tool.
    paced : run the loop in real time (False only for tests of the bookkeeping).
    mcap : also write each trial as ``<trial>.mcap`` beside its Parquet file (ROS 2
        messages Foxglove opens, :mod:`coassist.data.trial_mcap`; the bags extra).
    way : the way round the obstacle the person is asked to take in every trial of the session, +1 on the left
        of the plan, −1 on the right (calibration trials for a way ``coassist calibrate`` says was shown too
        seldom): the page says so before each trial, and each trial records it (``meta.extra["asked_way"]``) so
        that the person model counts its path but not as their preference. 0: the person chooses.
    """

    user: str
    out: Path
    controllers: tuple[str, ...] = ("manual", "impedance", "cooperative")
    intent: str = DEFAULT_INTENT
    preset: str = APPLICATION_PRESET
    tasks: tuple[str, ...] = TASK_KINDS
    seed: int = 0
    motion_time: float | None = None
    arrive_radius: float = 0.025
    dwell: float = 3.0
    time_limit: float | None = None
    grace: float = 3.0
    arm: SpringDamper = field(default_factory=SpringDamper)
    paced: bool = True
    mcap: bool = False
    way: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.user, str) or not _USER.match(self.user):
            raise ValueError(
                f"PlayConfig.user must be 1-32 letters, digits, '-' or '_' (it names a folder), got {self.user!r}"
            )
        object.__setattr__(self, "out", Path(self.out))
        ctrl = tuple(self.controllers)
        if not ctrl or len(set(ctrl)) != len(ctrl) or any(c not in CONTROLLERS for c in ctrl):
            raise ValueError(
                f"PlayConfig.controllers must be distinct names from {tuple(CONTROLLERS)}, got {self.controllers!r}"
            )
        object.__setattr__(self, "controllers", ctrl)
        if (
            not isinstance(self.intent, str)
            or not self.intent
            or (self.intent in INTENT_SOURCES and INTENT_SOURCES[self.intent].simulation_only)
        ):
            raise ValueError(
                f"PlayConfig.intent must be a named source or a folder (a person has no oracle), got {self.intent!r}"
            )
        try:  # a name or folder nothing knows: refused now, not when the session loads it
            check_intent(self.intent, simulation=False)
        except ValueError as exc:
            raise ValueError(f"PlayConfig.intent {exc}") from None
        try:
            get_preset(self.preset)
        except ValueError as exc:
            raise ValueError(f"PlayConfig.{exc}") from None
        tasks = tuple(self.tasks)
        if not tasks or any(t not in TASKS for t in tasks):
            raise ValueError(f"PlayConfig.tasks must be names from {tuple(TASKS)}, got {self.tasks!r}")
        object.__setattr__(self, "tasks", tasks)
        object.__setattr__(self, "seed", check_int(self.seed, "PlayConfig.seed", 0))
        for name in ("motion_time", "time_limit"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, check_positive_scalar(getattr(self, name), f"PlayConfig.{name}"))
        lo, hi = MOTION_TIME_RANGE  # 1e9 s was taken and failed at the first trial, allocating 1.8 TiB
        if self.motion_time is not None and not lo <= self.motion_time <= hi:
            raise ValueError(f"PlayConfig.motion_time must be within {lo:g} … {hi:g} s, got {self.motion_time!r}")
        for name in ("arrive_radius", "dwell", "grace"):
            object.__setattr__(self, name, check_positive_scalar(getattr(self, name), f"PlayConfig.{name}"))
        if not isinstance(self.arm, SpringDamper):
            raise ValueError(f"PlayConfig.arm must be a SpringDamper, got {type(self.arm).__name__}")
        object.__setattr__(self, "way", check_way(self.way, "PlayConfig.way"))

    @property
    def folder(self) -> Path:
        return self.out / self.user

    @property
    def dataset_id(self) -> str:
        return f"play-{self.user}"


@dataclass(frozen=True)
class TrialResult:
    """One finished trial: where it was written, its scores, why it ended."""

    file: str
    index: int
    task: str
    controller: str
    f_rms: float
    sigma: float | None  # None: the target was never reached
    ended: str
    n_ticks: int
    deadline_misses: int

    def to_json(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def view_bounds(tasks: tuple[str, ...], margin: float = 0.12) -> tuple[float, float, float, float]:
    """(x_min, x_max, y_min, y_max) [m] of the view: every protocol path ± margin, square-ish."""
    return points_bounds(np.concatenate([nominal_path(t).points for t in tasks]), margin)


def points_bounds(points: np.ndarray, margin: float = 0.12) -> tuple[float, float, float, float]:
    """(x_min, x_max, y_min, y_max) [m] of (n, 2) points ± margin."""
    pts = np.asarray(points, dtype=float)
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


class PlaySession:
    """The session's state and its trials (module docstring).

    The server calls :meth:`start_trial`, :meth:`abort`, :meth:`hand_left` and
    :meth:`hand_back`; the loop thread calls ``publish(message)`` with each frame and
    each result (set :attr:`publish` before the first trial; it must not block).
    """

    def __init__(self, config: PlayConfig, hand: BrowserHand | None = None, *, live: Any = None) -> None:
        if not isinstance(config, PlayConfig):
            raise ValueError(f"config must be a PlayConfig, got {type(config).__name__}")
        self.config = config
        self.live = live  # a LiveFeed (coassist.runtime.live) that watches every trial, or None
        self.results: list[TrialResult] = []
        # The folder is this session's until close(): a second server on the same --out/--user would keep a protocol
        # of its own and write the same protocol trial twice (OutputBusyError names the other run's pid).
        self._folder_lock: OutputLock | None = OutputLock(config.folder).__enter__()
        try:
            self._open(config, hand)
        except BaseException:
            self._release_folder()
            raise

    def _open(self, config: PlayConfig, hand: BrowserHand | None) -> None:
        self._resume()  # a folder that is not a session fails here, before anything is built
        self.hand = hand or BrowserHand(config.arm)
        self.preset = get_preset(config.preset)
        self.bounds = view_bounds(config.tasks)
        # the game's gains are computed once per session, before the first trial
        self._controllers = {name: make_controller(name, self.preset) for name in config.controllers}
        H = int(self.preset.game.horizon)
        self.source = load_intent_source(config.intent, horizon=max(H, 2))
        if not getattr(self, "watch_only", False):  # a monitored drive checks its own person (robot.drive)
            check_person(
                self.source,
                config.user,
                config.intent,
                fix="play as a person it holds (--user), or calibrate them (coassist calibrate)",
            )
            check_person_world(self.source, "sim", "play", config.intent)  # the origin its trials record
        if int(self.source.horizon) < H:
            raise ValueError(f"the intent model predicts {self.source.horizon} steps; the controller needs {H}")
        model = getattr(self.source, "model", None)
        if model is not None:  # refuse a model of other features or another rate now, not in the first trial
            model.check_compatible(FEATURES, float(self.preset.impedance.dt), what="coassist play")
        # A person plays against the wall clock: the model runs in a worker process and the tick
        # never waits for it (computed inside the tick it made 7-13 % of the periods late).
        self._realtime = None
        if model is not None and config.paced:
            from coassist.intent.realtime import RealtimeConfig, RealtimePredictor

            self._realtime = RealtimePredictor(model, RealtimeConfig(backend="process"))
        self.publish: Callable[[dict], None] = lambda message: None
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._abort: str | None = None
        self._left_at: float | None = None
        self.running = False
        #: the status that ended the last trial (aborted, failed, its MCAP not written), None after a clean one:
        #: sent to a page that connects between trials, which missed it
        self.notice: dict[str, Any] | None = None
        self.current: dict[str, Any] | None = None
        self.frame: dict[str, Any] | None = None

    # ------------------------------------------------------------------ the folder
    def _resume(self) -> None:
        folder = self.config.folder
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"{folder} exists and is not a folder")
        if (folder / MANIFEST_NAME).is_file():
            ds = read_dataset(folder)
            for file, trial in zip(ds.files, ds.trials):
                self.results.append(score_trial(trial, file, len(self.results)))
        elif folder.is_dir() and any(folder.iterdir()):
            raise ValueError(
                f"{folder} is not empty and holds no {MANIFEST_NAME}: not a play session; pick another --out or --user"
            )

    # ------------------------------------------------------------------ the protocol
    def next_task(self) -> Task:
        """The task of the next trial (the same until a trial is written)."""
        i = len(self.results)
        kind = self.config.tasks[i % len(self.config.tasks)]
        return task_for_seed(kind, self.config.seed + i, motion_time=self.config.motion_time)

    def scene(self, task: Task | None = None) -> dict[str, Any]:
        """What the page draws that does not move: path, obstacle, start, target, timing."""
        task = task or self.next_task()
        pts = task.path.points[:: max(1, len(task.path.points) // 400)]
        pts = np.vstack([pts, task.path.points[-1:]])
        return {
            "index": len(self.results),
            "task": task.kind,
            "path": np.round(pts, 5).tolist(),
            "obstacle": task.obstacle.to_dict(),
            "start": task.start.tolist(),
            "target": task.target.tolist(),
            "arrive_radius": self.config.arrive_radius,
            "dwell": self.config.dwell,
            "motion_start": task.planner.start_delay,
            "motion_end": task.planner.end_time,
            # the way the person is asked to go round (the page says it); absent where they choose
            **({"way": WAY_NAMES[self.config.way]} if self.config.way else {}),
        }

    def summary(self) -> dict[str, Any]:
        """The running means per controller over this user's trials (f_RMS [N], σ [m])."""
        out: dict[str, Any] = {}
        for name in CONTROLLERS:
            rows = [r for r in self.results if r.controller == name]
            if not rows:
                continue
            sig = [r.sigma for r in rows if r.sigma is not None]
            out[name] = {
                "trials": len(rows),
                "f_rms": float(np.mean([r.f_rms for r in rows])),
                "sigma": float(np.mean(sig)) if sig else None,
                "reached": len(sig),
            }
        return out

    # ------------------------------------------------------------------ what a page is told and may ask
    def page_choices(self) -> tuple[str, ...]:
        """The names a page's ``start`` may ask for (the controllers offered)."""
        return self.config.controllers

    def for_page(self, message: dict[str, Any]) -> dict[str, Any]:
        """``message`` as a page receives it; every message to a page passes here (a study blinds it)."""
        return message

    def answer(self, step: int, values: list[float]) -> bool:
        """A questionnaire's answers from the page; False: none is asked (a study asks)."""
        return False

    def proceed(self, step: int) -> bool:
        """The page's "go on" after a rest; False: nothing waits for it (a study's rests do)."""
        return False

    def controller(self, name: str):
        if name not in self._controllers:
            raise ValueError(f"controller must be one of {self.config.controllers}, got {name!r}")
        return self._controllers[name]

    # ------------------------------------------------------------------ the hand's link
    def hand_left(self) -> None:
        self.hand.release()
        self._left_at = time.monotonic()

    def hand_back(self) -> None:
        self._left_at = None

    def abort(self, reason: str = "aborted") -> None:
        self._abort = reason

    # ------------------------------------------------------------------ one trial
    def start_trial(self, controller: str) -> bool:
        """Start the next trial with ``controller`` in a thread; False when one is running."""
        with self._lock:
            if self.running:
                return False
            ctrl = self.controller(controller)
            self.running = True
            self._abort = None
            self.notice = None
        task = self.next_task()
        self.current = {"controller": controller, "scene": self.scene(task)}
        self.publish({"type": "started", "controller": controller, "scene": self.current["scene"]})
        self._thread = threading.Thread(
            target=self._run, args=(task, controller, ctrl), name="coassist-play-loop", daemon=True
        )
        self._thread.start()
        return True

    def _notify(self, message: dict[str, Any]) -> None:
        """Publish a status about the last trial's end and keep it: a page that connects after it (the hand that
        left and came back after its trial was aborted) is told it too (:attr:`notice`)."""
        self.notice = message
        self.publish(message)

    def close(self) -> None:
        """Stop the model's worker process and give the folder up (the session's trials are all on disk already)."""
        try:
            if self._realtime is not None:
                self._realtime.close()
                self._realtime = None
        finally:
            self._release_folder()

    def _release_folder(self) -> None:
        lock, self._folder_lock = self._folder_lock, None
        if lock is not None:
            lock.__exit__(None, None, None)

    def wait(self, timeout: float | None = None) -> bool:
        """Wait for the running trial's thread; True when none is running."""
        t = self._thread
        if t is not None:
            t.join(timeout)
        return not self.running

    def _run(self, task: Task, name: str, controller) -> None:
        try:
            result = self._run_trial(task, name, controller)
        except Exception as exc:  # never leave the server with a dead trial: say why
            result = None
            why = str(exc) or type(exc).__name__  # (a refused prompt's Abort has no text: the line ended "failed: ")
            self._notify({"type": "status", "level": "error", "text": f"the trial failed: {why}"})
        finally:
            self.running = False
            self.current = None
        if result is not None:
            self.publish(
                {"type": "result", "result": result.to_json(), "summary": self.summary(), "next": self.scene()}
            )

    def trial_seed(self, index: int) -> int:
        """The seed of the session's trial ``index``: the root of the robot's own draws in it (the calibration
        probe's phases)."""
        return self.config.seed + index

    def _run_trial(self, task: Task, name: str, controller) -> TrialResult | None:
        cfg = self.config
        model = controller.model
        dt = float(model.dt)
        H = int(controller.horizon)
        n_max = episode_ticks(task, dt, cfg.time_limit)
        ref_abs = plan_grid(task, dt, n_max, int(self.source.horizon))
        x0 = np.array(task.start, dtype=float)
        world = PlayWorld(model, self.hand, x0, paced=cfg.paced)
        intent = (
            WindowIntent(self.source, H)
            if self._realtime is None
            else RealtimeIntent(self._realtime, model_id=self.source.model_id)
        )
        index = len(self.results)
        arm = cfg.arm
        episode = build_episode(
            world=world,
            controller=controller,
            intent=intent,
            wrench=WrenchPipeline(POINT_MASS_WRENCH, dt),
            safety=SafetyLayer(POINT_MASS_LIMITS, dt, 6),
            task=task,
            plan=ref_abs,
            start_pose=np.array((x0[0], x0[1], 0.0, 0.0, 0.0, 0.0)),
            n_max=n_max,
            labels=EpisodeLabels(
                user=cfg.user,
                object="none",
                seed=self.trial_seed(index),
                origin="sim",
                preset=cfg.preset,
                model_id=self.source.model_id,
            ),
            arrive_radius=cfg.arrive_radius,
            dwell=cfg.dwell,
            extra={
                "operator": "person",
                "hand": "browser",
                "world": "play",
                "arm": {"stiffness": arm.stiffness, "damping": arm.damping, "force_limit": arm.force_limit},
                "controller_name": name,
                "trial_index": index,
                **({ASKED_WAY: cfg.way} if cfg.way else {}),
            },
        )
        dwell = episode.termination

        def termination(k: int, pose: np.ndarray) -> bool:
            left = self._left_at
            if left is not None and time.monotonic() - left > cfg.grace:
                self._abort = "operator_left"
            return self._abort is not None or dwell(k, pose)

        def on_tick(k: int, state, out) -> None:
            pred = out.prediction if out.prediction is not None else ref_abs[k + 1 : k + 1 + H, :2]
            p = pred[::PREDICTION_STRIDE]
            frame = {
                "type": "frame",
                "index": index,
                "k": k + 1,
                "t": (k + 1) * dt,
                "x": world.x,
                "y": world.y,
                "vx": world.vx,
                "vy": world.vy,
                "fh": world.fh,
                "ur": out.command.effort.tolist() if out.command.effort is not None else [0.0, 0.0],
                "ref": ref_abs[k + 1, :2].tolist(),
                "prediction": np.vstack([p, pred[-1:]]).tolist(),
                "predicted": out.prediction is not None,
                "faults": fault_names(int(out.fault)),
                "seq": self.hand.seq,
                "held": self.hand.held,
                "controller": name,
                "misses": world.overruns,
            }
            self.frame = frame
            self.publish(frame)

        if self.live is not None:
            on_tick = self.live.watch(episode, on_tick)
        log = run_loop(episode.world, episode.tick, episode.n_max, termination, on_tick=on_tick)
        if self._abort is not None:
            self._notify(
                {
                    "type": "status",
                    "level": "warn",
                    "text": "trial aborted (nothing written)"
                    if self._abort == "aborted"
                    else "the hand left for too long: trial aborted (nothing written)",
                }
            )
            return None
        trial = episode.finish(
            log, {"deadline_misses": int(world.overruns), "mean_tick_seconds": float(np.mean(log.compute))}
        )
        return self._save(trial)

    def _save(self, trial: Trial) -> TrialResult:
        folder = self.config.folder
        if (folder / MANIFEST_NAME).is_file():
            append_to_dataset([trial], folder)
        else:
            write_dataset(
                [trial], folder, self.config.dataset_id, f"played in a browser by {self.config.user} (coassist play)"
            )
        # the trial is in the dataset: it counts from here whatever follows (an MCAP that failed once said "the trial
        # failed", and the protocol's next trial repeated this one)
        result = score_trial(trial, manifest_files(folder)[-1], len(self.results))
        self.results.append(result)
        if self.config.mcap:
            from coassist.data.run_pair import LIVE_START
            from coassist.data.trial_mcap import write_trial_mcap

            # stamped as the live view stamped the run (--foxglove), as drive's and ros2's MCAPs are; else from 0;
            # its /alpha the trial's own, tick by tick (the arbitration's online α too)
            mcap = (folder / result.file).with_suffix(".mcap")
            try:
                write_trial_mcap(trial, mcap, start_ns=trial.meta.extra.get(LIVE_START, 0))
            except (OSError, ValueError, ImportError) as exc:
                self._notify(
                    {"type": "status", "level": "warn", "text": f"trial {result.file} written, its MCAP not: {exc}"}
                )
        return result


def score_trial(trial: Trial, file: str, index: int) -> TrialResult:
    """f_RMS (eq. 5.9) and σ (eq. 5.10–5.11) of a trial, with how it ended."""
    extra = trial.meta.extra
    target = np.asarray(extra["target"], dtype=float)
    eps = float(extra.get("arrive_radius", 0.025))
    sigma = precision_sigma(trial.pose, target, trial.meta.dt, epsilon=eps, tau=SIGMA_TAU)
    return TrialResult(
        file=file,
        index=index,
        task=trial.meta.task,
        controller=FORMER_NAMES.get(name, name)
        if isinstance(name := extra.get("controller_name"), str)
        else trial.meta.controller,
        f_rms=f_rms(trial.wrench),
        sigma=None if math.isnan(sigma) else float(sigma),
        ended=str(extra.get("ended", "")),
        n_ticks=trial.n_samples,
        deadline_misses=int(extra.get("deadline_misses", 0)),
    )
