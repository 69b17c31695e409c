"""Controllers for the loop: the assistive game controller and the thesis' baselines.

Every controller renders the same free plant, the impedance model with the
operator's wrench and the controller's virtual effort::

    M a + D v = u_h + u_r

and differs only in u_r:

- :class:`AssistiveController` — u_r(k) of the cooperative (or Nash) game (eq. 3.27–3.31).
- :class:`ImpedanceControl` (IMP, eq. 5.4) — M a + D v + K (x − x_ref,r) = u_h: the
  spring toward the nominal reference, applied as u_r(k) = K (x_ref,r(k+1) − x(k)): the
  spring pulls toward the reference one tick *ahead* (the first row of ref_r, which like
  the game's references starts at k+1), i.e. eq. 5.4 with Δx(k) = x(k) − x_ref,r(k+1),
  leading the moving plan by dt. The robot adds no assistance beyond the spring.
- :class:`ManualGuidance` (MG, eq. 5.5) — u_r = 0: M a + D v = u_h.

All three take the same ``step(z, ref_h, ref_r, wrench)``: the assistive controller
reads ``horizon`` rows of the references, IMP and MG only the first row (they accept any
number of rows ≥ 1, so the arrays built for the game can be passed to them unchanged).

The control law is pure; the guard around it is what keeps bad input off the robot,
and ``step`` never raises. Every bad tick gives zero robot effort and a fault flag:

- not plainly numeric (booleans, strings, objects, complex numbers, values that do not
  convert, such as ``10**400`` in an object array or a torch tensor that requires grad),
  or the wrong shape → ``Fault.INVALID_INPUT``;
- non-finite state, reference or wrench → ``NONFINITE_STATE`` / ``_REFERENCE`` / ``_WRENCH``;
- finite but physically implausible (beyond :class:`InputBounds`: a 1e200 m state or
  reference, a 100 kN wrench) → ``Fault.INVALID_INPUT``, since saturating the effort
  would still act on garbage.

The effort is then saturated to ``effort_limit`` keeping its direction (``SATURATED``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import as_real_array, as_square_matrix, check_positive_scalar, check_positive_semidefinite
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


@dataclass(frozen=True)
class InputBounds:
    """The largest magnitudes a controller accepts as physically plausible.

    position : |Δx| of the state and the references [m, or rad for orientation DOFs];
        10 m is far beyond any arm's reach (UR5: 0.85 m).
    velocity : |ẋ| of the state and the references [m/s or rad/s]; a cobot's tool
        moves at most a few m/s.
    wrench : |f| of the hand wrench [N or N·m]; force/torque sensors on such arms
        range to a few hundred newtons.

    A finite input beyond these is flagged ``Fault.INVALID_INPUT`` (zero robot effort).
    """

    position: float = 10.0
    velocity: float = 10.0
    wrench: float = 1e4

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "wrench"):
            object.__setattr__(self, name, check_positive_scalar(getattr(self, name), f"InputBounds.{name}"))


def saturate(u: np.ndarray, limit: np.ndarray) -> tuple[np.ndarray, bool]:
    """Scale u (n,) so that |u_i| ≤ limit_i for all i, keeping its direction.

    Scaling the whole vector, instead of clipping each axis, keeps the assistance
    pointing where the law wants it to. Returns (u, whether it was scaled).
    """
    ratio = np.max(np.abs(u) / limit)
    if ratio <= 1.0:
        return u, False
    # u / ratio can land one ulp past the limit (the division rounds up): clip that ulp,
    # which moves the direction by a relative 1e-16 at most
    return np.clip(u / ratio, -limit, limit), True


class _GuardedController:
    """Input checks, saturation and fault reporting around a pure control law."""

    name = "controller"

    #: IMP and MG read one row of the references and accept any number of rows ≥ 1.
    _reads_first_row_only = False

    def __init__(
        self, model: ImpedanceModel, horizon: int, effort_limit: ArrayLike, bounds: InputBounds | None = None
    ) -> None:
        n = model.n_dof
        bounds = InputBounds() if bounds is None else bounds
        if not isinstance(bounds, InputBounds):
            raise ValueError(f"bounds must be an InputBounds, got {type(bounds).__name__}")
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
        self.bounds = bounds
        # |z_i| and |ref_ij| bound per column: positions then velocities.
        self._state_bound = np.concatenate([np.full(n, bounds.position), np.full(n, bounds.velocity)])
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
            log.warning(
                "%s: %s; robot effort set to zero (further occurrences are flagged, not logged)", self.name, repr(new)
            )

    def _ref_ok(self, ref: np.ndarray) -> bool:
        rows, cols = self._ref_shape
        if ref.ndim != 2 or ref.shape[1] != cols:
            return False
        return ref.shape[0] >= 1 if self._reads_first_row_only else ref.shape[0] == rows

    def step(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike, wrench: ArrayLike) -> ControlStep:
        """One guarded tick: z (2n,) [m, m/s], ref_h and ref_r (horizon, 2n) [m, m/s]
        (IMP and MG: any rows ≥ 1), wrench (n,) [N]. Never raises."""
        try:
            arrays = [as_real_array(a) for a in (z, ref_h, ref_r, wrench)]
            if any(a is None for a in arrays):
                return self._refuse(Fault.INVALID_INPUT)
            z, ref_h, ref_r, wrench = arrays
            if not (
                z.shape == self._state_bound.shape
                and wrench.shape == self._wrench_shape
                and self._ref_ok(ref_h)
                and self._ref_ok(ref_r)
            ):
                return self._refuse(Fault.INVALID_INPUT)
            bound = self._state_bound
            # NaN fails every comparison: inputs within their bounds are finite too (one pass per
            # array in the common case); otherwise find out which input is bad, and how.
            if not (
                (np.abs(z) <= bound).all()
                and (np.abs(ref_h) <= bound).all()
                and (np.abs(ref_r) <= bound).all()
                and (np.abs(wrench) <= self.bounds.wrench).all()
            ):
                fault = Fault.NONE
                if not np.isfinite(z).all():
                    fault |= Fault.NONFINITE_STATE
                if not (np.isfinite(ref_h).all() and np.isfinite(ref_r).all()):
                    fault |= Fault.NONFINITE_REFERENCE
                if not np.isfinite(wrench).all():
                    fault |= Fault.NONFINITE_WRENCH
                return self._refuse(fault or Fault.INVALID_INPUT)
            if self._reads_first_row_only:
                ref_h, ref_r = ref_h[:1], ref_r[:1]
            u_h, u_r = self._law(z, ref_h, ref_r)
            if not (np.isfinite(u_r).all() and np.isfinite(u_h).all()):
                return self._refuse(Fault.NONFINITE_EFFORT)
            u_r, clipped = saturate(u_r, self.effort_limit)
            return ControlStep(u_r, u_h, Fault.SATURATED if clipped else Fault.NONE)
        except Exception as exc:  # noqa: BLE001 -- the loop must go on; the robot gets zero effort
            if not self._warned & Fault.INTERNAL_ERROR:
                log.exception("%s: control law failed (%s); robot effort set to zero", self.name, exc)
                self._warned |= Fault.INTERNAL_ERROR
            n = self._zero.shape[0]
            return ControlStep(np.zeros(n), np.zeros(n), Fault.INTERNAL_ERROR)

    def step_batch(
        self,
        z: np.ndarray,
        ref_h: np.ndarray,
        ref_r: np.ndarray,
        wrench: np.ndarray,
        *,
        alone: Sequence[_GuardedController] | None = None,
    ) -> list[ControlStep]:
        """:meth:`step` for B ticks at once (many trials in lockstep sharing this controller):
        z (B, 2n), ref_h and ref_r (B, rows, 2n), wrench (B, n), float64 arrays.

        Row b is ``step(z[b], ref_h[b], ref_r[b], wrench[b])`` bit for bit: the checks and the
        saturation are elementwise (or exact reductions, max and all) over the batch, the law
        is :meth:`_law_batch` (row for row the law's own arithmetic), and a row the batch
        finds bad — out of bounds, non-finite, a non-finite effort — goes through
        :meth:`step` itself, which refuses it with its flag and its one warning. Anything
        else (other shapes or dtypes, a law that raises) falls back to :meth:`step` per row.
        ``alone``: whose :meth:`step` redoes row b there (``alone[b]``: controllers built alike, each
        with its own warnings; default this one for every row). Never raises.
        """
        return self._steps(self._batch_core(z, ref_h, ref_r, wrench), z, ref_h, ref_r, wrench, self._step_of(alone))

    def _step_of(self, alone: Sequence[_GuardedController] | None) -> Callable[[int], Callable[..., ControlStep]]:
        """Whose guarded step redoes row b where a batch cannot (:meth:`step_batch`'s ``alone``)."""
        if alone is None:
            return lambda b: self.step
        return lambda b: alone[b].step

    def _steps(
        self, core, z, ref_h, ref_r, wrench, step_of: Callable[[int], Callable[..., ControlStep]]
    ) -> list[ControlStep]:
        """:meth:`step_batch`'s answer from :meth:`_batch_core`'s: row b's :class:`ControlStep`, where
        the batch found it good and its effort finite (saturated as :func:`saturate` does), else
        ``step_of(b)``'s guarded step of the row (every row where ``core`` is None)."""
        if core is None:
            return [step_of(b)(*row) for b, row in enumerate(zip(z, ref_h, ref_r, wrench))]
        good, u_h, u_r, fine, ratio = core
        limit = self.effort_limit
        out: list[ControlStep | None] = [None] * z.shape[0]
        for j, b in enumerate(good.tolist()):
            if not fine[j]:
                continue
            r = ratio[j]
            if r <= 1.0:
                out[b] = ControlStep(u_r[j], u_h[j], Fault.NONE)
            else:  # as saturate()
                out[b] = ControlStep(np.clip(u_r[j] / r, -limit, limit), u_h[j], Fault.SATURATED)
        return [s if s is not None else step_of(b)(z[b], ref_h[b], ref_r[b], wrench[b]) for b, s in enumerate(out)]

    def effort_batch(
        self,
        z: np.ndarray,
        ref_h: np.ndarray,
        ref_r: np.ndarray,
        wrench: np.ndarray,
        *,
        alone: Sequence[_GuardedController] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The robot efforts of :meth:`step_batch`'s clean rows, as arrays, for a runner that
        only goes on with ticks that carry no flag (:mod:`coassist.sim.array_runner`).

        Returns (u_r (B, n), clean (B,) bool): where ``clean[b]``, ``u_r[b]`` is
        ``step(z[b], ref_h[b], ref_r[b], wrench[b]).u_r`` bit for bit and that step carries
        no fault flag (not even SATURATED); elsewhere ``u_r[b]`` is 0 and the caller must
        not use it (step that row itself, which reports it). On the batched path nothing is
        logged or warned: a row that is not clean has not been stepped. Inputs the batch
        cannot take (other dtypes or shapes) go through :meth:`step` row by row (``alone``'s, as
        :meth:`step_batch`'s), which warns as it always does. Never raises.
        """
        return self._clean_efforts(
            self._batch_core(z, ref_h, ref_r, wrench), z, ref_h, ref_r, wrench, self._step_of(alone)
        )

    def _clean_efforts(
        self, core, z, ref_h, ref_r, wrench, step_of: Callable[[int], Callable[..., ControlStep]]
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`effort_batch`'s answer from :meth:`_batch_core`'s; where that is None, row b
        goes through ``step_of(b)`` (a guarded step) and is clean where it carries no flag
        (a function of b, not a list: the batched path, nearly every tick, builds none)."""
        B, n = z.shape[0], self._zero.shape[0]
        u = np.zeros((B, n))
        clean = np.zeros(B, dtype=bool)
        if core is None:  # odd inputs: step() per row decides (and warns, as it always does)
            for b in range(B):
                s = step_of(b)(z[b], ref_h[b], ref_r[b], wrench[b])
                if s.fault == Fault.NONE:
                    u[b], clean[b] = s.u_r, True
            return u, clean
        good, _, u_r, fine, ratio = core
        ok = fine & (ratio <= 1.0)
        rows = good[ok]
        u[rows] = u_r[ok]
        clean[rows] = True
        return u, clean

    def _batch_core(self, z, ref_h, ref_r, wrench, law=None) -> tuple[np.ndarray, ...] | None:
        """The batched half of :meth:`step_batch`: (good rows (the guard's bounds hold), u_h,
        u_r (of the good rows), fine (finite efforts), ratio (largest |u_r| / limit)), or
        None where the rows must go through :meth:`step` one by one. ``law(good, z, ref_h,
        ref_r)`` replaces :meth:`_law_batch` for the good rows (their indices first)."""
        try:
            fast = self._batch_ok(z, ref_h, ref_r, wrench)
        except Exception:  # noqa: BLE001 -- whatever it is, step() per row handles it
            fast = False
        if not fast:
            return None
        try:
            bound = self._state_bound
            ok = (np.abs(z) <= bound).all(axis=1)
            ok &= (np.abs(ref_h) <= bound).all(axis=(1, 2))
            ok &= (np.abs(ref_r) <= bound).all(axis=(1, 2))
            ok &= (np.abs(wrench) <= self.bounds.wrench).all(axis=1)
            good = np.flatnonzero(ok)
            # every row good (nearly every tick): the rows as they are, not copies of them (the laws only read them)
            zg, rh, rr = (z, ref_h, ref_r) if good.size == ok.size else (z[good], ref_h[good], ref_r[good])
            if self._reads_first_row_only:
                rh, rr = rh[:, :1], rr[:, :1]
            u_h, u_r = self._law_batch(zg, rh, rr) if law is None else law(good, zg, rh, rr)
            fine = np.isfinite(u_r).all(axis=1) & np.isfinite(u_h).all(axis=1)
            if fine.all():  # finite efforts: no inf / inf to silence (entering np.errstate costs a tick microseconds)
                ratio = np.max(np.abs(u_r) / self.effort_limit, axis=1)
            else:
                with np.errstate(invalid="ignore"):  # rows with a non-finite effort are redone by step()
                    ratio = np.max(np.abs(u_r) / self.effort_limit, axis=1)
        except Exception:  # noqa: BLE001 -- step() per row reports the fault as it always does
            return None
        return good, u_h, u_r, fine, ratio

    def _batch_ok(self, z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray) -> bool:
        """Whether :meth:`step_batch` may take its batched path: float64 arrays of the shapes
        :meth:`step` accepts, one row per tick."""
        arrays = (z, ref_h, ref_r, wrench)
        if not all(type(a) is np.ndarray and a.dtype == np.float64 for a in arrays):
            return False
        B = z.shape[0]
        return (
            z.shape == (B, *self._state_bound.shape)
            and wrench.shape == (B, *self._wrench_shape)
            and ref_h.ndim == 3
            and ref_h.shape[0] == B
            and self._ref_ok(ref_h[0])
            and ref_r.ndim == 3
            and ref_r.shape[0] == B
            and self._ref_ok(ref_r[0])
        )

    def _law_batch(self, z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The law for B rows, (u_h (B, n), u_r (B, n)); row b must equal ``_law`` on row b bit
        for bit (here: the law itself, row by row)."""
        n = self._zero.shape[0]
        u_h, u_r = np.empty((z.shape[0], n)), np.empty((z.shape[0], n))
        for b in range(z.shape[0]):
            u_h[b], u_r[b] = self._law(z[b], ref_h[b], ref_r[b])
        return u_h, u_r


class AssistiveController(_GuardedController):
    """The assistive controller: the robot applies its equilibrium effort u_r(k) of a game.

    Parameters
    ----------
    game : a :class:`CooperativeGame` (the thesis) or :class:`NashGame`.
    effort_limit : (n,) or scalar, the largest robot effort per DOF [N]; required, so
        that no robot runs unlimited by omission (pass np.inf to mean it).
    bounds : the plausible input range (default :class:`InputBounds`).
    """

    def __init__(
        self, game: CooperativeGame | NashGame, *, effort_limit: ArrayLike, bounds: InputBounds | None = None
    ) -> None:
        if not isinstance(game, (CooperativeGame, NashGame)):
            raise ValueError(f"game must be a CooperativeGame or NashGame, got {type(game).__name__}")
        self.game = game
        self.name = "cooperative" if isinstance(game, CooperativeGame) else "nash"
        super().__init__(game.model, game.horizon, effort_limit, bounds)

    @property
    def alpha(self) -> float | None:
        """The cooperative game's α now (what a live view and the MCAP's ``/alpha`` show); None for a Nash game."""
        return getattr(self.game, "alpha", None)

    def _law(self, z, ref_h, ref_r):
        return self.game.solve(z, ref_h, ref_r)

    def _law_batch(self, z, ref_h, ref_r):
        return self.game.solve_batch(z, ref_h, ref_r)


class ImpedanceControl(_GuardedController):
    """IMP baseline (eq. 5.4): a spring of stiffness K toward the nominal reference.

    Parameters
    ----------
    model : the free plant (M, D, K = 0).
    K : (n, n) or diagonal, stiffness toward x_ref,r [N/m]; PSD. Stiffer pulls the
        operator back to the nominal path harder.
    effort_limit, bounds : as for :class:`AssistiveController`.

    ``step`` reads only the first row of ``ref_r`` (x_ref,r(k+1), the row the game's
    references start with) and accepts references of any number of rows ≥ 1.
    """

    name = "impedance"
    _reads_first_row_only = True

    def __init__(
        self, model: ImpedanceModel, K: ArrayLike, *, effort_limit: ArrayLike, bounds: InputBounds | None = None
    ) -> None:
        K = as_square_matrix(K, "K", model.n_dof)
        check_positive_semidefinite(K, "K")
        self.K = K
        super().__init__(model, 1, effort_limit, bounds)

    def _law(self, z, ref_h, ref_r):
        n = self.model.n_dof
        return self._zero.copy(), self.K @ (ref_r[0, :n] - z[:n])


class ManualGuidance(_GuardedController):
    """MG baseline (eq. 5.5): no robot effort, the operator moves the free plant alone.

    ``step`` takes the same arguments as the others (references of any rows ≥ 1) and
    applies the same input guard, so a bad input is flagged under MG too.
    """

    name = "manual"
    _reads_first_row_only = True

    def __init__(self, model: ImpedanceModel, *, bounds: InputBounds | None = None) -> None:
        super().__init__(model, 1, np.inf, bounds)

    def _law(self, z, ref_h, ref_r):
        return self._zero.copy(), self._zero.copy()

    def _law_batch(self, z, ref_h, ref_r):
        # the law's zeros for every row at once (a Python call per row cost most of an MG tick's law)
        shape = (z.shape[0], self._zero.shape[0])
        return np.zeros(shape), np.zeros(shape)
