"""The shared validation layer: NumPy integers are integers, bool is not, messages name the field."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from coassist._checks import (
    check_int,
    check_int_at_least,
    check_optional_int,
    check_positive_scalar,
    is_integer,
    is_real_number,
)

INTEGERS = [0, 7, -3, 2**70, np.int64(7), np.int32(-3), np.uint8(255), np.intp(1)]
NOT_INTEGERS = [True, False, np.bool_(True), 7.0, np.float64(7.0), "7", None, [7], np.array(7), 1 + 0j]


@pytest.mark.parametrize("value", INTEGERS, ids=repr)
def test_python_and_numpy_integers_are_integers(value):
    assert is_integer(value)
    assert is_real_number(value)


@pytest.mark.parametrize("value", NOT_INTEGERS, ids=repr)
def test_bool_floats_strings_and_arrays_are_not_integers(value):
    assert not is_integer(value)


@pytest.mark.parametrize("value", [1.5, np.float32(0.25), np.float64(-2.0), float("inf"), 3, np.int16(3)], ids=repr)
def test_real_numbers(value):
    assert is_real_number(value)


@pytest.mark.parametrize("value", [True, np.bool_(False), "1.5", None, 1 + 0j, np.array([1.0])], ids=repr)
def test_not_real_numbers(value):
    assert not is_real_number(value)


def test_check_int_returns_a_python_int():
    out = check_int(np.int64(12), "train.epochs", 1)
    assert out == 12 and type(out) is int  # JSON-serialisable, unlike np.int64
    assert type(check_int_at_least(np.uint16(3), "n", 0)) is int


@pytest.mark.parametrize("value", [True, False, np.bool_(True)], ids=repr)
def test_check_int_rejects_bool_naming_the_field(value):
    with pytest.raises(ValueError, match=r"^TrialSpec\.seed must be an integer, got "):
        check_int(value, "TrialSpec.seed", 0)


@pytest.mark.parametrize(
    ("value", "minimum", "maximum", "message"),
    [
        (0, 1, None, "horizon must be >= 1, got 0"),
        (np.int64(-1), 0, None, "seed must be >= 0, got -1"),
        (6, 0, 5, "seed must be <= 5, got 6"),
        (2.0, None, None, "must be an integer, got 2.0"),
        ("3", 0, None, "must be an integer, got '3'"),
        (None, 0, None, "must be an integer, got None"),
    ],
)
def test_check_int_errors(value, minimum, maximum, message):
    name = message.split(" must")[0] if message.split(" ")[0] in ("horizon", "seed") else "x"
    with pytest.raises(ValueError, match=message):
        check_int(value, name, minimum, maximum)


@pytest.mark.parametrize(
    ("value", "minimum", "maximum"), [(1, 1, None), (5, 0, 5), (np.int8(-4), None, None), (0, 0, 0)]
)
def test_check_int_bounds_are_inclusive(value, minimum, maximum):
    assert check_int(value, "x", minimum, maximum) == int(value)


def test_check_int_at_least_keeps_its_messages():
    assert check_int_at_least(np.int64(1), "game.horizon", 1) == 1
    with pytest.raises(ValueError, match=r"^game\.horizon must be >= 1, got 0$"):
        check_int_at_least(0, "game.horizon", 1)
    with pytest.raises(ValueError, match=r"^game\.horizon must be an integer, got True$"):
        check_int_at_least(True, "game.horizon", 1)


def test_check_optional_int():
    assert check_optional_int(None, "seed") is None
    out = check_optional_int(np.int64(4), "seed", 0)
    assert out == 4 and type(out) is int
    with pytest.raises(ValueError, match=r"^seed must be an integer or None, got True$"):
        check_optional_int(True, "seed")
    with pytest.raises(ValueError, match=r"^seed must be >= 0, got -2$"):
        check_optional_int(-2, "seed", 0)


def test_check_positive_scalar():
    assert check_positive_scalar(np.float32(0.5), "dt") == 0.5
    assert check_positive_scalar(np.int64(2), "dt") == 2.0
    for bad, message in (
        (0.0, "dt must be a finite number > 0"),
        (float("nan"), "finite number > 0"),
        (-1, "> 0, got -1"),
        ("abc", "dt must be a number, got 'abc'"),
        (True, "dt must be a number, got True"),  # float(True) is 1: a one-second period
        (np.bool_(True), "dt must be a number, got np.True_|dt must be a number, got True"),
    ):
        with pytest.raises(ValueError, match=message):
            check_positive_scalar(bad, "dt")


@pytest.mark.parametrize("bad", [True, [True, True], np.array([True, False])], ids=repr)
def test_gains_that_are_no_numbers_are_refused_naming_the_field(bad):
    from coassist.config import ImpedanceParameters
    from coassist.model import ImpedanceModel

    with pytest.raises(ValueError, match="impedance.M must be a list of numbers"):
        ImpedanceParameters(M=bad if isinstance(bad, list) else (bad, bad))
    with pytest.raises(ValueError, match="^M must be a (matrix of numbers|number)"):
        ImpedanceModel(bad, np.diag([100.0, 100.0]), 0, 0.008)
    assert ImpedanceParameters(M=(np.int64(3), 4)).M == (3.0, 4.0)  # integers are numbers


def _realtime_config(**kw):
    from coassist.intent.realtime import RealtimeConfig

    return RealtimeConfig(**kw)


def _network_config(**kw):
    from coassist.intent import NetworkConfig

    return NetworkConfig(**{"n_features": 8, "n_outputs": 100, **kw})


def _trial_spec(**kw):
    from coassist.sim import TrialSpec

    return TrialSpec(task="linear", **kw)


def _force_sensor(**kw):
    from coassist.scenario.objects import ForceSensor

    return ForceSensor(**kw)


def _play_config(**kw):
    from coassist.play.session import PlayConfig

    return PlayConfig(user="me", out=Path("unused"), **kw)  # validated only: nothing is written


#: Configs that used to validate integers by hand, some rejecting NumPy integers: (make, field, name in the message).
CONFIG_FIELDS = [
    (_realtime_config, "threads", "realtime.threads"),
    (_realtime_config, "max_hold", "realtime.max_hold"),
    (_realtime_config, "max_age", "realtime.max_age"),
    (_network_config, "hidden", "network.hidden"),
    (_network_config, "lstm_layers", "network.lstm_layers"),
    (_trial_spec, "user", "TrialSpec.user"),
    (_trial_spec, "seed", "TrialSpec.seed"),
    (_force_sensor, "zero_samples", "ForceSensor.zero_samples"),
    (_play_config, "seed", "PlayConfig.seed"),
]


@pytest.mark.parametrize(("make", "field", "name"), CONFIG_FIELDS, ids=lambda x: x if isinstance(x, str) else "")
def test_configs_accept_numpy_integers_and_store_python_ints(make, field, name):
    config = make(**{field: np.int64(2)})
    value = getattr(config, field)
    assert value == 2 and type(value) is int


@pytest.mark.parametrize(("make", "field", "name"), CONFIG_FIELDS, ids=lambda x: x if isinstance(x, str) else "")
def test_configs_reject_bool_naming_the_field(make, field, name):
    with pytest.raises(ValueError, match="^" + re.escape(f"{name} must be an integer")):
        make(**{field: True})


def test_functions_accept_numpy_integers():
    from coassist.scenario.operator import operator_profile
    from coassist.scenario.reference_intents import NominalIntent
    from coassist.sim.collect import dataset_specs

    assert operator_profile(np.int64(3), np.int64(1)) == operator_profile(3, 1)
    assert NominalIntent(np.int32(5)).horizon == 5
    with pytest.raises(ValueError, match="^population_seed must be an integer, got True"):
        operator_profile(1, True)
    specs = dataset_specs(
        controller="manual", users=[0], tasks=["linear"], objects=["handle"], trials=np.int64(2), seed=np.int64(5)
    )
    assert [s.seed for s in specs] == [5, 6]
    with pytest.raises(ValueError, match="^trials must be an integer, got True"):
        dataset_specs(controller="manual", users=[0], tasks=["linear"], objects=["handle"], trials=True, seed=0)
