"""The live Foxglove view (coassist.runtime.foxglove) through a WebSocket client that speaks the SDK's
subprotocol by hand (tests/runtime/foxglove_client.py): what it receives is the run's own log, in
the MCAP file's topics, schemas and bytes; the scene is the task's; a stalled viewer slows nothing."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import threading
import time
from typing import NamedTuple

import numpy as np
import pytest

pytest.importorskip("foxglove", reason="the live view needs the viz extra: pip install 'coassist[viz]'")
pytest.importorskip("rosbags", reason="the live view needs the viz extra (rosbags)")
pytest.importorskip("websockets", reason="the test's Foxglove client needs websockets (the web extra)")

from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from coassist.control.presets import get_preset, make_controller  # noqa: E402
from coassist.data.trial_mcap import MCAP_TOPICS, write_trial_mcap  # noqa: E402
from coassist.runtime.foxglove import SCENE_TOPIC, open_foxglove  # noqa: E402
from coassist.runtime.live import LiveFeed  # noqa: E402
from coassist.scenario.intent_registry import load_intent_source  # noqa: E402
from coassist.scenario.objects import get_object  # noqa: E402
from coassist.scenario.operator import operator_profile  # noqa: E402
from coassist.scenario.tasks import task_for_seed  # noqa: E402
from coassist.sim.trial_runner import TrialSpec, build_trial  # noqa: E402

from .foxglove_client import FoxgloveClient  # noqa: E402
from .test_live import Recorder  # noqa: E402

TS = get_typestore(Stores.ROS2_HUMBLE)
TOPICS = [*MCAP_TOPICS, SCENE_TOPIC]
#: Messages the test's server keeps per viewer: more than any run here can send (_watch checks it),
#: so it drops none and every tick the feed published must reach the viewer whole. (With the
#: default 1024 a viewer that the loaded machine let fall 110 frames behind lost the oldest.)
BACKLOG = 1 << 16


def _wait(predicate, timeout: float = 30.0, what: str = "") -> None:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


class Watched(NamedTuple):
    """A watched run: its trial and α, the live view's trial (its clock), the viewer, how many ticks
    the feed published, and the run's MCAP file ((topic, stamp) → bytes; topic → schema)."""

    trial: object
    alpha: float
    live: object
    client: FoxgloveClient
    published: int
    mcap: dict
    schemas: dict


def _watch(run, tmp_path, joint_names=None) -> Watched:
    """Serve, connect a viewer subscribed to every topic, ``run(feed)`` → (trial, alpha), write the
    run's MCAP file, and collect what the viewer received until every message of the last tick arrived."""
    feed, sink = open_foxglove(0, rate_hz=50.0, backlog=BACKLOG)
    client = FoxgloveClient(sink.url)
    try:
        assert client.server_info["name"] == "coassist"
        client.subscribe(TOPICS)
        _wait(lambda: all(sink.watched(t) for t in TOPICS), what="the subscriptions")
        trial, alpha = run(feed)
        assert feed.flush(30)
        assert trial.n_samples * len(TOPICS) <= BACKLOG  # the server can drop nothing of this run
        live = feed.current
        mcap, schemas = _mcap_messages(trial, alpha, live, tmp_path, joint_names)
        last = live.stamp(trial.n_samples - 1)
        # all of the last tick's topics, not only /faults: /joint_states and the joint commands are sent
        # after it, and a viewer closed on seeing /faults could miss them (the machine loaded)
        last_topics = [topic for topic, stamp in mcap if stamp == last]
        assert "/faults" in last_topics
        _wait(
            lambda: all(any(t == last for t, _ in client.of(topic)) for topic in last_topics),
            what="the last tick's messages",
        )
        assert feed.failures == 0 and not client.bad_frames
        return Watched(trial, alpha, live, client, feed.published, mcap, schemas)
    finally:
        client.close()
        feed.close()


def _mcap_messages(trial, alpha, live, tmp_path, joint_names=None) -> tuple[dict, dict]:
    """The run's MCAP file (written from its trial with the live view's clock): (topic, stamp) → bytes,
    and topic → (schema name, encoding, text) as embedded in the file."""
    path = write_trial_mcap(trial, tmp_path / "run.mcap", alpha=alpha, start_ns=live.start_ns, joint_names=joint_names)
    out, schemas = {}, {}
    with AnyReader([path]) as reader:
        for c in reader.connections:
            schemas[c.topic] = (c.msgtype, c.msgdef.format.name.lower(), c.msgdef.data)
        for conn, stamp, raw in reader.messages():
            out[(conn.topic, stamp)] = bytes(raw)
    return out, schemas


def _check_against_log(w: Watched) -> set[int]:
    """Every message received is the MCAP file's message of its tick, byte for byte, and decodes to
    the trial's row; every tick the feed published arrived, whole; returns the ticks seen."""
    client, trial, alpha, live, mcap, schemas = w.client, w.trial, w.alpha, w.live, w.mcap, w.schemas
    # the channels: the MCAP file's topics with its types and schema text, CDR messages
    for topic, (msgtype, fmt, text) in schemas.items():
        ch = client.channels[topic]
        assert (ch["schemaName"], ch["schemaEncoding"], ch["encoding"]) == (msgtype, "ros2msg", "cdr") and fmt == "msg"
        assert ch["schema"] == text
    ticks = set()
    tick_of = {live.stamp(k): k for k in range(trial.n_samples)}
    for topic in MCAP_TOPICS:
        for stamp, payload in client.of(topic):
            k = tick_of[stamp]  # a stamp of the run's ticks (KeyError otherwise)
            ticks.add(k)
            assert mcap[(topic, stamp)] == payload, f"{topic} at tick {k} differs from the MCAP file's"
            msg = TS.deserialize_cdr(payload, MCAP_TOPICS[topic])
            if topic == "/current_pose":
                p = msg.pose.position
                np.testing.assert_array_equal([p.x, p.y], trial.pose[k, :2])
            elif topic == "/human_wrench":
                np.testing.assert_array_equal([msg.wrench.force.x, msg.wrench.force.y], trial.wrench[k, :2])
            elif topic == "/prediction":
                xy = [(q.pose.position.x, q.pose.position.y) for q in msg.poses]
                np.testing.assert_array_equal(xy, trial.prediction[k, :, :2])
            elif topic == "/alpha":
                assert msg.data == alpha
            elif topic == "/faults":
                assert {v.key: v.value for v in msg.status[0].values}["flags"] == str(int(trial.fault[k]))
            elif topic == "/joint_states":
                np.testing.assert_array_equal(msg.position, trial.joints[k])
            elif topic == "/forward_velocity_controller/commands":
                np.testing.assert_array_equal(msg.data, trial.joint_velocity[k])
    assert trial.n_samples - 1 in ticks and len(ticks) >= 2
    # each of the feed's frames is one tick (a new snapshot each), and the server dropped none (BACKLOG):
    # what the viewer received is exactly what was sent, however few frames the machine's load let through
    assert len(ticks) == w.published, f"{len(ticks)} ticks received of the {w.published} the feed published"
    # every topic of a received tick came (the /faults of every tick; the others where the file has them)
    for k in ticks:
        stamp = live.stamp(k)
        for topic in MCAP_TOPICS:
            if (topic, stamp) in mcap:
                assert any(t == stamp for t, _ in client.of(topic)), (topic, k)
    return ticks


def _point_mass_episode(seconds: float = 5.0):
    """A curved-path trial of the point-mass world, cut to ``seconds``: the oracle intent (a
    prediction in use) and the cooperative game (its α)."""
    spec = TrialSpec(task="curved", seed=3, intent="oracle")
    task = task_for_seed(spec.task, spec.seed)
    preset = get_preset(spec.preset)
    controller = make_controller(spec.controller, preset)
    source = load_intent_source(spec.intent, max(controller.horizon, preset.game.horizon))
    return build_trial(
        task, operator_profile(0), get_object("handle"), controller, source, spec.seed, time_limit=seconds
    )


def test_the_point_mass_stream_is_the_runs_log_and_its_mcap_file(tmp_path):
    episode = _point_mass_episode()

    def run(feed):
        watch = feed.watch(episode)

        def paced(*args):
            # a lockstep run of 625 ticks can end before the publisher's first frame on a loaded machine (CI-like
            # run, 2026-12-02: only the final flush, one tick); 1 ms a tick spans some 30 frame periods at 50 Hz
            watch(*args)
            time.sleep(0.001)

        trial = episode.finish(episode.run(on_tick=paced))
        return trial, episode.tick.controller.game.alpha

    w = _watch(run, tmp_path)
    _check_against_log(w)
    assert not w.client.of("/joint_states")  # the point mass has no joints
    # the scene: decoded with the protobuf schema the server advertised
    _check_scene(w.client, episode, w.live)


def test_the_mujoco_ur5_stream_carries_its_joints(tmp_path):
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra")
    from coassist.robot.drive import DriveConfig, drive
    from coassist.robot.ros2_world import UR_JOINT_NAMES

    def run(feed):
        config = DriveConfig(world="mujoco", controller="cooperative", intent="oracle", time_limit=1.5)
        return _with_alpha(drive(config, live=feed))

    w = _watch(run, tmp_path, joint_names=UR_JOINT_NAMES)
    _check_against_log(w)
    names = TS.deserialize_cdr(w.client.of("/joint_states")[0][1], MCAP_TOPICS["/joint_states"]).name
    assert list(names) == list(UR_JOINT_NAMES)


def _with_alpha(trial):
    """(trial, α of the trial's preset): what a world run by drive() logs on /alpha."""
    return trial, get_preset(trial.meta.extra["preset"]).game.alpha


def _check_scene(client: FoxgloveClient, episode, live) -> None:
    pytest.importorskip("google.protobuf", reason="decoding the scene needs protobuf")
    from google.protobuf import descriptor_pb2, message_factory

    ch = client.channels[SCENE_TOPIC]
    assert (ch["schemaName"], ch["schemaEncoding"], ch["encoding"]) == ("foxglove.SceneUpdate", "protobuf", "protobuf")
    fds = descriptor_pb2.FileDescriptorSet.FromString(client.schema(SCENE_TOPIC))
    SceneUpdate = message_factory.GetMessages(fds.file)["foxglove.SceneUpdate"]
    received = client.of(SCENE_TOPIC)
    assert received and received[0][0] == live.start_ns
    scene = SceneUpdate.FromString(received[0][1])
    by_id = {e.id: e for e in scene.entities}
    assert set(by_id) == {"obstacle", "path", "target"}
    assert all(e.frame_id == "base" for e in scene.entities)
    task, z = episode.task, float(episode.start_pose[2])
    box = by_id["obstacle"].cubes[0]
    np.testing.assert_allclose(
        [box.pose.position.x, box.pose.position.y, box.pose.position.z], [*task.obstacle.center, z], rtol=0, atol=0
    )
    np.testing.assert_array_equal([box.size.x, box.size.y], task.obstacle.size)
    line = by_id["path"].lines[0]
    np.testing.assert_array_equal([(p.x, p.y) for p in line.points], task.path.points)
    ball = by_id["target"].spheres[0]
    np.testing.assert_array_equal([ball.pose.position.x, ball.pose.position.y], task.target)
    assert ball.size.x == 2 * episode.arrive_radius


def _stalled_viewer(port: int, channel_ids: list[int]) -> socket.socket:
    """A viewer that subscribes and then never reads: a tiny receive buffer, the handshake and one
    masked subscribe frame written by hand."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)
    s.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall(
        (
            f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
        ).encode()
    )
    assert s.recv(12).startswith(b"HTTP/1.1 101")
    body = json.dumps(
        {"op": "subscribe", "subscriptions": [{"id": i + 1, "channelId": c} for i, c in enumerate(channel_ids)]}
    ).encode()
    mask = os.urandom(4)
    header = (
        bytes([0x81, 0x80 | 126]) + struct.pack(">H", len(body))
        if len(body) >= 126
        else bytes([0x81, 0x80 | len(body)])
    )
    s.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(body)))
    return s


def test_a_stalled_viewer_blocks_neither_the_publisher_nor_another_viewer():
    feed, sink = open_foxglove(0, rate_hz=30.0)
    healthy = FoxgloveClient(sink.url)
    stalled = _stalled_viewer(sink.port, [ch["id"] for ch in healthy.channels.values()])
    healthy.subscribe(TOPICS)
    try:
        _wait(lambda: all(sink.watched(t) for t in TOPICS), what="the subscriptions")
        time.sleep(0.2)  # the stalled viewer's subscriptions too
        recorder = Recorder()
        with LiveFeed(recorder, rate_hz=100.0) as snapshots:  # some ticks of a run, to send again and again
            episode = _point_mass_episode(3.0)
            episode.run(on_tick=snapshots.watch(episode))
            snapshots.flush(10)
        snaps = recorder.snapshots
        # ~15 MB of messages, far beyond what a stalled socket's buffers hold: if the sink waited for
        # the stalled viewer, this would never finish
        done = threading.Event()

        def publish_all() -> None:
            for i in range(3000):
                sink.publish(snaps[i % len(snaps)])
            done.set()

        threading.Thread(target=publish_all, daemon=True).start()
        assert done.wait(120), "the publisher waited for the stalled viewer"
        last = snaps[(3000 - 1) % len(snaps)]
        _wait(lambda: any(t == last.trial.stamp(last.k) for t, _ in healthy.of("/faults")), what="the healthy viewer")
        # what went out to each viewer is over twice the most a socket's kernel buffers hold here (4 MB)
        assert sum(len(p) for _, _, p in healthy.messages) > 8e6
    finally:
        stalled.close()
        healthy.close()
        feed.close()


def _ticks_of_a_run(seconds: float = 1.0) -> list:
    """The snapshots of a short point-mass run (what a feed hands its sink)."""
    recorder = Recorder()
    with LiveFeed(recorder, rate_hz=100.0) as snapshots:
        episode = _point_mass_episode(seconds)
        watch = snapshots.watch(episode)

        def paced(*args):
            watch(*args)
            time.sleep(0.001)  # a few frames of the 100 Hz publisher, however fast the run

        episode.run(on_tick=paced)
        snapshots.flush(10)
    return recorder.snapshots


def test_closing_the_live_view_when_its_worker_hangs_returns_and_kills_the_worker():
    # The worker stops (SIGSTOP: a hung or starved process) while a viewer subscribes, and the publisher
    # fills the pipe until its send blocks. Closing used to write its stop request into that full pipe
    # and wait for ever, and `coassist ros2 --foxglove` never wrote its trial.
    import signal

    snaps = _ticks_of_a_run()
    feed, sink = open_foxglove(0, rate_hz=30.0)
    client = FoxgloveClient(sink.url)
    client.subscribe(TOPICS)
    sent = [0]
    try:
        _wait(lambda: all(sink.watched(t) for t in TOPICS), what="the subscriptions")
        os.kill(sink.pid, signal.SIGSTOP)

        def publish_for_ever() -> None:
            try:
                while True:
                    sink.publish(snaps[sent[0] % len(snaps)])
                    sent[0] += 1
            except OSError:  # the worker is gone: its end of the pipe closed
                pass

        publisher = threading.Thread(target=publish_for_ever, daemon=True)
        publisher.start()
        stuck_since, last = time.monotonic(), -1
        while time.monotonic() - stuck_since < 0.5:  # until no send returned for 0.5 s: the pipe is full
            if sent[0] != last:
                stuck_since, last = time.monotonic(), sent[0]
            assert publisher.is_alive()
            time.sleep(0.02)
        assert sent[0] > 10  # a few hundred kB went in before the pipe filled
        closer = threading.Thread(target=feed.close, daemon=True)
        t0 = time.monotonic()
        closer.start()
        # the feed's own thread is idle (1 frame), then the sink: the stuck send holds the pipe for the
        # lock's 1 s, the kill, then 2 s at most for the worker to go: ~8 s even on a loaded machine
        closer.join(60)
        took = time.monotonic() - t0
        assert not closer.is_alive(), "closing the live view blocked on the hung worker"
        assert took < 30, f"closing took {took:.1f} s"
        _wait(lambda: not publisher.is_alive(), 10, "the stuck send to fail")  # its worker's end is gone
        with pytest.raises(ProcessLookupError):
            os.kill(sink.pid, 0)  # killed and reaped
    finally:
        try:
            os.kill(sink.pid, signal.SIGKILL)  # never leave a stopped worker behind a failed test
        except ProcessLookupError:
            pass
        client.close()


def test_closing_the_live_view_asks_a_healthy_worker_to_stop():
    feed, sink = open_foxglove(0)
    t0 = time.monotonic()
    feed.close()
    assert time.monotonic() - t0 < 5.0  # asked, it stops at once: not killed after CLOSE_TIMEOUT
    assert sink._proc.exitcode == 0  # it returned (a kill is -9)


def test_a_port_in_use_a_bad_port_and_a_bad_backlog_are_one_line():
    from coassist.runtime.foxglove import LiveServerError

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(
            LiveServerError,
            match=rf"^127\.0\.0\.1:{port} is in use \(another program listens on it\): pick another port$",
        ):
            open_foxglove(port)
    for bad in (-1, 65536, 3.5, True, "8765"):
        with pytest.raises(ValueError, match="port must be a port number in 0 … 65535"):
            open_foxglove(bad)
    for bad in (0, -5, 2.0, True, "1024"):  # before a process starts
        with pytest.raises(ValueError, match="^backlog must be"):
            open_foxglove(0, backlog=bad)


@pytest.mark.realtime
@pytest.mark.alone  # the stream against the run's log while the loop runs: no other test beside it
def test_the_ur_simulator_stream_through_the_real_client_is_the_runs_log(tmp_path):
    """The UR world on ``coassist ur-sim`` (the real ur-rtde client, the simulated operator at the
    simulator's handle), watched live: the messages are the run's MCAP file's, with the UR's joints."""
    from ..ursim import needs_ur_rtde, realtime_priority, simulator

    needs_ur_rtde()
    pytest.importorskip("mujoco", reason="the simulator's arm is the MuJoCo UR5: pip install 'coassist[robot]'")
    from coassist.robot.drive import DriveConfig, drive
    from coassist.robot.ros2_world import UR_JOINT_NAMES

    with simulator() as sim:

        def run(feed):
            config = DriveConfig(world="ur", controller="cooperative", time_limit=1.5)
            with realtime_priority():  # the loop at the simulator's priority, as a lab runs it (chrt -f)
                return _with_alpha(drive(config, host=sim.host, live=feed))

        w = _watch(run, tmp_path, joint_names=UR_JOINT_NAMES)
    trial, client = w.trial, w.client
    assert trial.meta.extra["ended"] == "time_limit", trial.meta.extra.get("stop_message")
    ticks = _check_against_log(w)
    assert len(ticks) >= 20  # 1.5 s at 50 frames a second, most of them received
    names = TS.deserialize_cdr(client.of("/joint_states")[0][1], MCAP_TOPICS["/joint_states"]).name
    assert list(names) == list(UR_JOINT_NAMES)
    # the arm moved: the joints the viewer received are the simulator's, not a constant
    q = np.array([TS.deserialize_cdr(p, MCAP_TOPICS["/joint_states"]).position for _, p in client.of("/joint_states")])
    assert np.ptp(q, axis=0).max() > 1e-4


@pytest.mark.realtime
@pytest.mark.alone  # the stream against the run's log while the loop runs: no other test beside it
def test_the_franky_sim_stream_through_the_real_client_is_the_runs_log(tmp_path):
    """The Franka world on franky-sim (the real franky client, libfranka's protocol, a 10 N push read by
    an F/T sensor at the hand), watched live: the messages are the run's MCAP file's, with the FR3's
    seven joints."""
    pytest.importorskip("franky", reason="the Franka world needs franky: pip install 'coassist[franka]'")
    pytest.importorskip("franky_sim", reason="franky-sim: pip install 'coassist[franka]'")
    pytest.importorskip("pinocchio", reason="the FR3 kinematics need the robot extra: pip install 'coassist[robot]'")
    from coassist.robot.drive import DriveConfig, drive
    from coassist.robot.franka_world import FrankaWorld

    from ..robot.test_franka_world import LINK_TIMEOUT, PushSensor, SimServer

    server = SimServer()
    try:

        def run(feed):
            world = FrankaWorld(
                server.host, arm="fr3", ft_sensor=PushSensor(server, (10.0, 0.0, 0.0)), link_timeout=LINK_TIMEOUT
            )
            try:
                config = DriveConfig(world="franka", robot="fr3", controller="cooperative", time_limit=0.6)
                return _with_alpha(drive(config, world=world, live=feed))
            finally:
                world.close()

        w = _watch(run, tmp_path)
    finally:
        server.close()
    trial, client = w.trial, w.client
    assert trial.meta.extra["ended"] == "time_limit", trial.meta.extra.get("stop_message")
    ticks = _check_against_log(w)
    assert len(ticks) >= 10  # 0.6 s at 50 frames a second, most of them received
    names = TS.deserialize_cdr(client.of("/joint_states")[0][1], MCAP_TOPICS["/joint_states"]).name
    assert list(names) == [f"joint_{i}" for i in range(1, 8)]
    # the push moved the tool: the poses the viewer received are franky-sim's, not a constant
    x = [TS.deserialize_cdr(p, MCAP_TOPICS["/current_pose"]).pose.position.x for _, p in client.of("/current_pose")]
    assert np.ptp(x) > 1e-3


def test_the_ros2_stream_is_the_runs_log(tmp_path, monkeypatch):
    """The ROS 2 world over real DDS on loopback (a node plays the MuJoCo UR5 behind ros2_control's
    topics, lockstep: no clock), watched live: the messages are the run's MCAP file's, with the UR's
    joints as the driver names them."""
    pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
    pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")
    pytest.importorskip("rclpy", reason="the ros2 extra (ros-rclpy and the message packages) is not installed")
    from coassist.robot.drive import DriveConfig, drive
    from coassist.robot.ros2_world import MAX_STALE_AFTER, UR_JOINT_NAMES, Ros2Config, Ros2World

    from ..robot.test_ros2_world import DOMAIN, SimRobot, mujoco_world

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # as tests/robot/test_ros2_world.py
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)
    config = DriveConfig(world="ros2", controller="cooperative", time_limit=0.6)
    sim = mujoco_world(config)  # pushed: 8 N along +x, then 6 N along -y
    robot = SimRobot(sim)
    mass, com = sim.tool_mass_and_com()
    cfg = Ros2Config(
        domain_id=DOMAIN,
        lockstep=True,
        pace=False,
        stale_after=MAX_STALE_AFTER,  # as tests/robot/test_ros2_world.py's lockstep runs: 0.1 s lost the link under load
        rate_hz=config.rate_hz,
        tcp_offset=tuple(sim.kinematics().tcp_offset),
        payload=(mass, tuple(com)),
        connect_timeout=10.0,
    )
    try:

        def run(feed):
            world = Ros2World(cfg, alpha=0.8)
            try:
                return _with_alpha(drive(config, world=world, on_tick=world.publish_monitor, live=feed))
            finally:
                world.close()

        w = _watch(run, tmp_path, joint_names=UR_JOINT_NAMES)
    finally:
        time.sleep(0.05)  # the final zero command reaches the robot
        robot.close()
    trial, client = w.trial, w.client
    assert trial.meta.extra["ended"] == "time_limit", trial.meta.extra.get("stop_message")
    # lockstep, unpaced: the run's 75 ticks took 0.4–1.4 s of wall time, its world's start included (the
    # machine's load), and the 50 Hz feed published 7–36 of them (a floor of 10 failed at load 2–6);
    # _check_against_log holds the viewer to exactly the ticks published, the last among them
    _check_against_log(w)
    names = TS.deserialize_cdr(client.of("/joint_states")[0][1], MCAP_TOPICS["/joint_states"]).name
    assert list(names) == list(UR_JOINT_NAMES)
    # the push moved the tool: the poses received are the ROS 2 robot's, not a constant
    x = [TS.deserialize_cdr(p, MCAP_TOPICS["/current_pose"]).pose.position.x for _, p in client.of("/current_pose")]
    assert np.ptp(x) > 1e-3
    # a person at the arm, no scene file: the robot is told of no obstacle, and the view draws none (it drew
    # the task generator's box); its poses are in the world's base frame
    assert w.live.obstacles == () and w.live.frame_id == cfg.base_frame == "base"
