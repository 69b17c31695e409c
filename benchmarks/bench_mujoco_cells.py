"""The MuJoCo UR5's cells of the ablation alone, without the main job (issue 40).

    .venv/bin/python benchmarks/bench_mujoco_cells.py --out DIR [--seed 0] [--trials 4]
        [--sources paths,person,oracle] [--calibration mujoco] [--first 4]

Runs what ``coassist reproduce`` runs on the MuJoCo UR5 for run seed ``--seed``
(:func:`coassist.experiments.ablation.run_mujoco_ablation`, the default preset): MG and the arbitrated
controller with each of ``--sources`` on the first ``--trials`` application trials of each operator and
object, paired. ``paths`` and the point-mass world's ``person`` are calibrated as the main job calibrates
them (the same collections in ``DIR``); the person model of ``--calibration mujoco`` (the default preset's)
is calibrated on the MuJoCo UR5 itself, in its own job. The learned sources need the main job's trainings
and are not run here. One simulation process (``workers`` 1): on this shared machine one heavy process.

Prints, per object and source: f_RMS and the share of the oracle's force saving, overshoot and the share of its
overshoot reduction (95 % bootstrap intervals, :data:`~coassist.experiments.ablation_cells.BOOTSTRAP` resamples), the
paired differences from MG (Student-t 95 %) and jerk against MG's; with ``--first k`` the same on each
operator's first k trials too (the cells of ``ablation_mujoco_trials`` = k: the same trials). Then the report's
MuJoCo verdicts on these cells (``paths``' direction, the person model's direction with its intervals) and the
CPU seconds of the run (this process and its workers). Writes ``DIR/mujoco-cells.json``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import machine_line  # noqa: E402
from coassist._cpu import run_cpu_seconds  # noqa: E402
from coassist._io import atomic_write_text  # noqa: E402
from coassist.analysis.paired import gain_share, paired_difference  # noqa: E402
from coassist.experiments import pipeline, reproduce_config  # noqa: E402
from coassist.experiments.ablation import OBJECTS, run_mujoco_ablation
from coassist.experiments.ablation_cells import ARBITRATED, BOOTSTRAP
from coassist.experiments.ablation_report import mujoco_person_claims, precision_claims  # noqa: E402
from coassist.experiments.source_training import calibrate_paths, calibrate_person  # noqa: E402


def cell_figures(mg: dict, x: dict, oracle: dict, keep: np.ndarray) -> dict:
    """One cell's figures on the trials ``keep`` selects (a boolean mask over the cell's paired trials)."""
    out: dict = {"trials": int(keep.sum())}
    for metric in ("f_rms", "overshoot"):
        base, val, ref = (np.asarray(c[f"{metric}_trials"], float)[keep] for c in (mg, x, oracle))
        out[f"{metric}_share"] = gain_share(base, val, ref, n_boot=BOOTSTRAP)
        out[f"{metric}_vs_mg"] = paired_difference(val, base)[:3]
        out[metric] = float(np.nanmean(val))
    out["jerk_vs_mg"] = float(np.nanmean(np.asarray(x["jerk_rms_trials"], float)[keep])) / float(
        np.nanmean(np.asarray(mg["jerk_rms_trials"], float)[keep])
    )
    return out


def pct(s) -> str:
    share, lo, hi = s
    return f"{100 * share:4.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]" if np.isfinite(lo) else f"{100 * share:.0f} %"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--trials", type=int, default=None, help="per operator and object (default: the preset's)")
    parser.add_argument("--sources", default="paths,person,oracle")
    parser.add_argument("--calibration", choices=reproduce_config.MUJOCO_PERSON_CALIBRATIONS, default=None)
    parser.add_argument("--first", type=int, default=0, help="also the figures on each operator's first k trials")
    args = parser.parse_args()
    print(machine_line())
    base = reproduce_config.REPRODUCE_PRESETS["default"]
    sources = tuple(s for s in args.sources.split(",") if s)
    if "oracle" not in sources:
        raise SystemExit("--sources must hold the oracle: the shares are of its benefit")
    cfg = replace(
        base,
        seed=args.seed,
        workers=1,
        ablation_mujoco_trials=base.ablation_mujoco_trials if args.trials is None else args.trials,
        mujoco_sources=sources,
        mujoco_person_calibration=args.calibration or base.mujoco_person_calibration,
    )
    ws = pipeline.Workspace(cfg, args.out, progress=False)
    c0 = run_cpu_seconds()
    models = {"paths": calibrate_paths(ws), "person": calibrate_person(ws)}
    calibrated = run_cpu_seconds().since(c0)
    result = run_mujoco_ablation(ws, models)
    cpu = run_cpu_seconds().since(c0)
    doc: dict = {"config": {"seed": cfg.seed, "trials": cfg.ablation_mujoco_trials, "sources": sources}, "cells": {}}
    doc["config"]["calibration"] = cfg.mujoco_person_calibration
    subsets = [("all", None)] + ([(f"first {args.first}", args.first)] if args.first else [])
    for obj in OBJECTS:
        mg = result.mg[("mujoco", obj)]
        oracle = result.metrics[("mujoco", obj, ARBITRATED, "oracle")]
        pairs = result.pairs[("mujoco", obj)]
        # the cell's trials in pair order; an operator's k-th trial is the k-th of its seeds
        rank = np.array([sorted(s for u, s in pairs if u == user).index(seed) for user, seed in pairs])
        print(f"\n{obj}: MG f_RMS {mg['f_rms']:.2f} N, overshoot {1e3 * mg['overshoot']:.2f} mm, {len(pairs)} trials")
        for label, k in subsets:
            keep = np.ones(len(pairs), bool) if k is None else rank < k
            for source in sources:
                x = result.metrics[("mujoco", obj, ARBITRATED, source)]
                f = cell_figures(mg, x, oracle, keep)
                doc["cells"][f"{obj}/{source}/{label}"] = f
                df, dlo, dhi = f["f_rms_vs_mg"]
                do, olo, ohi = f["overshoot_vs_mg"]
                print(
                    f"  {label:>8} {source:>7} ({f['trials']:2d}): force {pct(f['f_rms_share'])}"
                    f" ({df:+.2f} [{dlo:+.2f}, {dhi:+.2f}] N), overshoot {pct(f['overshoot_share'])}"
                    f" ({1e3 * do:+.2f} [{1e3 * olo:+.2f}, {1e3 * ohi:+.2f}] mm), jerk {f['jerk_vs_mg']:.2f}× MG"
                )
    # the report's MuJoCo verdicts on these cells (section 6), with the evidence it prints
    claims = [c for c in precision_claims(result) if "MuJoCo" in c.text]
    if "person" in sources:
        claims += mujoco_person_claims(result)
    doc["claims"] = [c.to_dict() for c in claims]
    for c in claims:
        print(f"\n{'HOLDS' if c.holds else 'FAILS'}: {c.text}\n  {c.evidence}")
    doc["cpu_seconds"] = {"calibrations_point_mass": calibrated.total, "total": cpu.total}
    print(f"\nCPU seconds: point-mass calibrations {calibrated.total:.1f}, total {cpu.total:.1f}")
    atomic_write_text(args.out / "mujoco-cells.json", json.dumps(doc, indent=1, default=float))


if __name__ == "__main__":
    main()
