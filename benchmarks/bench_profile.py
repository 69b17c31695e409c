"""Where the main job's worker time goes (issue 44): one worker job per trial kind, and py-spy's stacks by kind of work.

    .venv/bin/python benchmarks/bench_profile.py job KIND RUN_FOLDER [--json OUT]
    .venv/bin/python benchmarks/bench_profile.py classify RAW [--rate 20] [--job]
    .venv/bin/python benchmarks/bench_profile.py io RUN_FOLDER

``job`` runs, in this process on one thread, what a pool worker of ``coassist reproduce`` runs
for one kind of trial, with the models of a finished run (``RUN_FOLDER/models``), and prints
its CPU seconds, trials, ticks and a SHA-256 of every array of the trials it returns (the
payloads a worker sends back): run it before and after a change that must keep the bits.

- ``pm-mg``: MG (manual guidance, nominal intent), the application's board cell: 24 trials;
- ``pm-lstm`` / ``pm-paths`` / ``pm-person``: the arbitrated controller with ``lstm-intent``,
  the path hypotheses or the person model, the same 24 trials, one lockstep group
  (:func:`coassist.sim.trial_runner.run_spec_lockstep`, as a worker's job);
- ``mj-mg`` / ``mj-lstm`` / ``mj-person``: the MuJoCo UR5's job of that source (``mj-mg``: MG's, no model)
  (:func:`coassist.experiments.ablation.mujoco_task`) for the board's cell, 24 trials; the
  person model's job first drives its probe trials on the arm (every calibration draw's) and fits the model there.

``io`` reads every dataset of a finished run (:func:`coassist.data.read_dataset`, as the main
process reads each collection back) and writes every trial again to a temporary folder
(:func:`coassist.data.trial_file.write_trial`, as the collections write them), and prints the CPU
seconds of each: what a run spends on its dataset files.

``classify`` reads a py-spy ``--format raw`` file (``py-spy record -s -f raw``, or ``--pid``
on a ``job`` process) and prints the samples by kind of work: network forward, simulation
step (point mass, MuJoCo UR5), intent source filter (person model, path hypotheses), feature
building, training, data writing and reading, scoring, imports; a sample's kind is that of the
innermost frame that has one. ``--job``: only the samples inside a ``job``'s worker function
(the script's own start-up left out). py-spy counts a thread that is running or waiting for a
core, so on a loaded machine the shares are of thread time, not CPU time.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

POINT_MASS = {"pm-mg": "nominal", "pm-lstm": "lstm-intent", "pm-paths": "paths", "pm-person": "person"}
#: The folder under ``RUN_FOLDER/models`` that a point-mass source's cells are given: the person model's
#: cells get its calibration draws (one person model per calibration, :mod:`coassist.scenario.calibration_draws`).
MODEL_FOLDERS = {"person": "person-draws"}
MUJOCO = {"mj-mg": "nominal-mg", "mj-lstm": "lstm-intent", "mj-person": "person"}
#: Frames of a worker's job (``classify --job`` keeps the samples under one of them).
JOB_FRAMES = ("run_spec_lockstep (", "_run_lockstep_batch (", "_drive_batch (", "calibrate_then_drive (")


def run_job(kind: str, run: Path) -> dict:
    """One worker job of ``kind`` (module docstring) with ``run``'s models: CPU seconds, trials, ticks, digest."""
    import torch

    from coassist.experiments.ablation import calibrate_then_drive, mujoco_task
    from coassist.experiments.ablation_cells import ARBITRATED
    from coassist.experiments.application import cell_options
    from coassist.experiments.pipeline import Workspace
    from coassist.experiments.reproduce_config import REPRODUCE_PRESETS
    from coassist.sim.collect import dataset_specs
    from coassist.sim.pool import trial_payload
    from coassist.sim.trial_runner import run_spec_lockstep

    torch.set_num_threads(1)
    cfg = REPRODUCE_PRESETS.lookup("default")
    models = run / "models"
    t0, c0 = time.perf_counter(), time.process_time()
    if kind in POINT_MASS:
        source = POINT_MASS[kind]
        intent = "nominal" if source == "nominal" else str(models / MODEL_FOLDERS.get(source, source))
        options = cell_options(cfg, 0, "board", "manual" if kind == "pm-mg" else ARBITRATED, intent)
        options.pop("groups")
        payloads = [trial_payload(t) for t in run_spec_lockstep(dataset_specs(**options))]
    else:
        source = MUJOCO[kind]
        with tempfile.TemporaryDirectory() as tmp:  # the person model fitted on the arm is written here
            fn, args = mujoco_task(Workspace(cfg, Path(tmp), False), source, {source: str(models / source)})
            # both objects' trials, the board's first: its cell alone, as the point-mass jobs
            # (_drive_batch(configs); calibrate_then_drive(probes, intent, configs, asked): its probe trials first)
            at = 2 if fn is calibrate_then_drive else 0
            configs = args[at]
            boards = [c for c in configs if c.object == "board"]
            if configs[: len(boards)] != boards:
                raise RuntimeError("the MuJoCo job's configs no longer start with the board's cell")
            payloads = fn(*args[:at], boards, *args[at + 1 :])
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    digest = hashlib.sha256()
    for _, arrays in payloads:
        for name in sorted(arrays):
            if arrays[name] is not None:
                digest.update(name.encode())
                digest.update(arrays[name].tobytes())
    ticks = sum(len(arrays["time"]) for _, arrays in payloads)
    return {
        "kind": kind,
        "trials": len(payloads),
        "ticks": ticks,
        "cpu_s": cpu,
        "wall_s": wall,
        "digest": digest.hexdigest(),
    }


def data_files(run: Path) -> str:
    """CPU seconds to read every dataset of ``run`` and to write its trials again (module docstring)."""
    from coassist.data import read_dataset
    from coassist.data.trial_file import write_trial

    read = write = 0.0
    trials = ticks = 0
    with tempfile.TemporaryDirectory() as tmp:
        for folder in sorted(p for p in (run / "datasets").iterdir() if p.is_dir()):
            c0 = time.process_time()
            dataset = read_dataset(folder)
            read += time.process_time() - c0
            c0 = time.process_time()
            for i, trial in enumerate(dataset.trials):
                write_trial(trial, Path(tmp) / f"{i}.parquet")
                ticks += len(trial.time)
            write += time.process_time() - c0
            trials += len(dataset.trials)
    return f"{trials} trials, {ticks} ticks: read_dataset {read:.1f} CPU-s, write_trial {write:.1f} CPU-s"


# --------------------------------------------------------------------------- py-spy's stacks

_FILTERS = {
    "coassist/scenario/person_intent.py": "intent filter: person model",
    "coassist/scenario/person_model.py": "intent filter: person model",
    "coassist/scenario/row_smoothing.py": "intent filter: person model",
    "coassist/scenario/path_hypotheses.py": "intent filter: path hypotheses",
    "coassist/scenario/path_model.py": "intent filter: person model",  # the person's paths (PathModel, PathFrame)
}
_NETWORK = ("coassist/intent/network.py", "coassist/intent/onnx_network.py")
_FEATURES = ("coassist/intent/features.py", "coassist/intent/batches.py", "coassist/runtime/intent.py")
_POINT_MASS = (
    "coassist/sim/point_mass.py",
    "coassist/sim/array_runner.py",
    "coassist/runtime/",
    "coassist/model/",
    "coassist/control/",
    "coassist/scenario/",
)
_DATA = ("coassist/data/", "pyarrow/", "pandas/", "coassist/sim/collect.py", "coassist/sim/pool.py")
_SCORING = ("coassist/metrics.py", "coassist/analysis/", "coassist/intent/evaluation.py")


def _frame(text: str) -> tuple[str, str]:
    m = re.match(r"(.*) \((.*):(\d+)\)$", text)
    return (m.group(1), m.group(2)) if m else (text, "")


def kind_of(stack: list[str]) -> str:
    """The kind of work of one sample (its frames, outermost first): module docstring."""
    frames = [_frame(f) for f in stack]
    files = [p for _, p in frames]
    names = [n for n, _ in frames]
    if any(n.startswith("_watch_parent") for n in names):
        return "parent-watch thread (a sleep loop: sampling artefact)"
    if "_find_and_load" in names:
        return "imports / process start-up"
    if any(n.startswith(("ForkingPickler.dumps", "_ConnectionBase.send_bytes")) for n in names):
        return "data: files and payloads"
    if "coassist/intent/training.py" in files:
        for _, p in reversed(frames):
            if p.startswith(_FEATURES):
                return "training: windows, features, scalers"
            if p.startswith("torch/") or p in _NETWORK:
                return "training: network (forward, backward, optimiser)"
        return "training: other (ridge and Kalman fits, plots)"
    mujoco = any(p.startswith("coassist/robot/") for p in files)
    for _, p in reversed(frames):  # the innermost frame that says
        if "onnxruntime" in p or p in _NETWORK or p.startswith("torch/"):
            return "network forward"
        if p in _FILTERS:
            return _FILTERS[p]
        if p.startswith(_FEATURES):
            return "feature building (windows)"
        if p.startswith(("coassist/robot/", "mujoco/")) or (mujoco and p.startswith("coassist/")):
            return "simulation: MuJoCo UR5"
        if p.startswith(_POINT_MASS):
            return "simulation: point mass (tick, plant, operator, controller)"
        if p.startswith(_DATA):
            return "data: files and payloads"
        if p.startswith(_SCORING):
            return "scoring (metrics, e_RMS)"
        if p.startswith(("matplotlib/", "coassist/experiments/report.py")):
            return "report, figures"
    return "other"


def samples(path: Path) -> list[tuple[list[str], int]]:
    """(frames without the ``process`` ones, count) of each line of a py-spy raw file."""
    text = path.read_text("utf-8")
    # with -s a process frame holds its command line, which may span lines: a sample starts at "process "
    lines = re.split(r"(?<=\d)\n(?=process )", text) if text.startswith("process ") else text.split("\n")
    out = []
    for line in lines:
        m = re.fullmatch(r"(.*) (\d+)", line.strip(), flags=re.DOTALL)
        if m is None:  # a fragment of a multi-line frame name without a count: not a sample
            continue
        out.append(([f for f in m.group(1).split(";") if not f.startswith("process ")], int(m.group(2))))
    return out


def classify(path: Path, rate: float, job_only: bool) -> None:
    by_kind: Counter[str] = Counter()
    for stack, n in samples(path):
        if not stack or (job_only and not any(f.startswith(JOB_FRAMES) for f in stack)):
            continue
        by_kind[kind_of(stack)] += n
    total = sum(by_kind.values())
    print(f"{path}: {total} samples, {total / rate:.0f} s of thread time")
    for kind, n in by_kind.most_common():
        print(f"  {kind:60s} {n / rate:8.1f} s {n / total:6.1%}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    job = sub.add_parser("job", help="run one worker job of a trial kind")
    job.add_argument("kind", choices=[*POINT_MASS, *MUJOCO])
    job.add_argument("run", type=Path, help="a finished `coassist reproduce --out` folder (its models)")
    job.add_argument("--json", type=Path, help="also write the result here")
    io = sub.add_parser("io", help="CPU seconds of reading and writing a run's dataset files")
    io.add_argument("run", type=Path, help="a finished `coassist reproduce --out` folder (its datasets)")
    spy = sub.add_parser("classify", help="py-spy raw stacks by kind of work")
    spy.add_argument("raw", type=Path)
    spy.add_argument("--rate", type=float, default=20.0, help="py-spy's samples per second")
    spy.add_argument("--job", action="store_true", help="only samples inside a job's worker function")
    args = parser.parse_args()
    if args.command == "job":
        if not (args.run / "models").is_dir():
            parser.error(f"{args.run}: not a reproduce run folder (no models/)")
        result = run_job(args.kind, args.run)
        print(json.dumps(result))
        if args.json:
            args.json.write_text(json.dumps(result), "utf-8")
    elif args.command == "io":
        if not (args.run / "datasets").is_dir():
            parser.error(f"{args.run}: not a reproduce run folder (no datasets/)")
        print(data_files(args.run))
    else:
        if args.rate <= 0:
            parser.error(f"--rate must be > 0, got {args.rate}")
        classify(args.raw, args.rate, args.job)


if __name__ == "__main__":
    main()
