"""A person's twin (coassist.sim.person_twin): their calibration replayed in closed loop says whether the person
model should lead them along their paths; told nothing but the calibration trials."""

from dataclasses import replace

import numpy as np
import pytest

from coassist.control.presets import get_preset, make_controller
from coassist.data import Trial
from coassist.interfaces import TrialContext
from coassist.scenario.intent_registry import load_intent_source
from coassist.scenario.objects import get_object
from coassist.scenario.operator import AUTHOR
from coassist.scenario.person_intent import PersonPathsIntent
from coassist.scenario.person_model import (
    PERSON_FILTER,
    LeadCheck,
    fit_person,
    read_person_model,
    write_person_model,
)
from coassist.scenario.populations import population_profile
from coassist.scenario.tasks import task_for_seed
from coassist.sim import person_twin
from coassist.sim.person_twin import TwinArm, lead_check, twin_overshoot, why_no_twin
from coassist.sim.trial_runner import run_trial

PRESET = get_preset("thesis-application-damped")
SEEDS = range(880000, 880005)


def _probes(profile) -> list[Trial]:
    ctrl = make_controller("manual-probe", PRESET)
    return [
        run_trial(
            task_for_seed("curved", s, obstacle="large"),
            profile,
            get_object("handle"),
            ctrl,
            None,
            s,
            preset_name=PRESET.name,
        )
        for s in SEEDS
    ]


@pytest.fixture(scope="module")
def steady():
    """Five probe trials of the author going left every time, their detour the same shape each time."""
    trials = _probes(replace(AUTHOR, name="steady", shape_jitter=0.0, left_preference=1.0))
    return trials, fit_person(trials)


@pytest.fixture(scope="module")
def corrective():
    """Five probe trials of held-out operator 2: detours of several corrective strokes that differ every time."""
    trials = _probes(population_profile("held-out", 2, 0))
    return trials, fit_person(trials)


@pytest.fixture(scope="module")
def corrective_check(corrective):
    """The check of ``corrective``, as it runs (computed once: several tests compare other ways of running it with it)."""
    return lead_check(*corrective, PERSON_FILTER)


def test_the_twin_arm_is_a_spring_and_damper_toward_the_intent():
    q = np.array([[0.1, -0.2], [0.3, 0.4]])
    arm = TwinArm(q, 650.0, -12.0)
    fx, fy = arm.force(1, 0.25, 0.5, 0.2, -0.1)
    assert fx == pytest.approx(650.0 * (0.3 - 0.25) + 12.0 * 0.2, abs=1e-12)
    assert fy == pytest.approx(650.0 * (0.4 - 0.5) - 12.0 * 0.1, abs=1e-12)
    assert arm.force(7, 0.3, 0.4, 0.0, 0.0) == (0.0, 0.0)  # past its end the intent holds its last row


def test_the_twins_arms_in_a_batch_are_each_twin_arm_row_for_row():
    from coassist.sim.person_twin import TwinArmBatch

    rng = np.random.default_rng(7)
    arms = [TwinArm(rng.normal(size=(n, 2)), K, C) for n, K, C in ((5, 650.0, -12.0), (3, 410.0, 8.5), (7, 1.3e3, 0.0))]
    batch = TwinArm.batch(arms)
    assert isinstance(batch, TwinArmBatch)
    for k in range(9):  # past each one's end too
        rows = np.array([0, 2] if k % 2 else [0, 1, 2])
        p, v = rng.normal(size=(len(rows), 2)), rng.normal(size=(len(rows), 2))
        got = batch.force(k, rows, p, v)
        want = [arms[r].force(k, *p[j], *v[j]) for j, r in enumerate(rows)]
        np.testing.assert_array_equal(got, np.asarray(want))  # the same operations in the same order: the same bits
    with pytest.raises(ValueError, match="TwinArm"):
        TwinArmBatch([])


def test_the_checks_twins_run_together_give_what_each_gives_alone(corrective, corrective_check, monkeypatch):
    # the check runs its twin trials in one lockstep batch on the point-mass array path (corrective_check); every
    # trial on the reference path (each its own scalar tick) gives the same check to the last bit, and so do trials
    # that leave the array path midway (built again and run on the reference path)
    import coassist.sim.trial_runner as trial_runner

    array_path = trial_runner.run_point_mass_lockstep
    batches = []

    def leaving(loops, on_end):  # every other run leaves the array path at its end, its source run to the end
        logs = array_path(loops, on_end=lambda j, log: None if j % 2 else on_end(j, log))
        batches.append(logs)
        return [None if j % 2 else log for j, log in enumerate(logs)]

    monkeypatch.setattr(trial_runner, "run_point_mass_lockstep", leaving)
    built = []  # the runs under MG share one MG (it keeps no state): stepped once a tick for all of them
    make = person_twin.make_controller
    monkeypatch.setattr(person_twin, "make_controller", lambda kind, preset: built.append(kind) or make(kind, preset))
    assert lead_check(*corrective, PERSON_FILTER) == corrective_check
    assert built.count("manual") == 1 and built.count(person_twin.TWIN_CONTROLLER) == 2 * len(SEEDS)  # led: rebuilt
    assert [len(logs) for logs in batches] == [2 * len(SEEDS)]  # one batch, every fold under MG and led
    assert all(log is not None for log in batches[0])  # none left the array path of itself: the batch is measured
    monkeypatch.setattr(trial_runner, "fast_path_eligible", lambda loop: False)
    assert lead_check(*corrective, PERSON_FILTER) == corrective_check
    assert corrective_check.folds == len(SEEDS)


def test_the_lead_is_kept_where_it_pays_and_dropped_where_it_costs_overshoot(steady, corrective_check):
    led = lead_check(*steady, PERSON_FILTER)
    assert led.follow and led.note == "checked" and led.folds == len(SEEDS)
    assert led.person_mm < led.mg_mm  # the lead halves what MG overshoots, or better
    held = corrective_check
    assert not held.follow and held.folds == len(SEEDS)
    assert held.person_mm > held.mg_mm
    assert "present estimate held" in held.line and f"{held.person_mm:.1f} mm with the lead" in held.line
    # the same trials give the same check
    assert lead_check(*steady, PERSON_FILTER) == led


def test_the_twin_reads_nothing_of_the_simulated_operator(steady):
    # what a lab's trial would not carry (the simulated operator, its intent and detour) taken out of the meta: the
    # twin's overshoot is the same to the last bit
    trials, fit = steady
    t = trials[0]
    secret = ("operator", "intent_side", "intent_amplitude", "intent_pace", "intent_end_time", "obstacle")
    bare = replace(t, meta=replace(t.meta, extra={k: v for k, v in t.meta.extra.items() if k not in secret}))
    q = t.pose[:, :2] + (t.wrench[:, :2] + fit.arm.damping * t.velocity[:, :2]) / fit.arm.stiffness
    assert twin_overshoot(bare, q, fit.arm, None) == twin_overshoot(t, q, fit.arm, None)


def test_trials_that_cannot_be_replayed_leave_the_person_led_and_say_why(steady):
    trials, fit = steady
    no_preset = [replace(t, meta=replace(t.meta, extra={**t.meta.extra, "preset": None})) for t in trials]
    check = lead_check(no_preset, fit, PERSON_FILTER)
    assert check.follow and check.folds == 0 and "control preset" in check.note
    assert why_no_twin(replace(trials[0], meta=replace(trials[0].meta, task="lab-plan"))).startswith("its task")
    # a plan of another shape than the task's (a lab's own plan under a task's name): not replayed
    bent = []
    for t in trials:
        ref = np.array(t.reference, dtype=float)
        ref[:, 1] += 0.01 * np.sin(np.linspace(0.0, np.pi, len(ref)))
        bent.append(replace(t, reference=ref))
    check = lead_check(bent, fit, PERSON_FILTER)
    assert check.follow and check.folds == 0 and "plan is not its task's" in check.note
    assert lead_check(trials[:1], fit, PERSON_FILTER).note.startswith("not checked")
    negative = [replace(t, meta=replace(t.meta, seed=-1)) for t in trials]
    assert "seed -1" in lead_check(negative, fit, PERSON_FILTER).note


def test_a_twin_trial_that_cannot_be_scored_leaves_the_person_led_and_says_why(steady, monkeypatch):
    # (a Trial refuses non-finite samples, so a scoring failure is stood in for: the check must not raise)
    import coassist.sim.person_twin as person_twin

    def refuses(pose, intent):
        raise ValueError("intent has non-finite values")

    monkeypatch.setattr(person_twin, "overshoot", refuses)
    check = lead_check(*steady, PERSON_FILTER)
    assert check.follow and check.folds == 0
    assert check.note == "not checked: its twin trials could not be run (intent has non-finite values)"


def test_a_real_arms_trials_are_checked_in_their_tasks_frame_and_rate(corrective, corrective_check):
    # a real arm lays the task's plan out from where its tool stands (each trial a little elsewhere): the same person,
    # the same verdict
    trials, fit = corrective
    base = corrective_check
    moved = []
    for k, t in enumerate(trials):
        by = np.array([0.41 + 0.003 * k, -0.137])
        pose, ref = np.array(t.pose, dtype=float), np.array(t.reference, dtype=float)
        pose[:, :2] += by
        ref[:, :2] += by
        moved.append(replace(t, pose=pose, reference=ref))
    shifted = lead_check(moved, fit_person(moved), PERSON_FILTER)
    assert shifted.note == "checked" and shifted.folds == base.folds and shifted.follow == base.follow
    # the same twins: the positions moved out and back differ by rounding (1e-16 m), which the closed loop and the
    # filter's thresholds could carry further on another BLAS; a micron still tells a wrong frame (millimetres)
    assert shifted.person_mm == pytest.approx(base.person_mm, abs=1e-3)
    assert shifted.mg_mm == pytest.approx(base.mg_mm, abs=1e-3)


def test_a_trial_at_500_hz_is_resampled_onto_the_presets_ticks():
    from coassist.sim.person_twin import on_ticks

    t = np.linspace(0.0, 2.0, 1001)
    xy = np.stack([np.sin(t), t**2], axis=1)  # 500 Hz
    coarse = on_ticks(xy, 0.002, 0.008)
    assert coarse.shape == (251, 2)
    np.testing.assert_allclose(coarse, np.stack([np.sin(t[::4]), t[::4] ** 2], axis=1), rtol=0, atol=1e-12)
    assert on_ticks(xy, 0.008, 0.008) is xy  # the same rows where the rates agree


def _context(user: str, path: np.ndarray) -> TrialContext:
    return TrialContext(
        dt=0.008,
        horizon=50,
        start=path[0],
        target=path[-1],
        reference=np.zeros((50, 4)),
        task="curved",
        object="heavy",
        user=user,
        path=path,
    )


def test_a_person_the_check_turned_away_gets_the_present_estimate_held(tmp_path, steady):
    trials, fit = steady
    path = fit.paths.nominal
    fits = {"led": fit, "held": replace(fit, lead=LeadCheck(follow=False, folds=5, person_mm=6.0, mg_mm=2.0))}
    folder = write_person_model(tmp_path / "pm", fits, default="held")
    source = read_person_model(folder)
    assert source.held == {"held", PersonPathsIntent.DEFAULT}
    t = trials[0]

    def rows_of(src, user: str) -> np.ndarray:
        src.reset(_context(user, path))
        out = []
        for k in range(600, 700):  # the feature rows of a trial: pose, velocity, wrench, plan
            row = np.concatenate([t.pose[k, :2], t.velocity[k, :2], t.wrench[k, :2], t.reference[k, :2]])[None, :]
            out.append(src.predict(row))
        return np.asarray(out)

    rows = {user: rows_of(source, user) for user in ("led", "held", "someone-else")}
    # held: what every world gives without a calibration (present-held), bit for bit
    np.testing.assert_array_equal(rows["held"], rows_of(load_intent_source("present-held", horizon=50), "held"))
    assert np.all(rows["held"] == rows["held"][:, :1, :])
    assert not np.all(rows["led"] == rows["led"][:, :1, :])
    np.testing.assert_array_equal(rows["someone-else"], rows["held"])  # the default person is held: so is anyone
    # and a file with the check read back gives it again
    again = read_person_model(folder)
    assert again.held == source.held


def test_a_fold_is_the_fit_of_the_other_trials(corrective):
    from coassist.scenario.person_model import without_trial

    trials, fit = corrective
    for leave in range(1, len(trials)):  # the plan is the first trial's: leave it in
        fold = without_trial(fit, trials, leave).paths
        refit = fit_person([t for j, t in enumerate(trials) if j != leave], arm=fit.arm).paths
        np.testing.assert_array_equal(fold.weights, refit.weights)  # each path's primitive fitted alone
        np.testing.assert_array_equal(fold.sides, refit.sides)
        assert fold.noise == refit.noise
        np.testing.assert_array_equal(fold.asked, refit.asked)
    with pytest.raises(ValueError, match="leave 9"):
        without_trial(fit, trials, 9)


def test_the_verdict_turns_away_a_lead_worse_beyond_its_spread_or_in_too_many_trials():
    from coassist.sim.person_twin import SIGN_LEVEL, lead_verdict

    # worse in 7 of 8 trials, one trial of the rare way round (MG 12.3 mm) widening the interval below zero: the sign
    # test, P(≥ 7 of 8 | a fair coin) = 9/256 = 0.035, turns the lead away
    mg = np.array([2.8, 3.0, 1.1, 1.9, 12.3, 0.8, 1.1, 0.4])
    led = np.array([6.9, 4.5, 6.4, 12.0, 5.4, 7.7, 4.8, 0.5])
    check = lead_verdict(led, mg)
    d = led - mg
    low = d.mean() - 2.3646242510102993 * d.std(ddof=1) / np.sqrt(8)  # t(0.975, 7)
    assert check.low_mm == pytest.approx(low, rel=1e-9) and low < 0.0
    assert 9 / 256 < SIGN_LEVEL and check.worse == 7 and not check.follow
    assert "more with the lead in 7" in check.line
    # 6 of 8 (P = 37/256 = 0.145) and the interval across zero: led
    mg6 = np.array([2.8, 3.0, 1.1, 1.9, 12.3, 0.8, 7.1, 0.4])
    assert lead_verdict(led, mg6).follow and lead_verdict(led, mg6).worse == 6
    # worse by 5 mm in 6 of 8 and better by 0.1 mm in two: the interval above zero (mean 3.725 mm, its lower end
    # 3.725 − 2.365 · 2.361 / √8 = 1.75 mm) turns the lead away where the sign test would not
    worse6 = mg + np.array([5.0, 5.0, 5.0, 5.0, 5.0, 5.0, -0.1, -0.1])
    check = lead_verdict(worse6, mg)
    assert check.worse == 6 and check.low_mm == pytest.approx(1.751, abs=1e-3) and not check.follow
    # ties count for neither side; a lead better in every trial is followed
    assert lead_verdict(mg, mg).worse == 0 and lead_verdict(mg, mg).follow
    assert lead_verdict(0.5 * mg, mg).follow
    with pytest.raises(ValueError, match="paired"):
        lead_verdict(led[:1], mg[:1])


def test_a_calibration_checked_from_its_folders_is_checked_as_its_trials(tmp_path, corrective, corrective_check):
    # the main job checks each calibration draw on its pool, from the draw's dataset folders (a trial does not pickle):
    # the trials read back give the checks of the trials in memory, bit for bit
    from coassist.data import write_dataset
    from coassist.experiments.source_training import checked_calibration

    trials, fit = corrective
    first = write_dataset(trials[:3], tmp_path / "probe", "probe")
    asked = write_dataset(trials[3:], tmp_path / "probe-ask", "probe-ask")
    fits = {"held-out-user-2": fit}
    from_folders = checked_calibration([str(first), str(asked)], fits, PERSON_FILTER)
    assert from_folders["held-out-user-2"].lead == corrective_check  # every trial is that person's
    assert from_folders["held-out-user-2"].lead.folds == len(SEEDS)
