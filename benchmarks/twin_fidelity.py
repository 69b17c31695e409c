"""The person twin's verdicts against what the simulated person themself gives (issue 40).

    .venv/bin/python benchmarks/twin_fidelity.py RUN [--cells held-out] [--cutoffs 1.5,3,6] [--draws 4]

RUN is a ``coassist reproduce`` output folder, or a base folder of ``coassist compare-intents --source
person=person`` (``OUT/base-<seed>``). For each calibration draw of the cells named (``thesis``: the thesis cells'
calibrations, ``held-out``: the held-out cells', of whichever population the run drew there, ``varied``: a comparison's
on the varied population) and each
person in it, every fold of the twin check (:func:`coassist.sim.person_twin.lead_check`: each chosen-way trial
replayed with the model of the person's other trials, under MG and with the lead, carrying the twin's object) is
run three ways:

- **twin**: the check's own twin, its intent the trial's reconstruction low-passed at each of ``--cutoffs`` Hz (the
  first cutoff given should be the fit's, ``INTENT_SMOOTHING``, 1.5 Hz: the check as it ran);
- **true intent**: the twin pulled toward the trial's true intent (the simulation's ``Trial.intent``);
- **the person**: the simulated person themself (the profile the trial recorded: arm, reaction delay, noise, true
  intent) on the trial's task, seed and obstacle, with the same controllers and model, no sensor model.

Prints per (draw, person): each way's mean overshoot with the lead and under MG [mm] and in how many trials the lead
was worse, and the check's verdict for the twins (L led, x turned away: :func:`~coassist.sim.person_twin.
lead_verdict`). The last two read what only a simulation knows: a measure of the check, not something a lab can run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
from dataclasses import fields  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from coassist.control.presets import get_preset, make_controller  # noqa: E402
from coassist.data import read_dataset  # noqa: E402
from coassist.metrics import overshoot  # noqa: E402
from coassist.scenario.detours import family_from_extra  # noqa: E402
from coassist.scenario.objects import get_object  # noqa: E402
from coassist.scenario.operator import OperatorProfile  # noqa: E402
from coassist.scenario.person_intent import PersonPathsIntent  # noqa: E402
from coassist.scenario.person_model import (  # noqa: E402
    INTENT_SMOOTHING,
    PERSON_FILTER,
    asked_way,
    fit_people,
    intent_estimate,
    without_trial,
)
from coassist.scenario.tasks import OBSTACLES, task_for_seed  # noqa: E402
from coassist.sim.person_twin import (  # noqa: E402
    TWIN_CONTROLLER,
    TWIN_HORIZON,
    TWIN_OBJECT,
    lead_verdict,
    twin_overshoot,
)
from coassist.sim.trial_runner import build_trial, run_episodes_lockstep  # noqa: E402

#: The calibration datasets' names in a run, per cells (draw k > 0 adds ``-draw<k>``; asked trials ``-ask-…``).
CALIBRATIONS = {
    "thesis": "calibration-probe",
    "held-out": "calibration-probe-held-out",
    "varied": "calibration-probe-varied",
}


def profile_of(trial) -> OperatorProfile:
    """The simulated person a trial recorded (``meta.extra['operator']``, :meth:`OperatorProfile.to_extra`)."""
    extra = dict(trial.meta.extra.get("operator") or {})
    if not extra:
        raise SystemExit(f"trial {trial.meta.user} seed {trial.meta.seed}: no simulated operator recorded")
    names = {f.name for f in fields(OperatorProfile)}
    detour = extra.pop("detour", None)
    return OperatorProfile(
        **{k: v for k, v in extra.items() if k in names},
        detour=None if detour is None else family_from_extra(dict(detour)),
    )


def task_of(trial):
    """The trial's task, obstacle included (the named obstacle of the recorded size, checked where it stands)."""
    meta = trial.meta
    recorded = meta.extra["obstacle"]
    size = tuple(float(x) for x in recorded["size"])
    names = [name for name, (s, _) in OBSTACLES.items() if tuple(s) == size]
    if not names:
        raise SystemExit(f"trial seed {meta.seed}: an obstacle of size {size} is none of {tuple(OBSTACLES)}")
    motion = meta.extra.get("motion_time")
    task = task_for_seed(
        meta.task, int(meta.seed), obstacle=names[0], motion_time=None if motion is None else float(motion)
    )
    if np.max(np.abs(np.asarray(task.obstacle.center) - np.asarray(recorded["center"], dtype=float))) > 1e-9:
        raise SystemExit(f"trial seed {meta.seed}: the rebuilt task's obstacle is not where the trial's stood")
    return task


def person_overshoots(trials, chosen, models) -> tuple[np.ndarray, np.ndarray]:
    """The simulated person themself on each chosen trial's task and seed, under MG and with the fold's model
    (``models[i]``): overshoot past their true intent [mm], (lead, MG)."""
    builds = []
    for i, model in zip(chosen, models):
        trial = trials[i]
        profile, task = profile_of(trial), task_of(trial)
        preset = get_preset(str(trial.meta.extra["preset"]))
        for source in (None, model):

            def build(task=task, profile=profile, source=source, preset=preset, seed=int(trial.meta.seed)):
                controller = make_controller(TWIN_CONTROLLER if source is not None else "manual", preset)
                return build_trial(
                    task, profile, get_object(TWIN_OBJECT), controller, source, seed, preset_name=preset.name
                )

            builds.append(build)
    out = [0.0] * len(builds)

    def keep(i: int, trial) -> None:
        out[i] = 1000.0 * overshoot(trial.pose[:, :2], trial.intent[:, :2])

    run_episodes_lockstep([b() for b in builds], lambda i: builds[i](), keep)
    return np.asarray(out[1::2]), np.asarray(out[0::2])


def fidelity(run: Path, cells: str, cutoffs: list[float], draws: int) -> list[dict]:
    """Every (draw, person) of ``cells`` in ``run`` (module docstring): a row each, printed as it comes."""
    datasets = run / "datasets"
    rows = []
    for k in range(draws):
        name = CALIBRATIONS[cells] + ("" if k == 0 else f"-draw{k}")
        if not (datasets / name).is_dir():
            raise SystemExit(f"{datasets / name}: no such calibration in the run")
        folders = [datasets / name, *sorted(datasets.glob(name + "-ask-*"))]
        trials = [t for folder in folders for t in read_dataset(folder).trials]
        for user, fit in fit_people(trials).items():
            own = [t for t in trials if str(t.meta.user) == user]
            chosen = [i for i, t in enumerate(own) if asked_way(t) == 0]
            models = [
                PersonPathsIntent(
                    TWIN_HORIZON,
                    paths={user: without_trial(fit, own, i).paths},
                    arms={user: fit.arm},
                    settings=PERSON_FILTER,
                    model_id="twin",
                )
                for i in chosen
            ]
            row: dict = {"draw": k, "user": user}
            intents = {
                f"twin {hz:g} Hz": lambda t, hz=hz, arm=fit.arm: intent_estimate(t, arm, smoothing=hz)[1]
                for hz in cutoffs
            }
            intents["true intent"] = lambda t: np.asarray(t.intent[:, :2], dtype=float)
            for label, intent_of in intents.items():
                led, mg = [], []
                for i, model in zip(chosen, models):
                    q = intent_of(own[i])
                    pair = [twin_overshoot(own[i], q, fit.arm, source) for source in (None, model)]
                    if None in pair:  # a plan the twin cannot rebuild: the check itself leaves such a person led
                        raise SystemExit(f"{user}, draw {k}: trial {i + 1} cannot be replayed by the twin")
                    mg.append(1000.0 * pair[0])
                    led.append(1000.0 * pair[1])
                check = lead_verdict(np.asarray(led), np.asarray(mg))
                row[label] = {
                    "led": float(np.mean(led)),
                    "mg": float(np.mean(mg)),
                    "worse": check.worse,
                    "follow": check.follow,
                }
            led, mg = person_overshoots(own, chosen, models)
            row["the person"] = {"led": float(led.mean()), "mg": float(mg.mean()), "worse": int(np.sum(led > mg))}
            rows.append(row)
            print(
                f"draw {k} {user}: "
                + "  ".join(
                    f"{label} {'' if 'follow' not in v else ('L ' if v['follow'] else 'x ')}"
                    f"{v['led']:.1f}/{v['mg']:.1f} ({v['worse']})"
                    for label, v in row.items()
                    if isinstance(v, dict)
                ),
                flush=True,
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a coassist reproduce output folder")
    parser.add_argument("--cells", choices=sorted(CALIBRATIONS), default="held-out")
    parser.add_argument(
        "--cutoffs", default=f"{INTENT_SMOOTHING:g}", help="the twin's intent low-pass [Hz], comma-separated"
    )
    parser.add_argument("--draws", type=int, default=4, help="calibration draws to read (the run's: 4)")
    parser.add_argument("--json", type=Path, help="also write the rows here")
    args = parser.parse_args()
    try:
        cutoffs = [float(x) for x in args.cutoffs.split(",")]
    except ValueError:
        raise SystemExit(f"--cutoffs must be numbers [Hz] separated by commas, got {args.cutoffs!r}") from None
    if not cutoffs or any(not 0.1 <= hz <= 30.0 for hz in cutoffs):
        raise SystemExit(f"--cutoffs must each be in [0.1, 30] Hz, got {args.cutoffs!r}")
    if args.draws < 1:
        raise SystemExit(f"--draws must be >= 1, got {args.draws}")
    print("mean overshoot with the lead / under MG [mm] (trials where the lead was worse); L led, x turned away")
    rows = fidelity(args.run, args.cells, cutoffs, args.draws)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
