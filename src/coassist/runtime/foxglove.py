"""The live view in Foxglove: a WebSocket server that the Foxglove app opens while a run goes on.

:func:`open_foxglove` starts the server (foxglove-sdk, the ``viz`` extra) and returns the
:class:`~coassist.runtime.live.LiveFeed` that publishes to it: every command that runs the
control loop (``drive``, ``play``, ``collect``, ``study run``, ``ros2``) passes the feed's
``watch(episode)`` to its loop, so every world is shown the same way.

The topics are the MCAP file's (:data:`coassist.data.trial_mcap.MCAP_TOPICS`: tool pose and
twist, hand wrench, reference, prediction, α, fault flags, joint states and commands), with
the same names, types, ``ros2msg`` schemas (the very text the MCAP file embeds,
:func:`~coassist.data.trial_mcap.ros2_schema`) and values in CDR (:mod:`coassist.data.tick_cdr`,
rosbags' bytes); and one more, ``/scene`` (``foxglove.SceneUpdate``): the obstacles the run's
intent source is told of as boxes (:func:`~coassist.runtime.live.told_obstacles`: a scene file's,
the simulated task's, or none), the path the operator is shown as a line and the target ball, all
in the trial's frame (the robot's base frame, ``base`` unless the world names another) at the
tool's start height, sent when a trial begins and whenever a viewer subscribes to it.

What it costs the control loop: nothing on its thread but the snapshot
(:mod:`coassist.runtime.live`). The server, and all encoding, run in a worker process of their
own (:class:`FoxgloveProcess`, as the real-time predictor's ``process`` backend): the feed's
publishing thread only packs a snapshot into raw float64 bytes (about 10 µs) and writes them
to a pipe, so it holds the control process's interpreter lock for microseconds a frame. (A
thread encoding the messages itself held it for ~0.1 ms a frame, 0.5 ms on a loaded machine,
and when the OS preempted that thread mid-frame the control thread waited for the lock: it
more than doubled a 500 Hz loop's deadline misses on a 2-core machine at load 15, docs/foxglove.md.)
In the worker, nothing is encoded for a topic no viewer subscribes to, and the server (Rust)
sends on its own threads; a slow viewer loses the oldest messages (``backlog`` per viewer are
kept, 1024 by default), it never slows the worker, and a worker that falls behind only makes the publishing thread
wait on the pipe, never the control thread. Closing never waits on the worker for long: a worker that
hangs (stopped, starved) with the pipe full is killed, not written to (:meth:`FoxgloveProcess.close`),
so a command writes its trial whatever became of its live view.
"""

from __future__ import annotations

import importlib.util
import json
import math
import multiprocessing
import select
import struct
import sys
import threading
import time
from typing import Any

import numpy as np

from coassist._checks import check_int
from coassist.data.trial_mcap import MCAP_TOPICS
from coassist.errors import CoassistError
from coassist.runtime.live import LiveFeed, LiveTrial, TickSnapshot

__all__ = [
    "BACKLOG",
    "CLOSE_TIMEOUT",
    "FOXGLOVE_PORT",
    "INSTALL_HINT",
    "SCENE_TOPIC",
    "TOPICS",
    "FoxgloveProcess",
    "FoxgloveServer",
    "LiveServerError",
    "check_port",
    "open_foxglove",
]

#: The Foxglove app's default WebSocket port (Open connection → Foxglove WebSocket).
FOXGLOVE_PORT = 8765
#: The scene's topic (foxglove.SceneUpdate).
SCENE_TOPIC = "/scene"
#: Every topic the server offers: the MCAP file's, then the scene.
TOPICS: tuple[str, ...] = (*MCAP_TOPICS, SCENE_TOPIC)
#: What to install for the live view.
INSTALL_HINT = "pip install 'coassist[viz]'"
#: [s] how long :meth:`FoxgloveProcess.close` waits for the worker to stop when asked, before it kills it.
CLOSE_TIMEOUT = 5.0
#: Messages the server keeps per viewer by default (the SDK's own default): a viewer that falls
#: further behind loses the oldest ones (about 110 frames of the MCAP file's nine topics).
BACKLOG = 1024


class LiveServerError(CoassistError, OSError):
    """The live view's server could not start (its port is taken, the address is not this machine's)."""


def check_port(port: object, name: str = "port") -> int:
    """``port`` as an int in 0 … 65535 (0: any free port); ValueError naming ``name`` otherwise."""
    if isinstance(port, bool) or not isinstance(port, (int, np.integer)) or not 0 <= int(port) <= 65535:
        raise ValueError(f"{name} must be a port number in 0 … 65535 (0: any free port), got {port!r}")
    return int(port)


def _import_viz() -> tuple[Any, Any]:
    """foxglove and rosbags' typestore, or one line saying what to install."""
    try:
        import foxglove
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ImportError(f"the live view needs the viz extra ({exc.name} missing): {INSTALL_HINT}") from None
    return foxglove, get_typestore(Stores.ROS2_HUMBLE)


class FoxgloveServer:
    """The Foxglove server, its channels and the encoding (module docstring): a
    :class:`~coassist.runtime.live.LiveSink` in the process it runs in (:class:`FoxgloveProcess`'s worker).

    port : 0 … 65535 (0: any free one; :attr:`port` says which).  host : the address to listen on
    (default this machine only).  name : the server's name in the app.  watched : an integer array
    (len(:data:`TOPICS`)) the server keeps each topic's subscription count in (None: none kept).
    backlog : messages kept per viewer, ≥ 1 (:data:`BACKLOG`); a viewer further behind loses the oldest.
    """

    def __init__(
        self,
        port: int = FOXGLOVE_PORT,
        host: str = "127.0.0.1",
        name: str = "coassist",
        watched: Any = None,
        backlog: int = BACKLOG,
    ) -> None:
        port = check_port(port)
        backlog = check_int(backlog, "backlog", 1)
        foxglove, ts = _import_viz()
        from foxglove.channels import SceneUpdateChannel
        from foxglove.websocket import ServerListener

        from coassist.data.trial_mcap import ros2_schema

        sink = self
        self._scene_wanted = threading.Event()

        class _Listener(ServerListener):  # on the server's thread: a flag and a count
            def on_subscribe(self, client: Any, channel: Any) -> None:
                if channel.topic == SCENE_TOPIC:
                    sink._scene_wanted.set()
                if watched is not None and channel.topic in TOPICS:
                    watched[TOPICS.index(channel.topic)] += 1

            def on_unsubscribe(self, client: Any, channel: Any) -> None:
                if watched is not None and channel.topic in TOPICS:
                    watched[TOPICS.index(channel.topic)] -= 1

        self._ctx = foxglove.Context()
        try:
            self._server = foxglove.start_server(
                name=name,
                host=host,
                port=port,
                context=self._ctx,
                server_listener=_Listener(),
                message_backlog_size=backlog,
            )
        except (RuntimeError, OSError, ValueError) as exc:
            text = " ".join(str(exc).split())
            if "in use" in text:
                raise LiveServerError(
                    f"{host}:{port} is in use (another program listens on it): pick another port"
                ) from None
            raise LiveServerError(f"cannot serve the live view on {host}:{port}: {text}") from None
        self.host = host
        self._channels = {
            topic: foxglove.Channel(
                topic,
                schema=foxglove.Schema(name=msgtype, encoding="ros2msg", data=ros2_schema(ts, msgtype).encode()),
                message_encoding="cdr",
                context=self._ctx,
            )
            for topic, msgtype in MCAP_TOPICS.items()
        }
        self._scene = SceneUpdateChannel(SCENE_TOPIC, context=self._ctx)
        self._trial: LiveTrial | None = None
        self._encoder: Any = None
        self._scene_msg: Any = None

    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self._server.port)

    def watched(self, topic: str) -> bool:
        """Whether a viewer subscribes to ``topic`` now."""
        channel = self._scene if topic == SCENE_TOPIC else self._channels[topic]
        return bool(channel.has_sinks())

    @property
    def url(self) -> str:
        """What the Foxglove app opens (Open connection → Foxglove WebSocket)."""
        return f"ws://{self.host}:{self.port}"

    def publish(self, snapshot: TickSnapshot) -> None:
        """One tick's messages (and the scene on a new trial or a new viewer); on the publishing thread."""
        from coassist.data.tick_cdr import TickEncoder

        trial = snapshot.trial
        if trial is not self._trial:
            self._trial = trial
            self._encoder = TickEncoder(trial.frame_id, trial.joint_names, trial.dt_ns)
            self._scene_msg = scene_update(trial)
            self._scene_wanted.set()
        if self._scene_wanted.is_set() and self._scene.has_sinks():
            self._scene_wanted.clear()
            self._scene.log(self._scene_msg, log_time=trial.start_ns)
        channels = self._channels
        if not any(ch.has_sinks() for ch in channels.values()):
            return  # nobody watches: nothing to encode
        ns = trial.stamp(snapshot.k)
        for topic, payload in self._encoder.messages(ns, *tick_rows(snapshot)):
            channel = channels[topic]
            if channel.has_sinks():
                channel.log(payload, log_time=ns)

    def close(self) -> None:
        self._server.stop()


def tick_rows(snapshot: TickSnapshot) -> tuple[Any, ...]:
    """The arguments of :meth:`TickEncoder.tick <coassist.data.tick_cdr.TickEncoder.tick>` after the
    stamp, as :func:`~coassist.data.trial_mcap.write_trial_mcap` builds them from the trial file:
    pose and reference (6,) with the uncontrolled axes at the start pose, twist and wrench (6,)
    with zeros there, the prediction (H_s, d) with the uncontrolled controlled-axes columns held
    at the start pose (the nominal plan's next H_s rows for the nominal source), α, flags, joints."""
    trial = snapshot.trial
    start = trial.start_pose
    d = snapshot.pose.shape[0]

    def full(row: np.ndarray, fill: np.ndarray) -> np.ndarray:
        out = fill.copy()
        out[:d] = row
        return out

    pose6 = full(snapshot.pose, start)
    pred = snapshot.prediction
    if pred is None and trial.plan is not None:
        pred = trial.plan[snapshot.k + 1 : snapshot.k + 1 + trial.horizon, :2]
    if pred is not None and d > 2:  # the trial file's prediction columns of the other controlled axes
        wide = np.empty((pred.shape[0], d))
        wide[:, :2] = pred
        wide[:, 2:] = start[list(trial.dofs[2:])]
        pred = wide
    zeros = np.zeros(6)
    return (
        pose6,
        full(snapshot.velocity, zeros),
        full(snapshot.wrench, zeros),
        full(snapshot.reference, start),
        pred,
        snapshot.alpha,
        snapshot.fault,
        snapshot.joints,
        snapshot.joint_command,
    )


def scene_update(trial: LiveTrial) -> Any:
    """The trial's ``foxglove.SceneUpdate``: entity ``obstacle`` (a red box per obstacle the intent source
    is told of, 5 cm tall; none where it is told none, which clears the previous trial's),
    ``path`` (the operator's path, a line strip) and ``target`` (a sphere of the arrive radius), in
    ``trial.frame_id`` at the start pose's height [m]."""
    from foxglove.messages import (
        Color,
        CubePrimitive,
        LinePrimitive,
        LinePrimitiveLineType,
        Point3,
        Pose,
        Quaternion,
        SceneEntity,
        SceneUpdate,
        SpherePrimitive,
        Timestamp,
        Vector3,
    )

    z = float(trial.start_pose[2])
    stamp = Timestamp(trial.start_ns // 1_000_000_000, trial.start_ns % 1_000_000_000)
    upright = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)

    def at(x: float, y: float) -> Any:
        return Pose(position=Vector3(x=float(x), y=float(y), z=z), orientation=upright)

    def entity(name: str, **primitives: Any) -> Any:
        return SceneEntity(timestamp=stamp, frame_id=trial.frame_id, id=name, **primitives)

    boxes = [
        CubePrimitive(
            pose=at(c[0], c[1]),
            size=Vector3(x=float(s[0]), y=float(s[1]), z=0.05),
            color=Color(r=0.85, g=0.2, b=0.2, a=0.6),
        )
        for c, s in trial.obstacles
    ]
    line = LinePrimitive(
        type=LinePrimitiveLineType.LineStrip,
        pose=at(0.0, 0.0),
        thickness=0.004,
        points=[Point3(x=float(x), y=float(y), z=0.0) for x, y in trial.path.tolist()],
        color=Color(r=0.2, g=0.45, b=0.9, a=1.0),
    )
    r = 2.0 * trial.arrive_radius
    ball = SpherePrimitive(
        pose=at(trial.target[0], trial.target[1]), size=Vector3(x=r, y=r, z=r), color=Color(r=0.2, g=0.7, b=0.3, a=0.4)
    )
    return SceneUpdate(
        entities=[entity("obstacle", cubes=boxes), entity("path", lines=[line]), entity("target", spheres=[ball])]
    )


# --------------------------------------------------------------------------- the worker process
# Parent → worker: b"T" + JSON (a new trial), b"K" + a tick (a header, then raw float64 arrays),
# b"C" (close). Worker → parent, once: b"R" + the port, or b"E" / b"I" + the one-line error
# (the server could not listen / the extra is missing).
_TICK = struct.Struct("<qqdiii")  # k, fault, α (NaN: none), d, rows of the prediction (-1: none), joints (-1: none)


def _pack_trial(trial: LiveTrial) -> bytes:
    return (
        b"T"
        + json.dumps(
            {
                "number": trial.number,
                "start_ns": trial.start_ns,
                "dt": trial.dt,
                "n_max": trial.n_max,
                "dofs": list(trial.dofs),
                "start_pose": trial.start_pose.tolist(),
                "horizon": trial.horizon,
                "joint_names": list(trial.joint_names),
                "obstacles": [[c.tolist(), z.tolist()] for c, z in trial.obstacles],
                "path": trial.path.tolist(),
                "target": trial.target.tolist(),
                "arrive_radius": trial.arrive_radius,
                "frame_id": trial.frame_id,
            }
        ).encode()
    )


def _unpack_trial(data: bytes) -> LiveTrial:
    t = json.loads(data)
    return LiveTrial(
        number=int(t["number"]),
        start_ns=int(t["start_ns"]),
        dt=float(t["dt"]),
        n_max=int(t["n_max"]),
        dofs=tuple(t["dofs"]),
        start_pose=np.array(t["start_pose"], dtype=float),
        horizon=int(t["horizon"]),
        plan=None,  # the parent sends the nominal plan's rows with each tick
        joint_names=tuple(t["joint_names"]),
        obstacles=tuple((np.array(c, dtype=float), np.array(z, dtype=float)) for c, z in t["obstacles"]),
        path=np.array(t["path"], dtype=float).reshape(-1, 2),
        target=np.array(t["target"], dtype=float),
        arrive_radius=float(t["arrive_radius"]),
        frame_id=str(t["frame_id"]),
    )


def _pack_tick(snap: TickSnapshot) -> bytes:
    """A snapshot as bytes: the prediction resolved (the nominal plan's rows where the source is the plan)."""
    trial, k = snap.trial, snap.k
    pred = snap.prediction
    if pred is None and trial.plan is not None:
        pred = trial.plan[k + 1 : k + 1 + trial.horizon, :2]
    joints = snap.joints
    parts = [snap.pose, snap.velocity, snap.wrench, snap.reference]
    if pred is not None:
        parts.append(pred)
    if joints is not None:
        parts += [joints, np.zeros_like(joints) if snap.joint_command is None else snap.joint_command]
    alpha = math.nan if snap.alpha is None else float(snap.alpha)
    header = _TICK.pack(
        k,
        int(snap.fault),
        alpha,
        snap.pose.shape[0],
        -1 if pred is None else pred.shape[0],
        -1 if joints is None else joints.shape[0],
    )
    return b"K" + header + np.concatenate([np.ravel(a) for a in parts]).astype("<f8", copy=False).tobytes()


def _unpack_tick(data: bytes, trial: LiveTrial) -> TickSnapshot:
    k, fault, alpha, d, n_pred, n_joints = _TICK.unpack_from(data)
    values = np.frombuffer(data, dtype="<f8", offset=_TICK.size)
    at = 0

    def take(n: int) -> np.ndarray:
        nonlocal at
        out = values[at : at + n]
        at += n
        return out

    pose, velocity, wrench, reference = take(d), take(d), take(d), take(d)
    pred = None if n_pred < 0 else take(2 * n_pred).reshape(n_pred, 2)
    joints = command = None
    if n_joints >= 0:
        joints, command = take(n_joints), take(n_joints)
    return TickSnapshot(
        trial, k, pose, velocity, wrench, reference, pred, None if math.isnan(alpha) else alpha, fault, joints, command
    )


def _serve(conn: Any, host: str, port: int, name: str, watched: Any, backlog: int) -> None:
    """The worker process: the server, fed by the parent's pipe until it closes."""
    try:
        server = FoxgloveServer(port, host=host, name=name, watched=watched, backlog=backlog)
    except ImportError as exc:
        conn.send_bytes(b"I" + str(exc).encode())
        return
    except (LiveServerError, ValueError) as exc:
        conn.send_bytes(b"E" + str(exc).encode())
        return
    conn.send_bytes(b"R" + str(server.port).encode())
    trial: LiveTrial | None = None
    said = False
    try:
        while True:
            try:
                data = conn.recv_bytes()
            except (EOFError, OSError):
                return  # the parent is gone
            kind = data[:1]
            if kind == b"C":
                return
            try:
                if kind == b"T":
                    trial = _unpack_trial(data[1:])
                elif kind == b"K" and trial is not None:
                    server.publish(_unpack_tick(data[1:], trial))
            except Exception as exc:  # noqa: BLE001 - one message lost; the view goes on
                if not said:
                    print(f"live view: a message was not published ({type(exc).__name__}: {exc})", file=sys.stderr)
                    said = True
    finally:
        server.close()


class FoxgloveProcess:
    """A :class:`~coassist.runtime.live.LiveSink` that runs a :class:`FoxgloveServer` in a worker
    process (module docstring): snapshots go there as raw bytes over a pipe.

    port, host, name, backlog : the server's (:class:`FoxgloveServer`).  start_timeout : [s] to wait for
    the worker to listen. Raises as :func:`open_foxglove`.  pid : the worker's process id.
    """

    def __init__(
        self,
        port: int = FOXGLOVE_PORT,
        host: str = "127.0.0.1",
        name: str = "coassist",
        start_timeout: float = 60.0,
        backlog: int = BACKLOG,
    ) -> None:
        port = check_port(port)
        backlog = check_int(backlog, "backlog", 1)
        for module in ("foxglove", "rosbags"):  # said here in one line, before a process starts
            if importlib.util.find_spec(module) is None:
                raise ImportError(f"the live view needs the viz extra ({module} missing): {INSTALL_HINT}")
        self.host = host
        ctx = multiprocessing.get_context("spawn")  # no fork of a process running the control loop's threads
        self._watched = ctx.Array("i", len(TOPICS), lock=False)  # written by the worker's server only
        self._conn, child = ctx.Pipe()
        # held by whoever writes to the pipe: the publishing thread (blocked while the pipe is full) or close()
        self._send_lock = threading.Lock()
        self._proc = ctx.Process(
            target=_serve, args=(child, host, port, name, self._watched, backlog), name="coassist-foxglove", daemon=True
        )
        self._proc.start()
        self.pid = self._proc.pid
        child.close()
        reply = b""
        deadline = time.monotonic() + start_timeout
        while (
            time.monotonic() < deadline
        ):  # with the process in view (see ProcessRunner: a dead child's EOF may not come)
            if self._conn.poll(0.05):
                try:
                    reply = self._conn.recv_bytes()
                except (EOFError, OSError):
                    pass
                break
            if not self._proc.is_alive():
                break
        if reply[:1] != b"R":
            code = self._proc.exitcode
            self.close()
            text = reply[1:].decode(errors="replace")
            if reply[:1] == b"I":
                raise ImportError(text)
            if reply[:1] == b"E":
                raise LiveServerError(text)
            why = f"it exited with code {code}" if code is not None else f"no answer within {start_timeout:g} s"
            raise LiveServerError(f"the live view's server process did not start ({why})")
        self.port = int(reply[1:])
        self._trial: LiveTrial | None = None

    @property
    def url(self) -> str:
        """What the Foxglove app opens (Open connection → Foxglove WebSocket)."""
        return f"ws://{self.host}:{self.port}"

    def watched(self, topic: str) -> bool:
        """Whether a viewer subscribes to ``topic`` now."""
        return self._watched[TOPICS.index(topic)] > 0

    def publish(self, snapshot: TickSnapshot) -> None:
        """Send the snapshot to the worker (its trial first, once): on the feed's publishing thread.
        Nothing but a new trial is sent while no viewer subscribes to anything."""
        with self._send_lock:
            if snapshot.trial is not self._trial:
                self._trial = snapshot.trial
                self._conn.send_bytes(_pack_trial(snapshot.trial))
            if any(self._watched):
                self._conn.send_bytes(_pack_tick(snapshot))

    def close(self, timeout: float = CLOSE_TIMEOUT) -> None:
        """Stop the worker (it stops the server) without ever blocking for long: it is asked to stop where
        the pipe takes the request at once, and killed when it has not stopped within ``timeout`` s. A
        worker that hangs with the pipe full (a publish stuck in its send holds the pipe, or the pipe has
        no room) is killed at once: writing to it would wait for ever."""
        deadline = time.monotonic() + float(timeout)
        asked = False
        if self._send_lock.acquire(timeout=min(1.0, float(timeout))):
            try:
                _, room, _ = select.select([], [self._conn], [], 0.0)
                if room:  # a Unix socket that selects writable has room for this 5-byte message: no wait
                    self._conn.send_bytes(b"C")
                    asked = True
            except (OSError, ValueError):  # closed already, or the worker is gone
                pass
            finally:
                self._send_lock.release()
        if asked:
            self._proc.join(timeout=max(0.0, deadline - time.monotonic()))
        if self._proc.is_alive():
            self._proc.kill()  # SIGKILL: it ends a stopped process too; a publish stuck in its send then fails
            self._proc.join(timeout=2.0)
        # a publish that was stuck returns (the worker's end is closed) before the connection is closed under it
        if self._send_lock.acquire(timeout=1.0):
            try:
                self._conn.close()
            finally:
                self._send_lock.release()


def open_foxglove(
    port: int = FOXGLOVE_PORT,
    *,
    host: str = "127.0.0.1",
    rate_hz: float = 30.0,
    name: str = "coassist",
    backlog: int = BACKLOG,
) -> tuple[LiveFeed, FoxgloveProcess]:
    """Start the Foxglove server on ``host:port`` in its worker process and a :class:`LiveFeed`
    publishing to it at ``rate_hz``; returns both (the sink says the port and the URL). ``backlog``:
    the messages the server keeps per viewer (a viewer further behind loses the oldest ones).

    Raises ImportError (one line: what to install) without the viz extra, ValueError for a port
    outside 0 … 65535 or a backlog < 1, :class:`LiveServerError` when the server cannot listen (the
    port in use). Close the feed when done (it stops the server)."""
    sink = FoxgloveProcess(port, host=host, name=name, backlog=backlog)
    try:
        return LiveFeed(sink, rate_hz), sink
    except BaseException:
        sink.close()
        raise
