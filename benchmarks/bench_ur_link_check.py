"""What URRTDEWorld's check before each speedJ costs: ``poll(2)`` on the control socket and ``isConnected()``.

    .venv/bin/python benchmarks/bench_ur_link_check.py [--calls 20000] [--rounds 5]

``coassist ur-sim`` (e-Series) in its own process; the real ur-rtde 1.6.5 interfaces connect to
it as :class:`~coassist.robot.ur_rtde_world.URRTDEWorld` does (receive, then control), the
control interface's socket to port 30004 is found the same way
(:func:`~coassist.robot.socket_watch.sockets_to`), and each check is timed ``--calls`` times in a
row, ``--rounds`` times, each call timed: prints the median and p99 per call [µs] of ``isConnected()``
alone (the check that was not enough: the baseline), ``SocketWatch.ended()`` and the two together (the
world's check), their medians' ratio to the baseline's, and the p99's share of a 2 ms (500 Hz) tick.
The machine's load is printed first.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import numpy as np

from coassist.robot.socket_watch import SocketWatch, socket_fds, sockets_to
from coassist.robot.ur_sim import URSimConfig
from coassist.robot.ur_sim.process import URSimProcess


def per_call_us(f: Callable[[], object], calls: int, rounds: int) -> np.ndarray:
    """Each call's time [µs], ``rounds`` × ``calls`` calls timed one by one (``perf_counter_ns`` around each: its
    own ~0.05 µs is in every figure, the baseline's too)."""
    out = np.empty(rounds * calls)
    clock = time.perf_counter_ns
    for k in range(rounds * calls):
        t = clock()
        f()
        out[k] = clock() - t
    return out / 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=20000)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    import rtde_control
    import rtde_receive

    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    pid = os.getpid()
    host = f"127.{100 + pid % 100}.{(pid // 100) % 250 + 1}.9"
    with URSimProcess(URSimConfig(host=host)):
        receive = rtde_receive.RTDEReceiveInterface(host, -1.0)
        before = socket_fds()
        control = rtde_control.RTDEControlInterface(host, 125.0)
        try:
            found = sockets_to(30004, before)
            if len(found) != 1:
                raise SystemExit(f"expected one new socket to port 30004, found {found}")
            watch = SocketWatch(found[0])

            def both() -> bool:
                return watch.ended() or not control.isConnected()

            times = {
                name: per_call_us(f, args.calls, args.rounds)
                for name, f in (
                    ("isConnected() alone", control.isConnected),
                    ("SocketWatch.ended()", watch.ended),
                    ("both (the world's)", both),
                )
            }
            base = float(np.median(times["isConnected() alone"]))
            print(f"{'per call':22s} median µs   p99 µs  median vs isConnected() alone  of a 2 ms tick")
            for name, t in times.items():
                med, p99 = float(np.median(t)), float(np.percentile(t, 99))
                print(f"{name:22s} {med:9.3f} {p99:8.3f} {med / base:10.2f}x {100 * p99 / 2000:19.3f}%")
            print(f"ended now: {watch.ended()}, isConnected: {control.isConnected()}")
        finally:
            control.stopScript()
            control.disconnect()
            receive.disconnect()


if __name__ == "__main__":
    main()
