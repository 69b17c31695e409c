"""The dMPC study of thesis §5.2.1 (Fig. 5.2–5.4).

One Cartesian DOF with the thesis' impedance (M = 10 kg, D = 100 N·s/m, K = 0,
dt = 0.008 s) is driven by both players applying their cooperative-equilibrium
efforts, u_h(k) + u_r(k), while the human's reference is x_ref,h = sin t and the
robot's x_ref,r = 0.5 sin t (velocity references are their derivatives). The study
sweeps α ∈ {0.2, 0.5, 0.9}, R_r ∈ {0.01, 5e-4, 1e-4} and the horizon
Np ∈ {5, 20, 50} samples, with Q_hh = Q_rr = diag(1, 1e-4), Q_hr = Q_rh = 0,
R_h = 5e-4, and reports the RMS tracking error against each reference.

Output scaling. The cost compares metres with newtons. With the thesis' weights
in SI units the effort cost dominates: over a 0.4 s horizon a force F moves the
10 kg tip by only about 0.008·F metres, so the optimum barely moves: every case
ends between 0.60 and 0.69 m RMS error to sin t, i.e. the tip hardly follows. The
three orderings already hold in SI units, but by margins of a few millimetres —
nothing like the thesis' figures. Expressing the output in decimetres — y' = s·y
with s = 10, i.e. Q scaled by s² = 100 — makes tracking and effort costs comparable
and reproduces the figures, with large effects. In centimetres (s = 100) tracking
is already saturated at Np = 5 and the horizon effect no longer holds everywhere.
``position_scale`` sets s; the study also runs SI units (s = 1) for the contrast.
"""

from __future__ import annotations

import itertools
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from coassist._checks import check_positive_scalar, is_real_number
from coassist._io import atomic_write_text, save_figure
from coassist.config import GameWeights
from coassist.control.game import CooperativeGame
from coassist.model.impedance import ImpedanceModel

ALPHAS = (0.2, 0.5, 0.9)
ROBOT_EFFORT_WEIGHTS = (0.01, 5e-4, 1e-4)
HORIZONS = (5, 20, 50)


#: [s] The longest case a sweep simulates (an hour: 450 000 ticks at the thesis' 8 ms).
MAX_DURATION = 3600.0
#: The largest output scaling of positions in the cost: millimetres (1 is SI, 10 the thesis' decimetres).
MAX_POSITION_SCALE = 1000.0


@dataclass(frozen=True)
class SweepConfig:
    """Parameters of the study; the defaults are the thesis' (§5.2, §5.2.1)."""

    alphas: tuple[float, ...] = ALPHAS
    robot_effort_weights: tuple[float, ...] = ROBOT_EFFORT_WEIGHTS
    horizons: tuple[int, ...] = HORIZONS
    duration: float = 10.0  # s
    dt: float = 0.008  # s
    mass: float = 10.0  # kg
    damping: float = 100.0  # N·s/m
    position_weight: float = 1.0  # Q_hh = Q_rr = diag(position_weight, velocity_weight)
    velocity_weight: float = 1e-4
    human_effort_weight: float = 5e-4  # R_h
    human_amplitude: float = 1.0  # x_ref,h = A_h sin t [m]
    robot_amplitude: float = 0.5  # x_ref,r = A_r sin t [m]
    position_scale: float = 10.0  # output in decimetres: see the module docstring

    def __post_init__(self) -> None:
        for name in (
            "duration",
            "dt",
            "mass",
            "damping",
            "human_effort_weight",
            "position_scale",
            "position_weight",
            "human_amplitude",
            "robot_amplitude",
        ):
            object.__setattr__(self, name, check_positive_scalar(getattr(self, name), name))
        if self.position_scale > MAX_POSITION_SCALE:  # 1e20 made the game's Hessian indefinite in floating point
            raise ValueError(
                f"position_scale must be at most {MAX_POSITION_SCALE:g} (positions in millimetres), got "
                f"{self.position_scale:g}"
            )
        if self.duration < self.dt:
            raise ValueError(f"duration must be at least one sample (dt = {self.dt}), got {self.duration}")
        if self.duration > MAX_DURATION:  # a case is simulated tick by tick: 1e308 s never ends (or overflows)
            raise ValueError(f"duration must be at most {MAX_DURATION:g} s, got {self.duration:g}")
        if not (np.isfinite(self.velocity_weight) and self.velocity_weight >= 0):
            raise ValueError(f"velocity_weight must be a finite number >= 0, got {self.velocity_weight}")
        object.__setattr__(self, "alphas", _values(self.alphas, "alphas", lambda a: 0.0 <= a <= 1.0, "in [0, 1]"))
        object.__setattr__(
            self,
            "robot_effort_weights",
            _values(self.robot_effort_weights, "robot_effort_weights", lambda r: 0.0 < r < np.inf, "finite and > 0"),
        )
        horizons = _values(self.horizons, "horizons", lambda h: h >= 1 and float(h).is_integer(), "integers >= 1")
        object.__setattr__(self, "horizons", tuple(int(h) for h in horizons))


def _values(values, name: str, ok, requirement: str) -> tuple[float, ...]:
    """A non-empty tuple of finite numbers satisfying ``ok``, or a ValueError naming ``name``."""
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        raise ValueError(f"{name} must be a list of numbers, got {values!r}")
    out = []
    for v in values:
        if not is_real_number(v) or not np.isfinite(v) or not ok(v):
            raise ValueError(f"{name} must be {requirement}, got {values!r}")
        out.append(float(v))
    if not out:
        raise ValueError(f"{name} must not be empty")
    return tuple(out)


@dataclass(frozen=True)
class CaseResult:
    alpha: float
    R_r: float
    horizon: int
    rms_error_human: float  # m, RMS of x − x_ref,h
    rms_error_robot: float  # m, RMS of x − x_ref,r
    rms_effort_human: float  # N
    rms_effort_robot: float  # N


@dataclass(frozen=True)
class SweepResult:
    config: SweepConfig
    cases: tuple[CaseResult, ...]
    si_cases: tuple[CaseResult, ...]  # the same sweep with position_scale = 1
    time: np.ndarray  # (T,) s
    trajectories: dict[tuple[float, float, int], np.ndarray]  # (α, R_r, Np) → x (T,) [m]
    observations: dict[str, dict]
    elapsed_s: float


def references(config: SweepConfig, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """y_ref,h and y_ref,r at t = k·dt, k = 0…n_samples−1, each (n_samples, 2): [position, velocity]."""
    t = np.arange(n_samples) * config.dt
    base = np.stack([np.sin(t), np.cos(t)], axis=1)
    return config.human_amplitude * base, config.robot_amplitude * base


def simulate_case(
    config: SweepConfig, alpha: float, R_r: float, horizon: int, position_scale: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run one case; returns x (T,) [m] at k = 1…T and the efforts u_h, u_r (T,) [N] at k = 0…T−1.

    The output scaling s multiplies both outputs, so the weights become s²·Q.
    """
    model = ImpedanceModel(config.mass, config.damping, 0.0, config.dt)
    Q = np.diag([config.position_weight, config.velocity_weight]) * position_scale**2
    zero = np.zeros_like(Q)
    weights = GameWeights(Q, zero, zero, Q, np.array([[config.human_effort_weight]]), np.array([[R_r]]))
    game = CooperativeGame(model, weights, alpha=alpha, horizon=horizon)
    T = int(round(config.duration / config.dt))
    ref_h, ref_r = references(config, T + horizon + 1)
    z = np.zeros(2)
    x = np.empty(T)
    u_h_log = np.empty(T)
    u_r_log = np.empty(T)
    for k in range(T):
        u_h, u_r = game.solve(z, ref_h[k + 1 : k + 1 + horizon], ref_r[k + 1 : k + 1 + horizon])
        z = model.Ad @ z + model.Bd @ (u_h + u_r)
        x[k] = z[0]
        u_h_log[k], u_r_log[k] = u_h[0], u_r[0]
    return x, u_h_log, u_r_log


def _sweep(config: SweepConfig, position_scale: float, progress=None, task=None):
    T = int(round(config.duration / config.dt))
    ref_h, ref_r = references(config, T + 1)
    cases, trajectories = [], {}
    for R_r, horizon, alpha in itertools.product(config.robot_effort_weights, config.horizons, config.alphas):
        x, u_h, u_r = simulate_case(config, alpha, R_r, horizon, position_scale)
        cases.append(
            CaseResult(
                alpha=alpha,
                R_r=R_r,
                horizon=horizon,
                rms_error_human=float(np.sqrt(np.mean((x - ref_h[1:, 0]) ** 2))),
                rms_error_robot=float(np.sqrt(np.mean((x - ref_r[1:, 0]) ** 2))),
                rms_effort_human=float(np.sqrt(np.mean(u_h**2))),
                rms_effort_robot=float(np.sqrt(np.mean(u_r**2))),
            )
        )
        trajectories[(alpha, R_r, horizon)] = x
        if progress is not None:
            progress.advance(task)
    return tuple(cases), trajectories


def _is_monotone(values: list[float], decreasing: bool = True) -> bool:
    diffs = np.diff(values)
    return bool(np.all(diffs < 0) if decreasing else np.all(diffs > 0))


def check_observations(config: SweepConfig, cases: tuple[CaseResult, ...]) -> dict[str, dict]:
    """The thesis' three claims, each checked over every combination of the other two parameters.

    - higher α tracks the human's reference more closely (error to x_ref,h falls as α rises);
    - lower R_r makes the robot more responsive (error to x_ref,h falls as R_r falls);
    - a longer horizon tracks better (error to x_ref,h falls as Np grows).
    """
    table = {(c.alpha, c.R_r, c.horizon): c.rms_error_human for c in cases}
    alphas = sorted(config.alphas)
    weights = sorted(config.robot_effort_weights, reverse=True)
    horizons = sorted(config.horizons)

    def check(series_of) -> dict:
        series = list(series_of())
        if all(len(values) < 2 for _, values in series):
            return {"holds": None, "counterexamples": [], "note": "n/a: the swept axis has a single value"}
        failures = [key for key, values in series if not _is_monotone(values)]
        return {"holds": not failures, "counterexamples": [list(k) for k in failures]}

    return {
        "higher_alpha_tracks_human_reference": check(
            lambda: (((r, h), [table[(a, r, h)] for a in alphas]) for r in weights for h in horizons)
        ),
        "lower_R_r_tracks_better": check(
            lambda: (((a, h), [table[(a, r, h)] for r in weights]) for a in alphas for h in horizons)
        ),
        "longer_horizon_tracks_better": check(
            lambda: (((a, r), [table[(a, r, h)] for h in horizons]) for a in alphas for r in weights)
        ),
    }


def run_sweep(config: SweepConfig, out: Path | None = None, *, progress: bool = False) -> SweepResult:
    """Run the study (and its SI-unit contrast); write ``dmpc_sweep.png`` and ``summary.json`` to ``out``."""
    start = time.perf_counter()
    n_cases = len(config.alphas) * len(config.robot_effort_weights) * len(config.horizons)
    if progress:
        from rich.progress import Progress

        with Progress() as bar:
            task = bar.add_task("dMPC sweep", total=2 * n_cases)
            cases, trajectories = _sweep(config, config.position_scale, bar, task)
            si_cases, _ = _sweep(config, 1.0, bar, task)
    else:
        cases, trajectories = _sweep(config, config.position_scale)
        si_cases, _ = _sweep(config, 1.0)
    T = int(round(config.duration / config.dt))
    result = SweepResult(
        config=config,
        cases=cases,
        si_cases=si_cases,
        time=np.arange(1, T + 1) * config.dt,
        trajectories=trajectories,
        observations=check_observations(config, cases),
        elapsed_s=time.perf_counter() - start,
    )
    if out is not None:
        write_outputs(result, Path(out))
    return result


def summary(result: SweepResult) -> dict:
    """The JSON-able numbers of a sweep."""
    si_errors = [c.rms_error_human for c in result.si_cases]
    return {
        "experiment": "dmpc_sweep",
        "thesis": "§5.2.1, Fig. 5.2-5.4",
        "config": asdict(result.config),
        "cases": [asdict(c) for c in result.cases],
        "observations": result.observations,
        "si_units": {
            "position_scale": 1.0,
            "cases": [asdict(c) for c in result.si_cases],
            "observations": check_observations(result.config, result.si_cases),
            "spread_of_error_to_human_reference": [min(si_errors), max(si_errors)],
        },
        "elapsed_s": result.elapsed_s,
    }


def write_outputs(result: SweepResult, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    cfg = result.config
    weights, horizons = cfg.robot_effort_weights, cfg.horizons
    fig, axes = plt.subplots(
        len(weights),
        len(horizons),
        figsize=(4.2 * len(horizons), 3.0 * len(weights)),
        sharex=True,
        sharey=True,
        squeeze=False,
    )
    t = result.time
    for i, R_r in enumerate(weights):
        for j, horizon in enumerate(horizons):
            ax = axes[i][j]
            ax.plot(t, cfg.human_amplitude * np.sin(t), "k--", lw=1.2, label="x_ref,h")
            ax.plot(t, cfg.robot_amplitude * np.sin(t), "k:", lw=1.2, label="x_ref,r")
            for alpha in cfg.alphas:
                ax.plot(t, result.trajectories[(alpha, R_r, horizon)], lw=1.4, label=f"α = {alpha}")
            ax.set_title(f"R_r = {R_r:g}, horizon {horizon} ({horizon * cfg.dt:.2f} s)", fontsize=9)
            ax.grid(alpha=0.3)
            if i == len(weights) - 1:
                ax.set_xlabel("t [s]")
            if j == 0:
                ax.set_ylabel("x [m]")
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"Cooperative dMPC tracking (thesis Fig. 5.2–5.4), output scaling s = {cfg.position_scale:g}")
    fig.tight_layout()
    save_figure(fig, out / "dmpc_sweep.png")
    plt.close(fig)
    atomic_write_text(out / "summary.json", json.dumps(summary(result), indent=2))


def print_summary(result: SweepResult, console) -> None:
    from rich.table import Table

    table = Table(title=f"dMPC sweep: RMS error to x_ref,h [m] (scaling s = {result.config.position_scale:g})")
    table.add_column("R_r")
    table.add_column("horizon [samples]")
    for alpha in result.config.alphas:
        table.add_column(f"α = {alpha}", justify="right")
    by_key = {(c.alpha, c.R_r, c.horizon): c for c in result.cases}
    for R_r in result.config.robot_effort_weights:
        for horizon in result.config.horizons:
            table.add_row(
                f"{R_r:g}",
                str(horizon),
                *(f"{by_key[(a, R_r, horizon)].rms_error_human:.4f}" for a in result.config.alphas),
            )
    console.print(table)
    for name, verdict in result.observations.items():
        if verdict["holds"] is None:
            mark = f"[yellow]{verdict['note']}[/]"
        elif verdict["holds"]:
            mark = "[green]holds[/]"
        else:
            mark = f"[red]does not hold[/] {verdict['counterexamples']}"
        console.print(f"  {name}: {mark}")
