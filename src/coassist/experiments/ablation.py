"""The in-loop ablation of intent sources (issue 18): which prediction makes assistance better?

Every intent source drives the same assistive controllers on the same trials of the
application scenario (the report's seeds, :func:`~coassist.experiments.pipeline.application_seed`),
paired against manual guidance (MG) on those trials, in two worlds: the point-mass world
and the MuJoCo UR5 (``coassist drive``'s world; fewer trials, the intervals say what they
resolve). The sources:

- ``nominal``: the robot's own plan as the intent (the thesis' M0 assumption, eq. 4.7);
- ``constant-velocity``: the tool's constant-velocity extrapolation;
- ``ridge``: the validation-tuned ridge (the ``linear`` preset), trained on the tool's future;
- ``lstm-tool``: the LSTM+FC of the simulated stages trained on the tool's future (the thesis);
- ``lstm-hand-alone``: the same network trained on the path the hand alone would have
  produced (the robot's effort removed through the known impedance, ``label="hand_alone"``);
- ``lstm-intent``: the same network trained on the simulated operator's true intent
  (``label="intent"``; simulation only: real recordings have no intent label);
- ``oracle``: the operator's true intent itself, the best any predictor could do.

Every learned source is trained from scratch on the same datasets by the same protocol; only
the label differs, and the ridge's model class (:mod:`coassist.experiments.intent_sources`,
trained in the application stage, whose assistive rows use one of them and are reused here).

Per cell (world, object, controller, source): :func:`~coassist.experiments.application.application_metrics`,
and the **share of the oracle's benefit** for force and for overshoot::

    share = mean_i(MG_i − X_i) / mean_i(MG_i − oracle_i)

over the paired trials i, with a 95 % percentile bootstrap interval over trials
(:func:`oracle_share`). 1 is everything the oracle gains over MG; 0 nothing; below 0 worse
than MG.
"""

from __future__ import annotations

import os
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

import numpy as np

from coassist.experiments.application import (
    OBJECTS,
    OBSTACLE,
    _pair_key,
    application_metrics,
    cell_options,
    paired_difference,
)
from coassist.experiments.intent_sources import LEARNED
from coassist.experiments.pipeline import EVAL_HORIZONS, Workspace, application_seed, in_loop_errors
from coassist.experiments.report import Claim, Section

SOURCES = ("nominal", "constant-velocity", "ridge", "lstm-tool", "lstm-hand-alone", "lstm-intent", "oracle")
CONTROLLERS = ("cooperative", "cooperative-arbitrated")
WORLDS = ("point-mass", "mujoco")
#: Issue 18's bar: a learned predictor in the loop gets this share of the oracle's benefit over MG.
ORACLE_SHARE_BAR = 0.8
#: Bootstrap resamples of the share's interval (seeded: the same run gives the same interval).
BOOTSTRAP = 2000


def oracle_share(mg, x, oracle, *, seed: int = 0, confidence: float = 0.95) -> tuple[float, float, float]:
    """(share, low, high): mean(MG − X) / mean(MG − oracle) over paired trials, with a percentile
    bootstrap interval (trials resampled with replacement, ``BOOTSTRAP`` times, seeded).

    ``mg``, ``x``, ``oracle``: per-trial values of one metric on the same trials, same order.
    Trials where any of the three is non-finite are left out. NaN when the oracle gains
    nothing on average (the share is undefined) or no trial is left.
    """
    mg, x, oracle = (np.asarray(v, dtype=float) for v in (mg, x, oracle))
    if not mg.shape == x.shape == oracle.shape or mg.ndim != 1:
        raise ValueError(f"paired values need one shape (n,), got {mg.shape}, {x.shape}, {oracle.shape}")
    ok = np.isfinite(mg) & np.isfinite(x) & np.isfinite(oracle)
    gain_x, gain_o = (mg - x)[ok], (mg - oracle)[ok]
    nan = float("nan")
    if gain_x.size == 0 or gain_o.mean() == 0.0:
        return nan, nan, nan
    share = float(gain_x.mean() / gain_o.mean())
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, gain_x.size, (BOOTSTRAP, gain_x.size))
    denom = gain_o[idx].mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        boot = gain_x[idx].mean(axis=1) / denom
    boot = boot[np.isfinite(boot)]
    if boot.size < BOOTSTRAP // 2:  # the oracle's gain is too often zero in a resample: no interval
        return share, nan, nan
    lo, hi = np.quantile(boot, [(1 - confidence) / 2, (1 + confidence) / 2])
    return share, float(lo), float(hi)


@dataclass(frozen=True)
class AblationResult:
    """metrics[(world, object, controller, source)] and mg[(world, object)]: :func:`application_metrics`;
    pairs[(world, object)]: the (operator, seed) of every trial, in the order all cells share;
    models: the learned sources' model folders; skipped: world → why it did not run."""

    metrics: dict[tuple[str, str, str, str], dict[str, Any]]
    mg: dict[tuple[str, str], dict[str, Any]]
    pairs: dict[tuple[str, str], list[tuple[str, int]]]
    models: dict[str, str]
    skipped: dict[str, str]
    preset: str
    #: errors[(world, object, controller, source)][h] = {"tool": e_RMS against the measured future pose,
    #: "intent": against the operator's true intent} [m] of the predictions the loop used, h in samples.
    errors: dict[tuple[str, str, str, str], dict[int, dict[str, float]]]

    def shares(self, world: str, obj: str, controller: str, source: str) -> dict[str, tuple[float, float, float]]:
        """The share of the oracle's benefit for force and for overshoot (:func:`oracle_share`); each
        cell's bootstrap runs once (the summary, the section and the first screen all ask)."""
        key = (world, obj, controller, source)
        cache = self.__dict__.setdefault("_shares", {})  # frozen: the cache is not a field
        if key not in cache:
            cache[key] = self._shares_of(*key)
        return cache[key]

    def _shares_of(self, world: str, obj: str, controller: str, source: str) -> dict[str, tuple[float, float, float]]:
        mg = self.mg[(world, obj)]
        x = self.metrics[(world, obj, controller, source)]
        o = self.metrics[(world, obj, controller, "oracle")]
        return {m: oracle_share(mg[f"{m}_trials"], x[f"{m}_trials"], o[f"{m}_trials"])
                for m in ("f_rms", "overshoot")}  # fmt: skip

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {"preset": self.preset, "models": self.models, "skipped": self.skipped, "cells": {},
                               "pairs": {f"{w}/{o}": p for (w, o), p in self.pairs.items()},
                               "mg": {f"{w}/{o}": {k: v for k, v in m.items() if not k.endswith("_trials")}
                                      for (w, o), m in self.mg.items()}}  # fmt: skip
        for (world, obj, controller, source), r in self.metrics.items():
            sh = self.shares(world, obj, controller, source)
            out["cells"][f"{world}/{obj}/{controller}/{source}"] = {
                **{k: v for k, v in r.items() if not k.endswith("_trials")},
                "oracle_share_force": sh["f_rms"], "oracle_share_overshoot": sh["overshoot"],
                "prediction_errors": self.errors[(world, obj, controller, source)],
            }
        return out


def run_ablation(ws: Workspace, models: dict[str, str], known: dict[tuple[str, str, str], list] | None = None,
                 ) -> AblationResult:  # fmt: skip
    """Run every cell in both worlds with the learned sources' ``models`` (source → model folder,
    :func:`~coassist.experiments.intent_sources.train_sources`).

    ``known``: (object, controller, source) → trials the application stage already ran with the
    same seeds, settings and model (its MG trials under ``(object, "manual", "nominal")`` and its
    assistive rows under the application's source); those cells reuse them instead of running
    them again. Without them every cell, MG's included, is collected here."""
    cfg = ws.config
    intents = {s: models.get(s, s) for s in SOURCES}
    known = known or {}
    metrics, mg, pairs, skipped, errors = {}, {}, {}, {}, {}
    for j, obj in enumerate(OBJECTS):

        def collect(name: str, controller: str, intent: str, j: int = j, obj: str = obj):
            _, ds = ws.collect(name, **cell_options(cfg, j, obj, controller, intent))
            return sorted(ds.trials, key=_pair_key)

        base = known.get((obj, "manual", "nominal"))
        base = collect(f"ablation-{obj}-manual", "manual", "nominal") if base is None else sorted(base, key=_pair_key)
        mg[("point-mass", obj)] = application_metrics(base)
        pairs[("point-mass", obj)] = [_pair_key(t) for t in base]
        for controller in CONTROLLERS:
            for source in SOURCES:
                trials = known.get((obj, controller, source))
                if trials is None:
                    trials = collect(f"ablation-{obj}-{controller}-{source}", controller, intents[source])
                trials = sorted(trials, key=_pair_key)
                if [_pair_key(t) for t in trials] != pairs[("point-mass", obj)]:
                    raise RuntimeError(f"ablation cell {obj}/{controller}/{source} did not meet MG's trials")
                metrics[("point-mass", obj, controller, source)] = application_metrics(trials)
                errors[("point-mass", obj, controller, source)] = prediction_errors_against_intent(trials)
    why = _mujoco_unavailable()
    if why is None and cfg.ablation_mujoco_trials > 0:
        _run_mujoco(ws, intents, metrics, mg, pairs, errors)
    else:
        skipped["mujoco"] = why or "reproduce.ablation_mujoco_trials is 0"
    return AblationResult(metrics, mg, pairs, models, skipped, cfg.application_preset, errors)


class AblationAhead:
    """Puts the ablation's simulations on the run's pool before the ablation stage asks for them.

    Called with the learned sources written so far (source → model folder; the application
    stage calls it while the sources train, :func:`~coassist.experiments.application.run_application`'s
    ``ahead``), it starts every cell whose source can run and has not started yet: the named
    sources' at the first call, each learned source's once it is written. The point-mass cells
    are prefetched datasets (:meth:`Workspace.prefetch`, the same options as :func:`run_ablation`'s
    collections: the same trials bit for bit), the MuJoCo UR5's one lockstep job per source
    (:meth:`Workspace.submit`). ``reused``: the (object, controller, source) cells the
    application stage collects and hands to :func:`run_ablation` as ``known``; not started here.
    """

    def __init__(self, ws: Workspace, reused: set[tuple[str, str, str]]) -> None:
        self.ws, self.reused = ws, set(reused)
        self.started: set[str] = set()
        cfg = ws.config
        self.mujoco = _mujoco_unavailable() is None and cfg.ablation_mujoco_trials > 0

    def __call__(self, models: dict[str, str], only: Collection[str] | None = None) -> None:
        """Start what ``models`` lets run and has not started; ``only``: of these sources (and
        :data:`MG_JOB`) alone, so that a caller can spread the work over its own idle spells."""
        cfg = self.ws.config
        intents = {s: models.get(s, s) for s in SOURCES if s in models or s not in LEARNED}
        for source in [s for s in (MG_JOB, *SOURCES) if s not in self.started and (s == MG_JOB or s in intents)
                       and (only is None or s in only)]:
            self.started.add(source)
            for j, obj in enumerate(OBJECTS):
                cells = [("manual", "nominal")] if source == MG_JOB else [(c, source) for c in CONTROLLERS]
                for controller, src in cells:
                    if (obj, controller, src) in self.reused:
                        continue
                    name = f"ablation-{obj}-manual" if source == MG_JOB else f"ablation-{obj}-{controller}-{src}"
                    self.ws.prefetch(name, **cell_options(cfg, j, obj, controller, intents.get(src, src)))
            if self.mujoco:
                job = _mujoco_jobs(cfg, {**{s: s for s in SOURCES}, **intents})[source]
                self.ws.submit(f"mujoco:{source}", _drive_batch, [c for _, configs in job for c in configs])


def prediction_errors_against_intent(trials, horizons=EVAL_HORIZONS) -> dict[int, dict[str, float]]:
    """e_RMS per horizon of the predictions the loop used, against the measured future pose
    ("tool", eq. 5.6) and against the operator's true intent ("intent"), pooled over the
    trials' scored ticks [m] (:func:`~coassist.experiments.pipeline.in_loop_errors`)."""
    trials = [t for t in trials if t.intent is not None]  # both columns over the same ticks
    tool, intent = (in_loop_errors(trials, horizons, against=a) for a in ("pose", "intent"))
    return {int(h): {"tool": tool[h]["e_rms"], "intent": intent[h]["e_rms"]} for h in tool}


def _mujoco_unavailable() -> str | None:
    """Why the MuJoCo UR5 cannot run here (None when it can): the robot extra is optional."""
    try:
        import mujoco  # noqa: F401
        import pinocchio  # noqa: F401
    except ImportError as exc:
        return f"the MuJoCo UR5 needs the robot extra (pip install coassist[robot]): {exc}"
    return None


def _mujoco_configs(cfg, obj: str, seed0: int, controller: str, intent: str) -> list:
    from coassist.robot.drive import DriveConfig
    from coassist.sim.collect import dataset_specs

    # The first trials of each operator in the point-mass cells (the same seeds: the same task and intent draws).
    specs = dataset_specs(controller=controller, users=cfg.application_users, tasks=(cfg.application_task,),
                          objects=(obj,), trials=cfg.application_trials, seed=seed0, preset=cfg.application_preset,
                          obstacle=OBSTACLE)  # fmt: skip
    return [DriveConfig(world="mujoco", controller=controller, task=s.task, object=obj, preset=s.preset, intent=intent,
                        user=s.user, seed=s.seed, obstacle=s.obstacle)  # fmt: skip
            for n, s in enumerate(specs) if n % cfg.application_trials < cfg.ablation_mujoco_trials]


def _drive_batch(configs: list) -> list[tuple[dict, dict]]:
    """A worker's MuJoCo runs, in lockstep (one network call per tick for those sharing a model;
    spawned process, one torch thread like the simulator's workers)."""
    import torch

    from coassist.robot.drive import drive_lockstep

    torch.set_num_threads(1)
    return [(t.meta.to_dict(), {n: getattr(t, n) for n in ("time", "pose", "velocity", "wrench", "reference",
                                                          "prediction", "intent", "effort_h", "effort_r")})
            for t in drive_lockstep(configs)]  # fmt: skip


#: The MuJoCo job of MG's trials (its cells have no intent source).
MG_JOB = "nominal-mg"


def _mujoco_jobs(cfg, intents: dict[str, str]) -> dict[str, list[tuple[tuple[str, str, str], list]]]:
    """One job per intent source (and MG's, :data:`MG_JOB`): its cells (objects × controllers), each
    (object, controller, source) with its drive configs; the job's cells run in lockstep in one
    worker, so a model in the loop is called once per tick for all of them."""
    jobs: dict[str, list[tuple[tuple[str, str, str], list]]] = {}
    for j, obj in enumerate(OBJECTS):
        seed0 = application_seed(cfg.seed, j)
        jobs.setdefault(MG_JOB, []).append(((obj, "manual", "nominal"),
                                            _mujoco_configs(cfg, obj, seed0, "manual", "nominal")))  # fmt: skip
        for controller in CONTROLLERS:
            for source in SOURCES:
                jobs.setdefault(source, []).append(((obj, controller, source),
                                                    _mujoco_configs(cfg, obj, seed0, controller, intents[source])))  # fmt: skip
    return jobs


def _run_mujoco(ws: Workspace, intents: dict[str, str], metrics: dict, mg: dict, pairs: dict, errors: dict) -> None:
    """The same cells on the MuJoCo UR5 (fewer trials: ``ablation_mujoco_trials`` per operator)."""
    import contextlib

    from coassist.data import Trial, TrialMeta
    from coassist.sim.world import worker_pool

    cfg = ws.config
    jobs = _mujoco_jobs(cfg, intents)
    workers = max(1, min(cfg.workers, os.cpu_count() or 1))
    # the run's simulation processes where it has them (started once), else a pool for these runs
    with contextlib.nullcontext(ws.pool) if ws.pool is not None else worker_pool(workers) as pool:
        # a job AblationAhead started is taken, not run again
        futures = [(cells, ws.take(f"mujoco:{source}") or pool.submit(_drive_batch, [c for _, configs in cells for c in configs]))
                   for source, cells in jobs.items()]  # fmt: skip
        done = []
        for cells, fut in futures:
            runs = iter(fut.result())
            for key, configs in cells:
                done.append((key, [next(runs) for _ in configs]))
        for (obj, controller, source), payloads in done:
            trials = [Trial(meta=TrialMeta.from_dict(m), **a) for m, a in payloads]
            trials = sorted(trials, key=_pair_key)
            if controller == "manual":
                mg[("mujoco", obj)] = application_metrics(trials)
                pairs[("mujoco", obj)] = [_pair_key(t) for t in trials]
                continue
            if [_pair_key(t) for t in trials] != pairs[("mujoco", obj)]:
                raise RuntimeError(f"ablation cell mujoco/{obj}/{controller}/{source} did not meet MG's trials")
            metrics[("mujoco", obj, controller, source)] = application_metrics(trials)
            errors[("mujoco", obj, controller, source)] = prediction_errors_against_intent(trials)


def _share_text(s: tuple[float, float, float]) -> str:
    share, lo, hi = s
    if not np.isfinite(share):
        return "n/a"
    bracket = f" [{100 * lo:.0f}, {100 * hi:.0f}]" if np.isfinite(lo) else ""
    return f"{100 * share:.0f} %{bracket}"


def headline_rows(result: AblationResult, world: str = "point-mass") -> tuple[str, list[str], list[list[Any]]]:
    """The report's first-screen table: per intent source, the share of the oracle's benefit
    over MG (force, overshoot) per object, with the arbitrated controller."""
    rows = []
    for source in SOURCES:
        row: list[Any] = [source]
        for obj in OBJECTS:
            if (world, obj, "cooperative-arbitrated", source) not in result.metrics:
                row += ["—", "—"]
                continue
            sh = result.shares(world, obj, "cooperative-arbitrated", source)
            row += [_share_text(sh["f_rms"]), _share_text(sh["overshoot"])]
        rows.append(row)
    n = len(next(iter(result.pairs.values())))
    caption = (f"Share of the oracle's benefit over MG per intent source ({world} world, arbitrated controller, "
               f"{n} paired trials per object; 95 % bootstrap interval): 100 % is all the oracle gains, 0 nothing, "
               "below 0 worse than MG")  # fmt: skip
    header = ["intent source"] + [f"{o}: {m}" for o in OBJECTS for m in ("force", "overshoot")]
    return caption, header, rows


def ablation_section(result: AblationResult) -> Section:
    """The report's ablation section: every cell of both worlds, and the claims of issue 18's bar."""
    s = Section("6. Which intent makes assistance better? The in-loop ablation (issue 18)")
    s.paragraphs.append(
        "Each intent source drives the fixed-α and the arbitrated assistive controller (preset "
        f"'{result.preset}') on the application's trials, paired against MG on the same trials. The learned sources are "
        "trained from scratch on the same datasets by the same protocol; only what they learn to predict differs: the "
        "tool's future pose (the thesis), the path the hand alone would have produced (the robot's effort removed "
        "through the known impedance), or the simulated operator's true intent. Share of the oracle's benefit = "
        "mean(MG − X) / mean(MG − oracle) over paired trials, with a 95 % bootstrap interval."
    )
    for world, why in result.skipped.items():
        s.paragraphs.append(f"The {world} world did not run: {why}.")
    for world in WORLDS:
        rows = []
        for obj in OBJECTS:
            if (world, obj) not in result.mg:
                continue
            m = result.mg[(world, obj)]
            rows.append([obj, "—", "MG", f"{m['f_rms']:.2f}", f"{m['sigma'] * 1e3:.2f}", f"{m['overshoot'] * 1e3:.1f}",
                         f"{m['jerk_rms']:.2f}", f"{m['peak_effort_ratio']:.2f}", "", ""])  # fmt: skip
            for controller in CONTROLLERS:
                for source in SOURCES:
                    r = result.metrics[(world, obj, controller, source)]
                    sh = result.shares(world, obj, controller, source)
                    d, lo, hi, _ = paired_difference(r["overshoot_trials"], m["overshoot_trials"])
                    rows.append([obj, controller, source, f"{r['f_rms']:.2f}", f"{r['sigma'] * 1e3:.2f}",
                                 f"{r['overshoot'] * 1e3:.1f} ({d * 1e3:+.1f} [{lo * 1e3:+.1f}, {hi * 1e3:+.1f}])",
                                 f"{r['jerk_rms']:.2f}", f"{r['peak_effort_ratio']:.2f}", _share_text(sh["f_rms"]),
                                 _share_text(sh["overshoot"])])  # fmt: skip
        if rows:
            n = len(result.pairs[(world, OBJECTS[0])])
            s.tables.append((
                f"{world} world, {n} paired trials per cell: f_RMS [N], σ [mm], overshoot past the intent [mm] (paired "
                "difference from MG, 95 % interval), jerk RMS [m/s³], peak robot/hand effort, share of the oracle's benefit",
                ["object", "controller", "intent source", "f_RMS", "σ", "overshoot", "jerk RMS", "peak |u_r|/|u_h|",
                 "oracle share: force", "oracle share: overshoot"], rows))  # fmt: skip
    rows = []
    for source in SOURCES:
        for obj in OBJECTS:
            e = result.errors.get(("point-mass", obj, "cooperative-arbitrated", source), {})
            rows.append([source, obj] + [f"{1e3 * e[h]['tool']:.2f} / {1e3 * e[h]['intent']:.2f}" if h in e else "—"
                                         for h in EVAL_HORIZONS])  # fmt: skip
    s.tables.append((
        "What each source predicted in the loop (point-mass world, arbitrated controller): e_RMS [mm] against the tool's "
        "measured future pose / against the operator's true intent, per horizon",
        ["intent source", "object"] + [f"{h} samples" for h in EVAL_HORIZONS], rows))
    for obj in OBJECTS:
        for source in ("lstm-tool", "lstm-hand-alone", "lstm-intent"):
            key = ("point-mass", obj, "cooperative-arbitrated", source)
            sh = result.shares(*key)
            f, o = sh["f_rms"][0], sh["overshoot"][0]
            s.claims.append(Claim(
                f"{obj}: the arbitrated controller with {source} in the loop gets ≥ {100 * ORACLE_SHARE_BAR:.0f} % of the "
                "oracle's force saving and of its overshoot reduction over MG (issue 18's bar; point-mass world)",
                bool(np.isfinite(f) and np.isfinite(o) and f >= ORACLE_SHARE_BAR and o >= ORACLE_SHARE_BAR),
                f"force {_share_text(sh['f_rms'])}, overshoot {_share_text(sh['overshoot'])} of the oracle's benefit",
                reason="a prediction from the past cannot anticipate all of the operator's turns; what it misses at a "
                "turn the robot pushes past it",
            ))
    return s
