"""Bookkeeping of Algorithm 4.1 and 4.2 with fake worlds: who collects with what, who starts from what."""

import pytest

from coassist.experiments import iterative
from coassist.experiments.iterative import TRANSFER_STARTS, iterative_training, transfer_learning


class FakeWorld:
    """Models are strings; a dataset records the model in the loop; errors fall then settle."""

    def __init__(self, errors_by_model):
        self.errors_by_model = errors_by_model
        self.calls = []

    def collect(self, k, model):
        self.calls.append(("collect", k, model))
        return {"k": k, "model_in_loop": model}

    def train(self, k, dataset, start):
        self.calls.append(("train", k, dataset["k"], start))
        return f"M{k}"

    def online_errors(self, dataset):
        e = self.errors_by_model[dataset["model_in_loop"]]
        return {5: e / 4, 50: e}


def test_algorithm_4_1_collects_with_the_previous_model_and_starts_from_it():
    world = FakeWorld({None: 0.10, "M0": 0.05, "M1": 0.045, "M2": 0.0449, "M3": 0.0448})
    result = iterative_training(world.collect, world.train, world.online_errors, iterations=4, tol=1e-3)
    assert world.calls == [
        ("collect", 0, None),
        ("train", 0, 0, None),
        ("collect", 1, "M0"),
        ("train", 1, 1, "M0"),
        ("collect", 2, "M1"),
        ("train", 2, 2, "M1"),
        ("collect", 3, "M2"),
        ("train", 3, 3, "M2"),
        ("collect", 4, "M3"),
    ]
    assert result.models == ("M0", "M1", "M2", "M3")
    assert result.error_of_model(-1)[50] == 0.10
    assert [result.error_of_model(k)[50] for k in range(4)] == [0.05, 0.045, 0.0449, 0.0448]
    assert result.deltas == pytest.approx((0.005, 0.0001, 0.0001))
    assert result.converged_at == 1  # |e(M2) − e(M1)| = 1e-4 < 1e-3: the first k meeting eq. 4.13
    with pytest.raises(IndexError):
        result.error_of_model(4)


def test_never_converging_is_reported_as_none():
    world = FakeWorld({None: 0.1, "M0": 0.08, "M1": 0.06})
    result = iterative_training(world.collect, world.train, world.online_errors, iterations=2, tol=1e-3)
    assert result.converged_at is None and result.deltas == pytest.approx((0.02,))


class FakeClock:
    """time.perf_counter for the module under test: advanced only by the fake steps."""

    def __init__(self):
        self.now = 1000.0

    def perf_counter(self):
        return self.now


def test_timings_are_recorded_per_step(monkeypatch):
    # Each step takes a known time on a fake clock: collect k takes 3 + k s, train k
    # 10 + k s, and the evaluation 100 s, which belongs to neither.
    clock = FakeClock()
    monkeypatch.setattr(iterative, "time", clock)
    world = FakeWorld({None: 0.1, "M0": 0.08, "M1": 0.07})

    def collect(k, model):
        clock.now += 3.0 + k
        return world.collect(k, model)

    def train(k, dataset, start):
        clock.now += 10.0 + k
        return world.train(k, dataset, start)

    def online_errors(dataset):
        clock.now += 100.0
        return world.online_errors(dataset)

    result = iterative_training(collect, train, online_errors, iterations=2)
    assert [(s.collect_s, s.train_s) for s in result.iterations] == [(3.0, 10.0), (4.0, 11.0)]
    assert result.deltas == pytest.approx((0.01,))


def test_transfer_timings_are_per_start(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(iterative, "time", clock)
    cost = {"transfer": 2.0, "scratch": 30.0, "finetune_all": 7.0}

    def collect():
        clock.now += 5.0
        return "D_TL"

    def train(start, data):
        clock.now += cost[start]
        return start

    outcome, _ = transfer_learning("z", collect, train)
    assert outcome.collect_s == 5.0 and dict(outcome.train_s) == cost


@pytest.mark.parametrize(
    "kwargs, message",
    [(dict(iterations=0), "iterations"), (dict(tol=0), "tol"), (dict(criterion_horizon=7), "criterion_horizon=7")],
)
def test_arguments_are_checked(kwargs, message):
    world = FakeWorld({None: 0.1, "M0": 0.08})
    with pytest.raises(ValueError, match=message):
        iterative_training(world.collect, world.train, world.online_errors, **kwargs)


def test_transfer_collects_once_and_trains_every_start_on_the_same_data():
    collected, trained = [], []

    def collect():
        collected.append(1)
        return "D_TL"

    def train(start, data):
        trained.append((start, data))
        return f"model-{start}"

    outcome, data = transfer_learning("z", collect, train)
    assert collected == [1] and data == "D_TL"
    assert trained == [(s, "D_TL") for s in TRANSFER_STARTS]
    assert outcome.models == {s: f"model-{s}" for s in TRANSFER_STARTS}
    with pytest.raises(ValueError, match="starts"):
        transfer_learning("z", collect, train, starts=("freeze_everything",))
