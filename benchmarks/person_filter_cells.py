"""The person filter's settings compared on the eight validation cells, paired trial by trial (issue 40).

    .venv/bin/python benchmarks/person_filter_cells.py OUT --variant NAME='{"field": value, ...}' [...]

The cells every filter change of docs/person-model.md was chosen on: the application scenario's trials on the
validation bases 50000 and 60000 (never a report's seeds), the thesis population's operators 0–2 and the varied
population's 0, 3, 4, 5, 7 and 8 (the two that limit-cycle with the board left out), four trials per operator,
object and base, both objects, the arbitrated controller: 144 paired trials. Each operator's person model is fitted
to the default preset's ``person_calibration_trials`` probe trials per calibration draw (``--probe-trials N``:
another count, into another OUT: docs/person-model.md's "Eight probe trials a person").

The reference is ``coassist compare-intents --source person=person`` on each cell (MG, the oracle, the four
calibration draws and the person model with :data:`~coassist.scenario.person_model.PERSON_FILTER`), written once
under ``OUT/ref/<population>-<base>`` and reused by later calls (with a line saying so where this tree's default
filter is not the one it ran). Each variant is the reference's calibration
draws with the ``filter`` fields of its JSON replaced (``PersonFilterSettings`` fields: a setting of the code in
this tree), run on the same trials into ``OUT/<NAME>/<population>-<base>``. A cell already done is not run
again (delete its folder to redo it).

Prints, per cell and object, each source's force share / overshoot share [95 %, (operator, calibration)
clusters] / jerk × MG, and per variant the paired differences from the reference over the 144 trials
(overshoot [mm], f_RMS [N], jerk RMS [m/s³]; 95 % cluster-robust Student-t intervals over the (cell, operator,
calibration draw) clusters: the trials of one calibration, both objects, share its person model, so they are not
144 independent pairs). Reads the simulated intent (the
overshoot): a measure of the filter in simulation.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import time  # noqa: E402
from dataclasses import asdict, fields, replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from coassist._io import read_hashed_json, write_hashed_json  # noqa: E402
from coassist.analysis.paired import clustered_difference, gain_share  # noqa: E402
from coassist.data import read_dataset  # noqa: E402
from coassist.experiments.ablation_cells import ARBITRATED  # noqa: E402
from coassist.experiments.application import OBJECTS, OBSTACLE, application_metrics, pair_key  # noqa: E402
from coassist.experiments.pipeline import Workspace  # noqa: E402
from coassist.experiments.precision import compare_intents  # noqa: E402
from coassist.experiments.reproduce_config import REPRODUCE_PRESETS  # noqa: E402
from coassist.experiments.seed_plan import application_seed  # noqa: E402
from coassist.scenario.calibration_draws import draw_clusters, draw_count  # noqa: E402
from coassist.scenario.person_intent import PersonFilterSettings  # noqa: E402
from coassist.scenario.person_model import PERSON_FILTER  # noqa: E402

#: (population, operators, base) of the eight cells (each with both objects).
CELLS = (
    ("thesis", (0, 1, 2), 50000),
    ("thesis", (0, 1, 2), 60000),
    ("varied", (0, 3, 4, 5, 7, 8), 50000),
    ("varied", (0, 3, 4, 5, 7, 8), 60000),
)
TRIALS = 4
PERSON_MODEL_FORMAT = "coassist-person-model-2"
#: What a reference written before the lead check kept its count may hold (read, written back as the current).
PERSON_MODEL_READS = (PERSON_MODEL_FORMAT, "coassist-person-model-1")


def _suffix(population: str) -> str:
    return "" if population == "thesis" else "-" + population


def _config(users, base: int, workers: int):
    return replace(
        REPRODUCE_PRESETS["default"],
        application_users=tuple(users),
        application_trials=TRIALS,
        ablation_mujoco_trials=0,
        workers=workers,
        seed=base,
    )


def _trials(folder: Path) -> list:
    return sorted(read_dataset(folder).trials, key=pair_key)


def _filter_of(recorded: str) -> PersonFilterSettings | None:
    """The filter a reference recorded, a setting added to the code since at its default (the same filter: a
    variant's new field must not make every cached reference look stale); None where it names a field the code
    no longer has or a value it refuses."""
    try:
        return PersonFilterSettings(**json.loads(recorded))
    except (TypeError, ValueError):
        return None


def run_reference(out: Path, population: str, users, base: int, workers: int, probes: int, asked: int = 0) -> Path:
    """The reference cell (compare_intents with the person model fitted to ``probes`` probe trials per operator and
    draw); its folder."""
    folder = out / "ref" / f"{population}-{base}"
    if (folder / "done").exists():
        # a reference run before the default changed is another filter's: the differences would be from that one
        ran = (folder / "filter.json").read_text() if (folder / "filter.json").exists() else None
        if ran is None or _filter_of(ran) != PERSON_FILTER:
            print(f"{folder}: run with another default filter than this tree's PERSON_FILTER; delete it to redo it")
        # (a reference from before the count was recorded had four)
        had = int((folder / "probe_trials").read_text()) if (folder / "probe_trials").exists() else 4
        if had != probes:
            print(
                f"{folder}: fitted to {had} probe trials per operator, not the {probes} asked for; delete it to redo it"
            )
        # (a reference from before ways could be asked for asked for none)
        was = int((folder / "asked_trials").read_text()) if (folder / "asked_trials").exists() else 0
        if was != asked:
            print(
                f"{folder}: its calibrations asked for up to {was} trials of a thin way, not {asked}; delete it to redo it"
            )
    else:
        start = time.time()
        compare_intents(
            {"person": "person"},
            folder,
            bases=(base,),
            users=users,
            population=population,
            workers=workers,
            progress=False,
            probe_trials=probes,
            asked_trials=asked,
        )
        (folder / "filter.json").write_text(json.dumps(asdict(PERSON_FILTER), sort_keys=True))
        (folder / "probe_trials").write_text(f"{probes}\n")
        (folder / "asked_trials").write_text(f"{asked}\n")
        (folder / "done").write_text(f"{time.time() - start:.0f} s wall\n")
    return folder


def run_variant(out: Path, name: str, override: dict, population: str, users, base: int, workers: int) -> Path:
    """A variant's person-model trials on the reference cell's trials and calibration draws; its folder."""
    ref = out / "ref" / f"{population}-{base}"
    folder = out / name / f"{population}-{base}"
    if (folder / "done").exists():
        return folder
    start = time.time()
    draws = folder / "draws"
    if draws.exists():
        shutil.rmtree(draws)
    shutil.copytree(ref / f"base-{base}" / "models" / f"person{_suffix(population)}-draws", draws)
    for path in sorted(draws.glob("draw-*/person-model.json")):
        doc = read_hashed_json(path, format=PERSON_MODEL_READS)
        doc["filter"].update(override)
        PersonFilterSettings(**doc["filter"])  # refuse a bad setting before anything runs
        write_hashed_json(path, doc, format=PERSON_MODEL_FORMAT)
    cfg = _config(users, base, workers)
    ws = Workspace(cfg, folder, False)
    for j, obj in enumerate(OBJECTS):
        ws.collect(
            f"{obj}-person{_suffix(population)}",
            tasks=(cfg.application_task,),
            users=cfg.application_users,
            objects=(obj,),
            trials=cfg.application_trials,
            seed=application_seed(base, j),
            controller=ARBITRATED,
            preset=cfg.application_preset,
            intent=str(draws),
            obstacle=OBSTACLE,
            population=population,
        )
    (folder / "done").write_text(f"{time.time() - start:.0f} s wall\n")
    return folder


def _share(values, name, mg, oracle, clusters) -> str:
    share, lo, hi = gain_share(
        mg[f"{name}_trials"], values[f"{name}_trials"], oracle[f"{name}_trials"], clusters=clusters
    )
    return f"{100 * share:.0f} [{100 * lo:.0f}, {100 * hi:.0f}]"


def report(out: Path, names: list[str], against: str = "ref") -> None:
    """The table (module docstring); each variant's paired differences are from ``against`` (the default or a
    variant)."""
    pooled: dict[str, dict[str, list[float]]] = {n: {"overshoot": [], "f_rms": [], "jerk_rms": []} for n in names}
    # each pooled pair's (cell, person, draw): the trials that share one person model (both objects)
    pooled_clusters: dict[str, list[tuple[str, str, int]]] = {n: [] for n in names}
    for population, _, base in CELLS:
        cell = f"{population}-{base}"
        ref = out / "ref" / cell
        if not (ref / "done").exists():
            continue
        data = ref / f"base-{base}" / "datasets"
        draws = draw_count(ref / f"base-{base}" / "models" / f"person{_suffix(population)}-draws")
        for obj in OBJECTS:
            name_of = {k: data / f"{obj}-{k}{_suffix(population)}" for k in ("MG", "oracle", "person")}
            base_trials = {k: _trials(v) for k, v in name_of.items()}
            keys = [pair_key(t) for t in base_trials["person"]]
            clusters = draw_clusters(keys, draws)
            m = {k: application_metrics(v) for k, v in base_trials.items()}
            values = {"ref": m["person"]}
            for n in names:
                folder = out / n / cell
                if (folder / "done").exists():
                    trials = _trials(folder / "datasets" / f"{obj}-person{_suffix(population)}")
                    if [pair_key(t) for t in trials] != keys:
                        raise SystemExit(f"{folder}: its trials are not the reference's")
                    values[n] = application_metrics(trials)
            line = [f"{cell} {obj}:"]
            for n, v in values.items():
                jerk = v["jerk_rms"] / m["MG"]["jerk_rms"]
                line.append(
                    f"{n} {_share(v, 'f_rms', m['MG'], m['oracle'], clusters)} / "
                    f"{_share(v, 'overshoot', m['MG'], m['oracle'], clusters)} / {jerk:.2f}"
                )
                if n != against and n != "ref" and against in values:
                    for metric in pooled[n]:
                        pooled[n][metric] += list(
                            np.subtract(v[f"{metric}_trials"], values[against][f"{metric}_trials"])
                        )
                    pooled_clusters[n] += [(cell, *c) for c in clusters]
            print("  ".join(line))
    for n in names:
        d = pooled[n]
        if not d["overshoot"]:
            continue
        parts = []
        for metric, scale, unit in (("overshoot", 1e3, "mm"), ("f_rms", 1.0, "N"), ("jerk_rms", 1.0, "m/s³")):
            mean, lo, hi, count = clustered_difference(
                scale * np.asarray(d[metric]), np.zeros(len(d[metric])), pooled_clusters[n]
            )
            parts.append(f"{metric} {mean:+.3f} [{lo:+.3f}, {hi:+.3f}] {unit}")
        print(
            f"{n} − {against} over {count} paired trials in {len(set(pooled_clusters[n]))} calibrations: "
            + ", ".join(parts)
        )


def compare_references(out: Path, other: Path) -> None:
    """Two references on the same trials with other calibrations (``--paired-with``): per cell and object each one's
    force share / overshoot share / jerk × MG, then the paired differences of ``out``'s person-model trials from
    ``other``'s over every cell both ran (overshoot [mm], f_RMS [N], jerk RMS [m/s³]; 95 % cluster-robust Student-t
    over the (cell, operator, draw) clusters of ``out``'s calibrations)."""
    pooled: dict[str, list[float]] = {"overshoot": [], "f_rms": [], "jerk_rms": []}
    pooled_clusters: list[tuple[str, str, int]] = []
    for population, _, base in CELLS:
        cell = f"{population}-{base}"
        folders = [o / "ref" / cell for o in (out, other)]
        if not all((f / "done").exists() for f in folders):
            continue
        line = [f"{cell}"]
        for obj in OBJECTS:
            got = []
            for f in folders:
                data = f / f"base-{base}" / "datasets"
                t = {k: _trials(data / f"{obj}-{k}{_suffix(population)}") for k in ("MG", "oracle", "person")}
                if [pair_key(x) for x in t["MG"]] != [pair_key(x) for x in t["person"]]:
                    raise SystemExit(f"{f}: its person trials are not its MG trials")
                got.append(t)
            if [pair_key(x) for x in got[0]["person"]] != [pair_key(x) for x in got[1]["person"]]:
                raise SystemExit(f"{cell} {obj}: the two references ran different trials")
            for t in got[1:]:
                for k in ("MG", "oracle"):  # the baselines do not depend on the calibration: the same trials
                    if application_metrics(t[k])["f_rms_trials"] != application_metrics(got[0][k])["f_rms_trials"]:
                        raise SystemExit(f"{cell} {obj}: the two references' {k} trials differ")
            draws = draw_count(folders[0] / f"base-{base}" / "models" / f"person{_suffix(population)}-draws")
            clusters = draw_clusters([pair_key(x) for x in got[0]["person"]], draws)
            m = [{k: application_metrics(v) for k, v in t.items()} for t in got]
            for name, mm in zip((out.name, other.name), m):
                line.append(
                    f"{obj} {name} {_share(mm['person'], 'f_rms', mm['MG'], mm['oracle'], clusters)} / "
                    f"{_share(mm['person'], 'overshoot', mm['MG'], mm['oracle'], clusters)} / "
                    f"{mm['person']['jerk_rms'] / mm['MG']['jerk_rms']:.2f}"
                )
            for metric in pooled:
                pooled[metric] += list(
                    np.subtract(m[0]["person"][f"{metric}_trials"], m[1]["person"][f"{metric}_trials"])
                )
            pooled_clusters += [(cell, *c) for c in clusters]
        print("  ".join(line))
    if pooled["overshoot"]:
        parts = []
        for metric, scale, unit in (("overshoot", 1e3, "mm"), ("f_rms", 1.0, "N"), ("jerk_rms", 1.0, "m/s³")):
            mean, lo, hi, count = clustered_difference(
                scale * np.asarray(pooled[metric]), np.zeros(len(pooled[metric])), pooled_clusters
            )
            parts.append(f"{metric} {mean:+.3f} [{lo:+.3f}, {hi:+.3f}] {unit}")
        print(
            f"{out.name} − {other.name} over {count} paired trials in {len(set(pooled_clusters))} calibrations: "
            + ", ".join(parts)
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--variant", action="append", default=[], help="NAME='{\"field\": value}' (repeatable)")
    parser.add_argument("--workers", type=int, default=2)
    default_probes = REPRODUCE_PRESETS["default"].person_calibration_trials
    parser.add_argument(
        "--probe-trials",
        type=int,
        default=default_probes,
        help=f"the reference's probe trials per operator and calibration draw (default {default_probes}, the main job's)",
    )
    default_asked = REPRODUCE_PRESETS["default"].person_calibration_asked
    parser.add_argument(
        "--asked-trials",
        type=int,
        default=default_asked,
        help=f"the most trials the reference's calibrations ask of an operator for a way shown too seldom (default "
        f"{default_asked}, the main job's)",
    )
    parser.add_argument(
        "--paired-with",
        type=Path,
        help="another OUT whose reference ran on the same trials with other calibrations (--probe-trials, "
        "--asked-trials): print both references' shares and the paired differences of this one from that one",
    )
    parser.add_argument("--report-only", action="store_true", help="print the table of what is already run")
    parser.add_argument("--against", default="ref", help="the paired differences from this: ref or a variant's NAME")
    args = parser.parse_args()
    if args.probe_trials < 1:
        raise SystemExit(f"--probe-trials must be >= 1, got {args.probe_trials}")
    known = {f.name for f in fields(PersonFilterSettings)}
    variants: dict[str, dict] = {}
    for spec in args.variant:
        name, sep, text = spec.partition("=")
        if not sep or not name or name == "ref" or "/" in name:
            raise SystemExit(f"--variant must be NAME=JSON with a NAME other than ref, got {spec!r}")
        try:
            override = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SystemExit(f"--variant {name}: not JSON ({exc})") from None
        if not isinstance(override, dict) or not set(override) <= known:
            raise SystemExit(
                f"--variant {name}: fields must be among PersonFilterSettings' ({', '.join(sorted(known))})"
            )
        PersonFilterSettings(**override)  # a bad value is refused here, naming the field
        variants[name] = override
    if not args.report_only:
        for population, users, base in CELLS:
            run_reference(args.out, population, users, base, args.workers, args.probe_trials, args.asked_trials)
            for name, override in variants.items():
                run_variant(args.out, name, override, population, users, base, args.workers)
            print(f"{population}-{base} done", flush=True)
    names = (
        list(variants) or sorted(p.name for p in args.out.iterdir() if p.is_dir() and p.name != "ref")
        if args.out.exists()
        else []
    )
    if args.against != "ref" and args.against not in names:
        names.insert(0, args.against)
    report(args.out, names, args.against)
    if args.paired_with is not None:
        compare_references(args.out, args.paired_with)


if __name__ == "__main__":
    main()
