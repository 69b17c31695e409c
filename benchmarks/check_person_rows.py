"""The person model's rows, recorded once and compared after a change to its tick (issue 40: faster, the same rows).

    .venv/bin/python benchmarks/check_person_rows.py --record /tmp/person-rows.npz   # before the change
    .venv/bin/python benchmarks/check_person_rows.py --compare /tmp/person-rows.npz  # after: exit 1 on any difference

Each case fits one simulated operator's person model from probe trials (``--calibration`` of them, as
``bench_person.py``), runs one application trial with the person model (:data:`PERSON_FILTER`) in the loop
and keeps the feature windows it was given; then replays those windows through fresh sources and keeps
every row each ``predict`` returned: the person model with several filter settings (:data:`SETTINGS`: the
fitted filter, the defaults, the "mixture" and "offset" side rules, the naive ±20 cm search, no blend nor
smoothing, the mirror followed, curves far at 1 cm), the present estimate alone, the ``paths`` source (it
shares the hand force's filter) with the operator's shape, and the fitted filter on the windows with the
tool put 4 cm aside for a third of the trial (every curve far). The cases (:data:`CASES`): the bench's own
trial (thesis operator 1, the board), the heavy load, the handle, an operator of the varied population, and
a way the calibration never took.

``--compare`` re-fits, re-runs the trials in the loop (their windows must be the recorded ones) and
replays the *recorded* windows: every row must equal the recorded row bit for bit (``--rtol`` to
allow a relative difference instead). The file is not for committing: it holds one code version's rows.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from bench_common import RecordsWindows  # noqa: E402
from coassist.control.presets import get_preset, make_controller  # noqa: E402
from coassist.runtime.episode import run_episode  # noqa: E402
from coassist.scenario.objects import get_object  # noqa: E402
from coassist.scenario.path_hypotheses import PathHypothesesIntent, PersonShape  # noqa: E402
from coassist.scenario.person_intent import PersonFilterSettings, PersonPathsIntent  # noqa: E402
from coassist.scenario.person_model import PERSON_FILTER, fit_person  # noqa: E402
from coassist.scenario.populations import population_profile  # noqa: E402
from coassist.scenario.tasks import task_for_seed  # noqa: E402
from coassist.sim.trial_runner import build_trial  # noqa: E402

#: (label, population, user, population seed, object, trial seed, calibration: (first seed, trials) or None for
#: ``--calibration`` trials from the trial seed + 1000). "thesis-1-unseen": four calibration trials all went right,
#: the trial goes left (a way nobody took: the fitted filter's present-estimate rows there).
CASES = (
    ("thesis-1-board", "thesis", 1, 0, "board", 950000, None),
    ("thesis-1-heavy", "thesis", 1, 0, "heavy", 950001, None),
    ("thesis-2-handle", "thesis", 2, 0, "handle", 950002, None),
    ("varied-3-board", "varied", 3, 50000, "board", 950003, None),
    ("thesis-1-unseen", "thesis", 1, 0, "board", 950013, (951010, 4)),
)

#: The filter settings every case's windows are replayed through.
SETTINGS: dict[str, PersonFilterSettings] = {
    "fitted": PERSON_FILTER,
    "defaults": PersonFilterSettings(),
    "mixture": replace(PERSON_FILTER, side_rule="mixture"),
    "offset": replace(PERSON_FILTER, side_rule="offset", evidence_gap=0.0, hedge_lateral=True),
    "naive": replace(PERSON_FILTER, search_window=0.2),
    "no-blend": replace(PERSON_FILTER, blend_time=0.0, row_smoothing=0.0, residual_time=0.0),
    "mirror": replace(PERSON_FILTER, follow_mirror=True, object_yaw=False, reaction_lead=0.0),
    "tight": replace(PERSON_FILTER, max_offset=0.01),  # curves far from the tool, some or all
}


class _Recording(RecordsWindows, PersonPathsIntent):
    """The source in the loop, keeping the windows it was given."""


def run_case(population: str, user: int, population_seed: int, obj: str, seed: int, calibration: tuple[int, int]):
    """(windows (T, 1, F), context, the person model's source for filter settings, the operator) of one case."""
    preset = get_preset("thesis-application-damped")
    profile = population_profile(population, user, population_seed)
    trials = []
    for k in range(calibration[1]):
        s = calibration[0] + k
        trials.append(
            run_episode(
                build_trial(
                    task_for_seed("curved", s, obstacle="large"),
                    profile,
                    get_object("handle"),
                    make_controller("manual-probe", preset),
                    None,
                    s,
                    preset_name=preset.name,
                )
            )
        )
    fit = fit_person(trials)
    name = profile.name

    def source(settings: PersonFilterSettings) -> PersonPathsIntent:
        return PersonPathsIntent(50, paths={name: fit.paths}, arms={name: fit.arm}, settings=settings)

    recorder = _Recording(50, paths={name: fit.paths}, arms={name: fit.arm}, settings=PERSON_FILTER)
    run_episode(
        build_trial(
            task_for_seed("curved", seed, obstacle="large"),
            profile,
            get_object(obj),
            make_controller("cooperative-arbitrated", preset),
            recorder,
            seed,
            preset_name=preset.name,
        )
    )
    return np.asarray(recorder.windows), recorder.context, source, profile


def replay_rows(source: PersonPathsIntent, context, windows: np.ndarray) -> np.ndarray:
    source.reset(context)
    return np.asarray([np.array(source.predict(w), dtype=float) for w in windows])


def _shifted(windows: np.ndarray) -> np.ndarray:
    """The windows with the tool 4 cm to the side (+y) through the trial's middle third: far from every curve."""
    out = windows.copy()
    third = len(out) // 3
    out[third : 2 * third, :, 1] += 0.04
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--record", metavar="NPZ")
    mode.add_argument("--compare", metavar="NPZ")
    parser.add_argument("--calibration", type=int, default=10)
    parser.add_argument("--rtol", type=float, default=0.0, help="relative difference allowed (0: bit for bit)")
    args = parser.parse_args()
    ref = np.load(args.compare) if args.compare else None
    out: dict[str, np.ndarray] = {}
    bad = 0
    for label, population, user, population_seed, obj, seed, calibration in CASES:
        calibration = calibration or (seed + 1000, args.calibration)
        windows, context, source, profile = run_case(population, user, population_seed, obj, seed, calibration)
        if ref is not None:
            recorded = ref[f"{label}/windows"]
            same = windows.shape == recorded.shape and np.array_equal(windows, recorded)
            print(f"{label}: {len(windows)} ticks in the loop, windows {'the same' if same else 'DIFFER'}")
            bad += not same
            windows = recorded
        out[f"{label}/windows"] = windows
        sources = {k: source(s) for k, s in SETTINGS.items()}
        sources["present"] = PersonPathsIntent(50, model_id="present")
        # the ``paths`` source shares the hand force's filter (coassist.scenario.hand_force)
        shape = PersonShape(profile.clearance, profile.anticipation, profile.left_preference, 4)
        sources["paths"] = PathHypothesesIntent(50, default=shape)
        sources["shifted"] = source(PERSON_FILTER)
        for key, src in sources.items():
            rows = replay_rows(src, context, _shifted(windows) if key == "shifted" else windows)
            out[f"{label}/{key}"] = rows
            if ref is None:
                continue
            want = ref[f"{label}/{key}"]
            if args.rtol > 0.0:
                ok = np.allclose(rows, want, rtol=args.rtol, atol=0.0)
            else:
                ok = np.array_equal(rows, want)
            diff = np.abs(rows - want)
            rel = float(np.max(diff / np.maximum(np.abs(want), 1e-300)))
            print(
                f"  {key:10s} {rows.shape}: {'same' if ok else 'DIFFERENT'} (max |Δ| {diff.max():.3g} m, rel {rel:.3g})"
            )
            bad += not ok
    if args.record:
        np.savez_compressed(args.record, **out)
        print(f"recorded {len(out)} arrays to {args.record}")
    elif bad:
        print(f"{bad} differences")
        sys.exit(1)
    else:
        print("every row the same")


if __name__ == "__main__":
    main()
