"""The twin check's cost per person: its twin trials run together against each run alone (issue 44).

    .venv/bin/python benchmarks/bench_twin.py [--trials 8] [--repeats 3] [--seed 880000]

Simulates ``--trials`` calibration probe trials (manual guidance with the probe, the application's task and
preset, the handle) of each of six people (held-out operators 0–2, thesis operators 0–2), fits each one's person
model and times :func:`coassist.sim.person_twin.lead_check` on them two ways, alternated:

- ``together``: the check as it runs, every twin trial of the person in one lockstep batch on the point-mass
  array path (:mod:`coassist.sim.array_runner`);
- ``alone`` (the naive baseline): each twin trial on the reference path, its own scalar tick every period
  (``run_loops``, as without the array path).

The two must give the same check to the last bit (the benchmark stops otherwise). Times are the process's CPU time
per person's check; prints median and p99 [s] of each way and the ratio of the medians. One BLAS thread.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from unittest import mock  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import machine_line  # noqa: E402
from coassist.control.presets import get_preset, make_controller  # noqa: E402
from coassist.experiments.reproduce_config import ReproduceConfig  # noqa: E402
from coassist.scenario.objects import get_object  # noqa: E402
from coassist.scenario.person_model import PERSON_FILTER, fit_person  # noqa: E402
from coassist.scenario.populations import population_profile  # noqa: E402
from coassist.scenario.tasks import task_for_seed  # noqa: E402
from coassist.sim import person_twin, trial_runner  # noqa: E402
from coassist.sim.trial_runner import run_trial  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=8, help="calibration probe trials a person (the default's 8)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=880000)
    args = parser.parse_args()
    if args.trials < 2 or args.repeats < 1:
        parser.error("--trials must be at least 2 and --repeats at least 1")
    print(machine_line())
    cfg = ReproduceConfig()
    preset = get_preset(cfg.application_preset)
    probe = make_controller("manual-probe", preset)
    people = []
    for population in ("held-out", "thesis"):
        for user in range(3):
            profile = population_profile(population, user, 0)
            seeds = range(args.seed + 100 * len(people), args.seed + 100 * len(people) + args.trials)
            trials = [
                run_trial(
                    task_for_seed(cfg.application_task, s, obstacle="large"),
                    profile,
                    get_object("handle"),
                    probe,
                    None,
                    s,
                    preset_name=preset.name,
                )
                for s in seeds
            ]
            people.append((f"{population} {user}", trials, fit_person(trials)))
    times: dict[str, list[float]] = {"together": [], "alone": []}
    for _ in range(args.repeats):
        for name, trials, fit in people:
            t0 = time.process_time()
            together = person_twin.lead_check(trials, fit, PERSON_FILTER)
            times["together"].append(time.process_time() - t0)
            with mock.patch.object(trial_runner, "fast_path_eligible", lambda loop: False):
                t0 = time.process_time()
                alone = person_twin.lead_check(trials, fit, PERSON_FILTER)
                times["alone"].append(time.process_time() - t0)
            if together != alone:
                raise SystemExit(f"{name}: the checks differ: {together} against {alone}")
    for name, _, fit in people:
        print(f"{name}: {person_twin.lead_check(_of(people, name), fit, PERSON_FILTER).line}")
    for way, ts in times.items():
        print(
            f"{way:>8}: median {np.median(ts):.2f} s, p99 {np.percentile(ts, 99):.2f} s CPU a person ({len(ts)} checks)"
        )
    print(f"ratio alone / together (medians): {np.median(times['alone']) / np.median(times['together']):.2f}")


def _of(people, name: str):
    return next(trials for n, trials, _ in people if n == name)


if __name__ == "__main__":
    main()
