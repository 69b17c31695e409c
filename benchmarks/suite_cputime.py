"""Where the test suite's time goes: each test's wall and CPU seconds, then a summary by file.

As a pytest plugin (it writes ``OUT.<worker>``, one per xdist worker, ``OUT.main`` without)::

    PYTHONPATH=benchmarks SUITE_CPUTIME_OUT=/tmp/suite.tsv OMP_NUM_THREADS=1 \\
        .venv/bin/python -m pytest -p suite_cputime -q -m "not slow and not realtime"

then the summary::

    .venv/bin/python benchmarks/suite_cputime.py /tmp/suite.tsv

A test's seconds are its setup, call and teardown (a module fixture's cost lands on the first test
that uses it). CPU seconds are the pytest process's (user + system) plus those of the child
processes it reaped meanwhile (``RUSAGE_CHILDREN``): a pool kept by a fixture is counted when
it is shut down, on the test whose teardown does it. Wall seconds grow with the machine's load,
CPU seconds much less: compare CPU seconds across machines and days, wall seconds within one run.
The sum of CPU seconds over two cores is the floor of ``./dev test``'s main part (two workers).
"""

from __future__ import annotations

import argparse
import collections
import glob
import os
import resource
import sys
import time
from collections.abc import Iterator
from typing import Any

ENV = "SUITE_CPUTIME_OUT"
_rows: list[tuple[str, float, float]] = []


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


try:
    import pytest
except ImportError:  # the summary needs no pytest
    pytest = None  # type: ignore[assignment]

if pytest is not None:

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item: Any, nextitem: Any) -> Iterator[None]:
        cpu, wall = _cpu(), time.perf_counter()
        yield
        _rows.append((item.nodeid, time.perf_counter() - wall, _cpu() - cpu))

    def pytest_sessionfinish(session: Any) -> None:
        out = os.environ.get(ENV)
        if not out or not _rows:
            return
        path = f"{out}.{os.environ.get('PYTEST_XDIST_WORKER', 'main')}"
        tmp = path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as f:
            f.writelines(f"{n}\t{w:.3f}\t{c:.3f}\n" for n, w, c in _rows)
        os.replace(tmp, path)  # whole or not at all


def summarize(prefix: str, top: int = 25, cores: int = 2) -> str:
    """The files ``prefix.*`` as text: totals, the floor on ``cores`` cores, files and tests by CPU seconds."""
    rows = []
    for path in sorted(glob.glob(prefix + ".*")):
        with open(path, encoding="utf-8") as f:
            for line in f:
                name, wall, cpu = line.rstrip("\n").split("\t")
                rows.append((name, float(wall), float(cpu)))
    if not rows:
        raise SystemExit(f"no {prefix}.* files")
    wall = sum(r[1] for r in rows)
    cpu = sum(r[2] for r in rows)
    lines = [f"{len(rows)} tests: {wall:.1f} s wall, {cpu:.1f} CPU-s (floor on {cores} cores: {cpu / cores:.1f} s)"]
    by_file: dict[str, list[float]] = collections.defaultdict(lambda: [0.0, 0.0, 0.0])
    for name, w, c in rows:
        entry = by_file[name.split("::")[0]]
        entry[0] += 1
        entry[1] += w
        entry[2] += c
    lines.append(f"\nfiles by CPU seconds (top {top}): cpu  wall  tests  file")
    for name, (n, w, c) in sorted(by_file.items(), key=lambda kv: -kv[1][2])[:top]:
        lines.append(f"{c:7.1f} {w:7.1f} {int(n):5d}  {name}")
    lines.append(f"\ntests by CPU seconds (top {top}): cpu  wall  test")
    for name, w, c in sorted(rows, key=lambda r: -r[2])[:top]:
        lines.append(f"{c:7.1f} {w:7.1f}  {name}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("prefix", help="the SUITE_CPUTIME_OUT the suite ran with")
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--cores", type=int, default=2)
    args = parser.parse_args(argv)
    print(summarize(args.prefix, args.top, args.cores))
    return 0


if __name__ == "__main__":
    sys.exit(main())
