"""What the live Foxglove view costs a real-time control loop: its deadline misses with the view on and off.

    .venv/bin/python benchmarks/bench_live.py [--world mujoco|franka|ur] [--rate 500] [--seconds 8]
        [--rounds 2] [--controller cooperative] [--intent SOURCE] [--modes off,live,naive,encode]
        [--rt-priority 0]

``coassist drive``'s loop on a real-time world: the MuJoCo UR5 paced to the wall clock
(``--world mujoco``), or an FR3 in franky-sim (``--world franka``: the real franky client over
libfranka's protocol, the loop paced by the robot's 1 kHz clock; franky-sim in its own process,
tests/robot/franky_sim_server.py), or a UR5 behind ``coassist ur-sim`` (``--world ur``: the real
ur-rtde client over UR's RTDE protocol, the loop paced by ``initPeriod`` / ``waitPeriod``, the
simulator in its own process at SCHED_FIFO where allowed, its simulated operator at the
handle), at ``--rate`` (the e-Series' 500 Hz by default: 2 ms). A
Foxglove viewer (a WebSocket client speaking ``foxglove.sdk.v1`` in its own process, as the
Foxglove app is) subscribes to every topic. The modes run in rounds (off, live, naive, off, …)
so that a busy machine's drift hits them alike:

- ``off``: no live view;
- ``live``: coassist's (``--foxglove``): the tick stores a snapshot, a thread hands it to the
  server's worker process as raw bytes 30 times a second (the viewer receives only here);
- ``thread``: the design before it: a thread of the control process encodes every message of
  the newest tick 30 times a second (the server's Python work, no server);
- ``naive``: the same encoding on the control thread, on every tick whose time has come for the
  next 30 Hz frame (a common "publish from the callback" design).

Per mode: the loop's deadline misses (ticks flagged DEADLINE_MISS: the tick's own work over
the period, or, on franky-sim, the robot's clock overrunning), late periods (two ticks more
than 1.5 periods apart on the wall clock; on franky-sim the robot's clock paces, and it runs
slower than the wall's on a busy machine), the tick's own work (median, p99 [ms], the loop's
``compute``), the whole ``on_tick`` on the control thread (median, p99 [µs]; the naive
design's includes its publishing), the publishing thread's CPU per frame [ms] and its frames
per second. The ratio line compares the tick's p99 and the misses with ``off``'s.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import json  # noqa: E402
import multiprocessing  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

import coassist.runtime.episode as episode_module  # noqa: E402
from bench_common import machine_line  # noqa: E402
from coassist.data.tick_cdr import TickEncoder  # noqa: E402
from coassist.interfaces import Fault  # noqa: E402
from coassist.robot.drive import TASK_HEIGHT, DriveConfig, drive  # noqa: E402
from coassist.robot.worlds import WorldRequest, build_world  # noqa: E402
from coassist.runtime.foxglove import open_foxglove, scene_update, tick_rows  # noqa: E402
from coassist.runtime.live import LiveFeed  # noqa: E402
from coassist.runtime.loop import run_loop  # noqa: E402
from coassist.scenario.tasks import task_for_seed  # noqa: E402

RATE_HZ = 30.0


@contextlib.contextmanager
def priority(prio: int):  # type: ignore[no-untyped-def]
    """SCHED_FIFO ``prio`` for the calling thread while inside (not for processes it forks); yields whether granted."""
    granted = False
    if prio:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(prio))
            granted = True
        except (AttributeError, OSError):
            pass
    try:
        yield granted
    finally:
        if granted:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def _view(url: str, frames, ready) -> None:
    """The viewer's process: subscribe to every channel, count the data frames (a Foxglove app is
    another process too: its decoding must not share this interpreter's lock with the loop)."""
    with connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        channels: list[dict] = []
        while not channels:
            msg = json.loads(ws.recv(timeout=10))
            if msg.get("op") == "advertise":
                channels = msg["channels"]
        subs = [{"id": i + 1, "channelId": ch["id"]} for i, ch in enumerate(channels)]
        ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        ready.set()
        try:
            while True:
                if isinstance(ws.recv(), bytes):
                    with frames.get_lock():
                        frames.value += 1
        except Exception:  # noqa: BLE001 - closed by the parent
            return


class Viewer:
    """A Foxglove client in its own process, subscribed to every channel, counting data frames."""

    def __init__(self, url: str) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._frames = ctx.Value("q", 0)
        ready = ctx.Event()
        self._proc = ctx.Process(target=_view, args=(url, self._frames, ready), daemon=True)
        self._proc.start()
        if not ready.wait(30):
            raise RuntimeError("the viewer did not subscribe")

    @property
    def frames(self) -> int:
        return int(self._frames.value)

    def close(self) -> None:
        self._proc.terminate()
        self._proc.join(5)


class NaiveLive(LiveFeed):
    """The naive design: the snapshot and, when the next 30 Hz frame is due, its encoding, on the
    control thread (this feed's own thread does nothing)."""

    def _run(self) -> None:
        return

    def watch(self, episode, on_tick=None, *, joint_names=None):  # type: ignore[no-untyped-def]
        snapshot = super().watch(episode, None, joint_names=joint_names)
        due = [0.0]

        def on_tick_naive(k, state, out) -> None:
            snapshot(k, state, out)
            now = time.perf_counter()
            if now >= due[0]:
                due[0] = now + 1.0 / RATE_HZ
                self.sink.publish(self._latest)
                self.published += 1
            if on_tick is not None:
                on_tick(k, state, out)

        return on_tick_naive


class FrankySim:
    """franky-sim (libfranka's protocol, MuJoCo behind it) in its own process: tests/robot/franky_sim_server.py."""

    def __init__(self) -> None:
        script = Path(__file__).resolve().parents[1] / "tests" / "robot" / "franky_sim_server.py"
        env = dict(os.environ, OMP_NUM_THREADS="1")
        self.proc = subprocess.Popen(
            [sys.executable, str(script)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env
        )
        line = self.proc.stdout.readline().split()
        if line[:1] != ["HOST"]:
            self.proc.kill()
            raise RuntimeError(f"franky-sim did not start: {line}")
        self.host = line[1]

    def close(self) -> None:
        try:
            self.proc.stdin.write("quit\n")
            self.proc.stdin.flush()
            self.proc.wait(10)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()


class StillHand:
    """An F/T sensor at the hand reading no force (noise free, and saying so: franky-sim 1.0.4 estimates
    no external force, and the frozen-sensor check would stop a run on its constant zero)."""

    noise_force = noise_torque = 0.0

    def __init__(self) -> None:
        self.seq = 0

    def read(self):  # type: ignore[no-untyped-def]
        self.seq += 1
        return np.zeros(6), np.eye(3), self.seq


class URSim:
    """``coassist ur-sim`` (e-Series, 500 Hz; CB3 for ``--rate 125``) in its own process, on a loopback address of its own."""

    def __init__(self, rate: int) -> None:
        from coassist.robot.ur_sim import URSimConfig
        from coassist.robot.ur_sim.process import URSimProcess

        pid = os.getpid()
        self.host = f"127.{100 + pid % 100}.{(pid // 100) % 250 + 1}.7"
        series = "cb3" if rate == 125 else "e-series"
        self.proc = URSimProcess(URSimConfig(host=self.host, series=series, rt_priority=20))
        self.proc.start()

    def close(self) -> None:
        self.proc.stop()


def make_world(args, config: DriveConfig, sim):  # type: ignore[no-untyped-def]
    task = task_for_seed(config.task, config.seed)
    start = (float(task.start[0]), float(task.start[1]), TASK_HEIGHT)
    if args.world == "ur":  # as drive builds it on the simulator: at the task's start, its operator at the handle
        from coassist.robot.ur_sim_world import URSimWorld

        return URSimWorld(sim.host, start=start, frequency=float(config.rate_hz))
    if args.world == "franka":
        from coassist.robot.franka_world import FrankaWorld

        return FrankaWorld(sim.host, frequency=float(config.rate_hz), arm="fr3", ft_sensor=StillHand())
    return build_world("mujoco", WorldRequest("ur5", config.object, config.rate_hz, config.seed, start, realtime=True))


class EncodeOnly:
    """The Foxglove server's Python work (the scene on a new trial, every message of the tick encoded),
    without the server: what a publishing thread in the control process would hold its interpreter for."""

    def __init__(self) -> None:
        self._trial = None
        self._encoder = None

    def publish(self, snapshot) -> None:  # type: ignore[no-untyped-def]
        trial = snapshot.trial
        if trial is not self._trial:
            self._trial = trial
            self._encoder = TickEncoder(trial.frame_id, trial.joint_names, trial.dt_ns)
            scene_update(trial)
        for _ in self._encoder.messages(trial.stamp(snapshot.k), *tick_rows(snapshot)):
            pass

    def close(self) -> None:
        return


def one_run(mode: str, args, feeds: dict, viewer: Viewer, sim) -> dict:  # type: ignore[no-untyped-def]
    config = DriveConfig(
        world=args.world,
        robot="fr3" if args.world == "franka" else "ur5",
        controller=args.controller,
        intent=args.intent,
        task="linear",
        seed=1,
        rate_hz=args.rate,
        time_limit=args.seconds,
    )
    rt = priority(args.rt_priority)  # from the world's start: ur-rtde's receive threads inherit it
    granted = rt.__enter__()
    world = make_world(args, config, sim)
    starts: list[float] = []
    costs: list[float] = []
    logs: list = []
    feed = feeds.get(mode)
    frames0, published0 = viewer.frames, (feed.published if feed is not None else 0)
    cpu0 = feed.cpu_seconds if feed is not None else 0.0

    def stamp(k, state, out) -> None:  # the caller's monitor: when each tick's command went out
        starts.append(time.perf_counter())

    def timed_run_loop(world_, tick, n_max, termination=None, *, on_tick=None, **kw):  # type: ignore[no-untyped-def]
        def timed(k, state, out) -> None:  # the whole on_tick: the live view's part, then stamp (~1 us)
            t0 = time.perf_counter()
            on_tick(k, state, out)
            costs.append(time.perf_counter() - t0)

        log = run_loop(world_, tick, n_max, termination, on_tick=timed, **kw)
        logs.append(log)
        return log

    episode_module.run_loop = timed_run_loop  # Episode.run's loop, timed (the loop itself unchanged)
    try:
        trial = drive(config, world=world, on_tick=stamp, live=feed)
    finally:
        episode_module.run_loop = run_loop
        world.close()
        rt.__exit__(None, None, None)
    if feed is not None:
        feed.flush(2.0)
    time.sleep(0.2)
    dt = 1.0 / args.rate
    return {
        "ticks": trial.n_samples,
        "fifo": granted,
        "ended": f"{trial.meta.extra['ended']} {trial.meta.extra.get('stop_message', '')}",
        "misses": int(np.count_nonzero(trial.fault & int(Fault.DEADLINE_MISS))),
        "late": int(np.count_nonzero(np.diff(np.asarray(starts)) > 1.5 * dt)),
        "compute": logs[0].compute * 1e3,
        "costs_us": np.asarray(costs) * 1e6,
        "frames": viewer.frames - frames0,
        "published": (feed.published - published0) if feed is not None else 0,
        "publish_cpu": (feed.cpu_seconds - cpu0) if feed is not None else 0.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", choices=("mujoco", "franka", "ur"), default="mujoco")
    parser.add_argument("--rate", type=int, default=500)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--controller", default="cooperative")
    parser.add_argument(
        "--intent",
        default=None,
        help="the intent source (default: the simulated operator's true intent, oracle, in MuJoCo; the nominal plan "
        "on franka and ur, which drive refuses a simulation-only source on, as it would on an arm)",
    )
    parser.add_argument(
        "--rt-priority", type=int, default=0, help="SCHED_FIFO priority of the control loop (0: normal), as chrt -f"
    )
    parser.add_argument(
        "--modes", default="off,live,thread,naive", help="of off, live, thread, naive (in rounds, in this order)"
    )
    args = parser.parse_args()
    if args.intent is None:  # a simulation-only source is refused on the arm worlds (DriveConfig), as on an arm
        args.intent = "oracle" if args.world == "mujoco" else "nominal"
    print(machine_line())
    where = {
        "franka": "franky-sim FR3 (the robot's clock)",
        "ur": "coassist ur-sim UR5 (the real ur-rtde client)",
        "mujoco": "MuJoCo UR5 paced",
    }[args.world]
    print(
        f"{where} at {args.rate} Hz ({1e3 / args.rate:g} ms), {args.controller}, intent {args.intent}, "
        f"{args.seconds:g} s x {args.rounds} rounds per mode"
    )
    sim = FrankySim() if args.world == "franka" else URSim(args.rate) if args.world == "ur" else None
    feed, sink = open_foxglove(0, rate_hz=RATE_HZ)
    feeds = {"live": feed, "thread": LiveFeed(EncodeOnly(), RATE_HZ), "naive": NaiveLive(EncodeOnly(), RATE_HZ)}
    viewer = Viewer(sink.url)
    while not sink.watched("/current_pose"):
        time.sleep(0.01)
    modes = tuple(args.modes.split(","))
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    try:
        for r in range(args.rounds):
            for mode in modes:
                res = one_run(mode, args, feeds, viewer, sim)
                runs[mode].append(res)
                print(
                    f"  round {r + 1} {mode:5s}: {res['ticks']} ticks, {res['misses']} deadline misses, "
                    f"{res['late']} late periods, tick p99 {np.percentile(res['compute'], 99):.3f} ms, "
                    f"{res['frames']} frames received, loop {'SCHED_FIFO' if res['fifo'] else 'normal'}, "
                    f"ended {res['ended']}",
                    flush=True,
                )
    finally:
        viewer.close()
        for f in feeds.values():
            f.close()
        if sim is not None:
            sim.close()
    print(
        f"{'mode':6s} {'ticks':>6s} {'misses':>7s} {'late':>5s} {'tick med':>9s} {'tick p99':>9s}"
        f"  on_tick med/p99 [us]  publish CPU/frame [ms]  frames/s"
    )
    base_p99 = base_misses = None
    for mode in modes:
        rs = runs[mode]
        compute = np.concatenate([r["compute"] for r in rs])
        costs = np.concatenate([r["costs_us"] for r in rs])
        ticks, misses, late, published = (sum(r[key] for r in rs) for key in ("ticks", "misses", "late", "published"))
        cpu = sum(r["publish_cpu"] for r in rs)
        p99 = float(np.percentile(compute, 99))
        if mode == "off":
            base_p99, base_misses = p99, misses
        ratio = (
            f"  tick p99 x{p99 / base_p99:.2f} of off's, misses {misses} vs {base_misses}"
            if base_p99 and mode != "off"
            else ""
        )
        cost = f"{np.median(costs):7.1f} / {np.percentile(costs, 99):7.1f}"
        per_frame = f"{1e3 * cpu / published:8.3f}" if published and cpu else "       -"
        rate = published / (len(rs) * args.seconds)
        print(
            f"{mode:6s} {ticks:6d} {misses:7d} {late:5d} {np.median(compute):8.3f}  {p99:8.3f}  {cost}"
            f"  {per_frame}  {rate:6.1f}{ratio}",
            flush=True,
        )


if __name__ == "__main__":
    main()
