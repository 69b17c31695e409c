"""Does the learned predictor earn its place? Held-out real recordings, several seeds, tuned baselines.

    python -m coassist.experiments.predictors --data ../shared/data/ur5-thesis --seeds 0,1,2 \\
        --variant default --variant default:freeze_skip=true [--json out.json]

Protocols (split by trial, never tuned on a test trial):

- ``user-a``: user-a's 15 recordings, 20 % of the trials held out (``split_trials`` with the seed);
- ``user-b``: user-a's recordings plus two of user-b's for training, the third user-b
  recording held out; seed s holds out user-b trial s (mod 3).

Each variant (a preset from :data:`coassist.intent.presets.MODEL_PRESETS`, optionally with
TrainConfig overrides ``field=value``) is trained from scratch per seed; its baselines
(ridge α, Kalman noise) are tuned on validation trials split from the training trials
(``baselines.fit_tuned_baselines``), and everything is scored on the same ticks
(:func:`coassist.intent.evaluate_model`). Reported: e_RMS per horizon, median over seeds
with the min–max, and the model's gain over the best baseline and over the ridge.
Training work is given as epochs × windows, not seconds.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["parse_variant", "run", "summarise"]

PROTOCOLS = ("user-a", "user-b")


def parse_variant(text: str) -> tuple[str, dict[str, Any]]:
    """``preset[:field=value,...]`` -> (preset name, TrainConfig overrides); values parsed as JSON."""
    from coassist.intent.presets import MODEL_PRESETS, TrainConfig

    name, _, rest = text.partition(":")
    if name not in MODEL_PRESETS:
        raise ValueError(f"--variant {text!r}: unknown preset {name!r}; choose one of {sorted(MODEL_PRESETS)}")
    known = {f.name for f in fields(TrainConfig)}
    overrides: dict[str, Any] = {}
    for item in filter(None, rest.split(",")):
        key, sep, value = item.partition("=")
        if not sep or key not in known:
            raise ValueError(f"--variant {text!r}: {item!r} is not field=value with a TrainConfig field")
        try:
            overrides[key] = json.loads(value)
        except json.JSONDecodeError:
            overrides[key] = value
    return name, overrides


def run(
    data: Path, variants: list[str], seeds: list[int], protocols: tuple[str, ...] = PROTOCOLS, threads: int = 1
) -> list[dict[str, Any]]:
    """One record per (protocol, variant, seed): the evaluation, the training work and the split."""
    import torch

    from coassist.intent import evaluate_model, load_trials, train_model
    from coassist.intent.presets import MODEL_PRESETS

    torch.set_num_threads(threads)
    a = load_trials([data / "user-a"])
    b = load_trials([data / "user-b"]) if "user-b" in protocols else []
    out = []
    for text in variants:
        name, overrides = parse_variant(text)
        preset = MODEL_PRESETS[name]
        for protocol in protocols:
            for seed in seeds:
                cfg = replace(preset.train, seed=seed, threads=threads, **overrides)
                if protocol == "user-a":
                    model = train_model(a, preset, cfg)
                    ev = evaluate_model(model, a, held_out_only=True)
                else:
                    test = [b[seed % len(b)]]
                    train = a + [t for t in b if t.id != test[0].id]
                    model = train_model(train, preset, replace(cfg, test_fraction=0.0))
                    ev = evaluate_model(model, test, held_out_only=False)
                epochs = len(model.info["training_history"])
                out.append(
                    {
                        "protocol": protocol,
                        "variant": text,
                        "seed": seed,
                        "evaluation": ev,
                        "work": {
                            "epochs": epochs,
                            "windows": model.info["n_train_windows"],
                            "windows_trained": epochs * model.info["n_train_windows"],
                        },
                    }
                )
    return out


def summarise(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (protocol, variant, predictor, horizon): median, min and max over seeds of the pooled e_RMS [m],
    and per (protocol, variant, horizon) the model's gain over the best baseline and over the ridge."""
    rows = []
    keys = sorted({(r["protocol"], r["variant"]) for r in records})
    for protocol, variant in keys:
        recs = [r for r in records if r["protocol"] == protocol and r["variant"] == variant]
        horizons = recs[0]["evaluation"].horizons
        for p in recs[0]["evaluation"].results:
            for h in horizons:
                v = np.array([r["evaluation"].results[p][h]["e_rms"] for r in recs])
                rows.append(
                    {
                        "protocol": protocol,
                        "variant": variant,
                        "predictor": p,
                        "horizon": h,
                        "median": float(np.median(v)),
                        "min": float(v.min()),
                        "max": float(v.max()),
                        "n": len(v),
                    }
                )
        for h in horizons:
            gain_best = np.array([r["evaluation"].best_baseline[h]["gain"] for r in recs])
            res = [r["evaluation"].results for r in recs]
            gain_ridge = np.array(
                [(x["ridge"][h]["e_rms"] - x["model"][h]["e_rms"]) / x["ridge"][h]["e_rms"] for x in res]
            )
            best = [r["evaluation"].best_baseline[h]["name"] for r in recs]
            rows.append(
                {
                    "protocol": protocol,
                    "variant": variant,
                    "predictor": "gain",
                    "horizon": h,
                    "over_best_median": float(np.median(gain_best)),
                    "over_best_min": float(gain_best.min()),
                    "over_best_max": float(gain_best.max()),
                    "over_ridge_median": float(np.median(gain_ridge)),
                    "over_ridge_min": float(gain_ridge.min()),
                    "over_ridge_max": float(gain_ridge.max()),
                    "best_baselines": best,
                }
            )
    return rows


def _print(rows: list[dict[str, Any]], dt: float) -> None:
    for r in rows:
        head = f"{r['protocol']:7s} {r['variant']:34s} {r['horizon'] * dt:.2f} s"
        if r["predictor"] == "gain":
            print(
                f"{head}  gain over best baseline {100 * r['over_best_median']:+.1f} % "
                f"[{100 * r['over_best_min']:+.1f}, {100 * r['over_best_max']:+.1f}], over ridge "
                f"{100 * r['over_ridge_median']:+.1f} % [{100 * r['over_ridge_min']:+.1f}, {100 * r['over_ridge_max']:+.1f}]"
                f"  (best: {', '.join(r['best_baselines'])})"
            )
        else:
            print(
                f"{head}  {r['predictor']:22s} e_RMS {1e3 * r['median']:8.4f} mm [{1e3 * r['min']:.4f}–{1e3 * r['max']:.4f}]"
                f" over {r['n']} seeds"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--data",
        type=Path,
        required=True,
        help="folder holding user-a/ and user-b/ recordings",
    )
    ap.add_argument(
        "--variant",
        action="append",
        default=None,
        help="preset[:field=value,...] (repeatable)",
    )
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--protocols", default=",".join(PROTOCOLS))
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    try:
        seeds = [int(s) for s in args.seeds.split(",")]
        protocols = tuple(p for p in args.protocols.split(",") if p)
        if any(p not in PROTOCOLS for p in protocols):
            raise ValueError(f"--protocols {args.protocols!r}: choose among {PROTOCOLS}")
        if not (args.data / "user-a").is_dir():
            raise ValueError(f"--data {args.data}: no user-a/ recordings there")
        variants = args.variant or ["default"]
        for v in variants:
            parse_variant(v)
    except ValueError as exc:
        raise SystemExit(f"error: {exc}") from None
    records = run(args.data, variants, seeds, protocols, args.threads)
    rows = summarise(records)
    _print(rows, records[0]["evaluation"].dt)
    if args.json:
        from coassist._io import atomic_write_text

        atomic_write_text(
            args.json,
            json.dumps(
                {"records": [{**r, "evaluation": r["evaluation"].to_dict()} for r in records], "summary": rows},
                indent=1,
            )
            + "\n",
        )


if __name__ == "__main__":
    main()
