"""A job's trials back from a pool's worker: through the pool's shared-memory folder against pickled inline (issue 44).

    .venv/bin/python benchmarks/bench_payloads.py [--jobs 40] [--trials 6] [--ticks 2200] [--json OUT]

Each job of a two-process :func:`coassist.sim.pool.worker_pool` returns ``--trials`` payloads shaped as
the main job's (a (ticks, 50, 2) prediction, the 2 MB that dominate them, and nine smaller arrays): as
:class:`~coassist.sim.pool.Payloads` (its arrays through a file in ``/dev/shm``) or as a plain list
(the naive baseline: pickled through the pool's pipe, as before). The two alternate job by job on the
same pool. Printed per way: each job's latency from its submission to its payloads in the parent
(median, p99), the parent's CPU-seconds (its pool thread reads the results and unpickles them) and
the workers' (they pickle, or write the file), from ``/proc``; then the ratios. Every payload is
checked equal, bit for bit, to the arrays the job built.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from pathlib import Path

import numpy as np

from coassist.sim.pool import SHARED_MEMORY, Payloads, worker_pool


def build(seed: int, trials: int, ticks: int) -> list:
    """``trials`` payloads of a trial's shape (meta, arrays), drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    out = []
    for t in range(trials):
        arrays = {name: rng.standard_normal((ticks, 2)) for name in ("pose", "velocity", "wrench", "reference")}
        arrays |= {"effort_h": rng.standard_normal((ticks, 2)), "effort_r": rng.standard_normal((ticks, 2))}
        arrays |= {"time": np.arange(ticks) * 0.008, "intent": rng.standard_normal((ticks, 2))}
        arrays |= {"prediction": rng.standard_normal((ticks, 50, 2)), "fault": np.zeros(ticks, dtype=np.int64)}
        out.append(({"seed": seed, "trial": t}, arrays))
    return out


def shipped(seed: int, trials: int, ticks: int) -> Payloads:
    return Payloads(build(seed, trials, ticks))


def inline(seed: int, trials: int, ticks: int) -> list:
    return build(seed, trials, ticks)


def _pid_after(seconds: float) -> int:
    time.sleep(seconds)  # held long enough that the other worker takes the next job
    return os.getpid()


def _worker_pids(pool, n: int) -> list[int]:
    """The pool's ``n`` worker processes' pids: ``n`` jobs that wait side by side, one on each."""
    pids = sorted({f.result() for f in [pool.submit(_pid_after, 0.5) for _ in range(n)]})
    if len(pids) != n:
        raise RuntimeError(f"expected {n} workers to answer, {len(pids)} did")
    return pids


def _cpu(pid: int) -> float:
    """CPU-seconds (user + system) of process ``pid`` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _same(got: list, want: list) -> bool:
    return all(
        gm == wm and all(ga[k].dtype == wa[k].dtype and ga[k].tobytes() == wa[k].tobytes() for k in wa)
        for (gm, ga), (wm, wa) in zip(got, want, strict=True)
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=40, help="jobs per way (default 40)")
    ap.add_argument("--trials", type=int, default=6, help="trials per job (default 6)")
    ap.add_argument("--ticks", type=int, default=2200, help="ticks per trial (default 2200, a board trial)")
    ap.add_argument("--json", type=Path, help="write the figures here too")
    args = ap.parse_args()
    if min(args.jobs, args.trials, args.ticks) < 1:
        ap.error("--jobs, --trials and --ticks must be >= 1")
    if not SHARED_MEMORY.is_dir():
        ap.error(f"no {SHARED_MEMORY} here: payloads are pickled inline, nothing to compare")
    ways = {"shared memory": shipped, "pickled inline (naive)": inline}
    latency: dict[str, list[float]] = {w: [] for w in ways}
    parent = {w: 0.0 for w in ways}
    workers = {w: 0.0 for w in ways}
    equal = True
    with worker_pool(2) as pool:
        pids = _worker_pids(pool, 2)
        for job in range(args.jobs):
            for way, fn in ways.items() if job % 2 == 0 else reversed(list(ways.items())):
                want = build(job, args.trials, args.ticks)
                c_self = resource.getrusage(resource.RUSAGE_SELF)
                c_workers = sum(_cpu(p) for p in pids)
                t0 = time.perf_counter()
                got = pool.submit(fn, job, args.trials, args.ticks).result()
                latency[way].append(time.perf_counter() - t0)
                c_after = resource.getrusage(resource.RUSAGE_SELF)
                parent[way] += (c_after.ru_utime + c_after.ru_stime) - (c_self.ru_utime + c_self.ru_stime)
                workers[way] += sum(_cpu(p) for p in pids) - c_workers
                equal &= _same(got, want)
    size = sum(a.nbytes for _, arrays in build(0, args.trials, args.ticks) for a in arrays.values())
    print(f"{args.jobs} jobs per way, {args.trials} trials a job, {size / 1e6:.1f} MB a job; bit for bit: {equal}")
    print("| way | latency median [ms] | p99 [ms] | parent CPU-s | workers CPU-s (incl. building) |")
    print("|---|---|---|---|---|")
    figures = {}
    for way in ways:
        lat = np.array(latency[way]) * 1e3
        figures[way] = {
            "median_ms": float(np.median(lat)),
            "p99_ms": float(np.percentile(lat, 99)),
            "parent_cpu_s": parent[way],
            "workers_cpu_s": workers[way],
        }
        f = figures[way]
        print(f"| {way} | {f['median_ms']:.1f} | {f['p99_ms']:.1f} | {parent[way]:.2f} | {workers[way]:.2f} |")
    new, old = figures["shared memory"], figures["pickled inline (naive)"]
    ratios = {
        "latency": old["median_ms"] / new["median_ms"],
        "parent_cpu": old["parent_cpu_s"] / max(new["parent_cpu_s"], 1e-9),
        "workers_cpu": old["workers_cpu_s"] / max(new["workers_cpu_s"], 1e-9),
    }
    print(
        f"naive / shared memory: latency {ratios['latency']:.2f}x, parent CPU {ratios['parent_cpu']:.2f}x, "
        f"workers' CPU {ratios['workers_cpu']:.2f}x"
    )
    if args.json:
        args.json.write_text(json.dumps({"equal": equal, "figures": figures, "ratios": ratios}, indent=2))


if __name__ == "__main__":
    main()
