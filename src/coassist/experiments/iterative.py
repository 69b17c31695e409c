"""Iterative training (thesis Algorithm 4.1, §4.1.1) and transfer learning (Algorithm 4.2, §4.1.2).

The bookkeeping only: which dataset is collected with which model in the loop, which
model each training starts from, when to stop, and how long each step took. The
world, the trainer and the evaluator are passed in, so the procedure is tested on
its own and runs unchanged in simulation or on a real robot::

    D_0 = collect(None)                      # ŷ_ref,h = y_ref,r (eq. 4.7)
    M_0 = train(D_0, start=None)             # eq. 4.8
    for k = 0, 1, …:
        D_{k+1} = collect(M_k)               # the robot predicts with M_k (eq. 4.9)
        M_{k+1} = train(D_{k+1}, start=M_k)  # eq. 4.11
        stop when |e_RMS^{k+1} − e_RMS^k| < tol   (eq. 4.12–4.13)

The e_RMS of model M_k is the one it achieves *in the loop*: measured on D_{k+1},
whose trials carry the prediction M_k made at every tick (D_0 carries the nominal
reference, so e_RMS of "no model" is the M0 assumption's). The thesis runs a fixed
number of iterations even after the criterion is met (§5.2.2); so does this code,
and it reports the iteration at which the criterion was first met.

Transfer (eq. 4.14): M_TL = train(D_TL, start=M_k) with the LSTM frozen; the same
small dataset also trains a model from scratch and fine-tunes all layers, so the
report can show what freezing buys.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from coassist._checks import is_integer

Model = TypeVar("Model")
Data = TypeVar("Data")

#: collect(iteration, model or None) -> dataset collected with that model in the loop
Collect = Callable[[int, "Model | None"], "Data"]
#: train(iteration, dataset, start model or None) -> model
Train = Callable[[int, "Data", "Model | None"], "Model"]
#: online_errors(dataset) -> {horizon: e_RMS [m]} of the predictions the loop used
OnlineErrors = Callable[["Data"], Mapping[int, float]]


@dataclass(frozen=True)
class Iteration(Generic[Model, Data]):
    """One step k of Algorithm 4.1."""

    k: int
    dataset: Data  # D_k, collected with M_{k−1} (None for k = 0) in the loop
    model: Model  # M_k, trained on D_k starting from M_{k−1}
    collect_s: float
    train_s: float
    loop_errors: Mapping[int, float]  # e_RMS per horizon of the predictions used while collecting D_k


@dataclass(frozen=True)
class IterativeResult(Generic[Model, Data]):
    iterations: tuple[Iteration, ...]
    final_errors: Mapping[int, float]  # e_RMS of the last model in the loop (one extra collection)
    final_dataset: Data
    tol: float
    criterion_horizon: int
    converged_at: int | None  # first k with |e^{k+1} − e^k| < tol, None if never
    deltas: tuple[float, ...] = field(default=())  # |e^{k+1} − e^k| for successive loop models

    @property
    def models(self) -> tuple:
        return tuple(it.model for it in self.iterations)

    def error_of_model(self, k: int) -> Mapping[int, float]:
        """e_RMS per horizon of M_k in the loop (k = −1: no model, the nominal assumption)."""
        if k == -1:
            return self.iterations[0].loop_errors
        if k + 1 < len(self.iterations):
            return self.iterations[k + 1].loop_errors
        if k + 1 == len(self.iterations):
            return self.final_errors
        raise IndexError(f"no model M_{k}")


def iterative_training(
    collect: Collect,
    train: Train,
    online_errors: OnlineErrors,
    *,
    iterations: int = 4,
    tol: float = 1e-3,
    criterion_horizon: int = 50,
    progress: Callable[[str], None] | None = None,
) -> IterativeResult:
    """Run Algorithm 4.1 for ``iterations`` models M_0 … M_{iterations−1}.

    ``tol`` [m] is the stop criterion on e_RMS at ``criterion_horizon`` samples (eq. 4.13);
    like the thesis, all iterations run and the first k that meets it is reported.
    Each model is then measured in the loop on the next dataset; the last model on one
    extra collection, so every model has an in-loop error.
    """
    if not is_integer(iterations) or iterations < 1:
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    if not tol > 0:
        raise ValueError(f"tol must be > 0, got {tol!r}")
    say = progress or (lambda message: None)
    steps: list[Iteration] = []
    model = None
    for k in range(iterations):
        say(
            f"iteration {k}: collecting D_{k} with {'M_' + str(k - 1) if model is not None else 'the nominal assumption'}"
        )
        t0 = time.perf_counter()
        dataset = collect(k, model)
        collect_s = time.perf_counter() - t0
        errors = dict(online_errors(dataset))
        if criterion_horizon not in errors:
            raise ValueError(
                f"online_errors gave no e_RMS at criterion_horizon={criterion_horizon} (got {sorted(errors)})"
            )
        say(f"iteration {k}: training M_{k} on D_{k}" + (f" from M_{k - 1}" if model is not None else " from scratch"))
        t0 = time.perf_counter()
        model = train(k, dataset, model)
        steps.append(Iteration(k, dataset, model, collect_s, time.perf_counter() - t0, errors))
    say(f"measuring M_{iterations - 1} in the loop")
    final_dataset = collect(iterations, model)
    final_errors = dict(online_errors(final_dataset))
    # in-loop error of M_k, k = 0 … K−1
    series = [steps[k + 1].loop_errors[criterion_horizon] for k in range(iterations - 1)]
    series.append(final_errors[criterion_horizon])
    deltas = tuple(abs(b - a) for a, b in zip(series, series[1:]))
    converged_at = next((k for k, d in enumerate(deltas) if d < tol), None)
    return IterativeResult(tuple(steps), final_errors, final_dataset, tol, criterion_horizon, converged_at, deltas)


@dataclass(frozen=True)
class TransferOutcome(Generic[Model]):
    """One transfer target (a new trajectory, users or object) and its candidate models."""

    name: str
    collect_s: float
    models: Mapping[str, Model]  # "transfer" (LSTM frozen), "scratch", "finetune_all"
    train_s: Mapping[str, float]


TRANSFER_STARTS = ("transfer", "scratch", "finetune_all")


def transfer_learning(
    name: str,
    collect: Callable[[], Data],
    train: Callable[[str, Data], Model],
    *,
    starts: tuple[str, ...] = TRANSFER_STARTS,
) -> tuple[TransferOutcome, Data]:
    """Algorithm 4.2 for one target: collect D_TL once, then train each starting point on it.

    ``train(start, dataset)`` is called with start ∈ ``starts``: "transfer" freezes the LSTM
    of the previous model and trains the FC layers, "scratch" ignores the previous model,
    "finetune_all" starts from it and trains every layer.
    """
    unknown = [s for s in starts if s not in TRANSFER_STARTS]
    if unknown or not starts:
        raise ValueError(f"starts must be a non-empty subset of {TRANSFER_STARTS}, got {starts!r}")
    t0 = time.perf_counter()
    dataset = collect()
    collect_s = time.perf_counter() - t0
    models, times = {}, {}
    for start in starts:
        t0 = time.perf_counter()
        models[start] = train(start, dataset)
        times[start] = time.perf_counter() - t0
    return TransferOutcome(name, collect_s, models, times), dataset
