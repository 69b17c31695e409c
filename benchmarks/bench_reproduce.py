"""Speed of ``coassist reproduce`` end to end, per stage: lockstep against the per-trial path, in one run.

Runs the whole pipeline (:func:`coassist.experiments.reproduce.run_reproduce`) on one
preset ``--repeats`` times with the reference path — every simulated trial alone, one
batch-1 network call per trial and tick (``ReproduceConfig.lockstep=False``) — and as
many times with the default lockstep path (one batched call per tick for every trial of
a worker's group, :mod:`coassist.runtime.batched_loops`), alternating the two so that a
change in the machine's load falls on both. Prints, per stage and in total, the median
and p99 wall time of each path and the ratio of their medians. The training, the
dMPC study and the real-recordings stage do the same work on both paths; the ratio
is the simulation's.

The two paths give the same trials to the network's float32 rounding (with a model in
the loop; bit for bit without one), so their reports agree; the benchmark checks that
the two runs' claims have the same verdicts and says so.

Usage: ``.venv/bin/python benchmarks/bench_reproduce.py [--preset default] [--repeats 1]``
(the default preset takes tens of minutes for both paths on 2 cores; ``--preset tiny`` a
minute, but its datasets are too small for lockstep to matter).

``--presets full,default`` compares two presets instead (issue 35: the previous default, now
``full``, against the default that does less arithmetic), alternating them ``--repeats`` times:
per stage the median wall and CPU seconds of each, the ratio, the run's network arithmetic in
TFLOP (``bench_floor.run_work``) and whether the claims' verdicts agree. ``--from RUN RUN …``
prints the same table for finished runs (``coassist reproduce --out RUN``, or a ``--seeds`` run's
``seed-<k>`` folders), preset by preset, without running anything.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from bench_common import machine_line
from coassist.experiments.reproduce import run_reproduce
from coassist.experiments.reproduce_config import REPRODUCE_PRESETS


def _stats(values: list[float]) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    return float(np.median(v)), float(np.percentile(v, 99))


def _run_row(run: Path) -> tuple[str, dict[str, tuple[float, float]], float, list[tuple[str, bool]]]:
    """(preset, stage → (wall s, CPU s) with "total", network TFLOP, [(claim, holds)]) of a finished run."""
    import json

    from bench_floor import run_work

    summary = json.loads((run / "summary.json").read_text("utf-8"))
    stages = {}
    for name, wall in summary["stage_seconds"].items():
        cpu = summary["stage_cpu_seconds"][name]
        stages[name] = (float(wall), float(cpu["main"]) + float(cpu["workers"] or 0.0))
    total_cpu = summary["cpu_seconds"]
    stages["total"] = (float(summary["total_seconds"]), float(total_cpu["main"]) + float(total_cpu["workers"] or 0.0))
    train, loop, *_ = run_work(run)
    return (
        summary["config"]["name"],
        stages,
        (train + loop) / 1e12,
        [(c["claim"], bool(c["holds"])) for c in summary["claims"]],
    )


def headline_figures(run: Path) -> dict[str, tuple[float, float, float]]:
    """The first screen's figures of a finished run with their 95 % intervals: (estimate, low, high).

    Per object and assistive variant, the force saved against MG per trial (Student-t interval of the
    mean), σ's and the overshoot's paired differences from MG; per object and headline intent source
    (arbitrated controller; the damped one for the damping row), the shares of the oracle's force
    saving and overshoot reduction (their bootstrap intervals)."""
    import json

    from coassist.analysis.paired import paired_difference
    from coassist.experiments.ablation_report import HEADLINE

    summary = json.loads((run / "summary.json").read_text("utf-8"))
    app, cells = summary["application"], summary["ablation"]["cells"]
    out: dict[str, tuple[float, float, float]] = {}
    for obj in ("board", "heavy"):
        mg = app[f"{obj}/manual"]
        for variant in ("cooperative", "cooperative-arbitrated"):
            v = app[f"{obj}/{variant}"]
            saved = 1.0 - np.asarray(v["f_rms_trials"]) / np.asarray(mg["f_rms_trials"])
            mean, lo, hi, _ = paired_difference(saved, np.zeros_like(saved))
            out[f"{obj} {variant}: force saved vs MG"] = (mean, lo, hi)
            for metric in ("sigma", "overshoot"):
                d, lo, hi, _ = paired_difference(v[f"{metric}_trials"], mg[f"{metric}_trials"])
                out[f"{obj} {variant}: {metric} vs MG [m]"] = (d, lo, hi)
        for label, controller, source in HEADLINE:
            cell = cells.get(f"point-mass/{obj}/{controller}/{source}")
            if cell is None or source == "oracle":
                continue
            out[f"{obj} {label}: force share"] = tuple(cell["oracle_share_force"])
            out[f"{obj} {label}: overshoot share"] = tuple(cell["oracle_share_overshoot"])
    return out


def compare_presets(runs: dict[str, list[Path]]) -> None:
    """The preset table: per stage the median wall and CPU seconds of each preset's runs, and the ratio."""
    names = list(runs)
    rows = {name: [_run_row(r) for r in runs[name]] for name in names}
    a, b = names
    print(f"\n{'stage':<22}" + "".join(f"{n + ' wall':>14}{n + ' CPU':>14}" for n in names) + f"{'CPU ratio':>11}")
    for stage in rows[a][0][1]:
        med = {
            n: (
                float(np.median([r[1][stage][0] for r in rows[n]])),
                float(np.median([r[1][stage][1] for r in rows[n]])),
            )
            for n in names
        }
        print(
            f"{stage:<22}"
            + "".join(f"{med[n][0]:>12.0f} s{med[n][1]:>12.0f} s" for n in names)
            + f"{med[b][1] / med[a][1] if med[a][1] else float('nan'):>10.2f}×"
        )
    for n in names:
        tf = [r[2] for r in rows[n]]
        print(f"{n}: network arithmetic {np.median(tf):.2f} TFLOP (runs: {', '.join(f'{v:.2f}' for v in tf)})")
    for i, (ra, rb) in enumerate(zip(rows[a], rows[b])):
        same = [x == y for x, y in zip(ra[3], rb[3])]
        print(
            f"pair {i + 1}: {sum(same)} of {len(same)} verdicts the same"
            + ("" if all(same) else "; differ: " + "; ".join(t for (t, _), ok in zip(ra[3], same) if not ok))
        )
        fa, fb = headline_figures(runs[a][i]), headline_figures(runs[b][i])
        outside = [k for k in fa if k in fb and np.isfinite(fa[k][1]) and not fa[k][1] <= fb[k][0] <= fa[k][2]]
        print(
            f"  headline figures of {b} inside {a}'s 95 % interval: {len(fa) - len(outside)} of {len(fa)}"
            + "".join(
                f"\n    outside: {k}: {fb[k][0]:.4g} vs {fa[k][0]:.4g} [{fa[k][1]:.4g}, {fa[k][2]:.4g}]"
                for k in outside
            )
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="default", help=f"reproduce preset: {', '.join(REPRODUCE_PRESETS)}")
    parser.add_argument("--presets", default=None, help="two presets to compare instead, e.g. full,default")
    parser.add_argument(
        "--from", dest="runs", nargs="+", type=Path, default=None, help="finished runs to tabulate by preset (no run)"
    )
    parser.add_argument("--repeats", type=int, default=1, help="runs of each path (alternating)")
    parser.add_argument("--workers", type=int, default=None, help="simulation processes (default: the preset's)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")
    if args.runs:
        import json

        by: dict[str, list[Path]] = {}
        for run in args.runs:
            if not (run / "summary.json").is_file():
                parser.error(f"--from {run}: no summary.json there")
            by.setdefault(json.loads((run / "summary.json").read_text())["config"]["name"], []).append(run)
        if len(by) != 2:
            parser.error(f"--from needs the runs of exactly two presets, got {sorted(by)}")
        print(machine_line())
        compare_presets(by)
        return
    if args.presets:
        names = [p.strip() for p in args.presets.split(",")]
        if len(names) != 2 or any(n not in REPRODUCE_PRESETS for n in names):
            parser.error(f"--presets needs two of {', '.join(REPRODUCE_PRESETS)}, got {args.presets!r}")
        print(machine_line())
        print(f"load average before: {os.getloadavg()[0]:.2f} (other processes on the machine inflate every number)")
        keep = Path(tempfile.mkdtemp(prefix="bench-presets-"))
        runs: dict[str, list[Path]] = {n: [] for n in names}
        for r in range(args.repeats):
            for n in names:
                config = REPRODUCE_PRESETS.lookup(n)
                if args.workers is not None:
                    config = replace(config, workers=args.workers)
                out = keep / f"{n}-{r}"
                summary = run_reproduce(config, out, progress=False)
                runs[n].append(out)
                print(
                    f"  run {r + 1}, {n}: {summary['total_seconds']:.0f} s (load {os.getloadavg()[0]:.2f}); {out}",
                    flush=True,
                )
        compare_presets(runs)
        return
    config = REPRODUCE_PRESETS.lookup(args.preset)
    if args.workers is not None:
        config = replace(config, workers=args.workers)
    print(machine_line())
    print(f"load average before: {os.getloadavg()[0]:.2f} (other processes on the machine inflate every number)")
    print(f"preset {config.name}: workers {config.workers}, torch threads {config.threads}, device {config.device}")
    times: dict[bool, list[dict[str, float]]] = {False: [], True: []}
    verdicts: dict[bool, list[bool]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for lockstep in (False, True):
                out = Path(tmp) / f"{'lockstep' if lockstep else 'per-trial'}-{r}"
                summary = run_reproduce(replace(config, lockstep=lockstep), out, progress=False)
                stages = dict(summary["stage_seconds"])
                stages["total"] = float(summary["total_seconds"])
                times[lockstep].append(stages)
                verdicts.setdefault(lockstep, [bool(c["holds"]) for c in summary["claims"]])
                cpu = summary["cpu_seconds"]
                used = "" if cpu["workers"] is None else f", {cpu['main'] + cpu['workers']:.0f} CPU-s"
                print(
                    f"  run {r + 1}, {'lockstep' if lockstep else 'per-trial'}: {stages['total']:.0f} s{used} "
                    f"(load {os.getloadavg()[0]:.2f})",
                    flush=True,
                )
    print(f"\n{'stage':<24}{'per-trial median':>18}{'p99':>9}{'lockstep median':>18}{'p99':>9}{'ratio':>8}")
    for stage in times[True][0]:
        base, base99 = _stats([t[stage] for t in times[False]])
        fast, fast99 = _stats([t[stage] for t in times[True]])
        print(f"{stage:<24}{base:>16.1f} s{base99:>7.1f} s{fast:>16.1f} s{fast99:>7.1f} s{base / fast:>7.2f}×")
    same = verdicts[False] == verdicts[True]
    print(
        f"\nclaims' verdicts: {'the same' if same else 'DIFFERENT'} on both paths "
        f"({sum(verdicts[True])} of {len(verdicts[True])} hold with lockstep)"
    )


if __name__ == "__main__":
    main()
