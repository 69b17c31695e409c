"""What URRTDEWorld's check before each speedJ costs: ``poll(2)`` on the control socket and ``isConnected()``.

    .venv/bin/python benchmarks/bench_ur_link_check.py [--calls 20000] [--rounds 5]

``coassist ur-sim`` (e-Series) in its own process; the real ur-rtde 1.6.5 interfaces connect to
it as :class:`~coassist.robot.ur_rtde_world.URRTDEWorld` does (receive, then control), the
control interface's socket to port 30004 is found the same way
(:func:`~coassist.robot.socket_watch.sockets_to`), and each check is timed ``--calls`` times in a
row, ``--rounds`` times: prints the median, smallest and largest per-call time [µs] over the
rounds, for ``SocketWatch.ended()``, ``isConnected()`` and the two together (the world's check).
The machine's load is printed first.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

from coassist.robot.socket_watch import SocketWatch, socket_fds, sockets_to
from coassist.robot.ur_sim import URSimConfig
from coassist.robot.ur_sim.process import URSimProcess


def per_call_us(f: Callable[[], object], calls: int, rounds: int) -> tuple[float, float, float]:
    """(median, min, max) over ``rounds`` of the mean time of one of ``calls`` calls in a row [µs]."""
    out = []
    for _ in range(rounds):
        t = time.perf_counter_ns()
        for _ in range(calls):
            f()
        out.append((time.perf_counter_ns() - t) / calls / 1e3)
    return statistics.median(out), min(out), max(out)


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

            for name, f in (
                ("SocketWatch.ended()", watch.ended),
                ("isConnected()", control.isConnected),
                ("both", both),
            ):
                med, lo, hi = per_call_us(f, args.calls, args.rounds)
                print(
                    f"{name:20s} median {med:.3f} µs  (min {lo:.3f}, max {hi:.3f}; {args.rounds} x {args.calls} calls)"
                )
            print(f"ended now: {watch.ended()}, isConnected: {control.isConnected()}")
        finally:
            control.stopScript()
            control.disconnect()
            receive.disconnect()


if __name__ == "__main__":
    main()
