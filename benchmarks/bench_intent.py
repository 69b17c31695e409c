"""Intent predictor speed: per-prediction latency on one core, and training throughput.

    .venv/bin/python benchmarks/bench_intent.py [--calls 300] [--train-batches 20]
        [--full-train] [--json out.json]

Latency (torch.set_num_threads(1), ONNX Runtime with one intra-op thread): median and
p99 of one complete prediction (raw history in, positions in m out, scaling included)
for the ``lstm`` (the former default) and thesis-size (3 × 250) networks, against plain eager PyTorch on
the full 125-sample window in the same run:

- ``eager full``: eager PyTorch, 125 steps (the naive baseline);
- ``eager decimated``: eager PyTorch on the decimated window (every 5th sample, 25 steps);
- ``onnx full`` / ``onnx decimated``: ONNX Runtime on the same (needs onnx + onnxruntime);
- ``stream step``: one LSTM step with the state carried (what a streaming predictor would
  pay per tick; shown for reference: a window-trained LSTM is not exact when streamed);
- ``baselines``: the tuned ridge (one matrix product on the decimated window) and the
  constant-acceleration Kalman predictor (one filter step), ratios against the ``lstm``
  network's ``eager full``. The ``linear`` preset is that ridge in the model format.

Targets (issue 4): lstm ≤ 2 ms p99, thesis-size ≤ 8 ms p99.

Training throughput (2 threads): windows/s of a training step for both presets on a
synthetic simulated-size dataset (60 trials × 18 s at 125 Hz). With ``--full-train`` it
also times a complete ``lstm`` training on that dataset (target ≤ 3 min) and a
transfer on a 15-trial set (target ≤ 20 s).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from coassist.data import Trial, TrialMeta  # noqa: E402
from coassist.intent import MODEL_PRESETS, IntentModel, IntentNet, LabeledTrial, Scaler, save_model, train_model  # noqa: E402
from coassist.intent.features import WindowSet  # noqa: E402
from coassist.intent.realtime import make_runner  # noqa: E402
from coassist.intent.training import _Windows  # noqa: E402


def percentiles(samples_ns) -> tuple[float, float]:
    s = np.asarray(samples_ns, dtype=float) / 1e6
    return float(np.median(s)), float(np.percentile(s, 99))


def time_calls(f, calls: int, warmup: int = 20) -> tuple[float, float]:
    for _ in range(warmup):
        f()
    out = []
    for _ in range(calls):
        t0 = time.perf_counter_ns()
        f()
        out.append(time.perf_counter_ns() - t0)
    return percentiles(out)


def random_model(layers: int, hidden: int, fc: tuple[int, ...], decimation: int, skip: bool) -> IntentModel:
    """A model with random weights and plausible scalers (latency does not depend on training)."""
    base = MODEL_PRESETS["lstm"]
    window = replace(base.window, decimation=decimation)
    p = replace(base, window=window, lstm_layers=layers, hidden=hidden, fc=fc, skip=skip)
    torch.manual_seed(0)
    net = IntentNet(p.network(2)).eval()
    nsteps = window.horizon if window.target_scaling == "step" else 1
    return IntentModel(
        net, window, Scaler([-1.0] * 8, [1.0] * 8), Scaler([-0.1] * 2 * nsteps, [0.1] * 2 * nsteps), 0.008
    )


def latency(calls: int) -> list[dict]:
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    history = rng.normal(scale=0.05, size=(125, 8))
    rows = []
    lstm_preset = MODEL_PRESETS["lstm"]
    for name, layers, hidden, fc, skip in (
        ("lstm", lstm_preset.lstm_layers, lstm_preset.hidden, lstm_preset.fc, lstm_preset.skip),
        ("thesis-size", 3, 250, (200,), False),
    ):
        variants = {}
        for dec in (1, 5):
            m = random_model(layers, hidden, fc, dec, skip)
            label = "full" if dec == 1 else "decimated"
            variants[f"eager {label}"] = make_runner(m, "torch", 1)
            try:
                variants[f"onnx {label}"] = make_runner(m, "onnx", 1)
            except ImportError as exc:
                print(f"  (onnx skipped: {exc})")
        lstm = random_model(layers, hidden, fc, 1, False).net.lstm
        x1 = torch.zeros(1, 1, 8)
        state = (torch.zeros(layers, 1, hidden), torch.zeros(layers, 1, hidden))

        def step():
            with torch.inference_mode():
                lstm(x1, state)

        base = None
        for label, run in variants.items():
            med, p99 = time_calls(lambda: run(history), calls)
            base = base or (med, p99)
            rows.append({"network": name, "variant": label, "median_ms": med, "p99_ms": p99})
        med, p99 = time_calls(step, calls)
        rows.append({"network": name, "variant": "stream step (eager, 1 LSTM step)", "median_ms": med, "p99_ms": p99})
        for r in rows:
            if r["network"] == name:
                r["speedup_median"] = base[0] / r["median_ms"]
                r["speedup_p99"] = base[1] / r["p99_ms"]
    return rows


def baseline_latency(calls: int, naive: tuple[float, float]) -> list[dict]:
    """One prediction of the tuned baselines, raw history in, positions in m out, against ``naive``
    (the default network, eager, full window: median and p99 in ms, measured in the same run)."""
    from coassist.intent import RidgeBaseline
    from coassist.intent.features import decode_target, to_relative, unscale_targets
    from coassist.intent.kalman import KalmanCA, constant_acceleration, kalman_ca_filter

    rng = np.random.default_rng(0)
    history = rng.normal(scale=0.05, size=(125, 8))
    m = random_model(1, 8, (8,), 5, False)  # only its window and scalers are used
    w = m.window
    ridge = RidgeBaseline(
        rng.normal(size=(w.steps * 8, w.horizon * 2)) * 1e-2,
        np.zeros(w.horizon * 2),
        1e-4,
        w,
        m.input_scaler,
        m.target_scaler,
        m.dt,
    )

    def ridge_once():
        x = to_relative(history[None, w.offsets + w.history - 1], 2)
        out = ridge.predict_scaled(ridge.input_scaler.transform(x))
        decode_target(
            unscale_targets(ridge.target_scaler, out, w.horizon, 2),
            history[None, -1, :2],
            history[None, -1, 2:4],
            w,
            m.dt,
        )

    kalman = KalmanCA(jerk_psd=1e3, velocity_noise=1e-3)

    def kalman_once():  # one predict/update step from the previous tick, then the extrapolation
        states = kalman_ca_filter(history[-2:, :2], history[-2:, 2:4], 0.008, [kalman])
        constant_acceleration(states[0, -1], 50, 0.008)

    rows = []
    for label, f in (
        ("ridge (numpy, decimated window)", ridge_once),
        ("Kalman CA (1 filter step + extrapolation)", kalman_once),
    ):
        med, p99 = time_calls(f, calls)
        rows.append(
            {
                "network": "baselines",
                "variant": label,
                "median_ms": med,
                "p99_ms": p99,
                "speedup_median": naive[0] / med,
                "speedup_p99": naive[1] / p99,
            }
        )
    return rows


def synthetic_trials(
    n_trials: int, seconds: float = 18.0, dt: float = 0.008, prefix: str = "SIM"
) -> list[LabeledTrial]:
    """Smooth random hand-guided motions the size of the simulator's trials."""
    out = []
    n = int(seconds / dt)
    t = np.arange(n) * dt
    for i in range(n_trials):
        rng = np.random.default_rng(i)
        ref = np.stack([0.5 * t / seconds, np.zeros(n)], axis=1)
        dev = np.stack([a * np.sin(w * t + p) for a, w, p in rng.uniform([0.01, 0.5, 0], [0.08, 3, 6], (2, 3))], 1)
        pose = ref + dev
        vel = np.gradient(pose, dt, axis=0)
        meta = TrialMeta("user-0", "linear", "handle", "cooperative", None, i, "sim", dt)
        tr = Trial(
            meta=meta, time=t, pose=pose, velocity=vel, wrench=100 * vel + rng.normal(0, 0.5, pose.shape), reference=ref
        )
        out.append(LabeledTrial(f"{prefix}/trial_{i:05d}", prefix, tr))
    return out


def throughput(trials: list[LabeledTrial], batches: int) -> list[dict]:
    torch.set_num_threads(2)
    rows = []
    for name in ("lstm", "thesis"):
        p = MODEL_PRESETS[name]
        from coassist.intent.training import build_model

        model = build_model(p, trials, replace(p.train, threads=2))
        ws = WindowSet([lt.trial for lt in trials[:10]], model.window, model.dt)
        data = _Windows(model, ws, frozen_lstm=False)
        opt = torch.optim.Adam(model.net.parameters(), lr=1e-3)
        rng = np.random.default_rng(0)
        n_batches = batches if name == "lstm" else max(3, batches // 5)
        bs = p.train.batch_size
        model.net.train()
        for i in range(n_batches + 2):
            if i == 2:
                t0 = time.perf_counter()
            loss = data.loss(torch.from_numpy(rng.integers(0, len(ws), bs)))
            opt.zero_grad()
            loss.backward()
            opt.step()
        sec = time.perf_counter() - t0
        rows.append(
            {
                "preset": name,
                "windows_per_s": n_batches * bs / sec,
                "batch_size": bs,
                "batches": n_batches,
                "network": f"LSTM {p.lstm_layers}x{p.hidden}, {p.window.steps} steps",
            }
        )
    return rows


def full_train(trials: list[LabeledTrial]) -> dict:
    """The default preset's training as ``coassist reproduce`` runs it (its epochs and window stride)."""
    from coassist.experiments.reproduce import REPRODUCE_PRESETS as PIPELINE

    cfg = PIPELINE["default"]
    p = MODEL_PRESETS["lstm"]
    t0 = time.perf_counter()
    model = train_model(trials, p, replace(p.train, threads=2, epochs=cfg.epochs, train_stride=cfg.train_stride))
    train_s = time.perf_counter() - t0
    transfer_set = synthetic_trials(15, prefix="TL")
    with tempfile.TemporaryDirectory() as tmp:
        save_model(model, tmp)
        t0 = time.perf_counter()
        tl = train_model(
            transfer_set,
            p,
            replace(
                p.train, threads=2, init=f"transfer:{tmp}", epochs=cfg.transfer_epochs, train_stride=cfg.train_stride
            ),
        )
        transfer_s = time.perf_counter() - t0
    return {
        "train_s": train_s,
        "train_windows": model.info["n_train_windows"],
        "epochs": cfg.epochs,
        "transfer_s": transfer_s,
        "transfer_windows": tl.info["n_train_windows"],
        "transfer_epochs": cfg.transfer_epochs,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--train-batches", type=int, default=20)
    ap.add_argument("--full-train", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    print("latency per prediction, 1 thread (ms)")
    lat = latency(args.calls)
    naive = next(r for r in lat if r["network"] == "lstm" and r["variant"] == "eager full")
    lat += baseline_latency(args.calls, (naive["median_ms"], naive["p99_ms"]))
    print(f"  {'network':12s} {'variant':34s} {'median':>8s} {'p99':>8s} {'x med':>7s} {'x p99':>7s}")
    for r in lat:
        print(
            f"  {r['network']:12s} {r['variant']:34s} {r['median_ms']:8.3f} {r['p99_ms']:8.3f} "
            f"{r['speedup_median']:7.1f} {r['speedup_p99']:7.1f}"
        )
    trials = synthetic_trials(60)
    print("training throughput, 2 threads")
    thr = throughput(trials, args.train_batches)
    for r in thr:
        print(f"  {r['preset']:8s} {r['network']:28s} {r['windows_per_s']:9.0f} windows/s")
    result = {"latency": lat, "throughput": thr, "torch": torch.__version__}
    if args.full_train:
        full = full_train(trials)
        print(
            f"default training on 60 simulated-size trials: {full['train_s']:.0f} s "
            f"({full['train_windows']} windows x {full['epochs']} epochs); transfer on 15 trials: {full['transfer_s']:.1f} s "
            f"({full['transfer_windows']} windows x {full['transfer_epochs']} epochs)"
        )
        result["full_train"] = full
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
