"""The checkpoint of an interrupted training run: what a resume needs beyond the weights.

:func:`coassist.intent.training.train_model` (``checkpoint_to=``) writes, beside the model
files of each epoch's snapshot, :data:`CHECKPOINT` (the optimizer's tensors, safetensors)
and :data:`CHECKPOINT_JSON` (format :data:`CHECKPOINT_FORMAT`: epoch, first epoch, trial
ids, training configuration, the optimizer's other state, the learning-rate schedule's
position and the batch-order generator's state). :func:`checkpoint_files` builds those
files, :func:`read_checkpoint` reads them back from a model folder and
:func:`restore_checkpoint` puts the optimizer, schedule and generator where they were.

A checkpoint is bound to the model files it was written with: it records the SHA-256 of their
weights file (``weights_sha256``, the sidecar's, which :func:`coassist.intent.model.load_model`
verifies) and the epoch of their training history's last entry (``model_epoch``).
:func:`check_binding` refuses a checkpoint beside other weights (the files of two epochs mixed: a
folder copied by hand, or read while a run swapped in its next epoch), which would otherwise
continue from one epoch's weights with another's optimizer state and epoch count. A checkpoint
without them (written by a coassist before the check) is refused by :func:`read_checkpoint`.
It also records the SHA-256 of its tensors file (``tensors_sha256``) and of its own record (``record_sha256``):
a resume from edited or damaged state (an epoch count, a learning rate, the generator's state, the optimizer's
moments) would not give the unbroken run's weights, and is refused.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from coassist.intent.presets import TrainConfig
from coassist.intent.trials import hash_arrays

__all__ = [
    "CHECKPOINT",
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_JSON",
    "check_binding",
    "checkpoint_files",
    "read_checkpoint",
    "restore_checkpoint",
    "trials_digest",
]

CHECKPOINT = "checkpoint.safetensors"
CHECKPOINT_JSON = "checkpoint.json"
CHECKPOINT_FORMAT = "coassist-checkpoint/1"


def checkpoint_files(
    opt: torch.optim.Optimizer,
    sched: Any,
    rng: np.random.Generator,
    *,
    epoch0: int,
    epoch: int,
    trials: list[str],
    contents: str,
    config: TrainConfig,
    weights_sha256: str,
    model_epoch: int,
) -> dict[str, bytes]:
    """What a resume needs beyond the weights: optimizer tensors (safetensors) and the rest (JSON).

    ``weights_sha256``, ``model_epoch``: the SHA-256 of the weights file written beside it and the
    epoch of that model's last history entry (:func:`check_binding`)."""
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
        "trials_sha256": contents,  # what the trials hold (trials_digest): a resume on other data is refused
        "weights_sha256": weights_sha256,  # the model files it belongs to (check_binding)
        "model_epoch": model_epoch,
        "train_config": asdict(config),
        "optimizer": {"param_groups": state["param_groups"], "scalars": scalars},
        "scheduler": sched_state,
        "numpy_rng": rng.bit_generator.state,
    }
    raw = st_save(tensors)
    record["tensors_sha256"] = hashlib.sha256(raw).hexdigest()  # the optimizer's tensors it was written with
    record["record_sha256"] = _record_digest(record)  # what it holds: an epoch, a rate, a generator state edited
    return {CHECKPOINT: raw, CHECKPOINT_JSON: (json.dumps(record, indent=1, allow_nan=False) + "\n").encode()}


def _record_digest(record: dict[str, Any]) -> str:
    """SHA-256 of the checkpoint's record without its own digest, keys sorted: the same for the record as written
    and as read back (JSON's numbers round-trip exactly)."""
    body = {k: v for k, v in record.items() if k not in ("record_sha256", "tensors")}
    return hashlib.sha256(json.dumps(body, sort_keys=True, allow_nan=False).encode()).hexdigest()


def trials_digest(trials: Sequence[Any]) -> str:
    """SHA-256 of what labeled ``trials`` hold (each one's id and what a training reads, in order: the
    arrays, the efforts and the rendered impedance ``meta.extra["plant"]`` the ``hand_alone`` label is
    built from): the same ids collected again are other data.

    A trial without efforts or plant hashes as it did before they were included; one with them
    does not, so a checkpoint an older coassist wrote on such trials is refused as on other data.
    """
    h = hashlib.sha256()
    for lt in trials:
        h.update(str(lt.id).encode() + b"\0")
        t = lt.trial
        hash_arrays(h, t, ("time", "pose", "velocity", "wrench", "reference", "intent", "effort_r", "effort_h"))
        meta = getattr(t, "meta", None)
        plant = meta.to_dict()["extra"].get("plant") if meta is not None else None
        if plant is not None:
            h.update(b"plant" + json.dumps(plant, sort_keys=True, allow_nan=False).encode())
    return h.hexdigest()


def read_checkpoint(folder: Path) -> dict[str, Any] | None:
    """The checkpoint record of a model folder (tensors under ``"tensors"``), or None without one."""

    from safetensors import SafetensorError
    from safetensors.torch import load as st_load

    path = folder / CHECKPOINT_JSON
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_bytes().decode("utf-8"))
        if not isinstance(record, dict) or record.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"format is not {CHECKPOINT_FORMAT!r}")
        if "weights_sha256" not in record:  # (all else it holds may be in order: said apart from a damaged file)
            raise ValueError(
                "written by an older coassist, before a checkpoint recorded the weights it belongs to, so it cannot "
                "be checked against the model beside it"
            )
        for key in (
            "epoch", "epoch0", "trials", "trials_sha256", "train_config", "optimizer", "scheduler", "numpy_rng",
            "model_epoch",
        ):  # fmt: skip
            if key not in record:
                raise ValueError(f"missing {key!r}")
        for key in ("weights_sha256", "trials_sha256"):
            sha = record[key]
            if not isinstance(sha, str) or len(sha) != 64 or any(c not in "0123456789abcdef" for c in sha):
                raise ValueError(f"{key!r} must be a SHA-256 hex digest, got {json.dumps(sha)}")
        for key in ("epoch", "epoch0", "model_epoch"):  # epochs done: a count (the run's total is checked where known)
            value = record[key]
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{key!r} must be an integer >= 0, got {json.dumps(value)}")
        if not isinstance(record["trials"], list) or not all(isinstance(t, str) for t in record["trials"]):
            raise ValueError("'trials' must be a list of trial ids")
        if not isinstance(record["train_config"], dict):
            raise ValueError("'train_config' must be an object")
        for key in ("tensors_sha256", "record_sha256"):
            if key not in record:
                raise ValueError(
                    "written by an older coassist, before a checkpoint recorded digests of what it holds, so an edit "
                    "or a damaged file cannot be told"
                )
        if record["record_sha256"] != _record_digest(record):
            raise ValueError(
                "its contents are not those written (their SHA-256 differs from the one recorded: edited by hand?)"
            )
        raw = (folder / CHECKPOINT).read_bytes()
        if hashlib.sha256(raw).hexdigest() != record["tensors_sha256"]:
            raise ValueError(
                f"{CHECKPOINT} is not the file written with it (its SHA-256 differs from the one recorded: damaged, "
                "or another run's?)"
            )
        record["tensors"] = st_load(raw)
    except (OSError, ValueError, RecursionError, SafetensorError) as exc:
        raise ValueError(f"{path}: unusable checkpoint ({exc}); start a new stage with finetune:{folder}") from None
    return record


def check_binding(ckpt: dict[str, Any], folder: Path, weights_sha256: str | None, model_epoch: int | None) -> None:
    """Refuse (ValueError, one line naming ``folder``) a checkpoint that is not the one written with the model
    files beside it: ``weights_sha256`` (the loaded model's, verified against its weights file) and
    ``model_epoch`` (its history's last epoch) must be what the checkpoint recorded."""
    wrong = []
    if ckpt["weights_sha256"] != weights_sha256:
        wrong.append(
            f"their weights' SHA-256 is {str(weights_sha256)[:12]}…, the checkpoint's {ckpt['weights_sha256'][:12]}…"
        )
    if ckpt["model_epoch"] != model_epoch:
        wrong.append(f"their history ends at epoch {model_epoch}, the checkpoint at epoch {ckpt['model_epoch']}")
    if wrong:
        raise ValueError(
            f"{folder}: unusable checkpoint: {CHECKPOINT_JSON} was not written with the model files beside it "
            f"({'; '.join(wrong)}): files of two saves mixed (copied by hand, or read while a run replaced them?); "
            f"start a new stage from the model with finetune:{folder}"
        )


def restore_checkpoint(ckpt: dict[str, Any], opt: torch.optim.Optimizer, sched: Any, rng: np.random.Generator) -> None:
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
