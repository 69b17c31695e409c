"""A live view of the control loop, off its thread: the tick hands over a snapshot, a thread publishes it.

The control thread's whole part is the ``on_tick`` that :meth:`LiveFeed.watch` returns: it
copies the tick's few small arrays (pose, twist, hand wrench, reference, prediction, joints,
the joint command; a few microseconds) into a :class:`TickSnapshot` and stores it in one
slot, overwriting the one before. That store is one attribute assignment: no lock, no queue
that can fill, no serialisation, no socket, so nothing a viewer does (a slow link, a stalled
socket, a crashed sink) can make a tick wait.

A publishing thread wakes ``rate_hz`` times a second (default 30, a viewer's rate), takes the
newest snapshot if it is new and hands it to the sink (:class:`LiveSink`; the Foxglove server
is :mod:`coassist.runtime.foxglove`). The ticks in between are not published: the live view
shows the run as it goes, the trial file (and its MCAP) keeps every tick. A sink that raises
is counted (:attr:`LiveFeed.failures`, :attr:`LiveFeed.last_error`) and the run goes on.

The publishing thread runs at the scheduling policy of the thread that called :meth:`LiveFeed.watch`
(the control thread, at SCHED_FIFO when the lab gives the loop real-time priority, ``chrt -f``): a
thread at normal priority that the OS preempts while it holds the interpreter lock makes the
real-time control thread wait for it behind every other process of a busy machine (a priority
inversion: with ``coassist ur-sim`` at 500 Hz and the loop at SCHED_FIFO on the loaded 2-core
machine it doubled the loop's deadline misses, docs/foxglove.md). At the loop's own priority it is
never preempted by them, and it holds the lock for microseconds a frame.

Every trial the feed watches gets a :class:`LiveTrial`: its scene (the path shown to the
operator, the target ball and the obstacles the run's intent source is told of, in the plan's
frame: :func:`told_obstacles`), the frame its poses are in (the world's ``base_frame`` where it
has one, e.g. ``coassist ros2 --base-frame``; else ``base``), its period, the axes a 2-D
world does not control (held at the start pose, as the MCAP file fills them) and the start
of its clock. Tick k is stamped ``start_ns + round(k·dt·1e9)``, the MCAP file's stamps with
``start_ns`` the wall clock when the trial began (never before the previous trial's last
possible stamp, so a viewer's clock never runs backwards when a simulated trial ran faster
than real time). :meth:`LiveFeed.watch` records ``start_ns`` in the episode's meta fields
(:data:`~coassist.data.run_pair.LIVE_START`), so the trial file keeps it and the run's MCAP file
(:func:`~coassist.data.run_pair.write_run_pair`) is stamped as the live view was.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np

from coassist._checks import check_real
from coassist.data.run_pair import LIVE_START
from coassist.runtime.loop import alpha_reader
from coassist.runtime.world import RobotState, finite_vector, optional_member

__all__ = ["LiveFeed", "LiveSink", "LiveTrial", "TickSnapshot", "told_obstacles"]

OnTick = Callable[[int, RobotState, Any], None]


@dataclass(frozen=True, eq=False)
class LiveTrial:
    """What a live view needs of one trial besides its ticks (module docstring).

    number : the feed's count of trials so far (0 first).  start_ns : tick 0's stamp [ns since the epoch].
    dt : the period [s].  n_max : the most ticks it may run.  dofs : the controlled pose axes.
    start_pose : (6,) where the tool started [m, rad] (the uncontrolled axes' values).
    horizon : H_s, the rows of the prediction a tick logs.  plan : (n, 4) the plan grid when the
    intent source is the nominal plan (its next H_s rows are the prediction, as in the trial
    file), else None.  joint_names : ``/joint_states``' names (empty: no joints).
    obstacles : ((center (2,), size (2,)), …) [m], those the intent source is told of (:func:`told_obstacles`).
    path : (m, 2) the path the operator is shown [m].
    target : (2,) [m] and arrive_radius [m]: the ball that ends the trial.  frame_id : every pose's frame.
    """

    number: int
    start_ns: int
    dt: float
    n_max: int
    dofs: tuple[int, ...]
    start_pose: np.ndarray
    horizon: int
    plan: np.ndarray | None
    joint_names: tuple[str, ...]
    obstacles: tuple[tuple[np.ndarray, np.ndarray], ...]
    path: np.ndarray
    target: np.ndarray
    arrive_radius: float
    frame_id: str = "base"

    @property
    def dt_ns(self) -> int:
        return round(self.dt * 1e9)

    def stamp(self, k: int) -> int:
        """Tick k's stamp [ns]: ``start_ns + round(k·dt·1e9)`` (the MCAP file's, module docstring)."""
        return self.start_ns + round(k * self.dt * 1e9)

    @property
    def end_ns(self) -> int:
        """The latest stamp the trial can have (its last possible tick)."""
        return self.stamp(self.n_max)


class TickSnapshot(NamedTuple):
    """One tick as the control thread handed it over (copies; d controlled DOFs, J joints).

    trial : its :class:`LiveTrial`.  k : the tick.  pose, velocity, wrench, reference : (d,)
    as the tick reports them.  prediction : (H_s, 2) the positions in use [m], or None (none
    in use, or the nominal plan's, which the publisher takes from ``trial.plan``).
    alpha : the controller's α now, or None.  fault : the tick's flags.  joints : (J,) the
    measured q [rad] (the last finite one after a glitch, as the log) and joint_command (J,)
    the commanded q̇ [rad/s], or None for a world without joints.
    """

    trial: LiveTrial
    k: int
    pose: np.ndarray
    velocity: np.ndarray
    wrench: np.ndarray
    reference: np.ndarray
    prediction: np.ndarray | None
    alpha: float | None
    fault: int
    joints: np.ndarray | None
    joint_command: np.ndarray | None


class LiveSink(Protocol):
    """Where the publishing thread sends the snapshots (the Foxglove server, a test's recorder)."""

    def publish(self, snapshot: TickSnapshot) -> None:
        """Send one tick (and, on a new trial, its scene); called on the publishing thread only."""
        ...

    def close(self) -> None:
        """Stop serving; called once, after the last :meth:`publish`."""
        ...


#: (policy, priority) of a thread: os.sched_getscheduler's policy, SCHED_RESET_ON_FORK removed.
Policy = tuple[int, int]


def _thread_policy() -> Policy | None:
    """The calling thread's scheduling policy and priority (Linux), or None where the OS has none."""
    try:
        policy = os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
        return policy, int(os.sched_getparam(0).sched_priority)
    except (AttributeError, OSError):
        return None


def _set_thread_policy(want: Policy) -> bool:
    """Give the calling thread ``want`` (not to processes it forks); whether the OS allowed it."""
    try:
        os.sched_setscheduler(0, want[0] | getattr(os, "SCHED_RESET_ON_FORK", 0), os.sched_param(want[1]))
        return True
    except (AttributeError, OSError):
        return False


def told_obstacles(episode: Any) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The boxes ``episode``'s intent source is told of, ((centre (2,), size (2,)), …) [m] in the plan's
    frame: those of the context :func:`~coassist.runtime.episode.build_episode` reset its tick with
    (``Episode.context.obstacles``: a lab's scene file's, the task's where the simulated operator goes round
    it, or none), read from there rather than decided again, so that the live view draws what the source was
    told on every world."""
    return tuple(
        (np.array(centre[:2], dtype=float), np.array(size[:2], dtype=float))
        for centre, size in episode.context.obstacles
    )


class LiveFeed:
    """The latest-value slot and its publishing thread (module docstring).

    sink : a :class:`LiveSink`.  rate_hz : how often the thread publishes, in (0, 100] [Hz].
    Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, sink: LiveSink, rate_hz: float = 30.0) -> None:
        self.rate_hz = check_real(rate_hz, "LiveFeed.rate_hz", 0.0, 100.0, open_lo=True)
        self.sink = sink
        #: Snapshots handed to the sink, and those that raised there (the run goes on).
        self.published = 0
        #: CPU seconds the publishing thread spent in the sink (what publishing costs).
        self.cpu_seconds = 0.0
        self.failures = 0
        self.last_error = ""
        #: The trial watched last (None before the first).
        self.current: LiveTrial | None = None
        self._latest: TickSnapshot | None = None  # the slot: written by the control thread only
        self._done: TickSnapshot | None = None  # the last one the sink returned from
        self._trials = 0
        self._last_end_ns = 0
        #: The publishing thread's scheduling (policy, priority) once it followed a watching thread's.
        self.policy: Policy | None = None
        self._want_policy: Policy | None = None  # the watching thread's
        self._tried_policy: Policy | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="coassist-live", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ the control side
    def watch(self, episode: Any, on_tick: OnTick | None = None, *, joint_names: Sequence[str] | None = None) -> OnTick:
        """Begin a trial of ``episode`` (a built :class:`~coassist.runtime.episode.Episode`) and return
        the ``on_tick`` to run it with: it stores the tick's snapshot, then calls ``on_tick`` (the
        caller's own monitor, if any). ``joint_names``: the arm's (default ``joint_1 …``).
        Records the trial's live start in the episode's meta fields (module docstring).
        Called before the run, on the thread that runs it."""
        trial = self._trial(episode, joint_names)
        episode.extra[LIVE_START] = trial.start_ns  # the trial file keeps it: its MCAP is stamped alike
        self._want_policy = _thread_policy()  # the publisher follows it (module docstring)
        tick = episode.tick
        alpha_of = alpha_reader(tick.controller)
        nj = int(episode.world.n_joints)
        horizon = trial.horizon
        held = [np.zeros(nj)]  # the joints of the last finite reading (a glitch repeats it, as the log)
        then = on_tick

        def on_tick_live(k: int, state: RobotState, out: Any) -> None:
            pred = out.prediction
            if pred is not None:
                # fewer rows than the log's H_s leave NaN there: the file has no path at that tick
                pred = pred.copy() if pred.shape[0] >= horizon else np.full((horizon, 2), np.nan)
            joints = command = None
            if nj:
                q = finite_vector(state.q, nj)
                if q is None:
                    q = held[0]
                else:
                    held[0] = q = np.array(q, dtype=float)
                joints = q
                qd = out.command.qd
                command = np.zeros(nj) if qd is None else np.array(qd, dtype=float)
            self._latest = TickSnapshot(
                trial,
                k,
                np.array(out.pose, dtype=float),
                np.array(out.velocity, dtype=float),
                np.array(out.wrench, dtype=float),
                np.array(out.reference, dtype=float),
                pred,
                None if alpha_of is None else alpha_of(),
                int(out.fault),
                joints,
                command,
            )
            if then is not None:
                then(k, state, out)

        return on_tick_live

    def _trial(self, episode: Any, joint_names: Sequence[str] | None) -> LiveTrial:
        tick, plan = episode.tick, np.asarray(episode.plan, dtype=float)
        frame = optional_member(episode.world, "base_frame")  # coassist ros2 --base-frame; the others' "base"
        frame = "base" if frame is None else frame
        if not isinstance(frame, str) or not frame:
            raise ValueError(f"the world's base_frame must be a frame name, got {frame!r}")
        dt = float(tick.dt)
        nj = int(episode.world.n_joints)
        names = tuple(joint_names) if joint_names is not None else tuple(f"joint_{i + 1}" for i in range(nj))
        if len(names) != nj:
            raise ValueError(f"joint_names: {nj} names needed, got {len(names)}")
        target = np.array(episode.context.target, dtype=float)  # where the run ends (the termination's ball)
        start_ns = max(time.time_ns(), self._last_end_ns)
        trial = LiveTrial(
            number=self._trials,
            start_ns=start_ns,
            dt=dt,
            n_max=int(episode.n_max),
            dofs=tuple(int(i) for i in tick.config.dofs),
            start_pose=np.array(episode.start_pose, dtype=float),
            horizon=int(tick.Hs),
            plan=plan if tick.intent.nominal else None,
            joint_names=names if nj else (),
            obstacles=told_obstacles(episode),
            path=np.asarray(episode.context.path, dtype=float),  # the source's (build_episode's)
            target=target,
            arrive_radius=float(episode.arrive_radius),
            frame_id=frame,
        )
        self._trials += 1
        self._last_end_ns = trial.end_ns
        self.current = trial
        return trial

    # ------------------------------------------------------------------ the publishing thread
    def _run(self) -> None:
        period = 1.0 / self.rate_hz
        due = time.monotonic()
        while True:
            stopping = self._stop.wait(max(0.0, due - time.monotonic()))
            due = max(due + period, time.monotonic())  # after a slow publish: no burst to catch up
            self._publish_latest()
            if stopping:
                return

    def _publish_latest(self) -> None:
        want = self._want_policy
        if want is not None and want != self._tried_policy:  # once per change (a refusal is not retried)
            self._tried_policy = want
            _set_thread_policy(want)
            self.policy = _thread_policy()
        snap = self._latest
        if snap is None or snap is self._done:
            return
        t0 = time.thread_time()
        try:
            self.sink.publish(snap)
            self.published += 1
        except Exception as exc:  # noqa: BLE001 - a viewer's failure must not reach the run
            self.failures += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
        self.cpu_seconds += time.thread_time() - t0
        self._done = snap

    def flush(self, timeout: float = 5.0) -> bool:
        """Wait until the newest snapshot has been published (at most ``timeout`` s); whether it was.
        Not for the control thread (a test's, or the command's, after the run)."""
        end = time.monotonic() + float(timeout)
        while self._done is not self._latest:
            if time.monotonic() > end or not self._thread.is_alive():
                return False
            time.sleep(0.002)
        return True

    def close(self, timeout: float = 5.0) -> None:
        """Publish the newest snapshot, stop the thread (waiting at most ``timeout`` s for a stalled
        sink; the thread is a daemon) and close the sink."""
        self._stop.set()
        self._thread.join(timeout)
        try:
            self.sink.close()
        except Exception as exc:  # noqa: BLE001 - closing a viewer never fails the command
            self.last_error = f"{type(exc).__name__}: {exc}"

    def __enter__(self) -> LiveFeed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
