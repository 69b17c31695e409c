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
seed and the thread count, a run is deterministic.
"""

from __future__ import annotations

import copy
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from coassist._io import atomic_write_text, save_figure
from coassist.intent.baselines import RidgeBaseline
from coassist.intent.features import WindowConfig, WindowSet, feature_names, scale_targets, split_trials
from coassist.intent.model import IntentModel, load_model, save_model
from coassist.intent.network import IntentNet, NetworkConfig
from coassist.intent.sources import LabeledTrial

__all__ = [
    "OPTIMIZERS",
    "PRESETS",
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
    threads : torch intra-op threads (1 or 2 on the project machines).
    test_fraction : share of *trials* held out (thesis 0.2).
    train_stride, eval_stride : keep every n-th window (consecutive windows overlap almost
        entirely; 1 = all, the thesis).
    ridge_alpha : regularisation of the ridge baseline fitted on the same windows (the
        baseline the model is compared with; not tuned to the model's advantage).
    skip_alpha : regularisation of the ridge solution the network's linear skip starts
        from (``Preset.skip``). Larger shrinks that linear map, which makes the model
        degrade more gracefully on inputs outside the training range (a new user, data
        collected with another model in the loop).
    grad_clip : max gradient norm (0 = off).
    device : torch device to train on (``"cpu"``, ``"cuda"``); the model returned is on the CPU.
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
    ridge_alpha: float = 1.0
    skip_alpha: float = 1.0
    grad_clip: float = 0.0
    device: str = "cpu"
    mirror: bool = False

    def __post_init__(self) -> None:
        for name, minimum in (("epochs", 1), ("batch_size", 1), ("threads", 1), ("train_stride", 1),
                              ("eval_stride", 1), ("seed", 0)):  # fmt: skip
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
                raise ValueError(f"train.{name} must be an integer >= {minimum}, got {v!r}")
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
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not ok(v):
                raise ValueError(f"train.{name} must be a finite number {what}, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"train.optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if not isinstance(self.device, str) or self.device.split(":")[0] not in ("cpu", "cuda", "mps"):
            raise ValueError(f"train.device must be 'cpu', 'cuda[:n]' or 'mps', got {self.device!r}")
        if not isinstance(self.mirror, bool):
            raise ValueError(f"train.mirror must be a bool, got {self.mirror!r}")
        mode, _ = self.start
        if mode not in INIT_MODES:
            raise ValueError(f"train.init must be 'scratch' or one of resume:/finetune:/transfer:<model>, got {self.init!r}")

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
        return NetworkConfig(4 * n_dof, self.window.horizon * n_dof, self.lstm_layers, self.hidden, self.fc,
                             self.activation, skip)  # fmt: skip


#: ``thesis``: exactly §5.2.2 — 125 samples of absolute features, LSTM 3 × 250,
#: FC 250 → 200 → 2·50 (SiLU), Adam 1e-3 → 5e-5, batch 64, 25 epochs, MSE.
#: ``default``: small and fast on a 2-core CPU; input frame, target, per-step target
#: scaling, the ridge-initialised linear skip and mirror augmentation chosen by
#: measurement on real user-a data (docs/intent-parameterisation.md).
PRESETS: dict[str, Preset] = {
    "thesis": Preset(
        "thesis",
        WindowConfig(history=125, decimation=1, horizon=50, input_frame="absolute", target="absolute"),
        lstm_layers=3, hidden=250, fc=(200,),
        train=TrainConfig(epochs=25, batch_size=64, lr=1e-3, lr_final_ratio=0.05, optimizer="adam"),
    ),  # fmt: skip
    "default": Preset(
        "default",
        WindowConfig(history=125, decimation=5, horizon=50, input_frame="relative", target="residual",
                     target_scaling="step"),
        lstm_layers=2, hidden=64, fc=(64,), skip=True,
        train=TrainConfig(epochs=15, batch_size=64, lr=3e-3, lr_final_ratio=0.05, optimizer="adam", mirror=True,
                          train_stride=4),
    ),  # fmt: skip
}


def _optimizer(name: str, params: list[nn.Parameter], lr: float, weight_decay: float) -> torch.optim.Optimizer:
    if name == "adam":
        return torch.optim.Adam(params, lr=lr, weight_decay=weight_decay)
    if name == "adamw":
        return torch.optim.AdamW(params, lr=lr, weight_decay=weight_decay)
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


def build_model(preset: Preset, trials: Sequence[LabeledTrial], config: TrainConfig) -> IntentModel:
    """The starting model: fresh (scalers fitted on the training split) or loaded from ``init``."""
    mode, path = config.start
    d = trials[0].trial.n_dof
    dt = _common_dt(trials)
    if mode != "scratch":
        return load_model(path, features=feature_names(d), dt=dt)
    ids = [lt.id for lt in trials]
    train_idx, _ = split_trials(ids, config.test_fraction, config.seed)
    ws = WindowSet([trials[i].trial for i in train_idx], preset.window, dt)
    in_scaler, out_scaler = ws.fit_scalers()
    torch.manual_seed(config.seed)
    net = IntentNet(preset.network(d))
    if net.skip is not None:
        ridge = RidgeBaseline.fit(ws, in_scaler, out_scaler, config.skip_alpha)
        net.init_skip(torch.from_numpy(ridge.W.T.astype(np.float32)), torch.from_numpy(ridge.b.astype(np.float32)))
    return IntentModel(net, preset.window, in_scaler, out_scaler, dt)


def _batch(model: IntentModel, ws: WindowSet, sel: np.ndarray, signs: np.ndarray | None = None
           ) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """Scaled inputs (B, steps, 4·d) and targets (B, H·d); ``signs`` (B, d) of ±1 mirror the axes."""
    x, y = ws.raw_inputs(sel), ws.raw_targets(sel)
    if signs is not None:
        x = x * np.tile(signs, 4)[:, None, :]
        y = y * signs[:, None, :]
    return model.scale_inputs(x), torch.from_numpy(scale_targets(model.target_scaler, y).astype(np.float32))


class _Windows:
    """Batches of (network input, scaled target) for one split.

    With ``frozen_lstm`` the LSTM's output is computed once per window and cached: the
    frozen LSTM maps a window to the same features every epoch, so transfer learning
    (Algorithm 4.2) trains the FC layers on cached features, exactly and much faster.
    """

    def __init__(self, model: IntentModel, ws: WindowSet, frozen_lstm: bool, chunk: int = 1024,
                 device: str = "cpu") -> None:  # fmt: skip
        self.model, self.ws, self.cached, self.device = model, ws, frozen_lstm, torch.device(device)
        if frozen_lstm:
            hs, xs, ys = [], [], []
            with torch.no_grad():
                for sel in np.array_split(np.arange(len(ws)), max(1, math.ceil(len(ws) / chunk))):
                    x, y = (t.to(self.device) for t in _batch(model, ws, sel))
                    hs.append(model.net.lstm_features(x))
                    xs.append(x.flatten(1) if model.net.skip is not None else None)
                    ys.append(y)
            self.h = torch.cat(hs)
            self.x = torch.cat(xs) if model.net.skip is not None else None
            self.y = torch.cat(ys)

    def __len__(self) -> int:
        return len(self.ws)

    def loss(self, sel: np.ndarray, reduction: str = "mean", signs: np.ndarray | None = None) -> torch.Tensor:
        net = self.model.net
        if self.cached:
            t = torch.from_numpy(sel).to(self.device)
            pred = net.forward_head(self.h[t], None if self.x is None else self.x[t])
            y = self.y[t]
        else:
            x, y = (t.to(self.device, non_blocking=True) for t in _batch(self.model, self.ws, sel, signs))
            pred = net(x)
        return nn.functional.mse_loss(pred, y, reduction=reduction)


@torch.no_grad()
def _mean_loss(data: _Windows | None, batch: int = 1024) -> float | None:
    if data is None:
        return None
    data.model.net.eval()
    total, n = 0.0, 0
    for sel in np.array_split(np.arange(len(data)), max(1, math.ceil(len(data) / batch))):
        total += float(data.loss(sel, reduction="sum")) / data.model.net.config.n_outputs
        n += sel.size
    return total / n


def train_model(
    trials: Sequence[LabeledTrial],
    preset: Preset,
    config: TrainConfig,
    *,
    progress: bool = False,
    on_epoch: Callable[[dict[str, Any]], None] | None = None,
) -> IntentModel:
    """Train on ``trials`` (split by trial) and return the model, its sidecar info filled.

    ``preset`` gives window and sizes for ``init="scratch"``; for the other modes they
    come from the starting model. ``on_epoch`` gets each epoch's record
    ``{epoch, train_loss, test_loss, lr, seconds}`` (losses: MSE on scaled targets).
    """
    if not trials:
        raise ValueError("no trials to train on")
    torch.set_num_threads(config.threads)
    t_start = time.perf_counter()
    mode, base_path = config.start
    base = build_model(preset, trials, config)
    model = IntentModel(copy.deepcopy(base.net), base.window, base.input_scaler, base.target_scaler, base.dt, {})
    net, window, dt = model.net, model.window, model.dt

    ids = [lt.id for lt in trials]
    train_idx, test_idx = split_trials(ids, config.test_fraction, config.seed)
    train_ws = WindowSet([trials[i].trial for i in train_idx], window, dt, stride=config.train_stride)
    test_ws = WindowSet([trials[i].trial for i in test_idx], window, dt, stride=config.eval_stride) if test_idx else None

    frozen = mode == "transfer"
    if config.mirror and (window.input_frame != "relative" or window.target == "absolute"):
        raise ValueError("train.mirror needs window.input_frame='relative' and a relative or residual window.target")
    # Transfer caches the frozen LSTM's features of the windows as they are: no mirroring there.
    mirror = config.mirror and not frozen
    if frozen:
        for p in net.lstm_parameters():
            p.requires_grad_(False)
    net.to(config.device)
    train_data = _Windows(model, train_ws, frozen, device=config.device)
    test_data = _Windows(model, test_ws, frozen, device=config.device) if test_ws else None
    params = [p for p in net.parameters() if p.requires_grad]
    opt = _optimizer(config.optimizer, params, config.lr, config.weight_decay)
    steps_per_epoch = math.ceil(len(train_ws) / config.batch_size)
    total_steps = config.epochs * steps_per_epoch
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: config.lr_final_ratio ** (min(s, total_steps) / total_steps))
    rng = np.random.default_rng(config.seed)
    torch.manual_seed(config.seed)

    history: list[dict[str, Any]] = list(base.info.get("training_history", [])) if mode == "resume" else []
    epoch0 = history[-1]["epoch"] if history else 0
    bar = _progress_bar(progress)
    task = bar.add_task("training", total=total_steps) if bar else None
    with bar if bar else _nullcontext():
        for epoch in range(1, config.epochs + 1):
            t0 = time.perf_counter()
            net.train()
            if mode == "transfer":
                net.lstm.eval()
            perm = rng.permutation(len(train_ws))
            running, seen = 0.0, 0
            for s in range(steps_per_epoch):
                sel = perm[s * config.batch_size : (s + 1) * config.batch_size]
                signs = rng.choice([-1.0, 1.0], size=(sel.size, model.n_dof)) if mirror else None
                loss = train_data.loss(sel, signs=signs)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                if config.grad_clip:
                    nn.utils.clip_grad_norm_(params, config.grad_clip)
                opt.step()
                sched.step()
                running += loss.detach() * sel.size  # no device sync per step
                seen += sel.size
                if bar and (s % 20 == 0 or s == steps_per_epoch - 1):
                    bar.update(task, completed=(epoch - 1) * steps_per_epoch + s + 1,
                               description=f"epoch {epoch}/{config.epochs} loss {float(running) / seen:.2e}")  # fmt: skip
            record = {
                "epoch": epoch0 + epoch,
                "train_loss": float(running) / seen,
                "test_loss": _mean_loss(test_data),
                "lr": opt.param_groups[0]["lr"],
                "seconds": time.perf_counter() - t0,
            }
            history.append(record)
            if on_epoch:
                on_epoch(record)

    if frozen:
        for p in net.lstm_parameters():
            p.requires_grad_(True)
    net.cpu().eval()
    model.ridge = RidgeBaseline.fit(train_ws, model.input_scaler, model.target_scaler, config.ridge_alpha)
    datasets = sorted({lt.dataset for lt in trials})
    model.info = {
        "preset": base.info.get("preset", preset.name) if mode != "scratch" else preset.name,
        "dataset_ids": datasets,
        "train_trials": [ids[i] for i in train_idx],
        "test_trials": [ids[i] for i in test_idx],
        "n_train_windows": len(train_ws),
        "n_test_windows": len(test_ws) if test_ws else 0,
        "init": config.init,
        "parent": None if mode == "scratch" else {
            "path": base_path, "dataset_ids": base.info.get("dataset_ids"), "preset": base.info.get("preset"),
            "train_trials": base.info.get("train_trials"),
        },  # fmt: skip
        "frozen": ["lstm"] if mode == "transfer" else [],
        "mirrored": mirror,
        "train_config": asdict(config),
        "training_history": history,
        "train_seconds": time.perf_counter() - t_start,
        "torch_version": torch.__version__,
    }
    return model


class _nullcontext:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def _progress_bar(enabled: bool):
    if not enabled:
        return None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    TimeRemainingColumn())  # fmt: skip


def plot_losses(history: Sequence[dict[str, Any]], path: Path, title: str = "") -> None:
    """Train and test loss per epoch on a log scale (thesis Fig. 5.12), PNG."""
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
    save_figure(fig, path)
    plt.close(fig)


def write_model(model: IntentModel, out: str | os.PathLike[str]) -> None:
    """Save the model folder with its ``history.json`` and ``loss.png``."""
    out = Path(out)
    save_model(model, out)
    history = model.info.get("training_history", [])
    atomic_write_text(out / "history.json", _json(history))
    plot_losses(history, out / "loss.png", title=f"{model.info.get('preset', '')} {model.info.get('init', '')}")


def _json(obj: Any) -> str:
    import json

    return json.dumps(obj, indent=1, allow_nan=False) + "\n"


def with_overrides(preset: Preset, **train_overrides: Any) -> Preset:
    """A preset with some TrainConfig fields replaced (None values ignored)."""
    kw = {k: v for k, v in train_overrides.items() if v is not None}
    return replace(preset, train=replace(preset.train, **kw)) if kw else preset
