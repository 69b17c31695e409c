"""The free point-mass plant, axis by axis: the one discrete step every point-mass world takes.

The robot rendered as an ideal admittance with K = 0 and diagonal M and D (the
point-mass simulator, :class:`coassist.sim.point_mass.PointMassWorld`; the play world,
:class:`coassist.play.world.PlayWorld`), with an added mass m on every axis (a carried
object; 0 for none)::

    (M_ii + m) a_i + D_ii v_i = f_i                                     (eq. 3.1, K = 0)

decouples into one mass-damper per axis, whose exact zero-order hold over dt (eq. 3.5;
the physical plant is always held exactly, whatever discretisation the controller's own
model uses) is::

    x_i(k+1) = x_i(k) + a_xv,i v_i(k) + b_x,i f_i(k)
    v_i(k+1) =          a_vv,i v_i(k) + b_v,i f_i(k)

a_xv,i = A_d[i, n+i], a_vv,i = A_d[n+i, n+i], b_x,i = B_d[i, i], b_v,i = B_d[n+i, i] of
the zero-order-hold :class:`~coassist.model.impedance.ImpedanceModel` (M + m I, D, 0, dt) (the other
entries are those of the identity and zeros). :func:`plant_step` is that step, written
once for Python floats and numpy arrays alike (elementwise + and ×, the same IEEE
operations in the same order), so the per-trial worlds (floats) and the point-mass
array path (:mod:`coassist.sim.array_runner`, arrays of many trials) integrate the same
plant bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from coassist._checks import is_real_number
from coassist.model.impedance import ImpedanceModel

__all__ = ["PointMassPlant", "plant_step"]

T = TypeVar("T", float, np.ndarray)


def plant_step(x: T, v: T, f: T, a_xv: T, a_vv: T, b_x: T, b_v: T) -> tuple[T, T]:
    """One period of the free mass-damper (module docstring): (x(k+1), v(k+1)).

    Elementwise: floats for one axis, or arrays of any one shape (e.g. (B, 2): B trials'
    x-y axes, each with its coefficients). x [m], v [m/s], f [N], the coefficients of
    :class:`PointMassPlant` [s, 1, s²/kg, s/kg].
    """
    return x + a_xv * v + b_x * f, a_vv * v + b_v * f


@dataclass(frozen=True)
class PointMassPlant:
    """The coefficients of :func:`plant_step`, per axis (module docstring).

    a_xv, a_vv, b_x, b_v : (n,) per axis: position from velocity [s], velocity from
        velocity [1], position from force [s²/kg], velocity from force [s/kg].
    """

    a_xv: tuple[float, ...]
    a_vv: tuple[float, ...]
    b_x: tuple[float, ...]
    b_v: tuple[float, ...]

    @classmethod
    def free(cls, model: ImpedanceModel, added_mass: float = 0.0) -> PointMassPlant:
        """The free plant (K = 0) of ``model``'s M and D with ``added_mass`` [kg] ≥ 0 on every axis.

        M and D must be diagonal (ValueError naming the entry otherwise): off-diagonal
        terms would couple the axes, which this plant does not model. The model's own
        stiffness K is not rendered (the plant is free, as the thesis' robot), and the
        step is the exact zero-order hold whatever ``model.discretization`` says.
        """
        if not isinstance(model, ImpedanceModel):
            raise ValueError(f"model must be an ImpedanceModel, got {type(model).__name__}")
        if not is_real_number(added_mass) or not np.isfinite(added_mass) or added_mass < 0.0:
            raise ValueError(f"added_mass must be a finite mass >= 0 [kg], got {added_mass!r}")
        M, D = np.asarray(model.M, dtype=float), np.asarray(model.D, dtype=float)
        for name, matrix in (("M", M), ("D", D)):
            off = matrix - np.diag(np.diag(matrix))
            if np.any(off != 0.0):
                raise ValueError(f"the point-mass plant needs a diagonal {name}, got {matrix.tolist()}")
        n = model.n_dof
        free = ImpedanceModel(np.diag(np.diag(M) + added_mass), model.D, np.zeros((n, n)), model.dt)
        Ad, Bd = free.Ad, free.Bd
        return cls(
            a_xv=tuple(float(Ad[i, n + i]) for i in range(n)),
            a_vv=tuple(float(Ad[n + i, n + i]) for i in range(n)),
            b_x=tuple(float(Bd[i, i]) for i in range(n)),
            b_v=tuple(float(Bd[n + i, i]) for i in range(n)),
        )

    @property
    def n_dof(self) -> int:
        """Number of axes n."""
        return len(self.a_xv)
