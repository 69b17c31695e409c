"""What a calibration learnt of each person, drawn: their paths round the task and their arm (``coassist calibrate``).

One panel per person, in the plane of the task [m]: the nominal plan (black, dashed), each demonstrated intent path
the person model was fitted from (the primitives' rendering, :meth:`~coassist.scenario.path_model.PathModel.demonstrations`),
coloured by its way round (left blue, right orange, no detour grey), and each way's mean path (thick: the mean of its
demonstrations at each phase, which is the primitive of their mean weights, the ProMP's mean; a way nobody took is not
drawn: the filter gives the present estimate's rows there). The title says the arm (K̂ and Ĉ with their
jackknife standard errors, or that it was assumed), the present estimate's noise σ₀ and how far the detours repeat
(:meth:`~coassist.scenario.path_model.PathModel.repeatability`): what a lab checks before a person assists with it —
a way shown once, paths that do not repeat, an arm far from the 100–5000 N/m of people's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from coassist._io import atomic_write_bytes, figure_bytes
from coassist.experiments.person_calibration import PersonCalibration
from coassist.scenario.person_model import PersonFit

__all__ = [
    "PERSON_FIGURE_FILE",
    "WAY_COLOURS",
    "calibration_panels",
    "person_figure",
    "person_figure_png",
    "write_person_figure",
]

#: The figure's name in a person-model folder (beside person-model.json).
PERSON_FIGURE_FILE = "person-model.png"

#: Each way round's colour: +1 left, −1 right, 0 no detour.
WAY_COLOURS = {1: "tab:blue", -1: "tab:orange", 0: "0.55"}
_WAY_NAMES = {1: "left", -1: "right", 0: "no detour"}


def calibration_panels(people: Sequence[PersonCalibration]) -> list[tuple[str, PersonFit]]:
    """One panel per calibrated person: "person (task, n trials)" and their fit."""
    return [(f"{c.person} ({c.task}, {len(c.trials)} trials)", c.fit) for c in people]


def _title(heading: str, fit: PersonFit) -> str:
    arm, paths = fit.arm, fit.paths
    if arm.method == "probe-iv":
        arm_text = (
            f"K̂ {arm.stiffness:.0f} ± {arm.stiffness_se:.0f} N/m, Ĉ {arm.damping:.1f} ± {arm.damping_se:.1f} N·s/m "
            f"({arm.trials} probe trials)"
        )
    else:
        arm_text = f"arm assumed: K̂ {arm.stiffness:.0f} N/m, Ĉ {arm.damping:.1f} N·s/m"
    repeat = paths.repeatability()
    repeat_text = "no way taken twice" if repeat is None else f"detours repeat to {repeat:.2f}"
    return f"{heading}\n{arm_text}\nσ₀ {1e3 * paths.noise:.1f} mm, {repeat_text}"


def person_figure(panels: Sequence[tuple[str, PersonFit]]) -> Any:
    """The figure (a matplotlib Figure, Agg): one panel per (heading, fit) of ``panels``, in their order (module
    docstring); :func:`calibration_panels` makes them of ``coassist calibrate``'s people."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not panels:
        raise ValueError("person_figure needs at least one calibrated person")
    cols = min(3, len(panels))
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.6 * rows), squeeze=False)
    for ax in axes.ravel()[len(panels) :]:
        ax.set_visible(False)
    for ax, (heading, fit) in zip(axes.ravel(), panels):
        model = fit.paths
        plan = model.nominal
        ax.plot(plan[:, 0], plan[:, 1], "k--", lw=1.2, label="plan", gid="plan")
        demos = model.demonstrations()
        for j, (demo, side) in enumerate(zip(demos, model.sides.tolist())):
            label = f"demonstrated, {_WAY_NAMES[side]}" if side not in model.sides[:j] else None
            ax.plot(demo[:, 0], demo[:, 1], color=WAY_COLOURS[side], lw=0.9, alpha=0.7, label=label, gid=f"demo-{j}")
        for way in sorted(set(model.sides.tolist()), reverse=True):
            mean = demos[model.sides == way].mean(axis=0)  # the primitives are linear in their weights
            ax.plot(
                mean[:, 0],
                mean[:, 1],
                color=WAY_COLOURS[way],
                lw=2.6,
                label=f"mean, {_WAY_NAMES[way]}",
                gid=f"way{way}",
            )
        ax.plot(*plan[0], "ko", ms=5, ls="")
        ax.plot(*plan[-1], marker="x", color="k", ms=9, mew=2, ls="")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(_title(heading, fit), fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    if cols > 1:  # a lone panel's own title says it (the line is wider than one panel)
        fig.suptitle("The person model: each person's intent paths from their calibration trials, and their arm")
    fig.tight_layout()
    return fig


def write_person_figure(panels: Sequence[tuple[str, PersonFit]], path: str | Path) -> Path:
    """:func:`person_figure` to the PNG ``path`` (written whole or not at all); returns the path."""
    return atomic_write_bytes(path, person_figure_png(panels))


def person_figure_png(panels: Sequence[tuple[str, PersonFit]]) -> bytes:
    """:func:`person_figure` as PNG bytes (drawn in memory: a caller that writes other files first writes this last)."""
    import matplotlib.pyplot as plt

    fig = person_figure(panels)
    try:
        return figure_bytes(fig)
    finally:
        plt.close(fig)
