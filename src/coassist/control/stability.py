"""When the person and the assistance fall into an oscillation: the robot becomes a damper (issue 40).

A person whose own arm loop is near its margin — a stiff arm behind a long reflex delay — moving a tool of
damping D through that delay is stable only while K τ / D < π/2 (a first-order plant under delayed proportional
feedback). The simulated people stiffen with their tracking error (K up to K_max), so such a person can cross it
mid-trial. Assistance that follows the hand's force adds to the loop: a held-out person (K 905–2584 N/m, τ = 0.149 s)
fell into a limit cycle round the target with the default source, the tool orbiting 6 cm out at about 1 Hz against
39–42 N of steady hand force, every trial at the time limit (docs/person-model.md, "People the assistance
destabilises"). Taking the robot's effort away (manual guidance from then on) did not end the cycle once it had
begun; damping does: D + c > K τ / (π/2) is 245 N·s/m for K = 2.6 kN/m and τ = 0.149 s, against the application
preset's D = 100 N·s/m.

:class:`StabilityGuard` wraps a controller. Each tick it low-passes the hand force's magnitude and the force itself,

    f̄ ← f̄ + a (‖w‖ − f̄),    w̄ ← w̄ + a (w − w̄),    a = 1 − e^(−dt/τ_f),

and the first time f̄ passes f_s while the force turns, ρ = ‖w̄‖ / f̄ ≤ ρ_s, it engages for the rest of the run.
ρ is 1 for a force held in one direction and near 0 for one that goes round: in the limit cycles above the hand
force circles with the tool (ρ 0.33–0.57 where f̄ first passed 20 N, 0.1–0.7 after), while real people push hard
in one direction: in 7 of the 18 recorded UR5 trials of the thesis' lab (user-a) f̄ passed 20 N (up to 32 N), with
ρ ≥ 0.90 throughout — a guard on f̄ alone would have made their assistance a damper. Over ``fade_time`` the robot's
effort then moves from the controller's u_c to a damper's,

    u_r = g u_c − (1 − g) c v,   g = max(0, 1 − m dt / t_fade) on the m-th tick engaged (m = 1, 2, …),

v the velocity in the controller's state z = [Δx; v] (the measured one in an effort world, the admittance's, which
the arm tracks, in an arm world), saturated to the controller's ``effort_limit`` keeping its direction
(:func:`~coassist.control.controllers.saturate`, ``SATURATED``); every tick engaged carries
``Fault.STABILITY_DAMPING``. Until then ``step`` returns the controller's own answer, the same object. A tick the
controller's guard refused (:data:`~coassist.interfaces.ZERO_EFFORT_FAULTS`: a non-finite or invalid state, reference
or wrench) stays its answer, zero effort and flagged, engaged or not; a wrench that is not finite, or not of the
controller's n DOFs (the control tick never passes one: it checks the controller's DOFs against its own), leaves f̄
and w̄ as they were.

f_s = 20 N: under assistance the report's operators need 2–3 N RMS of hand force, under manual guidance 4–5 N, and
20 N for half a second is a person fighting the tool or the loop. ρ_s = 0.75: between the cycles' ≤ 0.57 and the
real pushes' ≥ 0.90 (a force turning at ω against the low-pass's 1/τ_f has ρ → 1/√(1 + (ω τ_f)²): 0.30 at 1 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_positive_scalar, check_real
from coassist.control.controllers import ControlStep, saturate
from coassist.interfaces import ZERO_EFFORT_FAULTS, Fault

__all__ = ["StabilityGuard", "StabilityGuardParameters"]


@dataclass(frozen=True)
class StabilityGuardParameters:
    """When the guard engages and what the robot then is (module docstring). SI units.

    force_threshold : f_s [N], the low-passed hand force above which the guard engages.
    time_constant : τ_f [s], of that low-pass: a push of 2 f_s engages it after about 0.7 τ_f.
    fade_time : [s] from the controller's effort to the damper's, once engaged.
    damping : c [N·s/m], the damper the robot becomes (added to the plant's own D).
    direction_ratio : ρ_s in (0, 1], it engages only while ‖w̄‖ / f̄ ≤ ρ_s: a hand force that turns (an
        oscillation), not one held in one direction (a person pushing hard). 1: any force held above f_s.
    """

    force_threshold: float = 20.0
    time_constant: float = 0.5
    fade_time: float = 0.5
    damping: float = 150.0
    direction_ratio: float = 0.75

    def __post_init__(self) -> None:
        for name in ("force_threshold", "time_constant", "fade_time", "damping"):
            object.__setattr__(
                self, name, check_positive_scalar(getattr(self, name), f"StabilityGuardParameters.{name}")
            )
        # ‖w̄‖ / f̄ is at most 1 (the mean of vectors is no longer than the mean of their lengths)
        object.__setattr__(
            self,
            "direction_ratio",
            check_real(self.direction_ratio, "StabilityGuardParameters.direction_ratio", 0.0, 1.0, open_lo=True),
        )


class StabilityGuard:
    """A controller that becomes a damper once a large hand force turns, an oscillation (module docstring).

    Parameters
    ----------
    controller : the controller to guard (``name``, ``model``, ``horizon``, ``step``; an assistive one: manual
        guidance and impedance control are the baselines and stay as they are).
    params : :class:`StabilityGuardParameters`.

    ``engaged_at`` is the tick (counted from the last ``reset``) at which it engaged, None before; ``force`` is f̄
    [N] and ``mean_force`` w̄ (n,) [N], as of the last tick.
    """

    def __init__(self, controller: Any, params: StabilityGuardParameters | None = None) -> None:
        for attr in ("step", "model", "horizon"):
            if not hasattr(controller, attr):
                raise ValueError(
                    f"controller must have {attr!r} (a controller of coassist.control), got {controller!r}"
                )
        params = StabilityGuardParameters() if params is None else params
        if not isinstance(params, StabilityGuardParameters):
            raise ValueError(f"params must be StabilityGuardParameters, got {type(params).__name__}")
        self.controller, self.params = controller, params
        # the controller's own name: the guard is a safety behaviour of the loop (a study's conditions, a trial's
        # controller, are the controller's); the ticks it acts on carry STABILITY_DAMPING
        self.name = getattr(controller, "name", type(controller).__name__)
        self.model, self.horizon = controller.model, controller.horizon
        self.effort_limit = getattr(controller, "effort_limit", None)
        self.n = int(controller.model.n_dof)
        dt = float(controller.model.dt)
        self._gain = 1.0 - math.exp(-dt / params.time_constant)
        self._fade = dt / params.fade_time
        self.reset()

    @property
    def alpha(self) -> float | None:
        """The controller's α where it has one (an arbitrated game's, what a live view shows), else None."""
        return getattr(self.controller, "alpha", None)

    def reset(self) -> None:
        """A new run: f̄ = 0, not engaged (and the controller's own state, where it keeps one)."""
        inner_reset = getattr(self.controller, "reset", None)
        if callable(inner_reset):
            inner_reset()
        self.force = 0.0
        self.mean_force = np.zeros(self.n)
        self.share = 1.0  # g
        self.engaged_at: int | None = None
        self._k = 0

    def step(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike, wrench: ArrayLike) -> ControlStep:
        """The controller's step, or once engaged the fade to the damper (module docstring). Never raises."""
        out = self.controller.step(z, ref_h, ref_r, wrench)
        k = self._k
        self._k += 1
        try:
            w = np.asarray(wrench, dtype=float).reshape(-1)
            f = math.sqrt(float(w @ w)) if w.size == self.n else math.nan
        except (TypeError, ValueError):
            f = math.nan
        if math.isfinite(f):
            self.force += self._gain * (f - self.force)
            self.mean_force += self._gain * (w - self.mean_force)
        if self.engaged_at is None:
            if not self.force > self.params.force_threshold:
                return out
            m = self.mean_force
            if math.sqrt(float(m @ m)) > self.params.direction_ratio * self.force:
                return out  # held in one direction: a person pushing, not an oscillation
            self.engaged_at = k
        self.share = max(0.0, self.share - self._fade)
        if out.fault & ZERO_EFFORT_FAULTS:
            return out  # a bad tick gives zero effort, as the controller's guard says (no damper on a bad state)
        v = np.asarray(z, dtype=float).reshape(-1)[self.n : 2 * self.n]
        if not np.isfinite(v).all():  # a controller without the guard's checks: no damper on a bad state
            v = np.zeros(self.n)
        u = self.share * np.asarray(out.u_r, dtype=float) - (1.0 - self.share) * self.params.damping * v
        fault = out.fault | Fault.STABILITY_DAMPING
        if self.effort_limit is not None:
            u, clipped = saturate(u, np.broadcast_to(np.asarray(self.effort_limit, dtype=float), (self.n,)))
            if clipped:
                fault |= Fault.SATURATED
        return ControlStep(u, out.u_h_model, fault)
