"""A plan checked whole before anyone sits down: what every step will need, and what a session will take.

:func:`preflight` runs at ``coassist study init`` (and at ``study amend``), after the plan's
fields passed :func:`coassist.study.plan.parse_plan`. It refuses, in one
:class:`~coassist.study.plan.PlanError` line naming the field, every plan that would fail
only after a participant's trials:

- every intent source a condition names is built as the session builds it
  (:func:`coassist.scenario.intent_registry.load_intent_source`, the controller's horizon
  H): a named source, a calibration folder, a model folder (its sidecar and weights
  checked, its features and dt those of the loop, its horizon >= H, at most
  :data:`MAX_PARAMETERS` parameters);
- a model the study trains further on a participant's trials (``[transfer]`` and
  ``[online]`` ``source_model``, ``[training] preset`` of an iterative study) must learn a
  label a person's trials have: not ``intent`` (the simulated operator's true intent);
- an iterative study's stop criterion (eq. 4.13) at ``criterion_horizon`` samples must be
  computable on every round: at most the horizon of the predictions round 0 (the nominal
  plan, H rows) and the models (``window.horizon``) log;
- the study's own networks have at most :data:`MAX_PARAMETERS` parameters (counted on
  torch's meta device: nothing allocated), and every trial is long enough to give a
  training window (ticks >= history + horizon);
- a plan with ``[calibration]``: the participant's person model (``"calibrated"``) is built as
  the session builds it, with the controller's horizon; a calibration trial as planned lasts at
  least :data:`~coassist.scenario.arm_identification.MIN_TRIAL_S` (the arm is measured from
  trials that long: shorter ones would leave it assumed); an iterative study of the person
  model logs the controller's H predictions, which bounds ``criterion_horizon``;
- a participant's session (:class:`SessionEstimate`) takes at most :data:`MAX_SESSION_HOURS`.

The session estimate, shown before the first trial: participant 1's steps
(:func:`~coassist.study.protocols.participant_steps`), each

- trial: expected t_end + dwell (the task's planned motion, then the dwell in the target:
  a trial that goes as planned), at most its time limit (2 t_end + 10 s by default);
- questionnaire: :data:`SECONDS_PER_ITEM` per item (an assumption, not a measurement);
- rest: its length;
- fit (a person model): :data:`FIT_SECONDS`, waited for (measured: docs/study.md);
- training: windows × epochs × s per window, the last measured here by timing the plan's
  network (forward, backward and an Adam step on random batches of the plan's size, the
  median of :data:`TIMING_REPEATS`); the participant waits for what a model's training
  outlasts of the rest after it (the whole of the last iterative model's);

windows per model: Σ over its trials of ⌊(T − history − H_model)/train_stride⌋ + 1, T the
expected ticks, the held-out trials (``test_fraction``) left out. Memory: a trial's arrays
are 8 B × (3 + 6 d + H d + 2 n_joints) a tick ((d,) pose, velocity, wrench, reference and
both efforts, (H, d) prediction, time, fault and the game's α (none under IMP and MG: 8 B less),
joints and their speeds on an arm), the
loop's log as much again; training holds 16 B a parameter (weights, gradients, Adam's two
moments) and the trials' features.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field
from typing import Any

from coassist.config import CONTROL_PRESETS
from coassist.robot.worlds import WORLDS
from coassist.scenario import intent_registry
from coassist.scenario.assistance import check_person_tasks, check_person_world
from coassist.study.design import blinding_labels, latin_square_rows
from coassist.study.plan import CALIBRATED, PlanError, StudyPlan, TrainingPlan
from coassist.study.protocols import SEED_BAND, condition_names, participant_steps, trial_seed_base

__all__ = [
    "FIT_SECONDS",
    "MAX_PARAMETERS",
    "MAX_SESSION_HOURS",
    "SessionEstimate",
    "bytes_per_tick",
    "counterbalance_warning",
    "preflight",
    "training_windows",
]

#: The largest network a study trains (the thesis' is 1.4 million parameters): about 0.3 GB to train.
MAX_PARAMETERS = 20_000_000
#: The longest session one participant can sit (a plan beyond it is split into sessions).
MAX_SESSION_HOURS = 8.0
#: [s] per questionnaire item (reading, rating): an assumption of the estimate.
SECONDS_PER_ITEM = 10.0
#: Batches timed for the training estimate (after one warm-up).
TIMING_REPEATS = 3
#: [s] a person model's fit as the participant waits for it: the worker's start, reading the trials,
#: the arm and the paths (docs/study.md: 3.7–5.5 s of the worker's CPU for six trials, plus its start).
FIT_SECONDS = 8.0
#: The degrees of freedom a study's trials log (the x-y plane) and an arm's joints.
STUDY_DOF = 2
ARM_JOINTS = 6


@dataclass(frozen=True)
class SessionEstimate:
    """One participant's session, estimated (module docstring); seconds and bytes.

    expected_s : trials as planned, rests, questionnaires, waits for models.  max_s : every trial
    to its time limit.  n_trials : trials (practice included).  trials_s : of expected_s, the trials'.  training_s : every model's training
    (in the background).  wait_s : of it, what the participant waits.  trial_bytes : the largest
    trial's memory in the run's process (trial and loop log).  training_bytes : the largest training's.
    s_per_window : measured training time per window (None: the study trains nothing).
    """

    expected_s: float
    max_s: float
    n_trials: int
    trials_s: float = 0.0
    training_s: float = 0.0
    wait_s: float = 0.0
    trial_bytes: int = 0
    training_bytes: int = 0
    s_per_window: float | None = None
    models: dict[str, float] = field(default_factory=dict)
    #: what the plan allows but should not be run as it is (:func:`counterbalance_warning`), shown as "warning: …"
    warnings: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "warnings", tuple(self.warnings))  # a list as read back from study.json

    def lines(self) -> list[str]:
        """What ``study init`` and ``study run`` show before the first trial."""
        out = [
            f"a participant's session: about {_duration(self.expected_s)} ({self.n_trials} trials; at most "
            f"{_duration(self.max_s)} if every trial runs to its time limit)"
        ]
        if self.models:
            out.append(
                f"training: {len(self.models)} models, about {_duration(self.training_s)} in the background "
                f"({1e3 * (self.s_per_window or 0):.2f} ms a window, measured now); the participant waits about "
                f"{_duration(self.wait_s)} of it"
            )
        mem = f"memory: about {_mb(self.trial_bytes)} for a trial"
        if self.training_bytes:
            mem += f", {_mb(self.training_bytes)} for the largest training"
        out.append(mem)
        out.extend(f"warning: {w}" for w in self.warnings)
        return out

    def to_json(self) -> dict[str, Any]:
        return {
            "expected_s": round(self.expected_s, 1),
            "max_s": round(self.max_s, 1),
            "n_trials": self.n_trials,
            "trials_s": round(self.trials_s, 1),
            "training_s": round(self.training_s, 1),
            "wait_s": round(self.wait_s, 1),
            "trial_bytes": int(self.trial_bytes),
            "training_bytes": int(self.training_bytes),
            "s_per_window": self.s_per_window,
            "models": {k: round(v, 1) for k, v in self.models.items()},
            **({"warnings": list(self.warnings)} if self.warnings else {}),
        }


def counterbalance_warning(plan: StudyPlan) -> str | None:
    """One line where ``[study] participants`` is not a whole number of the balanced Latin square's rows (n rows
    for an even number n of blinded conditions, 2n for an odd n: :func:`coassist.study.design.latin_square_rows`):
    participants take the rows in turn, so only a whole number of squares puts every condition equally often in
    every position and every pair of conditions next to each other equally often. None where it is (or where
    nothing is counterbalanced: fewer than two conditions)."""
    n = len(condition_names(plan))
    if n < 2:
        return None
    rows = len(latin_square_rows(n))
    k = plan.participants
    if k % rows == 0:
        return None
    near = [m for m in (k // rows * rows, (k // rows + 1) * rows) if m > 0]
    square = f"{n} rows and their mirror, {n} being odd" if n % 2 else f"{n} rows, {n} being even"
    return (
        f"study.participants = {k} is not a multiple of {rows}, the rows of the balanced Latin square of {n} "
        f"conditions ({square}): their order is not counterbalanced (every condition equally often in every "
        f"position, every pair next to each other equally often) unless the number of participants who finish "
        f"is a multiple of {rows}; plan {' or '.join(map(str, near))}"
    )


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _mb(n: int) -> str:
    return f"{n / 2**20:.0f} MB" if n >= 2**20 else f"{n / 2**10:.0f} kB"


def bytes_per_tick(horizon: int, n_dof: int = STUDY_DOF, n_joints: int = 0) -> int:
    """A trial's arrays per tick [B] (module docstring): 8 (3 + 6 d + H d + 2 n_joints), α included."""
    return 8 * (3 + 6 * n_dof + horizon * n_dof + 2 * n_joints)


def training_windows(ticks: list[int], history: int, horizon: int, stride: int, test_fraction: float) -> int:
    """Training windows of trials of ``ticks`` samples each (module docstring; the held-out trials left out
    as :func:`coassist.intent.features.split_trials` does)."""
    n = len(ticks)
    n_test = int(round(test_fraction * n))
    if test_fraction > 0 and n >= 2:
        n_test = min(max(n_test, 1), n - 1)
    kept = sorted(ticks)[n_test:]  # the estimate keeps the longest (split_trials draws them at random)
    return sum((t - history - horizon) // stride + 1 for t in kept if t >= history + horizon)


# ----------------------------------------------------------------------------- the checks


def _controller_horizon(plan: StudyPlan) -> tuple[int, float]:
    preset = CONTROL_PRESETS[plan.trials.preset]
    return int(preset.game.horizon), float(preset.impedance.dt)


def _check_sources(plan: StudyPlan, H: int, dt: float) -> dict[str, Any]:
    """Build every condition's intent source as the session does; returns the loaded models by path."""
    from coassist.interfaces import FEATURES

    models: dict[str, Any] = {}
    for i, c in enumerate(plan.conditions):
        where = f"condition[{i}].intent"
        try:
            source = (
                _person_source(H)
                if c.intent == CALIBRATED
                else intent_registry.load_intent_source(c.intent, horizon=max(H, 2), network="torch")
            )
        except (ValueError, OSError, ImportError) as exc:
            raise PlanError(f"{where}: {exc}") from None
        model = getattr(source, "model", None)
        if model is not None:
            try:
                model.check_compatible(FEATURES, dt, what="coassist study")
            except ValueError as exc:
                raise PlanError(f"{where}: {exc}") from None
            n_params = sum(p.numel() for p in model.net.parameters())
            if n_params > MAX_PARAMETERS:
                raise PlanError(
                    f"{where}: the model has {n_params:,} parameters; a study runs at most {MAX_PARAMETERS:,} in the loop"
                )
            models[c.intent] = model
        try:
            check_person_tasks(
                source,
                plan.trials.tasks,
                c.intent,
                fix='give [trials] tasks the model\'s task, or calibrate in the study (intent = "calibrated")',
            )
            check_person_world(source, WORLDS[plan.world].origin, plan.world, c.intent)
        except ValueError as exc:
            raise PlanError(f"{where}: {exc}") from None
        horizon = getattr(source, "horizon", H)
        if horizon < H:
            raise PlanError(f"{where}: {c.intent!r} predicts {horizon} steps; the controller needs {H}")
    return models


def _person_source(H: int):
    """The participant's person model as the session builds it (a person-model folder's source), knowing no
    person yet: what every ``"calibrated"`` condition runs, with its horizon."""
    from coassist.scenario.person_intent import PersonPathsIntent

    return PersonPathsIntent(max(H, 2), model_id="calibrated")


def _check_calibration(plan: StudyPlan, H: int, trial_s: float) -> None:
    """The calibration block's checks (module docstring)."""
    from coassist.scenario.arm_identification import MIN_TRIAL_S

    if plan.calibration is None:
        return
    if trial_s < MIN_TRIAL_S:
        field = "trials.motion_time" if plan.world == "play" else "trials"
        raise PlanError(
            f"{field}: a calibration trial as planned lasts {trial_s:g} s; the arm is measured from trials of at "
            f"least {MIN_TRIAL_S:g} s (shorter ones would leave it assumed): give a longer motion_time or dwell"
        )
    if plan.iterative is not None and plan.iterative.source == CALIBRATED:
        horizon = int(_person_source(H).horizon)
        if plan.iterative.criterion_horizon > horizon:
            raise PlanError(
                f"iterative.criterion_horizon: {plan.iterative.criterion_horizon} samples, but the rounds log the "
                f"person model's predictions of {horizon} (the controller's horizon): the stop criterion could not be "
                f"computed; give at most {horizon}"
            )


def _check_seeds(plan: StudyPlan) -> None:
    """Refuse a plan whose trials would share a seed (the same path and obstacle): each participant's trials draw
    from the 10 000 seeds past their base (:func:`~coassist.study.protocols.trial_seed_base`; practice from 5 000
    on, collections from 2 000, calibration from 8 000), the same offsets for every participant."""
    names = condition_names(plan)
    base = trial_seed_base(plan, 1)
    seen: dict[int, tuple[str, tuple[Any, ...]]] = {}
    for step in participant_steps(plan, dict(zip(names, names)), 1, 0):
        if step["kind"] != "trial":
            continue
        offset, what = step["seed"] - base, f"{step['block']} trial {step['index'] + 1}"
        # measured trial j of every condition shares its seed on purpose (the conditions are paired)
        role = (
            ("paired", step["index"])
            if step["block"] in names and not step["practice"]
            else (step["block"], step["index"])
        )
        if 0 <= offset < SEED_BAND and seen.setdefault(offset, (what, role))[1] == role:
            continue
        clash = f"as {seen[offset][0]}" if offset in seen else "outside the participant's 10 000 seeds"
        fields = "iterative.rounds × iterative.trials_per_round" if plan.iterative is not None else "trials"
        raise PlanError(
            f"{fields}: a participant's {what} would take seed base + {offset}, {clash} (the next participant's "
            "trials, or another block's: the same path and obstacle twice); plan fewer trials"
        )


def _source_model(plan: StudyPlan, H: int, dt: float):
    """The transfer/online source model, loaded and checked for its use: in the loop, and trained further."""
    from coassist.intent.model import load_model
    from coassist.interfaces import FEATURES

    extra = plan.transfer or plan.online
    if extra is None:
        return None
    where = f"{plan.protocol}.source_model"
    try:
        model = load_model(extra.source_model, features=FEATURES, dt=dt)
    except (ValueError, OSError) as exc:
        raise PlanError(f"{where}: {exc}") from None
    if model.window.horizon < H:
        raise PlanError(f"{where}: the model predicts {model.window.horizon} steps; the controller needs {H}")
    if model.window.label == "intent":
        raise PlanError(
            f"{where}: the model was trained on the 'intent' label (the simulated operator's true intent), which "
            "a person's trials do not have: the study could not train it on them; give a model trained on "
            "the 'tool' label"
        )
    return model


def _study_preset(plan: StudyPlan, init: str):
    from coassist.study.training import study_preset

    assert plan.training is not None
    try:
        return study_preset(plan.training, init)
    except ValueError as exc:
        raise PlanError(f"training: {exc}") from None


def _n_parameters(cfg) -> int:
    """Parameters of ``IntentNet(cfg)``, built on torch's meta device (shapes only, nothing allocated)."""
    import torch

    from coassist.intent.network import IntentNet

    with torch.device("meta"):
        net = IntentNet(cfg)
    return int(sum(p.numel() for p in net.parameters()))


def _seconds_per_window(cfg, steps: int, training: TrainingPlan, batch_size: int) -> float:
    """Measured: one training step (forward, backward, Adam) on a random batch, per window (module docstring)."""
    import torch

    from coassist.intent.network import IntentNet

    threads = torch.get_num_threads()
    torch.set_num_threads(training.threads or 1)
    try:
        gen = torch.Generator().manual_seed(0)
        net = IntentNet(cfg, generator=gen)
        opt = torch.optim.Adam(net.parameters(), lr=1e-3)
        x = torch.randn(batch_size, steps, cfg.n_features, generator=gen)
        y = torch.randn(batch_size, cfg.n_outputs, generator=gen)
        times = []
        for i in range(TIMING_REPEATS + 1):
            t0 = time.perf_counter()
            opt.zero_grad()
            loss = torch.nn.functional.mse_loss(net(x), y)
            loss.backward()
            opt.step()
            if i:  # the first is a warm-up
                times.append(time.perf_counter() - t0)
        step_s = statistics.median(times)
    finally:
        torch.set_num_threads(threads)
    return step_s / batch_size


def _check_training(plan: StudyPlan, H: int, source) -> tuple[Any, Any, Any, int]:
    """The study's own models: (their preset, window, network config, parameter count), checked."""
    assert plan.training is not None
    scratch = _study_preset(plan, "scratch")  # the plan's [training] options applied (sizes: scratch only)
    if plan.iterative is not None:
        if scratch.window.label == "intent":
            raise PlanError(
                f"training.preset: {plan.training.preset!r} trains on the 'intent' label (the simulated operator's "
                "true intent), which a person's trials do not have; use a preset of the 'tool' label"
            )
        if scratch.window.horizon < H:
            raise PlanError(
                f"training.preset: {plan.training.preset!r} predicts {scratch.window.horizon} steps; the "
                f"controller needs {H}"
            )
        logged = min(H, scratch.window.horizon)
        if plan.iterative.criterion_horizon > logged:
            raise PlanError(
                f"iterative.criterion_horizon: {plan.iterative.criterion_horizon} samples, but the rounds log "
                f"predictions of {logged} (the nominal plan: the controller's {H}; the models: "
                f"training.preset {plan.training.preset!r}'s {scratch.window.horizon}): the stop criterion "
                f"could not be computed; give at most {logged}"
            )
        window, cfg = scratch.window, scratch.network(STUDY_DOF)
    else:  # transfer, online: the source model's network, trained further
        assert source is not None
        window, cfg = source.window, source.net.config
    n_params = _n_parameters(cfg)
    if n_params > MAX_PARAMETERS:
        raise PlanError(
            f"training: the network (layers {cfg.lstm_layers}, hidden {cfg.hidden}, fc {list(cfg.fc)}) has "
            f"{n_params:,} parameters; a study trains at most {MAX_PARAMETERS:,} within a rest"
        )
    return scratch, window, cfg, n_params


def preflight(plan: StudyPlan) -> SessionEstimate:
    """Check ``plan`` against what every step will need (module docstring); its :class:`SessionEstimate`."""
    H, dt = _controller_horizon(plan)
    _check_sources(plan, H, dt)
    source = _source_model(plan, H, dt)
    end, dwell = plan.task_end(), plan.dwell()
    limit = plan.trials.time_limit if plan.trials.time_limit is not None else 2.0 * end + 10.0
    trial_s = end + dwell
    ticks = int(math.ceil(trial_s / dt))
    n_joints = ARM_JOINTS if plan.world != "play" else 0
    trial_bytes = 2 * int(math.ceil(limit / dt)) * bytes_per_tick(H, n_joints=n_joints)
    _check_calibration(plan, H, trial_s)
    _check_seeds(plan)

    train_s: dict[str, float] = {}
    training_bytes = n_params = 0
    s_per_window = None
    if plan.training is not None:
        preset, window, cfg, n_params = _check_training(plan, H, source)
        if ticks < window.history + window.horizon:
            raise PlanError(
                f"trials.motion_time: a trial as planned lasts {trial_s:g} s ({ticks} ticks), shorter than the "
                f"models' window ({window.history} samples of history + {window.horizon} of horizon): nothing "
                "to train on; give a longer motion_time or dwell"
            )
        s_per_window = _seconds_per_window(cfg, window.steps, plan.training, min(int(preset.train.batch_size), 4096))
        training_bytes = 16 * n_params
    names = condition_names(plan)
    labels = dict(zip(names, blinding_labels(max(len(names), 1), plan.seed)))
    steps = participant_steps(plan, labels, 1, 0)
    expected = longest = wait = 0.0
    n_trials = 0
    items = (6 if plan.questionnaire.tlx else 0) + len(plan.questionnaire.likert)
    trials_of: dict[str, int] = {}
    for k, step in enumerate(steps):
        kind = step["kind"]
        if kind == "trial":
            n_trials += 1
            expected += trial_s
            longest += limit
            trials_of[step["block"]] = trials_of.get(step["block"], 0) + 1
        elif kind == "questionnaire":
            expected += SECONDS_PER_ITEM * items
            longest += SECONDS_PER_ITEM * items
        elif kind == "rest":
            expected += float(step["seconds"])
            longest += float(step["seconds"])
        elif kind == "fit":
            expected += FIT_SECONDS
            longest += FIT_SECONDS
            wait += FIT_SECONDS
        elif kind == "train" and s_per_window is not None:
            n = sum(trials_of.get(b, 0) for b in step["data"])  # the trials so far of the blocks it trains on
            t = preset.train
            w = training_windows([ticks] * n, window.history, window.horizon, t.train_stride, t.test_fraction)
            seconds = w * t.epochs * s_per_window
            train_s[step["model"]] = seconds
            training_bytes = max(training_bytes, 16 * n_params + 8 * n * ticks * 4 * STUDY_DOF)
            if step["init"] != "online":  # online updates are never waited for
                nxt = steps[k + 1] if k + 1 < len(steps) else None
                covered = float(nxt["seconds"]) if nxt is not None and nxt["kind"] == "rest" else 0.0
                waited = max(0.0, seconds - covered)
                wait += waited
                expected += waited
                longest += waited
    if plan.calibration is not None and plan.calibration.asked:
        # the trials a calibration may ask for after its fit, and the second fit: not in the steps until then
        longest += plan.calibration.asked * limit + FIT_SECONDS
    estimate = SessionEstimate(
        expected_s=expected,
        max_s=longest,
        n_trials=n_trials,
        trials_s=n_trials * trial_s,
        training_s=sum(train_s.values()),
        wait_s=wait,
        trial_bytes=trial_bytes,
        training_bytes=training_bytes,
        s_per_window=s_per_window,
        models=train_s,
        warnings=tuple(w for w in (counterbalance_warning(plan),) if w),
    )
    if expected > 3600 * MAX_SESSION_HOURS:
        raise PlanError(
            f"a participant's session would take about {_duration(expected)} ({n_trials} trials, "
            f"{_duration(wait)} of waiting for models): more than {MAX_SESSION_HOURS:g} h; plan fewer trials or "
            "rounds, shorter rests, a smaller [training]"
        )
    return estimate
