"""The simulated operator as the hand of an arm world (the MuJoCo UR5): the 2-D arm lifted to 3-D.

x-y as in the thesis: :class:`~coassist.scenario.operator.OperatorArm` (eq. 4.1 with delay,
adaptation, noise and force limit) pulls the handle toward the operator's intent. The
other DOFs:

- ``full_pose=False`` (default, the thesis' x-y tasks): the hand applies nothing along
  z or in rotation; the robot holds those DOFs at the start pose itself (the tick's
  stiff hold impedance).
- ``full_pose=True`` (6-DOF control): the hand also holds z and the orientation at the
  start pose with its own spring-damper, the orientation error as a rotation vector::

      f_z = k_z (z0 − z) − c_z ż,      τ = k_r log(R0 Rᵀ) − c_r ω

The world calls :meth:`SimulatedHand.force` once per control period, in order.
:meth:`SimulatedHand.to_dict` / :meth:`SimulatedHand.from_dict` carry a hand not yet used to
another process as JSON (``coassist ur-sim`` holds it on its simulated handle).
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

import numpy as np

from coassist.scenario.operator import OperatorArm, OperatorProfile
from coassist.spatial import orientation_error, rotation_matrix

__all__ = ["SimulatedHand"]


class SimulatedHand:
    """A :class:`~coassist.runtime.world.HandOperator` driven by an :class:`OperatorArm`.

    Parameters
    ----------
    arm : the operator's arm for this trial (intent grid on the control period).
    dt : the control period [s] (the arm's tick).
    start_pose : (6,) the handle's start pose (held in z and orientation when full_pose).
    full_pose : see the module docstring.
    offset : (2,) the hand point minus the tool's TCP in x-y at the start [m]: the arm's
        intent is the TCP's (as in the point-mass world, where the hand point moves with
        the board's yaw), so the constant grasp offset is taken out.
    z_stiffness, z_damping : [N/m], [N·s/m] of the hand's hold along z.
    rotation_stiffness, rotation_damping : [N·m/rad], [N·m·s/rad] of the wrist's hold.
    """

    def __init__(
        self,
        arm: OperatorArm,
        dt: float,
        start_pose: np.ndarray,
        *,
        full_pose: bool = False,
        offset=(0.0, 0.0),
        z_stiffness: float = 300.0,
        z_damping: float = 30.0,
        rotation_stiffness: float = 3.0,
        rotation_damping: float = 0.3,
    ) -> None:
        self.arm = arm
        self.dt = float(dt)
        self.start = np.asarray(start_pose, dtype=float).copy()
        self.R0 = rotation_matrix(self.start[3:6])
        self.full_pose = bool(full_pose)
        self.kz, self.cz = float(z_stiffness), float(z_damping)
        self.kr, self.cr = float(rotation_stiffness), float(rotation_damping)
        self.ox, self.oy = float(offset[0]), float(offset[1])
        self.k = 0
        self.last = np.zeros(6)

    def to_dict(self) -> dict[str, Any]:
        """Everything that builds this hand, JSON-ready (plain lists and numbers); a hand already used refuses."""
        if self.k:
            raise ValueError(f"SimulatedHand.to_dict: the hand has already run {self.k} ticks")
        arm = self.arm
        return {
            "profile": asdict(arm.profile),
            "intent": np.asarray(arm.intent, dtype=float).tolist(),
            "noise": np.asarray(arm.noise, dtype=float).tolist(),
            "dt": self.dt,
            "start_pose": self.start.tolist(),
            "full_pose": self.full_pose,
            "offset": [self.ox, self.oy],
            "z_stiffness": self.kz,
            "z_damping": self.cz,
            "rotation_stiffness": self.kr,
            "rotation_damping": self.cr,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SimulatedHand:
        """The hand of :meth:`to_dict`: the same forces for the same states, bit for bit.

        Raises ValueError naming the field that is missing or malformed.
        """
        try:
            profile = OperatorProfile(**data["profile"])
            intent = np.asarray(data["intent"], dtype=float)
            noise = np.asarray(data["noise"], dtype=float)
            dt = float(data["dt"])
            start = np.asarray(data["start_pose"], dtype=float)
        except KeyError as exc:
            raise ValueError(f"SimulatedHand.from_dict: no {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            raise ValueError(f"SimulatedHand.from_dict: {exc}") from None
        if intent.ndim != 2 or intent.shape[1] != 2 or noise.shape != intent.shape or start.shape != (6,):
            raise ValueError(
                f"SimulatedHand.from_dict: intent and noise must be (n, 2) alike and start_pose 6 numbers, got "
                f"{intent.shape}, {noise.shape}, {start.shape}"
            )
        return cls(
            OperatorArm(profile, intent, dt, noise),
            dt,
            start,
            full_pose=bool(data.get("full_pose", False)),
            offset=tuple(data.get("offset", (0.0, 0.0))),
            z_stiffness=float(data.get("z_stiffness", 300.0)),
            z_damping=float(data.get("z_damping", 30.0)),
            rotation_stiffness=float(data.get("rotation_stiffness", 3.0)),
            rotation_damping=float(data.get("rotation_damping", 0.3)),
        )

    def force(self, t: float, hand_pose: np.ndarray, hand_twist: np.ndarray) -> np.ndarray:
        k = self.k
        self.k += 1
        w = np.zeros(6)
        # a NaN or ±inf survives the sum (inf − inf is NaN); where the sum does not, numpy's own check decides (a sum
        # of large finite entries may overflow): the same answer, without two numpy calls on every tick
        total = sum(np.ravel(hand_pose).tolist()) + sum(np.ravel(hand_twist).tolist())
        if total - total != 0.0 and not (np.isfinite(hand_pose).all() and np.isfinite(hand_twist).all()):
            self.last = w
            return w
        w[0], w[1] = self.arm.force(
            k, float(hand_pose[0]) - self.ox, float(hand_pose[1]) - self.oy, float(hand_twist[0]), float(hand_twist[1])
        )
        if self.full_pose:
            w[2] = self.kz * (self.start[2] - hand_pose[2]) - self.cz * hand_twist[2]
            w[3:6] = self.kr * orientation_error(self.R0, rotation_matrix(hand_pose[3:6])) - self.cr * hand_twist[3:6]
        self.last = w
        return w
