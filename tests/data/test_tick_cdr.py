"""The live view's CDR bytes (coassist.data.tick_cdr) are rosbags' for the same messages, byte for
byte: every topic of MCAP_TOPICS, on ticks drawn to hit each branch (a prediction or none or a
NaN one, α or none or NaN, fault flags, joints or none, a rotation near π, stamps across a second)."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.interfaces import Fault

pytest.importorskip("rosbags", reason="the bags extra (rosbags) is not installed")
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from coassist.data.tick_cdr import TickEncoder  # noqa: E402
from coassist.data.trial_mcap import MCAP_TOPICS, TickMessages  # noqa: E402

TS = get_typestore(Stores.ROS2_HUMBLE)


def _reference(m: TickMessages, *args, **kwargs) -> list[tuple[str, bytes]]:
    return [(topic, bytes(TS.serialize_cdr(msg, MCAP_TOPICS[topic]))) for topic, msg in m.tick(*args, **kwargs)]


@pytest.mark.parametrize("frame_id", ["base", "base_link", ""])  # string lengths 5, 10, 1: every padding
@pytest.mark.parametrize("n_joints", [0, 6, 7])
def test_every_topic_is_rosbags_bytes(frame_id: str, n_joints: int) -> None:
    rng = np.random.default_rng(n_joints + len(frame_id))
    # names of every length mod 4 (the UR's among them): each string's length field is 4-aligned
    pool = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "j", "ab", "abc", "abcd"]
    names = [pool[(i + n_joints) % len(pool)] for i in range(n_joints)]
    dt_ns = 8_000_000
    ref = TickMessages(TS, frame_id, names, dt_ns)
    enc = TickEncoder(frame_id, names, dt_ns)
    flags = [0, int(Fault.WRENCH_SPIKE | Fault.TOOL_SPEED_LIMIT), int(Fault.STOPPED | Fault.CONTACT_FORCE_LIMIT)]
    seen: set[str] = set()
    for k in range(60):
        ns = 1_700_000_000_999_000_000 + k * dt_ns  # crosses a whole second
        pose6 = rng.normal(0, 0.3, 6)
        if k % 5 == 0:
            pose6[3:] = [0.0, 0.0, np.pi - 1e-9]  # |rv| at π
        H, c = [1, 0, 250][k % 3] if k % 10 == 9 else int(rng.integers(2, 60)), int(rng.choice([2, 3, 6]))
        pred = rng.normal(0, 0.5, (H, c))
        if k % 7 == 3 and H:
            pred[H // 2, 0] = np.nan  # a prediction not in use: no path
        prediction = None if k % 4 == 1 else pred
        alpha = [None, 0.7, float("nan"), 0.25][k % 4]
        joints = rng.normal(0, 1, n_joints) if n_joints else None
        qd = rng.normal(0, 0.1, n_joints) if n_joints and k % 3 else None
        args = (ns, pose6, rng.normal(size=6), rng.normal(size=6), rng.normal(size=6))
        kwargs = dict(prediction=prediction, alpha=alpha, flags=flags[k % 3], joints=joints, joint_velocity=qd)
        want = _reference(ref, *args, **kwargs)
        got = enc.tick(*args, **kwargs)
        assert [t for t, _ in got] == [t for t, _ in want], k
        for (topic, a), (_, b) in zip(got, want):
            assert a == b, f"tick {k}, {topic}: {a.hex()} != {b.hex()}"
            seen.add(topic)
    expected = (
        set(MCAP_TOPICS)
        if n_joints
        else set(MCAP_TOPICS)
        - {
            "/joint_states",
            "/forward_velocity_controller/commands",
        }
    )
    assert seen == expected


def test_the_bytes_decode_to_the_values_given() -> None:
    # independent of the encoder's own reference: rosbags reads the bytes back to the inputs
    enc = TickEncoder("base", ["a", "b"], 8_000_000)
    pose6 = np.array([0.4, -0.1, 0.2, 0.0, 0.0, 0.3])
    out = dict(enc.tick(5_000_000_123, pose6, np.arange(6.0), -np.arange(6.0), pose6 + 1, np.ones((3, 2)), 0.5, 3))
    msg = TS.deserialize_cdr(out["/current_pose"], "geometry_msgs/msg/PoseStamped")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (5, 123, "base")
    assert [msg.pose.position.x, msg.pose.position.y, msg.pose.position.z] == [0.4, -0.1, 0.2]
    np.testing.assert_allclose([msg.pose.orientation.z, msg.pose.orientation.w], [np.sin(0.15), np.cos(0.15)])
    path = TS.deserialize_cdr(out["/prediction"], "nav_msgs/msg/Path")
    assert [p.header.stamp.nanosec for p in path.poses] == [8_000_123, 16_000_123, 24_000_123]
    assert [(p.pose.position.x, p.pose.position.y, p.pose.position.z) for p in path.poses] == [(1.0, 1.0, 0.2)] * 3
    w = TS.deserialize_cdr(out["/human_wrench"], "geometry_msgs/msg/WrenchStamped").wrench
    assert [w.force.x, w.torque.z] == [-0.0, -5.0]
    assert TS.deserialize_cdr(out["/alpha"], "std_msgs/msg/Float64").data == 0.5
    status = TS.deserialize_cdr(out["/faults"], "diagnostic_msgs/msg/DiagnosticArray").status[0]
    assert status.level == 1 and {v.key: v.value for v in status.values}["flags"] == "3"
