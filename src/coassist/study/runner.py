"""``coassist study run``: one participant's steps, in their recorded order, resumed where they stopped.

:class:`ParticipantRun` registers the participant (number and Latin-square row, in order
of arrival), fixes their steps at the first run (:func:`coassist.study.protocols.participant_steps`,
written to ``order.json``), and runs the steps not yet on record
(:class:`~coassist.study.folder.ParticipantFolder`), each committed as it finishes:

- ``trial``: through :class:`~coassist.study.session.StudySession`, on the page (the person
  presses Start; an aborted trial, or one whose hand left, is shown again) or with the
  simulated operator; written into its block's dataset, then its progress line;
- ``questionnaire``: on the page, or the simulated participant's answers;
- ``rest``: the page counts down and goes on once the person says so and the model the next
  trials need is ready; a simulated participant does not rest (it only waits for the model);
- ``train``: started in the background (:class:`~coassist.study.training.BackgroundTraining`);
  a trial that needs the model waits for it, a trial that takes "the newest online model"
  never does; an online update whose predecessor is still training is deferred (the next
  one trains on every trial so far);
- ``check``: Algorithm 4.1's stop criterion on the in-loop e_RMS (eq. 4.12–4.13);
- ``freeze``: the newest online model becomes the ``online`` condition;
- ``fit``: a person model fitted from the calibration block (or refitted from an iterative
  round's trials) in the background worker (:mod:`coassist.study.calibration`; seconds) while
  the page says to wait; its line records what it was fitted from, the arm and the SHA-256 of
  each task's model, which every trial that uses it checks. A calibration that fails is
  recorded with its reason, the block is put into the participant's order again after it, and
  the run stops with one line (:class:`~coassist.study.calibration.CalibrationFailed`): the same
  command runs the block again.

A kill loses at most the step in progress; a background training that was cut off is
started again when its model is next needed (training is deterministic: same model), a fit
that was cut off is fitted again when the run resumes (the same model).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from coassist.data import append_to_dataset, read_dataset, write_dataset
from coassist.data.datasets import MANIFEST_NAME, manifest_files
from coassist.play.session import PlayConfig
from coassist.scenario.path_model import ASKED_WAY, WAY_NAMES
from coassist.scenario.tasks import task_for_seed
from coassist.study.calibration import (
    CalibrationFailed,
    FitJob,
    fit_job,
    lead_lines,
    model_hashes,
    person_model_folder,
)
from coassist.study.folder import (
    ParticipantFolder,
    StudyFolder,
    StudyFolderError,
    file_sha256,
    step_key,
    trial_record,
    utc_now,
)
from coassist.study.plan import is_real_arm
from coassist.study.protocols import (
    CALIBRATION_BLOCK,
    MAX_CALIBRATION_ATTEMPTS,
    asked_steps,
    calibration_steps,
    participant_steps,
)
from coassist.study.questionnaires import form_for
from coassist.study.training import BackgroundTraining, TrainJob, model_ready, train_command

__all__ = ["ParticipantRun", "simulated_ids"]


def _simulated_arm(world: str, host: str | None) -> bool:
    """Whether the arm at ``host`` is a simulator a simulated participant can hold (``coassist ur-sim``)."""
    if world != "ur" or not host:
        return False
    from coassist.robot.ur_sim_world import is_simulator

    return is_simulator(host)


def simulated_ids(n: int) -> list[str]:
    """The ids of ``n`` simulated participants: S01, S02, …"""
    return [f"S{i:02d}" for i in range(1, n + 1)]


class ParticipantRun:
    """One participant's run (module docstring); use as a context manager, then :meth:`run`.

    study : the study folder.  participant : the pseudonymous id.  simulate : a simulated
    operator stands in (no page needed).  page : serve the page (host, port, token) — a person,
    or a browser automation moving the pointer along the simulated operator's path.
    realtime : pace a simulated participant's trials to the wall clock (a person's pace).
    host : a real arm's address.  confirm : asked before a real arm moves.  say : progress lines.
    live : a :class:`~coassist.runtime.live.LiveFeed` that watches every trial (``--foxglove``).
    """

    def __init__(
        self,
        study: StudyFolder,
        participant: str,
        *,
        simulate: bool = False,
        page: tuple[str, int, str | None] | None = None,
        realtime: bool = False,
        host: str | None = None,
        confirm: Any = None,
        say: Callable[[str], None] | None = None,
        live: Any = None,
    ) -> None:
        self.study = study
        self.live = live
        self.plan = study.plan()
        if page is None and not simulate:
            raise StudyFolderError("a person takes part through the page: run without --no-page (or --simulate)")
        if is_real_arm(self.plan.world) and simulate and not _simulated_arm(self.plan.world, host):
            raise StudyFolderError(
                f"--simulate: the {self.plan.world} world is a real arm; rehearse on mujoco or play"
                + (", or against coassist ur-sim (--robot-host its address)" if self.plan.world == "ur" else "")
            )
        self.id = participant
        new = participant not in study.participants()
        if new:
            self._check_person_models()  # before the participant is registered: a refusal must not lock the plan
        self.simulate, self.page, self.realtime = simulate, page, realtime
        self.host, self.confirm = host, confirm
        self.say = say or (lambda line: None)
        self._page_sock: Any = None
        if page is not None:  # the page's port too: one taken registered the participant and locked the plan
            from coassist.play.server import bind_page_socket

            self._page_sock = bind_page_socket(page[0], page[1])
        try:
            self.record = study.register(participant, simulated=simulate)  # the table cross-checked first
        except BaseException:
            self._close_page_socket()
            raise
        if new and self.record["number"] > self.plan.participants:
            rows = len(study.record.get("latin_square") or ())
            self.say(
                f"warning: {participant} is participant {self.record['number']} of {self.plan.participants} planned"
                + (
                    f" (row {self.record['row'] % rows} of the Latin square's {rows}): the order of conditions "
                    f"stays balanced only if the participants who finish fill whole squares of {rows} rows"
                    if rows > 1 and self.plan.protocol != "iterative"
                    else ""
                )
            )
        self.folder: ParticipantFolder = study.participant(participant)
        self.session: Any = None
        self.server: Any = None
        self.training = BackgroundTraining()
        self._lock: Any = None

    def _check_person_models(self) -> None:
        """StudyFolderError in one line where a condition names a person-model folder (``coassist calibrate``) that
        holds no calibration of this participant (in every world the person at the handle is the participant: the
        page's user, drive's ``person``): their trials of it would be refused partway through the study, or get the
        present estimate held while the report names the model."""
        from coassist.control.presets import CONTROL_PRESETS
        from coassist.scenario.assistance import check_person
        from coassist.scenario.intent_registry import intent_folder_kind, load_intent_source

        horizon = max(int(CONTROL_PRESETS[self.plan.trials.preset].game.horizon), 2)
        for i, c in enumerate(self.plan.conditions):
            if intent_folder_kind(c.intent) != "person-model":
                continue  # a network's, a named source or draws (a simulation's own people): no person to check
            try:
                check_person(
                    load_intent_source(c.intent, horizon=horizon),
                    self.id,
                    c.intent,
                    fix="calibrate them into it (coassist calibrate), or let the study calibrate each participant: "
                    'intent = "calibrated" and a [calibration] block (docs/study.md)',
                    by_default=False,  # another participant's own fit (its default is them) is not this one's
                )
            except (ValueError, OSError) as exc:
                raise StudyFolderError(f"condition[{i}] ({c.name}): {exc}") from None

    # ------------------------------------------------------------------ set up and tear down
    def __enter__(self) -> ParticipantRun:
        self._lock = self.folder.lock()
        self._lock.__enter__()
        try:
            self._open()
        except BaseException:
            self.close(interrupted=True)
            raise
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        self.close(interrupted=exc_type is not None)

    def _open(self) -> None:
        plan, rec = self.plan, self.record
        order = self.folder.order()
        if order is None:
            steps = participant_steps(plan, self.study.labels, rec["number"], rec["row"])
            order = {
                "participant": self.id,
                "number": rec["number"],
                "row": rec["row"],
                "operator": rec["number"] if self.simulate else None,
                "steps": steps,
            }
            self.folder.write_order(order)
        self.order = order
        self.steps: list[dict[str, Any]] = order["steps"]
        self.folder.audit(self.steps)  # the log, the order and the manifests agree (else one line, nothing run)
        if self.folder.reconcile(self.steps):
            self.say(f"{self.id}: recovered the last trial's record (the run stopped while writing it)")
        self.done = self.folder.progress()
        tp = plan.trials
        kinds = sorted({s["controller"] for s in self.steps if s["kind"] == "trial"})
        config = PlayConfig(
            user=self.id,
            out=self.folder.folder.parent,
            controllers=tuple(kinds),
            preset=tp.preset,
            tasks=tp.tasks,
            seed=0,
            motion_time=tp.motion_time,
            arrive_radius=tp.arrive_radius,
            dwell=tp.dwell,
            time_limit=tp.time_limit,
            paced=self.page is not None or self.realtime,
        )
        from coassist.control.presets import CONTROLLERS, FORMER_NAMES
        from coassist.study.session import StudySession

        secrets = (
            *CONTROLLERS,
            *FORMER_NAMES,
            *(c.name for c in plan.conditions),
            *(c.intent for c in plan.conditions if c.intent != "nominal"),  # a named source names the condition
            *plan.intent_folders(),
            "source",
            "transferred",
            "online",
            "offline",
            "calibrated",
            "calibration",
            "person-model",
            "person:",
            str(self.folder.folder / "models"),
        )
        drive = {
            "object": tp.object,
            "obstacle": tp.obstacle,
            "preset": tp.preset,
            "time_limit": tp.time_limit,
            # MuJoCo's simulated participant p is the page's: operator p of the plan's population and seed
            "population": plan.population,
            "population_seed": plan.seed,
        }
        self.session = StudySession(
            config, world=plan.world, secrets=secrets, drive=drive, host=self.host, confirm=self.confirm, live=self.live
        )
        if self.page is not None:
            from coassist.play.server import PlayServer

            host, port, token = self.page
            sock, self._page_sock = self._page_sock, None
            self.server = PlayServer(self.session, host=host, port=port, token=token, sock=sock).start()

    @property
    def url(self) -> str | None:
        return None if self.server is None else self.server.url

    def _close_page_socket(self) -> None:
        sock, self._page_sock = self._page_sock, None
        if sock is not None:
            sock.close()

    def close(self, *, interrupted: bool = False) -> None:
        try:
            self._close_page_socket()  # bound, never served (the run stopped before the page): let the port go
            self.training.close(interrupted=interrupted)
        finally:
            if self.server is not None:
                self.server.stop()  # closes the session too
                self.server = None
            elif self.session is not None:
                self.session.close()
            self.session = None
            if self._lock is not None:
                self._lock.__exit__(None, None, None)
                self._lock = None

    # ------------------------------------------------------------------ the steps
    @property
    def complete(self) -> bool:
        return len(self.done) == len(self.steps) or bool(self.done and self.done[-1].get("stop"))

    def run(self) -> bool:
        """Run the steps not yet on record; True once the participant has done all of them."""
        self._check_person_models()  # a participant resumed (one who finished is not run, and not refused)
        self._refuse_exhausted()
        if self.done:
            self.say(f"{self.id}: resuming at step {len(self.done) + 1} of {len(self.steps)}")
        else:
            estimate = self.study.estimate()
            for line in estimate.lines() if estimate is not None else ():
                self.say(f"{self.id}: {line}")
        while not self.complete:
            k = len(self.done)
            step = self.steps[k]
            record = getattr(self, f"_{step['kind']}")(k, step)
            record = {"step": k, "kind": step["kind"], "key": step_key(step), **record, "t": utc_now()}
            self.folder.append(record)
            self.done.append(record)
            self._refuse_exhausted()
            if step["kind"] == "fit" and record.get("redo"):
                self._show({"kind": "wait", "text": "Thank you. We need to repeat the first part: a moment…"})
                raise CalibrationFailed(
                    f"the calibration failed: {record['reason']}; recorded, and the block is run again "
                    f"({record['redo']}) when the same command continues"
                )
        for name in self._train_jobs():  # every model this participant's study trains, finished
            self._ensure_model(name)
        self._show({"kind": "done", "text": "Thank you: the session is over."})
        return True

    def _refuse_exhausted(self) -> None:
        """One line, nothing run, once the participant's calibration has failed in every attempt there are seeds
        for (:data:`~coassist.study.protocols.MAX_CALIBRATION_ATTEMPTS`): another would draw the next participant's."""
        last = self.done[-1] if self.done else {}
        if last.get("kind") == "fit" and last.get("exhausted"):
            raise CalibrationFailed(
                f"the calibration failed in all {MAX_CALIBRATION_ATTEMPTS} attempts (the last: {last.get('reason')}); "
                "no seeds are left for another: this participant's session ends here (the report counts them "
                "incomplete)"
            )

    def _view(self, k: int, step: dict[str, Any], **more: Any) -> dict[str, Any]:
        return {
            "step": k,
            "of": len(self.steps),
            "kind": step["kind"],
            "label": step.get("label"),
            "practice": bool(step.get("practice", False)),
            **more,
        }

    def _show(self, view: dict[str, Any]) -> None:
        if self.session is not None:
            self.session.show(view)

    # trial ------------------------------------------------------------------------------------
    def _trial(self, k: int, step: dict[str, Any]) -> dict[str, Any]:
        from coassist.runtime.episode import episode_ticks
        from coassist.scenario.operator import asked_to_go
        from coassist.study.participants import OperatorHand, simulated_profile
        from coassist.study.session import TrialSetup

        plan = self.plan
        tp = plan.trials
        t0 = time.monotonic()
        intent, model_name, model_sha = self._intent(step["intent"], step["task"])  # a model training: waited for
        waited = time.monotonic() - t0
        task = task_for_seed(
            step["task"],
            step["seed"],
            obstacle=tp.obstacle,
            motion_time=tp.motion_time if plan.world == "play" else None,
        )
        hand = None
        operator = self.record["number"] if self.simulate else None
        way = int(step.get("way", 0))  # a calibration trial that asks for a way round
        if operator is not None and self.page is None and plan.world == "play":
            dt = float(self.session.preset.impedance.dt)
            hand = OperatorHand(
                task,
                step["seed"],
                asked_to_go(simulated_profile(operator, plan.seed, plan.population), way),
                dt,
                episode_ticks(task, dt, tp.time_limit) + 1,
            )
        page_name = step["label"] or "go"
        meta = {
            "study": plan.name,
            "study_participant": self.id,
            "study_step": k,
            "study_block": step["block"],
            "study_condition": step["condition"],
            "study_label": step["label"],
            "study_position": step["position"],
            "study_practice": step["practice"],
            "study_model": model_name,
            # the person model's file the trial ran with: a trial recovered after a kill rebuilds its line from it
            **({"study_model_sha256": model_sha} if model_sha is not None else {}),
            "study_operator": None
            if operator is None
            else simulated_profile(operator, plan.seed, plan.population).name,
            **({ASKED_WAY: way} if way else {}),
        }
        setup = TrialSetup(
            step=k,
            page_name=page_name,
            controller=step["controller"],
            intent=intent,
            task=task,
            seed=step["seed"],
            meta=meta,
            operator=operator if self.page is None else None,
            hand=hand,
            way=way,
        )
        what = "practice trial" if step["practice"] else "trial"
        label = f"condition {step['label']}" if step["label"] else step["block"].replace("-", " ")
        text = f"{label}: {what} {step['index'] + 1} — press Start, then follow the plan, avoid the box and hold in the target"
        if step["condition"] == CALIBRATION_BLOCK:  # the page never names the probe; the person is told of pushes
            n = sum(1 for s in self.steps if s["kind"] == "trial" and s["block"] == step["block"])
            text = (
                f"warm-up trial {step['index'] + 1} of {n} — press Start, then follow the plan, avoid the box and hold "
                "in the target; you will feel small pushes now and then: carry on as you would"
            )
            if way:
                text = (
                    f"warm-up trial {step['index'] + 1} of {n} — this time go round the box on the "
                    f"{WAY_NAMES[way]} side of the path (seen along it); press Start, then follow the "
                    "plan and hold in the target; you will feel small pushes now and then"
                )
        self.session.view = self._view(k, step, text=text)
        trial = self.session.run(setup, wait_for_page=self.page is not None)
        folder = self.folder.block(step["block"])
        if (folder / MANIFEST_NAME).is_file():
            append_to_dataset([trial], folder)
        else:
            write_dataset(
                [trial],
                folder,
                f"{self.id}/{step['block']}",
                f"study {plan.name}, participant {self.id}, {step['block']} (coassist study)",
            )
        file = manifest_files(folder)[-1]
        self.say(
            f"{self.id}: step {k + 1}/{len(self.steps)} {step['block']} trial {step['index'] + 1}: "
            f"{trial.meta.extra.get('ended')}"
        )
        more: dict[str, Any] = {"model": model_name, "waited_for_model_s": round(waited, 3)}
        if model_sha is not None:
            more["model_sha256"] = model_sha
        rec = trial_record(k, step, file, trial.meta.to_dict(), sha256=file_sha256(folder / file), **more)
        return {key: v for key, v in rec.items() if key not in ("step", "kind", "key")}

    def _intent(self, ref: str, task: str) -> tuple[str, str | None, str | None]:
        """(intent source for the session, the study model's name or None, the SHA-256 of a person model's
        file or None) of a step's ``intent`` on ``task``."""
        if ref == "nominal":
            return "nominal", None, None
        if ref.startswith("model:"):
            name = ref.removeprefix("model:")
            if name == "online":
                name = self._frozen_online()
            self._ensure_model(name)
            return str(self._model_dir(name)), name, None
        if ref == "latest:online":
            newest = self._newest_online()
            if newest is None:
                assert self.plan.online is not None
                return self.plan.online.source_model, None, None
            return str(self._model_dir(newest)), newest, None
        if ref.startswith("person:"):
            return self._person_model(ref.removeprefix("person:"), task)
        return ref, None, None

    # person models ------------------------------------------------------------------------------
    def _person_fit(self, name: str) -> dict[str, Any]:
        """The progress line of the person model ``name`` (P0, P1, …), or of the newest before it that was
        fitted (an iterative refit that failed keeps its predecessor in the loop)."""
        number = int(name.removeprefix("P"))
        fits = {r["model"]: r for r in self.done if r["kind"] == "fit" and not r.get("failed")}
        for n in range(number, -1, -1):
            if f"P{n}" in fits:
                return fits[f"P{n}"]
        raise StudyFolderError(f"{self.id}: no person model was fitted before a trial that needs {name}")

    def _person_model(self, name: str, task: str) -> tuple[str, str, str]:
        rec = self._person_fit(name)
        model = rec["model"]
        if task not in rec["sha256"]:
            raise StudyFolderError(f"{self.id}: person model {model} knows no path of task {task!r}")
        folder = person_model_folder(self._model_dir(model), task)
        try:
            digest = model_hashes(self._model_dir(model), [task])[task]
        except OSError:
            digest = "missing"
        if digest != rec["sha256"][task]:
            raise StudyFolderError(
                f"{folder}: {'missing' if digest == 'missing' else 'changed'} after it was fitted (sha256 "
                f"{rec['sha256'][task][:12]} recorded in {self.folder.progress_file}); restore it from your backup of "
                "the study folder"
            )
        return str(folder), str(model), digest

    def _fit(self, k: int, step: dict[str, Any]) -> dict[str, Any]:
        data = list(step["data"])
        # an iterative refit builds on its base's recorded line (the audit holds the folder to it)
        base = None if step.get("base") is None else self._person_fit(step["base"])
        job = FitJob(root=str(self.folder.folder), data=tuple(data), model=step["model"], person=self.id, base_fit=base)
        key = f"fit:{step['index']}"
        self._show({"kind": "wait", "text": "the robot is getting to know how you move: a moment…"})
        self.training.submit(key, job, work=fit_job)
        try:
            record = self.training.wait(key)
        except CalibrationFailed as exc:
            return self._fit_failed(k, step, str(exc))
        arm = record["arm"]
        how = record["arm_note"] if record["arm_measured"] or record["base"] else f"assumed: {record['arm_note']}"
        self.say(
            f"{self.id}: person model {record['model']} fitted in {record['fit_seconds']:.1f} s from "
            + ", ".join(f"{len(v)} {t} trials" for t, v in record["demonstrations"].items())
            + f"; arm K = {arm['stiffness']:.0f} N/m, C = {arm['damping']:.1f} N·s/m ({how})"
            # whether the model leads them (its twin check): a participant turned away gets the present estimate held
            + "".join(f"; {task}: {line}" for task, line in lead_lines(record).items())
        )
        out = {"attempt": step["attempt"], **record}
        asks = self._asks(step, record)
        if asks:
            more = asked_steps(self.plan, self.record["number"], int(step["attempt"]), step["data"][0], asks)
            self.steps = self.folder.insert_steps(k, more)
            self.order["steps"] = self.steps
            self.say(
                f"{self.id}: asking for "
                + ", ".join(f"{n} more {task} trial(s) going {WAY_NAMES[way]}" for task, way, n in asks)
                + " (a way shown too seldom), then fitting again"
            )
            out["asks"] = [list(a) for a in asks]
        return out

    def _asks(self, step: dict[str, Any], record: dict[str, Any]) -> list[tuple[str, int, int]]:
        """What the calibration asks for after the fit ``record`` of ``step`` (``[calibration] asked``): per task, the
        way(s) its paths show too seldom (:func:`~coassist.experiments.person_calibration.ways_to_ask`) within the
        plan's budget; none after an iterative refit or a fit that already followed an asking."""
        from coassist.experiments.person_calibration import ways_to_ask

        cal = self.plan.calibration
        if cal is None or not cal.asked or step.get("base") is not None or step.get("asked"):
            return []
        room, asks = cal.asked, []
        for task in record["tasks"]:
            for way, n in ways_to_ask(np.asarray(record["paths"][task]["sides"]), room):
                asks.append((task, way, n))
                room -= n
        return asks

    def _fit_failed(self, k: int, step: dict[str, Any], reason: str) -> dict[str, Any]:
        """Record a failed fit; a calibration's is run again (its block inserted after this step)."""
        out: dict[str, Any] = {"model": step["model"], "attempt": step["attempt"], "failed": True, "reason": reason}
        if step.get("base") is not None:  # an iterative refit: the rounds go on with its predecessor
            self.say(f"{self.id}: person model {step['model']} not refitted ({reason}); the last one stays")
            return out
        if int(step["attempt"]) >= MAX_CALIBRATION_ATTEMPTS:  # no seeds left for another (protocols)
            return {**out, "exhausted": True}
        redo = calibration_steps(self.plan, self.record["number"], int(step["attempt"]) + 1)
        self.steps = self.folder.insert_steps(k, redo)
        self.order["steps"] = self.steps
        return {**out, "redo": redo[0]["block"]}

    # models -------------------------------------------------------------------------------------
    def _model_dir(self, name: str) -> Path:
        return self.folder.folder / "models" / name

    def _train_jobs(self) -> list[str]:
        """The models of the train steps on record (started or done)."""
        return [
            self.steps[i]["model"] for i, r in enumerate(self.done) if r["kind"] == "train" and not r.get("deferred")
        ]

    def _job(self, name: str) -> TrainJob:
        k = next(i for i, s in enumerate(self.steps) if s["kind"] == "train" and s["model"] == name)
        step = self.steps[k]
        rec = self.done[k] if k < len(self.done) else None
        init = rec["init"] if rec is not None else self._init(step)
        data = rec["data"] if rec is not None else self._data(step["data"])
        assert self.plan.training is not None  # plans that train have [training]
        return TrainJob(data=tuple(data), out=str(self._model_dir(name)), init=init, training=self.plan.training)

    def _data(self, blocks: list[str]) -> tuple[str, ...]:
        """What a train step trains on: the blocks' folders, or, for the online blocks that still grow while a
        model trains, their trial files as they are now (so the job sees exactly these)."""
        out: list[str] = []
        for b in blocks:
            folder = self.folder.block(b)
            if b == "adaptation":
                out += [str(folder / f) for f in manifest_files(folder)]
            else:
                out.append(str(folder))
        return tuple(out)

    def _init(self, step: dict[str, Any]) -> str:
        init = step["init"]
        if init.startswith("resume:model:"):
            return f"resume:{self._model_dir(init.removeprefix('resume:model:'))}"
        if init == "online":  # from the newest online model, or the source
            assert self.plan.online is not None
            prev = self._newest_online()
            return f"transfer:{self._model_dir(prev) if prev else self.plan.online.source_model}"
        return init

    def _ensure_model(self, name: str) -> None:
        """Wait for the model ``name`` (started again if its training was cut off by a stop)."""
        if model_ready(self._model_dir(name)) and not self.training.running(name):
            return
        if not self.training.has(name):
            self.training.submit(name, self._job(name))
        if self.training.running(name):
            self._show({"kind": "wait", "text": "the robot is learning from your trials: a moment…"})
            self.say(f"{self.id}: waiting for model {name}")
        self.training.wait(name)

    def _online_models(self) -> list[str]:
        return [s["model"] for s in self.steps if s["kind"] == "train" and s["model"].startswith("online-")]

    def _newest_online(self) -> str | None:
        ready = [n for n in self._online_models() if model_ready(self._model_dir(n)) and not self.training.running(n)]
        return ready[-1] if ready else None

    def _frozen_online(self) -> str:
        for r in self.done:
            if r["kind"] == "freeze":
                return str(r["model_from"])
        raise StudyFolderError("the online condition is used before the online model was frozen")

    def _train(self, k: int, step: dict[str, Any]) -> dict[str, Any]:
        name = step["model"]
        if step["init"] == "online" and self.training.busy(self._online_models()):
            return {"model": name, "deferred": True}  # the loop never waits: the next update takes these trials too
        assert self.plan.training is not None  # plans that train have [training]
        job = TrainJob(
            data=self._data(step["data"]),
            out=str(self._model_dir(name)),
            init=self._init(step),
            training=self.plan.training,
        )
        ready = model_ready(job.out)
        if not ready:
            self.training.submit(name, job)
            self.say(f"{self.id}: training {name} in the background ({job.init})")
        if step.get("wait"):
            self._ensure_model(name)
        return {
            "model": name,
            "init": job.init,
            "data": list(job.data),
            "command": train_command(job),
            "ready_when_recorded": model_ready(job.out) and not self.training.running(name),
            "was_ready": ready,
        }

    def _freeze(self, k: int, step: dict[str, Any]) -> dict[str, Any]:
        for name in self._online_models():  # the last update, if one is still training
            if self.training.running(name):
                self.training.wait(name)
        # the last update started, trained again if a stop cut it off (a kill -9 while it trained): the run that was
        # not stopped froze it once it finished, and training is deterministic (the same model)
        started = [n for n in self._train_jobs() if n in self._online_models()]
        if started:
            self._ensure_model(started[-1])
        newest = self._newest_online()
        if newest is None:
            raise StudyFolderError("no online model was trained (every update failed?)")
        return {"model": step["model"], "model_from": newest}

    # questionnaire, rest, check --------------------------------------------------------------------
    def _questionnaire(self, k: int, step: dict[str, Any]) -> dict[str, Any]:
        form = form_for(self.plan.questionnaire)
        if self.page is None:
            from coassist.study.participants import simulated_answers, simulated_profile

            f, s = self._block_scores(step["block"])
            values = simulated_answers(
                form,
                f,
                s,
                simulated_profile(self.record["number"], self.plan.seed, self.plan.population),
                np.random.default_rng([self.plan.seed, self.record["number"], k]),
            )
            answers = form.check(values)
        else:
            what = f"condition {step['label']}" if step["label"] else step["block"].replace("-", " ")
            answers = self.session.ask(
                self._view(k, step, form=form.to_page(), text=f"About {what}: how was it?"), form.check
            )
        return {"block": step["block"], "condition": step["condition"], "label": step["label"], "answers": answers}

    def _block_scores(self, block: str) -> tuple[float, float | None]:
        from coassist.metrics import f_rms, precision_sigma

        trials = read_dataset(self.folder.block(block)).trials
        f = float(np.mean([f_rms(t.wrench) for t in trials]))
        sig = [
            precision_sigma(
                t.pose,
                np.asarray(t.meta.extra["target"], float),
                t.meta.dt,
                epsilon=float(t.meta.extra.get("arrive_radius", 0.025)),
            )
            for t in trials
        ]
        sig = [v for v in sig if math.isfinite(v)]
        return f, (float(np.mean(sig)) if sig else None)

    def _rest(self, k: int, step: dict[str, Any]) -> dict[str, Any]:
        t0 = time.monotonic()
        rest = self.plan.rest  # the plan's length, not the recorded step's (coassist study amend may change it)
        planned = rest.between_trials if step.get("why") == "between trials" else rest.between_conditions
        # a simulated participant rests only when paced to the wall clock (--realtime: the session's length rehearsed)
        seconds = float(planned) if self.page is not None or self.realtime else 0.0
        view = self._view(
            k,
            step,
            seconds=seconds,
            ready=False,
            text="Rest. The next part starts when you are ready (and the robot has learned).",
        )
        self.session.rest(view, lambda: not self.training.busy(), wait_for_page=self.page is not None, seconds=seconds)
        return {"rested_s": round(time.monotonic() - t0, 3)}

    def _check(self, k: int, step: dict[str, Any]) -> dict[str, Any]:
        from coassist.experiments.pipeline import in_loop_errors

        it = self.plan.iterative
        assert it is not None
        h = it.criterion_horizon
        rounds = {}
        for r in (step["round"] - 1, step["round"]):
            err = in_loop_errors(read_dataset(self.folder.block(f"round-{r}")).trials, horizons=(h,))
            rounds[r] = err[h]["e_rms"] if h in err else math.nan
        e_prev, e_now = rounds[step["round"] - 1], rounds[step["round"]]
        delta = abs(e_now - e_prev)
        computable = math.isfinite(delta)  # a round whose trials logged no prediction h long: not met, go on
        met = computable and bool(delta < it.tolerance)
        self.say(
            f"{self.id}: round {step['round']}: in-loop e_RMS {1e3 * e_now:.2f} mm (was {1e3 * e_prev:.2f}); "
            + (f"criterion {'met' if met else 'not met'}" if computable else f"criterion not computable at {h} samples")
        )
        return {
            "round": step["round"],
            "e_rms": e_now,
            "e_rms_before": e_prev,
            "delta": delta,
            "tolerance": it.tolerance,
            "criterion_horizon": h,
            "met": met,
            "stop": met and it.stop_at_criterion and step["round"] < it.rounds - 1,
        }
