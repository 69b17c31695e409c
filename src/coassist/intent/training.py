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

The loss is the MSE (eq. 5.3) on scaled targets; the learning rate decays
geometrically from ``lr`` to ``lr · lr_final_ratio`` over the whole run. Given the
seed and the thread count, a run is deterministic. The library leaves torch's global
state alone: the initial weights come from a ``torch.Generator`` seeded with ``seed``,
the batch order from a NumPy generator, and the caller (the CLI) sets the thread count.
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import IO, Any

import numpy as np
import torch
from torch import nn

from coassist._checks import is_integer, is_real_number
from coassist._io import partial_folder, save_figure
from coassist._progress import progress_bar
from coassist.intent.baselines import UNTUNED_RIDGE_ALPHA, RidgeBaseline, fit_tuned_baselines, tune_ridge_alpha
from coassist.intent.batches import DeviceWindows
from coassist.intent.features import WindowConfig, WindowSet, feature_names, scale_targets, split_trials
from coassist.intent.model import IntentModel, load_model, save_model
from coassist.intent.network import IntentNet, NetworkConfig
from coassist.intent.trials import LabeledTrial
from coassist.registry import Registry

__all__ = [
    "OPTIMIZERS",
    "MODEL_PRESETS",
    "Preset",
    "TrainConfig",
    "build_model",
    "plot_losses",
    "train_model",
    "write_model",
]

OPTIMIZERS = ("adam", "adamw", "rmsprop", "sgd")
INIT_MODES = ("scratch", "resume", "finetune", "transfer")


@dataclass(frozen=True)
class TrainConfig:
    """How to train. Every field is validated on construction; errors name the field.

    epochs, batch_size : thesis 25 and 64.
    lr, lr_final_ratio : initial learning rate (thesis 1e-3) and the fraction it decays to
        geometrically by the end (0.05).
    optimizer : one of :data:`OPTIMIZERS` (thesis: Adam, chosen with Optuna).
    weight_decay : L2 / decoupled decay (0 = none).
    seed : seeds the split, initialisation and batch order.
    init : ``"scratch"`` or ``"resume:<model>"``, ``"finetune:<model>"``, ``"transfer:<model>"``.
    threads : torch intra-op threads (1 or 2 on the project machines); the CLI sets them,
        ``train_model`` does not (it leaves torch's global state alone).
    test_fraction : share of *trials* held out (thesis 0.2).
    train_stride, eval_stride : keep every n-th window (consecutive windows overlap almost
        entirely; 1 = all, the thesis).
    fit_stride : every n-th training window for what is fitted in closed form before the
        first epoch: the scalers' ranges and the linear skip's ridge (1 = all, the thesis).
    ridge_alpha : regularisation of the ridge baseline fitted on the same windows (the
        baseline the model is compared with). None (default): chosen on validation
        trials split from the training trials, like the model's own hyper-parameters
        (``baselines.fit_tuned_baselines``); a number fixes it.
    skip_alpha : regularisation of the ridge solution the network's linear skip starts
        from (``Preset.skip``); None: the baseline's α (tuned unless ``ridge_alpha`` is set). Larger shrinks that linear map, which makes the model
        degrade more gracefully on inputs outside the training range (a new user, data
        collected with another model in the loop).
    grad_clip : max gradient norm (0 = off).
    freeze_skip : keep the linear skip at the ridge solution it starts from, so the LSTM+FC
        learns only the residual over that linear predictor. In transfer the skip is first
        re-fitted: the ridge (α as ``skip_alpha``) on the new training trials, in the
        source model's scalers; the frozen LSTM and the retrained FC layers then learn the
        residual over the new data's own linear predictor.
    device : torch device to train on (``"cpu"``, ``"cuda"``); the model returned is on the CPU.
        The trials' features go there once and every batch is cut there
        (``intent.batches.DeviceWindows``, bit-identical to cutting it with NumPy).
    mirror : data augmentation: each training window is mirrored along each axis with
        probability 1/2 (all positions, velocities, forces and the target of that axis
        negated). The planar admittance M a + D v = f is symmetric under it; it needs the
        relative input frame and a relative or residual target. Not applied in transfer
        (the frozen LSTM's features are computed once per window).
    """

    epochs: int = 25
    batch_size: int = 64
    lr: float = 1e-3
    lr_final_ratio: float = 0.05
    optimizer: str = "adam"
    weight_decay: float = 0.0
    seed: int = 0
    init: str = "scratch"
    threads: int = 2
    test_fraction: float = 0.2
    train_stride: int = 1
    eval_stride: int = 1
    fit_stride: int = 1
    ridge_alpha: float | None = None
    skip_alpha: float | None = None
    grad_clip: float = 0.0
    device: str = "cpu"
    mirror: bool = False
    freeze_skip: bool = False

    def __post_init__(self) -> None:
        for name, minimum in (
            ("epochs", 1),
            ("batch_size", 1),
            ("threads", 1),
            ("train_stride", 1),
            ("eval_stride", 1),
            ("fit_stride", 1),
            ("seed", 0),
        ):
            v = getattr(self, name)
            if not is_integer(v) or v < minimum:
                raise ValueError(f"train.{name} must be an integer >= {minimum}, got {v!r}")
            object.__setattr__(self, name, int(v))
        for name, ok, what in (
            ("lr", lambda v: v > 0, "> 0"),
            ("lr_final_ratio", lambda v: 0 < v <= 1, "in (0, 1]"),
            ("weight_decay", lambda v: v >= 0, ">= 0"),
            ("test_fraction", lambda v: 0 <= v < 1, "in [0, 1)"),
            ("ridge_alpha", lambda v: v >= 0, ">= 0"),
            ("skip_alpha", lambda v: v >= 0, ">= 0"),
            ("grad_clip", lambda v: v >= 0, ">= 0"),
        ):
            v = getattr(self, name)
            if v is None and name in ("ridge_alpha", "skip_alpha"):  # None: tuned on validation trials
                continue
            if not is_real_number(v) or not math.isfinite(v) or not ok(v):
                raise ValueError(f"train.{name} must be a finite number {what}, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"train.optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if not isinstance(self.device, str) or self.device.split(":")[0] not in ("cpu", "cuda", "mps"):
            raise ValueError(f"train.device must be 'cpu', 'cuda[:n]' or 'mps', got {self.device!r}")
        if not isinstance(self.freeze_skip, bool):
            raise ValueError(f"train.freeze_skip must be a bool, got {self.freeze_skip!r}")
        if not isinstance(self.mirror, bool):
            raise ValueError(f"train.mirror must be a bool, got {self.mirror!r}")
        mode, _ = self.start
        if mode not in INIT_MODES:
            raise ValueError(
                f"train.init must be 'scratch' or one of resume:/finetune:/transfer:<model>, got {self.init!r}"
            )

    @property
    def start(self) -> tuple[str, str | None]:
        """(mode, model path or None) parsed from ``init``."""
        if self.init == "scratch":
            return "scratch", None
        mode, sep, path = self.init.partition(":")
        if not sep or not path or mode == "scratch":
            return "invalid", None
        return mode, path


@dataclass(frozen=True)
class Preset:
    """A named starting configuration: window, network sizes, training."""

    name: str
    window: WindowConfig
    lstm_layers: int
    hidden: int
    fc: tuple[int, ...]
    train: TrainConfig = field(default_factory=TrainConfig)
    activation: str = "silu"
    skip: bool = False  # linear skip initialised with the ridge solution

    def network(self, n_dof: int) -> NetworkConfig:
        skip = self.window.steps * 4 * n_dof if self.skip else 0
        return NetworkConfig(
            4 * n_dof, self.window.horizon * n_dof, self.lstm_layers, self.hidden, self.fc, self.activation, skip
        )


#: ``thesis``: exactly §5.2.2 — 125 samples of absolute features, LSTM 3 × 250,
#: FC 250 → 200 → 2·50 (SiLU), Adam 1e-3 → 5e-5, batch 64, 25 epochs, MSE.
#: ``lstm``: small and fast on a 2-core CPU; input frame, target, per-step target
#: scaling, the ridge-initialised linear skip and mirror augmentation chosen by
#: measurement on real user-a data (docs/intent-parameterisation.md).
#: ``default``: ``lstm`` with its skip frozen at the validation-tuned ridge, so the LSTM+FC
#: learns only the residual over that linear predictor (``train.freeze_skip``).
#: ``linear``: the same window with no LSTM — the validation-tuned ridge in the model
#: format, fitted in closed form.
#: ``intent``: ``lstm`` learning the simulated operator's true intent instead of the tool's
#: future (issue 18; needs simulated trials).
#: Held-out real recordings, 3 seeds/folds (docs/intent-baselines.md, issue 11): ``default``
#: beats the tuned ridge at every horizon in every run, but by 2–5 %, not the 15 % asked:
#: e_RMS at 0.4 s (median) user-a 1.658 mm against 1.744, user-b 5.277 against 5.379 mm.
#: ``lstm`` trails the ridge at 0.04 s (user-b −3.4 %).
_LSTM = Preset(
    "lstm",
    WindowConfig(
        history=125, decimation=5, horizon=50, input_frame="relative", target="residual", target_scaling="step"
    ),
    lstm_layers=2,
    hidden=64,
    fc=(64,),
    skip=True,
    train=TrainConfig(
        epochs=15, batch_size=64, lr=3e-3, lr_final_ratio=0.05, optimizer="adam", mirror=True, train_stride=4
    ),
)
MODEL_PRESETS: Registry[Preset] = Registry(
    "intent-model preset",
    {
        "thesis": Preset(
            "thesis",
            WindowConfig(history=125, decimation=1, horizon=50, input_frame="absolute", target="absolute"),
            lstm_layers=3,
            hidden=250,
            fc=(200,),
            train=TrainConfig(epochs=25, batch_size=64, lr=1e-3, lr_final_ratio=0.05, optimizer="adam"),
        ),
        "lstm": _LSTM,
        "default": replace(_LSTM, name="default", train=replace(_LSTM.train, freeze_skip=True)),
        "linear": Preset(
            "linear",
            _LSTM.window,
            lstm_layers=0,
            hidden=1,
            fc=(),
            skip=True,
            train=TrainConfig(epochs=1, train_stride=4),
        ),
        # ``intent``: ``lstm`` trained on the simulated operator's true intent (window.label "intent"),
        # the intent source that wins the in-loop ablation (docs/intent-labels.md); simulated data only.
        "intent": replace(_LSTM, name="intent", window=replace(_LSTM.window, label="intent")),
    },
)


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
        """The MSE of the windows ``sel`` (int64 on the device); ``signs`` (B, d) mirror them."""
        net = self.model.net
        if self.cached:
            sel = sel.to(self.y.device)  # no-op but on MPS, where the windows are cut on the CPU
            pred = net.forward_head(self.h[sel], None if self.x is None else self.x[sel])
            y = self.y[sel]
        else:
            x, y = self.windows.batch(sel, signs)
            pred = net(x)
        return nn.functional.mse_loss(pred, y, reduction=reduction)


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


def train_model(
    trials: Sequence[LabeledTrial],
    preset: Preset,
    config: TrainConfig,
    *,
    progress: bool = False,
    on_epoch: Callable[[dict[str, Any]], None] | None = None,
    checkpoint_to: str | os.PathLike[str] | None = None,
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
    The network has no dropout, so torch draws no random numbers after initialisation
    (its weights come from a generator seeded in :func:`build_model`): nothing of torch's
    to save. Torch's thread count is the caller's to set (``torch.set_num_threads``).
    """
    if not trials:
        raise ValueError("no trials to train on")
    t_start = time.perf_counter()
    mode, base_path = config.start
    if mode == "resume" and (partial_folder(base_path) / CHECKPOINT_JSON).is_file():
        base_path = str(partial_folder(base_path))  # an interrupted run on that folder: newer than it
    base, tuning = _build_model(
        preset,
        trials,
        replace(config, init=f"resume:{base_path}") if mode == "resume" else config,
        fit_linear_skip=False,
    )
    ids = [lt.id for lt in trials]
    ckpt = _read_checkpoint(Path(base_path)) if mode == "resume" and not base.info.get("finished", True) else None
    if ckpt is not None:
        if ckpt["trials"] != ids:
            raise ValueError(
                f"{base_path} is an interrupted run on {len(ckpt['trials'])} other trials; continue it with the same "
                "data, or start a new stage from it with finetune:"
            )
        try:
            config = replace(TrainConfig(**ckpt["train_config"]), threads=config.threads, device=config.device)
        except TypeError as exc:  # a checkpoint of another coassist version
            raise ValueError(
                f"{base_path}: checkpoint's training configuration is not this version's ({exc})"
            ) from None
        mode = config.start[0]  # the interrupted run's own mode (a transfer stays frozen)
    model = IntentModel(copy.deepcopy(base.net), base.window, base.input_scaler, base.target_scaler, base.dt, {})
    net, window, dt = model.net, model.window, model.dt

    train_idx, test_idx = split_trials(ids, config.test_fraction, config.seed)
    train_ws = WindowSet([trials[i].trial for i in train_idx], window, dt, stride=config.train_stride)
    test_ws = (
        WindowSet([trials[i].trial for i in test_idx], window, dt, stride=config.eval_stride) if test_idx else None
    )

    frozen = mode == "transfer"
    if config.mirror and (window.input_frame != "relative" or window.target == "absolute"):
        raise ValueError("train.mirror needs window.input_frame='relative' and a relative or residual window.target")
    # Transfer caches the frozen LSTM's features of the windows as they are: no mirroring there.
    mirror = config.mirror and not frozen
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
        _restore(ckpt, opt, sched, rng)

    def info(finished: bool) -> dict[str, Any]:
        out = {
            "preset": base.info.get("preset", preset.name) if mode != "scratch" or ckpt else preset.name,
            "dataset_ids": sorted({lt.dataset for lt in trials}),
            "train_trials": [ids[i] for i in train_idx],
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
            history.append(record)
            if checkpoint_to is not None:
                snapshot = IntentModel(net, window, model.input_scaler, model.target_scaler, dt, info(False))
                files = _checkpoint_files(opt, sched, rng, epoch0=epoch0, epoch=epoch, trials=ids, config=config)
                save_model(
                    snapshot,
                    partial_folder(checkpoint_to),
                    extra_files={**files, "history.json": _json(history).encode()},
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


CHECKPOINT = "checkpoint.safetensors"
CHECKPOINT_JSON = "checkpoint.json"
CHECKPOINT_FORMAT = "coassist-checkpoint/1"


def _checkpoint_files(
    opt: torch.optim.Optimizer,
    sched: Any,
    rng: np.random.Generator,
    *,
    epoch0: int,
    epoch: int,
    trials: list[str],
    config: TrainConfig,
) -> dict[str, bytes]:
    """What a resume needs beyond the weights: optimizer tensors (safetensors) and the rest (JSON)."""
    from safetensors.torch import save as st_save

    state = opt.state_dict()
    tensors, scalars = {}, {}
    for idx, per_param in state["state"].items():
        for name, value in per_param.items():
            if torch.is_tensor(value):
                tensors[f"state.{idx}.{name}"] = value.detach().cpu().contiguous()
            else:
                scalars[f"{idx}.{name}"] = value
    sched_state = {k: v for k, v in sched.state_dict().items() if k != "lr_lambdas"}
    record = {
        "format": CHECKPOINT_FORMAT,
        "epoch": epoch,
        "epoch0": epoch0,
        "trials": trials,
        "train_config": asdict(config),
        "optimizer": {"param_groups": state["param_groups"], "scalars": scalars},
        "scheduler": sched_state,
        "numpy_rng": rng.bit_generator.state,
    }
    return {CHECKPOINT: st_save(tensors), CHECKPOINT_JSON: _json(record).encode()}


def _read_checkpoint(folder: Path) -> dict[str, Any] | None:
    """The checkpoint record of a model folder (tensors under ``"tensors"``), or None without one."""
    import json

    from safetensors import SafetensorError
    from safetensors.torch import load as st_load

    path = folder / CHECKPOINT_JSON
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_bytes().decode("utf-8"))
        if not isinstance(record, dict) or record.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"format is not {CHECKPOINT_FORMAT!r}")
        for key in ("epoch", "epoch0", "trials", "train_config", "optimizer", "scheduler", "numpy_rng"):
            if key not in record:
                raise ValueError(f"missing {key!r}")
        record["tensors"] = st_load((folder / CHECKPOINT).read_bytes())
    except (OSError, ValueError, SafetensorError) as exc:
        raise ValueError(f"{path}: unusable checkpoint ({exc}); start a new stage with finetune:{folder}") from None
    return record


def _restore(ckpt: dict[str, Any], opt: torch.optim.Optimizer, sched: Any, rng: np.random.Generator) -> None:
    """Put the optimizer, schedule and batch-order generator back where the checkpoint left them."""
    per_param: dict[int, dict[str, Any]] = {}
    for key, value in ckpt["tensors"].items():
        _, idx, name = key.split(".", 2)
        per_param.setdefault(int(idx), {})[name] = value
    for key, value in ckpt["optimizer"]["scalars"].items():
        idx, name = key.split(".", 1)
        per_param.setdefault(int(idx), {})[name] = value
    opt.load_state_dict({"state": per_param, "param_groups": ckpt["optimizer"]["param_groups"]})
    sched.load_state_dict({**ckpt["scheduler"], "lr_lambdas": [None] * len(opt.param_groups)})
    rng.bit_generator.state = ckpt["numpy_rng"]


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


def _json(obj: Any) -> str:
    import json

    return json.dumps(obj, indent=1, allow_nan=False) + "\n"


def with_batch_size(train: TrainConfig, batch_size: int) -> TrainConfig:
    """``train`` with another batch size and its learning rate scaled by the square-root rule,
    lr' = lr · √(batch_size / train.batch_size) (opt-in; the presets keep their batches).

    Why √ and not linear: for Adam the update's noise scales with 1/√B, and the rule that
    keeps its stochastic dynamics the same is the square root (Malladi et al. 2022, *On the
    SDEs and scaling rules for adaptive gradient algorithms*); the linear rule (Goyal et al.
    2017) is SGD's. The decay to ``lr_final_ratio`` still spans the whole run (fewer steps).
    Checked on validation loss for the default preset: docs/history.md ("Bigger batches").
    A bigger batch is fewer, larger matrix products per window: more windows/s on a device
    with parallel width to fill, different (not worse, there) weights than the preset's.
    """
    if not is_integer(batch_size) or batch_size < 1:
        raise ValueError(f"train.batch_size must be an integer >= 1, got {batch_size!r}")
    return replace(train, batch_size=int(batch_size), lr=train.lr * math.sqrt(batch_size / train.batch_size))


def with_overrides(preset: Preset, **train_overrides: Any) -> Preset:
    """A preset with some TrainConfig fields replaced (None values ignored)."""
    kw = {k: v for k, v in train_overrides.items() if v is not None}
    return replace(preset, train=replace(preset.train, **kw)) if kw else preset
