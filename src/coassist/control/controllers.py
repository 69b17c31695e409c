"""Controllers for the loop: the assistive game controller and the thesis' baselines.

Every controller renders the same free plant, the impedance model with the
operator's wrench and the controller's virtual effort::

    M a + D v = u_h + u_r

and differs only in u_r:

- :class:`AssistiveController` — u_r(k) of the cooperative (or Nash) game (eq. 3.27–3.31).
- :class:`ImpedanceControl` (IMP, eq. 5.4) — M a + D v + K (x − x_ref,r) = u_h: the
  spring toward the nominal reference, applied as u_r = K (x_ref,r − x). With a moving
  reference this is exactly eq. 5.4 with Δx = x − x_ref,r(t); the robot adds no
  assistance beyond the spring.
- :class:`ManualGuidance` (MG, eq. 5.5) — u_r = 0: M a + D v = u_h.

The control law is pure; the guard around it is what keeps bad input off the robot:
a non-finite state, reference or wrench gives zero robot effort and a fault flag,
the effort is saturated to ``effort_limit`` keeping its direction, and ``step``
never raises.
"""

from __future__ import annotations

import logging
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import as_square_matrix, check_positive_semidefinite
from coassist.control.game import CooperativeGame, NashGame
from coassist.interfaces import Fault
from coassist.model.impedance import ImpedanceModel

log = logging.getLogger(__name__)


class ControlStep(NamedTuple):
    """What one tick produces.

    u_r : (n,) robot effort to add to the measured wrench [N], after the guard.
    u_h_model : (n,) the controller's model of the human effort (the game's predicted
        u_h(k)); zeros for the baselines.
    fault : the tick's fault flags.
    """

    u_r: np.ndarray
    u_h_model: np.ndarray
    fault: Fault


class Controller(Protocol):
    """What the closed loop needs from a controller."""

    name: str
    model: ImpedanceModel  # the free plant the robot renders (K = 0)
    horizon: int  # rows of ref_h / ref_r the controller reads

    def step(self, z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray) -> ControlStep: ...


def saturate(u: np.ndarray, limit: np.ndarray) -> tuple[np.ndarray, bool]:
    """Scale u (n,) so that |u_i| ≤ limit_i for all i, keeping its direction.

    Scaling the whole vector, instead of clipping each axis, keeps the assistance
    pointing where the law wants it to. Returns (u, whether it was scaled).
    """
    ratio = np.max(np.abs(u) / limit)
    if ratio <= 1.0:
        return u, False
    return u / ratio, True


class _GuardedController:
    """Input checks, saturation and fault reporting around a pure control law."""

    name = "controller"

    def __init__(self, model: ImpedanceModel, horizon: int, effort_limit: ArrayLike) -> None:
        n = model.n_dof
        if not np.all(model.K == 0):
            raise ValueError(
                "model.K must be zero: controllers render the free plant M a + D v = u_h + u_r "
                "(use model.with_stiffness(0); ImpedanceControl takes its spring K separately)"
            )
        try:
            limit = np.broadcast_to(np.asarray(effort_limit, dtype=float), (n,)).copy()
        except (TypeError, ValueError):
            raise ValueError(f"effort_limit must be a number or {n} numbers [N], got {effort_limit!r}") from None
        if np.any(~(limit > 0)):
            raise ValueError(f"effort_limit must be > 0 for every DOF (np.inf for no limit), got {effort_limit!r}")
        self.effort_limit = limit
        self._wrench_shape = (n,)
        self.model = model
        self.horizon = horizon
        self._zero = np.zeros(n)
        self._ref_shape = (horizon, 2 * n)
        self._warned = Fault.NONE

    def _law(self, z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _refuse(self, fault: Fault) -> ControlStep:
        """Zero robot effort (and no model of the human) for a tick whose input was bad."""
        self._warn_once(fault)
        return ControlStep(self._zero.copy(), self._zero.copy(), fault)

    def _warn_once(self, fault: Fault) -> None:
        new = fault & ~self._warned & ~Fault.SATURATED
        if new:
            self._warned |= new
            log.warning("%s: %s; robot effort set to zero (further occurrences are flagged, not logged)", self.name, repr(new))

    def step(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike, wrench: ArrayLike) -> ControlStep:
        """One guarded tick: z (2n,), ref_h and ref_r (horizon, 2n), wrench (n,) [N]."""
        try:
            raw = (z, ref_h, ref_r, wrench)
            if any(np.iscomplexobj(a) for a in raw):
                raise TypeError("complex input")
            z, ref_h, ref_r, wrench = (np.asarray(a, dtype=float) for a in raw)
        except (TypeError, ValueError):
            return self._refuse(Fault.INVALID_INPUT)
        if (
            ref_h.shape != self._ref_shape
            or ref_r.shape != self._ref_shape
            or z.shape != (self._ref_shape[1],)
            or wrench.shape != self._wrench_shape
        ):
            return self._refuse(Fault.INVALID_INPUT)
        try:
            fault = Fault.NONE
            if not np.isfinite(z).all():
                fault |= Fault.NONFINITE_STATE
            if not (np.isfinite(ref_h).all() and np.isfinite(ref_r).all()):
                fault |= Fault.NONFINITE_REFERENCE
            if not np.isfinite(wrench).all():
                fault |= Fault.NONFINITE_WRENCH
            if fault:
                return self._refuse(fault)
            u_h, u_r = self._law(z, ref_h, ref_r)
            if not (np.isfinite(u_r).all() and np.isfinite(u_h).all()):
                return self._refuse(Fault.NONFINITE_EFFORT)
            u_r, clipped = saturate(u_r, self.effort_limit)
            return ControlStep(u_r, u_h, Fault.SATURATED if clipped else Fault.NONE)
        except Exception as exc:  # the loop must go on; the robot gets zero effort
            if not self._warned & Fault.INTERNAL_ERROR:
                log.exception("%s: control law failed (%s); robot effort set to zero", self.name, exc)
                self._warned |= Fault.INTERNAL_ERROR
            n = self._zero.shape[0]
            return ControlStep(np.zeros(n), np.zeros(n), Fault.INTERNAL_ERROR)


class AssistiveController(_GuardedController):
    """The assistive controller: the robot applies its equilibrium effort u_r(k) of a game.

    Parameters
    ----------
    game : a :class:`CooperativeGame` (the thesis) or :class:`NashGame`.
    effort_limit : (n,) or scalar, the largest robot effort per DOF [N]; required, so
        that no robot runs unlimited by omission (pass np.inf to mean it).
    """

    def __init__(self, game: CooperativeGame | NashGame, *, effort_limit: ArrayLike) -> None:
        if not isinstance(game, (CooperativeGame, NashGame)):
            raise ValueError(f"game must be a CooperativeGame or NashGame, got {type(game).__name__}")
        self.game = game
        self.name = "cooperative" if isinstance(game, CooperativeGame) else "nash"
        super().__init__(game.model, game.horizon, effort_limit)

    def _law(self, z, ref_h, ref_r):
        return self.game.solve(z, ref_h, ref_r)


class ImpedanceControl(_GuardedController):
    """IMP baseline (eq. 5.4): a spring of stiffness K toward the nominal reference.

    Parameters
    ----------
    model : the free plant (M, D, K = 0).
    K : (n, n) or diagonal, stiffness toward x_ref,r [N/m]; PSD. Stiffer pulls the
        operator back to the nominal path harder.
    effort_limit : as for :class:`AssistiveController`.
    """

    name = "impedance"

    def __init__(self, model: ImpedanceModel, K: ArrayLike, *, effort_limit: ArrayLike) -> None:
        K = as_square_matrix(K, "K", model.n_dof)
        check_positive_semidefinite(K, "K")
        self.K = K
        super().__init__(model, 1, effort_limit)

    def _law(self, z, ref_h, ref_r):
        n = self.model.n_dof
        return self._zero.copy(), self.K @ (ref_r[0, :n] - z[:n])


class ManualGuidance(_GuardedController):
    """MG baseline (eq. 5.5): no robot effort, the operator moves the free plant alone."""

    name = "manual"

    def __init__(self, model: ImpedanceModel) -> None:
        super().__init__(model, 1, np.inf)

    def _law(self, z, ref_h, ref_r):
        return self._zero.copy(), self._zero.copy()
