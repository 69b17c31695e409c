"""How should the predictor see its input and give its output? Measured, not assumed.

The thesis feeds absolute positions and predicts absolute positions, each output axis
scaled to [−1, 1] over the whole horizon. The alternatives (``coassist.intent.features``,
``coassist.intent.network``, ``coassist.intent.training``):

- input frame ``relative``: positions and the nominal reference minus the current pose,
  so the network does not have to learn that the task is translation-invariant;
- target ``relative`` (future minus current pose) or ``residual`` (future minus the
  constant-velocity extrapolation, so the network learns only the correction);
- target scaling ``step``: one range per horizon step, so the loss weighs the first
  steps (millimetres) like the last (centimetres);
- a linear skip from the window to the outputs, initialised with the ridge solution:
  the LSTM+FC learns a correction on top of the best linear predictor;
- mirror augmentation: windows mirrored along each axis (the planar admittance is
  symmetric), doubling what 12 recordings show the network.

:func:`compare_parameterisations` trains one model per variant with everything else
equal (preset sizes, split, seed, epochs) and scores all of them, and the baselines, on
the same held-out ticks. ``python -m coassist.experiments.parameterisation`` runs it on
the real user-a recordings and writes a Markdown table (``docs/intent-parameterisation.md``).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from coassist._io import atomic_write_text

#: label -> (window fields, preset fields, train fields) replaced in the base preset.
VARIANTS: dict[str, tuple[dict[str, Any], dict[str, Any], dict[str, Any]]] = {
    "thesis: absolute in / absolute out": (
        {"input_frame": "absolute", "target": "absolute", "target_scaling": "axis"},
        {"skip": False},
        {"mirror": False},
    ),
    "relative in / relative out": (
        {"input_frame": "relative", "target": "relative", "target_scaling": "axis"},
        {"skip": False},
        {"mirror": False},
    ),
    "relative in / residual out": (
        {"input_frame": "relative", "target": "residual", "target_scaling": "axis"},
        {"skip": False},
        {"mirror": False},
    ),
    "+ per-step target scaling": (
        {"input_frame": "relative", "target": "residual", "target_scaling": "step"},
        {"skip": False},
        {"mirror": False},
    ),
    "+ ridge-initialised linear skip": (
        {"input_frame": "relative", "target": "residual", "target_scaling": "step"},
        {"skip": True},
        {"mirror": False},
    ),
    "+ mirror augmentation (the lstm preset)": (
        {"input_frame": "relative", "target": "residual", "target_scaling": "step"},
        {"skip": True},
        {"mirror": True},
    ),
}
BASELINES = ("constant_velocity", "constant_acceleration", "ridge", "nominal")


def compare_parameterisations(
    trials: Sequence[Any],
    preset: Any,
    *,
    variants: Sequence[str] = tuple(VARIANTS),
    seeds: Sequence[int] = (0,),
    epochs: int | None = None,
    threads: int = 2,
    train_stride: int = 4,
    say=print,
) -> dict[str, Any]:
    """Train ``preset`` once per variant and seed; e_RMS per horizon on the held-out trials.

    Returns ``{"rows": [{"variant", "seed", "e_rms": {horizon: m}, "seconds"}], "baselines":
    [{"predictor", "seed", "e_rms"}], "test_trials": {seed: [...]}}``. The baselines are
    scored on the same ticks as the models; the ridge is the one fitted on the last
    variant's training windows (the default preset's frame and scaling).
    """
    from coassist.intent import evaluate_model, train_model

    rows, baselines, test_trials = [], [], {}
    for seed in seeds:
        for label in variants:
            window_kw, preset_kw, train_kw = VARIANTS[label]
            p = replace(
                preset,
                window=replace(preset.window, **window_kw),
                **preset_kw,
                train=replace(
                    preset.train,
                    seed=seed,
                    threads=threads,
                    epochs=epochs or preset.train.epochs,
                    train_stride=train_stride,
                    **train_kw,
                ),
            )
            t0 = time.perf_counter()
            model = train_model(trials, p, p.train)
            seconds = time.perf_counter() - t0
            ev = evaluate_model(model, trials, held_out_only=True)
            e = {h: v["e_rms"] for h, v in ev.results["model"].items()}
            rows.append({"variant": label, "seed": seed, "e_rms": e, "seconds": seconds})
            say(
                f"seed {seed} {label}: "
                + ", ".join(f"{h}: {1e3 * v:.2f} mm" for h, v in e.items())
                + f" ({seconds:.0f} s)"
            )
        test_trials[seed] = list(ev.trials)
        for name in BASELINES:
            baselines.append(
                {"predictor": name, "seed": seed, "e_rms": {h: v["e_rms"] for h, v in ev.results[name].items()}}
            )
    return {"rows": rows, "baselines": baselines, "test_trials": test_trials}


def markdown(result: dict[str, Any], title: str, notes: str = "") -> str:
    rows = result["rows"] + [{"variant": f"baseline: {b['predictor']}", **b} for b in result["baselines"]]
    horizons = sorted(result["rows"][0]["e_rms"])
    head = "| predictor | seed | " + " | ".join(f"e_RMS@{h} [mm]" for h in horizons) + " |"
    lines = [f"# {title}", "", notes, "", head, "|" + "---|" * (len(horizons) + 2)]
    for r in rows:
        lines.append(
            f"| {r['variant']} | {r['seed']} | " + " | ".join(f"{1e3 * r['e_rms'][h]:.3f}" for h in horizons) + " |"
        )
    lines += [
        "",
        "Held-out trials per seed: " + "; ".join(f"seed {s}: {', '.join(t)}" for s, t in result["test_trials"].items()),
        "",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    from coassist.intent import MODEL_PRESETS, load_trials

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--data", type=Path, default=None, help="recordings folder (default: user-a of the real recordings)"
    )
    ap.add_argument("--preset", default="lstm", choices=sorted(MODEL_PRESETS))  # its variants are LSTM variants
    ap.add_argument("--epochs", type=int, default=None)
    ap.add_argument("--seeds", default="0", help="comma-separated seeds (each: another split and initialisation)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument(
        "--train-stride", type=int, default=4, help="keep every n-th training window (as coassist reproduce)"
    )
    ap.add_argument("--out", type=Path, default=Path("docs/intent-parameterisation.md"))
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(args.threads)  # a command's choice: the library leaves torch's threads alone
    from coassist.data import default_real_data

    args.data = args.data or default_real_data() / "user-a"
    seeds = [int(s) for s in args.seeds.split(",")]
    preset = MODEL_PRESETS[args.preset]
    result = compare_parameterisations(
        load_trials([args.data]),
        preset,
        seeds=seeds,
        epochs=args.epochs,
        threads=args.threads,
        train_stride=args.train_stride,
    )
    notes = (
        f"Measured with `python -m coassist.experiments.parameterisation --data {args.data.name} --preset {args.preset} "
        f"--seeds {args.seeds}{f' --epochs {args.epochs}' if args.epochs else ''} --train-stride {args.train_stride}`: preset `{args.preset}` "
        f"({preset.lstm_layers} × {preset.hidden} LSTM, FC {list(preset.fc)}, {args.epochs or preset.train.epochs} "
        f"epochs, every {args.train_stride}th window), trained on {args.data.name}'s recordings split 80/20 by trial, scored on the held-out trials' "
        "every tick (e_RMS, eq. 5.6)."
    )
    atomic_write_text(
        args.out, markdown(result, "Input frame and output parameterisation of the intent predictor", notes)
    )
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(result, indent=1, allow_nan=False) + "\n")
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")


if __name__ == "__main__":  # pragma: no cover
    main()
