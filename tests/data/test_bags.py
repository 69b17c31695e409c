"""Reading ROS 1 / ROS 2 bags (coassist.data.bags): the real UR5 recordings written back
into bags from their CSV export must load to the very Trial the CSV loader gives, and
small synthetic bags carry each kind of bad input."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from coassist.data import RecordingError, default_real_data, load_ros_trial
from coassist.data.bags import BAG_TOPICS, bag_paths, is_bag, load_bag_trial

rosbags = pytest.importorskip("rosbags", reason="the bags extra (rosbags) is not installed")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

# The CSV file of each topic and the message type its columns came from
# (pose.position/orientation -> PoseStamped, twist.linear/angular -> TwistStamped, …).
CSV_OF = {
    "/current_pose": ("current_pose.csv", "geometry_msgs/msg/PoseStamped"),
    "/current_velocity": ("current_velocity.csv", "geometry_msgs/msg/TwistStamped"),
    "/human_wrench": ("human_wrench.csv", "geometry_msgs/msg/WrenchStamped"),
    "/robot_ref_pos": ("robot_ref_pos.csv", "geometry_msgs/msg/PoseStamped"),
}


def _body(ts, msgtype: str, row) -> object:
    """The message body of one CSV row, every column in its field."""
    g = lambda c: float(row[c])  # noqa: E731
    if msgtype.endswith("PoseStamped"):
        Point, Quaternion, Pose = (ts.types[f"geometry_msgs/msg/{n}"] for n in ("Point", "Quaternion", "Pose"))
        return Pose(
            position=Point(x=g("pose.position.x"), y=g("pose.position.y"), z=g("pose.position.z")),
            orientation=Quaternion(
                x=g("pose.orientation.x"),
                y=g("pose.orientation.y"),
                z=g("pose.orientation.z"),
                w=g("pose.orientation.w"),
            ),
        )
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    if msgtype.endswith("TwistStamped"):
        Twist = ts.types["geometry_msgs/msg/Twist"]
        return Twist(
            linear=Vector3(*(g(f"twist.linear.{a}") for a in "xyz")),
            angular=Vector3(*(g(f"twist.angular.{a}") for a in "xyz")),
        )
    Wrench = ts.types["geometry_msgs/msg/Wrench"]
    return Wrench(
        force=Vector3(*(g(f"wrench.force.{a}") for a in "xyz")),
        torque=Vector3(*(g(f"wrench.torque.{a}") for a in "xyz")),
    )


def _message(ts, msgtype: str, row, ros1: bool) -> object:
    Time, Header = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"]
    stamp = Time(sec=int(row["header.stamp.secs"]), nanosec=int(row["header.stamp.nsecs"]))
    frame = "" if pd.isna(row["header.frame_id"]) else str(row["header.frame_id"])
    header = (
        Header(seq=int(row["header.seq"]), stamp=stamp, frame_id=frame) if ros1 else Header(stamp=stamp, frame_id=frame)
    )
    body = _body(ts, msgtype, row)
    cls = ts.types[msgtype]
    field = {"PoseStamped": "pose", "TwistStamped": "twist", "WrenchStamped": "wrench"}[msgtype.rsplit("/", 1)[1]]
    return cls(header=header, **{field: body})


def csv_to_bag(folder: Path, out: Path, kind: str) -> Path:
    """Write a CSV-exported recording as a bag: kind "ros1" (.bag), "sqlite3" or "mcap" (ROS 2 folders).

    The log time is the CSV's receive time ``Time`` rounded to the ns exactly (Fraction:
    a float product at 1.7e18 ns would round to 256 ns).
    """
    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    entries = []
    for topic, (file, msgtype) in CSV_OF.items():
        df = pd.read_csv(folder / file)
        for _, row in df.iterrows():
            log_ns = round(Fraction(float(row["Time"])) * 10**9)
            entries.append((log_ns, topic, msgtype, _message(ts, msgtype, row, ros1)))
    entries.sort(key=lambda e: e[0])
    if ros1:
        with Writer1(out) as w:
            conns = {t: w.add_connection(t, m, typestore=ts) for t, (_, m) in CSV_OF.items()}
            for log_ns, topic, msgtype, msg in entries:
                w.write(conns[topic], log_ns, ts.serialize_ros1(msg, msgtype))
    else:
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        with Writer2(out, version=9, storage_plugin=plugin) as w:
            conns = {t: w.add_connection(t, m, typestore=ts) for t, (_, m) in CSV_OF.items()}
            for log_ns, topic, msgtype, msg in entries:
                w.write(conns[topic], log_ns, ts.serialize_cdr(msg, msgtype))
    return out


def _without_keys(extra, drop=()):
    return {k: v for k, v in extra.items() if k not in drop}


# --------------------------------------------------------------------------- the real recordings

REAL = default_real_data()


@pytest.mark.real_data
@pytest.mark.skipif(
    not (REAL / "user-a" / "trial_1").is_dir(), reason=f"real recordings not found at {REAL} (set COASSIST_REAL_DATA)"
)
@pytest.mark.parametrize("recording", ["user-a/trial_1", "user-b/trial_2"])
def test_real_recording_as_bags_loads_to_the_csv_trial(tmp_path, recording):
    folder = REAL / recording
    user = folder.parent.name
    csv_trial = load_ros_trial(folder, dofs=("x", "y", "z"))
    (tmp_path / user).mkdir()
    bag1 = csv_to_bag(folder, tmp_path / user / f"{folder.name}.bag", "ros1")
    t1 = load_bag_trial(bag1, dofs=("x", "y", "z"))
    # rows_dropped_per_file is keyed by the CSV file there and by the topic here.
    per_topic = dict(t1.meta.extra["rows_dropped_per_file"])
    assert {CSV_OF[t][0]: n for t, n in per_topic.items()} == dict(csv_trial.meta.extra["rows_dropped_per_file"])
    # ROS 1: the seq join of the CSV loader, so everything is the same, bit for bit.
    for name in ("time", "pose", "velocity", "wrench", "reference"):
        a, b = getattr(t1, name), getattr(csv_trial, name)
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name
    assert _without_keys(t1.meta.to_dict()["extra"], ["rows_dropped_per_file"]) == _without_keys(
        csv_trial.meta.to_dict()["extra"], ["rows_dropped_per_file"]
    )
    meta1, meta0 = t1.meta.to_dict(), csv_trial.meta.to_dict()
    meta1.pop("extra"), meta0.pop("extra")
    assert meta1 == meta0

    # ROS 2 (no seq): joined on the stamp; the same rows, the seq diagnostics are None.
    for kind in ("sqlite3", "mcap"):
        bag2 = csv_to_bag(folder, tmp_path / user / f"{folder.name}_{kind}", kind)
        assert is_bag(bag2)
        t2 = load_bag_trial(bag2, dofs=("x", "y", "z"), user=user)
        for name in ("time", "pose", "velocity", "wrench", "reference"):
            assert getattr(t2, name).tobytes() == getattr(csv_trial, name).tobytes(), (kind, name)
        assert t2.meta.dt == csv_trial.meta.dt
        seqless = ["seq_first", "seq_last", "seq_gaps", "rows_dropped_per_file", "recording"]
        assert _without_keys(t2.meta.to_dict()["extra"], seqless) == _without_keys(
            csv_trial.meta.to_dict()["extra"], seqless
        )
        assert (t2.meta.extra["seq_first"], t2.meta.extra["seq_gaps"]) == (None, None)


# --------------------------------------------------------------------------- synthetic bags

TS2 = get_typestore(Stores.ROS2_HUMBLE)
S0 = 1_700_000_000


#: The synthetic bags' unit (a power of two: scaling by it is exact), so their values stay
#: physically plausible (below 5 m, 5 m/s and 330 N: coassist.data.rosbag_csv.check_plausible).
UNIT = 1 / 64


def synthetic_bag(path: Path, *, n=20, types=None, skip=(), values=None, stamps=None, storage="mcap") -> Path:
    """A ROS 2 bag with the four topics, 8 ms apart; value of axis j at tick k of topic i: ((i+1)·k + j/10)·UNIT.

    types: topic -> message type override; skip: topics left out; values: (topic, k) -> x value;
    stamps: topic -> list of stamp ns offsets replacing 0, 8 ms, 16 ms, ….
    """
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    Time, Header, V3 = (
        TS2.types[n] for n in ("builtin_interfaces/msg/Time", "std_msgs/msg/Header", "geometry_msgs/msg/Vector3")
    )
    Point, Quat, Pose = (TS2.types[f"geometry_msgs/msg/{n}"] for n in ("Point", "Quaternion", "Pose"))
    with Writer2(path, version=9, storage_plugin=plugin) as w:
        for i, (field, topic) in enumerate(BAG_TOPICS.items()):
            if topic in skip:
                continue
            msgtype = (types or {}).get(
                topic,
                {
                    "pose": "geometry_msgs/msg/PoseStamped",
                    "reference": "geometry_msgs/msg/PoseStamped",
                    "velocity": "geometry_msgs/msg/TwistStamped",
                    "wrench": "geometry_msgs/msg/WrenchStamped",
                }[field],
            )
            conn = w.add_connection(topic, msgtype, typestore=TS2)
            offsets = (stamps or {}).get(topic, [k * 8_000_000 for k in range(n)])
            for k, off in enumerate(offsets):
                x = (values or {}).get((topic, k), (i + 1) * k * UNIT)
                vec = [x, ((i + 1) * k + 0.1) * UNIT, ((i + 1) * k + 0.2) * UNIT]
                header = Header(stamp=Time(sec=S0 + off // 10**9, nanosec=off % 10**9), frame_id="base")
                if msgtype == "geometry_msgs/msg/PoseStamped":
                    msg = TS2.types[msgtype](
                        header=header, pose=Pose(position=Point(*vec), orientation=Quat(0.0, 0.0, 0.0, 1.0))
                    )
                elif msgtype == "geometry_msgs/msg/TwistStamped":
                    msg = TS2.types[msgtype](
                        header=header,
                        twist=TS2.types["geometry_msgs/msg/Twist"](linear=V3(*vec), angular=V3(0.0, 0.0, 0.0)),
                    )
                elif msgtype == "geometry_msgs/msg/WrenchStamped":
                    msg = TS2.types[msgtype](
                        header=header,
                        wrench=TS2.types["geometry_msgs/msg/Wrench"](force=V3(*vec), torque=V3(0.0, 0.0, 0.0)),
                    )
                else:  # a Vector3Stamped: the wrong type
                    msg = TS2.types[msgtype](header=header, vector=V3(*vec))
                # received in the order written, 8 ms apart, whatever the header stamp says
                w.write(conn, S0 * 10**9 + k * 8_000_000 + 100_000, TS2.serialize_cdr(msg, msgtype))
    return path


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_synthetic_bag_values_and_alignment(tmp_path, storage):
    # the wrench starts two ticks late: the join keeps ticks 2..19 of every topic
    stamps = {"/human_wrench": [k * 8_000_000 for k in range(2, 20)]}
    bag = synthetic_bag(tmp_path / "user-s" / "run_1", stamps=stamps, storage=storage)
    trial = load_bag_trial(bag)
    k = np.arange(2, 20)
    assert trial.n_samples == 18 and trial.n_dof == 2
    np.testing.assert_array_equal(trial.pose, np.column_stack([k, k + 0.1]) * UNIT)
    np.testing.assert_array_equal(trial.velocity, np.column_stack([2 * k, 2 * k + 0.1]) * UNIT)
    # the wrench's tick k was written as its message k-2, with x = 3·(k-2): aligned by stamp
    np.testing.assert_array_equal(trial.wrench, np.column_stack([3 * (k - 2), 3 * (k - 2) + 0.1]) * UNIT)
    np.testing.assert_array_equal(trial.time, (k - 2) * 8_000_000 * 1e-9)
    assert trial.meta.dt == pytest.approx(0.008, abs=1e-15)
    assert trial.meta.user == "user-s" and trial.meta.extra["recording"] == "run_1"
    assert dict(trial.meta.extra["rows_dropped_per_file"]) == {
        "/current_pose": 2,
        "/current_velocity": 2,
        "/human_wrench": 0,
        "/robot_ref_pos": 2,
    }


def test_topics_are_configurable(tmp_path):
    bag = synthetic_bag(tmp_path / "b")
    with pytest.raises(RecordingError, match=r"no topic /ft \(the bag has: /current_pose"):
        load_bag_trial(bag, topics={"wrench": "/ft"})
    swapped = load_bag_trial(bag, topics={"pose": "/robot_ref_pos", "reference": "/current_pose"})
    plain = load_bag_trial(bag)
    np.testing.assert_array_equal(swapped.pose, plain.reference)
    with pytest.raises(ValueError, match="unknown field 'force'"):
        load_bag_trial(bag, topics={"force": "/ft"})


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(skip=("/human_wrench",)), r"no topic /human_wrench"),
        (
            dict(types={"/human_wrench": "geometry_msgs/msg/Vector3Stamped"}),
            r"topic /human_wrench is geometry_msgs/msg/Vector3Stamped, expected geometry_msgs/msg/WrenchStamped",
        ),
        (
            dict(values={("/current_velocity", 5): float("nan")}),
            r"topic /current_velocity: message 5 has twist.linear.x = nan",
        ),
        (
            dict(values={("/robot_ref_pos", 3): float("inf")}),
            r"topic /robot_ref_pos: message 3 has pose.position.x = inf",
        ),
        (
            dict(stamps={"/current_pose": [0, 8_000_000, 8_000_000, 24_000_000]}),
            r"topic /current_pose: header stamp duplicated at message 2 \(1700000000.008000000 s then 1700000000.008000000 s\)",
        ),
        (
            dict(stamps={"/human_wrench": [0, 16_000_000, 8_000_000, 24_000_000]}),
            r"topic /human_wrench: header stamp out of order at message 2",
        ),
    ],
)
def test_bad_bags_name_the_topic_and_the_problem(tmp_path, kwargs, message):
    bag = synthetic_bag(tmp_path / "bad", **kwargs)
    with pytest.raises(RecordingError, match=message) as info:
        load_bag_trial(bag)
    assert "\n" not in str(info.value) and str(info.value).startswith(str(bag))


def test_not_a_bag(tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"not an mcap file")
    with pytest.raises(RecordingError, match=r"x.mcap: cannot read the bag"):
        load_bag_trial(tmp_path / "x.mcap")
    with pytest.raises(RecordingError, match="bag not found"):
        load_bag_trial(tmp_path / "none.bag")


def test_bag_paths_lists_files_and_bag_folders_in_natural_order(tmp_path):
    for name in ("run_10", "run_2"):
        synthetic_bag(tmp_path / name, n=3)
    (tmp_path / "notes.txt").write_text("")
    assert [p.name for p in bag_paths(tmp_path)] == ["run_2", "run_10"]
    assert bag_paths(tmp_path / "run_2") == []  # a bag folder is one bag, not a folder of bags


def test_load_trials_reads_a_bag_and_a_folder_of_bags(tmp_path):
    from coassist.intent import load_trials

    folder = tmp_path / "user-s"
    synthetic_bag(folder / "run_1", n=6)
    synthetic_bag(folder / "run_2", n=7, storage="sqlite3")
    synthetic_bag(folder / "run_3", n=5, skip=("/robot_ref_pos",))
    with pytest.raises(RecordingError, match=r"run_3: no topic /robot_ref_pos"):
        load_trials([folder])
    bad: list[tuple[str, str]] = []
    got = load_trials([folder], on_bad=lambda where, why: bad.append((where, why)))
    assert [lt.id for lt in got] == [f"{tmp_path.name}/user-s/run_1", f"{tmp_path.name}/user-s/run_2"]
    assert [lt.trial.n_samples for lt in got] == [6, 7] and len(bad) == 1 and bad[0][0].endswith("run_3")
    one = load_trials([folder / "run_2"])
    assert [(lt.id, lt.dataset) for lt in one] == [("user-s/run_2", "user-s")]


def test_show_reads_bags_with_renamed_topics(tmp_path):
    from typer.testing import CliRunner

    from coassist.cli import app

    folder = tmp_path / "user-s"
    synthetic_bag(folder / "run_1", n=30)
    res = CliRunner().invoke(
        app,
        [
            "show",
            str(folder),
            "--out",
            str(tmp_path / "s.png"),
            "--bag-topics",
            "pose=/robot_ref_pos,reference=/current_pose",
        ],
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "s.png").stat().st_size > 1000
    res = CliRunner().invoke(app, ["show", str(folder), "--bag-topics", "wrench=/ft"])
    assert res.exit_code == 2 and "PATH: " in res.output and "no topic /ft" in res.output
    res = CliRunner().invoke(app, ["show", str(folder), "--bag-topics", "wrench"])
    assert res.exit_code == 2 and "--bag-topics: expected field=/topic pairs" in res.output


def test_a_folder_named_dot_and_trial_files_beside_their_bags(tmp_path, monkeypatch):
    """Three readings a review found wrong (2026-12-06): "." named no user ("TrialMeta.user must be a non-empty
    string"); a folder of drive's runs, each a trial file and its .mcap bag, read the bags (no controller, no person,
    the folder's name as the user) where the trial files hold the whole record; two folders of one name (a/D, b/D)
    were "given twice"."""
    from dataclasses import replace as _replace

    from coassist.data import read_trial, write_dataset, write_trial
    from coassist.intent import load_trials

    folder = tmp_path / "user-s"
    synthetic_bag(folder / "run_1", n=6)
    synthetic_bag(folder / "run_2", n=7)
    monkeypatch.chdir(folder)
    for given in (".", "./"):
        got = load_trials([given])
        assert [lt.trial.meta.user for lt in got] == ["user-s", "user-s"]
        assert [lt.id for lt in got] == [f"{tmp_path.name}/user-s/run_1", f"{tmp_path.name}/user-s/run_2"]
    # drive's runs: run_1.parquet beside run_1.mcap; the trial file is read, and a bag without one too
    runs = tmp_path / "runs"
    runs.mkdir()
    made = load_trials([folder / "run_1"])[0].trial
    mine = _replace(made, meta=_replace(made.meta, user="P07", controller="manual-probe"))
    write_trial(mine, runs / "run_1.parquet")
    synthetic_bag(runs / "run_1.mcap", n=9)  # another recording under the same name: not read
    synthetic_bag(runs / "run_9.mcap", n=5)
    got = load_trials([runs])
    assert [lt.id for lt in got] == ["runs/run_1", "runs/run_9"]
    assert got[0].trial.equals(read_trial(runs / "run_1.parquet")) and got[0].trial.meta.user == "P07"
    assert got[1].trial.n_samples == 5
    # two dataset folders of one name, other trials: both read, the second named by the folder where they part
    for side, run in (("a", "run_1"), ("b", "run_2")):
        t = load_trials([folder / run])[0].trial
        write_dataset([t], tmp_path / side / "D", "D")
    got = load_trials([tmp_path / "a" / "D", tmp_path / "b" / "D"])
    assert [lt.id for lt in got] == ["D/trial_00000", "b/D/trial_00000"]
    assert [lt.trial.n_samples for lt in got] == [6, 7]
    with pytest.raises(ValueError, match=r"trial 'D/trial_00000' is given twice \(.*a/D and .*a/D\)"):
        load_trials([tmp_path / "a" / "D", tmp_path / "a" / ".." / "a" / "D"])
