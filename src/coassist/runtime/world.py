"""The interfaces between the control tick and a world (robot + physics) and its operator.

A *world* owns time and physics: the point-mass simulator, the MuJoCo UR5, a real UR5
through ur-rtde. An *operator* owns the hand: a simulated operator, a scripted force
profile, a person in a browser. The tick (:mod:`coassist.runtime.tick`) owns neither;
it reads a :class:`RobotState`, decides, and hands the world a :class:`Command`. This
is dm_control's Physics / Task / Environment split (docs/architecture.md, *One loop, several worlds*).

Frames and units. The *base* frame is the robot's base (x forward, z up). A pose is
``[x, y, z, rx, ry, rz]``: the tool centre point (TCP) position [m] and its orientation
as a rotation vector [rad] (axis · angle), both in the base frame. A twist is
``[vx, vy, vz, ωx, ωy, ωz]`` [m/s, rad/s] in the base frame. The raw wrench is what
the force/torque sensor reports, ``[fx, fy, fz, τx, τy, τz]`` [N, N·m] in the *sensor*
frame, with the sign of the force the tool applies to the sensor: a hand pushing a
weightless tool along +x_sensor with 10 N reads +10 N. Bias, the tool's weight and
noise are in it; :mod:`coassist.runtime.wrench` removes them.

Command spaces. An arm world takes a joint velocity (its controller servos it, like a
UR's ``speedJ``); ``"effort"`` worlds (the 2-D point-mass world) render the impedance
model physically and take the robot's Cartesian effort u_r instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from coassist._checks import as_real_array
from coassist.errors import CoassistError

__all__ = [
    "COMMAND_SPACES",
    "MAX_LINK_TIMEOUT",
    "OPTIONAL_WORLD_MEMBERS",
    "Command",
    "HandOperator",
    "OptionalWorldMembers",
    "RobotLinkError",
    "RobotState",
    "World",
    "finite_vector",
    "optional_member",
]

#: [s] The longest an arm world waits for a new state before it calls the link lost: a stopped robot clock is a lost
#: link, never a wait without end (the tests of a busy machine allow 1 s; ROS 2's stale_after is at most 0.5 s).
MAX_LINK_TIMEOUT = 1.0

COMMAND_SPACES: tuple[str, ...] = ("joint_velocity", "effort")


class RobotLinkError(CoassistError, ConnectionError):
    """The link to a robot failed: its driver stopped answering, its state went stale, or its
    controller stopped taking commands. Any world's :meth:`World.read` and :meth:`World.apply`
    raise it (or a subclass); the loop ends the run with ``"link_lost"`` and stops the arm.

    A ``ConnectionError``, so a loop can catch it without importing any world.
    """


@dataclass(slots=True)
class RobotState:
    """One timestamped reading of the robot and its sensor.

    t : [s] the world's clock at the reading (simulated time, or the robot's own
        timestamp); strictly increasing from tick to tick.
    q, qd : (n_joints,) joint positions [rad] and velocities [rad/s]; (0,) for a world
        without joints.
    tool_pose : (6,) TCP pose in the base frame (module docstring); for the point-mass
        world the first ``d`` entries are its position and the rest are zero.
    tool_twist : (6,) TCP twist in the base frame.
    wrench : (6,) raw sensor reading in the sensor frame [N, N·m].
    sensor_rotation : (3, 3) orientation of the sensor frame in the base frame
        (columns: the sensor's axes); the wrench pipeline rotates with it.
    wrench_seq : counts the sensor's samples; unchanged from the last tick means the
        sensor sent nothing new (a 100 Hz sensor read at 125 Hz repeats one in five).
    protective_stop, emergency_stop : the robot controller's own stop states.
    """

    t: float
    q: np.ndarray
    qd: np.ndarray
    tool_pose: np.ndarray
    tool_twist: np.ndarray
    wrench: np.ndarray
    sensor_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    wrench_seq: int = 0
    protective_stop: bool = False
    emergency_stop: bool = False


def finite_vector(x: object, n: int) -> np.ndarray | None:
    """A state field as a finite float64 (n,) array, or None (a glitch: None, not numeric,
    another shape, NaN or ±inf anywhere); the loop and the tick hold the last good value then."""
    if type(x) is np.ndarray and x.dtype.char == "d" and x.shape == (n,):  # the per-tick case: no allocation
        s = sum(x.tolist())
        if s - s == 0.0:  # NaN and ±inf survive the sum (inf − inf = NaN); an overflow is re-checked below
            return x
    a = as_real_array(x)
    if a is None or a.shape != (n,) or not np.isfinite(a).all():
        return None
    return a


@dataclass(slots=True)
class Command:
    """What the tick sends the world for one control period.

    qd : (n_joints,) joint velocity [rad/s] (``joint_velocity`` worlds).
    effort : (d,) the robot's Cartesian effort u_r [N] (``effort`` worlds).
    twist : (6,) the Cartesian twist the joint velocity realises [m/s, rad/s] (for logs
        and worlds that prefer ``speedL``).
    stop : the safety layer has stopped the robot: brake to rest and hold.
    """

    qd: np.ndarray | None = None
    effort: np.ndarray | None = None
    twist: np.ndarray | None = None
    stop: bool = False


@runtime_checkable
class World(Protocol):
    """A robot and the physics around it, stepped one control period at a time.

    Attributes
    ----------
    dt : the control period [s] (0.008 at 125 Hz, 0.002 at 500 Hz).
    command_space : ``"joint_velocity"`` or ``"effort"``.
    n_joints : joints commanded (0 for the point-mass world).
    realtime : True when ``apply`` waits for the wall clock (a real robot, a world
        paced for a viewer): the loop then measures deadline misses.
    """

    dt: float
    command_space: str
    n_joints: int
    realtime: bool

    def read(self) -> RobotState:
        """The state at the start of the current period (cheap; no waiting); :class:`RobotLinkError` when the link is lost."""
        ...

    def apply(self, command: Command) -> None:
        """Send ``command`` and advance to the next period (simulate it, or wait for it); :class:`RobotLinkError` when the link is lost."""
        ...

    def stop(self) -> None:
        """Bring the robot to rest now (decelerate within its limits); safe to call twice."""
        ...

    def close(self) -> None:
        """Release the robot or the physics; calls :meth:`stop` first where it moves."""
        ...


class OptionalWorldMembers(Protocol):
    """What the runtime reads of a world when the world has it, besides :class:`World`'s members.

    None is required: a world without one gets the default of :data:`OPTIONAL_WORLD_MEMBERS`,
    and the runtime reads each through :func:`optional_member` (``hand_wrench`` is looked up on
    the world's class, being a property a world computes on demand).

    Attributes
    ----------
    last_overrun : [s] how far the last period ran over ``dt`` (0.0 on time), for a world that
        measures its own period (a real arm's clock, a world paced for a viewer); > 0 after a
        read or an apply makes the loop flag ``Fault.DEADLINE_MISS``. Absent (None): the loop
        does not ask.
    stop_detail : what stopped the robot and what to do (None while it runs); replaces the
        log's message when the run ended with ``"robot_stop"`` or ``"safety_stop"``.
    hand_wrench : (6,) the hand's wrench at the handle in the last period [N, N·m], base frame,
        for a world that simulates the hand; the log's effort_h (its first ``d`` entries).
    base_frame : the name of the frame the world's poses are in (``coassist ros2 --base-frame``), for the
        live view and the MCAP file; absent (None): ``"base"``.
    """

    last_overrun: float | None
    stop_detail: str | None
    base_frame: str | None

    @property
    def hand_wrench(self) -> np.ndarray:
        """(6,) the hand's wrench in the last period [N, N·m], base frame (class docstring)."""
        ...

    def hand_force(self) -> tuple[float, float]:
        """(d,) the hand force u_h the world applied in the last period [N] (a simulated hand; the
        point-mass world's (2,)); preferred to ``hand_wrench`` where a world has both."""
        ...

    def follow_episode(self, episode: Any) -> None:
        """Told the run's :class:`~coassist.runtime.episode.Episode` before it starts, by a world that
        publishes what the run does (ROS 2's monitor: its controller's α, its plan's rows)."""
        ...


#: Every member of :class:`OptionalWorldMembers` → what the runtime reads when a world lacks it.
OPTIONAL_WORLD_MEMBERS: dict[str, None] = {
    "last_overrun": None,
    "stop_detail": None,
    "hand_force": None,
    "hand_wrench": None,
    "base_frame": None,
    "follow_episode": None,
}


def optional_member(world: object, name: str) -> Any:
    """``world``'s member ``name`` of :class:`OptionalWorldMembers`, or its default (None) when the
    world lacks it. ``world`` may be a world's class (a property is then found without being
    computed). Raises ``ValueError`` for a name the protocol does not declare: a new probe of a
    world is declared there first (tests/runtime/test_world_members.py checks both)."""
    if name not in OPTIONAL_WORLD_MEMBERS:
        raise ValueError(
            f"optional_member: name must be one of {sorted(OPTIONAL_WORLD_MEMBERS)} (declare it in "
            f"OptionalWorldMembers), got {name!r}"
        )
    return getattr(world, name, OPTIONAL_WORLD_MEMBERS[name])


@runtime_checkable
class HandOperator(Protocol):
    """Whoever applies the hand force on the handle.

    A world calls :meth:`force` during its physics (once per control period, or once
    per physics sub-step where it integrates finer) with the handle's state, and
    applies the returned wrench at the handle.
    """

    def force(self, t: float, hand_pose: np.ndarray, hand_twist: np.ndarray) -> np.ndarray:
        """(6,) wrench the hand applies at the handle [N, N·m], base frame, at time t [s].

        ``hand_pose`` and ``hand_twist`` are the handle's pose and twist (module
        docstring for the layout). Must return a finite (6,) array; a world treats
        anything else as zero force (the hand lets go).
        """
        ...
