"""The closed loop: determinism, termination, sensor, intent sources, the assistance claim, batches."""

import sys
from dataclasses import replace

import numpy as np
import pytest

from coassist.control import Fault
from coassist.control.presets import get_preset, make_controller
from coassist.interfaces import FEATURES
from coassist.scenario import AUTHOR, ForceSensor, NominalIntent, get_object, make_task
from coassist.sim import TrialSpec, run_spec, run_trial, run_trials


@pytest.fixture(scope="module")
def trial():
    return run_spec(TrialSpec(task="curved", seed=11))


def test_same_seed_same_trial_bit_for_bit(trial):
    again = run_spec(TrialSpec(task="curved", seed=11))
    assert again.equals(trial)
    other = run_spec(TrialSpec(task="curved", seed=12))
    assert not other.equals(trial)
    assert other.meta.extra["obstacle"] != trial.meta.extra["obstacle"]


def test_trial_ends_at_the_target(trial):
    target = np.array(trial.meta.extra["target"])
    assert trial.meta.extra["ended"] == "target"
    dwell = int(np.ceil(5.0 / trial.meta.dt))
    dist = np.linalg.norm(trial.pose - target, axis=1)
    assert np.all(dist[-dwell:] < 0.025)  # settled for the whole dwell
    assert trial.duration < 2 * 10.9 + 10  # well before the time limit
    assert trial.time[-1] >= trial.meta.extra["intent_end_time"]


def test_trial_logs_every_signal(trial):
    T = trial.n_samples
    assert trial.meta.origin == "sim" and trial.meta.user == "user-0" and trial.meta.model_id is None
    assert trial.prediction.shape == (T, 50, 2) and trial.intent.shape == (T, 2)
    assert trial.fault.shape == (T,) and np.all(trial.fault & ~int(Fault.SATURATED) == 0)
    # nominal intent: the prediction in use is the planner's next 50 positions
    np.testing.assert_allclose(trial.prediction[100], trial.reference[101:151])
    # the tip really moved along the task and back to rest
    assert np.linalg.norm(trial.pose[-1] - trial.pose[0]) > 0.45
    np.testing.assert_allclose(trial.velocity[-1], 0.0, atol=5e-3)


def _quiet_sensor(**kw):
    return ForceSensor(**{"noise": 0.0, "offset": 0.0, "tilt": 0.0, "rate_hz": None, **kw})


def _run(
    obj="handle",
    sensor=None,
    source=None,
    task="linear",
    seed=3,
    preset="thesis-evaluation",
    controller="cooperative",
    **kw,
):
    c = make_controller(controller, get_preset(preset))
    return run_trial(
        make_task(task, np.random.default_rng(seed)), AUTHOR, get_object(obj), c, source, seed, sensor=sensor, **kw
    )


def test_sensor_bias_is_zeroed_at_the_start():
    sensor = ForceSensor(offset=5.0, tilt=0.05, noise=0.05, zero_samples=25)
    still = replace(AUTHOR, motor_noise=0.0)  # an operator who holds still until the motion starts
    c = make_controller("cooperative", get_preset("thesis-evaluation"))
    tr = run_trial(make_task("linear", np.random.default_rng(3)), still, get_object("heavy"), c, None, 3, sensor=sensor)
    raw = np.array(tr.meta.extra["sensor_raw_bias"])
    residual = np.array(tr.meta.extra["sensor_residual_bias"])
    assert np.linalg.norm(raw) > 1.0  # several N of offset and leaked weight before zeroing
    assert np.all(np.abs(residual) < 5 * 0.05 / np.sqrt(25))  # what averaging 25 readings leaves
    # at rest the reading is the small residual plus noise, not the raw bias
    rest = tr.time < 0.9
    assert np.all(np.abs(tr.wrench[rest] - residual) < 5 * 0.05)
    np.testing.assert_allclose(tr.wrench[rest].mean(axis=0), residual, atol=0.03)


def test_sensor_measures_hand_force_minus_object_inertia():
    tr = _run(obj="heavy", sensor=_quiet_sensor())
    m = get_object("heavy").mass
    a = np.diff(tr.velocity, axis=0) / tr.meta.dt  # acceleration over [k, k+1]
    # reading at k+1 = u_h(k) − m a(k): a heavy load hides part of the hand's force
    np.testing.assert_allclose(tr.wrench[1:], tr.effort_h[:-1] - m * a, atol=1e-9)
    assert np.abs(m * a).max() > 1.0


def test_board_yaw_makes_a_lateral_disturbance():
    tr = _run(obj="board", sensor=_quiet_sensor())
    assert tr.meta.extra["ended"] == "target"
    m = get_object("board").mass
    a = np.diff(tr.velocity, axis=0) / tr.meta.dt
    # the sensor sees more than the translational inertia: the board's yaw acceleration
    residual = tr.wrench[1:] - (tr.effort_h[:-1] - m * a)
    assert np.abs(residual).max() > 0.05


class _Recorder:
    """An intent source that records its windows and predicts the nominal reference."""

    history = 5
    horizon = 50
    model_id = "recorder"

    def reset(self, context):
        self.ref = context.reference
        self.windows = []
        self.k = 0

    def predict(self, history):
        self.windows.append(history.copy())
        k, self.k = self.k, self.k + 1
        return self.ref[k + 1 : k + 51, :2]


def test_intent_source_sees_the_logged_rows():
    src = _Recorder()
    tr = _run(source=src)
    assert tr.meta.model_id == "recorder"
    feats = np.column_stack([tr.pose, tr.velocity, tr.wrench, tr.reference])
    assert feats.shape[1] == len(FEATURES)
    for k in (0, 2, 4, 5, 300, tr.n_samples - 1):
        expected = feats[max(0, k - 4) : k + 1]
        if k < 4:  # padded at the front with tick 0's row
            expected = np.vstack([np.tile(feats[0], (4 - k, 1)), expected])
        np.testing.assert_array_equal(src.windows[k], expected)
    # a prediction equal to the nominal positions gives (almost) the nominal trial
    nominal = _run(source=NominalIntent())
    np.testing.assert_allclose(tr.pose, nominal.pose, atol=2e-4)


class _Broken(_Recorder):
    def predict(self, history):
        k = self.k
        super().predict(history)
        if k % 2:
            return np.full((50, 2), np.nan)
        if k % 3 == 0:
            raise RuntimeError("model crashed")
        return self.ref[k + 1 : k + 51, :2]


def test_bad_predictions_fall_back_to_nominal_and_are_flagged():
    tr = _run(source=_Broken())
    flagged = (tr.fault & int(Fault.PREDICTION_FALLBACK)) != 0
    k = np.arange(tr.n_samples)
    np.testing.assert_array_equal(flagged, (k % 2 == 1) | (k % 3 == 0))
    assert tr.meta.extra["ended"] == "target"


def test_operator_pushes_less_when_the_robot_follows_the_true_intent():
    # With the thesis' weights in decimetres the robot assists with a few N per cm; the
    # oracle (true intent) helps the operator around the obstacle instead of pulling
    # them back to the nominal path, and the operator relaxes.
    for task in ("linear", "sinusoidal"):
        for seed in (0, 1):
            common = dict(task=task, seed=seed, preset="thesis-evaluation-dm")
            nominal = run_spec(TrialSpec(intent="nominal", **common))
            oracle = run_spec(TrialSpec(intent="oracle", **common))
            f_nom = np.linalg.norm(nominal.effort_h, axis=1)
            f_ora = np.linalg.norm(oracle.effort_h, axis=1)
            assert f_ora.mean() < 0.8 * f_nom.mean()
            assert f_ora.max() < 0.6 * f_nom.max()
            # and it follows its intent more closely
            assert np.abs(oracle.pose - oracle.intent).max() < np.abs(nominal.pose - nominal.intent).max()


def test_parallel_run_equals_serial_run():
    specs = [
        TrialSpec(task=t, seed=s, user=u)
        for t, s, u in (("linear", 1, 0), ("curved", 2, 1), ("z", 3, 2), ("linear", 4, 0))
    ]
    serial = run_trials(specs, workers=1, progress=False)
    parallel = run_trials(specs, workers=2, progress=False)
    assert len(parallel) == len(specs)
    for a, b, spec in zip(serial, parallel, specs):
        assert a.equals(b)
        assert a.meta.seed == spec.seed and a.meta.task == spec.task


def test_named_intents_on_the_pool_run_in_lockstep_groups_bit_for_bit_as_alone():
    """With named intents, run_trials' lockstep groups (the default) give every controller kind's
    trials bit for bit what the per-trial path gives, on a pool and in this process; in this
    process each trial is delivered as it ends (shortest first), not when the group ends."""
    from coassist.control.presets import CONTROLLER_KINDS
    from coassist.sim.pool import worker_pool
    from coassist.sim.trial_runner import NAMED_GROUP, submit_trials

    specs = [
        TrialSpec(task=t, seed=s, user=s % 3, controller=c, intent=i)
        for s, (t, c, i) in enumerate(
            zip(
                ("linear", "curved", "z", "linear", "sinusoidal", "curved", "z", "linear"),
                CONTROLLER_KINDS * 2,
                ("nominal", "oracle") * 4,
            )
        )
    ]
    alone = run_trials(specs, workers=1, progress=False, lockstep=False)
    # One pool of two for both runs on a pool below (``pool=``: the same jobs on the same number of processes as
    # the pool run_trials would start itself, pool_for; a job carries all its inputs, so the processes give the
    # same trials call after call: test_a_kept_pool_serves_call_after_call_and_stays_up). A second fresh pool
    # cost ~3 CPU-s of interpreters importing numpy, scipy and torch (issue 44).
    with worker_pool(2) as shared:
        pooled = run_trials(specs, workers=2, progress=False, pool=shared)
        one_group = run_trials(specs, workers=2, progress=False, groups=1, pool=shared)
    order: list[int] = []
    here = run_trials(specs, workers=1, progress=False, on_result=lambda i, t: order.append(i)) or None
    assert here is None and sorted(order) == list(range(len(specs)))
    lengths = [t.n_samples for t in alone]
    assert [lengths[i] for i in order] == sorted(lengths)  # as each ends
    for a, b in zip(alone, pooled, strict=True):
        assert a.equals(b)

    # groups: one per worker for a short list, of at most NAMED_GROUP trials for a long one
    class Pool:
        def submit(self, fn, batch):
            return batch

    assert [g for _, g in submit_trials(specs, Pool(), workers=2).jobs] == [(0, 2, 4, 6), (1, 3, 5, 7)]
    many = submit_trials([specs[0]] * (5 * NAMED_GROUP + 1), Pool(), workers=2).jobs
    assert len(many) == 6 and max(len(g) for _, g in many) <= NAMED_GROUP
    assert sorted(i for _, g in many for i in g) == list(range(5 * NAMED_GROUP + 1))
    # groups= overrides the rule (a prefetching caller keeps the pool busy itself), at most one per trial
    assert [g for _, g in submit_trials(specs, Pool(), workers=2, groups=1).jobs] == [tuple(range(8))]
    assert [g for _, g in submit_trials(specs, Pool(), workers=2, groups=3).jobs] == [(0, 3, 6), (1, 4, 7), (2, 5)]
    assert len(submit_trials(specs[:2], Pool(), workers=2, groups=5).jobs) == 2
    with pytest.raises(ValueError, match="groups must be >= 1"):
        submit_trials(specs, Pool(), workers=2, groups=0)
    for a, b in zip(alone, one_group, strict=True):
        assert a.equals(b)


def test_a_kept_pool_serves_call_after_call_and_stays_up():
    """run_trials(pool=...) runs on the caller's processes, gives what a fresh pool gives, and leaves
    them running for the next call (coassist reproduce keeps one pool for its ~40 collections)."""
    from coassist.sim.pool import worker_pool

    specs = [TrialSpec(task=t, seed=s) for t, s in (("linear", 11), ("curved", 12), ("z", 13))]
    serial = run_trials(specs, workers=1, progress=False)
    with worker_pool(2) as pool:
        first = run_trials(specs, workers=2, progress=False, pool=pool)
        second = run_trials(specs[::-1], workers=2, progress=False, pool=pool)  # the same processes again
        assert pool.submit(int, "7").result() == 7  # not shut down by run_trials
    for a, b, c in zip(serial, first, second[::-1]):
        assert a.equals(b) and a.equals(c)
    with pytest.raises(ValueError, match="workers"):
        worker_pool(0)


def test_baselines_apply_their_laws_in_the_loop():
    # IMP (eq. 5.4): u_r(k) = K (x_ref,r(k+1) − x(k)), the spring toward the next nominal
    # point; recomputed here from the logged pose and reference. MG (eq. 5.5): u_r = 0.
    imp = run_spec(TrialSpec(task="linear", seed=5, controller="impedance"))
    assert imp.meta.controller == "impedance" and imp.meta.extra["ended"] == "target"
    preset = get_preset(imp.meta.extra["preset"])
    K = make_controller("impedance", preset).K
    assert K[0, 0] > 0 and K[0, 1] == 0  # a spring on each axis
    spring = (imp.reference[1:] - imp.pose[:-1]) @ K.T
    assert 1.0 < np.abs(spring).max() < preset.effort_limit  # it pulls, unsaturated
    np.testing.assert_allclose(imp.effort_r[:-1], spring, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(imp.fault, 0)

    mg = run_spec(TrialSpec(task="linear", seed=5, controller="manual"))
    assert mg.meta.controller == "manual" and mg.meta.extra["ended"] == "target"
    np.testing.assert_array_equal(mg.effort_r, 0.0)


def test_ray_is_an_optional_extra(monkeypatch):
    # Whether or not Ray is installed: hide it (a None entry makes `import ray` fail).
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(RuntimeError, match=r"ray_address=.*needs Ray.*pip install coassist\[cluster\]"):
        run_trials([TrialSpec(task="linear")], ray_address="auto", progress=False)


def test_spec_validation_names_the_field():
    with pytest.raises(ValueError, match="TrialSpec.task"):
        TrialSpec(task="circle")
    with pytest.raises(ValueError, match="TrialSpec.controller"):
        TrialSpec(task="linear", controller="nash")
    with pytest.raises(ValueError, match="object"):
        TrialSpec(task="linear", object="piano")
    with pytest.raises(ValueError, match="TrialSpec.seed"):
        TrialSpec(task="linear", seed=-1)
    with pytest.raises(ValueError, match="intent"):
        run_spec(TrialSpec(task="linear", intent="/nonexistent/model.safetensors"))
    with pytest.raises(ValueError, match="TrialSpec.population"):
        TrialSpec(task="linear", population="everyone")


def test_a_thesis_collection_keeps_its_key_and_a_population_trial_its_record(trial):
    # the thesis population's specs are keyed as before populations had names (a collection on disk stays
    # recognised); its trials record no family (their metadata unchanged)
    from dataclasses import asdict

    from coassist.sim.collect import spec_key

    spec = TrialSpec(task="curved", seed=11)
    before = (
        "task",
        "user",
        "object",
        "controller",
        "preset",
        "seed",
        "intent",
        "population_seed",
        "obstacle",
        "network",
    )
    assert spec_key(spec) == {k: v for k, v in asdict(spec).items() if k in before}
    assert spec_key(replace(spec, way=-1))["way"] == -1
    assert spec_key(replace(spec, population="held-out"))["population"] == "held-out"
    assert "detour" not in trial.meta.extra["operator"] and "intent_detour" not in trial.meta.extra
    held_out = run_spec(replace(spec, population="held-out", user=1))
    assert held_out.meta.user == "held-out-user-1"
    assert held_out.meta.extra["operator"]["detour"]["family"] == "hesitant"
    assert held_out.meta.extra["intent_detour"]["family"] == "hesitant"


def test_the_applications_large_obstacle_makes_a_wide_detour_that_still_ends_at_the_target():
    """obstacle="large" (thesis §5.2.3): a 12 cm box midway; the operator passes it farther
    from the nominal path than the evaluation's 6 cm box, and still settles on the target."""
    from coassist.experiments.realism import trial_stats
    from coassist.metrics import distance_to_target
    from coassist.scenario.tasks import OBSTACLES
    from coassist.sim import TrialSpec, run_spec

    dev = {}
    for name in ("small", "large"):
        t = run_spec(
            TrialSpec(
                task="curved",
                object="board",
                controller="manual",
                preset="thesis-application-damped",
                seed=11,
                obstacle=name,
            )
        )
        assert tuple(t.meta.extra["obstacle"]["size"]) == OBSTACLES[name][0]
        assert distance_to_target(t.pose, np.asarray(t.meta.extra["target"], float))[-1] < 0.025
        dev[name] = trial_stats(t)["peak_deviation"]
    assert dev["large"] > dev["small"] + 0.02 and dev["large"] > 0.07
    with pytest.raises(ValueError, match="TrialSpec.obstacle"):
        TrialSpec(task="curved", obstacle="huge")


def test_an_operator_asked_for_a_way_goes_that_way_and_the_trial_says_it_was_asked():
    """TrialSpec.way forces the operator's side draw and nothing else: the intent up to the detour's onset is the
    chosen trial's bit for bit, the way taken is the one asked for, and the meta records the asking (ASKED_WAY)
    beside the operator's own profile (their preference, not the forced one)."""
    from coassist.scenario.path_model import ASKED_WAY

    chosen = run_spec(TrialSpec(task="curved", controller="manual", seed=5, user=1, obstacle="large"))
    side = chosen.meta.extra["intent_side"]
    asked = run_spec(TrialSpec(task="curved", controller="manual", seed=5, user=1, obstacle="large", way=-side))
    assert ASKED_WAY not in chosen.meta.extra
    assert asked.meta.extra[ASKED_WAY] == -side and asked.meta.extra["intent_side"] == -side
    assert asked.meta.extra["operator"] == chosen.meta.extra["operator"]
    same = run_spec(TrialSpec(task="curved", controller="manual", seed=5, user=1, obstacle="large", way=side))
    assert same.meta.extra[ASKED_WAY] == side
    np.testing.assert_array_equal(same.pose, chosen.pose)  # asked the way they would have taken: the same trial
    # the two sides' trials share their first ticks exactly (the intent is the same up to the onset)
    n = min(len(asked.pose), len(chosen.pose))
    differs = np.flatnonzero(np.any(asked.pose[:n] != chosen.pose[:n], axis=1))
    assert differs.size and differs[0] > 50
    for bad in (2, True, 0.5):
        with pytest.raises(ValueError, match="TrialSpec.way"):
            TrialSpec(task="curved", way=bad)
