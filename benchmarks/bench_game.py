"""Per-tick cost of the cooperative game controller, against a naive rebuild-every-tick baseline.

    .venv/bin/python benchmarks/bench_game.py [--ticks 20000] [--naive-ticks 30]

For 2 and 6 DOFs and horizons 5, 20, 50 it prints median and p99 of:
- ``solve``: the library's tick (precomputed gains, three matrix-vector products);
- naive: what the thesis group's ROS controller does every tick — build the
  prediction matrices and the equilibrium system, and solve it;
and the ratio, plus the time to recompute the gains after an α change.
Targets (issue #2): 6-DOF Np = 50 tick p99 ≤ 20 µs and ≥ 1000× faster than naive;
gain recompute ≤ 20 ms. One BLAS thread, so the numbers describe one core.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from coassist.control import CooperativeGame, prediction_matrices  # noqa: E402
from coassist.model import ImpedanceModel  # noqa: E402


def build_game(n: int, horizon: int, alpha: float = 0.8) -> CooperativeGame:
    model = ImpedanceModel(np.full(n, 10.0), np.full(n, 100.0), 0.0, 0.008)
    Q = np.diag([1.0] * n + [1e-4] * n)
    return CooperativeGame(model, Q_hh=Q, Q_hr=0.0, Q_rh=0.0, Q_rr=Q, R_h=np.full(n, 5e-4), R_r=np.full(n, 5e-4), alpha=alpha, horizon=horizon)


def naive_tick(game: CooperativeGame, z, ref_h, ref_r) -> tuple[np.ndarray, np.ndarray]:
    """Rebuild everything and solve the full equilibrium system (eq. 3.27–3.31) for one tick."""
    model, n, a = game.model, game.n_dof, game.alpha
    Np = game.horizon
    F, Phi = prediction_matrices(model.Ad, model.Bd, model.C, Np)
    W_h = np.kron(np.eye(Np), a * game.Q["Q_hh"] + (1 - a) * game.Q["Q_rh"])
    W_r = np.kron(np.eye(Np), a * game.Q["Q_hr"] + (1 - a) * game.Q["Q_rr"])
    S = W_h + W_r
    P = Phi.T @ S @ Phi
    H = np.block([[P + np.kron(np.eye(Np), game.R_h), P], [P, P + np.kron(np.eye(Np), game.R_r)]])
    g = Phi.T @ (W_h @ ref_h.reshape(-1) + W_r @ ref_r.reshape(-1) - S @ F @ z)
    U = np.linalg.solve(H, np.concatenate([g, g]))
    N = n * Np
    return U[:n], U[N : N + n]


def percentiles(samples_ns) -> tuple[float, float]:
    s = np.asarray(samples_ns, dtype=float) / 1e3
    return float(np.median(s)), float(np.percentile(s, 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ticks", type=int, default=20000, help="timed calls of solve per case")
    parser.add_argument("--naive-ticks", type=int, default=30, help="timed calls of the naive baseline per case")
    parser.add_argument("--json", type=str, default=None, help="also write the figures to this file")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    rows = []
    print(f"{'case':<14}{'solve med':>11}{'p99 [µs]':>10}{'naive med':>12}{'p99 [µs]':>11}{'ratio (med)':>13}{'ratio (p99)':>13}")
    for n in (2, 6):
        for horizon in (5, 20, 50):
            game = build_game(n, horizon)
            z = rng.normal(size=2 * n)
            ref_h = rng.normal(size=(horizon, 2 * n))
            ref_r = rng.normal(size=(horizon, 2 * n))
            u_fast = game.solve(z, ref_h, ref_r)
            u_naive = naive_tick(game, z, ref_h, ref_r)
            if not np.allclose(np.concatenate(u_fast), np.concatenate(u_naive), rtol=1e-6, atol=1e-8):
                raise SystemExit(f"solve and the naive baseline disagree for n={n}, Np={horizon}")
            for _ in range(1000):
                game.solve(z, ref_h, ref_r)
            fast = np.empty(args.ticks, dtype=np.int64)
            clock = time.perf_counter_ns
            for i in range(args.ticks):
                t0 = clock()
                game.solve(z, ref_h, ref_r)
                fast[i] = clock() - t0
            slow = np.empty(args.naive_ticks, dtype=np.int64)
            for i in range(args.naive_ticks):
                t0 = clock()
                naive_tick(game, z, ref_h, ref_r)
                slow[i] = clock() - t0
            recompute = []
            for alpha in np.linspace(0.2, 0.9, 15):
                t0 = clock()
                game.set_alpha(float(alpha))
                recompute.append(clock() - t0)
            f_med, f_p99 = percentiles(fast)
            s_med, s_p99 = percentiles(slow)
            r_med, r_p99 = percentiles(recompute)
            row = dict(n_dof=n, horizon=horizon, solve_median_us=f_med, solve_p99_us=f_p99, naive_median_us=s_med,
                       naive_p99_us=s_p99, ratio_median=s_med / f_med, ratio_p99=s_p99 / f_p99,
                       alpha_recompute_median_ms=r_med / 1e3, alpha_recompute_p99_ms=r_p99 / 1e3)
            rows.append(row)
            print(f"{n}-DOF Np={horizon:<5}{f_med:>11.2f}{f_p99:>10.2f}{s_med:>12.0f}{s_p99:>11.0f}{s_med / f_med:>13.0f}{s_p99 / f_p99:>13.0f}")
    print()
    print(f"{'case':<14}{'α change: gain recompute median':>34}{'p99 [ms]':>10}")
    for row in rows:
        print(f"{row['n_dof']}-DOF Np={row['horizon']:<5}{row['alpha_recompute_median_ms']:>34.2f}{row['alpha_recompute_p99_ms']:>10.2f}")
    target = next(r for r in rows if r["n_dof"] == 6 and r["horizon"] == 50)
    print()
    print(f"6-DOF Np=50: tick p99 {target['solve_p99_us']:.1f} µs (target ≤ 20), "
          f"{target['ratio_median']:.0f}× faster than naive (target ≥ 1000), "
          f"gain recompute p99 {target['alpha_recompute_p99_ms']:.1f} ms (target ≤ 20)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
