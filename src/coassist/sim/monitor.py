"""The monitor view of a trial (thesis Fig. 5.7–5.8) plus its force over time.

Left: the x-y plane with the nominal path (dashed), the path actually taken, the
operator's intent (simulated trials), the obstacle box and the target, and the
prediction horizon in use at a few ticks (short coloured strokes ahead of the tip).
Right: the planar force measured at the sensor over time (‖f‖ and its components).
Works for simulated trials (meta.extra holds the obstacle and target) and recorded
ones (target = the last nominal reference point; no obstacle known).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from coassist._io import save_figure
from coassist.control.presets import INTENT_FREE_CONTROLLERS
from coassist.data import Trial, TrialMeta


def _numbers(value: object, n: int) -> tuple[float, ...] | None:
    """``value`` as ``n`` finite numbers (positive where ``n`` is 1), or None where it is not."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        return None
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        return None
    if n == 1 and not value[0] > 0:
        return None
    return tuple(float(v) for v in value)


def trial_title(meta: TrialMeta) -> str:
    """A trial figure's title from its ``meta`` (:class:`~coassist.data.TrialMeta`): where, who, what task, object and
    controller, and the intent source. A controller that reads no intent (MG, its probe, IMP) logs a source's rows
    all the same: the title says so, not "model present-held" beside an MG trial that had no assistance."""
    head = f"{meta.origin}: {meta.user} · {meta.task} · {meta.object} · {meta.controller}"
    if not meta.model_id:
        return head
    if meta.controller in INTENT_FREE_CONTROLLERS:
        return f"{head} · no intent read ({meta.model_id}'s rows logged)"
    return f"{head} · model {meta.model_id}"


def plot_trial(trial: Trial, out: str | Path, *, n_predictions: int = 6, title: str | None = None) -> Path:
    """Draw the monitor view of ``trial`` to the PNG ``out``; returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Rectangle

    if not isinstance(trial, Trial):
        raise ValueError(f"trial must be a Trial, got {type(trial).__name__}")
    if trial.n_dof < 2:
        raise ValueError(f"the monitor view needs x-y trials, got {trial.n_dof} DOF")
    out = Path(out)
    extra = trial.meta.extra
    fig, (ax, axf) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1.25, 1]})

    ax.plot(trial.reference[:, 0], trial.reference[:, 1], "k--", lw=1.2, label="nominal path")
    if trial.intent is not None:
        ax.plot(trial.intent[:, 0], trial.intent[:, 1], color="tab:green", lw=1.0, alpha=0.8, label="operator intent")
    ax.plot(trial.pose[:, 0], trial.pose[:, 1], color="tab:blue", lw=1.8, label="tip path")
    # what meta.extra says of the scene is drawn where it is well formed (a file of the format without checksums, edited
    # by hand, made this a traceback), else left out: the trial's own arrays are drawn whatever it says
    told_box = extra.get("obstacle")
    told_box = told_box if isinstance(told_box, Mapping) else {}  # meta.extra is frozen: read-only mappings
    box, size = _numbers(told_box.get("center"), 2), _numbers(told_box.get("size"), 2)
    if box is not None and size is not None and min(size) > 0:
        (cx, cy), (w, h) = box, size
        ax.add_patch(Rectangle((cx - w / 2, cy - h / 2), w, h, color="tab:red", alpha=0.6, label="obstacle"))
    told = _numbers(extra.get("target"), 2)
    target = (told[0], told[1]) if told is not None else (float(trial.reference[-1, 0]), float(trial.reference[-1, 1]))
    radius = (_numbers([extra.get("arrive_radius")], 1) or (0.025,))[0]
    ax.add_patch(Circle(target, radius, fill=False, color="tab:orange", lw=1.5))
    ax.plot(*target, marker="x", color="tab:orange", ms=10, mew=2, ls="", label="target")
    ax.plot(*trial.pose[0], marker="o", color="k", ms=5, ls="", label="start")

    if trial.prediction is not None:
        valid = np.flatnonzero(np.isfinite(trial.prediction[:, 0, 0]))
        if valid.size:
            # Ticks where the tip is moving, spread over the trial.
            speed = np.linalg.norm(trial.velocity[valid], axis=1)
            moving = valid[speed > 0.2 * max(float(speed.max()), 1e-9)]
            ticks = moving if moving.size >= n_predictions else valid
            chosen = ticks[np.linspace(0, ticks.size - 1, n_predictions).round().astype(int)]
            cmap = plt.get_cmap("plasma")
            for j, k in enumerate(chosen):
                p = trial.prediction[k]
                ax.plot(
                    p[:, 0],
                    p[:, 1],
                    color=cmap(j / max(1, len(chosen) - 1)),
                    lw=3,
                    alpha=0.85,
                    label="prediction horizon" if j == 0 else None,
                )
                ax.plot(*trial.pose[k], marker=".", color=cmap(j / max(1, len(chosen) - 1)), ms=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    meta = trial.meta
    label = title or trial_title(meta)
    ax.set_title(label, fontsize=10)

    f = trial.wrench
    axf.plot(trial.time, np.linalg.norm(f[:, :2], axis=1), color="k", lw=1.4, label="‖f‖ (planar)")
    axf.plot(trial.time, f[:, 0], color="tab:blue", lw=0.9, label="f_x")
    axf.plot(trial.time, f[:, 1], color="tab:red", lw=0.9, label="f_y")
    if trial.effort_r is not None:
        axf.plot(
            trial.time,
            np.linalg.norm(trial.effort_r[:, :2], axis=1),
            color="tab:purple",
            lw=0.9,
            ls=":",
            label="‖u_r‖ (robot)",
        )
    axf.set_xlabel("time [s]")
    axf.set_ylabel("force at the sensor [N]")
    axf.grid(alpha=0.3)
    axf.legend(loc="best", fontsize=8)
    axf.set_title(
        f"duration {trial.duration:.1f} s, peak ‖f‖ {np.linalg.norm(f[:, :2], axis=1).max():.1f} N", fontsize=10
    )
    fig.tight_layout()
    save_figure(fig, out)
    plt.close(fig)
    return out


def load_for_show(path: str | Path, index: int = 0) -> Trial:
    """A trial from a trial file, a dataset folder (its ``index``-th trial) or a ROS CSV recording folder."""
    from coassist.data import load_ros_trial, read_trial
    from coassist.data.datasets import read_dataset_trial

    path = Path(path)
    if path.is_dir():
        if (path / "manifest.json").exists():
            return read_dataset_trial(path, index)  # a bad other trial does not matter here
        if (path / "current_pose.csv").exists():
            return load_ros_trial(path)
        raise ValueError(f"{path}: neither a dataset (manifest.json) nor a recording (current_pose.csv)")
    if not path.exists():
        raise ValueError(f"{path}: no such file or folder")
    return read_trial(path)
