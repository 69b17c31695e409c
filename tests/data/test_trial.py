"""Trial and TrialMeta: validation on construction, immutability, properties."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from coassist.data import Trial, TrialMeta


def make_meta(**changes) -> TrialMeta:
    base = dict(
        user="user-0",
        task="linear",
        object="handle",
        controller="cooperative",
        model_id="M1",
        seed=7,
        origin="sim",
        dt=0.008,
        extra={"target": (0.4, 0.1), "obstacle": {"center": [0.2, 0.05], "size": [0.05, 0.05]}},
    )
    base.update(changes)
    return TrialMeta(**base)


def make_trial(n: int = 10, d: int = 2, h: int | None = 4, **changes) -> Trial:
    rng = np.random.default_rng(0)
    base = dict(
        meta=make_meta(),
        time=np.arange(n) * 0.008,
        pose=rng.normal(size=(n, d)),
        velocity=rng.normal(size=(n, d)),
        wrench=rng.normal(size=(n, d)),
        reference=rng.normal(size=(n, d)),
        prediction=None if h is None else rng.normal(size=(n, h, d)),
    )
    base.update(changes)
    return Trial(**base)


def test_meta_normalises_extra_through_json_and_is_read_only():
    meta = make_meta()
    # tuples become lists (read back as tuples), so a re-read meta compares equal
    assert meta.extra["target"] == (0.4, 0.1)
    assert meta.to_dict()["extra"]["target"] == [0.4, 0.1]
    assert TrialMeta.from_json(meta.to_json()) == meta
    with pytest.raises(TypeError):
        meta.extra["target"] = 1  # type: ignore[index]
    with pytest.raises(dataclasses.FrozenInstanceError):
        meta.user = "x"  # type: ignore[misc]


def test_meta_extra_is_a_copy():
    src = {"target": [0.4, 0.1]}
    meta = make_meta(extra=src)
    src["target"][0] = 99.0
    assert meta.extra["target"] == (0.4, 0.1)


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"user": ""}, "user"),
        ({"task": 3}, "task"),
        ({"model_id": ""}, "model_id"),
        ({"seed": 1.5}, "seed"),
        ({"seed": True}, "seed"),
        ({"origin": "lab"}, "origin"),
        ({"dt": 0.0}, "dt"),
        ({"dt": float("nan")}, "dt"),
        ({"extra": {"x": float("nan")}}, "extra"),
        ({"extra": {"x": object()}}, "extra"),
        ({"extra": [1, 2]}, "extra"),
    ],
)
def test_meta_rejects_bad_fields(changes, field):
    with pytest.raises(ValueError, match=rf"TrialMeta\.{field}"):
        make_meta(**changes)


def test_meta_accepts_numpy_seed_and_int_dt():
    meta = make_meta(seed=np.int64(3), dt=1)
    assert type(meta.seed) is int and meta.seed == 3
    assert type(meta.dt) is float and meta.dt == 1.0
    assert json.loads(meta.to_json())["seed"] == 3


def test_meta_from_dict_rejects_unknown_and_missing_keys():
    d = make_meta().to_dict()
    with pytest.raises(ValueError, match="no field"):
        TrialMeta.from_dict({**d, "colour": "red"})
    del d["user"]
    with pytest.raises(ValueError, match=r"missing field.*user"):
        TrialMeta.from_dict(d)


def test_trial_properties():
    t = make_trial(n=10, d=2, h=4)
    assert t.n_samples == 10
    assert t.n_dof == 2
    assert t.horizon == 4
    assert t.duration == pytest.approx(9 * 0.008, abs=1e-15)
    assert make_trial(h=None).horizon is None


def test_trial_arrays_are_float64_read_only_copies():
    pose = np.zeros((10, 2), dtype=np.float32)
    fault = [0] * 9 + [3]
    t = make_trial(pose=pose, fault=fault)
    assert t.pose.dtype == np.float64 and t.fault.dtype == np.int64
    pose[0, 0] = 5.0
    assert t.pose[0, 0] == 0.0  # a copy, not a view
    for arr in (t.time, t.pose, t.velocity, t.wrench, t.reference, t.prediction, t.fault):
        assert not arr.flags.writeable
    with pytest.raises(ValueError):
        t.pose[0, 0] = 1.0


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("wrench", np.zeros((10, 3)), r"Trial.wrench has shape \(10, 3\), expected \(10, 2\)"),
        ("velocity", np.zeros((9, 2)), r"Trial.velocity has shape \(9, 2\), expected \(10, 2\)"),
        ("reference", np.zeros(10), r"Trial.reference has shape \(10,\), expected \(10, 2\)"),
        ("prediction", np.zeros((10, 4, 3)), r"Trial.prediction has shape \(10, 4, 3\), expected \(10, H, 2\)"),
        ("intent", np.zeros((10, 1)), r"Trial.intent has shape"),
        ("effort_r", np.zeros((11, 2)), r"Trial.effort_r has shape"),
        ("fault", np.zeros(9, dtype=int), r"Trial.fault has shape \(9,\), expected \(10,\)"),
        ("fault", np.full(10, 0.5), r"Trial.fault must hold integer flags"),
        ("pose", np.zeros((10, 7)), r"Trial.pose has shape \(10, 7\)"),
        ("pose", np.zeros((10, 0)), r"Trial.pose has shape"),
        ("time", np.zeros((10, 1)), r"Trial.time has shape"),
        ("wrench", np.full((10, 2), np.nan), r"Trial.wrench has non-finite"),
        ("prediction", np.full((10, 4, 2), np.inf), r"Trial.prediction has infinite"),
        ("velocity", None, r"Trial.velocity is required"),
        ("alpha", np.full(9, 0.5), r"Trial.alpha has shape \(9,\), expected \(10,\)"),
        ("alpha", np.full(10, 1.5), r"Trial.alpha must lie in \[0, 1\]; alpha\[0\] = 1.5"),
        ("alpha", np.full(10, np.nan), r"Trial.alpha has non-finite"),
        ("meta", {"user": "x"}, r"Trial.meta must be a TrialMeta"),
    ],
)
def test_trial_rejects_bad_shapes(field, value, message):
    with pytest.raises(ValueError, match=message):
        make_trial(**{field: value})


def test_trial_time_must_strictly_increase():
    time = np.arange(10) * 0.008
    time[5] = time[4]
    with pytest.raises(ValueError, match=r"strictly increasing; time\[5\]"):
        make_trial(time=time)


def test_a_trial_whose_clock_is_not_its_period_is_refused():
    """A trial's time column and its meta.dt were never compared: a 500 Hz recording named 125 Hz (or a clock in ms)
    was cut into windows, a plant and rates four times off. The median step must lie within CLOCK_TOLERANCE of dt;
    jitter and gaps (a few late ticks, one dropped stretch) pass."""
    from coassist.data.trial import CLOCK_TOLERANCE

    with pytest.raises(ValueError, match=r"steps by 0.002 s .* meta.dt is 0.008 s: a trial of 500 Hz named 125 Hz"):
        make_trial(time=np.arange(10) * 0.002)
    with pytest.raises(ValueError, match=r"steps by 8 s"):
        make_trial(time=np.arange(10) * 8.0)  # milliseconds
    rng = np.random.default_rng(0)
    jitter = np.cumsum(0.008 * (1.0 + rng.uniform(-0.2, 0.2, 10)))
    jitter[6:] += 0.1  # a gap of 12 periods
    assert make_trial(time=jitter).n_samples == 10
    edge = np.arange(10) * 0.008 * CLOCK_TOLERANCE * 0.999
    assert make_trial(time=edge).n_samples == 10
    with pytest.raises(ValueError, match="steps by"):
        make_trial(time=np.arange(10) * 0.008 * CLOCK_TOLERANCE * 1.001)


def test_trial_allows_nan_prediction_rows():
    pred = np.zeros((10, 4, 2))
    pred[:3] = np.nan  # no prediction yet
    t = make_trial(prediction=pred)
    assert np.isnan(t.prediction[:3]).all() and (t.prediction[3:] == 0).all()


def test_equals_is_exact():
    a = make_trial()
    b = dataclasses.replace(a)  # re-validated copy
    assert a.equals(b)
    pose = a.pose.copy()
    pose[3, 1] = np.nextafter(pose[3, 1], np.inf)  # one ulp
    assert not a.equals(dataclasses.replace(a, pose=pose))
    assert not a.equals(dataclasses.replace(a, prediction=None))
    assert not a.equals(dataclasses.replace(a, meta=make_meta(seed=8)))


def test_replace_revalidates():
    t = make_trial()
    with pytest.raises(ValueError, match="Trial.wrench"):
        dataclasses.replace(t, wrench=np.zeros((10, 3)))
