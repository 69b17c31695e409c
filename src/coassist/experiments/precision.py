"""Intent sources compared in the loop on validation seeds (issue 34): the tables docs/precision.md shows.

The application scenario's trials (the curved path, the large obstacle, operators 0, 1 and 2,
the board and the heavy load) on seeds the report never uses:
``application_seed(base, j)`` for each ``base`` given (50000 and 60000 in docs/precision.md:
disjoint trial seeds), every source with the same controller, paired against MG and the oracle on
the same trials, as the report's ablation pairs them
(:class:`~coassist.experiments.ablation_cells.AblationResult`: shares of the oracle's benefit, overshoot
and clearance deficit per side of the detour). ``paths`` needs a calibration: with
``calibrate=True`` the operators' calibration trials of each base
(``calibration_seed(base)``) are collected and fitted first
(:func:`~coassist.experiments.source_training.calibrate_paths`), one calibration per base.

:func:`compare_intents` runs it; ``coassist compare-intents`` is its command.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from coassist._checks import is_integer
from coassist.experiments.ablation_cells import ARBITRATED, DAMPED, SIDES, AblationResult
from coassist.experiments.ablation_report import seeds_text, share_text
from coassist.experiments.application import OBJECTS, OBSTACLE, application_metrics, pair_key
from coassist.experiments.pipeline import Workspace
from coassist.experiments.reproduce_config import REPRODUCE_PRESETS
from coassist.experiments.seed_plan import RUN_SEED_STRIDE, application_seed, calibration_seed
from coassist.experiments.source_training import calibrate_paths, calibrate_person
from coassist.scenario.calibration_draws import draw_clusters, draw_count
from coassist.scenario.populations import POPULATIONS

#: The offsets (base mod RUN_SEED_STRIDE) a validation base may have: its calibration trials
#: (base + 880000 …) and application trials (base + 900000 … + 1000 + trials) then stay clear of every
#: run's collections (offsets up to 902000) and of the next run's block.
VALIDATION_BASES = (25_000, 95_000)
#: The controllers a source may be compared with: the arbitrated one (the default), the damped one, and
#: the plain cooperative game (α fixed: the default controller of drive, ros2, play and collect).
COMPARED_CONTROLLERS = (ARBITRATED, DAMPED, "cooperative")

#: The populations a comparison may run (the sources are tuned on these): never the held-out one.
TUNING_POPULATIONS = ("thesis", "varied")

__all__ = ["TUNING_POPULATIONS", "compare_intents", "comparison_table"]


def compare_intents(
    sources: Mapping[str, str],
    out: str | Path,
    *,
    bases: Sequence[int] = (50000, 60000),
    controllers: Mapping[str, str] | None = None,
    trials: int = 4,
    users: Sequence[int] = (0, 1, 2),
    calibrate: bool = True,
    workers: int = 2,
    progress: bool = True,
    population: str = "thesis",
    probe_trials: int | None = None,
    asked_trials: int | None = None,
) -> AblationResult:
    """Every source of ``sources`` (label → intent: a named source, a model folder, a calibration folder or
    ``"paths"`` / ``"person"`` to use each base's fitted calibration / person models) on the validation trials
    of ``bases``, with the arbitrated controller or ``controllers[label]`` (one of :data:`COMPARED_CONTROLLERS`);
    MG and the oracle on the same trials (the arbitrated controller's; also the plain game's where a source runs
    with it: a share is measured against the oracle of its own controller, the damped one's against the arbitrated).
    ``population``: the simulated operators (:data:`TUNING_POPULATIONS`: the thesis population or ``varied``, the
    in-family one to tune on; never ``held-out`` nor ``unseen``, which only the report runs). ``probe_trials``: each operator's
    probe trials per calibration draw for ``person`` (default the main job's ``person_calibration_trials``);
    ``asked_trials``: the most trials each calibration then asks of an operator for a way round shown too seldom
    (default the main job's ``person_calibration_asked``). Datasets
    go under ``out``. The
    result is keyed like the ablation's (world "point-mass", controller, label), the bases' trials pooled in one
    cell."""
    if not sources:
        raise ValueError("compare_intents needs at least one source")
    if population not in TUNING_POPULATIONS:
        kept = " (it is kept out of everything tuned and used only to report)" if population in POPULATIONS else ""
        raise ValueError(f"population must be one of {', '.join(TUNING_POPULATIONS)}, got {population!r}{kept}")
    if probe_trials is not None and (not is_integer(probe_trials) or probe_trials < 1):
        raise ValueError(f"probe_trials must be an integer >= 1, got {probe_trials!r}")
    if not bases or len(set(bases)) != len(bases) or any(int(b) < 0 for b in bases):
        raise ValueError(f"bases must be distinct seeds >= 0, got {bases!r}")
    off = [b for b in bases if not VALIDATION_BASES[0] <= int(b) % RUN_SEED_STRIDE <= VALIDATION_BASES[1]]
    if off:
        raise ValueError(
            f"bases {off}: a validation base must be {VALIDATION_BASES[0]}–{VALIDATION_BASES[1]} past a multiple "
            f"of {RUN_SEED_STRIDE} (e.g. 50000), so that its trials are no run's own (the report's seeds)"
        )
    from coassist.control.presets import get_preset
    from coassist.interfaces import FEATURES
    from coassist.scenario.assistance import check_person_tasks, check_person_world
    from coassist.scenario.intent_registry import load_intent_source

    task = REPRODUCE_PRESETS["default"].application_task
    dt = float(get_preset(REPRODUCE_PRESETS["default"].application_preset).impedance.dt)  # the compared loop's
    for label, spec in sources.items():  # refuse a bad source before anything runs
        if spec not in ("paths", "person"):
            try:
                loaded = load_intent_source(spec, horizon=50)
                # a person model of another task or world: its rows would be the present estimate held, or its
                # filter another world's, under its label
                check_person_tasks(
                    loaded,
                    (task,),
                    spec,
                    fix=f"calibrate on the application's task (--tasks {task}), or compare person",
                )
                check_person_world(loaded, "sim", "point-mass", spec)
                model = getattr(loaded, "model", None)
                if model is not None:  # a network of other features or another rate: refused now, not after the
                    # baselines' datasets were simulated (a review, 2026-12-07)
                    model.check_compatible(FEATURES, dt, what="the simulated loop")
            except ValueError as exc:
                raise ValueError(f"source {label}: {exc}") from None
    controllers = dict(controllers or {})
    unknown = set(controllers) - set(sources)
    if unknown:
        raise ValueError(f"controllers names sources that are not compared: {sorted(unknown)}")
    bad = {k: v for k, v in controllers.items() if v not in COMPARED_CONTROLLERS}
    if bad:
        raise ValueError(f"controllers must be one of {', '.join(map(repr, COMPARED_CONTROLLERS))}, got {bad}")
    reserved = {"MG", "oracle", "oracle-cooperative"} & set(sources)
    if reserved:
        raise ValueError(f"source labels {sorted(reserved)} are taken by the baselines every comparison runs")
    out = Path(out)
    cfg = replace(
        REPRODUCE_PRESETS["default"],
        application_users=tuple(users),
        application_trials=int(trials),
        ablation_mujoco_trials=0,  # the comparison runs the point-mass world only
        workers=int(workers),
    )
    if probe_trials is not None:
        cfg = replace(cfg, person_calibration_trials=int(probe_trials))
    if asked_trials is not None:
        cfg = replace(cfg, person_calibration_asked=asked_trials)  # the config refuses a bad count, naming it
    cells: dict[tuple[str, str, str], list] = {}
    groups: dict[tuple[str, str, str], list] = {}  # each trial's (base, operator, calibration draw)
    drawn: dict[tuple[str, str, str], set[int]] = {}  # the draws each cell's sources held
    calibrations: dict[str, str] = {}
    for base in bases:
        ws = Workspace(replace(cfg, seed=int(base)), out / f"base-{base}", progress)
        # the operators' calibration trials only where a source needs them
        fit = calibrate and "paths" in sources.values()
        paths = calibrate_paths(ws, seed=calibration_seed(int(base)), population=population) if fit else "paths"
        if fit:
            calibrations[str(base)] = paths
        if calibrate and "person" in sources.values():
            calibrations[f"{base}/person"] = calibrate_person(
                ws, seed=calibration_seed(int(base)), population=population, draws=cfg.calibration_draws
            )
        # (dataset name, label, controller, intent): the plain game's oracle under its own name
        plan = [("MG", "MG", "manual", "nominal"), ("oracle", "oracle", ARBITRATED, "oracle")]
        if "cooperative" in controllers.values():
            plan.append(("oracle-cooperative", "oracle", "cooperative", "oracle"))
        plan += [
            (
                label,
                label,
                controllers.get(label, ARBITRATED),
                {"paths": paths, "person": calibrations.get(f"{base}/person", spec)}.get(spec, spec),
            )
            for label, spec in sources.items()
        ]
        for j, obj in enumerate(OBJECTS):
            for name, label, controller, intent in plan:
                _, ds = ws.collect(
                    f"{obj}-{name}{'' if population == 'thesis' else '-' + population}",
                    tasks=(cfg.application_task,),
                    users=cfg.application_users,
                    objects=(obj,),
                    trials=cfg.application_trials,
                    seed=application_seed(int(base), j),
                    controller=controller,
                    preset=cfg.application_preset,
                    intent=intent,
                    obstacle=OBSTACLE,
                    population=population,
                )
                ordered = sorted(ds.trials, key=pair_key)
                cells.setdefault((obj, label, controller), []).extend(ordered)
                draws = draw_count(intent)
                # a calibration's draws are this base's: the clusters are (base, operator, draw)
                groups.setdefault((obj, label, controller), []).extend(
                    (base, *c) for c in draw_clusters([pair_key(t) for t in ordered], draws)
                )
                drawn.setdefault((obj, label, controller), set()).add(draws)
    metrics, mg, pairs, clusters = {}, {}, {}, {}
    for (obj, label, controller), trials_ in cells.items():
        if label == "MG":
            mg[("point-mass", obj)] = application_metrics(trials_)
            pairs[("point-mass", obj)] = [pair_key(t) for t in trials_]
            continue
        if [pair_key(t) for t in trials_] != pairs[("point-mass", obj)]:
            raise RuntimeError(f"{obj}/{label} did not meet MG's trials")
        metrics[("point-mass", obj, controller, label)] = application_metrics(trials_)
        if drawn[(obj, label, controller)] != {1}:  # the labels were gathered in the trials' order
            clusters[("point-mass", obj, controller, label)] = groups[(obj, label, controller)]
    errors: dict[tuple[str, str, str, str], dict[int, dict[str, float]]] = {key: {} for key in metrics}
    models = {f"paths@{base}": folder for base, folder in calibrations.items()}
    return AblationResult(metrics, mg, pairs, models, {}, cfg.application_preset, errors, clusters)


def comparison_table(result: AblationResult) -> str:
    """A markdown table per object: MG, then every compared cell (f_RMS, force share, overshoot per side and
    its share, clearance deficit per side with the paired difference from MG, jerk against MG's, σ)."""
    lines = []
    for obj in OBJECTS:
        m = result.mg[("point-mass", obj)]
        side = np.asarray(m["side"])
        n = {s: int((side == s).sum()) for s in SIDES}
        lines += [
            f"**{obj}** ({len(side)} paired trials: {n[1]} left, {n[-1]} right of the path)",
            "",
            "| source | controller | f_RMS [N] | force share | overshoot L / R [mm] | overshoot share | "
            "clearance deficit L / R [mm] (vs MG, 95 %) | jerk RMS [m/s³] | σ [mm] |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]

        def sided(values: Any, side: np.ndarray = side) -> str:
            v = np.asarray(values, float)
            return " / ".join(f"{1e3 * np.nanmean(v[side == s]):.1f}" for s in SIDES if (side == s).any())

        lines.append(
            f"| MG | manual | {m['f_rms']:.2f} | | {sided(m['overshoot_trials'])} | | "
            f"{sided(m['clearance_deficit_trials'])} | {m['jerk_rms']:.2f} | {1e3 * m['sigma']:.2f} |"
        )
        for (world, o, controller, label), r in result.metrics.items():
            if o != obj:
                continue
            cd = result.by_side(world, obj, controller, label, "clearance_deficit")
            clear = " / ".join(
                f"{1e3 * v[0]:.1f} ({1e3 * v[1]:+.1f} [{1e3 * v[2]:+.1f}, {1e3 * v[3]:+.1f}])"
                if v[4] >= 2
                else (f"{1e3 * v[0]:.1f}" if v[4] else "—")
                for v in cd.values()
            )
            lines.append(
                f"| {label} | {controller} | {r['f_rms']:.2f} | "
                f"{seeds_text(result, world, obj, controller, label, 'f_rms')} | {sided(r['overshoot_trials'])} | "
                f"{share_text(result.shares(world, obj, controller, label)['overshoot'])} | {clear} | "
                f"{r['jerk_rms']:.2f} ({r['jerk_rms'] / m['jerk_rms']:.2f}×) | {1e3 * r['sigma']:.2f} |"
            )
        lines.append("")
    return "\n".join(lines)
