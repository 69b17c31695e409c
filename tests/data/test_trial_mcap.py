"""A trial written as MCAP (coassist.data.trial_mcap) reads back: as a training trial through
the bag reader, and message by message against the arrays it came from."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.data import Trial, TrialMeta
from coassist.interfaces import Fault
from coassist.spatial import rotation_matrix, rotation_vector_from_quaternion

pytest.importorskip("rosbags", reason="the bags extra (rosbags) is not installed")
from rosbags.highlevel import AnyReader  # noqa: E402

from coassist.data.bags import load_bag_trial  # noqa: E402
from coassist.data.trial_mcap import FAULT_STATUS_NAME, MCAP_TOPICS, write_trial_mcap  # noqa: E402

N, H, DT = 40, 5, 0.008


def six_dof_trial(seed: int = 0) -> Trial:
    rng = np.random.default_rng(seed)
    pose = np.cumsum(rng.normal(0, 0.01, (N, 6)), axis=0) + [0.4, -0.1, 0.2, 3.0, 0.1, -0.2]  # |rv| near π and past it
    pred = np.repeat(pose[:, None, :], H, axis=1)
    pred[:, :, :2] += 0.01 * np.arange(1, H + 1)[None, :, None]
    pred[7] = np.nan  # no prediction in use at tick 7
    fault = np.zeros(N, dtype=np.int64)
    fault[3] = Fault.WRENCH_SPIKE | Fault.TOOL_SPEED_LIMIT
    fault[-1] = Fault.STOPPED | Fault.CONTACT_FORCE_LIMIT
    meta = TrialMeta(
        user="u",
        task="linear",
        object="handle",
        controller="cooperative",
        model_id=None,
        seed=0,
        origin="mujoco",
        dt=DT,
        extra={"start_pose": [0.4, -0.1, 0.2, 3.0, 0.1, -0.2]},
    )
    return Trial(
        meta=meta,
        time=np.arange(N) * DT,
        pose=pose,
        velocity=rng.normal(0, 0.1, (N, 6)),
        wrench=rng.normal(0, 5, (N, 6)),
        reference=pose + 0.001,
        prediction=pred,
        fault=fault,
        joints=rng.normal(0, 1, (N, 6)),
        joint_velocity=rng.normal(0, 0.1, (N, 6)),
    )


def read_all(path):
    out: dict[str, list] = {}
    with AnyReader([path]) as r:
        conns = {c.topic: c for c in r.connections}
        for c in r.connections:
            # Foxglove decodes a ROS 2 MCAP from the embedded message definition and the cdr encoding
            assert c.msgtype == MCAP_TOPICS[c.topic] and c.msgdef.data and c.ext.serialization_format == "cdr"
        for c, t, raw in r.messages():
            out.setdefault(c.topic, []).append((t, r.deserialize(raw, c.msgtype)))
    return conns, out


def test_a_trial_round_trips_through_mcap(tmp_path):
    trial = six_dof_trial()
    path = write_trial_mcap(
        trial,
        tmp_path / "out" / "run.mcap",
        alpha=0.8,
        joint_names=[f"j{i}" for i in range(6)],
        start_ns=1_700_000_000_000_000_000,
    )
    assert path.is_file() and list(path.parent.iterdir()) == [path]  # no temporaries left

    # 1. read back as a training trial: the thesis topics, bit-exact positions/velocities/forces
    back = load_bag_trial(path, dofs=("x", "y", "z"))
    for name in ("pose", "velocity", "wrench", "reference"):
        np.testing.assert_array_equal(getattr(back, name), getattr(trial, name)[:, :3], err_msg=name)
    # stamps are whole ns: k·8e6 ns read back as k·8e6·1e-9, within an ulp of k·0.008
    np.testing.assert_allclose(back.time, trial.time, rtol=0, atol=1e-16 * N)
    assert back.meta.dt == pytest.approx(DT, abs=1e-17)

    # 2. message by message
    conns, msgs = read_all(path)
    assert set(conns) == set(MCAP_TOPICS)
    poses = msgs["/current_pose"]
    assert [t for t, _ in poses] == [1_700_000_000_000_000_000 + k * 8_000_000 for k in range(N)]
    for k, (_, m) in enumerate(poses):
        q = [m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w]
        assert abs(np.linalg.norm(q) - 1.0) < 1e-15 * 4
        # compare rotations, not vectors: the trial's vectors run past π (unwrapped), the quaternion's do not
        np.testing.assert_allclose(
            rotation_matrix(rotation_vector_from_quaternion(q)), rotation_matrix(trial.pose[k, 3:]), rtol=0, atol=1e-13
        )
        assert m.header.frame_id == "base"
    w = msgs["/human_wrench"][5][1].wrench
    np.testing.assert_array_equal([w.torque.x, w.torque.y, w.torque.z], trial.wrench[5, 3:])
    paths = msgs["/prediction"]
    assert len(paths) == N - 1  # tick 7 had none
    stamp_k = [t for t, _ in paths]
    assert 1_700_000_000_000_000_000 + 7 * 8_000_000 not in stamp_k
    _, p8 = paths[7]  # tick 8
    assert len(p8.poses) == H
    np.testing.assert_array_equal(
        [[ps.pose.position.x, ps.pose.position.y] for ps in p8.poses], trial.prediction[8, :, :2]
    )
    assert [ps.header.stamp.nanosec for ps in p8.poses] == [(8 + i) * 8_000_000 for i in range(1, H + 1)]
    assert [m.data for _, m in msgs["/alpha"]] == [0.8] * N
    statuses = [m.status[0] for _, m in msgs["/faults"]]
    assert [s.level for s in statuses[:5]] == [0, 0, 0, 1, 0] and statuses[-1].level == 2
    assert (
        statuses[3].name == FAULT_STATUS_NAME and statuses[3].message == "WRENCH_SPIKE, TOOL_SPEED_LIMIT"
    )  # lowest bit first
    assert {kv.key: kv.value for kv in statuses[3].values}["flags"] == str(int(trial.fault[3]))
    js = msgs["/joint_states"]
    assert list(js[0][1].name) == [f"j{i}" for i in range(6)]
    np.testing.assert_array_equal(np.array([m.position for _, m in js]), trial.joints)
    cmd = msgs["/forward_velocity_controller/commands"]
    np.testing.assert_array_equal(np.array([m.data for _, m in cmd]), trial.joint_velocity)


def test_a_planar_trial_fills_the_pose_from_the_start_pose(tmp_path):
    full = six_dof_trial()
    meta = full.meta
    planar = Trial(
        meta=meta,
        time=full.time,
        pose=full.pose[:, :2],
        velocity=full.velocity[:, :2],
        wrench=full.wrench[:, :2],
        reference=full.reference[:, :2],
    )
    path = write_trial_mcap(planar, tmp_path / "p.mcap")
    _, msgs = read_all(path)
    assert "/alpha" not in msgs and "/prediction" not in msgs and "/joint_states" not in msgs
    m = msgs["/current_pose"][4][1].pose
    assert (m.position.x, m.position.y, m.position.z) == (planar.pose[4, 0], planar.pose[4, 1], 0.2)
    back = load_bag_trial(path)
    assert back.pose.tobytes() == planar.pose.tobytes()


def test_bad_arguments_and_a_failed_write_leave_nothing(tmp_path, monkeypatch):
    trial = six_dof_trial()
    with pytest.raises(ValueError, match=r"alpha must be one number or 40"):
        write_trial_mcap(trial, tmp_path / "a.mcap", alpha=[0.5, 0.6])
    with pytest.raises(ValueError, match=r"must end in .mcap"):
        write_trial_mcap(trial, tmp_path / "a.bag")
    with pytest.raises(ValueError, match=r"joint_names must be 6 strings"):
        write_trial_mcap(trial, tmp_path / "a.mcap", joint_names=["a"])
    path = write_trial_mcap(trial, tmp_path / "a.mcap")
    before = path.read_bytes()

    from rosbags.rosbag2 import Writer

    calls = {"n": 0}
    original = Writer.write

    def failing(self, *args):
        calls["n"] += 1
        if calls["n"] > 50:
            raise OSError("disk full")
        return original(self, *args)

    monkeypatch.setattr(Writer, "write", failing)
    with pytest.raises(OSError, match="disk full"):
        write_trial_mcap(six_dof_trial(seed=1), path)
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.mcap"]


def test_the_trials_own_alpha_goes_out_tick_by_tick_and_a_given_one_wins(tmp_path):
    # the arbitration's online α: recorded by the arm worlds' loop, it was on no /alpha (drive and ros2 gave the
    # preset's α for the plain game only)
    from dataclasses import replace

    alpha = 0.6 + 0.3 * np.sin(np.arange(N) / 7.0) ** 2
    trial = replace(six_dof_trial(), alpha=alpha)
    _, msgs = read_all(write_trial_mcap(trial, tmp_path / "a.mcap"))
    assert [m.data for _, m in msgs["/alpha"]] == alpha.tolist()
    _, msgs = read_all(write_trial_mcap(trial, tmp_path / "b.mcap", alpha=0.5))
    assert [m.data for _, m in msgs["/alpha"]] == [0.5] * N
