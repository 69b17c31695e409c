"""Fakes for the control tick and the loop: linear kinematics, scripted worlds, a nominal intent stage.

They stand in for pinocchio/MuJoCo (and the point-mass simulator) so that
:class:`~coassist.runtime.tick.ControlTick` and :func:`~coassist.runtime.loop.run_loop`
can be tested on their own, against references computed in the tests.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from coassist.runtime.world import Command, RobotState

DT = 0.008  # [s] 125 Hz, a UR CB3's period


def well_conditioned_jacobian(singular_values=(2.0, 1.5, 1.2, 1.0, 0.8, 0.6), seed: int = 3) -> np.ndarray:
    """(6, 6) J = U diag(s) Vᵀ with fixed random orthogonal U, V: cond(J) = max(s)/min(s) (3.33 by default)."""
    rng = np.random.default_rng(seed)
    U, _ = np.linalg.qr(rng.standard_normal((6, 6)))
    V, _ = np.linalg.qr(rng.standard_normal((6, 6)))
    return U @ np.diag(singular_values) @ V.T


class LinearKinematics:
    """A constant Jacobian: x(q) = x0 + J q, the orientation R(rv0 + (J q)[3:]) (rotation vectors).

    ``forward_and_jacobian(q) -> (p (3,), R (3, 3), J (6, 6))`` as
    :class:`coassist.robot.kinematics.UR5Kinematics` gives it.
    """

    n_joints = 6

    def __init__(self, J: np.ndarray, pose0: np.ndarray) -> None:
        self.J = np.array(J, dtype=float)
        self.pose0 = np.array(pose0, dtype=float)

    def pose(self, q: np.ndarray) -> np.ndarray:
        return self.pose0 + self.J @ q

    def forward_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = self.pose(q)
        return x[:3].copy(), Rotation.from_rotvec(x[3:]).as_matrix(), self.J


class FakeArmWorld:
    """A joint-velocity world that integrates q ← q + q̇ dt exactly on a :class:`LinearKinematics`.

    wrench(k) gives the raw (6,) reading at tick k (sensor frame = base frame, no bias or
    payload), one new sensor sample per tick. ``fail_read_at`` / ``fail_apply_at``: the
    tick at which ``read`` / ``apply`` raise ``link_error``. Records every state read and
    every command sent, and how often ``stop`` was called.
    """

    command_space = "joint_velocity"
    realtime = False

    def __init__(
        self,
        kin: LinearKinematics,
        wrench: Callable[[int], np.ndarray],
        *,
        link_error: type[Exception] = ConnectionError,
        fail_read_at: int | None = None,
        fail_apply_at: int | None = None,
    ) -> None:
        self.kin, self.wrench = kin, wrench
        self.n_joints = kin.n_joints
        self.dt = DT
        self.q = np.zeros(self.n_joints)
        self.qd = np.zeros(self.n_joints)
        self.k = 0
        self.link_error, self.fail_read_at, self.fail_apply_at = link_error, fail_read_at, fail_apply_at
        self.states: list[RobotState] = []
        self.commands: list[Command] = []
        self.stops = 0

    def read(self) -> RobotState:
        if self.k == self.fail_read_at:
            raise self.link_error("read timed out")
        state = RobotState(
            t=self.k * DT,
            q=self.q.copy(),
            qd=self.qd.copy(),
            tool_pose=self.kin.pose(self.q),
            tool_twist=self.kin.J @ self.qd,
            wrench=np.array(self.wrench(self.k), dtype=float),
            wrench_seq=self.k + 1,
        )
        self.states.append(state)
        return state

    def apply(self, command: Command) -> None:
        if self.k == self.fail_apply_at:
            raise self.link_error("command not sent")
        self.commands.append(command)
        self.qd = np.array(command.qd, dtype=float)
        self.q = self.q + self.qd * DT
        self.k += 1

    def stop(self) -> None:
        self.stops += 1
        self.qd = np.zeros(self.n_joints)

    def close(self) -> None:
        self.stop()


class ScriptedEffortWorld:
    """An effort world whose tool pose follows a script (poses[k] (2,) [m]) whatever it is sent.

    Records the efforts it receives; ``overrun_at``: the tick after whose ``apply`` the
    world reports ``last_overrun`` > 0 (a real-time world's late period).
    """

    command_space = "effort"
    n_joints = 0
    realtime = False

    def __init__(self, poses: np.ndarray, wrench: np.ndarray | None = None, overrun_at: int | None = None) -> None:
        self.poses = np.asarray(poses, dtype=float)
        self.raw = np.zeros(6) if wrench is None else np.asarray(wrench, dtype=float)
        self.dt = DT
        self.k = 0
        self.overrun_at = overrun_at
        self.last_overrun = 0.0
        self.efforts: list[np.ndarray] = []
        self.stops = 0

    def read(self) -> RobotState:
        p = self.poses[min(self.k, len(self.poses) - 1)]
        v = (p - self.poses[self.k - 1]) / DT if 0 < self.k < len(self.poses) else np.zeros(2)
        pose = np.zeros(6)
        pose[:2] = p
        twist = np.zeros(6)
        twist[:2] = v
        return RobotState(
            t=self.k * DT,
            q=np.zeros(0),
            qd=np.zeros(0),
            tool_pose=pose,
            tool_twist=twist,
            wrench=self.raw.copy(),
            wrench_seq=self.k + 1,
        )

    def apply(self, command: Command) -> None:
        self.efforts.append(np.array(command.effort, dtype=float))
        self.last_overrun = 0.004 if self.k == self.overrun_at else 0.0
        self.k += 1

    def stop(self) -> None:
        self.stops += 1

    def close(self) -> None:
        pass


class NominalStage:
    """The intent stage of the nominal plan (eq. 4.7): ref_h = ref_r, never asked to predict."""

    nominal = True

    def __init__(self, horizon: int) -> None:
        self.horizon = horizon

    def reset(self, context: object) -> None:
        pass

    def update(self, k: int, row: tuple[float, ...], nominal: np.ndarray) -> tuple[None, object]:
        raise AssertionError("a nominal intent stage is never asked to predict")
