"""Loader for rosbag CSV exports: synthetic folders with known defects, then the real
UR5 recordings in ../shared/data/ur5-thesis (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from coassist.data import RecordingError, default_real_data, load_ros_trial, load_ros_user, read_trial, write_trial

# --------------------------------------------------------------------------- synthetic recordings

SECS0 = 1668678526
NSECS0 = 980_000_000  # close to a second boundary: the stamps cross it at seq 103

HEADER = "Time,header.seq,header.stamp.secs,header.stamp.nsecs,header.frame_id"
COLUMNS = {
    "current_pose.csv": (
        "pose.position",
        ["x", "y", "z"],
        ["pose.orientation.x", "pose.orientation.y", "pose.orientation.z", "pose.orientation.w"],
    ),
    "current_velocity.csv": (
        "twist.linear",
        ["x", "y", "z"],
        ["twist.angular.x", "twist.angular.y", "twist.angular.z"],
    ),
    "human_wrench.csv": ("wrench.force", ["x", "y", "z"], ["wrench.torque.x", "wrench.torque.y", "wrench.torque.z"]),
    "robot_ref_pos.csv": (
        "pose.position",
        ["x", "y", "z"],
        ["pose.orientation.x", "pose.orientation.y", "pose.orientation.z", "pose.orientation.w"],
    ),
}
# Value of axis j of each file at seq s: distinct per file so a misalignment shows.
SCALE = {"current_pose.csv": 1e-3, "current_velocity.csv": 2e-3, "human_wrench.csv": 0.5, "robot_ref_pos.csv": -1e-3}


def stamp_ns(seq: int) -> int:
    """8 ms ticks, plus a 12 ms late tick between seq 104 and 105 (a 20 ms gap)."""
    return (seq - 100) * 8_000_000 + (12_000_000 if seq >= 105 else 0)


def value(file: str, seq: int, j: int) -> float:
    return SCALE[file] * seq * (j + 1)


def write_csv(path: Path, seqs, *, drop_column: str | None = None, overrides=None, reverse=False):
    prefix, axes, rest = COLUMNS[path.name]
    names = HEADER.split(",") + [f"{prefix}.{a}" for a in axes] + rest
    rows = []
    for s in seqs:
        ns = SECS0 * 1_000_000_000 + NSECS0 + stamp_ns(s)
        vals = [value(path.name, s, j) for j in range(3)]
        for (seq_o, j), v in (overrides or {}).items():
            if seq_o == s:
                vals[j] = v
        row = [repr(ns * 1e-9 + 1e-4), str(s), str(ns // 1_000_000_000), str(ns % 1_000_000_000), ""]
        row += [repr(v) for v in vals] + ["5e-324"] * len(rest)
        rows.append(row)
    if reverse:
        rows.reverse()
    if drop_column is not None:
        k = names.index(drop_column)
        names = names[:k] + names[k + 1 :]
        rows = [r[:k] + r[k + 1 :] for r in rows]
    path.write_text("\n".join([",".join(names)] + [",".join(r) for r in rows]) + "\n")


def make_recording(folder: Path, *, drop=None, overrides=None, seqs=None) -> Path:
    """pose/vel seq 100..109, wrench 101..109 (starts late), ref 100..108 (ends early,
    written in reverse order). Common seq: 101..108."""
    folder.mkdir(parents=True, exist_ok=True)
    seqs = seqs or {
        "current_pose.csv": range(100, 110),
        "current_velocity.csv": range(100, 110),
        "human_wrench.csv": range(101, 110),
        "robot_ref_pos.csv": range(100, 109),
    }
    for name, s in seqs.items():
        write_csv(
            folder / name,
            s,
            drop_column=drop[1] if drop and drop[0] == name else None,
            overrides=(overrides or {}).get(name),
            reverse=name == "robot_ref_pos.csv",
        )
    return folder


WRENCH_DENORMALS = {"human_wrench.csv": {(102, 0): 5e-324, (103, 1): -1e-182, (104, 0): 1e-99}}


def _set_frames(folder: Path, frames: dict[str, list[str] | str]) -> None:
    """Write the header.frame_id column of each named file: one frame for every row, or one per row."""
    import pandas as pd

    for name, frame in frames.items():
        df = pd.read_csv(folder / name, dtype={"header.frame_id": str})
        df["header.frame_id"] = frame
        df.to_csv(folder / name, index=False)


def test_topics_in_different_frames_are_refused_naming_them(tmp_path):
    """The import reads every topic as it is, with no transform: a wrench in the sensor's frame beside a pose in the
    base frame (a push along the tool's x read as the base's x) is refused naming both, and so is a topic whose frame
    changes within the recording; one frame everywhere, or unset (the lab's exports), loads."""
    everywhere = {name: "base" for name in COLUMNS}
    folder = make_recording(tmp_path / "same")
    _set_frames(folder, everywhere)
    load_ros_trial(folder)
    folder = make_recording(tmp_path / "mixed")
    _set_frames(folder, {**everywhere, "human_wrench.csv": "ft_sensor"})
    with pytest.raises(RecordingError) as info:
        load_ros_trial(folder)
    assert str(info.value) == (
        f"{folder}: its topics are in different frames (current_pose.csv in 'base', current_velocity.csv in 'base', "
        "human_wrench.csv in 'ft_sensor', robot_ref_pos.csv in 'base'); the import reads them as they are, with no "
        "transform: record or export them in the robot's base frame"
    )
    folder = make_recording(tmp_path / "switch")
    _set_frames(folder, {"human_wrench.csv": ["base"] * 4 + ["tool0"] * 5})
    with pytest.raises(
        RecordingError, match=r"human_wrench\.csv: header\.frame_id changes within the recording \('base', 'tool0'\)"
    ):
        load_ros_trial(folder)


def test_alignment_time_and_diagnostics(tmp_path):
    trial = load_ros_trial(make_recording(tmp_path / "user-q" / "trial_1", overrides=WRENCH_DENORMALS))
    seq = np.arange(101, 109)
    assert trial.n_samples == 8 and trial.n_dof == 2
    # values line up by seq across the four files
    for field, file in [
        ("pose", "current_pose.csv"),
        ("velocity", "current_velocity.csv"),
        ("reference", "robot_ref_pos.csv"),
    ]:
        expected = np.column_stack([[value(file, s, j) for s in seq] for j in range(2)])
        np.testing.assert_array_equal(getattr(trial, field), expected, err_msg=field)
    # time from the header stamps minus the first; the 20 ms gap is kept
    np.testing.assert_allclose(trial.time, [0, 0.008, 0.016, 0.024, 0.044, 0.052, 0.060, 0.068], rtol=0, atol=1e-12)
    assert trial.meta.dt == pytest.approx(0.008, abs=1e-12)
    extra = trial.meta.extra
    assert extra["max_gap_s"] == pytest.approx(0.020, abs=1e-12)
    assert extra["rows_dropped"] == 2
    assert dict(extra["rows_dropped_per_file"]) == {
        "current_pose.csv": 2,
        "current_velocity.csv": 2,
        "human_wrench.csv": 1,
        "robot_ref_pos.csv": 1,
    }
    assert (extra["seq_first"], extra["seq_last"], extra["seq_gaps"]) == (101, 108, 0)
    assert extra["stamp_mismatch_max_s"] == 0.0
    assert trial.meta.user == "user-q" and trial.meta.origin == "real" and trial.meta.task == "real"
    assert (trial.meta.object, trial.meta.controller, trial.meta.model_id, trial.meta.seed) == (
        "unknown",
        "unknown",
        None,
        None,
    )


def test_denormals_become_zero(tmp_path):
    trial = load_ros_trial(make_recording(tmp_path / "r", overrides=WRENCH_DENORMALS))
    # rows: seq 101..108 -> index = seq - 101
    assert trial.wrench[1, 0] == 0.0 and not np.signbit(trial.wrench[1, 0])
    assert trial.wrench[2, 1] == 0.0
    assert trial.wrench[3, 0] == 1e-99  # above the 1e-100 threshold: a real (tiny) value
    assert trial.wrench[0, 0] == value("human_wrench.csv", 101, 0)
    assert trial.meta.extra["n_denormals_zeroed"] == 2


def test_three_dofs_and_one(tmp_path):
    folder = make_recording(tmp_path / "r")
    t3 = load_ros_trial(folder, dofs=("x", "y", "z"))
    assert t3.pose.shape == (8, 3)
    np.testing.assert_array_equal(t3.wrench[:, 2], [value("human_wrench.csv", s, 2) for s in range(101, 109)])
    assert load_ros_trial(folder, dofs=("x",)).pose.shape == (8, 1)
    with pytest.raises(ValueError, match="dofs"):
        load_ros_trial(folder, dofs=("x", "z"))


@pytest.mark.parametrize(
    "file, column",
    [
        ("human_wrench.csv", "wrench.force.y"),
        ("current_velocity.csv", "twist.linear.x"),
        ("robot_ref_pos.csv", "header.seq"),
        ("current_pose.csv", "header.stamp.nsecs"),
    ],
)
def test_missing_column_names_file_and_column(tmp_path, file, column):
    folder = make_recording(tmp_path / "r", drop=(file, column))
    with pytest.raises(RecordingError, match=rf"{file}: missing column '{column}'"):
        load_ros_trial(folder)


def test_z_column_only_needed_for_z(tmp_path):
    folder = make_recording(tmp_path / "r", drop=("current_pose.csv", "pose.position.z"))
    assert load_ros_trial(folder).n_dof == 2
    with pytest.raises(RecordingError, match=r"current_pose.csv: missing column 'pose.position.z'"):
        load_ros_trial(folder, dofs=("x", "y", "z"))


def test_missing_file(tmp_path):
    folder = make_recording(tmp_path / "r")
    (folder / "robot_ref_pos.csv").unlink()
    with pytest.raises(RecordingError, match=r"robot_ref_pos\.csv: file not found"):
        load_ros_trial(folder)
    assert issubclass(RecordingError, ValueError)


def test_non_numeric_value(tmp_path):
    folder = make_recording(tmp_path / "r", overrides={"current_velocity.csv": {(105, 1): float("nan")}})
    with pytest.raises(RecordingError, match=r"current_velocity\.csv: column 'twist.linear.y' has 1 missing"):
        load_ros_trial(folder)


def test_repeated_seq_and_no_overlap(tmp_path):
    seqs = {
        "current_pose.csv": [100, 101, 101, 102],
        "current_velocity.csv": range(100, 103),
        "human_wrench.csv": range(100, 103),
        "robot_ref_pos.csv": range(100, 103),
    }
    with pytest.raises(RecordingError, match=r"current_pose\.csv: column 'header.seq' repeats value 101"):
        load_ros_trial(make_recording(tmp_path / "a", seqs=seqs))
    seqs = {
        "current_pose.csv": range(100, 103),
        "current_velocity.csv": range(100, 103),
        "human_wrench.csv": range(200, 203),
        "robot_ref_pos.csv": range(100, 103),
    }
    with pytest.raises(RecordingError, match=r"human_wrench\.csv shares no header\.seq value with current_pose\.csv"):
        load_ros_trial(make_recording(tmp_path / "b", seqs=seqs))


def test_seq_gap_inside_the_join_is_counted(tmp_path):
    seqs = {name: [100, 101, 102, 105, 106] for name in COLUMNS}
    trial = load_ros_trial(make_recording(tmp_path / "r", seqs=seqs))
    assert trial.meta.extra["seq_gaps"] == 2
    assert trial.meta.extra["rows_dropped"] == 0
    # seq 102 -> 105: 3 ticks of 8 ms plus the 12 ms late tick at 105
    assert trial.meta.extra["max_gap_s"] == pytest.approx(0.036, abs=1e-12)


def test_load_user_natural_order(tmp_path):
    user = tmp_path / "user-z"
    for k in (10, 2, 1):
        make_recording(user / f"trial_{k}")
    (user / "notes").mkdir()
    trials = load_ros_user(user)
    assert [t.meta.extra["recording"] for t in trials] == ["trial_1", "trial_2", "trial_10"]
    assert {t.meta.user for t in trials} == {"user-z"}
    with pytest.raises(RecordingError, match="no trial_"):
        load_ros_user(user / "notes")


def test_loaded_trial_round_trips_through_the_store(tmp_path):
    trial = load_ros_trial(make_recording(tmp_path / "r", overrides=WRENCH_DENORMALS), user="u")
    assert read_trial(write_trial(trial, tmp_path / "t.parquet")).equals(trial)


# --------------------------------------------------------------------------- the real recordings


def real_data_dir() -> Path:
    path = default_real_data()
    if not (path / "user-a").is_dir():
        pytest.skip(f"real UR5 recordings (shared/data/ur5-thesis) not found: {path.resolve()}")
    return path


@pytest.mark.real_data
def test_real_user_a():
    trials = load_ros_user(real_data_dir() / "user-a")
    assert [t.meta.extra["recording"] for t in trials] == [f"trial_{k}" for k in range(1, 16)]
    first = trials[0]
    # the first row of trial_1/current_pose.csv, parsed exactly
    assert first.pose[0, 0] == -0.09533516395461707 and first.pose[0, 1] == -0.6129993762781097
    assert first.n_samples == 1992 and first.time[0] == 0.0
    dropped = {t.meta.extra["recording"]: t.meta.extra["rows_dropped"] for t in trials}
    assert dropped == {f"trial_{k}": {8: 1, 12: 13, 13: 1}.get(k, 0) for k in range(1, 16)}
    for t in trials:
        assert t.meta.user == "user-a" and t.n_dof == 2
        assert abs(t.meta.dt - 0.008) < 2e-5
        assert 15.5 < t.duration < 20.5  # README: 16–20 s
        assert t.meta.extra["max_gap_s"] < 0.030
        peak = np.linalg.norm(t.wrench, axis=1).max()
        assert 11.0 < peak < 38.0  # README: peak planar force 12–37 N
        for arr in (t.pose, t.velocity, t.wrench, t.reference):
            nz = np.abs(arr[arr != 0.0])
            assert nz.size == 0 or nz.min() >= 1e-100  # no denormal noise left


@pytest.mark.real_data
def test_real_user_b():
    trials = load_ros_user(real_data_dir() / "user-b")
    assert len(trials) == 3
    for t in trials:
        assert 31.0 < t.duration < 36.5  # README: 31–36 s
        assert abs(t.meta.dt - 0.008) < 5e-5
        # the person takes a very different route: deviations up to about 0.5 m
        assert 0.4 < np.linalg.norm(t.pose - t.reference, axis=1).max() < 0.6


def test_real_data_folder_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("COASSIST_REAL_DATA", str(tmp_path))
    assert default_real_data() == tmp_path
    monkeypatch.delenv("COASSIST_REAL_DATA")
    assert default_real_data().parts[-3:] == ("shared", "data", "ur5-thesis")


def test_a_header_naming_a_column_twice_is_refused(tmp_path):
    """A second column named like the force (holding the torque) was read silently, the first copy as the force:
    max |fx| 0.71 instead of 11.08 N on a user-a trial (review, 2026-12-06)."""
    folder = make_recording(tmp_path / "r")
    path = folder / "human_wrench.csv"
    lines = path.read_text().splitlines()
    lines[0] = lines[0].replace("wrench.force.y", "wrench.force.x")
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(
        RecordingError, match=r"human_wrench\.csv: the header names column 'wrench.force.x' more than once"
    ):
        load_ros_trial(folder)


def test_a_topic_that_stopped_early_is_said(tmp_path):
    """The join keeps the ticks every topic has: a topic that stopped early cut a recording to 5 % of itself without a
    word (review, 2026-12-06). A warning names the short topic; the thesis lab's recordings drop at most 0.7 %."""
    from coassist.data.rosbag_csv import RecordingWarning

    seqs = {name: range(100, 200) for name in ("current_pose.csv", "current_velocity.csv", "human_wrench.csv")}
    folder = make_recording(tmp_path / "r", seqs={**seqs, "robot_ref_pos.csv": range(100, 160)})
    with pytest.warns(
        RecordingWarning,
        match=r"the topics share 60 of the longest's 100 rows \(40 % dropped\): robot_ref_pos\.csv holds 60",
    ):
        trial = load_ros_trial(folder)
    assert trial.n_samples == 60
    whole = make_recording(tmp_path / "w", seqs={**seqs, "robot_ref_pos.csv": range(100, 198)})  # 2 % dropped
    import warnings

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        load_ros_trial(whole)
    assert [str(w.message) for w in seen if "dropped" in str(w.message)] == []


def test_a_users_folder_of_recordings_is_read_as_recordings_beside_a_trial_file(tmp_path):
    """A folder of trial_* recordings with a trial file beside them (an export kept there) is still a user's
    recordings: a folder of trial files is read as such only where it holds no recordings."""
    from coassist.intent import load_trials

    user = tmp_path / "user-z"
    make_recording(user / "trial_1")
    make_recording(user / "trial_2")
    write_trial(load_ros_trial(user / "trial_1"), user / "kept.parquet")
    got = load_trials([user])
    assert [lt.id for lt in got] == [f"{tmp_path.name}/user-z/trial_1", f"{tmp_path.name}/user-z/trial_2"]
