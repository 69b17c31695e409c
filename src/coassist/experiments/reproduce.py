"""The thesis' experiments end to end (chapter 5), in simulation, and one HTML report.

Stages, in order (each writes its data under ``out/`` and a section of the report):

1. the dMPC study (§5.2.1, Fig. 5.2–5.4);
2. iterative training (Algorithm 4.1, §5.3.1, Fig. 5.12–5.17, Table 5.1);
3. transfer learning (Algorithm 4.2, §5.3.2, Fig. 5.18–5.23, Table 5.2) to the new "z"
   trajectory, five new users and the board, each against a model trained from
   scratch and one fine-tuned in all layers on the same trials;
4. the application scenario (§5.2.3, §5.3.3, Fig. 5.24–5.31): the board and the heavy
   load carried past an obstacle with the assistive controller, IMP and MG; the assistive
   controller's intent source is the path hypotheses round the obstacle, calibrated to each
   operator, the source that did best in the in-loop ablation on validation seeds
   (:mod:`~coassist.experiments.source_training`, ``docs/precision.md``);
5. the real UR5 recordings: the predictor trained on user-a against its baselines,
   and transferred to user-b;
6. the in-loop ablation of intent sources (issues 18, 34): nominal, constant velocity, the
   present estimate, the tuned ridge on the tool's future and on the true intent, the LSTM+FC
   on both (three training seeds), the path hypotheses, with and without deceleration-gated
   damping, and the oracle, in the point-mass world and on the MuJoCo UR5
   (:mod:`~coassist.experiments.ablation`).

Control preset. The closed loops use the thesis' weights with positions scaled: in
decimetres for data collection (``thesis-evaluation-dm``) and ×3.5 for the application
(``thesis-application-damped``): in SI units the robot's effort is too small to change
what the operator does (see the dMPC study and the sim package), and iterative training
would have nothing to iterate on; in decimetres the application's robot, tracking a
learned prediction of its own motion, removes two thirds of the plant's damping and the
tool rings around the operator's intent (coassist.config.APPLICATION_DAMPED_SCALE).

The thesis' claims are checked against the numbers, each marked holds / does not hold.
The application's position scale and arbitration law were chosen on validation seeds the
report never uses; not everything was: the MuJoCo UR5's trial count (eight, where four
resolved five of the six cells) was chosen on the report's seeds 0–2, and the person model's
lead check, its sign test and its lock guard while seeing the held-out operators' trials of
seeds 0 and 1 (their cells now meet trials of their own: docs/person-model.md). Every
number the report prints comes from this run or from a config (the sweep's, the control
presets', the controllers').

Modules: the shared config, presets, seed plan and workspace are
:mod:`coassist.experiments.pipeline`; stages 3–5 are
:mod:`~coassist.experiments.transfer`, :mod:`~coassist.experiments.application` and
:mod:`~coassist.experiments.real_recordings`, each returning a typed result; stages 1–2
(whose experiments are :mod:`~coassist.experiments.dmpc_study` and
:mod:`~coassist.experiments.iterative`) and the report are here.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

from coassist._cpu import CpuSeconds, run_cpu_seconds
from coassist._io import atomic_write_text
from coassist.experiments.ablation import MG_JOB, AblationAhead, run_ablation
from coassist.experiments.ablation_report import ablation_section
from coassist.experiments.application import (
    application_section,
    handed_to_ablation,
    prefetch_model_free,
    run_application,
)
from coassist.experiments.iterative import IterativeResult
from coassist.experiments.pipeline import (
    EVAL_HORIZONS,
    ITERATION_TASKS,
    Workspace,
    default_real_data,
    evaluate_in_worker,
    in_loop_errors,
    pyplot,
    score_model,
    windows_trained,
)
from coassist.experiments.real_recordings import (
    real_recordings_in_worker,
    real_recordings_section,
    run_real_recordings,
)
from coassist.experiments.report import Claim, Section, write_report
from coassist.experiments.reproduce_config import REPRODUCE_PRESETS, ReproduceConfig
from coassist.experiments.seed_plan import iteration_seed, trial_seed_base
from coassist.experiments.transfer import run_transfer, transfer_section
from coassist.scenario.assistance import DEFAULT_INTENT

__all__ = [
    "EVAL_HORIZONS",
    "ITERATION_TASKS",
    "REPRODUCE_PRESETS",
    "ReproduceConfig",
    "default_real_data",
    "in_loop_errors",
    "run_reproduce",
]


class _Stage:
    """Timing and terminal progress for one stage: wall seconds, and the CPU seconds this
    process and the pool's workers used meanwhile (``coassist._cpu``; stages overlap on the
    pool, since a stage puts work there that a later one takes, so a stage's CPU seconds are
    those spent while it ran, whichever stage they served)."""

    def __init__(self, say: Callable[[str], None]) -> None:
        self.say = say
        self.times: dict[str, float] = {}
        self.cpu: dict[str, CpuSeconds] = {}

    def run(self, name: str, fn, *args, **kwargs):
        self.say(f"[bold]{name}[/]")
        t0, c0 = time.perf_counter(), run_cpu_seconds()
        out = fn(*args, **kwargs)
        self.times[name] = time.perf_counter() - t0
        self.cpu[name] = cpu = run_cpu_seconds().since(c0)
        used = "" if cpu.total is None else f" ({cpu.total:.0f} CPU-s)"
        self.say(f"  {name} done in {self.times[name]:.0f} s{used}")
        return out


# ----------------------------------------------------------------------------- the pipeline


@dataclass
class _Context:
    """The run's workspace, stage timer, and the summary and sections gathered so far."""

    ws: Workspace
    stage: _Stage
    summary: dict[str, Any] = field(default_factory=dict)
    sections: list[Section] = field(default_factory=list)

    @property
    def config(self) -> ReproduceConfig:
        return self.ws.config

    @property
    def out(self) -> Path:
        return self.ws.out


def simulation_pool(config: ReproduceConfig):
    """One pool of simulation processes for the whole run (coassist.sim.pool.worker_pool):
    started once, not once per collection; none where the run simulates in this process."""
    from coassist.sim.pool import worker_pool

    return worker_pool(config.workers) if config.workers > 1 else contextlib.nullcontext(None)


def run_reproduce(
    config: ReproduceConfig,
    out: Path,
    *,
    progress: bool = True,
    say: Callable[[str], None] | None = None,
    pool: Any = None,
) -> dict:
    """Run every stage; write ``report.html`` and ``summary.json`` in ``out``; return the summary.
    ``pool``: the simulation processes to run on (:func:`coassist.sim.pool.worker_pool`, kept by the caller
    across runs, e.g. :func:`coassist.experiments.seeds.run_seeds`); None: started for this run."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say = say or (lambda message: None)
    with contextlib.nullcontext(pool) if pool is not None else simulation_pool(config) as pool:
        ctx = _Context(Workspace(config, out, progress, pool), _Stage(say))
        t0, c0 = time.perf_counter(), run_cpu_seconds()
        ctx.summary["config"] = asdict(config)
        ctx.stage.run("dMPC study", _stage_sweep, ctx)
        real_data = config.real_data or default_real_data()
        # The ablation's simulations go on the pool before the ablation: the named sources' while
        # the iterative stage trains, the learned ones' while the application's sources train.
        ablation_ahead = AblationAhead(ctx.ws, handed_to_ablation())
        iterative = ctx.stage.run(
            "iterative training",
            run_iterative_stage,
            ctx.ws,
            ctx.stage.say,
            _beside_training(ctx.ws, real_data, ablation_ahead),
        )
        ctx.sections.append(iterative_section(iterative))
        ctx.summary["iterative"] = iterative.summary()
        final_model = iterative.final_model
        transfer = ctx.stage.run("transfer learning", run_transfer, ctx.ws, final_model, iterative.iteration_seconds)
        ctx.sections.append(
            transfer_section(
                transfer,
                iterative.final_model_offline_e_rms[50],
                sum(w["trials"] for w in iterative.work),
                sum(w["windows_trained"] for w in iterative.work),
            )
        )
        ctx.summary["transfer"] = transfer.summary()
        # Started on the pool during the iterative stage (without a pool: run here, now).
        real = ctx.stage.run(
            "real recordings", ctx.ws.result_of, "real recordings", run_real_recordings, ctx.ws, real_data
        )
        application = ctx.stage.run("application scenario", run_application, ctx.ws, final_model, ablation_ahead)
        ctx.sections.append(application_section(application))
        ctx.summary["application"] = application.summary()
        ctx.sections.append(real_recordings_section(real))
        ctx.summary["real"] = real.summary()
        ablation = ctx.stage.run("intent ablation", run_ablation, ctx.ws, application.models, application.cells())
        ctx.sections.append(ablation_section(ablation))
        ctx.summary["ablation"] = ablation.summary()
        ctx.summary["stage_seconds"] = ctx.stage.times
        ctx.summary["total_seconds"] = time.perf_counter() - t0
        # The work done, less sensitive to the machine's load than the wall time above.
        ctx.summary["stage_cpu_seconds"] = {name: c.to_dict() for name, c in ctx.stage.cpu.items()}
        cpu = run_cpu_seconds().since(c0)
        ctx.summary["cpu_seconds"] = cpu.to_dict()
        used = "" if cpu.total is None else f", {cpu.total:.0f} CPU-seconds"
        claims = [c.to_dict() for s in ctx.sections for c in s.claims]
        ctx.summary["claims"] = claims
        intro = (
            f"coassist reproduction of the thesis' experiments in simulation, preset '{config.name}' "
            f"(intent model preset '{config.intent_preset}', control preset '{config.control_preset}'), "
            f"seed {config.seed}; total time {ctx.summary['total_seconds']:.0f} s{used}. Every number below was measured in this run."
        )
        headline = headline_section(application, transfer, real, _sim_dt(config), ablation)
        ctx.summary["headline"] = {
            "table": headline.tables[0],
            "intent_sources": headline.tables[1],
            "prediction": headline.paragraphs,
        }
        write_report(
            out / "report.html", "coassist — the thesis' experiments, reproduced", intro, ctx.sections, headline
        )
        atomic_write_text(out / "summary.json", json.dumps(jsonable(ctx.summary), indent=1, allow_nan=False))
        return ctx.summary


def _beside_training(ws: Workspace, real_data: str | None, ablation_ahead: AblationAhead) -> Callable[[int], None]:
    """The iterative stage's ``ahead(k)``: while M_k trains in this process on one core, later
    stages' work that needs no model keeps the other busy. A share per training, not all at
    once: the pool runs its jobs in order, and D_{k+1}'s collection, submitted when M_k is
    done, waits behind what is queued; once it is collected the pool idles again beside
    M_{k+1}'s training unless some is left for then. In order: the real recordings (beside
    M_0, the longest training), the application's IMP and MG pairs and the operators' calibration
    trials, then the ablation's named sources (MG's MuJoCo trials and the nominal intent, then constant
    velocity, the present estimate, every world's default and the oracle).
    Whatever a short run's last training has not started is started there."""
    shares: list[Callable[[], object]] = [
        lambda: ws.submit("real recordings", real_recordings_in_worker, ws.config, ws.out, real_data),
        lambda: prefetch_model_free(ws),
        lambda: ablation_ahead({}, only=(MG_JOB, "nominal")),
        lambda: ablation_ahead({}, only=("constant-velocity", "present", DEFAULT_INTENT, "oracle")),
    ]
    last = ws.config.iterations - 1

    def ahead(k: int) -> None:
        for share in shares[k:] if k == last else shares[k : k + 1]:
            share()

    return ahead


def _sim_dt(config: ReproduceConfig) -> float:
    from coassist.control.presets import get_preset

    return float(get_preset(config.control_preset).impedance.dt)


def headline_section(application, transfer, real, sim_dt: float, ablation) -> Section:
    """The report's first screen: per object, force saved against MG and IMP with its spread,
    precision and smoothness against MG; the share of the oracle's benefit each intent source
    gets in the loop (the ablation); then whether the prediction beats its best simple
    baseline (the simulated transfer targets and the real recordings), in mm."""
    from coassist.experiments.ablation_report import headline_rows
    from coassist.experiments.application import headline_table

    s = Section("The answer: does the assistance help?")
    s.tables.append(headline_table(application))
    s.tables.append(headline_rows(ablation))
    if ablation.mg.get(("held-out", "board")) is not None:
        s.tables.append(headline_rows(ablation, "held-out"))
    if ablation.mg.get(("mujoco", "board")) is not None:  # the same rows on the MuJoCo UR5 (its sources only)
        s.tables.append(headline_rows(ablation, "mujoco"))

    def line(where: str, best: dict[int, dict], model: str, dt: float) -> str:
        h = max(best)
        b = best[h]
        verdict = "helps" if b["gain"] > 0 else "does not help"
        return (
            f"{where}: at {h * dt:.2f} s the {model} {verdict} over the best simple baseline ({b['name']}): "
            f"{b['model_e_rms'] * 1e3:.2f} vs {b['e_rms'] * 1e3:.2f} mm ({100 * b['gain']:+.1f} %)"
        )

    for name, t in transfer.targets.items():
        s.paragraphs.append(
            "Prediction, simulated transfer to " + line(name, t.best_baseline, "transferred model", sim_dt)
        )
    if not real.skipped:
        s.paragraphs.append(
            "Prediction, real recordings, "
            + line("user-a held out", real.user_a.best_baseline, "model", real.user_a.dt)
        )
        s.paragraphs.append(
            "Prediction, real recordings, "
            + line("user-b transferred", real.user_b["M_TL"].best_baseline, "transferred model", real.user_b["M_TL"].dt)
        )
    return s


def jsonable(obj):
    """``obj`` as JSON holds it: dict keys as strings, tuples as lists, numpy numbers and paths as Python's, NaN as null."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return None if not np.isfinite(obj) else float(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


# ----------------------------------------------------------------------------- 1. dMPC study


def _stage_sweep(ctx: _Context) -> None:
    from coassist.experiments import dmpc_study

    sweep = dmpc_study.SweepConfig(duration=ctx.config.sweep_duration)
    result = dmpc_study.run_sweep(sweep, ctx.out / "sweep")
    summary = dmpc_study.summary(result)
    ctx.summary["dmpc_sweep"] = {
        "observations": summary["observations"],
        "cases": summary["cases"],
        "si_spread": summary["si_units"]["spread_of_error_to_human_reference"],
    }
    s = Section("1. The dMPC study (thesis §5.2.1, Fig. 5.2–5.4)")
    s.paragraphs.append(
        f"Both players apply their cooperative-equilibrium efforts on one DOF (M = {sweep.mass:g} kg, D = {sweep.damping:g} "
        f"N·s/m) while the human's reference is {sweep.human_amplitude:g} sin t and the robot's {sweep.robot_amplitude:g} sin t. "
        f"Positions are weighted in units of 1/{sweep.position_scale:g} m: in SI units every case "
        f"tracks alike (RMS error {summary['si_units']['spread_of_error_to_human_reference'][0]:.3f}–"
        f"{summary['si_units']['spread_of_error_to_human_reference'][1]:.3f} m), because the effort cost dominates."
    )
    s.figures.append(
        (
            f"Tracking for α ∈ {{{', '.join(f'{a:g}' for a in sweep.alphas)}}} per R_r (rows) and horizon (columns).",
            (ctx.out / "sweep" / "dmpc_sweep.png").read_bytes(),
        )
    )
    rows = [[c.R_r, c.horizon, c.alpha, c.rms_error_human, c.rms_error_robot, c.rms_effort_robot] for c in result.cases]
    s.tables.append(
        (
            "RMS errors [m] and robot effort [N]",
            ["R_r", "horizon [samples]", "α", "error to x_ref,h [m]", "error to x_ref,r [m]", "RMS u_r [N]"],
            rows,
        )
    )
    texts = {
        "higher_alpha_tracks_human_reference": "Higher α tracks the human's reference more closely",
        "lower_R_r_tracks_better": "Lower R_r makes the robot more responsive (smaller tracking error)",
        "longer_horizon_tracks_better": "A longer prediction horizon tracks better",
    }
    for key, verdict in result.observations.items():
        ev = (
            "in every combination of the other two parameters"
            if verdict["holds"]
            else f"counterexamples: {verdict['counterexamples']}"
        )
        s.claims.append(
            Claim(texts[key], bool(verdict["holds"]), ev, reason="" if verdict["holds"] else "see the table")
        )
    ctx.sections.append(s)


# ----------------------------------------------------------------------------- 2. iterative training


@dataclass(frozen=True)
class IterativeStageResult:
    """The main job's Algorithm 4.1 (section 2): errors in m, horizons in ticks, times in s.

    run : the algorithm's own record (datasets D_k, models M_k, the stop criterion's deltas).
    labels : "nominal", "M0", …: who predicted in the loop while each dataset was collected.
    errors : label -> horizon -> in-loop e_RMS, e_MAX (coassist.experiments.pipeline.in_loop_errors).
    times : per step k, collect_s and train_s.  work : per step k, trials collected and
        windows trained (machine-independent, unlike times).
    final_model_offline_e_rms : the last model's e_RMS per horizon on the dataset collected
        with it in the loop (which it was not trained on).
    m0_on_d1_e_rms_50, constant_velocity_on_d1_e_rms_50 : M_0 and constant velocity on D_1
        at 50 ticks (the input shift the skip's shrinkage is chosen for).
    skip_alpha, trials_per_task, tol : the configuration the section reports.
    dt : the datasets' tick [s].  iteration_seconds : mean collect + train time of one step.
    """

    run: IterativeResult
    labels: tuple[str, ...]
    errors: dict[str, dict[int, dict[str, float]]]
    times: tuple[dict[str, Any], ...]
    work: tuple[dict[str, Any], ...]
    final_model_offline_e_rms: dict[int, float]
    m0_on_d1_e_rms_50: float
    constant_velocity_on_d1_e_rms_50: float
    skip_alpha: float
    trials_per_task: int
    tol: float
    dt: float
    iteration_seconds: float

    @property
    def final_model(self) -> Path:
        """The last model M_{K−1}: where transfer and the application start from."""
        return Path(self.run.models[-1])

    def summary(self) -> dict[str, Any]:
        """summary.json's "iterative" record."""
        return {
            "final_model_offline_e_rms": self.final_model_offline_e_rms,
            "in_loop_errors": self.errors,
            "deltas_e_rms_50": list(self.run.deltas),
            "tol": self.tol,
            "converged_at": self.run.converged_at,
            "times": list(self.times),
            "models": [str(m) for m in self.run.models],
            "m0_on_d1_e_rms_50": self.m0_on_d1_e_rms_50,
            "constant_velocity_on_d1_e_rms_50": self.constant_velocity_on_d1_e_rms_50,
            "work": list(self.work),
        }


def run_iterative_stage(
    ws: Workspace, say: Callable[[str], None], ahead: Callable[[int], None] | None = None
) -> IterativeStageResult:
    """Algorithm 4.1: collect D_k with M_{k−1} in the loop, train M_k, score every model.

    M_k trains in this process, on one core, while the run's pool would idle, so the pool
    gets work that needs no later model: ``ahead(k)`` is called as M_k's training starts
    (for later stages' own work: :func:`run_reproduce` spreads it over the trainings), and
    M_0's score on D_1 goes there as soon as D_1 is written; M_{K−1}'s on the last dataset
    beside the in-loop errors."""
    from coassist.experiments.iterative import iterative_training

    cfg = ws.config
    folders: dict[int, Path] = {}

    def collect(k, model_path):
        folder, ds = ws.collect(
            f"D{k}",
            tasks=ITERATION_TASKS,
            trials=cfg.trials_per_task,
            seed=iteration_seed(trial_seed_base(cfg.seed), k),
            intent=str(model_path) if model_path else "nominal",
        )
        folders[k] = folder
        if k == 1:
            # The skip's shrinkage is chosen for the input shift between D_k and D_{k+1}: how
            # M_0, trained on D_0, predicts on D_1 (collected with M_0 in the loop).
            ws.submit("iterative: M0 on D1", evaluate_in_worker, model_path, [folder], cfg.score_stride)
        return ds

    def train(k, dataset, start):
        if ahead is not None:
            ahead(k)
        init = "scratch" if start is None else f"resume:{start}"
        return ws.train(f"M{k}", [folders[k]], init=init, epochs=cfg.epochs if start is None else cfg.resume_epochs)

    measured: dict[int, dict[int, dict[str, float]]] = {}  # id(dataset) → its in-loop errors, computed once

    def online(dataset):
        measured[id(dataset)] = errors = in_loop_errors(dataset.trials)
        return {h: v["e_rms"] for h, v in errors.items()}

    result = iterative_training(
        collect,
        train,
        online,
        iterations=cfg.iterations,
        tol=cfg.tol,
        criterion_horizon=50,
        progress=lambda m: say("  " + m),
    )
    ws.submit(
        "iterative: final model offline",
        evaluate_in_worker,
        result.models[-1],
        [folders[cfg.iterations]],
        cfg.score_stride,
    )
    labels = ("nominal", *(f"M{k}" for k in range(cfg.iterations)))
    datasets = [it.dataset for it in result.iterations] + [result.final_dataset]
    errors = {label: measured[id(ds)] for label, ds in zip(labels, datasets)}
    times = tuple({"k": it.k, "collect_s": it.collect_s, "train_s": it.train_s} for it in result.iterations)
    # Measured work, not wall-clock (which depends on the machine's load): trials collected, windows trained.
    work = tuple(
        {"k": it.k, "trials": len(it.dataset.trials), "windows_trained": windows_trained(it.model)}
        for it in result.iterations
    )
    final_eval = ws.result_of(
        "iterative: final model offline", score_model, result.models[-1], [folders[cfg.iterations]], cfg.score_stride
    )
    shifted = ws.result_of("iterative: M0 on D1", score_model, result.models[0], [folders[1]], cfg.score_stride)
    return IterativeStageResult(
        run=result,
        labels=labels,
        errors=errors,
        times=times,
        work=work,
        final_model_offline_e_rms={h: v["e_rms"] for h, v in final_eval.results["model"].items()},
        m0_on_d1_e_rms_50=shifted.results["model"][50]["e_rms"],
        constant_velocity_on_d1_e_rms_50=shifted.results["constant_velocity"][50]["e_rms"],
        skip_alpha=cfg.skip_alpha,
        trials_per_task=cfg.trials_per_task,
        tol=cfg.tol,
        dt=result.final_dataset.trials[0].meta.dt,
        iteration_seconds=float(np.mean([t["collect_s"] + t["train_s"] for t in times])),
    )


def iterative_section(it: IterativeStageResult) -> Section:
    """The report's section 2 and its claims."""
    result, labels, errors, dt = it.run, list(it.labels), it.errors, it.dt
    iterations = len(result.iterations)
    m0_on_d1, cv_on_d1 = it.m0_on_d1_e_rms_50, it.constant_velocity_on_d1_e_rms_50
    s = Section("2. Iterative training (Algorithm 4.1, thesis §5.3.1)")
    s.paragraphs.append(
        f"D0 ({len(ITERATION_TASKS) * it.trials_per_task} trials: user 0, handle, {'/'.join(ITERATION_TASKS)}) is collected with the nominal "
        "assumption ŷ_ref,h = y_ref,r; M_k is trained on D_k starting from M_{k−1}; D_{k+1} is collected with M_k in the "
        "loop. Each model's error is the one it achieved in the loop: measured on the dataset collected with it (the "
        "predictions it made at every tick against the measured future poses). In the simulated stages the "
        f"network's linear skip starts from a strongly shrunk ridge solution (skip_alpha = {it.skip_alpha:g}): each model "
        "meets data collected with another model in the loop, and a weakly regularised linear map extrapolates badly "
        f"there (M_0 trained on D_0 and scored on D_1, in this run: {m0_on_d1 * 1000:.1f} mm at {50 * dt:.2f} s; "
        f"constant velocity {cv_on_d1 * 1000:.1f} mm)."
    )
    rows = [
        [label]
        + [errors[label].get(h, {}).get("e_rms", float("nan")) for h in EVAL_HORIZONS]
        + [errors[label].get(50, {}).get("e_max_mean", float("nan"))]
        for label in labels
    ]
    s.tables.append(
        (
            "In-loop e_RMS [m] per horizon, and mean e_MAX at 50 samples (Fig. 5.14, 5.16)",
            ["model", "5", "10", "20", "50", "e_MAX mean @50 [m]"],
            rows,
        )
    )
    s.tables.append(
        (
            "Time per iteration (Table 5.1)",
            ["iteration", "collect [s]", "train [s]"],
            [[t["k"], t["collect_s"], t["train_s"]] for t in it.times],
        )
    )
    s.paragraphs.append(
        "Stop criterion |e_RMS^{k+1} − e_RMS^k| < "
        f"{it.tol * 1000:g} mm at 50 samples: "  # 0.25 mm, which .1f printed as 0.2
        + (
            f"first met between M{result.converged_at} and M{result.converged_at + 1}"
            if result.converged_at is not None
            else "not met"
        )
        + f" (successive changes {', '.join(f'{d * 1000:.2f}' for d in result.deltas)} mm); all iterations run, as in the thesis."
    )
    _plot_iterative(s, labels, errors, result, dt)
    e50 = [errors[f"M{k}"][50]["e_rms"] for k in range(iterations)]
    drops = [a - b for a, b in pairwise(e50)]
    if drops:
        # "then it settles" needs a drop after the first (two models showed only the first, and the claim held
        # beside a stop criterion not met: a review, 2026-12-07)
        holds = len(drops) >= 2 and e50[-1] < e50[0] and drops[0] == max(drops) and drops[0] > 0
        s.claims.append(
            Claim(
                "Iterating lowers e_RMS: the largest drop is from M0 to M1, then it settles",
                holds,
                "e_RMS@50 in the loop: "
                + ", ".join(f"M{k} {e * 1000:.1f} mm" for k, e in enumerate(e50))
                + f"; nominal assumption {errors['nominal'][50]['e_rms'] * 1000:.1f} mm",
                reason="the simulated operator is stationary and the default model small; once the model predicts well, "
                "new in-loop data adds little beyond the first retraining, and training noise is as large as the gains"
                if len(drops) >= 2
                else f"{iterations} models show one drop: whether it settles needs three or more",
            )
        )
    grows = all(
        all(errors[m][a]["e_rms"] < errors[m][b]["e_rms"] for a, b in pairwise(EVAL_HORIZONS)) for m in labels[1:]
    )
    s.claims.append(
        Claim(
            "e_RMS grows with the prediction horizon",
            grows,
            "; ".join(
                f"{m}: " + " < ".join(f"{errors[m][h]['e_rms'] * 1000:.1f}" for h in EVAL_HORIZONS) + " mm"
                for m in labels[1:]
            ),
            reason="a model predicting short horizons no better than long ones",
        )
    )
    return s


def _plot_iterative(s: Section, labels, errors, result, dt: float) -> None:
    from coassist.intent import load_model

    plt = pyplot()
    # Fig. 5.12: loss curves
    fig, ax = plt.subplots(figsize=(7, 4))
    offset = 0
    for k, model_path in enumerate(result.models):
        hist = json.loads((Path(model_path) / "history.json").read_text())
        ep = np.arange(1, len(hist) + 1) + offset
        ax.semilogy(ep, [h["train_loss"] for h in hist], "o-", color=f"C{k}", label=f"M{k} train")
        if hist and hist[0].get("test_loss") is not None:
            ax.semilogy(ep, [h["test_loss"] for h in hist], "s--", color=f"C{k}", label=f"M{k} test")
        offset += len(hist)
    ax.set_xlabel("epoch (cumulative)")
    ax.set_ylabel("MSE (scaled)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2)
    s.add_figure(fig, "Train and test loss of each model (Fig. 5.12); M_{k+1} continues from M_k.")
    plt.close(fig)
    # Fig. 5.14/5.16: e_RMS and e_MAX per model and horizon
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    width = 0.8 / len(labels)
    for i, label in enumerate(labels):
        x = np.arange(len(EVAL_HORIZONS)) + i * width
        axes[0].bar(x, [errors[label][h]["e_rms"] * 1000 for h in EVAL_HORIZONS], width, label=label)
        axes[1].bar(x, [errors[label][h]["e_max_mean"] * 1000 for h in EVAL_HORIZONS], width, label=label)
    for ax, name in zip(axes, ("e_RMS", "mean e_MAX")):
        ax.set_xticks(np.arange(len(EVAL_HORIZONS)) + 0.4 - width / 2, [f"{h} ({h * dt:.2f} s)" for h in EVAL_HORIZONS])
        ax.set_ylabel(f"{name} [mm]")
        ax.grid(alpha=0.3, axis="y")
    axes[0].legend(fontsize=8)
    s.add_figure(fig, "In-loop e_RMS and mean e_MAX per model and horizon (Fig. 5.14, 5.16).")
    plt.close(fig)
    # Fig. 5.13/5.15/5.17: one linear trial, each model's 0.4 s prediction offline
    # A trial no model was trained on: from the last collection, with the final model in the loop.
    trial = next(t for t in result.final_dataset.trials if t.meta.task == "linear")
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    axes[0].plot(trial.reference[:, 0], trial.reference[:, 1], "k--", lw=1, label="nominal")
    axes[0].plot(trial.pose[:, 0], trial.pose[:, 1], "k", lw=2, label="measured")
    for k, model_path in enumerate(result.models):
        pred = load_model(model_path).predict_trial(trial)
        h = pred.shape[1]
        axes[0].plot(pred[:, h - 1, 0], pred[:, h - 1, 1], lw=1, color=f"C{k}", label=f"M{k}: x̂(k+{h})")
        valid = np.arange(trial.n_samples - h)
        err = np.linalg.norm(pred[valid, h - 1] - trial.pose[valid + h], axis=1)
        axes[1].plot(trial.time[valid], err * 1000, color=f"C{k}", lw=1, label=f"M{k}")
    # y stretched (not equal axes): the detours are centimetres on a half-metre path
    axes[0].set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    axes[0].grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    axes[1].set_xlabel("t [s]")
    axes[1].set_ylabel("error at 0.4 s ahead [mm]")
    axes[1].grid(alpha=0.3)
    axes[1].legend(fontsize=7)
    s.add_figure(
        fig,
        "One linear trial of the last collection (final model in the loop; no model trained on it): each model's "
        "prediction 0.4 s ahead (Fig. 5.13) and its point-wise error (Fig. 5.15, 5.17).",
    )
    plt.close(fig)
