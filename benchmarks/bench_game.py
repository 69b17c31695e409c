"""Per-tick cost of the cooperative game controller, against a naive rebuild-every-tick baseline.

    .venv/bin/python benchmarks/bench_game.py [--ticks 20000] [--naive-ticks 30]

For 2 and 6 DOFs and horizons 5, 20, 50 it prints median and p99 of:
- ``solve``: the library's tick (precomputed gains, three matrix-vector products);
- naive: what the thesis group's ROS controller does every tick — build the
  prediction matrices and the equilibrium system, and solve it;
and the ratio. Then the gains for a new α (online assistance level, issue #11):
``set_alpha`` after ``prepare_alpha_changes`` against a fresh computation of the
gains (assemble, Cholesky, solve: what ``set_alpha`` did before), on the thesis'
weights and on random weights where the gains are not affine in α (there the online
path reads a Chebyshev series per stretch of α, and the exact eigen-sum it was fitted to
is timed too); every online gain is checked against the fresh one (max |difference| /
max |gain| ≤ 1e-9). Last, a controller per simulated trial (``make_controller`` of the
pipeline's presets): built from scratch each time (the naive baseline: what every
arbitrated trial and every MuJoCo drive paid before) against a copy of the game built
once per process (``cooperative_game``'s memo), gains checked bit for bit. And
``solve_batch`` for a lockstep group of 30 trials (numpy's stacked matmul, one gemv per
row in C) against the same products in a Python loop of ``np.dot``, rows bit for bit; and
a lockstep group's guarded steps (B = 18): the shared game's ``effort_batch`` and the
online-α ``arbitrated_effort_batch`` against ``step`` per row, efforts bit for bit.
Targets: 6-DOF Np = 50 tick p99 ≤ 20 µs and ≥ 1000× faster than naive (issue #2);
gains for a new α p99 ≤ 50 µs (issue #11). One BLAS thread, so the numbers
describe one core.
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

from coassist.control import CooperativeGame, GameWeights, prediction_matrices  # noqa: E402
from coassist.model import ImpedanceModel  # noqa: E402


def build_game(n: int, horizon: int, alpha: float = 0.8) -> CooperativeGame:
    model = ImpedanceModel(np.full(n, 10.0), np.full(n, 100.0), 0.0, 0.008)
    Q = np.diag([1.0] * n + [1e-4] * n)
    weights = GameWeights(Q_hh=Q, Q_hr=0.0, Q_rh=0.0, Q_rr=Q, R_h=np.full(n, 5e-4), R_r=np.full(n, 5e-4))
    return CooperativeGame(model, weights, alpha=alpha, horizon=horizon)


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
    parser.add_argument("--alpha-changes", type=int, default=5000, help="timed α changes per case (online gains)")
    parser.add_argument("--fresh-changes", type=int, default=40, help="timed fresh gain computations per case")
    parser.add_argument("--controllers", type=int, default=5, help="timed fresh controller builds per case")
    parser.add_argument("--batch-calls", type=int, default=2000, help="timed solve_batch calls per case (B = 30)")
    parser.add_argument("--json", type=str, default=None, help="also write the figures to this file")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    rows = []
    print(
        f"{'case':<14}{'solve med':>11}{'p99 [µs]':>10}{'naive med':>12}{'p99 [µs]':>11}{'ratio (med)':>13}{'ratio (p99)':>13}"
    )
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
            f_med, f_p99 = percentiles(fast)
            s_med, s_p99 = percentiles(slow)
            row = dict(
                n_dof=n,
                horizon=horizon,
                solve_median_us=f_med,
                solve_p99_us=f_p99,
                naive_median_us=s_med,
                naive_p99_us=s_p99,
                ratio_median=s_med / f_med,
                ratio_p99=s_p99 / f_p99,
            )
            rows.append(row)
            print(
                f"{n}-DOF Np={horizon:<5}{f_med:>11.2f}{f_p99:>10.2f}{s_med:>12.0f}{s_p99:>11.0f}{s_med / f_med:>13.0f}{s_p99 / f_p99:>13.0f}"
            )
    target = next(r for r in rows if r["n_dof"] == 6 and r["horizon"] == 50)
    print()
    print(
        f"6-DOF Np=50: tick p99 {target['solve_p99_us']:.1f} µs (target ≤ 20), "
        f"{target['ratio_median']:.0f}× faster than naive (target ≥ 1000)"
    )
    print()
    alpha_rows = []
    print(
        f"{'gains for a new α':<34}{'rank':>6}{'prep [s]':>10}{'online med':>12}{'p99 [µs]':>10}"
        f"{'eigen-sum med':>15}{'p99 [µs]':>10}{'fresh med':>11}{'p99 [µs]':>10}{'ratio (p99)':>13}{'max rel diff':>14}  series degrees"
    )
    for weights in ("thesis", "random"):
        for n, horizon in ((2, 50), (6, 50)):
            alpha_rows.append(bench_alpha(n, horizon, weights, args.alpha_changes, args.fresh_changes))
            r = alpha_rows[-1]
            print(
                f"{weights + f' {n}-DOF Np={horizon}':<34}{r['rank']:>6}{r['prepare_s']:>10.2f}{r['online_median_us']:>12.1f}"
                f"{r['online_p99_us']:>10.1f}{r['exact_sum_median_us']:>15.1f}{r['exact_sum_p99_us']:>10.1f}"
                f"{r['fresh_median_us']:>11.0f}{r['fresh_p99_us']:>10.0f}"
                f"{r['fresh_p99_us'] / r['online_p99_us']:>13.0f}{r['max_rel_diff']:>14.1e}  "
                f"{r['chebyshev_degrees'] or '-'}"
                + (f" ({r['exact_stretches']} exact)" if r["exact_stretches"] else "")
            )
    print()
    for weights in ("thesis", "random"):
        t = next(r for r in alpha_rows if r["weights"] == weights and r["n_dof"] == 6)
        print(
            f"6-DOF Np=50, {weights} weights: gains for a new α p99 {t['online_p99_us']:.1f} µs (target ≤ 50), "
            f"fresh {t['fresh_p99_us'] / 1e3:.1f} ms; agreement {t['max_rel_diff']:.1e} (target ≤ 1e-9)"
        )
    print()
    batch_rows = bench_batch(args.batch_calls)
    print()
    step_rows = bench_group_steps(args.batch_calls)
    print()
    controller_rows = bench_controllers(args.controllers)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {
                    "tick": rows,
                    "alpha": alpha_rows,
                    "batch": batch_rows,
                    "steps": step_rows,
                    "controller": controller_rows,
                },
                fh,
                indent=2,
            )


def loop_solve_batch(game: CooperativeGame, z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray):
    """The baseline: ``solve_batch``'s three products per row as ``np.dot`` in a Python loop (as before)."""
    g, n, B = game._state[0], game.model.n_dof, z.shape[0]
    rh, rr = ref_h.reshape(B, -1), ref_r.reshape(B, -1)
    u = np.empty((B, g.G_z.shape[0]))
    for b in range(B):
        ub = np.dot(g.G_z, z[b])
        ub += np.dot(g.G_h, rh[b])
        ub += np.dot(g.G_r, rr[b])
        u[b] = ub
    return u[:, :n], u[:, n:]


def bench_batch(calls: int, B: int = 30) -> list[dict]:
    """``solve_batch`` for a lockstep group of B trials (numpy's stacked matmul: one gemv per
    row in C) against :func:`loop_solve_batch`; the rows must agree bit for bit."""
    rng = np.random.default_rng(1)
    out = []
    print(
        f"{'solve_batch, B = ' + str(B):<22}{'stacked med':>12}{'p99 [µs]':>10}{'loop med':>10}{'p99 [µs]':>10}{'ratio (med)':>13}"
    )
    for n, horizon in ((2, 50), (6, 50)):
        game = build_game(n, horizon)
        args = (rng.normal(size=(B, 2 * n)), *rng.normal(size=(2, B, horizon, 2 * n)))
        for a, b in zip(game.solve_batch(*args), loop_solve_batch(game, *args)):
            if not np.array_equal(a, b):
                raise SystemExit(f"solve_batch and the per-row loop differ for n={n}, Np={horizon}")
        stacked = time_calls(game.solve_batch, args, calls)
        loop = time_calls(loop_solve_batch, (game, *args), calls)
        (s_med, s_p99), (l_med, l_p99) = stacked, loop
        out.append(
            dict(
                n_dof=n,
                horizon=horizon,
                batch=B,
                stacked_median_us=s_med,
                stacked_p99_us=s_p99,
                loop_median_us=l_med,
                loop_p99_us=l_p99,
            )
        )
        print(
            f"{f'{n}-DOF Np={horizon}':<22}{s_med:>12.1f}{s_p99:>10.1f}{l_med:>10.1f}{l_p99:>10.1f}{l_med / s_med:>13.1f}"
        )
    return out


def time_calls(fn, args: tuple, calls: int) -> tuple[float, float]:
    """Median and p99 [µs] of ``fn(*args)`` over ``calls`` calls, after 100 warm-up calls."""
    for _ in range(100):
        fn(*args)
    t = np.empty(calls, dtype=np.int64)
    for i in range(calls):
        t0 = time.perf_counter_ns()
        fn(*args)
        t[i] = time.perf_counter_ns() - t0
    return percentiles(t)


def bench_controllers(fresh_builds: int) -> list[dict]:
    """A controller per trial: built from scratch against a copy of the memoised game."""
    from coassist.config import APPLICATION_PRESET, COLLECTION_PRESET
    from coassist.control import game as game_module
    from coassist.control.presets import get_preset, make_controller

    def gains(c) -> np.ndarray:
        g = (c.controller if hasattr(c, "controller") else c).game.gains
        return np.hstack([g.G_z, g.G_h, g.G_r])

    print(
        f"{'a controller per trial':<48}{'fresh med':>10}{'p99 [ms]':>10}{'memo med':>10}{'p99 [ms]':>10}{'ratio (med)':>13}"
    )
    out = []
    for preset_name in (COLLECTION_PRESET, APPLICATION_PRESET):
        preset = get_preset(preset_name)
        for kind in ("cooperative", "cooperative-arbitrated"):
            fresh, memo = np.empty(fresh_builds, dtype=np.int64), np.empty(10 * fresh_builds, dtype=np.int64)
            for i in range(fresh_builds):
                game_module._GAME_MEMO.clear()
                t0 = time.perf_counter_ns()
                reference = make_controller(kind, preset)
                fresh[i] = time.perf_counter_ns() - t0
            for i in range(memo.shape[0]):
                t0 = time.perf_counter_ns()
                c = make_controller(kind, preset)
                memo[i] = time.perf_counter_ns() - t0
            if not np.array_equal(gains(c), gains(reference)):
                raise SystemExit(f"the memoised {kind} controller's gains differ from a fresh one ({preset_name})")
            (f_med, f_p99), (m_med, m_p99) = (
                (np.median(fresh) / 1e6, np.percentile(fresh, 99) / 1e6),
                (np.median(memo) / 1e6, np.percentile(memo, 99) / 1e6),
            )
            print(
                f"{kind + ' ' + preset_name:<48}{f_med:>10.1f}{f_p99:>10.1f}{m_med:>10.2f}{m_p99:>10.2f}{f_med / m_med:>13.0f}"
            )
            out.append(
                dict(
                    preset=preset_name,
                    kind=kind,
                    fresh_median_ms=f_med,
                    fresh_p99_ms=f_p99,
                    memo_median_ms=m_med,
                    memo_p99_ms=m_p99,
                )
            )
    return out


def bench_group_steps(calls: int, B: int = 18) -> list[dict]:
    """A lockstep group's guarded controller steps, as :mod:`coassist.sim.array_runner` takes them
    (B = 18, an application cell; the application preset): the shared game's ``step`` per
    row in a Python loop (the naive baseline) against ``effort_batch``; the online-α
    arbitration's ``step`` per run against ``arbitrated_effort_batch`` (each run its own α).
    And as :func:`coassist.runtime.batched_loops.run_loops` takes them (MuJoCo drives in lockstep):
    MG's ``step`` per row against ``step_batch``, the arbitration's against ``arbitrated_step_batch``.
    Efforts checked bit for bit against the loop first (twin controllers)."""
    from coassist.config import APPLICATION_PRESET
    from coassist.control.arbitration import arbitrated_effort_batch, arbitrated_step_batch
    from coassist.control.presets import get_preset, make_controller

    preset = get_preset(APPLICATION_PRESET)
    rng = np.random.default_rng(2)
    H = preset.game.horizon
    z = rng.normal(size=(B, 4)) * 0.02
    ref_h = rng.normal(size=(B, H, 4)) * 0.02
    ref_r = rng.normal(size=(B, H, 4)) * 0.02 + z[:, None, :]
    w = rng.normal(size=(B, 2)) * 3.0
    print(
        f"{'controller steps, B = ' + str(B):<30}{'batched med':>12}{'p99 [µs]':>10}{'loop med':>10}{'p99 [µs]':>10}{'ratio (med)':>13}"
    )
    out = []
    shared = make_controller("cooperative", preset)
    arbitrated = [make_controller("cooperative-arbitrated", preset) for _ in range(B)]
    twins = [make_controller("cooperative-arbitrated", preset) for _ in range(B)]
    u, clean = arbitrated_effort_batch(arbitrated, z, ref_h, ref_r, w)
    want = [c.step(*row) for c, row in zip(twins, zip(z, ref_h, ref_r, w))]
    u2, clean2 = shared.effort_batch(z, ref_h, ref_r, w)
    want2 = [shared.step(*row) for row in zip(z, ref_h, ref_r, w)]
    for got, ok, expected in ((u, clean, want), (u2, clean2, want2)):
        if not ok.all() or not all(np.array_equal(got[b], e.u_r) for b, e in enumerate(expected)):
            raise SystemExit("a batched controller step differs from the per-row step")
    stepped = [make_controller("cooperative-arbitrated", preset) for _ in range(B)]
    twins = [make_controller("cooperative-arbitrated", preset) for _ in range(B)]
    manual = make_controller("manual", preset)
    for got, expected in (
        (
            arbitrated_step_batch(stepped, z, ref_h, ref_r, w),
            [c.step(*row) for c, row in zip(twins, zip(z, ref_h, ref_r, w))],
        ),
        (manual.step_batch(z, ref_h, ref_r, w), [manual.step(*row) for row in zip(z, ref_h, ref_r, w)]),
    ):
        if not all(
            np.array_equal(g.u_r, e.u_r) and np.array_equal(g.u_h_model, e.u_h_model) and g.fault == e.fault
            for g, e in zip(got, expected)
        ):
            raise SystemExit("a batched controller step differs from the per-row step")

    def loop(controllers):
        for c, row in zip(controllers, zip(z, ref_h, ref_r, w)):
            c.step(*row)

    cases = (
        ("cooperative (shared game)", shared.effort_batch, (z, ref_h, ref_r, w), loop, ([shared] * B,)),
        ("cooperative-arbitrated", arbitrated_effort_batch, (arbitrated, z, ref_h, ref_r, w), loop, (arbitrated,)),
        ("manual (shared), steps", manual.step_batch, (z, ref_h, ref_r, w), loop, ([manual] * B,)),
        ("cooperative-arbitrated, steps", arbitrated_step_batch, (stepped, z, ref_h, ref_r, w), loop, (stepped,)),
    )
    for name, batched, b_args, naive, n_args in cases:
        (b_med, b_p99), (l_med, l_p99) = time_calls(batched, b_args, calls), time_calls(naive, n_args, calls)
        out.append(
            dict(
                controller=name,
                batch=B,
                batched_median_us=b_med,
                batched_p99_us=b_p99,
                loop_median_us=l_med,
                loop_p99_us=l_p99,
            )
        )
        print(f"{name:<30}{b_med:>12.1f}{b_p99:>10.1f}{l_med:>10.1f}{l_p99:>10.1f}{l_med / b_med:>13.1f}")
    return out


def random_weights_game(n: int, horizon: int, alpha: float) -> CooperativeGame:
    """A game whose Q_hh ≠ Q_rr: H(α) depends on α, the gains are rational in α (rank r > 0)."""
    rng = np.random.default_rng(n)
    model = ImpedanceModel(np.full(n, 10.0), np.full(n, 100.0), 0.0, 0.008)

    def psd(scale):
        a = rng.normal(size=(2 * n, 2 * n))
        return scale * a @ a.T / (2 * n)

    Q = {k: psd(s) for k, s in (("Q_hh", 1.0), ("Q_hr", 0.2), ("Q_rh", 0.2), ("Q_rr", 0.5))}
    weights = GameWeights(**Q, R_h=np.full(n, 5e-4), R_r=np.full(n, 1e-4))
    return CooperativeGame(model, weights, alpha=alpha, horizon=horizon)


def bench_alpha(n: int, horizon: int, weights: str, changes: int, fresh_changes: int) -> dict:
    """Online gains for random α ∈ [0.05, 0.95] against a fresh computation, and their agreement."""
    build = (
        (lambda a: build_game(n, horizon, a)) if weights == "thesis" else (lambda a: random_weights_game(n, horizon, a))
    )
    game = build(0.8)
    clock = time.perf_counter_ns
    t0 = clock()
    game.prepare_alpha_changes()
    prepare_s = (clock() - t0) / 1e9
    alphas = np.random.default_rng(1).uniform(0.05, 0.95, changes)
    for a in alphas[:200]:
        game.set_alpha(float(a))
    online = np.empty(changes, dtype=np.int64)
    for i, a in enumerate(alphas):
        t0 = clock()
        game.set_alpha(float(a))
        online[i] = clock() - t0
    # The fresh computation: a second game recomputing from scratch (assemble, factor, solve).
    fresh_game = build(0.8)
    fresh = np.empty(fresh_changes, dtype=np.int64)
    worst = 0.0
    for i, a in enumerate(alphas[:fresh_changes]):
        t0 = clock()
        fresh_game._compute_gains(float(a))
        fresh[i] = clock() - t0
        game.set_alpha(float(a))
        g_online = np.hstack([game.gains.G_z, game.gains.G_h, game.gains.G_r])
        g_fresh = np.hstack([fresh_game.gains.G_z, fresh_game.gains.G_h, fresh_game.gains.G_r])
        worst = max(worst, float(np.abs(g_online - g_fresh).max() / np.abs(g_fresh).max()))
    if worst > 1e-9:
        raise SystemExit(
            f"online gains disagree with the fresh computation ({worst:.1e}) for {weights} n={n} Np={horizon}"
        )
    family = game._alpha_family
    e_med = e_p99 = float("nan")  # rank 0: the online path is the exact (affine) formula itself
    if family.rank:
        exact = np.empty(min(changes, 1000), dtype=np.int64)  # the eigen-sum the series replaces
        for i, a in enumerate(alphas[: exact.shape[0]]):
            t0 = clock()
            family._exact(float(a))
            exact[i] = clock() - t0
        e_med, e_p99 = percentiles(exact)
    o_med, o_p99 = percentiles(online)
    f_med, f_p99 = percentiles(fresh)
    degrees = sorted({p[1].shape[0] - 1 for p in family.pieces if p is not None})
    return dict(
        weights=weights,
        n_dof=n,
        horizon=horizon,
        rank=family.rank,
        prepare_s=prepare_s,
        online_median_us=o_med,
        online_p99_us=o_p99,
        fresh_median_us=f_med,
        fresh_p99_us=f_p99,
        exact_sum_median_us=e_med,
        exact_sum_p99_us=e_p99,
        chebyshev_degrees=degrees,
        exact_stretches=sum(p is None for p in family.pieces),
        max_rel_diff=worst,
    )


if __name__ == "__main__":
    main()
