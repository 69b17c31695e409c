"""Online assistance level: α of the cooperative game set every tick (the thesis' future work).

α is the share of the human's cost in the shared objective (eq. 3.17): α → 1 the robot
helps toward the predicted human reference ŷ_ref,h, α → 0 toward its own plan y_ref,r.
An arbitration law maps what the robot measures to α ∈ [α_min, α_max]:

- ``"hand_force"``: the harder the operator pushes, the more the robot follows them::

      α* = α_min + (α_max − α_min) · min(1, ||w|| / f_s)

  (w the measured hand force [N], f_s ``force_scale``). A passive operator leaves the
  robot on its plan, whose end is the target; one who pushes away from it is followed.
- ``"confidence"``: the robot trusts the prediction as far as it has come true. At tick k
  it compares the position predicted ``error_lag`` = d ticks ago for now with the
  measured one, e(k) = ||x̂_{k−d}(k) − x(k)||, filters it (time constant τ) into ē and::

      c = exp(−ē / e_s),   α* = α_min + (α_max − α_min) · c

- ``"target"``: the robot's plan ends at the target, a physical point it knows better
  than any prediction. Far from where the plan's horizon ends the robot follows the
  person; close to it, it homes in on its plan::

      e = ||x − y_ref,r(k+H)||,   α* = α_min + (α_max − α_min) · min(1, e / e_t)

  (x the tool position, y_ref,r(k+H) the plan's last row in the horizon, e_t
  ``target_scale``). Mid-task the plan's horizon lies ahead of the tool and α stays high;
  once the plan rests at the target and the tool comes within e_t of it, α falls.

Either target α* is then low-pass filtered, α(k) = α(k−1) + (dt/τ)(α* − α(k−1)), so the
gains never jump; with :meth:`CooperativeGame.set_alpha` a new α costs microseconds
(:mod:`coassist.control.game`, "Online α").

:class:`ArbitratedController` wraps an :class:`~coassist.control.controllers.AssistiveController`
on a cooperative game and sets the game's α before each guarded step. A non-finite
input leaves α where it was (the guard then refuses the tick as before).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_int_at_least, check_positive_scalar, check_real
from coassist.control.controllers import AssistiveController, ControlStep
from coassist.control.game import CooperativeGame, solve_with_gains

__all__ = [
    "ARBITRATION_LAWS",
    "AlphaArbiter",
    "ArbitratedController",
    "ArbitrationParameters",
    "arbitrated_effort_batch",
    "arbitrated_step_batch",
    "guard_key",
    "target_alpha",
]

#: The arbitration laws of :class:`ArbitrationParameters`.
ARBITRATION_LAWS = ("hand_force", "confidence", "target")


@dataclass(frozen=True)
class ArbitrationParameters:
    """An arbitration law and its constants (module docstring). SI units.

    law : one of :data:`ARBITRATION_LAWS`.
    alpha_min, alpha_max : the range of α, 0 ≤ α_min ≤ α_max ≤ 1.
    force_scale : f_s [N], the hand force at which the ``hand_force`` law reaches α_max.
    error_scale : e_s [m], the filtered prediction error at which the ``confidence``
        law's trust has fallen to 1/e.
    error_lag : d [ticks] ≥ 1, how old the prediction checked against the pose is.
    target_scale : e_t [m], the distance from the plan's horizon end below which the
        ``target`` law lowers α (α_min at the plan's end itself).
    time_constant : τ [s], of the α filter and of the error filter.
    """

    law: str = "hand_force"
    alpha_min: float = 0.6
    alpha_max: float = 0.95
    force_scale: float = 5.0
    error_scale: float = 0.005
    error_lag: int = 10
    target_scale: float = 0.05
    time_constant: float = 0.2

    def __post_init__(self) -> None:
        if self.law not in ARBITRATION_LAWS:
            raise ValueError(f"arbitration.law must be one of {ARBITRATION_LAWS}, got {self.law!r}")
        for name in ("alpha_min", "alpha_max"):
            try:
                v = float(getattr(self, name))
            except (TypeError, ValueError):
                raise ValueError(
                    f"arbitration.{name} must be a number in [0, 1], got {getattr(self, name)!r}"
                ) from None
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"arbitration.{name} must be in [0, 1], got {getattr(self, name)!r}")
            object.__setattr__(self, name, v)
        if self.alpha_min > self.alpha_max:
            raise ValueError(
                f"arbitration.alpha_min ({self.alpha_min}) must be <= arbitration.alpha_max ({self.alpha_max})"
            )
        for name in ("force_scale", "error_scale", "target_scale", "time_constant"):
            object.__setattr__(self, name, check_positive_scalar(getattr(self, name), f"arbitration.{name}"))
        object.__setattr__(self, "error_lag", check_int_at_least(self.error_lag, "arbitration.error_lag", 1))


def target_alpha(params: ArbitrationParameters, signal: float) -> float:
    """α* of the law for its signal: ||w|| [N] (``hand_force``), ē [m] (``confidence``) or e [m] (``target``)."""
    span = params.alpha_max - params.alpha_min
    if params.law == "confidence":
        return params.alpha_min + span * math.exp(-signal / params.error_scale)
    scale = params.force_scale if params.law == "hand_force" else params.target_scale
    return params.alpha_min + span * min(1.0, signal / scale)


class AlphaArbiter:
    """The stateful part of a law: the α filter, the error filter and the recent predictions.

    Parameters
    ----------
    params : the law.
    n_dof : n, the controlled DOFs (z is [Δx; v], (2n,)).
    dt : the tick [s].
    alpha0 : α at the start of a run (also where :meth:`reset` returns).
    """

    def __init__(self, params: ArbitrationParameters, n_dof: int, dt: float, alpha0: float) -> None:
        if not isinstance(params, ArbitrationParameters):
            raise ValueError(f"params must be ArbitrationParameters, got {type(params).__name__}")
        self.params = params
        self.n = check_int_at_least(n_dof, "n_dof", 1)
        self.dt = check_positive_scalar(dt, "dt")
        # a NaN would pass min/max into every tick's α, and a truth value is no α
        alpha0 = check_real(alpha0, "alpha0", -math.inf)
        self.alpha0 = min(max(alpha0, params.alpha_min), params.alpha_max)
        self._gain = min(1.0, self.dt / params.time_constant)
        d = params.error_lag
        self._pred = np.full((d, self.n), np.nan)  # ring: the position predicted for k+d at tick k
        self.reset()

    def reset(self) -> None:
        """A new run: α back to α0, no prediction history, no error."""
        self.alpha = self.alpha0
        self.error = 0.0
        self._pred[:] = np.nan
        self._k = 0

    def update(self, z: np.ndarray, ref_h: np.ndarray, wrench: np.ndarray, ref_r: np.ndarray | None = None) -> float:
        """α for this tick from z (2n,), ref_h (H, 2n), the hand force (n,) [N] and the
        robot's plan ref_r (H, 2n; the ``target`` law). Never raises."""
        p, n = self.params, self.n
        try:
            if p.law == "hand_force":
                w = np.asarray(wrench, dtype=float).reshape(-1)[:n]
                signal = float(math.sqrt(float(np.dot(w, w))))
            elif p.law == "target":
                x = np.asarray(z, dtype=float).reshape(-1)[:n]
                end = np.asarray(ref_r, dtype=float)[-1, :n]
                d = x - end
                signal = float(math.sqrt(float(np.dot(d, d))))  # np.linalg.norm costs ~2 µs more per tick
            else:
                x = np.asarray(z, dtype=float).reshape(-1)[:n]
                ref = np.asarray(ref_h, dtype=float)
                d = p.error_lag
                slot = self._k % d
                old = self._pred[slot]  # predicted d ticks ago for now
                if np.isfinite(old).all() and np.isfinite(x).all():
                    e = float(np.linalg.norm(old - x))
                    self.error += self._gain * (e - self.error)
                row = ref[d - 1, :n] if ref.ndim == 2 and ref.shape[0] >= d else np.full(n, np.nan)
                self._pred[slot] = row
                self._k += 1
                signal = self.error
            return self.advance(signal)
        except Exception:  # unusable input (e.g. an object array): α stays where it was, the tick goes on
            pass
        return self.alpha

    def advance(self, signal: float) -> float:
        """α for this tick from the law's signal (a float: ``target_alpha``'s), as :meth:`update`
        ends: the α filter moves toward α*; a non-finite signal leaves α where it was."""
        if math.isfinite(signal):
            self.alpha += self._gain * (target_alpha(self.params, signal) - self.alpha)
        return self.alpha


class ArbitratedController:
    """An assistive controller on a cooperative game whose α an :class:`AlphaArbiter` sets each tick.

    Parameters
    ----------
    controller : an :class:`AssistiveController` on a :class:`CooperativeGame`; its
        game's α changes at run time (:meth:`CooperativeGame.set_alpha`).
    params : the arbitration law.

    ``alpha`` is the α in use; :meth:`reset` starts a new run (α back to the game's
    initial α, clipped to the law's range).
    """

    def __init__(self, controller: AssistiveController, params: ArbitrationParameters) -> None:
        if not isinstance(controller, AssistiveController) or not isinstance(controller.game, CooperativeGame):
            raise ValueError(
                "controller must be an AssistiveController on a CooperativeGame (α is the cooperative game's)"
            )
        self.controller = controller
        self.game: CooperativeGame = controller.game
        self.name = f"{controller.name}+{params.law}"
        self.model = controller.model
        self.horizon = controller.horizon
        self.effort_limit = controller.effort_limit
        alpha_start = self.game.alpha
        self.game.prepare_alpha_changes()  # before the loop: no tick pays for it
        self.arbiter = AlphaArbiter(params, self.model.n_dof, float(self.model.dt), alpha_start)
        self.reset()

    @property
    def alpha(self) -> float:
        return self.game.alpha

    def reset(self) -> None:
        self.arbiter.reset()
        self.game.set_alpha(self.arbiter.alpha)

    def step(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike, wrench: ArrayLike) -> ControlStep:
        """One tick: α from the law, then the guarded assistive step (same contract: never raises)."""
        alpha = self.arbiter.update(z, ref_h, wrench, ref_r)
        if alpha != self.game.alpha:
            try:
                self.game.set_alpha(alpha)
            except Exception:  # keep the previous gains; the step below still runs and never raises
                pass
        return self.controller.step(z, ref_h, ref_r, wrench)


def guard_key(controller: ArbitratedController) -> tuple:
    """What :func:`arbitrated_effort_batch` needs its controllers to share: the assistive
    controller's guard (type, horizon, bounds, effort limit, shapes) and the game's class."""
    inner = controller.controller
    return (
        type(inner),
        type(controller.game),
        inner.horizon,
        inner.bounds,
        inner._ref_shape,
        inner._wrench_shape,
        np.asarray(inner.effort_limit, dtype=float).tobytes(),
        inner._state_bound.tobytes(),
    )


def arbitrated_effort_batch(
    controllers: list[ArbitratedController], z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`ArbitratedController.step` for B runs at once, run b with its own controller
    (its α and the arbiter's state), answered as
    :meth:`~coassist.control.controllers._GuardedController.effort_batch` answers.

    z (B, 2n), ref_h and ref_r (B, Np, 2n), wrench (B, n). Row b first updates
    ``controllers[b]``'s arbiter and sets its game's α, exactly as its ``step`` does (that
    happens whatever the guard then finds); then the guarded step runs for all rows at once,
    row b on its own gains (:func:`~coassist.control.game.solve_with_gains`). Returns
    (u_r (B, n), clean (B,) bool): where ``clean[b]``, ``u_r[b]`` is what
    ``controllers[b].step(z[b], ref_h[b], ref_r[b], wrench[b])`` gives, bit for bit, and
    that step carries no fault flag; elsewhere the row's effort is not given, and its
    arbiter has already advanced for this tick: the caller must not call that controller's
    ``step`` for the tick again (the lockstep runner rebuilds such a run and reruns it on
    the reference path). The controllers must share :func:`guard_key` and must be B
    distinct objects on B distinct games (every α is set before any gains are read).
    Never raises.
    """
    if not controllers:
        return np.zeros((0, z.shape[1] // 2 if np.ndim(z) == 2 else 0)), np.zeros(0, dtype=bool)
    inner = controllers[0].controller
    core = inner._batch_core(z, ref_h, ref_r, wrench, law=_advanced_law(controllers, z, ref_h, ref_r, wrench))
    return inner._clean_efforts(core, z, ref_h, ref_r, wrench, lambda b: controllers[b].controller.step)


def arbitrated_step_batch(
    controllers: list[ArbitratedController], z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray
) -> list[ControlStep]:
    """:meth:`ArbitratedController.step` for B runs at once, run b with its own controller, answered as
    :meth:`~coassist.control.controllers._GuardedController.step_batch` answers: row b's
    :class:`~coassist.control.controllers.ControlStep` is ``controllers[b].step(z[b], ref_h[b], ref_r[b],
    wrench[b])`` bit for bit (u_r, u_h and the flags; saturated rows included), and every arbiter has
    advanced once, as that step advances it. The arbiters and the α as :func:`arbitrated_effort_batch`; a
    row the batched guard does not take (out of bounds, not finite, a non-finite effort, or every row
    where the batch cannot run) is the guarded step of its own assistive controller on the α just set
    (what ``controllers[b].step`` runs after its arbiter). The same requirements: one
    :func:`guard_key`, B distinct objects on B distinct games. Never raises."""
    if not controllers:
        return []
    inner = controllers[0].controller
    core = inner._batch_core(z, ref_h, ref_r, wrench, law=_advanced_law(controllers, z, ref_h, ref_r, wrench))
    return inner._steps(core, z, ref_h, ref_r, wrench, lambda b: controllers[b].controller.step)


def _advanced_law(
    controllers: list[ArbitratedController], z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray
) -> Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Every row's arbiter advanced and its game's α set, as each ``step`` does before its guarded
    step (whatever the guard then finds); the law of the batch's good rows on their own gains
    (:func:`~coassist.control.game.solve_with_gains`)."""
    for c, alpha in zip(controllers, _arbitrate(controllers, z, ref_h, ref_r, wrench)):
        if alpha != c.game.alpha:
            try:
                c.game.set_alpha(alpha)
            except Exception:  # keep the previous gains, as step() does
                pass
    gains = [c.game.gains for c in controllers]

    def law(good: np.ndarray, zg: np.ndarray, rh: np.ndarray, rr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return solve_with_gains([gains[i] for i in good.tolist()], zg, rh, rr)

    return law


def _arbitrate(
    controllers: list[ArbitratedController], z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray
) -> list[float]:
    """Each row's arbiter updated as ``controllers[b].arbiter.update(z[b], ref_h[b], wrench[b], ref_r[b])``
    does it: its α for this tick, in row order.

    Where every arbiter has the ``target`` law on the same n DOFs and the inputs are float64
    arrays, the distances d = x − y_ref,r(k+H) of all rows are one subtraction (elementwise: each
    row's own), and each row's signal is √(d·d) with ``np.dot`` on its row as ``update`` takes it;
    anything else goes through ``update`` row by row."""
    arbiters = [c.arbiter for c in controllers]
    n = arbiters[0].n
    if (
        all(a.params.law == "target" and a.n == n for a in arbiters)
        and all(type(a) is np.ndarray and a.dtype == np.float64 for a in (z, ref_r))
        and z.ndim == 2
        and z.shape[1] >= n
        and ref_r.ndim == 3
        and ref_r.shape[1] >= 1
        and ref_r.shape[2] >= n
        and z.shape[0] == ref_r.shape[0] == len(arbiters)
    ):
        d = z[:, :n] - ref_r[:, -1, :n]
        dot, sqrt = np.dot, math.sqrt
        return [a.advance(float(sqrt(float(dot(db, db))))) for a, db in zip(arbiters, d)]
    return [a.update(z[b], ref_h[b], wrench[b], ref_r[b]) for b, a in enumerate(arbiters)]
