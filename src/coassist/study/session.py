"""One participant's trials on ``coassist play``'s machinery: the page, blinded, or a simulated hand.

:class:`StudySession` is a :class:`~coassist.play.session.PlaySession` whose trials are the
study's steps instead of the person's picks: the runner (:mod:`coassist.study.runner`)
hands it one :class:`TrialSetup` at a time, the page shows the step and its Start button
(or a simulated participant starts it at once), the trial runs through play's own loop
(the page's point-mass world) or ``coassist drive``'s (the MuJoCo UR5, a real arm), and
the trial comes back to the runner, which writes it into the study folder.

Blinding: every message to a page passes :meth:`StudySession.for_page`, which replaces a
controller by the condition's label (A, B, C…) and leaves out what could name it (the
controllers offered, the intent model, the preset, the folder, the per-controller means).
The page's ``start`` may only name the label of the step it is shown.

The page also gets the study's own messages: ``{"type": "step", ...}`` (what comes next:
a trial, a questionnaire with its items, a rest with its length, the end) and answers
with ``answers`` and ``next`` (:mod:`coassist.play.protocol`).
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from coassist.data import Trial, TrialMeta
from coassist.errors import CoassistError
from coassist.play.session import PlayConfig, PlaySession, TrialResult, arm_frame, score_trial
from coassist.robot.worlds import WORLDS
from coassist.scenario.tasks import Task, task_for_seed

__all__ = ["StudySession", "TrialSetup"]


@dataclass(frozen=True)
class TrialSetup:
    """One trial of the study: what the runner asks the session to run.

    step : its number in the participant's steps.  page_name : how the page names the condition
    (its label, or "go" where nothing is blinded).  controller : the controller kind.
    intent : "nominal" or a model folder.  task : the trial's task (seed ``seed``).
    meta : study fields added to the trial's ``meta.extra`` (condition, label, block, …).
    operator : the simulated operator's index (None: a person, or the page's pointer).
    way : the way round the obstacle the participant is asked to take (+1 left, −1 right; 0 their own choice): an
    arm world's simulated operator takes it (``DriveConfig.way``), and the trial records it.
    """

    step: int
    page_name: str
    controller: str
    intent: str
    task: Task
    seed: int
    meta: dict[str, Any] = field(default_factory=dict)
    operator: int | None = None
    hand: Any = None  # the page world's simulated hand (OperatorHand); None: the page's pointer
    way: int = 0


#: What a study frame carries to the page: what the page draws and times (the tool, the hand's force, the plan's
#: point, the fault flags, the hand's state, the frame's place in the trial). Everything else a frame carries (the
#: robot's effort, whether a prediction ran, the prediction's rows) tells the conditions apart (:meth:`for_page`).
BLIND_FRAME_KEYS = (
    "type",
    "index",
    "k",
    "t",
    "x",
    "y",
    "vx",
    "vy",
    "fh",
    "ref",
    "faults",
    "seq",
    "held",
    "misses",
    "world",
)


class _Aborted(CoassistError, RuntimeError):
    """The page aborted an arm world's trial (raised from drive's on_tick to end its loop)."""


class StudySession(PlaySession):
    """The study's trials on play's machinery (module docstring).

    config : the play session's (user = the participant's id; controllers = every kind the study uses).
    world : "play", "mujoco", "ur" or "franka".  secrets : every string a page must never receive
    (condition names, controller kinds, model paths and ids).  drive : DriveConfig options of the
    arm worlds (object, obstacle, preset, time_limit).  host : a real arm's address.
    confirm : asked before a real arm moves (as ``coassist drive``).  live : a
    :class:`~coassist.runtime.live.LiveFeed` that watches every trial (e.g. Foxglove; for the
    experimenter's screen: α and the prediction name the condition).
    """

    def __init__(
        self,
        config: PlayConfig,
        *,
        world: str = "play",
        secrets: tuple[str, ...] = (),
        drive: dict[str, Any] | None = None,
        host: str | None = None,
        confirm: Any = None,
        live: Any = None,
    ) -> None:
        super().__init__(config, live=live)
        self.world = world
        self.secrets = tuple(s for s in secrets if s)
        self.drive_options = dict(drive or {})
        self.robot_host, self.confirm = host, confirm
        self.setup: TrialSetup | None = None
        self.view: dict[str, Any] = {"kind": "wait", "text": "getting ready…"}
        self._sources: dict[str, Any] = {}
        self._realtimes: dict[str, Any] = {}
        self._page_hand = self.hand
        self._captured: Trial | None = None
        self._trial_over = threading.Event()
        self._may_start = False  # one Start per shown trial step (start_trial)
        self._reply = threading.Event()
        self._answer_check: Callable[[list[float]], Any] | None = None
        self._answer: Any = None
        self._proceed_ok: Callable[[], bool] | None = None

    # ------------------------------------------------------------------ PlaySession's hooks
    def _resume(self) -> None:
        """The study folder keeps the trials (coassist.study.folder), not a play folder."""

    def trial_seed(self, index: int) -> int:
        """The step's seed (the one its trial is recorded with), not the session's count: a resumed run draws
        the calibration probe's phases of each trial as the first run did."""
        return self.setup.seed if self.setup is not None else super().trial_seed(index)

    def next_task(self) -> Task:
        if self.setup is not None:
            return self.setup.task
        return task_for_seed(self.config.tasks[0], self.config.seed, motion_time=self.config.motion_time)

    def page_choices(self) -> tuple[str, ...]:
        return (self.setup.page_name,) if self.setup is not None else ()

    def start_trial(self, controller: str) -> bool:
        """Start the shown step's trial: once per showing. A second press, or a Start that arrives after
        the trial ended and before the runner shows the next step, would run a trial no step waits for
        (and write nothing); it is refused like a Start while running."""
        with self._lock:
            if not self._may_start or self.running:
                return False
            self._may_start = False
        started = False
        try:
            started = super().start_trial(controller)
        finally:
            if not started:  # refused or raised (a name that is not the step's): the step still waits
                with self._lock:
                    self._may_start = True
        return started

    def controller(self, name: str):
        if self.setup is None or name != self.setup.page_name:
            raise ValueError(
                f"the page asked for {name!r}; the step shown is {self.setup.page_name if self.setup else None!r}"
            )
        return self._controllers[self.setup.controller]

    def for_page(self, message: dict[str, Any]) -> dict[str, Any]:
        """The blinded message (module docstring)."""
        kind = message.get("type")
        name = self.setup.page_name if self.setup is not None else None
        if kind == "frame":
            # what the page draws, the controller as its label; not the robot's effort (zero under MG), whether a
            # prediction ran, nor its rows (the plan's under two conditions, a source's under the third): each told
            # a condition apart to anyone who opened the page's developer tools
            out = {k: message[k] for k in BLIND_FRAME_KEYS if k in message}
            out.update(controller=name, prediction=[])
            return out
        out = dict(message)
        if kind == "init":
            out.update(
                controllers=list(self.page_choices()),
                controller=name,
                model=None,
                preset=None,
                folder="",
                summary={},
                results=[self._blind_result(r) for r in message.get("results", [])],
                study=self.view,
            )
        elif kind == "started":
            out["controller"] = name
        elif kind == "result":
            out.update(result=self._blind_result(message["result"]), summary={})
        elif kind == "status":
            out["text"] = self._scrub(str(message.get("text", "")))
        return out

    def _blind_result(self, result: dict[str, Any]) -> dict[str, Any]:
        return dict(result, controller=self.setup.page_name if self.setup is not None else "", file="")

    def _scrub(self, text: str) -> str:
        for s in sorted(self.secrets, key=len, reverse=True):
            text = text.replace(s, "(blinded)")
        return text

    def _run(self, task: Task, name: str, controller) -> None:
        try:
            super()._run(task, name, controller)
        finally:
            self._trial_over.set()

    def _save(self, trial: Trial) -> TrialResult:
        """The trial goes back to the runner (which writes it), with the study's fields and seed."""
        setup = self.setup
        assert setup is not None  # a trial runs only for a setup
        extra = dict(trial.meta.extra)
        extra.update(setup.meta, controller_name=setup.page_name, trial_index=setup.step)
        trial = dataclasses.replace(
            trial,
            meta=TrialMeta(**{**trial.meta.to_dict(), "user": self.config.user, "seed": setup.seed, "extra": extra}),
        )
        self._captured = trial
        result = score_trial(trial, "", len(self.results))
        self.results.append(result)
        return result

    def _run_trial(self, task: Task, name: str, controller) -> TrialResult | None:
        if self.world == "play":
            return super()._run_trial(task, name, controller)
        return self._run_drive(name)

    # ------------------------------------------------------------------ the arm worlds (coassist drive)
    def _run_drive(self, name: str) -> TrialResult | None:
        from coassist.robot.drive import TASK_HEIGHT, DriveConfig, drive

        setup = self.setup
        assert setup is not None
        simulated = setup.operator is not None
        config = DriveConfig(
            world=self.world,
            controller=setup.controller,
            task=setup.task.kind,
            seed=setup.seed,
            intent=setup.intent,
            user=setup.operator or 0,
            # the person at the handle is the participant, as on the page (play): whose calibration a person model
            # uses and what every source is told (a simulated participant's arm and paths stay operator `user`'s)
            person=self.config.user,
            way=setup.way,
            realtime_intent=False if simulated else None,
            **self.drive_options,
        )
        dt = config.dt
        every = max(1, int(round(config.rate_hz / 125.0)))

        def on_tick(k: int, state, out) -> None:
            if self._abort is not None and WORLDS[self.world].simulated:
                # a simulated arm stops where it is; a real arm's run is never cut from the page (its own
                # stop and coassist drive's safety layer end it)
                raise _Aborted(self._abort)
            if k % every:
                return
            frame = arm_frame(
                out,
                index=setup.step,
                k=k,
                dt=dt,
                controller=name,
                world=self.world,
                seq=self.hand.seq,
                held=bool(getattr(self.hand, "held", False)),
            )
            self.frame = frame
            self.publish(frame)

        world = None
        if self.world == "mujoco":
            from coassist.robot.mujoco_world import MujocoUR5World

            task = setup.task
            world = MujocoUR5World(
                config.object,
                control_dt=dt,
                start=(float(task.start[0]), float(task.start[1]), TASK_HEIGHT),
                seed=config.seed,
                view=False,
                realtime=self.config.paced,
            )
        try:
            trial = drive(
                config,
                world=world,
                host=self.robot_host,
                confirm=self.confirm,
                on_tick=on_tick,
                operator=None if simulated else self.hand,
                live=self.live,
            )
        except _Aborted:
            self.publish({"type": "status", "level": "warn", "text": "trial aborted (nothing written)"})
            return None
        finally:
            if world is not None:
                world.close()
        return self._save(trial)

    # ------------------------------------------------------------------ the runner's side
    def _source(self, intent: str):
        """The intent source (and, paced, its real-time predictor) of ``intent``, loaded once."""
        from coassist.interfaces import FEATURES
        from coassist.scenario.intent_registry import load_intent_source

        if intent not in self._sources:
            H = int(self.preset.game.horizon)
            source = load_intent_source(intent, horizon=max(H, 2))
            model = getattr(source, "model", None)
            realtime = None
            if model is not None:
                model.check_compatible(FEATURES, float(self.preset.impedance.dt), what="coassist study")
                if self.config.paced and self.world == "play":
                    from coassist.intent.realtime import RealtimeConfig, RealtimePredictor

                    realtime = RealtimePredictor(model, RealtimeConfig(backend="process"))
            self._sources[intent], self._realtimes[intent] = source, realtime
        return self._sources[intent], self._realtimes[intent]

    def show(self, view: dict[str, Any]) -> None:
        """Tell the page what comes next (a ``step`` message; never a condition's name)."""
        self.view = view
        self.publish({"type": "step", **view})

    def run(self, setup: TrialSetup, *, wait_for_page: bool) -> Trial:
        """Run ``setup``'s trial and return it, ``meta.extra["attempts"]`` the times it was started.
        ``wait_for_page``: the page's Start begins it (a trial the person aborts, or whose hand left, is
        shown again); else it starts at once."""
        if self.world == "play":
            for other in [i for i in self._realtimes if i != setup.intent]:  # one model worker process at a time
                rt = self._realtimes.pop(other)
                self._sources.pop(other, None)
                if rt is not None:
                    rt.close()
            self.source, self._realtime = self._source(setup.intent)
        self.setup = setup
        self.hand = setup.hand if setup.hand is not None else self._page_hand
        self.current = None
        attempts = 0
        while True:
            attempts += 1
            self._captured = None
            self._trial_over.clear()
            with self._lock:
                self._may_start = True
            if wait_for_page:
                self.show({**self.view, "scene": self.scene()})
            elif not self.start_trial(setup.page_name):
                raise RuntimeError("a trial is already running")
            self._trial_over.wait()
            if self._captured is not None:
                # the times this step's trial was started, this one included: a trial the person aborted, or whose
                # hand left, is shown again, and the report counts those repeated (a condition people abort is news)
                trial = self._captured
                extra = {**trial.meta.extra, "attempts": attempts}
                return dataclasses.replace(trial, meta=dataclasses.replace(trial.meta, extra=extra))
            if not wait_for_page:
                raise RuntimeError("the simulated trial ended without a result (see the session's status)")

    def ask(self, view: dict[str, Any], check: Callable[[list[float]], Any]) -> Any:
        """Show a questionnaire and wait for answers that pass ``check`` (its result is returned)."""
        self._reply.clear()
        self._answer_check, self._answer = check, None
        self.show(view)
        self._reply.wait()
        self._answer_check = None
        return self._answer

    def answer(self, step: int, values: list[float]) -> bool:
        check = self._answer_check
        if check is None or step != self.view.get("step"):
            return False
        try:
            self._answer = check(values)
        except ValueError as exc:
            self.publish({"type": "status", "level": "warn", "text": f"answers not taken: {exc}"})
            return True
        self._reply.set()
        return True

    def rest(self, view: dict[str, Any], ready: Callable[[], bool], *, wait_for_page: bool, seconds: float) -> None:
        """Show a rest; return once ``seconds`` passed, ``ready()`` holds and (page) the person went on."""
        t_end = time.monotonic() + seconds
        self._reply.clear()
        self._proceed_ok = lambda: time.monotonic() >= t_end and ready()
        self.show(view)
        if wait_for_page:
            while not self._reply.wait(0.2):
                if self._proceed_ok() and self.view.get("ready") is not True:
                    self.show({**view, "ready": True})
        else:
            while not self._proceed_ok():
                time.sleep(0.05)
        self._proceed_ok = None

    def proceed(self, step: int) -> bool:
        ok = self._proceed_ok
        if ok is None or step != self.view.get("step") or not ok():
            return False
        self._reply.set()
        return True

    def close(self) -> None:
        super().close()
        for rt in self._realtimes.values():
            if rt is not None:
                rt.close()
        self._realtimes.clear()
