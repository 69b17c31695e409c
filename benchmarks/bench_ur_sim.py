"""The UR simulator's 500 Hz output stream while coassist drives it, against a naive clock.

    .venv/bin/python benchmarks/bench_ur_sim.py [--seconds 10] [--rt-priority 20] [--client-rt-priority 10]

``coassist ur-sim`` (e-Series, 500 Hz) in its own process; coassist drives it through the real
ur-rtde client (``coassist drive --world ur``'s loop at 500 Hz, MG, a 10 N push) for
``--seconds``; the stream's period is the interval between the cycles that sent their packages
(the simulator's own clock, ``URSim.stream_periods``). Two simulators, one after the other:

- **ur-sim**: its clock (sleeps until ``spin`` before each period, spins the rest; a period the
  process missed runs its physics and skips its packages), with ``--rt-priority`` (SCHED_FIFO,
  where the system allows it);
- **naive**: the same simulator with a clock that only sleeps (``spin = 0``) at normal priority.

The driving loop runs at ``--client-rt-priority`` where allowed (0: normal priority). Prints the
median and p99 of the period [ms], its largest, the share of periods within 10 % of 2 ms, the
packages skipped, the loop's overruns (ticks flagged DEADLINE_MISS), and the ratio naive/ur-sim of
the p99's excess over 2 ms. The machine's load is printed first: on a shared machine the naive
clock's tail is the load's.

``--foxglove`` adds a third run, **ur-sim + foxglove**: the same as ur-sim with the live view on
(``--foxglove``'s server in its worker process, 30 Hz, a viewer in its own process subscribed to
every topic: the test suite's client, tests/runtime/foxglove_client.py); its overruns against ur-sim's are the
issue's "live Foxglove adds no tick over its period".
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from coassist.interfaces import Fault  # noqa: E402
from coassist.robot.drive import DriveConfig, drive  # noqa: E402
from coassist.robot.ur_rtde_world import URRTDEWorld  # noqa: E402
from coassist.robot.ur_sim import URSimConfig  # noqa: E402
from coassist.robot.ur_sim.process import URSimProcess  # noqa: E402

PERIOD = 0.002


@contextlib.contextmanager
def priority(prio: int):
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


#: The viewer, in a process of its own (in this one its reading thread, at normal priority, would hold the
#: interpreter lock the real-time loop needs: a priority inversion of the benchmark's, not of the live view):
#: the test suite's client (tests/runtime/foxglove_client.py) subscribed to every topic until stdin closes.
_VIEWER = """
import importlib.util, sys
spec = importlib.util.spec_from_file_location("client", sys.argv[1])
m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m)
c = m.FoxgloveClient(sys.argv[2])
c.subscribe([t for t in sys.argv[3:] if t in c.channels])
print("subscribed", flush=True)
sys.stdin.read()
print(len(c.messages), flush=True)
c.close()
"""


def _viewer(url: str, topics: list[str]) -> subprocess.Popen:
    client = Path(__file__).parents[1] / "tests" / "runtime" / "foxglove_client.py"
    proc = subprocess.Popen(
        [sys.executable, "-c", _VIEWER, str(client), url, *topics],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "subscribed"
    return proc


def run(
    name: str, config: URSimConfig, seconds: float, client_prio: int, foxglove: bool = False
) -> tuple[float, float] | None:
    live = client = None
    if foxglove:
        from coassist.data.trial_mcap import MCAP_TOPICS
        from coassist.runtime.foxglove import SCENE_TOPIC, open_foxglove

        live, sink = open_foxglove(0, rate_hz=30.0)
        client = _viewer(sink.url, [*MCAP_TOPICS, SCENE_TOPIC])
    try:
        return _run(name, config, seconds, client_prio, live)
    finally:
        if client is not None:
            received, _ = client.communicate(timeout=30)
            print(f"{'':8s}  the viewer (its own process) received {received.strip()} messages")
        if live is not None:
            live.close()


def _run(name: str, config: URSimConfig, seconds: float, client_prio: int, live) -> tuple[float, float] | None:
    with URSimProcess(config) as sim:
        try:
            world = URRTDEWorld(config.host, frequency=500.0)
        except ConnectionError as exc:  # a starved simulator: its clock alone, nobody driving
            time.sleep(seconds)
            print(f"{name:8s}: coassist could not connect ({str(exc)[:70]}…); its clock's periods instead:")
            return _report(name, sim.clock_periods(), sim.status(), "not run", False)
        start = [0]

        def on_tick(k, state, out):
            if k == 50:
                sim.push([10.0, 0.0, 0.0])
                start[0] = len(sim.stream_periods())  # from here on coassist drives the arm

        with priority(client_prio) as granted:
            try:
                trial = drive(
                    DriveConfig(world="ur", controller="manual", rate_hz=500, time_limit=seconds),
                    world=world,
                    on_tick=on_tick,
                    live=live,
                )
                ended = trial.meta.extra["ended"]
                if ended != "time_limit":
                    ended += f" at tick {trial.n_samples}: {trial.meta.extra['stop_message'][:90]}…"
                overruns = int(np.count_nonzero(trial.fault[3:] & int(Fault.DEADLINE_MISS)))
                ended += f"; {overruns} of {trial.n_samples} ticks flagged DEADLINE_MISS"
            except RuntimeError as exc:  # the run ended before its first tick (a starved simulator)
                ended = f"before its first tick ({str(exc)[:60]}…)"
        world.close()
        periods = sim.stream_periods()[start[0] :]
        status = sim.status()
    return _report(name, periods, status, ended, granted)


def _report(name: str, periods: np.ndarray, status: dict, ended: str, granted: bool) -> tuple[float, float] | None:
    if periods.size < 100:
        print(f"{name:8s}: too few periods ({periods.size})")
        return None
    ms = periods * 1e3
    within = float(np.mean(np.abs(periods - PERIOD) <= 0.1 * PERIOD))
    med, p99 = float(np.median(ms)), float(np.percentile(ms, 99))
    print(
        f"{name}: period median {med:.3f} ms  p99 {p99:.3f} ms  max {ms.max():.3f} ms  "
        f"within 10 % {within:.1%}  skipped {status['skipped']}  ({periods.size} periods; "
        f"loop ended {ended}, client priority {'SCHED_FIFO' if granted else 'normal'})"
    )
    return med, p99


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rt-priority", type=int, default=20)
    ap.add_argument("--client-rt-priority", type=int, default=10)
    ap.add_argument("--foxglove", action="store_true", help="a third run with the live Foxglove view on")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    pid = os.getpid()
    host = f"127.{100 + pid % 100}.{(pid // 100) % 250 + 1}"
    ours = run(
        "ur-sim",
        URSimConfig(host=f"{host}.1", rt_priority=args.rt_priority or None),
        args.seconds,
        args.client_rt_priority,
    )
    if args.foxglove:
        time.sleep(1.0)
        run(
            "ur-sim + foxglove",
            URSimConfig(host=f"{host}.3", rt_priority=args.rt_priority or None),
            args.seconds,
            args.client_rt_priority,
            foxglove=True,
        )
    time.sleep(1.0)
    naive = run("naive", URSimConfig(host=f"{host}.2", spin=0.0), args.seconds, args.client_rt_priority)
    if ours and naive:
        excess = (naive[1] - 2.0) / max(ours[1] - 2.0, 1e-3)
        print(f"ratio of the p99's excess over 2 ms, naive / ur-sim: {excess:.1f}")
        print(f"ur-sim p99 within 10 % of 2 ms: {'yes' if ours[1] <= 2.2 else 'no'} ({ours[1]:.3f} ms)")


if __name__ == "__main__":
    main()
