"""Training the intent network (thesis §5.2.2, Algorithms 4.1 and 4.2).

One function, :func:`train_model`, does every kind of training; where it starts from
is configuration (``TrainConfig.init``):

- ``"scratch"``: Xavier init, scalers fitted on this training split (M_0, eq. 4.8);
- ``"resume:<model>"``: all weights from <model>, all trained, its training history
  continued (M_{k+1} from M_k, eq. 4.11);
- ``"finetune:<model>"``: the same, all layers trained, a fresh history (the "fine-tune
  everything" alternative to transfer);
- ``"transfer:<model>"``: the LSTM frozen, only the FC layers trained (eq. 4.14,
  Algorithm 4.2).

A model started from another keeps its window, features, dt and scaling ranges: its
weights only mean something on inputs scaled the same way.

The loss is the MSE (eq. 5.3) on scaled targets (a network with several hypotheses:
:func:`choice_loss`, the best hypothesis' MSE plus its chooser's cross-entropy); the learning rate decays
geometrically from ``lr`` to ``lr · lr_final_ratio`` over the whole run. Given the
seed and the thread count, a run is deterministic. The library leaves torch's global
state alone: the initial weights come from a ``torch.Generator`` seeded with ``seed``,
the batch order from a NumPy generator, and the caller (the CLI) sets the thread count.

What to train with (:class:`~coassist.intent.presets.TrainConfig`, the named presets
:data:`~coassist.intent.presets.MODEL_PRESETS`) lives in :mod:`coassist.intent.presets`; the
checkpoint an interrupted run leaves, in :mod:`coassist.intent.checkpoint`. This module holds
the training itself, the starting model (:func:`build_model`) and the finished model's folder
(:func:`write_model`, :func:`plot_losses`).
"""

from __future__ import annotations

import contextlib
import copy
import functools
import math
import os
import shutil
import time
from collections.abc import Callable, Collection, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import IO, Any

import numpy as np
import torch
from torch import nn

from coassist._io import OutputLock, partial_folder, save_figure
from coassist._progress import progress_bar
from coassist.intent.baselines import UNTUNED_RIDGE_ALPHA, RidgeBaseline, fit_tuned_baselines, tune_ridge_alpha
from coassist.intent.batches import DeviceWindows
from coassist.intent.checkpoint import (
    CHECKPOINT_JSON,
    check_binding,
    checkpoint_files,
    read_checkpoint,
    restore_checkpoint,
    trials_digest,
)
from coassist.intent.features import WindowConfig, WindowSet, feature_names, scale_targets, split_trials
from coassist.intent.model import IntentModel, lineage_train_trials, load_model, save_model
from coassist.intent.network import IntentNet
from coassist.intent.presets import Preset, TrainConfig
from coassist.intent.trials import LabeledTrial, content_digest

__all__ = [
    "CHOICE_RELAX",
    "build_model",
    "choice_loss",
    "plot_losses",
    "train_model",
    "write_model",
]


def _optimizer(name: str, params: list[nn.Parameter], lr: float, weight_decay: float) -> torch.optim.Optimizer:
    # fused: one kernel per step for all parameters (CPU and CUDA), instead of ~10 small ops per
    # tensor. Timed once for an LSTM 2 × 64 at batch 64 on 2 threads: the optimizer step took
    # 0.45 ms of a 7.8 ms training step, fused 0.12 ms.
    if name == "adam":
        return torch.optim.Adam(params, lr=lr, weight_decay=weight_decay, fused=True)
    if name == "adamw":
        return torch.optim.AdamW(params, lr=lr, weight_decay=weight_decay, fused=True)
    if name == "rmsprop":
        return torch.optim.RMSprop(params, lr=lr, weight_decay=weight_decay)
    return torch.optim.SGD(params, lr=lr, momentum=0.9, weight_decay=weight_decay)


def _common_dt(trials: Sequence[LabeledTrial]) -> float:
    dts = np.array([lt.trial.meta.dt for lt in trials])
    dt = float(np.median(dts))
    bad = [lt.id for lt in trials if not math.isclose(lt.trial.meta.dt, dt, rel_tol=0.01)]
    if bad:
        raise ValueError(f"trials sampled at different periods (median {dt:g} s): {bad[:5]}")
    # Real recordings have a median period of 7.99–8.01 ms: round to the µs.
    return round(dt, 6)


#: tune_ridge_alpha's (α, record) for a model's training trials, kept so the baselines reuse it.
_Tuning = tuple[float, dict[str, Any]] | None


def build_model(preset: Preset, trials: Sequence[LabeledTrial], config: TrainConfig) -> IntentModel:
    """The starting model: fresh (scalers fitted on the training split, the skip set to the
    ridge solution) or loaded from ``init``."""
    return _build_model(preset, trials, config)[0]


def _build_model(
    preset: Preset, trials: Sequence[LabeledTrial], config: TrainConfig, *, fit_linear_skip: bool = True
) -> tuple[IntentModel, _Tuning]:
    """:func:`build_model`, and the ridge α search run for its skip (None when none ran).

    ``fit_linear_skip=False``: a linear preset's skip is left as initialised, for
    :func:`train_model`, which sets it to the tuned ridge in closed form afterwards."""
    mode, path = config.start
    d = trials[0].trial.n_dof
    dt = _common_dt(trials)
    if mode != "scratch":
        return load_model(path, features=feature_names(d), dt=dt), None
    ids = [lt.id for lt in trials]
    train_idx, _ = split_trials(ids, config.test_fraction, config.seed)
    ws = WindowSet([trials[i].trial for i in train_idx], preset.window, dt, stride=config.fit_stride)
    in_scaler, out_scaler = ws.fit_scalers()
    net = IntentNet(preset.network(d), generator=torch.Generator().manual_seed(config.seed))
    tuning = None
    if net.skip is not None and (fit_linear_skip or not net.is_linear):
        tuning = _fit_skip(net, trials, train_idx, ws, in_scaler, out_scaler, config)
    return IntentModel(net, preset.window, in_scaler, out_scaler, dt), tuning


def _fit_skip(
    net: IntentNet,
    trials: Sequence[LabeledTrial],
    train_idx: Sequence[int],
    ws: WindowSet,
    in_scaler,
    out_scaler,
    config: TrainConfig,
) -> _Tuning:
    """Set the network's linear skip to the ridge solution on ``ws`` (α from :func:`_skip_alpha`);
    returns the α search when one ran."""
    alpha, tuning = _skip_alpha(trials, train_idx, ws.window, ws.dt, in_scaler, out_scaler, config)
    ridge = RidgeBaseline.fit(ws, in_scaler, out_scaler, alpha)
    net.init_skip(torch.from_numpy(ridge.W.T.astype(np.float32)), torch.from_numpy(ridge.b.astype(np.float32)))
    return tuning


def _skip_alpha(
    trials: Sequence[LabeledTrial],
    train_idx: Sequence[int],
    window: WindowConfig,
    dt: float,
    in_scaler,
    out_scaler,
    config: TrainConfig,
) -> tuple[float, _Tuning]:
    """The α of the ridge the skip starts from: skip_alpha, else ridge_alpha, else tuned on
    validation trials (then also the search: the baselines' ridge is tuned the same way)."""
    for alpha in (config.skip_alpha, config.ridge_alpha):
        if alpha is not None:
            return alpha, None
    if len(train_idx) < 2:
        return UNTUNED_RIDGE_ALPHA, None  # nothing to validate on
    tuning = tune_ridge_alpha(
        [trials[i].trial for i in train_idx],
        [trials[i].id for i in train_idx],
        window,
        dt,
        in_scaler,
        out_scaler,
        seed=config.seed,
        stride=config.train_stride,
    )
    return tuning[0], tuning


def _numpy_batch(
    model: IntentModel, ws: WindowSet, sel: np.ndarray, signs: np.ndarray | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """The NumPy reference of :meth:`DeviceWindows.batch` (how batches were cut before issue 19),
    kept for the tests and the benchmark only: scaled inputs (B, steps, 4·d) and targets (B, H·d)."""
    x, y = ws.raw_inputs(sel), ws.raw_targets(sel)
    if signs is not None:
        x = x * np.tile(signs, 4)[:, None, :]
        y = y * signs[:, None, :]
    return model.scale_inputs(x), torch.from_numpy(scale_targets(model.target_scaler, y).astype(np.float32))


class _Windows:
    """Batches of (network input, scaled target) for one split, cut on the training device.

    With ``frozen_lstm`` the LSTM's output is computed once per window and cached: the
    frozen LSTM maps a window to the same features every epoch, so transfer learning
    (Algorithm 4.2) trains the FC layers on cached features, exactly and much faster.
    """

    def __init__(
        self, model: IntentModel, ws: WindowSet, frozen_lstm: bool, chunk: int = 1024, device: str = "cpu"
    ) -> None:
        self.model, self.cached, self.device = model, frozen_lstm, torch.device(device)
        self.windows = DeviceWindows(ws, model.input_scaler, model.target_scaler, self.device)
        if frozen_lstm:
            hs, xs, ys = [], [], []
            with torch.no_grad():
                for sel in self.chunks(chunk):
                    x, y = self.windows.batch(sel)
                    hs.append(model.net.lstm_features(x))
                    xs.append(x.flatten(1) if model.net.skip is not None else None)
                    ys.append(y)
            self.h = torch.cat(hs)
            self.x = torch.cat(xs) if model.net.skip is not None else None
            self.y = torch.cat(ys)

    def __len__(self) -> int:
        return len(self.windows)

    def chunks(self, size: int) -> list[torch.Tensor]:
        """All window indices in order, where the windows are cut, in about equal chunks of at most ``size``."""
        idx = torch.arange(len(self), device=self.windows.device)
        return list(idx.tensor_split(max(1, math.ceil(len(self) / size))))

    def loss(self, sel: torch.Tensor, reduction: str = "mean", signs: torch.Tensor | None = None) -> torch.Tensor:
        """The MSE of the windows ``sel`` (int64 on the device); ``signs`` (B, d) mirror them.

        A network with hypotheses in training mode: :func:`choice_loss` instead (in eval mode, the
        MSE of its output, the mixture it predicts, comparable with a one-hypothesis network's)."""
        net = self.model.net
        if self.cached:
            sel = sel.to(self.y.device)  # no-op but on MPS, where the windows are cut on the CPU
            h, x_flat, y = self.h[sel], None if self.x is None else self.x[sel], self.y[sel]
        else:
            x, y = self.windows.batch(sel, signs)
            h, x_flat = net.lstm_features(x), x.flatten(1)
        if net.chooser is not None and net.training:
            return choice_loss(*net.forward_hypotheses(h, x_flat), y)
        return nn.functional.mse_loss(net.forward_head(h, x_flat), y, reduction=reduction)


#: The share of a batch's gradient the hypotheses that did not win get, together (relaxed winner-takes-all,
#: Rupprecht et al. 2017, *Learning in an uncertain world*): without it a hypothesis that never wins never moves.
CHOICE_RELAX = 0.05


def choice_loss(ys: torch.Tensor, logits: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Multiple-choice learning's loss: each window's best hypothesis' MSE (the others get
    :data:`CHOICE_RELAX` of the weight), plus the chooser's cross-entropy on which one was best.

    ys (B, K, O), logits (B, K), y (B, O). The chooser reads detached features
    (:meth:`IntentNet.forward_hypotheses`), so the two terms train disjoint parameters."""
    err = ((ys - y.unsqueeze(1)) ** 2).mean(dim=2)  # (B, K)
    best = err.detach().argmin(dim=1)
    k = ys.shape[1]
    weight = torch.full_like(err, CHOICE_RELAX / (k - 1))
    weight.scatter_(1, best.unsqueeze(1), 1.0 - CHOICE_RELAX)
    return (weight * err).sum(dim=1).mean() + nn.functional.cross_entropy(logits, best)


@torch.no_grad()
def _mean_loss(data: _Windows | None, batch: int = 1024) -> float | None:
    if data is None:
        return None
    data.model.net.eval()
    total, n = 0.0, 0
    for sel in data.chunks(batch):
        total += float(data.loss(sel, reduction="sum")) / data.model.net.config.n_outputs
        n += sel.numel()
    return total / n


def _epoch_order(
    rng: np.random.Generator, n: int, batch_size: int, n_dof: int
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """An epoch's window order (n,) and mirror signs (n, d) of ±1 (None when ``n_dof`` is 0),
    drawn as the batches were always drawn: the permutation, then each batch's signs in
    turn, so the generator's stream (and a checkpoint's state of it) is the same. One
    host→device copy per epoch, not per batch."""
    perm = torch.from_numpy(rng.permutation(n))
    if not n_dof:
        return perm, None
    signs = [rng.choice([-1.0, 1.0], size=(min(batch_size, n - a), n_dof)) for a in range(0, n, batch_size)]
    return perm, torch.from_numpy(np.concatenate(signs))


def _split_windows(
    split: str, trials: Sequence[LabeledTrial], idx: Sequence[int], window: WindowConfig, dt: float, stride: int
) -> WindowSet:
    """The windows of one split's trials; a refusal names the split (and its trials)."""
    try:
        return WindowSet([trials[i].trial for i in idx], window, dt, stride=stride)
    except ValueError as exc:
        names = ", ".join(trials[i].id for i in idx[:3]) + (", …" if len(idx) > 3 else "")
        raise ValueError(f"the {split} split ({len(idx)} trial{'s' * (len(idx) != 1)}: {names}): {exc}") from None


def _check_finite(record: dict[str, Any]) -> None:
    """Refuse an epoch whose losses are not finite: the run diverged (nothing of it is worth keeping)."""
    for key in ("train_loss", "test_loss"):
        value = record[key]
        if value is not None and not math.isfinite(value):
            raise ValueError(
                f"training diverged at epoch {record['epoch']} ({key.replace('_', ' ')} {value}); lower train.lr"
            )


def train_model(
    trials: Sequence[LabeledTrial],
    preset: Preset,
    config: TrainConfig,
    *,
    progress: bool = False,
    on_epoch: Callable[[dict[str, Any]], None] | None = None,
    checkpoint_to: str | os.PathLike[str] | None = None,
    given: Collection[str] = (),
) -> IntentModel:
    """Train on ``trials`` (split by trial) and return the model, its sidecar info filled.

    ``preset`` gives window and sizes for ``init="scratch"``; for the other modes they
    come from the starting model. ``on_epoch`` gets each epoch's record
    ``{epoch, train_loss, test_loss, lr, seconds}`` (losses: MSE on scaled targets).

    ``checkpoint_to``: after every epoch, a model folder is written to
    :func:`coassist._io.partial_folder` of it (``.<name>.partial`` beside it, swapped in
    whole) with a checkpoint: the optimizer's state, the learning-rate schedule's
    position, the batch-order generator's state and the epoch; :func:`write_model`
    removes it. ``init="resume:<checkpoint_to>"`` (or of the partial folder itself)
    then *continues the interrupted run* exactly: same trials, the run's own
    training configuration (only ``threads`` and ``device`` are the caller's), epochs
    ``k+1 … epochs``; a run stopped after epoch k and continued ends with the same
    weights as one never stopped. ``resume:`` of a finished model starts a new stage
    instead (Algorithm 4.1: ``epochs`` more, fresh optimizer, the history continued).
    ``given``: the :class:`TrainConfig` fields the caller set on purpose (the CLI: the options
    typed); continuing an interrupted run with one of them other than the run's own is refused.
    The network has no dropout, so torch draws no random numbers after initialisation
    (its weights come from a generator seeded in :func:`build_model`): nothing of torch's
    to save. Torch's thread count is the caller's to set (``torch.set_num_threads``).
    """
    if not trials:
        raise ValueError("no trials to train on")
    t_start = time.perf_counter()
    mode, base_path = config.start
    reading: contextlib.AbstractContextManager[Any] = contextlib.nullcontext()
    if mode == "resume" and base_path is not None and (partial_folder(base_path) / CHECKPOINT_JSON).is_file():
        # An interrupted run on that folder: newer than it. Another output's (resume:A -o B) is read under A's
        # lock, which the run writing A holds from start to end (the CLI's, a study's): a reader is refused while
        # it goes on, rather than read its partial folder as the next epoch is swapped in (or write_model removes
        # it). Not the partial folder's own lock: that one is taken for each epoch's save, which would fail if a
        # reader held it. Not for resume:A -o A: the caller holds A's lock (taken again under another spelling
        # of the path, the flock would refuse the process its own lock).
        if checkpoint_to is None or os.path.realpath(base_path) != os.path.realpath(checkpoint_to):
            reading = OutputLock(base_path)
        base_path = str(partial_folder(base_path))
    with reading:
        base, tuning = _build_model(
            preset,
            trials,
            replace(config, init=f"resume:{base_path}") if mode == "resume" else config,
            fit_linear_skip=False,
        )
        ckpt = read_checkpoint(Path(base_path)) if mode == "resume" and not base.info.get("finished", True) else None
    ids = [lt.id for lt in trials]
    # what the trials hold, for a checkpoint to be continued only on them (hashed only where one is read or kept)
    contents = trials_digest(trials) if ckpt is not None or checkpoint_to is not None else ""
    if ckpt is not None:
        history0 = base.info.get("training_history") or [{}]
        check_binding(ckpt, Path(base_path), base.weights_sha256, history0[-1].get("epoch"))
        if ckpt["trials"] != ids:
            raise ValueError(
                f"{base_path} is an interrupted run on {len(ckpt['trials'])} other trials; continue it with the same "
                "data, or start a new stage from it with finetune:"
            )
        if ckpt["trials_sha256"] != contents:
            raise ValueError(
                f"{base_path} is an interrupted run on other data under the same trial ids (a dataset collected "
                "again?); continue it with the data it began on, or start a new stage from it with finetune:"
            )
        try:
            own = replace(TrainConfig(**ckpt["train_config"]), threads=config.threads, device=config.device)
        except TypeError as exc:  # a checkpoint of another coassist version
            raise ValueError(
                f"{base_path}: checkpoint's training configuration is not this version's ({exc})"
            ) from None
        except ValueError as exc:  # its values refused (TrainConfig names the field, not an option given here)
            raise ValueError(f"{base_path}: unusable checkpoint (its train_config: {exc})") from None
        for name in given:  # the run continues on its own configuration: one asked for otherwise is refused
            if name not in ("init", "threads", "device") and getattr(config, name) != getattr(own, name):
                raise ValueError(
                    f"train.{name} {getattr(config, name)} asked, but {base_path} is an interrupted run with train.{name} "
                    f"{getattr(own, name)}: continue it without train.{name} (it keeps its own), or start a new stage "
                    "from it with finetune:"
                )
        config = own
        if ckpt["epoch"] > config.epochs:  # epochs done of this run: at most its own
            raise ValueError(
                f"{base_path}: unusable checkpoint (epoch {ckpt['epoch']} done of a run of {config.epochs}); start a "
                "new stage from it with finetune:"
            )
        mode = config.start[0]  # the interrupted run's own mode (a transfer stays frozen)
    model = IntentModel(copy.deepcopy(base.net), base.window, base.input_scaler, base.target_scaler, base.dt, {})
    net, window, dt = model.net, model.window, model.dt

    train_idx, test_idx = split_trials(ids, config.test_fraction, config.seed)
    # Trials the starting model or its parent trained on are not held out: they go to the training side (a
    # continued run: its own split, as it began), and so do copies of them under other names (their contents'
    # digests). Where none of them (and no copy of a training trial) is among the trials, the split is as it was.
    digests = [content_digest(lt.trial) for lt in trials]
    if ckpt is not None:
        ancestors = set(base.info.get("train_trials") or ())
        ancestor_contents = set(base.info.get("train_digests") or ())
    elif mode != "scratch":
        ancestors = lineage_train_trials(base.info)
        ancestor_contents = lineage_train_trials(base.info, "train_digests")
    else:
        ancestors, ancestor_contents = set(), set()
    # and a copy of a training-side trial within these trials (a dataset appended to twice) trains, not tests
    ancestor_contents = set(ancestor_contents) | {digests[i] for i in train_idx}
    trained_before = [i for i in test_idx if ids[i] in ancestors or digests[i] in ancestor_contents]
    if trained_before:
        train_idx = sorted([*train_idx, *trained_before])
        test_idx = [i for i in test_idx if i not in trained_before]
    train_ws = _split_windows("training", trials, train_idx, window, dt, config.train_stride)
    test_ws = _split_windows("test", trials, test_idx, window, dt, config.eval_stride) if test_idx else None

    frozen = mode == "transfer"
    # Transfer caches the frozen LSTM's features of the windows as they are: no mirroring there.
    mirror = config.mirror and not frozen
    if mirror and (window.input_frame != "relative" or window.target == "absolute"):
        if mode == "scratch":
            raise ValueError(
                "train.mirror needs window.input_frame='relative' and a relative or residual window.target"
            )
        # the window is the starting model's; train.mirror came with the configuration (a preset's)
        raise ValueError(
            f"{base_path}: its window (input_frame {window.input_frame!r}, target {window.target!r}) cannot be "
            f"mirrored, which train.mirror (on in this configuration) asks; {mode}: it with train.mirror off "
            "(--preset thesis does not mirror)"
        )
    if frozen:
        for p in net.lstm_parameters():
            p.requires_grad_(False)
    if config.freeze_skip and net.skip is not None:  # residual learning over the fixed (tuned) ridge
        if frozen and ckpt is None:
            # The residual is over the ridge of *this* data: the source's ridge, frozen, would
            # extrapolate on a new user's windows (user-b: 78.9 mm at 0.4 s against 5.5 mm; docs/history.md).
            tuning = _fit_skip(
                net,
                trials,
                train_idx,
                WindowSet([trials[i].trial for i in train_idx], window, dt, stride=config.fit_stride),
                model.input_scaler,
                model.target_scaler,
                config,
            )
        net.skip.requires_grad_(False)
    net.to(config.device)
    train_data = _Windows(model, train_ws, frozen, device=config.device)
    test_data = _Windows(model, test_ws, frozen, device=config.device) if test_ws else None
    params = [p for p in net.parameters() if p.requires_grad]
    opt = _optimizer(config.optimizer, params, config.lr, config.weight_decay)
    steps_per_epoch = math.ceil(len(train_ws) / config.batch_size)
    total_steps = config.epochs * steps_per_epoch
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: config.lr_final_ratio ** (min(s, total_steps) / total_steps)
    )
    rng = np.random.default_rng(config.seed)  # batch order and mirroring

    history: list[dict[str, Any]] = list(base.info.get("training_history", [])) if mode == "resume" or ckpt else []
    epoch0 = history[-1]["epoch"] if history else 0
    done = 0
    if ckpt is not None:
        epoch0, done = ckpt["epoch0"], ckpt["epoch"]
        try:
            restore_checkpoint(ckpt, opt, sched, rng)
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:  # the optimizer's or generator's state
            raise ValueError(f"{base_path}: unusable checkpoint ({type(exc).__name__}: {exc})") from None

    def info(finished: bool) -> dict[str, Any]:
        out = {
            "preset": base.info.get("preset", preset.name) if mode != "scratch" or ckpt else preset.name,
            "dataset_ids": sorted({lt.dataset for lt in trials}),
            "train_trials": [ids[i] for i in train_idx],
            "train_digests": [digests[i] for i in train_idx],  # their contents: a copy under another name is known
            "test_trials": [ids[i] for i in test_idx],
            "n_train_windows": len(train_ws),
            "n_test_windows": len(test_ws) if test_ws else 0,
            "init": config.init,
            "parent": None
            if mode == "scratch"
            else {
                "path": base_path,
                "dataset_ids": base.info.get("dataset_ids"),
                "preset": base.info.get("preset"),
                "train_trials": base.info.get("train_trials"),
                "train_digests": base.info.get("train_digests"),
                # its own lineage, as deep as it goes: a grandparent's training trials are not held out either
                "parent": base.info.get("parent"),
            },
            "frozen": ["lstm"] if frozen else [],
            "mirrored": mirror,
            "train_config": asdict(config),
            "training_history": history,
            "train_seconds": time.perf_counter() - t_start,
            "torch_version": torch.__version__,
            "finished": finished,
        }
        if ckpt is not None:  # the interrupted run's own lineage, plus where it was continued
            out.update({k: base.info[k] for k in ("preset", "init", "parent") if k in base.info})
            out["continued_after_epoch"] = [*base.info.get("continued_after_epoch", []), done]
        return out

    bar = progress_bar(True) if progress else None
    task = bar.add_task("training", total=total_steps) if bar else None
    if bar:
        bar.update(task, completed=done * steps_per_epoch)
    with bar if bar else contextlib.nullcontext():
        # A linear network (no LSTM) is the tuned ridge, fitted in closed form below: no gradient epochs.
        for epoch in range(done + 1, (0 if net.is_linear else config.epochs) + 1):
            t0 = time.perf_counter()
            net.train()
            if mode == "transfer":
                net.lstm.eval()
            perm, signs = _epoch_order(rng, len(train_ws), config.batch_size, model.n_dof if mirror else 0)
            on = train_data.windows.device  # the training device (the CPU for MPS, batches.DeviceWindows)
            perm, signs = perm.to(on), None if signs is None else signs.to(on)
            running, seen = 0.0, 0
            for s in range(steps_per_epoch):
                a, b = s * config.batch_size, min((s + 1) * config.batch_size, len(train_ws))
                loss = train_data.loss(perm[a:b], signs=None if signs is None else signs[a:b])
                opt.zero_grad(set_to_none=True)
                loss.backward()
                if config.grad_clip:
                    nn.utils.clip_grad_norm_(params, config.grad_clip)
                opt.step()
                sched.step()
                running += loss.detach() * (b - a)  # no device sync per step
                seen += b - a
                if bar and (s % 20 == 0 or s == steps_per_epoch - 1):
                    bar.update(
                        task,
                        completed=(epoch - 1) * steps_per_epoch + s + 1,
                        description=f"epoch {epoch}/{config.epochs} loss {float(running) / seen:.2e}",
                    )
            record = {
                "epoch": epoch0 + epoch,
                "train_loss": float(running) / seen,
                "test_loss": _mean_loss(test_data),
                "lr": opt.param_groups[0]["lr"],
                "seconds": time.perf_counter() - t0,
            }
            _check_finite(record)  # before anything of this epoch is kept
            history.append(record)
            if checkpoint_to is not None:
                # One save, swapped in whole: the model files, the checkpoint (bound to them by the weights'
                # SHA-256 and the history's last epoch, check_binding) and history.json are staged in a new
                # folder and put in place of the last epoch's by one rename (coassist._io.swap_in). A kill
                # before it leaves the last epoch's folder whole, after it this one's; the checkpoint is built
                # from the weights' digest before anything is written (save_model calls _epoch_files first).
                # A folder mixing two saves can only come from elsewhere (a copy by hand, a reader straddling
                # a swap): resume refuses it, as it refuses a checkpoint that records no weights.
                snapshot = IntentModel(net, window, model.input_scaler, model.target_scaler, dt, info(False))
                save_model(
                    snapshot,
                    partial_folder(checkpoint_to),
                    extra_files=functools.partial(
                        _epoch_files,
                        opt,
                        sched,
                        rng,
                        epoch0=epoch0,
                        epoch=epoch,
                        trials=ids,
                        contents=contents,
                        config=config,
                        history=history,
                    ),
                )
            if on_epoch:
                on_epoch(record)

    if frozen:
        for p in net.lstm_parameters():
            p.requires_grad_(True)
    if net.skip is not None:
        net.skip.requires_grad_(True)
    t_fit = time.perf_counter()
    model.ridge, _, baselines = fit_tuned_baselines(
        [trials[i].trial for i in train_idx],
        [ids[i] for i in train_idx],
        window,
        dt,
        model.input_scaler,
        model.target_scaler,
        seed=config.seed,
        stride=config.train_stride,
        alpha=config.ridge_alpha,
        tuned=tuning,
    )  # None on resume: _build_model only searches for a fresh model
    if net.is_linear:  # the linear predictor is the tuned ridge: one closed-form pass, recorded as one epoch
        net.init_skip(
            torch.from_numpy(model.ridge.W.T.astype(np.float32)).to(config.device),
            torch.from_numpy(model.ridge.b.astype(np.float32)).to(config.device),
        )
        history.append(
            {
                "epoch": epoch0 + 1,
                "train_loss": _mean_loss(train_data),
                "test_loss": _mean_loss(test_data),
                "lr": 0.0,
                "seconds": time.perf_counter() - t_fit,
                "closed_form": True,
            }
        )
    net.cpu().eval()
    model.info = info(True)
    model.info["baselines"] = baselines  # tuned α and Kalman noise: evaluation scores with these
    return model


def plot_losses(history: Sequence[dict[str, Any]], path: Path | IO[bytes], title: str = "") -> None:
    """Train and test loss per epoch on a log scale (thesis Fig. 5.12), PNG to a path or a binary file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ep = [r["epoch"] for r in history]
    ax.semilogy(ep, [r["train_loss"] for r in history], "o-", label="train")
    test = [r["test_loss"] for r in history]
    if any(t is not None for t in test):
        ax.semilogy(ep, [np.nan if t is None else t for t in test], "s-", label="test")
    ax.set_xlabel("epoch")
    ax.set_ylabel("MSE loss (scaled targets)")
    ax.set_title(title or "Train and test loss (cf. thesis Fig. 5.12)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    if hasattr(path, "write"):
        fig.savefig(path, format="png", dpi=110)
    else:
        save_figure(fig, path)
    plt.close(fig)


def write_model(model: IntentModel, out: str | os.PathLike[str]) -> None:
    """Save the model folder with its ``history.json`` and ``loss.png``, swapped in whole."""
    import io

    out = Path(out)
    history = model.info.get("training_history", [])
    png = io.BytesIO()
    plot_losses(history, png, title=f"{model.info.get('preset', '')} {model.info.get('init', '')}")
    save_model(model, out, extra_files={"history.json": _json(history).encode(), "loss.png": png.getvalue()})
    # The run is complete: the per-epoch checkpoint of train_model(checkpoint_to=out) is done with.
    shutil.rmtree(partial_folder(out), ignore_errors=True)


def _epoch_files(
    opt: torch.optim.Optimizer,
    sched: Any,
    rng: np.random.Generator,
    weights_sha256: str,
    *,
    history: list[dict[str, Any]],
    **kw: Any,
) -> dict[str, bytes]:
    """An epoch's files beside its model: the checkpoint bound to the weights ``weights_sha256`` and history.json."""
    files = checkpoint_files(opt, sched, rng, weights_sha256=weights_sha256, model_epoch=history[-1]["epoch"], **kw)
    return {**files, "history.json": _json(history).encode()}


def _json(obj: Any) -> str:
    import json

    return json.dumps(obj, indent=1, allow_nan=False) + "\n"
