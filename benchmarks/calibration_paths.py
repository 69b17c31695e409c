"""How many calibration paths a task the person model needs, and what their repeatability says (issue 40).

    .venv/bin/python benchmarks/calibration_paths.py [--configs small:2,small:3,small:4,small:8,large:2,large:8]
        [--users 0,1,2] [--trials 6] [--controller cooperative] [--filter '{"min_way_paths": 2}']

For each configuration (obstacle, probe trials): each simulated thesis operator records that many calibration trials
on the curved task under manual guidance with the probe (seeds 960000 + k), their person model is fitted
(:func:`coassist.scenario.person_model.fit_person`, the calibration's fit), and then ``--trials`` trials (seeds
970000 + k, the same obstacle class) run with MG, with ``present-held`` and with the person model, the controller
``--controller`` (a study's conditions use the plain cooperative game). The ``small`` obstacle is placed anywhere in
30–70 % of the plan and moves between trials, as a study's default plan draws it; the ``large`` one at 45–55 %.

Prints per operator the paths' repeatability (:meth:`coassist.scenario.path_model.PathModel.repeatability`, None
where no way round was taken twice), and each source's mean hand force f_RMS [N], overshoot [mm] and jerk RMS
[m/s³] over the trials, and the person model's and ``present-held``'s as ratios to MG's. ``--filter``: the person
model's filter settings changed from the default's (``PERSON_FILTER``; a JSON object of
:class:`~coassist.scenario.person_intent.PersonFilterSettings` fields). docs/person-model.md
("How far a person's paths repeat") has its table.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import curved_trial  # noqa: E402
from coassist.control.presets import CONTROLLERS  # noqa: E402
from coassist.metrics import f_rms, jerk_rms, overshoot  # noqa: E402
from coassist.scenario.intent_registry import load_intent_source  # noqa: E402
from coassist.scenario.person_intent import PersonPathsIntent  # noqa: E402
from coassist.scenario.person_model import PERSON_FILTER, fit_person  # noqa: E402
from coassist.scenario.populations import population_profile  # noqa: E402
from coassist.scenario.tasks import OBSTACLES  # noqa: E402

PROBE_SEED, TRIAL_SEED = 960000, 970000


def _measures(trial) -> tuple[float, float, float]:
    """f_RMS [N], overshoot [mm], jerk RMS [m/s³] of a simulated trial (its intent is known)."""
    return (
        f_rms(trial.wrench[:, :2]),
        1e3 * overshoot(trial.pose[:, :2], trial.intent[:, :2]),
        jerk_rms(trial.pose[:, :2], trial.meta.dt),
    )


def run_config(
    obstacle: str, probes: int, users: list[int], trials: int, controller: str, settings=PERSON_FILTER
) -> None:
    print(
        f"{obstacle} obstacle, {probes} probe trials (f_RMS N / overshoot mm / jerk m/s³; person and present-held × MG)"
    )
    for user in users:
        profile = population_profile("thesis", user, 0)
        cal = [curved_trial(profile, PROBE_SEED + k, "manual-probe", None, obstacle) for k in range(probes)]
        fit = fit_person(cal)
        r = fit.paths.repeatability()
        name = profile.name
        got: dict[str, list] = {"MG": [], "present-held": [], "person model": []}
        for k in range(trials):
            seed = TRIAL_SEED + k
            got["MG"].append(_measures(curved_trial(profile, seed, "manual", None, obstacle)))
            got["present-held"].append(
                _measures(curved_trial(profile, seed, controller, load_intent_source("present-held"), obstacle))
            )
            person = PersonPathsIntent(50, paths={name: fit.paths}, arms={name: fit.arm}, settings=settings)
            got["person model"].append(_measures(curved_trial(profile, seed, controller, person, obstacle)))
        means = {k: np.mean(v, axis=0) for k, v in got.items()}
        line = f"  user {user}: sides {fit.paths.sides.tolist()}, repeatability " + (
            "none" if r is None else f"{r:.2f}"
        )
        for k, m in means.items():
            line += f"; {k} {m[0]:.2f} / {m[1]:.2f} / {m[2]:.2f}"
        for k in ("person model", "present-held"):
            ratio = means[k] / means["MG"]
            line += f"; {k} × MG {ratio[0]:.2f} / {ratio[1]:.2f} / {ratio[2]:.2f}"
        print(line, flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", default="small:2,small:3,small:4,small:8,large:2,large:8")
    ap.add_argument("--users", default="0,1,2", help="thesis operators")
    ap.add_argument("--trials", type=int, default=6, help="trials per source and operator")
    ap.add_argument("--controller", default="cooperative", help="the assisting controller")
    ap.add_argument("--filter", default="{}", help="filter settings changed from the default's, a JSON object")
    args = ap.parse_args()
    try:
        changes = json.loads(args.filter)
        if not isinstance(changes, dict):
            raise ValueError("not a JSON object")
        settings = replace(PERSON_FILTER, **changes)
    except (ValueError, TypeError) as exc:
        ap.error(f"--filter: {exc}")
    configs = []
    for item in args.configs.split(","):
        obstacle, _, n = item.partition(":")
        if obstacle not in OBSTACLES or not n.isdigit() or not 1 <= int(n) <= 20:
            ap.error(f"--configs: {item!r} must be OBSTACLE:N, OBSTACLE one of {tuple(OBSTACLES)}, N in 1..20")
        configs.append((obstacle, int(n)))
    if args.controller not in CONTROLLERS:
        ap.error(f"--controller must be one of {tuple(CONTROLLERS)}")
    if args.trials < 1:
        ap.error("--trials must be >= 1")
    users = [int(u) for u in args.users.split(",")]
    for obstacle, n in configs:
        run_config(obstacle, n, users, args.trials, args.controller, settings)


if __name__ == "__main__":
    main()
