"""Training windows gathered on the training device (issue 19).

A :class:`~coassist.intent.features.WindowSet` cuts windows on the CPU with NumPy; a
training step that did so for every batch (gather, frame change, scaling, a host→device
copy) spent its time feeding the device instead of training. :class:`DeviceWindows`
holds the trials' features once on the device, (ΣT, 4·d) float64, with the index of every
window's last tick k, and cuts a batch there by index arithmetic alone::

    x[b, s] = features[ends[sel[b]] + offsets[s]]          s = 0 … steps−1
    future[b, i] = features[ends[sel[b]] + i, :d]          i = 1 … H

followed by the same frame change, target parameterisation (``features.encode_target``),
mirroring and [−1, 1] scaling (``Scaler.transform``) as the NumPy path, in the same
order and in float64, then one cast to float32. IEEE-754 makes each of those elementwise
operations correctly rounded on every device, so a batch here equals the NumPy batch
bit for bit (``tests/intent/test_batches.py``): a training run fed from here takes the
same steps as one fed from NumPy.

Why float64 and per-batch scaling rather than windows scaled once: in the relative
frame the current pose is subtracted *before* scaling, and scaling is affine, so scaled
features minus a scaled pose differ from the scaled difference in the last bits. The
per-batch arithmetic is a few elementwise kernels on (B, steps, 4·d) values, negligible
beside the network's forward and backward passes.
"""

from __future__ import annotations

import numpy as np
import torch

from coassist.intent.features import Scaler, WindowSet, free_motion

__all__ = ["DeviceWindows"]


class DeviceWindows:
    """The windows of a :class:`WindowSet`, cut and scaled on ``device``.

    ``batch(sel, signs)`` returns (inputs (B, steps, 4·d), targets (B, H·d)), float32,
    scaled by ``input_scaler`` and ``target_scaler``; ``sel`` (B,) int64 window indices
    and ``signs`` (B, d) float64 of ±1 (mirroring each axis; None: none), both on
    ``self.device`` (``device``, except the CPU for MPS).
    """

    def __init__(
        self, ws: WindowSet, input_scaler: Scaler, target_scaler: Scaler, device: str | torch.device = "cpu"
    ) -> None:
        # Apple's MPS has no float64: there the windows are cut on the CPU, the same way, and
        # each batch is copied over (the path of before, for that device only).
        self.out_device = torch.device(device)
        dev = torch.device("cpu") if self.out_device.type == "mps" else self.out_device
        w, d = ws.window, ws.n_dof

        def f64(a: np.ndarray) -> torch.Tensor:
            return torch.tensor(np.asarray(a, dtype=np.float64), device=dev)  # a copy: the arrays are read-only

        self.device, self.window, self.n_dof, self._n = dev, w, d, len(ws)
        self.features = f64(ws.features)  # (ΣT, 4·d), SI units
        self.ends = torch.as_tensor(ws.ends, dtype=torch.int64, device=dev)  # (N,) global index of k
        self.offsets = torch.as_tensor(w.offsets, dtype=torch.int64, device=dev)  # (steps,)
        self.ahead = torch.arange(1, w.horizon + 1, dtype=torch.int64, device=dev)  # (H,)
        # i·dt for i = 1 … H, computed as features.constant_velocity computes it.
        self.step_times = f64(ws.dt * np.arange(1, w.horizon + 1))
        self.trial = torch.as_tensor(ws.trial, dtype=torch.int64, device=dev)  # (N,) owning trial
        label, free = ws.label_arrays()
        self.label = None if label is None else f64(label)  # intent (ΣT, d) or z_r (ΣT, 2d)
        self.free = None if free is None else f64(free)  # (n_trials, H, d, 2d)
        self.in_lo, self.in_span = f64(input_scaler.lo), f64(input_scaler.span)
        self.out_lo, self.out_span = f64(target_scaler.lo), f64(target_scaler.span)

    def __len__(self) -> int:
        return self._n

    def raw_inputs(self, sel: torch.Tensor) -> torch.Tensor:
        """(B, steps, 4·d) float64 windows in the configured frame (``WindowSet.raw_inputs``)."""
        x = self.features[self.ends[sel][:, None] + self.offsets[None, :]]
        if self.window.input_frame == "relative":  # features.to_relative
            d = self.n_dof
            current = x[:, -1:, :d].clone()
            x[:, :, :d] -= current
            x[:, :, 3 * d :] -= current
        return x

    def future(self, sel: torch.Tensor) -> torch.Tensor:
        """(B, H, d) float64 labelled future positions (``WindowSet.future``)."""
        ends = self.ends[sel]
        idx = ends[:, None] + self.ahead[None, :]
        d, label = self.n_dof, self.window.label
        if label == "tool":
            return self.features[idx][:, :, :d]
        if self.label is None:
            raise ValueError("this WindowSet was cut without futures (need_future=False)")
        if label == "intent":
            return self.label[idx]
        if self.free is None:
            raise ValueError("this WindowSet was cut without futures (need_future=False)")
        series = self.label
        pushed = series[idx][:, :, :d] - free_motion(self.free[self.trial[sel]], series[ends])
        return self.features[idx][:, :, :d] - pushed

    def raw_targets(self, sel: torch.Tensor) -> torch.Tensor:
        """(B, H, d) float64 targets in the configured parameterisation (``WindowSet.raw_targets``)."""
        future = self.future(sel)
        target = self.window.target
        if target == "absolute":
            return future
        f = self.features[self.ends[sel]]
        pose = f[:, None, : self.n_dof]
        if target == "relative":
            return future - pose
        vel = f[:, None, self.n_dof : 2 * self.n_dof]
        return future - (pose + self.step_times[None, :, None] * vel)  # features.constant_velocity

    def batch(self, sel: torch.Tensor, signs: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Scaled float32 inputs (B, steps, 4·d) and targets (B, H·d); ``signs`` (B, d) mirror the axes."""
        x, y = self.raw_inputs(sel), self.raw_targets(sel)
        if signs is not None:
            x = x * signs.repeat(1, 4)[:, None, :]
            y = y * signs[:, None, :]
        x = 2.0 * (x - self.in_lo) / self.in_span - 1.0  # Scaler.transform, the same operations in order
        b, h, d = y.shape
        if self.out_lo.numel() == d:  # features.scale_targets: per axis, or per step and axis
            y = (2.0 * (y - self.out_lo) / self.out_span - 1.0).reshape(b, h * d)
        else:
            y = 2.0 * (y.reshape(b, h * d) - self.out_lo) / self.out_span - 1.0
        x, y = x.to(torch.float32).contiguous(), y.to(torch.float32).contiguous()
        if self.out_device != self.device:
            return x.to(self.out_device), y.to(self.out_device)
        return x, y
