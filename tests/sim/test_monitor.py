"""The monitor view (coassist.sim.monitor): what is drawn comes from the trial, and the file is whole."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from matplotlib.patches import Circle, Rectangle

from coassist.data import Trial, TrialMeta, write_trial
from coassist.sim import monitor

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
PNG_END = b"IEND\xaeB`\x82"


def _trial(*, simulated: bool = True, n: int = 300, horizon: int = 8, seed: int = 0) -> Trial:
    """An x-y trial with known numbers: the tip moves along a quarter circle and back."""
    rng = np.random.default_rng(seed)
    dt = 0.008
    t = np.arange(n) * dt
    s = np.sin(np.pi * t / t[-1])  # speed profile: zero at both ends
    pose = np.stack([0.3 * np.cumsum(s) * dt, 0.1 * np.sin(2 * t)], axis=1)
    velocity = np.gradient(pose, dt, axis=0)
    reference = np.stack([np.linspace(0.0, pose[-1, 0], n), np.zeros(n)], axis=1)
    wrench = np.stack([5.0 * s + rng.normal(0, 0.1, n), -3.0 * s], axis=1)
    extra: dict = {}
    kwargs: dict = {}
    if simulated:
        extra = {
            "obstacle": {"center": [0.05, 0.02], "size": [0.02, 0.04]},
            "target": [0.11, 0.0],
            "arrive_radius": 0.02,
        }
        prediction = pose[:, None, :] + 0.01 * np.arange(1, horizon + 1)[None, :, None]
        prediction[:20] = np.nan  # no history yet: nothing predicted
        kwargs = dict(
            prediction=prediction,
            intent=pose + 0.002,
            effort_h=wrench.copy(),
            effort_r=np.stack([1.5 * s, 0.5 * s], axis=1),
        )
    meta = TrialMeta(
        user="user-1",
        task="curved",
        object="board",
        controller="cooperative",
        model_id=None,
        seed=seed,
        origin="sim" if simulated else "real",
        dt=dt,
        extra=extra,
    )
    return Trial(meta=meta, time=t, pose=pose, velocity=velocity, wrench=wrench, reference=reference, **kwargs)


@pytest.fixture
def drawn(monkeypatch, tmp_path):
    """plot_trial's figure, kept for inspection (it is still written through the real writer)."""
    figures = []
    real_save = monitor.save_figure

    def keep(fig, path, *args):
        figures.append(fig)
        return real_save(fig, path, *args)

    monkeypatch.setattr(monitor, "save_figure", keep)

    def draw(trial, **kwargs):
        out = monitor.plot_trial(trial, tmp_path / "monitor.png", **kwargs)
        (fig,) = figures[-1:]
        return out, fig

    return draw


def _line(ax, label):
    (line,) = [ln for ln in ax.lines if ln.get_label() == label]
    return np.column_stack([line.get_xdata(), line.get_ydata()]).astype(float)


def test_the_paths_are_the_trials(drawn):
    trial = _trial()
    out, fig = drawn(trial)
    assert out.read_bytes().startswith(PNG_MAGIC)
    ax, axf = fig.axes
    np.testing.assert_array_equal(_line(ax, "nominal path"), trial.reference)
    np.testing.assert_array_equal(_line(ax, "tip path"), trial.pose)
    np.testing.assert_array_equal(_line(ax, "operator intent"), trial.intent)
    np.testing.assert_array_equal(_line(ax, "start"), trial.pose[:1])
    np.testing.assert_array_equal(_line(ax, "target"), [[0.11, 0.0]])
    assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]"


def test_obstacle_and_target_come_from_the_meta(drawn):
    _, fig = drawn(_trial())
    ax = fig.axes[0]
    (box,) = [p for p in ax.patches if isinstance(p, Rectangle)]
    assert box.get_xy() == pytest.approx((0.05 - 0.01, 0.02 - 0.02))
    assert (box.get_width(), box.get_height()) == pytest.approx((0.02, 0.04))
    (ball,) = [p for p in ax.patches if isinstance(p, Circle)]
    assert ball.center == pytest.approx((0.11, 0.0)) and ball.radius == pytest.approx(0.02)


@pytest.mark.parametrize(
    "extra",
    [
        {"obstacle": {"center": [0, "a"], "size": [-1, 0]}, "target": "x", "arrive_radius": -1},
        {"obstacle": [1, 2], "target": [1.0, 2.0, 3.0], "arrive_radius": "r"},
    ],
)
def test_a_scene_the_meta_tells_badly_is_left_out_not_a_traceback(drawn, extra):
    """A file of the format without checksums, its meta edited by hand: ``show`` ended in a TypeError (review,
    2026-12-06). What is malformed is not drawn; the target falls back to the plan's end."""
    from dataclasses import replace

    trial = _trial()
    trial = replace(trial, meta=replace(trial.meta, extra=extra))
    _, fig = drawn(trial)
    ax = fig.axes[0]
    assert not [p for p in ax.patches if isinstance(p, Rectangle)]
    (ball,) = [p for p in ax.patches if isinstance(p, Circle)]
    assert ball.center == pytest.approx(tuple(trial.reference[-1])) and ball.radius == pytest.approx(0.025)


@pytest.mark.parametrize("n_predictions", [3, 6])
def test_prediction_strokes_are_predictions_at_moving_ticks(drawn, n_predictions):
    trial = _trial()
    _, fig = drawn(trial, n_predictions=n_predictions)
    ax = fig.axes[0]
    strokes = [ln for ln in ax.lines if ln.get_linewidth() == 3]
    assert len(strokes) == n_predictions
    assert strokes[0].get_label() == "prediction horizon"
    speed = np.linalg.norm(trial.velocity, axis=1)
    valid = np.flatnonzero(np.isfinite(trial.prediction[:, 0, 0]))
    moving = valid[speed[valid] > 0.2 * speed[valid].max()]
    ticks = []
    for stroke in strokes:
        xy = np.column_stack([stroke.get_xdata(), stroke.get_ydata()])
        (k,) = [k for k in range(trial.n_samples) if np.array_equal(trial.prediction[k], xy, equal_nan=False)]
        ticks.append(k)
    # spread over the moving part, first and last moving tick included, in time order
    assert ticks[0] == moving[0] and ticks[-1] == moving[-1] and ticks == sorted(ticks)
    assert set(ticks) <= set(moving)


def test_force_panel_is_the_trials_force(drawn):
    trial = _trial()
    _, fig = drawn(trial)
    axf = fig.axes[1]
    planar = np.linalg.norm(trial.wrench[:, :2], axis=1)
    np.testing.assert_allclose(_line(axf, "‖f‖ (planar)"), np.column_stack([trial.time, planar]))
    np.testing.assert_array_equal(_line(axf, "f_x"), np.column_stack([trial.time, trial.wrench[:, 0]]))
    np.testing.assert_array_equal(_line(axf, "f_y"), np.column_stack([trial.time, trial.wrench[:, 1]]))
    robot = np.linalg.norm(trial.effort_r, axis=1)
    np.testing.assert_allclose(_line(axf, "‖u_r‖ (robot)"), np.column_stack([trial.time, robot]))
    assert axf.get_title() == f"duration {trial.time[-1]:.1f} s, peak ‖f‖ {planar.max():.1f} N"
    assert axf.get_xlabel() == "time [s]" and axf.get_ylabel() == "force at the sensor [N]"


def test_a_recording_has_no_intent_obstacle_or_predictions(drawn):
    trial = _trial(simulated=False)
    _, fig = drawn(trial)
    ax, axf = fig.axes
    labels = {ln.get_label() for ln in ax.lines}
    assert "operator intent" not in labels and "prediction horizon" not in labels
    assert not [p for p in ax.patches if isinstance(p, Rectangle)]
    # the target defaults to the last nominal point, with the default 2.5 cm ball
    np.testing.assert_array_equal(_line(ax, "target"), trial.reference[-1:])
    (ball,) = [p for p in ax.patches if isinstance(p, Circle)]
    assert ball.radius == pytest.approx(0.025)
    assert "‖u_r‖ (robot)" not in {ln.get_label() for ln in axf.lines}


def test_the_title_names_the_trial(drawn):
    _, fig = drawn(_trial())
    assert fig.axes[0].get_title() == "sim: user-1 · curved · board · cooperative"
    _, fig = drawn(_trial(), title="mine")
    assert fig.axes[0].get_title() == "mine"


def test_the_file_appears_whole_by_one_rename(monkeypatch, tmp_path):
    out = tmp_path / "monitor.png"
    out.write_bytes(b"the previous figure")
    real_replace = os.replace
    seen = []

    def spy(src, dst):
        src, dst = Path(src), Path(dst)
        # at the rename: the old file is untouched and the new one complete, beside it
        seen.append((src.parent == dst.parent, dst.read_bytes(), src.read_bytes()))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    monitor.plot_trial(_trial(), out)
    ((same_folder, old, new),) = seen
    assert same_folder and old == b"the previous figure"
    assert new.startswith(PNG_MAGIC) and new.endswith(PNG_END)
    assert out.read_bytes() == new
    assert sorted(p.name for p in tmp_path.iterdir()) == ["monitor.png"]


def test_a_failed_write_keeps_the_previous_file(monkeypatch, tmp_path):
    out = tmp_path / "monitor.png"
    out.write_bytes(b"the previous figure")

    def disk_full(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", disk_full)  # fails after the bytes went to the temporary file
    with pytest.raises(OSError, match="No space left"):
        monitor.plot_trial(_trial(), out)
    assert out.read_bytes() == b"the previous figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["monitor.png"]


@pytest.mark.parametrize(
    "trial, message",
    [("not a trial", "trial must be a Trial, got str"), (None, "trial must be a Trial, got NoneType")],
)
def test_bad_input_is_one_clear_error(trial, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        monitor.plot_trial(trial, tmp_path / "x.png")


def test_a_one_dof_trial_is_refused(tmp_path):
    t = _trial()
    one = Trial(
        meta=t.meta,
        time=t.time,
        pose=t.pose[:, :1],
        velocity=t.velocity[:, :1],
        wrench=t.wrench[:, :1],
        reference=t.reference[:, :1],
    )
    with pytest.raises(ValueError, match="needs x-y trials, got 1 DOF"):
        monitor.plot_trial(one, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_load_for_show_reads_a_trial_file_and_names_a_bad_path(tmp_path):
    trial = _trial()
    path = write_trial(trial, tmp_path / "t.parquet")
    assert monitor.load_for_show(path).equals(trial)
    with pytest.raises(ValueError, match=r"nothing\.parquet: no such file or folder"):
        monitor.load_for_show(tmp_path / "nothing.parquet")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match=r"empty: neither a dataset \(manifest\.json\) nor a recording"):
        monitor.load_for_show(tmp_path / "empty")


def test_the_title_of_a_trial_whose_controller_reads_no_intent_does_not_name_a_model():
    """The UR review of 3063e1e: an MG calibration trial's figure said "model present-held" where drive's line said
    "assistance: none": MG, its probe and IMP log a source's rows but read none."""
    from dataclasses import replace

    meta = _trial().meta
    for controller in ("manual", "manual-probe", "impedance"):
        title = monitor.trial_title(replace(meta, controller=controller, model_id="present-held"))
        assert title.endswith(f"· {controller} · no intent read (present-held's rows logged)"), title
    assembled = monitor.trial_title(replace(meta, controller="cooperative", model_id="present-held"))
    assert assembled.endswith("· cooperative · model present-held")
    assert monitor.trial_title(replace(meta, controller="manual", model_id=None)).endswith("· manual")
