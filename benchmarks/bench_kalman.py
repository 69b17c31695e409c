"""Speed of the constant-acceleration Kalman baseline on one trial, against its naive form in the same run.

The filter's gains do not depend on the measurements, so :func:`coassist.intent.kalman.kalman_ca_filter`
computes the gain sequence once per (dt, parameters) and reuses it for every trial. The
naive form recomputes the covariance recursion with every trial (what the filter did
before, and what a textbook filter does): here, the same call with the memo emptied
before it. Both give the same states bit for bit (checked). Prints median and p99 per
trial and the ratio of the medians.

Usage: ``.venv/bin/python benchmarks/bench_kalman.py [--ticks 2000] [--repeats 30]``
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from coassist.intent import kalman
from coassist.intent.kalman import KalmanCA, kalman_ca_filter


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=2000, help="samples per trial (2000: a 16 s trial at 125 Hz)")
    parser.add_argument("--repeats", type=int, default=30, help="timed trials per form")
    args = parser.parse_args()
    if args.ticks < 2 or args.repeats < 1:
        parser.error("--ticks must be >= 2 and --repeats >= 1")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, python {platform.python_version()}")
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    rng = np.random.default_rng(0)
    pose = np.cumsum(rng.normal(size=(args.ticks, 2)), axis=0) * 1e-3
    vel = rng.normal(size=(args.ticks, 2)) * 1e-2
    params, dt = [KalmanCA(jerk_psd=10.0, velocity_noise=0.01)], 0.008
    naive, reused = [], []
    reference = kalman_ca_filter(pose, vel, dt, params)
    for _ in range(args.repeats):  # alternating, so a change in load falls on both
        kalman._GAIN_MEMO.clear()
        t0 = time.perf_counter()
        a = kalman_ca_filter(pose, vel, dt, params)
        naive.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        b = kalman_ca_filter(pose, vel, dt, params)
        reused.append(time.perf_counter() - t0)
        if not (np.array_equal(a, reference) and np.array_equal(b, reference)):
            raise SystemExit("the two forms disagree")
    n, r = np.array(naive) * 1e3, np.array(reused) * 1e3
    print(f"one {args.ticks}-tick trial, gains recomputed (naive): median {np.median(n):.2f} ms, p99 {np.percentile(n, 99):.2f} ms")
    print(f"one {args.ticks}-tick trial, gains reused:           median {np.median(r):.2f} ms, p99 {np.percentile(r, 99):.2f} ms")
    print(f"ratio of medians: {np.median(n) / np.median(r):.1f}x (same states bit for bit)")


if __name__ == "__main__":
    main()
