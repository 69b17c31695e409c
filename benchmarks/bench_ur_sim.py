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
packages skipped, and the ratio naive/ur-sim of the p99's excess over 2 ms. The machine's load
is printed first: on a shared machine the naive clock's tail is the load's.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

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


def run(name: str, config: URSimConfig, seconds: float, client_prio: int) -> tuple[float, float] | None:
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
                )
                ended = trial.meta.extra["ended"]
                if ended != "time_limit":
                    ended += f" at tick {trial.n_samples}: {trial.meta.extra['stop_message'][:90]}…"
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
        f"{name:8s}: period median {med:.3f} ms  p99 {p99:.3f} ms  max {ms.max():.3f} ms  "
        f"within 10 % {within:.1%}  skipped {status['skipped']}  ({periods.size} periods; "
        f"loop ended {ended}, client priority {'SCHED_FIFO' if granted else 'normal'})"
    )
    return med, p99


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rt-priority", type=int, default=20)
    ap.add_argument("--client-rt-priority", type=int, default=10)
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
    time.sleep(1.0)
    naive = run("naive", URSimConfig(host=f"{host}.2", spin=0.0), args.seconds, args.client_rt_priority)
    if ours and naive:
        excess = (naive[1] - 2.0) / max(ours[1] - 2.0, 1e-3)
        print(f"ratio of the p99's excess over 2 ms, naive / ur-sim: {excess:.1f}")
        print(f"ur-sim p99 within 10 % of 2 ms: {'yes' if ours[1] <= 2.2 else 'no'} ({ours[1]:.3f} ms)")


if __name__ == "__main__":
    main()
