"""The protocols as step lists: what one participant does, in order, fixed at their first run.

A step is a small JSON object (so the order is recorded in the study folder as it is, and a
resumed run follows the record, not a recomputation)::

    trial          {block, index, condition, label, position, controller, intent, task, seed, practice[, way]}
    questionnaire  {block, index, condition, label}      after a condition (or a round)
    rest           {block, index, seconds, why}           the participant rests (a model may train meanwhile)
    train          {block: "models", index, model, data, init, wait}   a model trained in a background process
    fit            {block: "models", index, model, data, base, attempt[, asked]}   a person model fitted (in the background)
    check          {block, index, round}                  Algorithm 4.1's stop criterion (eq. 4.13)
    freeze         {block: "models", index, model}        online: the last online model becomes a condition

``intent`` is ``"nominal"``, a model folder of the plan, ``"model:<name>"`` (a model this
participant's study trained, in ``models/<name>``; a trial that needs it waits for it),
``"latest:online"`` (the newest online model ready when the trial starts; it never waits) or
``"person:<name>"`` (a person model this participant's study fitted, in ``models/<name>``: P0
from the calibration block, P1, P2, … an iterative study's refits).

Calibration (any protocol with ``[calibration]``), before everything else: ``trials`` trials of
block ``calibration`` under ``manual-probe`` (the plan's tasks in turn), then the fit of P0
(``data`` the block, ``base`` None) and a rest. A condition whose ``intent`` is ``"calibrated"``
runs with ``person:P0``. A calibration that fails (:mod:`coassist.study.calibration`) is run
again: the runner inserts :func:`calibration_steps` of attempt a + 1 (block ``calibration-<a+1>``)
after the failed fit. With ``[calibration] asked`` > 0, a fit that shows a way round the obstacle in
fewer than three of a task's paths (but once at least) is followed by :func:`asked_steps`: trials of
block ``<block>-asked`` whose ``way`` (+1 left, −1 right) the page asks the participant to take, then
P0 fitted again from both blocks (the asked trials' paths join that way's, not its prior).

Protocols (thesis §5.2.3 and Algorithms 4.1 and 4.2):

- ``comparison``: conditions in the participant's row of the balanced Latin square
  (:mod:`coassist.study.design`); per condition ``practice`` practice trials, then
  ``per_condition`` measured trials, then the questionnaire, then a rest. Measured trial j
  follows ``tasks[j mod n]`` with seed ``base + j`` in every condition: the conditions meet
  the same paths and obstacles, paired.
- ``iterative``: round k collects ``trials_per_round`` with M_{k−1} in the loop (round 0 with
  the nominal plan, D_0 of eq. 4.7); from round 1 on, the stop criterion
  |e_RMS^k − e_RMS^{k−1}| < tol on the in-loop errors (eq. 4.12–4.13); then M_k trains on D_k
  (``scratch`` for M_0, ``resume:`` M_{k−1} after, eq. 4.11) while the participant rests.
- ``transfer``: the participant's ``trials`` with the source model in the loop (D_TL), the
  frozen-LSTM transfer trained on them (``transfer:`` source, eq. 4.14) while they rest, then
  a comparison of ``transferred`` against ``source``.
- ``online``: ``trials`` with the newest online model in the loop; after each, the FC head is
  updated in the background from the previous online model on the trials it has not seen
  (``transfer:`` previous, frozen LSTM); then the offline transfer from the source model on
  the same trials trains while they rest, and ``online`` (the last update) is compared with
  ``offline``.
- ``iterative`` with ``source = "calibrated"``: round k runs with ``person:P<k>``; after it,
  P_{k+1} is refitted from P0's calibration trials and rounds 0 … k (``base`` P0: its arm, the
  rounds ran without the probe), no network trained. ``transfer`` and ``online`` with
  ``compare_calibrated``: ``calibrated`` (``person:P0``) is a third condition of the comparison.

Seeds: participant number p gets ``base = 10⁶·seed + 10⁴·p``; measured comparison trial j
``base + j``, practice trial i ``base + 5000 + i``, iterative round k trial j
``base + k·trials_per_round + j``, collection trial j (transfer, online) ``base + 2000 + j``,
calibration trial j of attempt a ``base + 8000 + 100·(a − 1) + j``, its asked trial j ``… + 50 + j``.
"""

from __future__ import annotations

from typing import Any

from coassist.study.design import participant_order
from coassist.study.plan import CALIBRATED, CALIBRATION_TRIALS_MAX, Condition, StudyPlan

__all__ = [
    "ASKED_SEED_OFFSET",
    "MAX_CALIBRATION_ATTEMPTS",
    "CALIBRATION_BLOCK",
    "PROBE_CONTROLLER",
    "SEED_BAND",
    "asked_steps",
    "calibration_steps",
    "condition_names",
    "participant_steps",
    "person_ref",
    "trial_seed_base",
]

#: The block of the calibration trials (attempt a > 1: ``calibration-<a>``) and their controller.
CALIBRATION_BLOCK = "calibration"
PROBE_CONTROLLER = "manual-probe"
#: The person model the calibration block fits.
CALIBRATED_MODEL = "P0"
#: The seeds of an attempt's asked trials start this far past its calibration trials' (at most 10 of those).
ASKED_SEED_OFFSET = 50


def person_ref(model: str = CALIBRATED_MODEL) -> str:
    """A step's ``intent`` for the person model ``model`` of this participant."""
    return f"person:{model}"


def condition_names(plan: StudyPlan) -> list[str]:
    """The blinded conditions of the plan's protocol (those shown as A, B, C…), in the plan's order
    (the iterative protocol has rounds, not conditions)."""
    if plan.protocol == "comparison":
        return [c.name for c in plan.conditions]
    extra = plan.transfer or plan.online
    calibrated = [CALIBRATED] if extra is not None and extra.compare_calibrated else []
    return {"transfer": ["source", "transferred"], "online": ["online", "offline"]}.get(plan.protocol, []) + (
        calibrated
    )


#: How many seeds each participant's trials draw from, past their base (module docstring).
SEED_BAND = 10_000

#: The most calibration attempts a participant may make: attempt a's seeds start 8000 + 100 (a − 1) past their
#: base, its trials and asked trials at most CALIBRATION_TRIALS_MAX in all, the asked ones from ASKED_SEED_OFFSET on;
#: so the last attempt whose seeds all lie inside the participant's SEED_BAND (20: its last seed 9958 at most, a 21st's
#: the next participant's).
MAX_CALIBRATION_ATTEMPTS = (SEED_BAND - 8000 - ASKED_SEED_OFFSET - CALIBRATION_TRIALS_MAX) // 100 + 1


def trial_seed_base(plan: StudyPlan, number: int) -> int:
    """``base`` of participant ``number`` (module docstring)."""
    return 1_000_000 * plan.seed + SEED_BAND * int(number)


def participant_steps(plan: StudyPlan, labels: dict[str, str], number: int, row: int) -> list[dict[str, Any]]:
    """The participant's steps (module docstring): ``labels`` the blinding key, ``number`` their number
    (1, 2, … in order of arrival), ``row`` their row of the Latin square."""
    base = trial_seed_base(plan, number)
    steps: list[dict[str, Any]] = calibration_steps(plan, number, 1) if plan.calibration is not None else []
    if plan.calibration is not None and plan.rest.between_conditions > 0:
        _rest(steps, plan, "after the calibration")
    if plan.protocol == "comparison":
        conditions = [
            Condition(c.name, c.controller, person_ref()) if c.intent == CALIBRATED else c for c in plan.conditions
        ]
        _compare(steps, plan, conditions, labels, row, base)
    elif plan.protocol == "iterative":
        _iterative(steps, plan, base)
    elif plan.protocol == "transfer":
        assert plan.transfer is not None  # parse_plan sets it for this protocol
        t = plan.transfer
        _trials(steps, plan, "transfer-set", t.trials, t.controller, t.source_model, base + 2000)
        _add(
            steps,
            "train",
            block="models",
            model="transferred",
            data=["transfer-set"],
            init=f"transfer:{t.source_model}",
            wait=False,
        )
        _rest(steps, plan, "the transfer trains")
        conditions = [
            Condition("source", t.controller, t.source_model),
            Condition("transferred", t.controller, "model:transferred"),
        ]
        if t.compare_calibrated:
            conditions.append(Condition(CALIBRATED, t.controller, person_ref()))
        _compare(steps, plan, conditions, labels, row, base)
    else:
        assert plan.online is not None
        o = plan.online
        for j in range(o.trials):
            _add(
                steps,
                "trial",
                block="adaptation",
                index=j,
                condition="adaptation",
                label=None,
                position=0,
                controller=o.controller,
                intent="latest:online",
                task=_task(plan, j),
                seed=base + 2000 + j,
                practice=False,
            )
            if j < o.trials - 1:
                _add(
                    steps,
                    "train",
                    block="models",
                    model=f"online-{j + 1}",
                    data=["adaptation"],
                    init="online",
                    wait=False,
                )
        _add(steps, "freeze", block="models", model="online")
        _add(
            steps,
            "train",
            block="models",
            model="offline",
            data=["adaptation"],
            init=f"transfer:{o.source_model}",
            wait=False,
        )
        _rest(steps, plan, "the offline transfer trains")
        conditions = [
            Condition("online", o.controller, "model:online"),
            Condition("offline", o.controller, "model:offline"),
        ]
        if o.compare_calibrated:
            conditions.append(Condition(CALIBRATED, o.controller, person_ref()))
        _compare(steps, plan, conditions, labels, row, base)
    return steps


def calibration_steps(plan: StudyPlan, number: int, attempt: int) -> list[dict[str, Any]]:
    """The calibration block's steps, attempt ``attempt`` (1, 2, …; module docstring): its trials under the
    probe, then the fit of P0 from them."""
    assert plan.calibration is not None  # a plan with [calibration]
    if not 1 <= attempt <= MAX_CALIBRATION_ATTEMPTS:  # the runner stops before (its own line): a programming error
        raise ValueError(f"calibration attempt {attempt} is outside 1 … {MAX_CALIBRATION_ATTEMPTS}")
    block = CALIBRATION_BLOCK if attempt == 1 else f"{CALIBRATION_BLOCK}-{attempt}"
    steps: list[dict[str, Any]] = []
    seed0 = trial_seed_base(plan, number) + 8000 + 100 * (attempt - 1)
    _trials(
        steps, plan, block, plan.calibration.trials, PROBE_CONTROLLER, "nominal", seed0, condition=CALIBRATION_BLOCK
    )
    index = CALIBRATED_MODEL if attempt == 1 else f"{CALIBRATED_MODEL}-{attempt}"
    _add(steps, "fit", block="models", index=index, model=CALIBRATED_MODEL, data=[block], base=None, attempt=attempt)
    return steps


def asked_steps(
    plan: StudyPlan, number: int, attempt: int, block: str, asks: list[tuple[str, int, int]]
) -> list[dict[str, Any]]:
    """The trials a calibration asks for once its fit shows a way round too seldom (module docstring): for each
    (task, way, count) of ``asks``, ``count`` trials of block ``<block>-asked`` under the probe, the participant asked
    to go round the obstacle ``way`` (+1 left, −1 right: the step's ``way``); then P0 fitted again from ``block`` and
    them (``asked``: no second asking)."""
    seed0 = trial_seed_base(plan, number) + 8000 + 100 * (attempt - 1) + ASKED_SEED_OFFSET
    steps: list[dict[str, Any]] = []
    more = f"{block}-asked"
    for task, way, count in asks:
        for _ in range(count):
            j = len(steps)  # the trials so far: the fit comes after them
            _add(
                steps,
                "trial",
                block=more,
                index=j,
                condition=CALIBRATION_BLOCK,
                label=None,
                position=0,
                controller=PROBE_CONTROLLER,
                intent="nominal",
                task=task,
                seed=seed0 + j,
                practice=False,
                way=way,
            )
    index = f"{CALIBRATED_MODEL}-asked" if attempt == 1 else f"{CALIBRATED_MODEL}-{attempt}-asked"
    _add(
        steps,
        "fit",
        block="models",
        index=index,
        model=CALIBRATED_MODEL,
        data=[block, more],
        base=None,
        attempt=attempt,
        asked=True,
    )
    return steps


def _add(steps: list[dict[str, Any]], kind: str, **fields: Any) -> None:
    index = fields.pop("index", sum(1 for s in steps if s["kind"] == kind))
    steps.append({"kind": kind, "index": index, **fields})


def _task(plan: StudyPlan, j: int) -> str:
    return plan.trials.tasks[j % len(plan.trials.tasks)]


def _rest(steps: list[dict[str, Any]], plan: StudyPlan, why: str) -> None:
    _add(steps, "rest", block="rest", seconds=plan.rest.between_conditions, why=why)


def _trials(
    steps,
    plan: StudyPlan,
    block: str,
    n: int,
    controller: str,
    intent: str,
    seed0: int,
    *,
    condition: str | None = None,
    label: str | None = None,
    position: int = 0,
    rests: bool = True,
) -> None:
    """``n`` trials of ``block`` (seeds seed0 … seed0 + n − 1, the plan's tasks in turn); ``condition``
    None: the block's name. ``rests``: the plan's rest between consecutive trials."""
    for j in range(n):
        _add(
            steps,
            "trial",
            block=block,
            index=j,
            condition=block if condition is None else condition,
            label=label,
            position=position,
            controller=controller,
            intent=intent,
            task=_task(plan, j),
            seed=seed0 + j,
            practice=False,
        )
        if rests and j < n - 1 and plan.rest.between_trials > 0:
            _add(steps, "rest", block="rest", seconds=plan.rest.between_trials, why="between trials")


def _compare(steps, plan: StudyPlan, conditions: list[Condition], labels: dict[str, str], row: int, base: int) -> None:
    tp = plan.trials
    order = participant_order(row, len(conditions))
    practice = sum(1 for s in steps if s["kind"] == "trial" and s["practice"])
    for pos, ci in enumerate(order):
        c = conditions[ci]
        label = labels[c.name]
        for _ in range(tp.practice):
            _add(
                steps,
                "trial",
                block="practice",
                index=practice,
                condition=c.name,
                label=label,
                position=pos,
                controller=c.controller,
                intent=c.intent,
                task=_task(plan, practice),
                seed=base + 5000 + practice,
                practice=True,
            )
            practice += 1
        _trials(steps, plan, c.name, tp.per_condition, c.controller, c.intent, base, label=label, position=pos)
        if plan.questionnaire.asked:
            _add(steps, "questionnaire", block=c.name, index=pos, condition=c.name, label=label)
        if pos < len(order) - 1 and plan.rest.between_conditions > 0:
            _rest(steps, plan, "between conditions")


def _iterative(steps, plan: StudyPlan, base: int) -> None:
    it = plan.iterative
    assert it is not None
    if it.source == CALIBRATED:
        _iterative_person(steps, plan, base)
        return
    for k in range(it.rounds):
        block = f"round-{k}"
        intent = "nominal" if k == 0 else f"model:M{k - 1}"
        seed0 = base + k * it.trials_per_round
        _trials(steps, plan, block, it.trials_per_round, it.controller, intent, seed0, position=k, rests=False)
        _round_end(steps, plan, block, k)
        init = "scratch" if k == 0 else "resume:model:M" + str(k - 1)
        _add(steps, "train", block="models", model=f"M{k}", data=[block], init=init, wait=k == it.rounds - 1)
        if k < it.rounds - 1:
            _rest(steps, plan, f"M{k} trains")


def _round_end(steps, plan: StudyPlan, block: str, k: int) -> None:
    """Round k's questionnaire, then its stop check: the check may end the protocol, and the round it ends on is rated
    too (asked after the check, the converged round, the best model's, went unrated)."""
    if plan.questionnaire.asked:
        _add(steps, "questionnaire", block=block, index=k, condition=block, label=None)
    if k >= 1:
        _add(steps, "check", block=block, index=k, round=k)


def _iterative_person(steps, plan: StudyPlan, base: int) -> None:
    """The iterative protocol with the person model (module docstring): round k with P_k, P_{k+1} refitted."""
    it = plan.iterative
    assert it is not None
    for k in range(it.rounds):
        block = f"round-{k}"
        seed0 = base + k * it.trials_per_round
        _trials(
            steps, plan, block, it.trials_per_round, it.controller, person_ref(f"P{k}"), seed0, position=k, rests=False
        )
        _round_end(steps, plan, block, k)
        model = f"P{k + 1}"
        data = [f"round-{r}" for r in range(k + 1)]
        _add(steps, "fit", block="models", index=model, model=model, data=data, base=CALIBRATED_MODEL, attempt=1)
        if k < it.rounds - 1:
            _rest(steps, plan, f"{model} is fitted")
