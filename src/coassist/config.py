"""Typed, validated parameter sets and the thesis' values (thesis §5.2; docs/architecture.md, *Parameters from the thesis*).

Parameters are frozen dataclasses checked on construction; each error names the
field. Matrices that are diagonal in the thesis are given as their diagonals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from coassist._checks import (
    as_square_matrix,
    check_int_at_least,
    check_positive_definite,
    check_positive_scalar,
    check_positive_semidefinite,
    check_real,
)
from coassist.registry import Registry


def _diag(values, name: str, length: int | None = None, *, positive: bool = False) -> tuple[float, ...]:
    try:
        arr = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError):
        arr = None
    if arr is None or np.asarray(values).dtype.kind == "b":  # truth values are no gains (float(True) is 1)
        raise ValueError(f"{name} must be a list of numbers, got {values!r}")
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a list of diagonal entries, got shape {arr.shape}")
    if length is not None and arr.size != length:
        raise ValueError(f"{name} must have {length} entries, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite entries: {values!r}")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name} entries must be > 0, got {values!r}")
    if not positive and np.any(arr < 0):
        raise ValueError(f"{name} entries must be >= 0, got {values!r}")
    return tuple(float(v) for v in arr)


@dataclass(frozen=True)
class ImpedanceParameters:
    """Diagonal impedance of eq. 3.1: inertia M [kg], damping D [N·s/m], stiffness K [N/m], dt [s]."""

    M: tuple[float, ...] = (10.0, 10.0)
    D: tuple[float, ...] = (100.0, 100.0)
    K: tuple[float, ...] = (0.0, 0.0)
    dt: float = 0.008

    def __post_init__(self) -> None:
        M = _diag(self.M, "impedance.M", positive=True)
        if not 1 <= len(M) <= 6:
            raise ValueError(f"impedance.M must have 1 to 6 entries (one per DOF), got {len(M)}")
        object.__setattr__(self, "M", M)
        object.__setattr__(self, "D", _diag(self.D, "impedance.D", len(M)))
        object.__setattr__(self, "K", _diag(self.K, "impedance.K", len(M)))
        object.__setattr__(self, "dt", check_positive_scalar(self.dt, "impedance.dt"))

    @property
    def n_dof(self) -> int:
        return len(self.M)


_Q_NAMES = ("Q_hh", "Q_hr", "Q_rh", "Q_rr")
_WEIGHT_NAMES = (*_Q_NAMES, "R_h", "R_r")


@dataclass(frozen=True, eq=False)
class GameWeights:
    """Both players' cost weights (eq. 3.15–3.17), validated once, read-only: the one home
    of the six weights, for a game built directly (:class:`coassist.control.CooperativeGame`,
    :class:`~coassist.control.NashGame`) and for a preset's (:attr:`GameParameters.weights`).

    Q_hh, Q_hr : (2n, 2n) the human's weights on tracking its own and the robot's
        reference (position then velocity). PSD.
    Q_rh, Q_rr : (2n, 2n) the robot's weights on the human's and its own reference. PSD.
    R_h, R_r : (n, n) effort weights [1/N²]; SPD. A lower R_r lets the robot assist harder.
    n_dof : n, needed only when every weight is given as a scalar; None: read from the
        first weight given as a vector or matrix (an R's size, or half a Q's).

    Each weight may be given as a matrix, a vector (its diagonal, as the thesis writes
    them) or a scalar (that multiple of the identity); every one is stored as a read-only
    float64 matrix. An error names the weight (``Q_hh must be 4x4 …``, ``R_r must be
    positive definite …``). Two weight sets are equal when their matrices are, entry by
    entry (so a preset's :class:`GameParameters` can key a memo of built games).
    """

    # stored as read-only float64 matrices, whatever array-like they were given as (__post_init__)
    Q_hh: np.ndarray
    Q_hr: np.ndarray
    Q_rh: np.ndarray
    Q_rr: np.ndarray
    R_h: np.ndarray
    R_r: np.ndarray
    n_dof: int | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        n = self.n_dof
        if n is None:
            n = _size_of(self, ("R_h", "R_r"), 1) or _size_of(self, _Q_NAMES, 2)
            if n is None:
                raise ValueError("GameWeights.n_dof is needed when every weight is a scalar")
        elif not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1:
            raise ValueError(f"GameWeights.n_dof must be an int >= 1, got {n!r}")
        n = int(n)
        for name in _Q_NAMES:  # the order the errors are checked in: the Q's, then the R's
            Q = as_square_matrix(getattr(self, name), name, 2 * n)
            check_positive_semidefinite(Q, name)
            object.__setattr__(self, name, Q)
        for name in ("R_h", "R_r"):
            object.__setattr__(self, name, as_square_matrix(getattr(self, name), name, n))
        check_positive_definite(self.R_h, "R_h")
        check_positive_definite(self.R_r, "R_r")
        object.__setattr__(self, "n_dof", n)

    @property
    def Q(self) -> dict[str, np.ndarray]:
        """The four state weights by name (``"Q_hh"``, ``"Q_hr"``, ``"Q_rh"``, ``"Q_rr"``)."""
        return {name: getattr(self, name) for name in _Q_NAMES}

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, GameWeights):
            return NotImplemented
        return self.n_dof == other.n_dof and all(
            np.array_equal(getattr(self, name), getattr(other, name)) for name in _WEIGHT_NAMES
        )

    def __hash__(self) -> int:
        # + 0.0 turns −0.0 into 0.0: equal weights (array_equal) must hash alike
        return hash((self.n_dof, *((getattr(self, name) + 0.0).tobytes() for name in _WEIGHT_NAMES)))


def _size_of(weights: GameWeights, names: tuple[str, ...], per_dof: int) -> int | None:
    """n from the first of ``names`` given as a vector or a matrix (its length / ``per_dof``), None if all are scalars."""
    for name in names:
        shape = np.shape(getattr(weights, name))
        if shape:
            return max(1, shape[0] // per_dof)
    return None


#: Thesis §5.2: Q_hh = Q_rr = diag(1, 1, 1e-4, 1e-4) (x-y positions [m], then velocities
#: [m/s]), Q_hr = Q_rh = 0, R_h = R_r = diag(5e-4, 5e-4) [1/N²].
THESIS_WEIGHTS = GameWeights(
    Q_hh=(1.0, 1.0, 1e-4, 1e-4),
    Q_hr=(0.0, 0.0, 0.0, 0.0),
    Q_rh=(0.0, 0.0, 0.0, 0.0),
    Q_rr=(1.0, 1.0, 1e-4, 1e-4),
    R_h=(5e-4, 5e-4),
    R_r=(5e-4, 5e-4),
)


@dataclass(frozen=True)
class GameParameters:
    """A preset's cooperative game (eq. 3.15–3.17): its weights and how it is played.

    weights : both players' cost weights (:class:`GameWeights`), on 1 to 6 DOFs.
    alpha : the share of the human's cost. horizon, control_horizon : Np, Nc [samples]
    (None: Nc = Np). input_weighting : "shared" (R_h, R_r) or "alpha_scaled" (α R_h, (1 − α) R_r).
    """

    weights: GameWeights = THESIS_WEIGHTS
    alpha: float = 0.8
    horizon: int = 50
    control_horizon: int | None = None
    input_weighting: str = "shared"

    def __post_init__(self) -> None:
        if not isinstance(self.weights, GameWeights):
            raise ValueError(f"game.weights must be a GameWeights, got {type(self.weights).__name__}")
        if not 1 <= self.weights.n_dof <= 6:  # type: ignore[operator]
            raise ValueError(f"game.weights must be on 1 to 6 DOFs, got {self.weights.n_dof}")
        alpha = check_real(self.alpha, "game.alpha", -math.inf)  # a truth value is no α (float(True) is 1)
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"game.alpha must be in [0, 1], got {self.alpha!r}")
        if self.input_weighting == "alpha_scaled" and not 0.0 < alpha < 1.0:
            raise ValueError(f"game.alpha must be in (0, 1) with input_weighting='alpha_scaled', got {self.alpha!r}")
        object.__setattr__(self, "alpha", alpha)
        check_int_at_least(self.horizon, "game.horizon", 1)
        if self.control_horizon is not None:
            check_int_at_least(self.control_horizon, "game.control_horizon", 1)
            if self.control_horizon > self.horizon:
                raise ValueError(
                    f"game.control_horizon must be <= game.horizon ({self.horizon}), got {self.control_horizon}"
                )
        if self.input_weighting not in ("shared", "alpha_scaled"):
            raise ValueError(f"game.input_weighting must be 'shared' or 'alpha_scaled', got {self.input_weighting!r}")

    @property
    def n_dof(self) -> int:
        return int(self.weights.n_dof)


@dataclass(frozen=True)
class ControlPreset:
    """A named pair of impedance and game parameters, plus the robot's effort limit [N]."""

    name: str
    impedance: ImpedanceParameters = field(default_factory=ImpedanceParameters)
    game: GameParameters = field(default_factory=GameParameters)
    effort_limit: float = 100.0

    def __post_init__(self) -> None:
        if self.impedance.n_dof != self.game.n_dof:
            raise ValueError(f"impedance has {self.impedance.n_dof} DOFs but game.weights has {self.game.n_dof}")
        object.__setattr__(self, "effort_limit", check_positive_scalar(self.effort_limit, "effort_limit"))


#: Thesis §5.2: x-y impedance, evaluation of the prediction model (α = 0.8, R_r = 5e-4).
THESIS_EVALUATION = ControlPreset(name="thesis-evaluation")
#: Thesis §5.2.3: application scenario, more assistance (α = 0.9, R_r = 1e-4).
THESIS_APPLICATION = ControlPreset(
    name="thesis-application", game=GameParameters(replace(THESIS_WEIGHTS, R_r=(1e-4, 1e-4)), alpha=0.9)
)


def scale_positions(preset: ControlPreset, scale: float, name: str) -> ControlPreset:
    """The preset with outputs in units of 1/scale m: every Q multiplied by scale².

    The thesis' weights in SI units make the robot's effort tiny (≈0.06 N per cm of
    error, see coassist.experiments.dmpc_study); in decimetres (scale 10) the robot
    assists with a few N per cm, like the thesis' figures.
    """
    w = preset.game.weights
    s2 = float(scale) ** 2
    weights = replace(w, **{q: s2 * Q for q, Q in w.Q.items()})
    return replace(preset, name=name, game=replace(preset.game, weights=weights))


#: Position scale of the "-dm" presets: positions in decimetres.
DECIMETRE_SCALE = 10.0
#: Position scale of the "thesis-application-damped" preset. A learned predictor predicts
#: the tool's future pose, to first order an extrapolation of the robot's own motion, so
#: the robot's gain on it is velocity feedback (coassist.control.game.extrapolation_feedback):
#: at α = 0.9 in decimetres (scale 10) it removes 67.5 of the plant's 100 N·s/m and the
#: coupled loop with the operator's arm (550–1300 N/m, 80 ms reflex delay) rings at every
#: turn; scale 5 leaves 53.6 N·s/m and the tool still overshoots the operator's turns more
#: than under MG; scale 3.5 leaves 68.7 N·s/m. 3.5 is the largest of the scales tried
#: (2.5, 3, 3.5, 4, 5) whose overshoot is below MG's with the paired 95 % interval's upper
#: end ≤ 0 on both objects, on validation seeds the report never uses (docs/assistance.md;
#: tests/control/test_game.py checks the damping figures).
APPLICATION_DAMPED_SCALE = 3.5

#: Control presets by name: the thesis' (SI units), the same in decimetres ("-dm"), and the
#: application weights at APPLICATION_DAMPED_SCALE ("-damped").
CONTROL_PRESETS: Registry[ControlPreset] = Registry(
    "control preset",
    {
        THESIS_EVALUATION.name: THESIS_EVALUATION,
        THESIS_APPLICATION.name: THESIS_APPLICATION,
        "thesis-evaluation-dm": scale_positions(THESIS_EVALUATION, DECIMETRE_SCALE, "thesis-evaluation-dm"),
        "thesis-application-dm": scale_positions(THESIS_APPLICATION, DECIMETRE_SCALE, "thesis-application-dm"),
        "thesis-application-damped": scale_positions(
            THESIS_APPLICATION, APPLICATION_DAMPED_SCALE, "thesis-application-damped"
        ),
    },
    entry_type=ControlPreset,
)

#: The preset of data collection: the main job's datasets D_0 … D_k (``coassist collect``'s
#: default). The predictor in the loop there is the nominal path or M_k being evaluated.
COLLECTION_PRESET = "thesis-evaluation-dm"
#: The preset wherever a learned predictor can be in the loop and the robot is to help:
#: the main job's application stage, ``coassist drive`` and ``coassist play``. Not the
#: "-dm" weights: with a learned prediction in the loop they remove 2/3 of the plant's
#: damping and the arm rings at the operator's turns (see APPLICATION_DAMPED_SCALE).
APPLICATION_PRESET = "thesis-application-damped"
