"""A trained intent model: network + windowing + scaling, saved as safetensors + JSON.

A model folder holds::

    weights.safetensors   the network's tensors (float32)
    ridge.safetensors     the ridge baseline fitted on the same training windows (optional)
    model.json            sidecar: features, dt, window, network, scaling ranges, dataset
                          ids, split, preset, training configuration and history

The folder is written whole beside the destination and swapped in at the end
(:func:`coassist._io.staged_folder`), under the output's lock, never pickled: a crash
leaves the old model or the new one, never a mix. :func:`load_model` validates the
sidecar, checks the weights against its hash and refuses a model whose features or dt
differ from what the caller expects (:class:`ModelMismatchError`); every defect of the
files is one :class:`ModelFileError` naming the file.

Tampering with the sidecar. The weights file's safetensors metadata records
``sidecar_sha256``, a SHA-256 of the sidecar's numeric and structural content (features,
dt, window, network, both scalers' ranges, the ridge's hash; not the descriptive
history). An edit of ``model.json`` alone (a ``target_scaler`` ×30 once made the robot
push 100 N) no longer matches it and the model is refused. A weights file without this
record (one re-saved by ``safetensors``' own ``save_file``, which drops the metadata, or
a model saved before the record existed) cannot be verified and is refused too: a
sidecar that cannot be checked is one a scaled ``target_scaler`` hides in (the probe's
×30 pushed 100 N). Every model coassist writes (``train``, ``transfer``, the
training checkpoints, the real-time predictor's copy; :func:`save_model`) carries the
record; the error says to retrain or re-export the model with coassist. Before any
tensor is allocated the network's size is checked against the weights file (a float32
parameter is 4 bytes), so ``hidden`` = 100 000 is one error, not a 160 GB allocation;
a sidecar nested too deep or larger than :data:`MAX_SIDECAR_BYTES` is refused unparsed.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load as st_load
from safetensors.torch import save as st_save

from coassist._checks import check_int, is_real_number
from coassist._io import OutputLock, atomic_write_bytes, no_constant, staged_folder
from coassist.data import Trial
from coassist.errors import CoassistError
from coassist.intent.features import (
    Scaler,
    WindowConfig,
    WindowSet,
    decode_target,
    feature_names,
    to_relative,
    unscale_targets,
)
from coassist.intent.network import IntentNet, NetworkConfig

__all__ = [
    "FORMAT",
    "IntentModel",
    "ModelFileError",
    "ModelMismatchError",
    "lineage_train_trials",
    "load_model",
    "save_model",
    "unfinished",
]

FORMAT = "coassist-intent/1"
WEIGHTS = "weights.safetensors"
RIDGE = "ridge.safetensors"
SIDECAR = "model.json"
#: Relative tolerance on dt when checking a model against a controller or data.
DT_RTOL = 0.01
#: Largest model.json read [bytes] (a real one, history included, is tens of kB).
MAX_SIDECAR_BYTES = 16 * 2**20
#: The sidecar fields covered by ``sidecar_sha256`` (module docstring).
_HASHED = (
    "features",
    "n_dof",
    "dt",
    "history",
    "horizon",
    "window",
    "network",
    "input_scaler",
    "target_scaler",
    "ridge_sha256",
)
_SIDECAR_HASH_KEY = "sidecar_sha256"


class ModelMismatchError(CoassistError, ValueError):
    """The model was trained on other features or another sampling period."""


class ModelFileError(CoassistError, ValueError):
    """A model folder that is missing files or inconsistent."""


class IntentModel:
    """Network, window and scalers: raw feature history in, predicted positions out.

    Parameters
    ----------
    net : IntentNet
    window : WindowConfig
    input_scaler : Scaler over the 4·d features (in ``window.input_frame``)
    target_scaler : Scaler over the d target axes (in ``window.target`` parameterisation)
    dt : sampling period in s the model was trained at
    info : JSON-ready details (preset, dataset ids, split, training history, …)
    ridge : optional ridge baseline fitted on the same training windows
    """

    def __init__(
        self,
        net: IntentNet,
        window: WindowConfig,
        input_scaler: Scaler,
        target_scaler: Scaler,
        dt: float,
        info: dict[str, Any] | None = None,
        ridge: Any = None,
    ) -> None:
        nf, no = net.config.n_features, net.config.n_outputs
        if nf % 4:
            raise ValueError(f"network.n_features must be 4·d, got {nf}")
        self.n_dof = nf // 4
        if no != window.horizon * self.n_dof:
            raise ValueError(f"network.n_outputs ({no}) must equal horizon·d = {window.horizon * self.n_dof}")
        if input_scaler.lo.size != nf:
            raise ValueError(f"input scaler has {input_scaler.lo.size} ranges, the network {nf} features")
        if target_scaler.lo.size not in (self.n_dof, no):
            raise ValueError(
                f"target scaler has {target_scaler.lo.size} ranges; expected {self.n_dof} (per axis) or {no} (per step)"
            )
        self.net, self.window = net, window
        self.input_scaler, self.target_scaler = input_scaler, target_scaler
        self.dt = float(dt)
        self.features = feature_names(self.n_dof)
        self.info = dict(info or {})
        self.ridge = ridge
        #: the SHA-256 of the weights file this model was loaded from, as :func:`load_model` verified it (None: built
        #: in memory); what a run records as the model's id, taken here, not from the folder read again (a folder
        #: swapped between the two reads named weights that never ran)
        self.weights_sha256: str | None = None

    @property
    def horizon(self) -> int:
        return self.window.horizon

    @property
    def history(self) -> int:
        return self.window.history

    # ------------------------------------------------------------------ inference
    def scale_inputs(self, x: np.ndarray) -> torch.Tensor:
        """Raw windows (B, steps, 4·d) in the model's frame -> scaled tensor in the network's
        dtype (float32 as trained and saved; float64 where a caller converted the network)."""
        dtype = np.float64 if next(self.net.parameters()).dtype == torch.float64 else np.float32
        return torch.from_numpy(self.input_scaler.transform(x).astype(dtype))

    def outputs_to_positions(self, out: np.ndarray, pose: np.ndarray, vel: np.ndarray) -> np.ndarray:
        """Network outputs (B, H·d), scaled -> predicted positions (B, H, d) in m."""
        y = unscale_targets(self.target_scaler, out.astype(np.float64), self.horizon, self.n_dof)
        return decode_target(y, pose, vel, self.window, self.dt)

    def prepare(self, history: np.ndarray) -> np.ndarray:
        """Raw history (B, history, 4·d), oldest first, at full rate -> (B, steps, 4·d) in the model's frame."""
        x = np.asarray(history, dtype=np.float64)[:, self.window.offsets + self.window.history - 1]
        return to_relative(x, self.n_dof) if self.window.input_frame == "relative" else x

    def checked_history(self, history: np.ndarray) -> np.ndarray:
        """Raw histories as float64 (B, history, 4·d); ValueError naming the expected shape otherwise."""
        h = np.asarray(history, dtype=np.float64)
        if h.ndim != 3 or h.shape[1:] != (self.history, 4 * self.n_dof):
            raise ValueError(f"history must have shape (B, {self.history}, {4 * self.n_dof}), got {h.shape}")
        return h

    def history_positions(self, out: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Network outputs (B, H·d) for checked histories ``h`` -> positions (B, H, d) in m,
        anchored at each history's current sample (pose and velocity of ``h[:, -1]``)."""
        d = self.n_dof
        return self.outputs_to_positions(out, h[:, -1, :d], h[:, -1, d : 2 * d])

    @torch.inference_mode()
    def predict_batch(self, history: np.ndarray) -> np.ndarray:
        """Predicted positions (B, H, d) in m from raw histories (B, history, 4·d).

        ``history[b, -1]`` is the current sample x(k); prediction i is for tick k+i.
        """
        h = self.checked_history(history)
        if self.net.training:  # toggled only when needed: eval() walks every module, a cost per tick
            self.net.eval()
        return self.history_positions(self.net(self.scale_inputs(self.prepare(h))).numpy(), h)

    def predict(self, history: np.ndarray) -> np.ndarray:
        """One prediction: raw history (history, 4·d) -> (H, d) positions in m.

        The signature of the simulator's ``IntentSource.predict``.
        """
        return self.predict_batch(np.asarray(history, dtype=np.float64)[None])[0]

    def reset(self, context: Any = None) -> None:
        """Nothing to reset: the windowed model keeps no state between calls."""

    @torch.inference_mode()
    def predict_trial(self, trial: Trial, batch_size: int = 1024, stride: int = 1) -> np.ndarray:
        """Predictions at every tick of a trial, (T, H, d); NaN before the history is full, and with ``stride``
        n > 1 at every tick but those of every n-th window (the first full history's, then every n-th after)."""
        self.check_compatible(trial_features_names(trial), trial.meta.dt, what=f"trial of user {trial.meta.user!r}")
        stride = check_int(stride, "predict_trial stride", 1)
        ws = WindowSet([trial], self.window, self.dt, need_future=False)
        self.net.eval()
        pred = np.full((trial.n_samples, self.horizon, self.n_dof), np.nan)
        chosen = np.arange(0, len(ws), stride)
        for sel in np.array_split(chosen, max(1, math.ceil(len(chosen) / batch_size))):
            out = self.net(self.scale_inputs(ws.raw_inputs(sel))).numpy()
            pose, vel = ws.anchors(sel)
            pred[ws.ends[sel]] = self.outputs_to_positions(out, pose, vel)
        return pred

    # ------------------------------------------------------------------ checks
    def check_compatible(self, features: Sequence[str] | None, dt: float | None, what: str = "the caller") -> None:
        """Raise :class:`ModelMismatchError` unless features and dt match the model's."""
        if features is not None and tuple(features) != self.features:
            raise ModelMismatchError(
                f"model was trained on features {list(self.features)}, but {what} provides {list(features)}"
            )
        if dt is not None and not math.isclose(float(dt), self.dt, rel_tol=DT_RTOL):
            raise ModelMismatchError(
                f"model was trained at dt = {self.dt:g} s ({1 / self.dt:g} Hz), but {what} runs at dt = {float(dt):g} s "
                f"({1 / float(dt):g} Hz); retrain or resample (tolerance {DT_RTOL:.0%})"
            )

    def sidecar(self, weights_sha256: str, ridge_sha256: str | None) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "features": list(self.features),
            "n_dof": self.n_dof,
            "dt": self.dt,
            "history": self.window.history,
            "horizon": self.window.horizon,
            "window": self.window.to_dict(),
            # What the output positions are (features.LABELS); read back from window.label.
            "predicts": PREDICTS[self.window.label],
            "network": self.net.config.to_dict(),
            "input_scaler": self.input_scaler.to_dict(),
            "target_scaler": self.target_scaler.to_dict(),
            "weights_sha256": weights_sha256,
            "ridge_sha256": ridge_sha256,
            **self.info,
        }


#: model.json's "predicts", per window label: what the model's output positions are.
PREDICTS = {
    "tool": "the measured future tool pose x(k+1..k+H) (the thesis)",
    "hand_alone": "the future tool pose with the robot's own effort removed: the path the hand alone would produce",
    "intent": "the simulated operator's true intended positions x_ref,h(k+1..k+H)",
}


def trial_features_names(trial: Trial) -> tuple[str, ...]:
    return feature_names(trial.n_dof)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def save_model(
    model: IntentModel,
    folder: str | os.PathLike[str],
    *,
    extra_files: Mapping[str, bytes] | Callable[[str], Mapping[str, bytes]] | None = None,
) -> Path:
    """Write ``model`` as the folder ``folder``, replacing what was there; returns the folder.

    The folder is written beside ``folder`` and swapped in whole, under the output lock
    (:class:`coassist._io.OutputLock`; a second writer gets ``OutputBusyError``).
    ``extra_files`` (name -> bytes: history, figures, a training checkpoint) go into the
    same swap; given as a function, it is called with the weights file's SHA-256 (the sidecar's
    ``weights_sha256``, what :func:`load_model` verifies), for files bound to these weights (a
    training checkpoint). Whether an existing model may be replaced is the caller's decision.
    """
    folder = Path(folder)
    state = {k: v.detach().cpu().contiguous() for k, v in model.net.state_dict().items()}
    ridge = st_save(model.ridge.state_dict()) if model.ridge is not None else None
    meta = model.sidecar("", None if ridge is None else _sha256(ridge))
    # the hash of the content as load_model will parse it back (JSON round trip)
    sidecar_hash = _sidecar_hash(json.loads(json.dumps(meta, allow_nan=False)))
    weights = st_save(state, metadata={_SIDECAR_HASH_KEY: sidecar_hash})
    meta["weights_sha256"] = _sha256(weights)
    text = json.dumps(meta, indent=1, allow_nan=False)
    extra = extra_files(meta["weights_sha256"]) if callable(extra_files) else extra_files
    files = {WEIGHTS: weights, **({RIDGE: ridge} if ridge is not None else {}), **dict(extra or {})}
    files[SIDECAR] = (text + "\n").encode("utf-8")
    if folder.exists() and not folder.is_dir():
        raise ModelFileError(f"{folder} exists and is not a folder")
    with OutputLock(folder), staged_folder(folder) as staging:
        for name, data in files.items():
            if Path(name).name != name:
                raise ValueError(f"extra_files names must be plain file names, got {name!r}")
            atomic_write_bytes(staging / name, data)
    return folder


def _fail(path: Path, what: str) -> ModelFileError:
    return ModelFileError(f"{path}: {what}")


def lineage_train_trials(info: Mapping[str, Any], key: str = "train_trials") -> set[str]:
    """The trial ids a model and the models it was started from trained on, as its sidecar records them
    (``train_trials``, then each ``parent``'s, as deep as the record goes; a training records its starting
    model's, so a model's own and its parent's): what is not held out from it. ``key="train_digests"``: the
    same trials' contents (:func:`~coassist.intent.trials.content_digest`; models trained before they were
    recorded have none), which know a copy of a training trial under another name."""
    out: set[str] = set()
    node: Any = info
    while isinstance(node, Mapping):  # a JSON record has no cycle: each parent is nested one level deeper
        trained = node.get(key)
        if isinstance(trained, (list, tuple)):
            out.update(t for t in trained if isinstance(t, str))
        node = node.get("parent")
    return out


def read_sidecar(folder: str | os.PathLike[str]) -> dict[str, Any]:
    """The sidecar of a model folder, its format and fields checked (:class:`ModelFileError`)."""
    folder = Path(folder)
    path = folder / SIDECAR
    if not folder.exists():
        raise _fail(path, f"not found: there is no model folder {folder}")
    if not path.is_file():
        raise _fail(path, f"not found (is {folder} a model folder?)")
    try:
        if path.stat().st_size > MAX_SIDECAR_BYTES:
            raise _fail(path, f"larger than {MAX_SIDECAR_BYTES // 2**20} MiB: not a model sidecar")
        meta = json.loads(path.read_bytes().decode("utf-8"), parse_constant=no_constant)  # save_model writes none
    except ModelFileError:  # (a ValueError too: the size refusal, not to be called malformed JSON)
        raise
    except RecursionError:
        raise _fail(path, "JSON nested too deeply: not a model sidecar") from None
    except UnicodeDecodeError as exc:
        raise _fail(path, f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # json.JSONDecodeError is one; so is no_constant's refusal
        raise _fail(path, f"malformed JSON: {exc}") from None
    except OSError as exc:
        raise _fail(path, f"cannot be read: {exc.strerror}") from None
    if not isinstance(meta, dict):
        raise _fail(path, f"must hold a JSON object, got {type(meta).__name__}")
    if meta.get("format") != FORMAT:
        raise _fail(path, f"format {meta.get('format')!r}, expected {FORMAT!r}")
    dt = meta.get("dt")
    if not is_real_number(dt) or not math.isfinite(dt) or dt <= 0:
        raise _fail(path, f"'dt' must be a finite number > 0 (s), got {json.dumps(dt)}")
    for key in ("window", "network", "input_scaler", "target_scaler"):
        if not isinstance(meta.get(key), dict):
            raise _fail(path, f"{key!r} must be an object, got {json.dumps(meta.get(key))}")
    features = meta.get("features")
    if not isinstance(features, list) or not all(isinstance(f, str) for f in features):
        raise _fail(path, f"'features' must be a list of names, got {json.dumps(features)}")
    for key in ("weights_sha256", "ridge_sha256"):
        value = meta.get(key)
        # a model without a ridge writes null: the key itself is always there
        if key not in meta or not (isinstance(value, str) or (key == "ridge_sha256" and value is None)):
            raise _fail(path, f"{key!r} must be a hex digest, got {json.dumps(value)}")
    return meta


def _sidecar_hash(meta: Mapping[str, Any]) -> str:
    """SHA-256 of the sidecar's numeric and structural content (:data:`_HASHED`), canonical JSON."""
    content = {k: meta[k] for k in _HASHED if k in meta}
    return _sha256(json.dumps(content, sort_keys=True, separators=(",", ":"), allow_nan=False).encode("utf-8"))


def _safetensors_metadata(raw: bytes) -> dict[str, Any]:
    """The ``__metadata__`` of a safetensors file's header ({} when absent or unreadable:
    the parser then names the damage)."""
    try:
        n = int.from_bytes(raw[:8], "little")
        if len(raw) < 8 + n:
            return {}
        header = json.loads(raw[8 : 8 + n].decode("utf-8"))
        meta = header.get("__metadata__") if isinstance(header, dict) else None
    except (ValueError, RecursionError):
        return {}
    return meta if isinstance(meta, dict) else {}


def _tensors(path: Path, raw: bytes) -> dict[str, torch.Tensor]:
    try:
        return st_load(raw)
    except SafetensorError as exc:
        raise _fail(path, f"not a readable safetensors file: {exc}") from None


def unfinished(model: IntentModel) -> str:
    """ "" for a finished training; else one line saying it is not (a checkpoint ``train`` writes after each epoch, in
    ``.<out>.partial``: its baselines untuned, its epochs not all run), for the commands that would use it."""
    if model.info.get("finished", True):
        return ""
    done = (model.info.get("training_history") or [{}])[-1].get("epoch", "?")
    of = (model.info.get("train_config") or {}).get("epochs", "?")
    return (
        f"an unfinished training (the checkpoint after epoch {done} of {of}; its baselines not tuned): finish it "
        "with coassist train … --init resume:<its --out> first"
    )


def load_model(
    folder: str | os.PathLike[str],
    *,
    features: Sequence[str] | None = None,
    dt: float | None = None,
) -> IntentModel:
    """Load a model folder written by :func:`save_model`.

    Parameters
    ----------
    folder : the model folder (``model.json`` and the weights).
    features, dt : optional
        What the caller will feed the model; a mismatch raises :class:`ModelMismatchError`.
    """
    from coassist.intent.baselines import RidgeBaseline  # local: baselines imports this module

    folder = Path(folder)
    meta = read_sidecar(folder)
    sidecar = folder / SIDECAR
    try:
        window = WindowConfig(**meta["window"])
        net_cfg = NetworkConfig(**meta["network"])
        in_scaler = Scaler.from_dict(meta["input_scaler"])
        out_scaler = Scaler.from_dict(meta["target_scaler"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise _fail(sidecar, f"bad or missing field: {exc}") from None
    model_dt = float(meta["dt"])
    stored_features = tuple(meta["features"])
    if stored_features != feature_names(net_cfg.n_features // 4):
        raise _fail(sidecar, f"features {list(stored_features)} do not match the network")
    for key, expected in (("history", window.history), ("horizon", window.horizon)):
        if key in meta and meta[key] != expected:
            raise _fail(sidecar, f"{key!r} is {json.dumps(meta[key])} but the window says {expected}")
    weights_path = folder / WEIGHTS
    if not weights_path.is_file():
        raise _fail(weights_path, "not found")
    n_params = net_cfg.n_parameters
    size = weights_path.stat().st_size
    if 4 * n_params > size:  # before any allocation: the network must fit its float32 weights
        # named as the weights file (a truncated copy is the usual cause; the sidecar's network, the other)
        raise _fail(
            weights_path,
            f"holds {size} bytes, too few for the network in {SIDECAR} ({json.dumps(meta['network'])}: {n_params} "
            f"parameters, {4 * n_params} bytes as float32): truncated, or from another model",
        )
    raw = weights_path.read_bytes()
    if _sha256(raw) != meta["weights_sha256"]:
        raise _fail(weights_path, f"does not match the hash in {SIDECAR} (files from different saves?)")
    net = IntentNet(net_cfg)
    try:
        net.load_state_dict(_tensors(weights_path, raw), strict=True)
    except RuntimeError as exc:
        # torch's message is a header and a line a tensor: the first three, on one line
        lines = [line.strip() for line in str(exc).splitlines()[1:] if line.strip()] or [str(exc).strip()]
        shown = "; ".join(lines[:3]) + (f"; and {len(lines) - 3} more" if len(lines) > 3 else "")
        raise _fail(weights_path, f"tensors do not fit the network in {SIDECAR}: {shown}") from None
    ridge = None
    if meta["ridge_sha256"]:
        ridge_path = folder / RIDGE
        rraw = ridge_path.read_bytes() if ridge_path.is_file() else b""
        if _sha256(rraw) != meta["ridge_sha256"]:
            raise _fail(ridge_path, f"missing or does not match the hash in {SIDECAR}")
        try:
            ridge = RidgeBaseline.from_state_dict(_tensors(ridge_path, rraw), window, in_scaler, out_scaler, model_dt)
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:
            raise _fail(ridge_path, f"tensors do not fit the ridge baseline: {exc}") from None
    recorded = _safetensors_metadata(raw).get(_SIDECAR_HASH_KEY)
    if recorded is None:
        raise _fail(
            weights_path,
            f"carries no {_SIDECAR_HASH_KEY!r} in its metadata (re-saved without it, e.g. by "
            f"safetensors' save_file?), so {SIDECAR} cannot be verified; retrain the model "
            "or re-export it with coassist (coassist.intent.save_model)",
        )
    if recorded != _sidecar_hash(meta):
        raise _fail(
            sidecar,
            f"its content does not match the hash recorded in {WEIGHTS} at save time "
            "(edited after saving?); restore it or retrain",
        )
    skip = {*_HASHED, "format", "weights_sha256", _SIDECAR_HASH_KEY, "predicts"}  # the fields read above
    info = {k: v for k, v in meta.items() if k not in skip}
    try:
        model = IntentModel(net, window, in_scaler, out_scaler, model_dt, info, ridge)
    except ValueError as exc:
        raise _fail(sidecar, f"inconsistent model: {exc}") from None
    model.check_compatible(features, dt)
    model.weights_sha256 = str(meta["weights_sha256"])
    return model
