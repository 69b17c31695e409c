"""`coassist ros2`'s world (coassist.robot.ros2_world) against a robot played over real ROS 2.

In this test process an rclpy node plays the robot: the MuJoCo UR5 of
coassist.robot.mujoco_world, publishing its joint states and F/T wrench and stepping one
control period for every velocity command it receives (lockstep). Everything goes over
DDS on loopback, in a domain id of its own. The run must match the in-process MuJoCo
drive, and topics that go silent must stop the arm.
"""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")
rclpy = pytest.importorskip("rclpy", reason="the ros2 extra (ros-rclpy and the message packages) is not installed")

from geometry_msgs.msg import WrenchStamped  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from coassist.robot.drive import TASK_HEIGHT, DriveConfig, drive  # noqa: E402
from coassist.robot.mujoco_world import MujocoUR5World  # noqa: E402
from coassist.robot.ros2_world import UR_JOINT_NAMES, Ros2Config, Ros2World  # noqa: E402
from coassist.runtime.operators import ScriptedForce  # noqa: E402
from coassist.runtime.world import Command, RobotLinkError  # noqa: E402
from coassist.scenario.tasks import make_task  # noqa: E402

# A domain of its own (140 … 229 of 0 … 232): the xdist worker's index sets the parity, so the
# two workers of a run never share one; the pid keeps other runs on this machine apart.
_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw")
DOMAIN = 140 + ((os.getpid() % 45) * 2 + (int(_WORKER) % 2 if _WORKER.isdigit() else 0)) % 90
#: [s] input age that stops the arm in the silence tests (generous: the CI machine is shared).
STALE = 0.25
#: [ns] the simulated robot's clock at t = 0 (a driver stamps with the ROS clock; a stamp of 0 is refused).
EPOCH_NS = 1_700_000_000 * 10**9
PUSH = ScriptedForce.steps([(0.0, (8.0, 0.0, 0.0, 0.0, 0.0, 0.0)), (0.6, (0.0, -6.0, 0.0, 0.0, 0.0, 0.0))])


@pytest.fixture(autouse=True)
def loopback(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")  # the older spelling, for older rmw
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)


class _SpunNode:
    """A node in its own rclpy context, spun by a daemon thread (:meth:`_start`), torn down by :meth:`close`."""

    def _open(self, name: str) -> None:
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=DOMAIN)
        self.node = rclpy.create_node(name, context=self.ctx)

    def _start(self) -> None:
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.running = True
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while self.running:
            self.executor.spin_once(timeout_sec=0.01)

    def close(self) -> None:
        self.running = False
        self.thread.join(timeout=2)
        self.executor.shutdown(timeout_sec=1)
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


class SimRobot(_SpunNode):
    """The robot's side: a MuJoCo UR5 behind ros2_control's topics, stepped once per command."""

    def __init__(
        self,
        world: MujocoUR5World,
        *,
        silent_after: int | None = None,
        silent_topic: str = "both",
        free_running: bool = False,
    ) -> None:
        self.world = world
        self.silent_after, self.silent_topic = silent_after, silent_topic
        self.commands: list[np.ndarray] = []
        self.started = False
        # Free-running, a driver's stamps advance while it waits for the first command (a repeated stamp is a
        # hung driver to a free-running world); in lockstep the simulator's clock stands still until then.
        self.free_running = free_running
        self.idle_ns = 0
        self._open("ur5_sim")
        self.js_pub = self.node.create_publisher(JointState, "/joint_states", 10)
        self.w_pub = self.node.create_publisher(WrenchStamped, "/force_torque_sensor_broadcaster/wrench", 10)
        self.node.create_subscription(Float64MultiArray, "/forward_velocity_controller/commands", self._on_command, 10)
        self.node.create_timer(0.02, self._announce)  # the state at rest, until the first command
        self._start()

    def _announce(self) -> None:
        if not self.started:
            if self.free_running:
                self.idle_ns += 20_000_000  # the timer's period
            self._publish()

    def _stamp_ns(self, state) -> int:
        """A message's stamp [ns] for the simulator's ``state``, as a driver stamps with the ROS clock (never 0)."""
        return EPOCH_NS + self.idle_ns + round(state.t * 1e9)

    def _on_command(self, msg) -> None:
        self.started = True
        qd = np.asarray(msg.data, dtype=float)
        self.commands.append(qd)
        self.world.apply(Command(qd=qd))
        self._publish()

    def _publish(self) -> None:
        s = self.world.read()
        n = len(self.commands)
        ns = self._stamp_ns(s)
        stamp = rclpy.time.Time(nanoseconds=ns).to_msg()
        silent = self.silent_after is not None and n > self.silent_after
        if not (silent and self.silent_topic in ("both", "wrench")):
            w = WrenchStamped()
            w.header.stamp, w.header.frame_id = stamp, "tool0"
            w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = (float(v) for v in s.wrench[:3])
            w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = (float(v) for v in s.wrench[3:])
            self.w_pub.publish(w)
        if not (silent and self.silent_topic in ("both", "joints")):
            js = JointState()
            js.header.stamp = stamp
            order = [3, 0, 5, 1, 4, 2]  # a driver's own order: the world must sort by name
            js.name = [UR_JOINT_NAMES[i] for i in order]
            js.position = [float(s.q[i]) for i in order]
            js.velocity = [float(s.qd[i]) for i in order]
            self.js_pub.publish(js)


def mujoco_world(config: DriveConfig) -> MujocoUR5World:
    """The world drive() builds for ``config`` in MuJoCo, with the scripted hand."""
    task = make_task(config.task, np.random.default_rng(np.random.SeedSequence([config.seed, 0])))
    start = (float(task.start[0]), float(task.start[1]), TASK_HEIGHT)
    return MujocoUR5World(config.object, control_dt=config.dt, start=start, seed=config.seed, operator=PUSH)


def ros_run(config: DriveConfig, *, stale_after=0.5, silent_after=None, silent_topic="both", lockstep=True):
    sim = mujoco_world(config)
    robot = SimRobot(sim, silent_after=silent_after, silent_topic=silent_topic, free_running=not lockstep)
    offset = sim.kinematics().tcp_offset
    mass, com = sim.tool_mass_and_com()
    cfg = Ros2Config(
        domain_id=DOMAIN,
        lockstep=lockstep,
        pace=not lockstep,
        stale_after=stale_after,
        stamps_on_this_clock=False,  # the simulated driver stamps on the simulator's clock
        rate_hz=config.rate_hz,
        tcp_offset=tuple(offset),
        payload=(mass, tuple(com)),
        connect_timeout=10.0,
    )
    world = Ros2World(cfg, alpha=0.8)
    try:
        trial = drive(config, world=world, on_tick=world.publish_monitor)
    finally:
        world.close()
        time.sleep(0.05)  # the final zero command reaches the robot
        robot.close()
    return trial, robot, world


def starved_once(run):
    """``run()`` (a lockstep run: (trial, robot, world)), run again once if this machine starved it.

    Beside two other test workers on two cores the simulated robot's threads were once starved for 0.76 s before
    drive's first read (stale_after 0.5 s: a lost link before any tick). Starved mid-run, the world rightly sends
    zeros for a command whose state aged past stale_after (``stale_commands``), a tick's motion off the in-process
    run's track (a CI run at bad086e had test_ros2_faults' base-frame run 0.1-0.4 mm off from tick 75; its cause was
    not seen again: 45 runs, three at once beside a main job, all within 1.3e-8 m). Both are the world's watchdog
    doing its job on a starved machine, tested on purpose
    by test_silent_topics_stop_the_arm and test_ros2_faults' stale-command test; what a comparison test compares is
    the runs, so such a run is run again once, as the realtime tests run a stalled run again. A second starved run
    is returned as it is (and fails the comparison)."""
    try:
        first = run()
        if first[2].stale_commands == 0:
            return first
    except RobotLinkError as exc:
        if "no new message" not in str(exc):
            raise
    return run()


@pytest.mark.parametrize("controller", ["manual", "cooperative"])
def test_a_ros2_run_matches_the_in_process_mujoco_drive(controller):
    base = dict(controller=controller, task="linear", time_limit=1.2, seed=2)
    ref = drive(DriveConfig(world="mujoco", **base), operator=PUSH)
    trial, robot, world = starved_once(lambda: ros_run(DriveConfig(world="ur", **base)))
    assert trial.n_samples == ref.n_samples == 150
    assert world.rejected_messages == 0 and world.rejected_commands == 0
    # Every command the tick sent arrived, in order (reliable, lockstep), then the stop's zeros.
    sent = np.asarray(robot.commands[: trial.n_samples])
    np.testing.assert_array_equal(sent, trial.joint_velocity)
    assert np.all(np.asarray(robot.commands[trial.n_samples :]) == 0.0)
    # The only difference between the two runs: the ROS world computes the TCP (and the
    # sensor's orientation) from the joint states with the pinocchio UR5, the in-process run
    # reads MuJoCo's sites; they agree to ~1e-8 m here (test_drive bounds it by 1e-6). The
    # loop is stable and short, so the runs differ by about that (measured: pose 1.3e-8 m,
    # velocity 1.3e-7 m/s, joints 3.8e-8 rad; the compensated wrench 1.2e-4 N, the tool's
    # weight rotated by the two models' orientations). Bounds: ~8x those.
    np.testing.assert_allclose(trial.pose, ref.pose, rtol=0, atol=1e-7)
    np.testing.assert_allclose(trial.velocity, ref.velocity, rtol=0, atol=1e-6)
    np.testing.assert_allclose(trial.wrench, ref.wrench, rtol=0, atol=1e-3)
    np.testing.assert_allclose(trial.joints, ref.joints, rtol=0, atol=3e-7)
    np.testing.assert_array_equal(trial.fault, ref.fault)
    # the run moved (the hand pushed 8 N along x for 0.6 s, then 6 N along -y): the match is not trivial
    assert np.abs(trial.pose - trial.pose[0]).max() > 0.005


@pytest.mark.parametrize(
    "topic, lockstep",
    [
        ("wrench", True),
        ("joints", True),
        # Free-running: the robot's thread and the loop each keep their own time, so a loaded machine
        # shifts the tick the silence falls on (78 ticks seen beside another test on 2 cores): it runs alone.
        pytest.param("joints", False, marks=[pytest.mark.realtime, pytest.mark.alone]),  # (it was only realtime:
        # two at a time, 77 ticks for at most 75 in CI at load 3.5, 2026-12-06)
    ],
)
def test_silent_topics_stop_the_arm(topic, lockstep):
    # Lockstep: the robot stops answering after its 40th command, read() waits stale_after
    # for it. Free-running (paced at 125 Hz): the last message ages past stale_after.
    config = DriveConfig(world="ur", controller="manual", task="linear", time_limit=2.0, seed=0)
    trial, robot, world = ros_run(config, stale_after=STALE, silent_after=40, silent_topic=topic, lockstep=lockstep)
    assert trial.meta.extra["ended"] == "link_lost"
    name = "/force_torque_sensor_broadcaster/wrench" if topic == "wrench" else "/joint_states"
    assert name in trial.meta.extra["stop_message"]
    if lockstep:  # ticks 0 … 40 read the start state and the answers to commands 1 … 40
        assert trial.n_samples == 41
    else:  # free-running ticks between the robot's steps: the stop comes within stale_after of the silence
        assert 41 <= trial.n_samples <= 41 + STALE / config.dt + 3
    assert np.all(robot.commands[-1] == 0.0)  # the last command the robot got: stand still


def test_no_robot_is_a_clear_error():
    cfg = Ros2Config(domain_id=DOMAIN, connect_timeout=0.3, node_name="lonely")
    with pytest.raises(
        RobotLinkError, match=r"no message on /joint_states and /force_torque_sensor_broadcaster/wrench within 0.3 s"
    ):
        Ros2World(cfg)


def test_config_names_the_field():
    with pytest.raises(ValueError, match=r"Ros2Config.wrench_topic must be a ROS topic name"):
        Ros2Config(wrench_topic="not a topic")
    with pytest.raises(ValueError, match=r"Ros2Config.stale_after must be a finite number > 0"):
        Ros2Config(stale_after=0)
    with pytest.raises(ValueError, match=r"Ros2Config.domain_id"):
        Ros2Config(domain_id=300)


class Listener(_SpunNode):
    """An operator's monitor: subscribes to the node's monitor topics."""

    TOPICS = {
        "/coassist/tool_pose": "geometry_msgs.msg.PoseStamped",
        "/coassist/prediction": "nav_msgs.msg.Path",
        "/coassist/alpha": "std_msgs.msg.Float64",
        "/coassist/hand_force": "geometry_msgs.msg.WrenchStamped",
        "/diagnostics": "diagnostic_msgs.msg.DiagnosticArray",
    }

    def __init__(self) -> None:
        import importlib

        self.got: dict[str, list] = {t: [] for t in self.TOPICS}
        self._open("monitor")
        for topic, kind in self.TOPICS.items():
            module, name = kind.rsplit(".", 1)
            cls = getattr(importlib.import_module(module), name)
            self.node.create_subscription(cls, topic, lambda m, t=topic: self.got[t].append(m), 1000)
        self._start()

    def close(self) -> None:
        time.sleep(0.3)  # what is in flight arrives
        super().close()


@pytest.mark.parametrize("controller", ["cooperative", "cooperative-arbitrated"])
def test_the_monitor_topics_carry_the_run(controller):
    """The plain game with the oracle's rows; the arbitrated one with the plan's (the nominal source gives the tick
    no rows: the monitor published none, while the MCAP and the live view drew the plan's) and its online α (a
    constant α given to the world was published instead)."""
    from coassist.scenario.reference_intents import OracleIntent

    nominal = controller == "cooperative-arbitrated"
    listener = Listener()
    try:
        config = DriveConfig(
            world="ur",
            controller=controller,
            intent="nominal" if nominal else DriveConfig.intent,
            task="linear",
            time_limit=0.6,
            seed=1,
        )
        sim = mujoco_world(config)
        robot = SimRobot(sim)
        mass, com = sim.tool_mass_and_com()
        cfg = Ros2Config(
            domain_id=DOMAIN,
            lockstep=True,
            pace=False,
            stale_after=0.5,
            tcp_offset=tuple(sim.kinematics().tcp_offset),
            payload=(mass, tuple(com)),
            connect_timeout=10.0,
        )
        world = Ros2World(cfg, alpha=0.123)  # until the run is followed: then its controller's
        deadline = time.monotonic() + 5.0  # the monitor's subscriptions are matched before the run
        while world._pubs["tool_pose"].get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        try:
            # Unpaced, the lockstep run publishes its 15 messages a topic within ~0.1 s, faster than the monitor's
            # rate; its publishers keep the last 10 (KEEP_LAST 10, as an operator's monitor would), so a listener
            # stalled by a busy machine lost 3 of 15 once in CI. A few ms a tick spaces them as a run's own pace
            # would (20 ms between messages here, 40 at 125 Hz), and the run stays unpaced (no deadline).
            def on_tick(k, state, out):
                world.publish_monitor(k, state, out)
                time.sleep(0.004)

            trial = drive(config, world=world, on_tick=on_tick, intent_source=None if nominal else OracleIntent(60))
        finally:
            world.close()
            robot.close()
    finally:
        listener.close()
    n = trial.n_samples  # 75 ticks at 125 Hz, the monitor at 25 Hz: every 5th tick, from tick 0
    poses = listener.got["/coassist/tool_pose"]
    assert len(poses) == len(range(0, n, 5)) == 15
    np.testing.assert_array_equal([[p.pose.position.x, p.pose.position.y] for p in poses], trial.pose[::5])
    assert all(p.header.frame_id == "base" for p in poses)
    paths = listener.got["/coassist/prediction"]
    # 0.4 s at 8 ms = 50 rows, every 5th drawn (rows 4, 9, …, 49), stamped at t + (i + 1)·dt
    rows = list(range(4, 50, 5))
    assert len(paths) == 15 and all(len(p.poses) == len(rows) for p in paths)
    np.testing.assert_array_equal(
        [[q.pose.position.x, q.pose.position.y] for q in paths[3].poses], trial.prediction[15, rows, :2]
    )
    t0 = paths[3].header.stamp.sec * 10**9 + paths[3].header.stamp.nanosec
    assert [q.header.stamp.sec * 10**9 + q.header.stamp.nanosec - t0 for q in paths[3].poses] == [
        (i + 1) * 8_000_000 for i in rows
    ]
    alphas = [m.data for m in listener.got["/coassist/alpha"]]
    assert alphas == trial.alpha[::5].tolist()
    if nominal:
        assert len(set(alphas)) > 1  # the arbitration's online α moves
    else:
        from coassist.control.presets import get_preset

        assert alphas == [get_preset(trial.meta.extra["preset"]).game.alpha] * 15  # the run's preset's α
    forces = listener.got["/coassist/hand_force"]
    np.testing.assert_array_equal([[f.wrench.force.x, f.wrench.force.y] for f in forces], trial.wrench[::5])
    diags = listener.got["/diagnostics"]
    flagged = int(np.count_nonzero(trial.fault))
    assert len(diags) == 15 + int(np.count_nonzero(trial.fault[np.arange(n) % 5 != 0]))
    assert all(d.status[0].name == "coassist: fault flags" for d in diags) and flagged == sum(
        d.status[0].level != b"\x00" for d in diags
    )


def test_coassist_ros2_drives_the_simulated_robot_and_writes_the_run(tmp_path):
    from typer.testing import CliRunner

    from coassist.cli import app
    from coassist.data import read_trial

    config = DriveConfig(world="ur", controller="manual", task="linear", time_limit=0.4, seed=0)
    sim = mujoco_world(config)
    robot = SimRobot(sim)
    offset = ",".join(repr(float(v)) for v in sim.kinematics().tcp_offset)
    try:
        result = CliRunner().invoke(
            app,
            [
                "ros2",
                "--controller",
                "manual",
                "--time-limit",
                "0.4",
                "--domain-id",
                str(DOMAIN),
                "--lockstep",
                "--yes",
                "--tcp-offset",
                offset,
                "--stale-after",
                "0.5",
                "--out",
                str(tmp_path / "run.parquet"),
                "--mcap",
                "--no-plot",
            ],
        )
    finally:
        time.sleep(0.05)
        robot.close()
    assert result.exit_code == 0, result.output
    trial = read_trial(tmp_path / "run.parquet")
    assert trial.n_samples == 50 and trial.meta.extra["ended"] == "time_limit"
    np.testing.assert_array_equal(np.asarray(robot.commands[:50]), trial.joint_velocity)
    from coassist.data.bags import load_bag_trial

    assert load_bag_trial(tmp_path / "run.mcap").pose.tobytes() == trial.pose.tobytes()
    bad = CliRunner().invoke(app, ["ros2", "--wrench-topic", "no spaces", "--yes"])
    assert bad.exit_code == 2 and "--wrench-topic must be a ROS topic name" in bad.output


def test_coassist_ros2_with_a_live_view_writes_the_run_first_and_shows_what_the_robot_is_told(tmp_path, monkeypatch):
    """``--foxglove`` with ``--scene``, ``--base-frame world`` and ``--mcap``: the run is written before the
    live view closes (a live view that hangs on closing once cost the trial); the view draws the scene
    file's box, the one the robot is told of, in the robot's base frame; the MCAP file is in that frame and
    stamped as the live view was."""
    from types import SimpleNamespace

    from rosbags.highlevel import AnyReader
    from typer.testing import CliRunner

    import coassist.cli.ros2 as ros2_cli
    import coassist.runtime.foxglove as foxglove_module
    from coassist.cli import app
    from coassist.data import read_trial
    from coassist.runtime.live import LiveFeed

    from ..runtime.test_live import Recorder

    sink = Recorder()
    monkeypatch.setattr(
        foxglove_module,
        "open_foxglove",
        lambda port, **kw: (LiveFeed(sink, rate_hz=100.0), SimpleNamespace(url=f"ws://127.0.0.1:{port}")),
    )
    out = tmp_path / "run.parquet"
    at_close: list[bool] = []
    real_close = ros2_cli.close_live

    def close_live(feed):
        at_close.append(out.exists())
        real_close(feed)

    monkeypatch.setattr(ros2_cli, "close_live", close_live)
    scene = tmp_path / "scene.toml"
    scene.write_text('[[obstacle]]\ncenter = [0.30, 0.35]\nsize = [0.10, 0.12]\nname = "fixture"\n')
    config = DriveConfig(world="ur", controller="manual", task="linear", time_limit=0.4, seed=0)
    sim = mujoco_world(config)
    robot = SimRobot(sim)
    offset = ",".join(repr(float(v)) for v in sim.kinematics().tcp_offset)
    # the path hypotheses, which read a scene (MG with --scene is refused: it records a scene nothing read)
    args = ["ros2", "--intent", "paths", "--time-limit", "0.4", "--domain-id", str(DOMAIN), "--lockstep"]
    args += ["--yes", "--tcp-offset", offset, "--stale-after", "0.5", "--out", str(out), "--mcap", "--no-plot"]
    args += ["--scene", str(scene), "--base-frame", "world", "--foxglove", "0"]
    try:
        result = CliRunner().invoke(app, args)
    finally:
        time.sleep(0.05)
        robot.close()
    assert result.exit_code == 0, result.output
    assert at_close == [True]  # the trial was on disk when the live view closed
    assert sink.closed
    trial = read_trial(out)
    live = sink.snapshots[-1].trial
    assert trial.n_samples == 50 and sink.snapshots[-1].k == 49
    # what the view draws: the scene file's box (the robot is told of it), in the robot's base frame
    assert live.frame_id == "world" and len(live.obstacles) == 1
    np.testing.assert_array_equal(live.obstacles[0][0], [0.30, 0.35])
    np.testing.assert_array_equal(live.obstacles[0][1], [0.10, 0.12])
    # the MCAP: the base frame, and tick k stamped live.start_ns + k·8 ms, as the view stamped it
    assert trial.meta.extra["live_start_ns"] == live.start_ns > 1_600_000_000 * 10**9
    frames, stamps = set(), []
    with AnyReader([tmp_path / "run.mcap"]) as reader:
        for conn, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if hasattr(msg, "header"):
                frames.add(msg.header.frame_id)
            if conn.topic == "/current_pose":
                stamps.append(stamp)
    assert frames == {"world"}
    assert stamps == [live.start_ns + k * 8_000_000 for k in range(50)] == [live.stamp(k) for k in range(50)]
