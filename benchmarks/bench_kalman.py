"""Speed of the constant-acceleration Kalman baseline on one trial, against its naive form in the same run.

The filter's gains do not depend on the measurements, so :func:`coassist.intent.kalman.kalman_ca_filter`
computes the gain sequence once per (dt, parameters) and reuses it for every trial. The
naive form recomputes the covariance recursion with every trial (what the filter did
before, and what a textbook filter does): here, the same call with the memo emptied
before it. Both give the same states bit for bit (checked). Prints median and p99 per
trial and the ratio of the medians.

Then the tuning of (q, r_v) on validation trials (:func:`~coassist.intent.kalman.tune_kalman`,
the 15 × 7 grid, 0.4 s horizon) over ``--tune-trials`` trials, three ways in the same run:
the naive direct sum (every grid point's H-step extrapolation formed and compared with the
future poses); the quadratic form in the filtered state, trial by trial on
:func:`~coassist.intent.kalman.kalman_ca_filter`'s states (what tune_kalman did before
2026-11-28); and the library's, every trial and grid point filtered at once as arrays with
the quadratic form summed tick by tick. The validation errors are checked equal to 1e-9
relative.

Usage: ``.venv/bin/python benchmarks/bench_kalman.py [--ticks 2000] [--repeats 30] [--tune-trials 6]``
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from bench_common import machine_line
from coassist.intent import kalman
from coassist.intent.kalman import KalmanCA, kalman_ca_filter


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=2000, help="samples per trial (2000: a 16 s trial at 125 Hz)")
    parser.add_argument("--repeats", type=int, default=30, help="timed trials per form")
    parser.add_argument(
        "--tune-trials", type=int, default=6, help="validation trials of the tuning comparison (0: skip)"
    )
    args = parser.parse_args()
    if args.ticks < 2 or args.repeats < 1:
        parser.error("--ticks must be >= 2 and --repeats >= 1")
    print(machine_line())
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
    print(
        f"one {args.ticks}-tick trial, gains recomputed (naive): median {np.median(n):.2f} ms, p99 {np.percentile(n, 99):.2f} ms"
    )
    print(
        f"one {args.ticks}-tick trial, gains reused:           median {np.median(r):.2f} ms, p99 {np.percentile(r, 99):.2f} ms"
    )
    print(f"ratio of medians: {np.median(n) / np.median(r):.1f}x (same states bit for bit)")
    if args.tune_trials:
        bench_tuning(rng, args.ticks, args.tune_trials, max(3, args.repeats // 10))


def naive_tuning_mse(trials, horizon: int, dt: float, grid) -> np.ndarray:
    """The validation MSE per grid point as a direct sum over the horizon (the naive baseline)."""
    sse, n = np.zeros(len(grid)), 0
    for pose, vel in trials:
        ks = np.arange(0, pose.shape[0] - horizon)
        states = kalman_ca_filter(pose, vel, dt, grid)[:, ks]
        future = pose[ks[:, None] + np.arange(1, horizon + 1)[None, :]]
        for gi in range(len(grid)):
            e = kalman.constant_acceleration(states[gi], horizon, dt) - future
            sse[gi] += float(np.sum(e * e)) / horizon
        n += ks.size
    return sse / n


def per_trial_quadratic_mse(trials, horizon: int, dt: float, grid) -> np.ndarray:
    """The validation MSE per grid point as the quadratic form δ'Aδ − 2δ'b + c in each trial's
    filtered states (kalman_ca_filter per trial: two stacked products of G small matrices a tick)."""
    tau = dt * np.arange(1, horizon + 1)
    phi = np.stack([np.ones_like(tau), tau, 0.5 * tau**2], axis=1)
    A = phi.T @ phi
    sse, n = np.zeros(len(grid)), 0
    for pose, vel in trials:
        ks = np.arange(0, pose.shape[0] - horizon)
        states = kalman_ca_filter(pose, vel, dt, grid)[:, ks]  # (G, K, 3, d)
        ahead = pose[ks[:, None] + np.arange(1, horizon + 1)[None, :]] - pose[ks][:, None]
        k, d = ahead.shape[0], ahead.shape[2]
        b = (phi.T @ ahead.transpose(1, 0, 2).reshape(horizon, k * d)).reshape(3, 1, k * d)
        delta = states.transpose(2, 0, 1, 3).reshape(3, len(grid), k * d)
        delta[0] -= pose[ks].reshape(-1)
        a_delta = (A @ delta.reshape(3, -1)).reshape(delta.shape)
        sse += (np.sum(delta * (a_delta - 2.0 * b), axis=(0, 2)) + float(np.sum(ahead * ahead))) / horizon
        n += ks.size
    return sse / n


def bench_tuning(rng: np.random.Generator, ticks: int, n_trials: int, repeats: int) -> None:
    from types import SimpleNamespace

    horizon, dt = 50, 0.008
    raw = [
        (np.cumsum(rng.normal(size=(ticks, 2)), axis=0) * 1e-3, rng.normal(size=(ticks, 2)) * 1e-2)
        for _ in range(n_trials)
    ]
    trials = [SimpleNamespace(pose=p, velocity=v) for p, v in raw]
    grid = [KalmanCA(q, rv, 1e-4, tuned=True) for q in kalman.JERK_PSD_GRID for rv in kalman.VELOCITY_NOISE_GRID]
    naive, per_trial, fast = [], [], []
    for _ in range(repeats):  # alternating; the gain memo is warm for all three
        t0 = time.perf_counter()
        want = naive_tuning_mse(raw, horizon, dt, grid)
        naive.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        before = per_trial_quadratic_mse(raw, horizon, dt, grid)
        per_trial.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        _, record = kalman.tune_kalman(trials, horizon, dt)
        fast.append(time.perf_counter() - t0)
        got = np.array(record["validation_mse"]).ravel()
        if max(np.max(np.abs(got - want) / want), np.max(np.abs(before - want) / want)) > 1e-9:
            raise SystemExit("the tuning's validation errors disagree with the direct sum")
    n, p, f = np.array(naive), np.array(per_trial), np.array(fast)
    print(f"Kalman tuning, {len(grid)} grid points, {n_trials} trials of {ticks} ticks, horizon {horizon}:")
    print(f"  direct sum (naive):             median {np.median(n):.2f} s, p99 {np.percentile(n, 99):.2f} s")
    print(f"  quadratic form, trial by trial: median {np.median(p):.2f} s, p99 {np.percentile(p, 99):.2f} s")
    print(f"  quadratic form, all at once:    median {np.median(f):.2f} s, p99 {np.percentile(f, 99):.2f} s")
    print(
        f"  ratio of medians: {np.median(n) / np.median(f):.1f}x against the direct sum, "
        f"{np.median(p) / np.median(f):.1f}x against trial by trial (validation errors equal to 1e-9)"
    )


if __name__ == "__main__":
    main()
