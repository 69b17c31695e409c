"""Speed of collecting one dataset with a model in the loop: lockstep against the per-trial path, in one run.

Measures:

1. the network's work per simulated tick for a group of B trials (median, p99 over
   ticks): one batched ``predict_batch`` call (lockstep) on ONNX Runtime (the default
   where the onnx extra is installed, ``coassist.intent.onnx_network``) and on torch,
   against B batch-1 torch calls (the per-trial path, ``ModelIntent.predict``), on real
   feature windows;
2. one 60-trial dataset — the iterative stage's: the tasks of
   ``coassist.experiments.pipeline.ITERATION_TASKS`` × 20 trials, cooperative controller,
   preset thesis-evaluation-dm — with the model in the loop, ``run_trials(...,
   lockstep=False)`` (every trial alone, one network call per trial and tick) against
   the default lockstep path (one batched call per tick per worker; and the network on
   torch instead of ONNX Runtime, on the kept pool), on ``--workers``
   processes started for the call (as ``coassist collect`` does) and on a kept pool
   (as ``coassist reproduce`` does: its ~40 collections share one pool, so a collection
   does not pay the workers' start, ~3 s of importing numpy, scipy and torch); wall time
   median and p99 over ``--repeats`` (the per-trial path once unless
   ``--baseline-repeats``), and the ratio (target: ≤ 10 s on 2 cores);
3. the same dataset with the nominal intent (no network), per trial and in lockstep
   groups (bit for bit the same trials);
4. per tick: one worker's lockstep group (every ``--workers``-th trial of the dataset),
   with the model and with the nominal intent, run in this process (one torch thread, as
   a worker), ``--repeats`` times: ``run_loops`` over the per-trial objects and as arrays
   (:mod:`coassist.sim.array_runner`, the default; the same trials bit for bit), with the
   model's network on torch and on ONNX Runtime (``TrialSpec.network``):
   wall and CPU seconds (CPU time is less inflated by other processes on a shared
   machine), the number of lockstep ticks and trial-ticks, µs per trial-tick and ms per
   lockstep tick, and the ratio;
5. ``sweep``: one network call at batch 1, 9, 18, 30 and 60 (random windows, one thread),
   torch eager against ONNX Runtime, median and p99 of ``--calls`` calls, and each
   backend's largest difference between a batch's rows and the same windows one at a time
   (0: batch-invariant, what makes lockstep bit for bit);
6. ``cells``: one of the main job's application cells (the board, its trials: 24 with the
   default's three users and eight trials each; the application preset; MG, the nominal intent,
   and with ``--cell-model`` the model in the loop, plain and arbitrated) in this process, as
   two lockstep groups of half the trials each (one per worker, the rule for a lone
   collection) against one group of all of them (``cell_options``' ``groups``), CPU seconds,
   the lower of ``--repeats`` runs each.

``--only network,groups,datasets,sweep,cells`` runs some of them (default: all; the
numbers above are the sections' order: network = 1, datasets = 2 and 3, groups = 4).

The model: ``--model PATH``, or an ``lstm``-preset model trained here for one epoch on
six nominal trials (its accuracy does not matter; its size does: LSTM 2 × 64, the
default and lstm presets' network).

Usage: ``.venv/bin/python benchmarks/bench_collect.py [--workers 2] [--repeats 3] [--baseline-repeats 1] [--model PATH]``
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from bench_common import machine_line


def train_small_model(folder: Path) -> str:
    from coassist.intent import LabeledTrial
    from coassist.intent.presets import MODEL_PRESETS
    from coassist.intent.training import train_model, write_model
    from coassist.sim.trial_runner import TrialSpec, run_spec

    specs = [
        TrialSpec(task=t, seed=s, user=s % 3, preset="thesis-evaluation-dm")
        for t in ("linear", "curved", "sinusoidal")
        for s in (900, 901)
    ]
    labeled = [LabeledTrial(f"B0/trial_{i:02d}", "B0", run_spec(spec)) for i, spec in enumerate(specs)]
    preset = MODEL_PRESETS.lookup("lstm")
    write_model(train_model(labeled, preset, replace(preset.train, epochs=1, threads=1)), folder)
    return str(folder)


def network_ticks(model_path: str, batch: int, ticks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-tick seconds of the network work for ``batch`` trials: batched on ONNX Runtime,
    batched on torch, and one torch call per trial."""
    import torch

    from coassist.intent import load_model_intent
    from coassist.sim.trial_runner import TrialSpec, run_spec

    torch.set_num_threads(1)
    source = load_model_intent(model_path, backend="torch")
    onnx = load_model_intent(model_path, backend="onnx")
    trial = run_spec(TrialSpec(task="curved", seed=7, preset="thesis-evaluation-dm"))
    rows = np.column_stack([trial.pose, trial.velocity, trial.wrench, trial.reference])
    L = source.history
    starts = np.linspace(0, rows.shape[0] - L - batch - ticks - 1, batch).astype(int)
    on_onnx, batched, alone = [], [], []
    for k in range(ticks):
        windows = np.stack([rows[s + k : s + k + L] for s in starts])
        t0 = time.perf_counter()
        onnx.batcher.predict_batch(windows)
        t1 = time.perf_counter()
        source.batcher.predict_batch(windows)
        t2 = time.perf_counter()
        for w in windows:
            source.predict(w)
        t3 = time.perf_counter()
        on_onnx.append(t1 - t0)
        batched.append(t2 - t1)
        alone.append(t3 - t2)
    return np.asarray(on_onnx), np.asarray(batched), np.asarray(alone)


def dataset_seconds(specs, workers: int, lockstep: bool, repeats: int, kept_pool: bool = False) -> np.ndarray:
    """Wall seconds of ``run_trials(specs)``, ``repeats`` times: on processes started for each
    call, or (``kept_pool``) on one pool started and warmed (a small run) before the timing."""
    import contextlib

    from coassist.sim.pool import worker_pool
    from coassist.sim.trial_runner import run_trials

    out = []
    with worker_pool(workers) if kept_pool else contextlib.nullcontext() as pool:
        if pool is not None:
            run_trials(specs[: 2 * workers], workers=workers, progress=False, lockstep=lockstep, pool=pool)
        for _ in range(repeats):
            t0 = time.perf_counter()
            run_trials(specs, workers=workers, progress=False, lockstep=lockstep, pool=pool)
            out.append(time.perf_counter() - t0)
    return np.asarray(out)


def sweep_calls(
    model_path: str, batches: Sequence[int], calls: int
) -> list[tuple[int, np.ndarray, np.ndarray, float, float]]:
    """Seconds of one network call per batch size: (B, torch, ONNX Runtime, and each one's
    largest |row in the batch − the window alone|), ``calls`` each, on the same random
    scaled windows, one thread."""
    import torch

    from coassist.intent.model import load_model
    from coassist.intent.onnx_network import OnnxNetwork

    torch.set_num_threads(1)
    model = load_model(model_path)
    net = model.net.eval()
    onnx = OnnxNetwork(net, model.window.steps)
    rng = np.random.default_rng(0)
    out = []
    for B in batches:
        x = rng.uniform(-1.0, 1.0, size=(B, model.window.steps, net.config.n_features)).astype(np.float32)
        xt = torch.from_numpy(x)
        times: dict[str, list[float]] = {"torch": [], "onnx": []}
        with torch.inference_mode():
            for _ in range(10):  # warm both
                net(xt), onnx(x)
            for _ in range(calls):
                t0 = time.perf_counter()
                net(xt)
                t1 = time.perf_counter()
                onnx(x)
                t2 = time.perf_counter()
                times["torch"].append(t1 - t0)
                times["onnx"].append(t2 - t1)
            alone_torch = np.concatenate([net(xt[b : b + 1]).numpy() for b in range(B)])
            alone_onnx = np.concatenate([onnx(x[b : b + 1]) for b in range(B)])
            d_torch = float(np.abs(net(xt).numpy() - alone_torch).max())
            d_onnx = float(np.abs(onnx(x) - alone_onnx).max())
        out.append((B, np.asarray(times["torch"]), np.asarray(times["onnx"]), d_torch, d_onnx))
    return out


def cell_cpu_seconds(specs, repeats: int) -> tuple[float, float]:
    """CPU seconds of an application cell's trials in this process, the lower of ``repeats``
    runs: as two lockstep groups (every other trial, :func:`submit_trials`' rule for two
    workers) and as one group."""
    import torch

    from coassist.sim.trial_runner import run_spec_lockstep

    torch.set_num_threads(1)
    run_spec_lockstep(specs[:1])  # warm: imports, the game's gains, the model's first call
    two, one = [], []
    for _ in range(repeats):
        c0 = time.process_time()
        for group in (specs[0::2], specs[1::2]):
            run_spec_lockstep(group)
        c1 = time.process_time()
        run_spec_lockstep(specs)
        c2 = time.process_time()
        two.append(c1 - c0)
        one.append(c2 - c1)
    return min(two), min(one)


def group_seconds(specs, repeats: int, arrays: bool = True) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Wall and CPU seconds of running ``specs`` in lockstep in this process (``arrays``: as
    arrays, coassist.sim.array_runner; else run_loops over the per-trial objects); lockstep ticks, trial-ticks."""
    import torch

    from coassist.sim.trial_runner import run_spec_lockstep

    torch.set_num_threads(1)
    run_spec_lockstep(specs[:2], arrays=arrays)  # warm: imports, the game's gains, the model's first call
    wall, cpu = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        trials = run_spec_lockstep(specs, arrays=arrays)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    lengths = [t.n_samples for t in trials]
    return np.asarray(wall), np.asarray(cpu), max(lengths), sum(lengths)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="processes for the dataset runs")
    parser.add_argument("--repeats", type=int, default=3, help="runs of the lockstep and nominal datasets")
    parser.add_argument(
        "--baseline-repeats", type=int, default=1, help="runs of the per-trial dataset (~1 min each; 0: skip)"
    )
    parser.add_argument("--trials", type=int, default=20, help="trials per task")
    parser.add_argument("--model", default=None, help="a model folder (default: train a small lstm-preset one)")
    parser.add_argument("--ticks", type=int, default=300, help="ticks timed in the network comparison")
    parser.add_argument("--calls", type=int, default=200, help="calls per batch size in the sweep")
    parser.add_argument(
        "--cell-model",
        default=None,
        help="a model folder for the cells section's assistive cells "
        "(the main job's lstm-intent; default: --model, or the small one trained here)",
    )
    parser.add_argument("--only", default="network,datasets,groups,sweep,cells", help="sections to run (docstring)")
    args = parser.parse_args()
    only = {name.strip() for name in args.only.split(",") if name.strip()}
    unknown = only - {"network", "datasets", "groups", "sweep", "cells"}
    if unknown:
        parser.error(f"--only: unknown sections {sorted(unknown)}; choose from network, datasets, groups, sweep, cells")
    from coassist.experiments.pipeline import ITERATION_TASKS
    from coassist.sim.collect import dataset_specs

    print(machine_line())
    print(f"load average before: {os.getloadavg()[0]:.2f} (other processes on the machine inflate every number)")
    with tempfile.TemporaryDirectory() as tmp:
        model = args.model or train_small_model(Path(tmp) / "m")
        B = -(-len(ITERATION_TASKS) * args.trials // args.workers)  # one lockstep group per worker
        if "sweep" in only:
            print(f"\none network call, one thread, {args.calls} calls per batch size (random scaled windows):")
            for b, t_torch, t_onnx, d_torch, d_onnx in sweep_calls(model, (1, 9, 18, 30, 60), args.calls):
                print(
                    f"  B = {b:2d}   torch median {np.median(t_torch) * 1e3:6.2f} ms  p99 {np.percentile(t_torch, 99) * 1e3:6.2f} ms"
                    f"   ONNX Runtime median {np.median(t_onnx) * 1e3:6.2f} ms  p99 {np.percentile(t_onnx, 99) * 1e3:6.2f} ms"
                    f"   torch / ONNX {np.median(t_torch) / np.median(t_onnx):.2f}x"
                    f"   rows vs alone: torch {d_torch:.1e}, ONNX {d_onnx:.1e}"
                )
        if "cells" in only:
            from coassist.experiments.application import cell_options
            from coassist.experiments.reproduce_config import ReproduceConfig

            cfg = ReproduceConfig()
            cell_model = args.cell_model or model
            cells = [
                ("manual", "nominal"),
                ("cooperative", "nominal"),
                ("cooperative", cell_model),
                ("cooperative-arbitrated", cell_model),
            ]
            n_cell = len(cfg.application_users) * cfg.application_trials
            print(
                f"\none application cell (board, {n_cell} trials), this process, CPU s, the lower of {args.repeats} "
                f"runs: two groups of {(n_cell + 1) // 2} and {n_cell // 2} against one of {n_cell}"
            )
            for controller, intent in cells:
                options = cell_options(cfg, 0, "board", controller, intent)
                options.pop("groups")
                two, one = cell_cpu_seconds(dataset_specs(**options), args.repeats)
                label = f"{controller}, {'model' if intent == cell_model else intent}"
                print(f"  {label:34s} two groups {two:6.2f} s   one group {one:6.2f} s   ratio {one / two:.2f}")
        if "network" in only:
            network_section(model, B, args.ticks)
        common = dict(
            controller="cooperative",
            users=(0,),
            tasks=ITERATION_TASKS,
            objects=("handle",),
            trials=args.trials,
            seed=1000,
            preset="thesis-evaluation-dm",
        )
        with_model = dataset_specs(intent=model, **common)
        nominal = dataset_specs(intent="nominal", **common)
        if "groups" in only:
            groups_section(with_model, nominal, args.workers, args.repeats)
        if "datasets" in only:
            datasets_section(with_model, nominal, args)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


def network_section(model: str, B: int, ticks: int) -> None:
    on_onnx, batched, alone = network_ticks(model, B, ticks)
    print(f"\nnetwork work per tick for {B} trials (one worker's group), {ticks} ticks:")
    for name, x in (
        ("lockstep, one batched call, ONNX Runtime", on_onnx),
        ("lockstep, one batched call, torch", batched),
        (f"per trial, {B} torch calls", alone),
    ):
        print(f"  {name:42s} median {np.median(x) * 1e3:6.2f} ms   p99 {np.percentile(x, 99) * 1e3:6.2f} ms")
    print(
        f"  speed-up (median): batched torch / ONNX {np.median(batched) / np.median(on_onnx):.2f}x, "
        f"per-trial torch / batched torch {np.median(alone) / np.median(batched):.1f}x"
    )


def groups_section(with_model, nominal, workers: int, repeats: int) -> None:
    for label, specs in (("model in the loop", with_model), ("nominal intent", nominal)):
        group = specs[::workers]
        print(f"\none worker's lockstep group, {label} ({len(group)} trials), in this process:")
        cpu_of = {}
        ways = (
            [(False, "torch"), (True, "torch"), (True, "onnx")]
            if label == "model in the loop"
            else [(False, "torch"), (True, "torch")]
        )
        for arrays, network in ways:
            g_wall, g_cpu, g_ticks, g_trial_ticks = group_seconds(
                [replace(s, network=network) for s in group], repeats, arrays
            )
            cpu_of[arrays, network] = np.median(g_cpu)
            name = "as arrays (coassist.sim.array_runner)" if arrays else "run_loops over per-trial objects"
            if label == "model in the loop":
                name += f", network on {network}"
            print(f"  {name}: {g_ticks} ticks, {g_trial_ticks} trial-ticks")
            for what, x in (("wall", g_wall), ("CPU", g_cpu)):
                print(
                    f"    {what:4s} median {np.median(x):6.2f} s   p99 {np.percentile(x, 99):6.2f} s   "
                    f"{np.median(x) / g_trial_ticks * 1e6:5.1f} us per trial-tick   {np.median(x) / g_ticks * 1e3:5.2f} ms per tick"
                )
        print(
            f"  speed-up (median CPU): arrays / run_loops {cpu_of[False, 'torch'] / cpu_of[True, 'torch']:.2f}x"
            + (
                f", ONNX / torch {cpu_of[True, 'torch'] / cpu_of[True, 'onnx']:.2f}x, both "
                f"{cpu_of[False, 'torch'] / cpu_of[True, 'onnx']:.2f}x"
                if (True, "onnx") in cpu_of
                else ""
            )
        )


def datasets_section(with_model, nominal, args) -> None:
    from coassist.experiments.pipeline import ITERATION_TASKS

    n = len(with_model)
    per_trial = dataset_seconds(with_model, args.workers, False, args.baseline_repeats)
    lock = dataset_seconds(with_model, args.workers, True, args.repeats)
    lock_kept = dataset_seconds(with_model, args.workers, True, args.repeats, kept_pool=True)
    on_torch = [replace(s, network="torch") for s in with_model]
    lock_kept_torch = dataset_seconds(on_torch, args.workers, True, args.repeats, kept_pool=True)
    nom = dataset_seconds(nominal, args.workers, False, args.repeats)
    nom_lock = dataset_seconds(nominal, args.workers, True, args.repeats)
    nom_kept = dataset_seconds(nominal, args.workers, True, args.repeats, kept_pool=True)

    def fmt(x: np.ndarray) -> str:
        if not x.size:
            return "not run (--baseline-repeats 0)"
        return f"median {np.median(x):6.1f} s   p99 {np.percentile(x, 99):6.1f} s   ({x.size} runs)"

    print(
        f"\none {n}-trial dataset ({', '.join(ITERATION_TASKS)} × {args.trials}, thesis-evaluation-dm) on {args.workers} workers:"
    )
    print(f"  model in the loop, per trial              {fmt(per_trial)}")
    print(f"  model in the loop, lockstep               {fmt(lock)}   (target <= 10 s on 2 cores)")
    print(f"  model in the loop, lockstep, kept pool    {fmt(lock_kept)}")
    print(
        f"    the same, network on torch              {fmt(lock_kept_torch)}   "
        f"(x{np.median(lock_kept_torch) / np.median(lock_kept):.2f} the default's time)"
    )
    print(f"  nominal intent, per trial                 {fmt(nom)}")
    print(f"  nominal intent, lockstep                  {fmt(nom_lock)}")
    print(f"  nominal intent, lockstep, kept pool       {fmt(nom_kept)}")
    speed_up = f"{np.median(per_trial) / np.median(lock):.1f}x" if per_trial.size else "n/a"
    print(
        f"  speed-up (median)                         with a model {speed_up}, nominal "
        f"{np.median(nom) / np.median(nom_lock):.1f}x; a kept pool saves {np.median(lock) - np.median(lock_kept):.1f} s; "
        f"lockstep with a model / nominal {np.median(lock) / np.median(nom_lock):.2f}"
    )


if __name__ == "__main__":
    main()
