"""Features, windows and scaling for the intent predictor (thesis §4.1, §5.2.2).

At tick k the predictor sees the last ``history`` samples of the 4·d features, in the
thesis' order (eq. 4.3–4.6; for the x-y plane d = 2)::

    x, y, ẋ, ẏ, f_x, f_y, x_ref, y_ref        (pose, velocity, wrench, nominal reference)

and predicts the human's desired positions at ticks k+1 … k+H. Training targets are
the *measured* future poses (the thesis trains on what the person actually did).

Two choices here are ours, both measured on real data (docs/intent-parameterisation.md):

- ``input_frame``: ``"absolute"`` (the thesis: positions as recorded) or
  ``"relative"`` (pose and reference columns minus the current pose x(k), so the
  network sees shapes, not places, and transfers to other workspaces);
- ``target``: what the network outputs for step i (i = 1 … H):
  ``"absolute"``  x(k+i);
  ``"relative"``  x(k+i) − x(k);
  ``"residual"``  x(k+i) − (x(k) + i·dt·ẋ(k))   (over constant-velocity extrapolation).

What the future positions x(k+i) *are* is the window's ``label`` (issue 18: under
assistance the tool's future contains the robot's own push, so a predictor of it feeds
the robot's motion back into itself as negative damping, docs/assistance.md):

- ``"tool"``: the measured future pose x(k+i) (the thesis);
- ``"hand_alone"``: the pose the hand alone would have produced from the same state at
  k, the robot's effort removed through the impedance the world rendered (linear and
  known; ``Trial.meta.extra["plant"]``)::

      x_h(k+i) = x(k+i) − Σ_{j=0}^{i−1} C_x A_d^{i−1−j} B_d u_r(k+j)
               = x(k+i) − [z_r(k+i) − A_d^i z_r(k)]_x,   z_r(k+1) = A_d z_r(k) + B_d u_r(k), z_r(0) = 0

  with (A_d, B_d) the exact ZOH discretisation of M a + D v + K Δx = u and [·]_x the
  position rows (:func:`robot_state`, :func:`free_response`). Where u_r ≡ 0 (manual
  guidance) it equals ``"tool"``;
- ``"intent"``: the operator's true desired position x_ref,h(k+i) (``Trial.intent``,
  simulated trials only): what a predictor of intent should output, to score against
  and as an upper bound on what can be learned.

Inputs and targets are scaled to [−1, 1] by a :class:`Scaler` fitted on the training
windows only (one range per feature; one range per axis for targets).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from coassist._checks import check_int_at_least
from coassist.data import Trial
from coassist.data.trial import time_gaps
from coassist.model.impedance import ImpedanceModel

__all__ = [
    "AXES",
    "INPUT_FRAMES",
    "LABELS",
    "TARGETS",
    "Scaler",
    "WindowConfig",
    "WindowSet",
    "feature_names",
    "robot_state",
    "split_trials",
    "trial_features",
    "validation_split",
]

#: Share of the training trials held out for validation (hyper-parameters, baselines' tuning).
VALIDATION_FRACTION = 0.25

AXES = ("x", "y", "z", "rx", "ry", "rz")
INPUT_FRAMES = ("absolute", "relative")
TARGETS = ("absolute", "relative", "residual")
LABELS = ("tool", "hand_alone", "intent")
TARGET_SCALINGS = ("axis", "step")


def feature_names(n_dof: int) -> tuple[str, ...]:
    """Feature names in the thesis' order: pose, velocity, wrench, nominal reference.

    ``feature_names(2) == ("x", "y", "vx", "vy", "fx", "fy", "x_ref", "y_ref")``.
    """
    if not 1 <= n_dof <= len(AXES):
        raise ValueError(f"n_dof must be between 1 and {len(AXES)}, got {n_dof}")
    ax = AXES[:n_dof]
    return ax + tuple(f"v{a}" for a in ax) + tuple(f"f{a}" for a in ax) + tuple(f"{a}_ref" for a in ax)


def trial_features(trial: Trial) -> np.ndarray:
    """The (T, 4·d) feature matrix [pose | velocity | wrench | reference] of a trial (SI units)."""
    return np.concatenate([trial.pose, trial.velocity, trial.wrench, trial.reference], axis=1)


@dataclass(frozen=True)
class WindowConfig:
    """How a window is cut from a trial.

    Attributes
    ----------
    history : int
        Past samples covered by one input window, current one included (thesis: 125 = 1 s).
    decimation : int
        Keep every ``decimation``-th of them (1 = all, the thesis). ``history`` must be a
        multiple; the network then sees ``history // decimation`` steps, the last being x(k).
    horizon : int
        Predicted future samples H (thesis: 50 = 0.4 s).
    input_frame : str
        ``"absolute"`` or ``"relative"`` (see the module docstring).
    target : str
        ``"absolute"``, ``"relative"`` or ``"residual"`` (see the module docstring).
    target_scaling : str
        ``"axis"``: one [−1, 1] range per axis over all H steps (the thesis);
        ``"step"``: one range per step and axis, so the MSE weighs near and far steps alike.
    label : str
        What the future positions are: ``"tool"`` (the measured pose, the thesis),
        ``"hand_alone"`` (the robot's effort removed) or ``"intent"`` (the simulated
        operator's true intent); see the module docstring. A model records it in its
        ``model.json`` (``window.label``); files from before it existed read as ``"tool"``.
    """

    history: int = 125
    decimation: int = 1
    horizon: int = 50
    input_frame: str = "absolute"
    target: str = "absolute"
    target_scaling: str = "axis"
    label: str = "tool"

    def __post_init__(self) -> None:
        check_int_at_least(self.history, "window.history", 1)
        check_int_at_least(self.decimation, "window.decimation", 1)
        check_int_at_least(self.horizon, "window.horizon", 1)
        if self.history % self.decimation:
            raise ValueError(
                f"window.history ({self.history}) must be a multiple of window.decimation ({self.decimation})"
            )
        if self.input_frame not in INPUT_FRAMES:
            raise ValueError(f"window.input_frame must be one of {INPUT_FRAMES}, got {self.input_frame!r}")
        if self.target not in TARGETS:
            raise ValueError(f"window.target must be one of {TARGETS}, got {self.target!r}")
        if self.label not in LABELS:
            raise ValueError(f"window.label must be one of {LABELS}, got {self.label!r}")
        if self.target_scaling not in TARGET_SCALINGS:
            raise ValueError(f"window.target_scaling must be one of {TARGET_SCALINGS}, got {self.target_scaling!r}")

    @property
    def steps(self) -> int:
        """Sequence length the network sees."""
        return self.history // self.decimation

    @property
    def offsets(self) -> np.ndarray:
        """Sample offsets of the window relative to k, oldest first, ending at 0. Shape (steps,)."""
        return -self.decimation * np.arange(self.steps - 1, -1, -1)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class Scaler:
    """Min-max scaling of each column to [−1, 1] (thesis §5.2.2).

    ``scaled = 2 (x − lo) / (hi − lo) − 1``. A constant column (hi = lo) gets a span of
    1 so it maps to −1 instead of dividing by zero. Immutable once built.
    """

    def __init__(self, lo: Sequence[float], hi: Sequence[float]) -> None:
        lo_a = np.array(lo, dtype=np.float64).reshape(-1)
        hi_a = np.array(hi, dtype=np.float64).reshape(-1)
        if lo_a.shape != hi_a.shape or lo_a.size == 0:
            raise ValueError(
                f"Scaler lo and hi must be non-empty and of equal length, got {lo_a.shape} and {hi_a.shape}"
            )
        if not (np.all(np.isfinite(lo_a)) and np.all(np.isfinite(hi_a))):
            raise ValueError("Scaler ranges must be finite")
        if np.any(hi_a < lo_a):
            raise ValueError("Scaler needs hi >= lo in every column")
        span = hi_a - lo_a
        span[span == 0.0] = 1.0
        for a in (lo_a, hi_a, span):
            a.setflags(write=False)
        self.lo, self.hi, self._span = lo_a, hi_a, span

    @property
    def span(self) -> np.ndarray:
        """hi − lo per column, 1 where the column is constant (read-only)."""
        return self._span

    @classmethod
    def fit(cls, values: np.ndarray) -> Scaler:
        """Ranges of the columns of ``values`` (..., n)."""
        flat = np.asarray(values, dtype=np.float64).reshape(-1, np.shape(values)[-1])
        return cls(flat.min(axis=0), flat.max(axis=0))

    def transform(self, x: np.ndarray) -> np.ndarray:
        """(..., n) physical -> (..., n) in [−1, 1] on the fitted range."""
        return 2.0 * (x - self.lo) / self._span - 1.0

    def inverse(self, s: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`transform`."""
        return (s + 1.0) * 0.5 * self._span + self.lo

    def to_dict(self) -> dict[str, list[float]]:
        return {"lo": self.lo.tolist(), "hi": self.hi.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scaler:
        try:
            return cls(data["lo"], data["hi"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"malformed scaler {data!r}: {exc}") from None


def _trial_name(t: Trial) -> str:
    """A trial as an error names it: its person, its recording (or seed) and its length."""
    which = t.meta.extra.get("recording") or (f"seed {t.meta.seed}" if t.meta.seed is not None else t.meta.task)
    return f"{t.meta.user}'s {which} ({t.n_samples} samples)"


def split_trials(ids: Sequence[str], test_fraction: float = 0.2, seed: int = 0) -> tuple[list[int], list[int]]:
    """Split trials (not windows) into train and test, deterministically.

    The ids are sorted first, so the split depends only on the set of trials and the
    seed, not on load order. At least one trial goes to each side when there are two
    or more. Returns (train indices, test indices) into ``ids``, each sorted.
    """
    if not 0.0 <= test_fraction < 1.0:
        raise ValueError(f"test_fraction must be in [0, 1), got {test_fraction!r}")
    if len(set(ids)) != len(ids):
        raise ValueError("trial ids must be unique")
    n = len(ids)
    order = sorted(range(n), key=lambda i: ids[i])
    perm = np.random.default_rng(seed).permutation(n)
    n_test = int(round(test_fraction * n))
    if test_fraction > 0 and n >= 2:
        n_test = min(max(n_test, 1), n - 1)
    test = sorted(order[p] for p in perm[:n_test])
    train = sorted(order[p] for p in perm[n_test:])
    return train, test


def validation_split(train_ids: Sequence[str], seed: int = 0) -> tuple[list[int], list[int]]:
    """Split the training trials again, by trial, into fit and validation: the one protocol by
    which hyper-parameters are chosen (``intent.tuning``) and the baselines are tuned
    (``baselines.fit_tuned_baselines``). A quarter of the trials (at least one), with seed + 1.
    Returns (fit indices, validation indices) into ``train_ids``.
    """
    if len(train_ids) < 2:
        raise ValueError(f"a validation split needs at least two training trials, got {len(train_ids)}")
    return split_trials(train_ids, VALIDATION_FRACTION, seed + 1)


class WindowSet:
    """All windows of some trials, cut lazily (one batch at a time).

    Holds the features of the trials concatenated, (ΣT, 4·d), and the global index of
    every tick k that has a full history and (``need_future``) a full horizon. Batches
    are gathered by fancy indexing, so nothing of size (N, steps, features) is built.
    """

    def __init__(
        self,
        trials: Sequence[Trial],
        window: WindowConfig,
        dt: float,
        *,
        stride: int = 1,
        need_future: bool = True,
    ) -> None:
        if not trials:
            raise ValueError("WindowSet needs at least one trial")
        d = trials[0].n_dof
        other = next((t for t in trials if t.n_dof != d), None)
        if other is not None:
            raise ValueError(
                f"all trials must have the same number of DOFs: {_trial_name(other)} has {other.n_dof}, "
                f"{_trial_name(trials[0])} {d}"
            )
        check_int_at_least(stride, "stride", 1)
        self.window, self.dt, self.n_dof = window, float(dt), d
        feats, ends, owner, start = [], [], [], 0
        labels: list[np.ndarray] = []
        free: list[np.ndarray] = []
        first = window.history - 1
        for i, t in enumerate(trials):
            f = trial_features(t)
            if window.label == "intent" and need_future:
                labels.append(_label_series(t, window.label))
            elif window.label == "hand_alone" and need_future:
                plant = trial_plant(t)
                labels.append(robot_state(plant, _label_series(t, window.label)))
                free.append(free_response(plant, window.horizon))
            ahead = window.horizon if need_future else 0
            last = t.n_samples - 1 - ahead
            ks = np.arange(first, last + 1, stride)
            # No window spans a gap in the recording: gap g lies between samples g and
            # g+1, and the window ending at k uses samples k−history+1 … k+ahead.
            gaps = time_gaps(t.time, t.meta.dt)
            if gaps.size:
                spans = np.searchsorted(gaps, ks + ahead, side="left") - np.searchsorted(gaps, ks - first, side="left")
                ks = ks[spans == 0]
            feats.append(f)
            ends.append(start + ks)
            owner.append(np.full(ks.size, i))
            start += t.n_samples
        self.features = np.concatenate(feats)
        # "intent": the true intent positions (ΣT, d); "hand_alone": the state z_r the robot's
        # effort alone drives (ΣT, 2d), and each trial's free response C_x A_d^i (n_trials, H, d, 2d).
        self._label = np.concatenate(labels) if labels else None
        self._free = np.stack(free) if free else None
        self.ends = np.concatenate(ends).astype(np.int64)
        self.trial = np.concatenate(owner)
        if self.ends.size == 0:
            named = ", ".join(_trial_name(t) for t in trials[:3]) + (
                f" and {len(trials) - 3} more" if len(trials) > 3 else ""
            )
            raise ValueError(
                f"no trial is long enough for history {window.history} + horizon {window.horizon} samples "
                f"({len(trials)} given: {named})"
            )

    def __len__(self) -> int:
        return int(self.ends.size)

    # -- raw (physical) pieces ------------------------------------------------
    def raw_inputs(self, sel: np.ndarray) -> np.ndarray:
        """(B, steps, 4·d) input windows in the configured frame, SI units."""
        ends = self.ends[sel]
        x = self.features[ends[:, None] + self.window.offsets[None, :]]
        if self.window.input_frame == "relative":
            x = to_relative(x, self.n_dof)
        return x

    def anchors(self, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Current pose x(k) and velocity ẋ(k), each (B, d)."""
        f = self.features[self.ends[sel]]
        d = self.n_dof
        return f[:, :d], f[:, d : 2 * d]

    def future(self, sel: np.ndarray) -> np.ndarray:
        """The labelled future positions for ticks k+1 … k+H, (B, H, d), m (``window.label``)."""
        idx = self.ends[sel][:, None] + np.arange(1, self.window.horizon + 1)[None, :]
        label = self.window.label
        if label == "tool":
            return self.features[idx][:, :, : self.n_dof]
        series, free = self._label, self._free
        if series is None:
            raise ValueError("this WindowSet was cut without futures (need_future=False)")
        if label == "intent":
            return series[idx]
        if free is None:
            raise ValueError("this WindowSet was cut without futures (need_future=False)")
        d = self.n_dof
        pose = self.features[idx][:, :, :d]
        # What u_r(k) … u_r(k+i−1) moved the tool from rest at k: z_r(k+i) − C_x A_d^i z_r(k).
        pushed = series[idx][:, :, :d] - free_motion(free[self.trial[sel]], series[self.ends[sel]])
        return pose - pushed

    def label_arrays(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """What the labels beyond ``"tool"`` are computed from: the true intent (ΣT, d) or the
        robot-driven state z_r (ΣT, 2d), and for ``"hand_alone"`` each trial's free response
        C_x A_d^i (n_trials, H, d, 2d); None where the label needs none (read-only views)."""
        return self._label, self._free

    def raw_targets(self, sel: np.ndarray) -> np.ndarray:
        """Training targets in the configured parameterisation, (B, H, d), m."""
        pose, vel = self.anchors(sel)
        return encode_target(self.future(sel), pose, vel, self.window, self.dt)

    # -- scaler fit (training split only) -------------------------------------
    def fit_scalers(self) -> tuple[Scaler, Scaler]:
        """Input scaler (per feature over every window step) and target scaler (per axis, or per step and axis)."""
        nf = self.features.shape[1]
        nt = self.n_dof * (self.window.horizon if self.window.target_scaling == "step" else 1)
        lo, hi = np.full(nf, np.inf), np.full(nf, -np.inf)
        tlo, thi = np.full(nt, np.inf), np.full(nt, -np.inf)
        for chunk in np.array_split(np.arange(len(self)), max(1, len(self) // 4096)):
            x = self.raw_inputs(chunk).reshape(-1, nf)
            lo, hi = np.minimum(lo, x.min(0)), np.maximum(hi, x.max(0))
            y = self.raw_targets(chunk).reshape(-1, nt)
            tlo, thi = np.minimum(tlo, y.min(0)), np.maximum(thi, y.max(0))
        return Scaler(lo, hi), Scaler(tlo, thi)


def scale_targets(scaler: Scaler, y: np.ndarray) -> np.ndarray:
    """Targets (B, H, d) -> scaled (B, H·d), per axis or per step and axis (by the scaler's size)."""
    b, h, d = y.shape
    if scaler.lo.size == d:
        return scaler.transform(y).reshape(b, h * d)
    return scaler.transform(y.reshape(b, h * d))


def unscale_targets(scaler: Scaler, s: np.ndarray, horizon: int, n_dof: int) -> np.ndarray:
    """Inverse of :func:`scale_targets`: (B, H·d) -> (B, H, d)."""
    s = s.reshape(-1, horizon * n_dof)
    if scaler.lo.size == n_dof:
        return scaler.inverse(s.reshape(-1, horizon, n_dof))
    return scaler.inverse(s).reshape(-1, horizon, n_dof)


def to_relative(x: np.ndarray, n_dof: int) -> np.ndarray:
    """Pose and reference columns of windows (..., steps, 4·d) minus the last pose."""
    d = n_dof
    out = np.array(x, dtype=np.float64, copy=True)
    current = out[..., -1:, :d].copy()
    out[..., :, :d] -= current
    out[..., :, 3 * d :] -= current
    return out


def _target_base(pose: np.ndarray, vel: np.ndarray, horizon: int, window: WindowConfig, dt: float) -> np.ndarray | None:
    """What the target is measured from: None (absolute), x(k), or x(k) + i·dt·ẋ(k). (B, H, d)."""
    if window.target == "absolute":
        return None
    if window.target == "relative":
        return np.repeat(pose[:, None, :], horizon, axis=1)
    return constant_velocity(pose, vel, horizon, dt)


def encode_target(future: np.ndarray, pose: np.ndarray, vel: np.ndarray, window: WindowConfig, dt: float) -> np.ndarray:
    """Future poses (B, H, d) -> network target in ``window.target`` parameterisation."""
    base = _target_base(pose, vel, future.shape[1], window, dt)
    return future if base is None else future - base


def decode_target(target: np.ndarray, pose: np.ndarray, vel: np.ndarray, window: WindowConfig, dt: float) -> np.ndarray:
    """Inverse of :func:`encode_target`: network output (B, H, d) -> positions in m."""
    base = _target_base(pose, vel, target.shape[1], window, dt)
    return target if base is None else target + base


def constant_velocity(pose: np.ndarray, vel: np.ndarray, horizon: int, dt: float) -> np.ndarray:
    """x(k) + i·dt·ẋ(k) for i = 1 … H: (B, d), (B, d) -> (B, H, d)."""
    steps = dt * np.arange(1, horizon + 1)[None, :, None]
    return pose[:, None, :] + steps * vel[:, None, :]


def free_motion(free, z):
    """Where the state z(k) alone moves the positions in i ticks, C_x A_d^i z(k):
    free (B, H, d, 2d), z (B, 2d) -> (B, H, d).

    Summed over the state's 2d entries in order, one product and one sum at a time, with
    operations NumPy arrays and torch tensors share: the training device's batches
    (``intent.batches``) call it on tensors and round exactly as the NumPy windows do (a
    BLAS-backed ``einsum`` may sum in any order).
    """
    acc = free[..., 0] * z[:, None, None, 0]
    for m in range(1, z.shape[-1]):
        acc = acc + free[..., m] * z[:, None, None, m]
    return acc


def robot_state(model: ImpedanceModel, effort: np.ndarray) -> np.ndarray:
    """The state the robot's effort alone drives the plant to, from rest at tick 0: (T, 2d).

    z_r(0) = 0, z_r(k+1) = A_d z_r(k) + B_d u_r(k) (exact ZOH). By linearity the motion that
    u_r(k) … u_r(k+i−1) cause from rest at tick k is z_r(k+i) − A_d^i z_r(k) (positions:
    the first d rows), which is what the ``hand_alone`` label removes. A non-finite effort
    (a tick the world never applied) counts as 0.
    """
    u = np.nan_to_num(np.asarray(effort, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    Ad, Bd = np.asarray(model.Ad), np.asarray(model.Bd)
    z = np.zeros((u.shape[0], Ad.shape[0]))
    drive = u @ Bd.T  # B_d u_r(k) for every k at once
    for k in range(u.shape[0] - 1):  # T small matrix products: ~1 ms per 1000 ticks
        z[k + 1] = Ad @ z[k] + drive[k]
    return z


def free_response(model: ImpedanceModel, horizon: int) -> np.ndarray:
    """C_x A_d^i for i = 1 … H: where a state's positions go in i ticks with no input, (H, d, 2d)."""
    horizon = check_int_at_least(horizon, "horizon", 1)
    d = model.n_dof
    out = np.empty((horizon, d, 2 * d))
    P = np.asarray(model.Ad, dtype=np.float64)
    for i in range(horizon):
        out[i] = P[:d]
        P = model.Ad @ P
    return out


def trial_plant(trial: Trial) -> ImpedanceModel:
    """The impedance a trial's world rendered between effort and motion (``meta.extra["plant"]``:
    diagonals ``M``, ``D``, ``K``; dt from the meta). Simulated and driven trials record it."""
    plant = trial.meta.extra.get("plant")
    where = f"trial {trial.meta.user}/{trial.meta.task}/seed {trial.meta.seed}"
    if not isinstance(plant, Mapping) or not all(k in plant for k in ("M", "D", "K")):
        raise ValueError(
            f"label 'hand_alone' needs the rendered impedance (meta.extra['plant'] with M, D, K); {where} has none "
            "(recordings without the robot's effort can only be labelled 'tool'; re-collect older simulated data)"
        )
    try:
        return ImpedanceModel(np.diag(plant["M"]), np.diag(plant["D"]), np.diag(plant["K"]), trial.meta.dt)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: malformed meta.extra['plant']: {exc}") from None


def _label_series(trial: Trial, label: str) -> np.ndarray:
    """The per-tick series a label needs: the true intent ("intent") or u_r ("hand_alone"), (T, d)."""
    name = "intent" if label == "intent" else "effort_r"
    series = getattr(trial, name)
    if series is None or not np.isfinite(series).any():
        what = "the operator's true intent (simulated trials only)" if label == "intent" else "the robot's effort u_r"
        raise ValueError(
            f"label {label!r} needs {what}, but the trial {_trial_name(trial)} has no {name}; label 'tool' works on any "
            "trial (coassist train --label)"
        )
    return np.asarray(series, dtype=np.float64)
