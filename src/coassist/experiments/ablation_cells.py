"""The in-loop ablation's cells and what it measured (issues 18, 34): its vocabulary and :class:`AblationResult`.

The cells are (world, object, controller, source): the sources (:data:`SOURCES` and the
:func:`registered_sources`), the controllers (:data:`CONTROLLERS`, the damped one on
:data:`DAMPED_SOURCES`), the worlds of :data:`ABLATION_CELLS` and the issues' bars.
:class:`AblationResult` holds each cell's metrics and computes from them the **share of the
oracle's benefit** for force and for overshoot::

    share = mean_i(MG_i − X_i) / mean_i(MG_i − oracle_i)

over the paired trials i, with a 95 % percentile bootstrap interval over trials
(:func:`~coassist.analysis.paired.gain_share`, :data:`BOOTSTRAP` resamples), and the per-side
paired differences from MG (:data:`SIDES`). The cells are run in :mod:`coassist.experiments.ablation`
(whose docstring describes the ablation), the report written in
:mod:`coassist.experiments.ablation_report`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from coassist.analysis.paired import clustered_difference, gain_share, paired_difference
from coassist.experiments.source_training import CALIBRATED_KINDS, LEARNED, seed_names
from coassist.robot.worlds import POINT_MASS
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.intent_registry import INTENT_FOLDERS, INTENT_SOURCES, Told, folder_told
from coassist.scenario.populations import HELD_OUT

SOURCES = (
    "nominal",
    "constant-velocity",
    "present",
    DEFAULT_INTENT,
    "ridge",
    "ridge-intent",
    "lstm-tool",
    "lstm-hand-alone",
    "lstm-intent",
    "paths",
    "person",
    "oracle",
)
ARBITRATED = "cooperative-arbitrated"
DAMPED = "cooperative-damped"
CONTROLLERS = ("cooperative", ARBITRATED)
#: The damped controller's cells: the lever on the application's source and on the oracle.
DAMPED_SOURCES = ("paths", "oracle")
#: The held-out population's cells (:mod:`coassist.experiments.ablation`'s docstring): the arbitrated
#: controller with these sources.
HELD_OUT_SOURCES = ("nominal", "present", DEFAULT_INTENT, "lstm-intent", "paths", "person", "oracle")
#: The report's world cells, the first item of every cell key (world, object, controller, source) and
#: the order the report's tables run in: not a list of worlds to choose from. "point-mass" and
#: "mujoco" are worlds of coassist.robot.worlds.WORLDS by name; "held-out" is the point-mass world
#: again with the held-out population's operators (:mod:`coassist.experiments.ablation`'s docstring).
#: The report's text and tables and experiments.precision and reproduce read the cells by these names.
ABLATION_CELLS = (POINT_MASS, "mujoco", HELD_OUT)
#: The sources calibrated per operator (not trained): their folder is written per population.
CALIBRATED = ("paths", "person")
#: Issue 18's bar: a learned predictor in the loop gets this share of the oracle's benefit over MG.
ORACLE_SHARE_BAR = 0.8
#: Issue 34's bars for the application's source (arbitrated controller): shares of the oracle's force
#: saving and overshoot reduction, the bootstrap lower bound of the latter, and jerk against MG's.
FORCE_SHARE_BAR, OVERSHOOT_SHARE_BAR, SHARE_LOWER_BAR, JERK_BAR = 0.85, 0.60, 0.30, 1.2
#: Bootstrap resamples of the share's interval (seeded: the same run gives the same interval).
BOOTSTRAP = 2000
#: The sides of the detour (TrialMeta.extra["intent_side"]): +1 passes on the left of the path.
SIDES = {1: "left", -1: "right"}


def registered_sources() -> tuple[str, ...]:
    """The sources of :data:`~coassist.scenario.intent_registry.INTENT_SOURCES` whose entry asks for the
    ablation (``ablation=True``) besides :data:`SOURCES`, in the registry's order (read when called)."""
    return tuple(n for n, e in INTENT_SOURCES.items() if e.ablation and n not in SOURCES)


def run_sources(cfg) -> tuple[str, ...]:
    """This run's sources, in the tables' order: the named ones, ``paths`` and its learned ones, then
    the :func:`registered_sources`."""
    return tuple(s for s in SOURCES if s not in LEARNED or s in cfg.learned_sources) + registered_sources()


def mujoco_sources(cfg) -> tuple[str, ...]:
    """The sources of the MuJoCo UR5's cells (``reproduce.mujoco_sources``; empty: every source of the run)."""
    chosen = tuple(cfg.mujoco_sources)
    return tuple(s for s in run_sources(cfg) if not chosen or s in chosen)


def base_source(name: str) -> str:
    """The source of a cell's name: ``lstm-intent-s2`` → ``lstm-intent``."""
    return re.sub(r"-s\d+$", "", name)


def ablation_cells(cfg) -> list[tuple[str, str]]:
    """The (controller, source) cells of one object in the point-mass world
    (:mod:`coassist.experiments.ablation`'s docstring); the fixed-α controller runs the learned
    sources only where ``reproduce.fixed_alpha_learned`` says so."""
    cells = [
        (c, s)
        for c in CONTROLLERS
        for s in run_sources(cfg)
        if c == ARBITRATED or s not in LEARNED or cfg.fixed_alpha_learned
    ]
    cells += [
        (ARBITRATED, name) for s in run_sources(cfg) if s in LEARNED for name in seed_names(s, cfg.source_seeds)[1:]
    ]
    cells += [(DAMPED, s) for s in DAMPED_SOURCES]
    return cells


def _oracle_of(controller: str) -> str:
    """The controller whose oracle cell is a cell's reference (the damped one is measured against the arbitrated)."""
    return ARBITRATED if controller == DAMPED else controller


@dataclass(frozen=True)
class AblationResult:
    """metrics[(world, object, controller, source)] and mg[(world, object)]: :func:`~coassist.experiments.application.application_metrics`;
    pairs[(world, object)]: the (operator, seed) of every trial, in the order all cells share;
    models: the learned sources' model folders (and ``paths``' calibration); skipped: world → why it
    did not run."""

    metrics: dict[tuple[str, str, str, str], dict[str, Any]]
    mg: dict[tuple[str, str], dict[str, Any]]
    pairs: dict[tuple[str, str], list[tuple[str, int]]]
    models: dict[str, str]
    skipped: dict[str, str]
    preset: str
    #: errors[(world, object, controller, source)][h] = {"tool": e_RMS against the measured future pose,
    #: "intent": against the operator's true intent} [m] of the predictions the loop used, h in samples.
    errors: dict[tuple[str, str, str, str], dict[int, dict[str, float]]]
    #: clusters[(world, object, controller, source)]: a label per pair (in ``pairs``' order) for a cell whose
    #: trials are not independent: the person model's calibration draws (scenario.calibration_draws). Its
    #: shares' intervals resample the clusters whole (:func:`~coassist.analysis.paired.gain_share`).
    clusters: dict[tuple[str, str, str, str], list] = field(default_factory=dict)
    #: The held-out population's people the cells met (reproduce.held_out_people: its population seed).
    held_out_people: int = 0
    #: Whose families the held-out cells met (reproduce.held_out_population).
    held_out_population: str = "held-out"

    def shares(self, world: str, obj: str, controller: str, source: str) -> dict[str, tuple[float, float, float]]:
        """The share of the oracle's benefit for force and for overshoot (:func:`~coassist.analysis.paired.gain_share`
        of MG, the source and the oracle, :data:`BOOTSTRAP` resamples); each
        cell's bootstrap runs once (the summary, the section and the first screen all ask)."""
        key = (world, obj, controller, source)
        cache = self.__dict__.setdefault("_shares", {})  # frozen: the cache is not a field
        if key not in cache:
            cache[key] = self._shares_of(*key)
        return cache[key]

    def _shares_of(self, world: str, obj: str, controller: str, source: str) -> dict[str, tuple[float, float, float]]:
        mg = self.mg[(world, obj)]
        x = self.metrics[(world, obj, controller, source)]
        o = self.metrics[(world, obj, _oracle_of(controller), "oracle")]
        return {
            m: gain_share(
                mg[f"{m}_trials"],
                x[f"{m}_trials"],
                o[f"{m}_trials"],
                n_boot=BOOTSTRAP,
                clusters=self.clusters.get((world, obj, controller, source)),
            )
            for m in ("f_rms", "overshoot")
        }

    def by_side(
        self,
        world: str,
        obj: str,
        controller: str,
        source: str,
        metric: str,
    ) -> dict[int, tuple[float, float, float, float, int]]:
        """Per side of the detour (:data:`SIDES`): (mean, paired difference from MG, its 95 % low and high,
        trials) of ``metric`` ("overshoot" or "clearance_deficit") [m]. In a cell with ``clusters`` (trials
        sharing a calibration of the person) the interval is the clusters' (:func:`clustered_difference`), as
        the shares' intervals resample them whole; elsewhere the trials' paired t interval."""
        x = self.metrics[(world, obj, controller, source)]
        mg = self.mg[(world, obj)]
        side = np.asarray(mg["side"])
        labels = self.clusters.get((world, obj, controller, source))
        out = {}
        for s in SIDES:
            on = side == s
            a, b = np.asarray(x[f"{metric}_trials"], float)[on], np.asarray(mg[f"{metric}_trials"], float)[on]
            if labels is None:
                d, lo, hi, n = paired_difference(a, b)
            else:
                d, lo, hi, n = clustered_difference(a, b, [c for c, keep in zip(labels, on) if keep])
            out[s] = (float(np.nanmean(a)) if n else float("nan"), d, lo, hi, n)
        return out

    def seeds_of(self, world: str, obj: str, controller: str, source: str) -> list[str]:
        """The cells of ``source``'s trainings that ran with ``controller`` (one unless the arbitrated LSTM);
        ``source`` itself first, also where its name ends like a training's (a compare-intents label ``k2-s1``)."""
        return sorted(
            (
                s
                for (w, o, c, s) in self.metrics
                if (w, o, c) == (world, obj, controller) and source in (s, base_source(s))
            ),
            key=lambda s: (s != source, s),
        )

    def summary(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "preset": self.preset,
            "models": self.models,
            "skipped": self.skipped,
            "cells": {},
            "pairs": {f"{w}/{o}": p for (w, o), p in self.pairs.items()},
            "mg": {
                f"{w}/{o}": {k: v for k, v in m.items() if not k.endswith("_trials")} for (w, o), m in self.mg.items()
            },
        }
        for (world, obj, controller, source), r in self.metrics.items():
            sh = self.shares(world, obj, controller, source)
            out["cells"][f"{world}/{obj}/{controller}/{source}"] = {
                **{k: v for k, v in r.items() if not k.endswith("_trials")},
                "oracle_share_force": sh["f_rms"],
                "oracle_share_overshoot": sh["overshoot"],
                "by_side": {
                    SIDES[s]: {
                        m: dict(zip(("mean", "vs_mg", "low", "high", "trials"), v[s]))
                        for m, v in (
                            (m, self.by_side(world, obj, controller, source, m))
                            for m in ("overshoot", "clearance_deficit")
                        )
                    }
                    for s in SIDES
                },
                "prediction_errors": self.errors[(world, obj, controller, source)],
            }
            labels = self.clusters.get((world, obj, controller, source))
            if labels is not None:  # the intervals resampled these clusters whole
                out["cells"][f"{world}/{obj}/{controller}/{source}"]["interval_clusters"] = len(set(map(str, labels)))
        return out


def told_of(source: str, folder: str | None = None) -> Told:
    """What a cell's source was told besides what an arm measures (:class:`~coassist.scenario.intent_registry.Told`);
    ``folder``: the calibration it ran with, where known (its arms measured or assumed: ``folder_told``)."""
    base = base_source(source)
    if base in CALIBRATED_KINDS:  # run with its calibration's folder (the registry's "paths" alone is told less)
        kind = CALIBRATED_KINDS[base]
        return INTENT_FOLDERS[kind].told if folder is None else folder_told(kind, folder)
    if base in INTENT_SOURCES:
        return INTENT_SOURCES[base].told
    label = LEARNED[base][1] if base in LEARNED else ""
    return Told(
        label={
            "tool": "the tool's future pose",
            "intent": "the simulated operator's intent",
            "hand_alone": "the simulated hand-alone path",
        }.get(label, label)
    )
