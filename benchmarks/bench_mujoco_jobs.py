"""What each of the main job's MuJoCo jobs costs, per trial (issue 40).

    /usr/bin/time -v .venv/bin/python benchmarks/bench_mujoco_jobs.py --out DIR [--trials 4] [--paths FOLDER]

Runs, one after the other in this process, the jobs :func:`coassist.experiments.ablation.mujoco_task` puts
on the pool for the default preset with ``ablation_mujoco_trials`` = ``--trials``: MG's, then the arbitrated
controller's with ``lstm-intent``, ``paths``, the person model (its probe trials on the arm first, in the same
job) and the oracle, and prints each job's CPU seconds (``time.process_time``) and per cell trial. The
``lstm-intent`` job gets a default-preset network trained one epoch on two trials: what a tick costs does not
depend on the weights. ``--paths``: a path-hypotheses calibration (default: fitted here as the main job
fits it). One torch and BLAS thread, as the pool's workers.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import torch  # noqa: E402

from bench_common import machine_line  # noqa: E402
from coassist.experiments import pipeline, reproduce_config  # noqa: E402
from coassist.experiments.ablation import MG_JOB, mujoco_task, probe_configs  # noqa: E402
from coassist.experiments.source_training import calibrate_paths  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--trials", type=int, default=reproduce_config.REPRODUCE_PRESETS["default"].ablation_mujoco_trials
    )
    parser.add_argument("--paths", default=None, help="a path-hypotheses calibration folder")
    args = parser.parse_args()
    print(machine_line())
    torch.set_num_threads(1)
    cfg = replace(
        reproduce_config.REPRODUCE_PRESETS["default"], workers=1, threads=1, ablation_mujoco_trials=args.trials
    )
    ws = pipeline.Workspace(cfg, args.out, progress=False)
    folder, _ = ws.collect("D0", tasks=("curved",), trials=2, seed=1, preset=cfg.application_preset, obstacle="large")
    model = ws.train("m", [folder], init="scratch", epochs=1)
    intents = {"lstm-intent": str(model), "paths": args.paths or calibrate_paths(ws), "oracle": "oracle"}
    total = 0.0
    for source in (MG_JOB, "lstm-intent", "paths", "person", "oracle"):
        fn, job = mujoco_task(ws, source, intents)
        t = time.process_time()
        out = fn(*job)
        dt = time.process_time() - t
        total += dt
        n_probes = sum(len(probe_configs(cfg, k)) for k in range(cfg.calibration_draws))
        probes = f" (+{n_probes} probe trials)" if source == "person" else ""
        print(
            f"{source:12s} {len(out)} trials{probes}: {dt:6.1f} CPU-s, {dt / len(out):.2f} per cell trial", flush=True
        )
    print(f"all MuJoCo jobs: {total:.1f} CPU-s")


if __name__ == "__main__":
    main()
