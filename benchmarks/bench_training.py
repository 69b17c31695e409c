"""Training throughput: batches cut on the device against today's NumPy batches (issue 19).

    .venv/bin/python benchmarks/bench_training.py [--steps 300] [--thesis-steps 100]
        [--threads 2] [--device cpu] [--batch-size B] [--rounds N] [--json out.json]

For the ``default`` preset (LSTM 2 × 64, 25-step windows, mirrored, skip frozen) and the
``thesis`` one (LSTM 3 × 250, 125-step windows), on a synthetic simulated-size dataset
(60 trials × 18 s at 125 Hz, bench_intent.synthetic_trials), the same training step as
``train_model`` (Adam, the preset's batch size, learning rate and mirroring) fed two ways
in the same run:

- ``numpy``: today's path, the naive baseline: each batch gathered, framed, mirrored and
  scaled with NumPy on the host, then copied to the device (``training._numpy_batch``);
- ``device``: the batches cut on the device from the features held there once
  (``intent.batches.DeviceWindows``, what ``train_model`` now does).

The two alternate in blocks of 10 steps, so a machine shared with other work slows both
alike. Reported per path: median and p99 of one step (ms), windows/s (batch size over the
median step, and over the whole run) and the ratio device/numpy; and the batch assembly
alone (median, p99), which is what the two paths differ in. And the roofline: the
network's matrix-product FLOPs per window (``training_flops_per_window``, a lower bound),
the GFLOP/s the device path reaches, and a large float32 matrix product's GFLOP/s on the
same device and threads, the most this machine's arithmetic gives.

``--rounds N`` compares whole processes instead (the in-process comparison above is not run), N rounds of two child runs each: OpenMP's
wait policy unset (libgomp spins, then sleeps, at every barrier; today's) against
``OMP_WAIT_POLICY=PASSIVE`` (threads sleep at once). libgomp reads it once, when torch
loads, so it takes a process each. On a 2-core machine shared with other work the policy,
not the batch path, is what moves 2-thread CPU training (docs/history.md, "OpenMP on a shared machine").

``--pairs N`` compares instead (neither the in-process comparison nor ``--rounds`` is run), N rounds, what the pipeline does with independent trainings (the
application's intent sources, ``experiments.source_training.train_sources``): two child
processes of one thread each training at the same time, against one child of two threads
(the naive baseline: the trainings one after the other, each on both cores); windows/s
of the pair (sum over the two, each over its own run) against the single run's, default
preset, device path.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from bench_common import network_forward_flops  # noqa: E402
from bench_intent import synthetic_trials  # noqa: E402
from coassist.intent import MODEL_PRESETS  # noqa: E402
from coassist.intent.batches import DeviceWindows  # noqa: E402
from coassist.intent.features import WindowSet  # noqa: E402
from coassist.intent.training import _numpy_batch, _optimizer, build_model  # noqa: E402

BLOCK = 10  # steps per block; the paths alternate block by block


def training_flops_per_window(preset, n_dof: int) -> float:
    """Multiply-add FLOPs of one window's training step in the network's matrix products:
    the LSTM's gates, 4·h·(in + h)·2 per layer and step, and the FC head; backward taken as
    twice forward (two products per forward one). Elementwise gate work is left out, so
    this is a lower bound on the arithmetic."""
    lstm, head = network_forward_flops(
        4 * n_dof, preset.window.horizon * n_dof, preset.lstm_layers, preset.hidden, preset.fc, preset.window.steps
    )
    return 3.0 * (lstm + head)


def gemm_ceiling(device: torch.device, n: int = 1024, repeats: int = 20) -> float:
    """Median GFLOP/s of one large float32 matrix product on ``device`` with the current
    threads: what this machine's arithmetic allows, the roofline a training step meets."""
    a, b = torch.randn(n, n, device=device), torch.randn(n, n, device=device)
    for _ in range(3):
        a @ b
    times = []
    for _ in range(repeats):
        _sync(device)
        t0 = time.perf_counter()
        a @ b
        _sync(device)
        times.append(time.perf_counter() - t0)
    return 2 * n**3 / float(np.median(times)) / 1e9


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def stats(ns: list[int]) -> tuple[float, float]:
    """Median and p99 in ms."""
    s = np.asarray(ns, dtype=float) / 1e6
    return float(np.median(s)), float(np.percentile(s, 99))


def bench_preset(name: str, trials, steps: int, device: torch.device, batch_size: int | None) -> dict:
    p = MODEL_PRESETS[name]
    # A fixed α: no ridge search (not what is timed).
    cfg = replace(p.train, skip_alpha=1e-3, ridge_alpha=1e-3, batch_size=batch_size or p.train.batch_size)
    model = build_model(p, trials, cfg)
    net = model.net.to(device).train()
    if cfg.freeze_skip and net.skip is not None:
        net.skip.requires_grad_(False)
    ws = WindowSet([lt.trial for lt in trials], model.window, model.dt, stride=cfg.train_stride)
    dev = DeviceWindows(ws, model.input_scaler, model.target_scaler, device)
    params = [q for q in net.parameters() if q.requires_grad]
    opt = _optimizer(cfg.optimizer, params, cfg.lr, cfg.weight_decay)
    rng = np.random.default_rng(0)
    bs, d = cfg.batch_size, model.n_dof

    def draw():
        sel = rng.integers(0, len(ws), bs)
        return sel, (rng.choice([-1.0, 1.0], size=(bs, d)) if cfg.mirror else None)

    def numpy_batch(sel, signs):
        x, y = _numpy_batch(model, ws, sel, signs)
        return x.to(device, non_blocking=True), y.to(device, non_blocking=True)

    # The device path's order and signs reach the device once per epoch in train_model: here once per run.
    pool = [draw() for _ in range(64)]
    pool_dev = [
        (torch.from_numpy(s).to(device), None if g is None else torch.from_numpy(g).to(device)) for s, g in pool
    ]

    def device_batch(i):
        return dev.batch(*pool_dev[i % len(pool_dev)])

    feeds = {"numpy": lambda i: numpy_batch(*pool[i % len(pool)]), "device": device_batch}

    def step(x, y):
        loss = torch.nn.functional.mse_loss(net(x), y)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    times: dict[str, list[int]] = {k: [] for k in feeds}
    assembly: dict[str, list[int]] = {k: [] for k in feeds}
    for i in range(2 * BLOCK):  # warm-up, both paths
        step(*feeds["numpy" if i % 2 else "device"](i))
    for block in range(max(1, steps // BLOCK)):
        for label, feed in feeds.items():
            for i in range(BLOCK):
                k = block * BLOCK + i
                _sync(device)
                t0 = time.perf_counter_ns()
                x, y = feed(k)
                _sync(device)
                t1 = time.perf_counter_ns()
                step(x, y)
                _sync(device)
                times[label].append(time.perf_counter_ns() - t0)
                assembly[label].append(t1 - t0)
    rows = {}
    for label in feeds:
        med, p99 = stats(times[label])
        amed, ap99 = stats(assembly[label])
        rows[label] = {
            "step_median_ms": med,
            "step_p99_ms": p99,
            "windows_per_s_median": bs / med * 1e3,
            "windows_per_s_run": bs * len(times[label]) / (sum(times[label]) / 1e9),
            "batch_median_ms": amed,
            "batch_p99_ms": ap99,
        }
    base, new = rows["numpy"], rows["device"]
    flops = training_flops_per_window(p, d)
    return {
        "flops_per_window": flops,
        "gflops_device_run": flops * new["windows_per_s_run"] / 1e9,
        "preset": name,
        "network": f"LSTM {p.lstm_layers}x{p.hidden}, {p.window.steps} steps, batch {bs}",
        "steps": len(times["device"]),
        "paths": rows,
        "ratio_windows_per_s_median": new["windows_per_s_median"] / base["windows_per_s_median"],
        "ratio_windows_per_s_run": new["windows_per_s_run"] / base["windows_per_s_run"],
        "ratio_step_p99": base["step_p99_ms"] / new["step_p99_ms"],
        "ratio_batch_median": base["batch_median_ms"] / new["batch_median_ms"],
    }


def compare_processes(args: argparse.Namespace) -> None:
    """Child processes with OpenMP's wait policy unset (today's) and PASSIVE, both batch paths in each."""
    common = [
        sys.executable,
        __file__,
        "--steps",
        str(args.steps),
        "--thesis-steps",
        str(args.thesis_steps),
        "--threads",
        str(args.threads),
        "--device",
        args.device,
    ]
    if args.batch_size:
        common += ["--batch-size", str(args.batch_size)]
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    runs: dict[str, list[dict]] = {"unset": [], "PASSIVE": []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for policy in runs:
                out = Path(tmp) / f"{policy}-{r}.json"
                child_env = env if policy == "unset" else {**env, "OMP_WAIT_POLICY": policy}
                subprocess.run([*common, "--json", str(out)], env=child_env, check=True, stdout=subprocess.DEVNULL)
                runs[policy].append(json.loads(out.read_text()))
    print(
        f"whole processes, {args.rounds} round(s) each, {args.threads} thread(s): windows/s over each run, median of rounds"
    )
    rows = []
    for i, first in enumerate(runs["unset"][0]["runs"]):
        name = first["preset"]
        med = {
            (pol, path): float(np.median([rr["runs"][i]["paths"][path]["windows_per_s_run"] for rr in runs[pol]]))
            for pol in runs
            for path in ("numpy", "device")
        }
        for (pol, path), v in med.items():
            print(f"  {name:8s} OMP_WAIT_POLICY={pol:8s} {path:7s} {v:9.0f} windows/s")
        ratio = med[("PASSIVE", "device")] / med[("unset", "numpy")]
        print(f"  {name:8s} {first['network']}: PASSIVE + device batches / unset + NumPy batches x{ratio:.2f}")
        rows.append({"preset": name, "windows_per_s": {f"{k[0]}/{k[1]}": v for k, v in med.items()}, "ratio": ratio})
    if args.json:
        Path(args.json).write_text(
            json.dumps({"rounds": args.rounds, "threads": args.threads, "processes": rows, "children": runs}, indent=1)
            + "\n"
        )


def compare_pairs(args: argparse.Namespace) -> None:
    """Two concurrent 1-thread trainings against one 2-thread training (module docstring)."""
    common = [sys.executable, __file__, "--steps", str(args.steps), "--thesis-steps", "0", "--device", args.device]
    if args.batch_size:
        common += ["--batch-size", str(args.batch_size)]
    pair, single = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.pairs):
            outs = [Path(tmp) / f"pair-{r}-{i}.json" for i in range(2)]
            procs = [
                subprocess.Popen([*common, "--threads", "1", "--json", str(o)], stdout=subprocess.DEVNULL) for o in outs
            ]
            if any(p.wait() for p in procs):
                raise SystemExit("a child run failed")
            pair.append(sum(json.loads(o.read_text())["runs"][0]["paths"]["device"]["windows_per_s_run"] for o in outs))
            out = Path(tmp) / f"single-{r}.json"
            subprocess.run([*common, "--threads", "2", "--json", str(out)], check=True, stdout=subprocess.DEVNULL)
            single.append(json.loads(out.read_text())["runs"][0]["paths"]["device"]["windows_per_s_run"])
    print(
        f"independent trainings, default preset, {args.steps} steps per run, {args.pairs} round(s), load average "
        f"{os.getloadavg()[0]:.1f}: windows/s per round"
    )
    print(f"  two 1-thread processes at once  {' '.join(f'{v:7.0f}' for v in pair)}   median {np.median(pair):7.0f}")
    print(
        f"  one 2-thread process            {' '.join(f'{v:7.0f}' for v in single)}   median {np.median(single):7.0f}"
    )
    print(f"  ratio of medians x{np.median(pair) / np.median(single):.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=300, help="training steps per path, default preset")
    ap.add_argument("--thesis-steps", type=int, default=100, help="training steps per path, thesis preset (0: skip)")
    ap.add_argument("--threads", type=int, default=2, help="torch intra-op threads")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--batch-size", type=int, default=None, help="override the presets' batch size")
    ap.add_argument("--json", default=None)
    ap.add_argument("--rounds", type=int, default=0, help="compare whole processes instead (see above), N rounds")
    ap.add_argument(
        "--pairs", type=int, default=0, help="compare two 1-thread trainings at once with one 2-thread (see above)"
    )
    args = ap.parse_args()
    if args.rounds and args.pairs:
        ap.error("--rounds and --pairs are two different comparisons: give one")
    if args.rounds:
        compare_processes(args)
        return
    if args.pairs:
        compare_pairs(args)
        return
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    trials = synthetic_trials(60)
    runs = [("default", args.steps)] + ([("thesis", args.thesis_steps)] if args.thesis_steps else [])
    out = []
    print(f"training throughput, {args.threads} thread(s), {device}, torch {torch.__version__}")
    print(
        f"  {'preset':8s} {'path':7s} {'step med':>9s} {'step p99':>9s} {'win/s med':>10s} {'win/s run':>10s}"
        f" {'batch med':>10s} {'batch p99':>10s}"
    )
    ceiling = gemm_ceiling(device)
    print(f"  a 1024 x 1024 float32 matrix product here: {ceiling:.0f} GFLOP/s (the arithmetic's ceiling)")
    for name, steps in runs:
        r = bench_preset(name, trials, steps, device, args.batch_size)
        out.append(r)
        for label, row in r["paths"].items():
            print(
                f"  {name:8s} {label:7s} {row['step_median_ms']:9.2f} {row['step_p99_ms']:9.2f} "
                f"{row['windows_per_s_median']:10.0f} {row['windows_per_s_run']:10.0f} "
                f"{row['batch_median_ms']:10.3f} {row['batch_p99_ms']:10.3f}"
            )
        print(
            f"  {name:8s} {r['network']}: device/numpy windows/s x{r['ratio_windows_per_s_median']:.2f} (median step), "
            f"x{r['ratio_windows_per_s_run']:.2f} (whole run), p99 step x{r['ratio_step_p99']:.2f}, "
            f"batch assembly x{r['ratio_batch_median']:.1f}"
        )
        print(
            f"  {name:8s} matrix products: {r['flops_per_window'] / 1e6:.2f} MFLOP per window, "
            f"{r['gflops_device_run']:.0f} GFLOP/s on the device path = {100 * r['gflops_device_run'] / ceiling:.0f} % "
            f"of the ceiling; 3x would need {3 * r['gflops_device_run']:.0f}"
        )
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {
                    "threads": args.threads,
                    "device": str(device),
                    "torch": torch.__version__,
                    "gemm_gflops": ceiling,
                    "runs": out,
                },
                indent=1,
            )
            + "\n"
        )


if __name__ == "__main__":
    main()
