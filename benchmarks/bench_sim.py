"""Speed of the simulated closed loop (coassist.sim), against a naive baseline in the same run.

Measures:

1. per-tick wall time (median, p99) of the loop — world + intent + controller + operator
   + plant + logging — with the cooperative controller and nominal intent, from the
   interval between consecutive controller calls;
2. the same for a naive loop whose controller solves the whole equilibrium every tick
   (``game.solve_horizon``: a Cholesky solve of the 2·Nc·n-variable system, what an MPC
   written straight from eq. 3.27–3.31 does) instead of applying precomputed
   first-step gains; the ratio is printed;
3. throughput in multiples of real time per core (simulated seconds per wall second,
   one process);
4. one dataset — 60 trials, 20 per trajectory, cooperative controller, nominal intent —
   with ``run_trials`` on ``--workers`` processes (target: ≤ 20 s on 2 cores).

Usage: ``.venv/bin/python benchmarks/bench_sim.py [--trials 60] [--workers 2]``
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from bench_common import machine_line
from coassist.control import AssistiveController
from coassist.control.presets import get_preset, make_controller
from coassist.scenario import AUTHOR, get_object, make_task
from coassist.sim import TrialSpec, run_trial, run_trials


class _Timed:
    """Wraps a controller and records the time of each call: consecutive calls bound one tick."""

    def __init__(self, inner):
        self.inner = inner
        self.name, self.model, self.horizon = inner.name, inner.model, inner.horizon
        self.stamps: list[float] = []
        self._clock = time.perf_counter

    def step(self, z, ref_h, ref_r, wrench):
        self.stamps.append(self._clock())
        return self.inner.step(z, ref_h, ref_r, wrench)


class FullSolveController(AssistiveController):
    """Naive baseline: the whole equilibrium solved every tick, only its first step applied."""

    def _law(self, z, ref_h, ref_r):
        U_h, U_r = self.game.solve_horizon(z, ref_h, ref_r)
        return U_h[0], U_r[0]


def tick_times(
    controller, task_kind: str, seed: int, time_limit: float | None = None
) -> tuple[np.ndarray, float, float]:
    """Per-tick wall times [s], the trial's simulated duration [s] and its wall time [s]."""
    timed = _Timed(controller)
    task = make_task(task_kind, np.random.default_rng(seed))
    t0 = time.perf_counter()
    trial = run_trial(task, AUTHOR, get_object("handle"), timed, None, seed, time_limit=time_limit)
    wall = time.perf_counter() - t0
    return np.diff(np.asarray(timed.stamps)), trial.duration, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=60, help="trials in the dataset run (split over 3 tasks)")
    parser.add_argument("--workers", type=int, default=2, help="processes for the dataset run")
    parser.add_argument("--tick-trials", type=int, default=6, help="trials timed tick by tick (per loop)")
    args = parser.parse_args()
    preset = get_preset("thesis-evaluation")
    print(machine_line())
    print(f"load average before: {os.getloadavg()[0]:.2f} (other processes on the machine inflate every number)")

    fast = make_controller("cooperative", preset)
    # warm-up (imports, caches)
    tick_times(fast, "linear", 0)
    ticks, sim_s, wall_s = [], 0.0, 0.0
    kinds = ("linear", "curved", "sinusoidal")
    for i in range(args.tick_trials):
        d, s, w = tick_times(fast, kinds[i % 3], 100 + i)
        ticks.append(d)
        sim_s += s
        wall_s += w
    ticks = np.concatenate(ticks)

    naive_ctrl = FullSolveController(fast.game, effort_limit=preset.effort_limit)
    naive = []
    for i in range(max(1, args.tick_trials // 3)):
        d, _, _ = tick_times(naive_ctrl, kinds[i % 3], 100 + i, time_limit=6.0)
        naive.append(d)
    naive = np.concatenate(naive)

    def us(x):
        return x * 1e6

    print()
    print(f"per-tick wall time over {ticks.size} ticks (cooperative, nominal intent, handle):")
    print(f"  coassist.sim loop  median {us(np.median(ticks)):7.1f} µs   p99 {us(np.percentile(ticks, 99)):7.1f} µs")
    print(
        f"  naive full solve   median {us(np.median(naive)):7.1f} µs   p99 {us(np.percentile(naive, 99)):7.1f} µs"
        f"   ({naive.size} ticks)"
    )
    print(f"  speed-up (median)  {np.median(naive) / np.median(ticks):.1f}x")
    dt = fast.model.dt
    print(f"  real-time budget   {dt * 1e6:.0f} µs per tick")
    print(
        f"throughput, one core: {sim_s / wall_s:.0f}x real time including trial set-up "
        f"({sim_s:.0f} s simulated in {wall_s:.2f} s); loop only {dt / np.median(ticks):.0f}x"
    )

    specs = [TrialSpec(task=kinds[i % 3], seed=i) for i in range(args.trials)]
    t0 = time.perf_counter()
    trials = run_trials(specs, workers=args.workers, progress=False)
    elapsed = time.perf_counter() - t0
    simulated = sum(t.duration for t in trials)
    print()
    print(
        f"dataset: {len(trials)} trials ({simulated:.0f} s simulated) on {args.workers} workers in {elapsed:.1f} s "
        f"(target <= 20 s for 60): {simulated / elapsed:.0f}x real time"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
