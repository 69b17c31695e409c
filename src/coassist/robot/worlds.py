"""The worlds, one entry each (the one table of them), and what an arm world offers the drive.

:data:`WORLDS` holds every world by name: the two point-mass worlds and the arm worlds. Every
choice of a world reads it: ``coassist drive`` (``--world``), ``coassist ros2``, ``coassist play
--drive`` and :class:`~coassist.robot.drive.DriveConfig` accept its arm worlds
(:func:`arm_worlds`: an entry with a builder); a study plan's ``[study] world`` the entries with
``studies`` (:func:`study_worlds`). An arm world's entry names the function that builds it (an
entry point, imported only then: a world whose extra is not installed is still listed), the
arms it drives, and what it needs::

    world       builds                         arms          needs
    point-mass  (coassist.sim's loop)          —             nothing: the simulated operator on the point mass
    play        (coassist.play's page)         —             the web extra: a person's mouse, touch screen or gamepad
    mujoco      MujocoUR5World/MujocoArmWorld  ur5, panda    the robot extra (MuJoCo physics, the simulated operator)
    ur          URRTDEWorld (URSimWorld)       ur5           --host (the robot's IP address, or coassist ur-sim's), the robot extra (ur-rtde)
    franka      FrankaWorld                    panda, fr3    --host (the FCI address), the franka extra (franky)
    ros2        Ros2World                      ur5           the ros2 extra (rclpy): ros2_control's topics

The point mass's names, mapped here once: the world is ``point-mass`` (the main job's
ablation cells and ``reproduce.mujoco_person_calibration`` say so too); ``play`` is the same
point mass with the browser as the hand (a study plan's default world); the trials of both
record ``TrialMeta.origin`` ``"sim"`` (the entries' ``origin``, as the ``ur`` world's trials
record ``"ur5"``). The point-mass worlds have no builder here: :mod:`coassist.sim` and
:mod:`coassist.play` run them (the layers keep the arm worlds and the simulator apart).

Every arm world is a :class:`~coassist.runtime.world.World` (read / apply / stop / close, its
period, its joints); :class:`ArmWorld` is what the drive needs of an arm beyond that (its
kinematics, the payload the wrench pipeline removes, whether its sensor is noise free), and
:class:`HandWorld` what a world with a simulated handle offers (the drive puts the simulated
operator's hand on it). The drive asks ``isinstance(world, ArmWorld)`` once and then calls
those members; it does not probe a world's attributes.

docs/architecture.md, *Add a world*, is the recipe: one module with the world class and its
``build_world(request: WorldRequest)``, one line here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from coassist.interfaces import missing_members
from coassist.registry import Registry, is_entry_point, load_entry_point
from coassist.runtime.world import HandOperator, World

__all__ = [
    "PLAY",
    "POINT_MASS",
    "WORLDS",
    "ArmWorld",
    "HandWorld",
    "WorldEntry",
    "WorldRequest",
    "arm_worlds",
    "build_world",
    "missing_members",
    "study_worlds",
]


@runtime_checkable
class ArmWorld(World, Protocol):
    """What the drive needs of an arm world besides :class:`~coassist.runtime.world.World`'s members.

    noise_free_sensor : True when the F/T reading repeats exactly while the push is constant
        (a noise-free simulated sensor): the wrench pipeline's frozen-sensor check would trip
        on it, so the drive switches that check off.
    """

    noise_free_sensor: bool

    def kinematics(self) -> Any:
        """The arm's kinematics with this world's TCP, for the tick's eq. 3.6: an
        :class:`~coassist.robot.kinematics.ArmKinematics`, or a
        :class:`~coassist.robot.arms.NullSpacePosture` on a redundant arm."""
        ...

    def tool_mass_and_com(self) -> tuple[float, np.ndarray]:
        """The payload below the sensor that the wrench pipeline removes: mass [kg] and centre
        of mass (3,) in the sensor frame [m]; (0.0, zeros) where the robot's controller
        removes it itself."""
        ...


@runtime_checkable
class HandWorld(Protocol):
    """A world with a simulated handle: the drive puts the (simulated) operator's hand on it.

    operator : the hand the world asks for a wrench during its physics (None: nobody holds it).
    """

    operator: HandOperator | None

    def hand_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The handle's pose (6,) and twist (6,) in the base frame."""
        ...


@dataclass(frozen=True)
class WorldRequest:
    """What a world's builder gets: the run's arm, tool, rate and seed, where the TCP starts, the host.

    robot : the arm (one of the entry's ``arms``).  object : the carried object.
    rate_hz : the control rate [Hz].  seed : the run's seed (a simulated sensor's noise).
    start : (3,) where a simulated TCP starts [m] (a real arm starts where it is).
    host : the robot's address, or None.  view : open a viewer (MuJoCo).
    realtime : pace a simulated world to the wall clock (a viewer, a real-time predictor).
    joint_acceleration : [rad/s²] the safety layer's bound on how fast the joint velocity command changes
        (``SafetyLimits.joint_acceleration``): an arm that ramps to each command by its own acceleration (a UR's
        ``speedJ``) ramps at least this fast, so it follows the command the layer let through instead of lagging.
    """

    robot: str
    object: str
    rate_hz: int
    seed: int
    start: tuple[float, float, float]
    host: str | None = None
    view: bool = False
    realtime: bool = False
    joint_acceleration: float = 8.0


@dataclass(frozen=True)
class WorldEntry:
    """One world.

    build : an arm world's entry point ``"package.module:function"`` of ``function(request:
        WorldRequest) -> ArmWorld``; None for a point-mass world (coassist.sim or coassist.play
        runs it, not the drive).
    arms : the arms it drives (:data:`coassist.robot.arms.ARMS`), the first its default; ()
        without a builder.
    summary : what it is, a phrase (the command line's help).
    simulated : the simulated operator holds the handle (and the oracle may be used); a
        run is deterministic for a seed. Otherwise a person does: on a real arm, or at the page.
    host : what ``--host`` is for this world ("the robot's IP address"), None when it takes none.
    extras : the optional dependency groups it needs (``pip install 'coassist[<extra>]'``).
    origin : the trials' ``TrialMeta.origin`` (where the data came from).
    studies : a study plan may name it (``[study] world``): the study builds it from the run's
        request alone. ros2: False, its node and topics are ``coassist ros2``'s options, which a
        plan does not carry; point-mass: False, a study's page world is ``play``.
    """

    build: str | None
    arms: tuple[str, ...]
    summary: str
    simulated: bool
    host: str | None
    extras: tuple[str, ...]
    origin: str
    studies: bool = True

    def __post_init__(self) -> None:
        from coassist.data.trial import ORIGINS

        for flag in ("simulated", "studies"):  # "False" is truthy: a real arm would be taken for a simulator
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"WorldEntry.{flag} must be True or False, got {getattr(self, flag)!r}")
        if self.origin not in ORIGINS:  # a trial records it: another value lost the run at its end
            raise ValueError(f"WorldEntry.origin must be one of {ORIGINS} (TrialMeta.origin), got {self.origin!r}")
        if self.build is None:
            if self.arms or self.host is not None:
                raise ValueError(
                    f"WorldEntry without a builder (a point-mass world) takes no arms or host, got {self.arms!r}, "
                    f"{self.host!r}"
                )
            return
        if not is_entry_point(self.build):
            raise ValueError(f"WorldEntry.build must be 'package.module:function' or None, got {self.build!r}")
        if not self.arms or not all(isinstance(a, str) and a for a in self.arms):
            raise ValueError(f"WorldEntry.arms must be one or more arm names, got {self.arms!r}")

    @property
    def is_arm(self) -> bool:
        """Whether the drive builds it (:func:`build_world`): an arm world."""
        return self.build is not None


#: The point mass run by coassist.sim (the simulated operator; the main job's data and ablation).
POINT_MASS = "point-mass"
#: The point mass of coassist play's page (the browser as the hand; a study plan's default world).
PLAY = "play"

#: The worlds (module docstring), in the order the help lists them.
WORLDS: Registry[WorldEntry] = Registry(
    "world",
    {
        POINT_MASS: WorldEntry(
            None,
            (),
            "the point mass with the simulated operator (coassist collect, the main job)",
            simulated=True,
            host=None,
            extras=(),
            origin="sim",
            studies=False,
        ),
        PLAY: WorldEntry(
            None,
            (),
            "the point mass of coassist play's page, the browser as the hand",
            simulated=False,
            host=None,
            extras=("web",),
            origin="sim",
        ),
        "mujoco": WorldEntry(
            "coassist.robot.mujoco_world:build_world",
            ("ur5", "panda"),
            "an arm in MuJoCo physics",
            simulated=True,
            host=None,
            extras=("robot",),
            origin="mujoco",
        ),
        "ur": WorldEntry(
            "coassist.robot.ur_sim_world:build_world",
            ("ur5",),
            "a real UR5 through ur-rtde (or coassist ur-sim)",
            simulated=False,
            host="the robot's IP address",
            extras=("robot",),
            origin="ur5",
        ),
        "franka": WorldEntry(
            "coassist.robot.franka_world:build_world",
            ("panda", "fr3"),
            "a Franka Panda/FR3 through franky",
            simulated=False,
            host="the robot's FCI address",
            extras=("franka",),
            origin="franka",
        ),
        "ros2": WorldEntry(
            "coassist.robot.ros2_world:build_world",
            ("ur5",),
            "a UR5 through ros2_control's topics, set by coassist ros2",
            simulated=False,
            host=None,
            extras=("ros2", "robot"),
            origin="ur5",
            studies=False,
        ),
    },
    entry_type=WorldEntry,
)


def arm_worlds() -> dict[str, WorldEntry]:
    """The arm worlds of :data:`WORLDS` (an entry with a builder), read when called (a world
    registered since is in it), in the table's order: what the drive, ``--world`` and
    ``play --drive`` accept."""
    return {name: entry for name, entry in WORLDS.items() if entry.is_arm}


def study_worlds() -> tuple[str, ...]:
    """The worlds a study plan may name (``[study] world``), read when called: every entry of
    :data:`WORLDS` with ``studies`` (play, mujoco, ur, franka, and any world registered since)."""
    return tuple(name for name, entry in WORLDS.items() if entry.studies)


def build_world(name: str, request: WorldRequest) -> ArmWorld:
    """The arm world ``name`` of :data:`WORLDS` for ``request``; ValueError naming what is missing
    (an arm it does not drive, a host it needs) or the arm worlds, for a point-mass world."""
    entry = WORLDS[name]
    if entry.build is None:
        raise ValueError(f"the {name} world is not an arm world: the drive builds {', '.join(arm_worlds())}")
    if request.robot not in entry.arms:
        raise ValueError(f"the {name} world drives {', '.join(entry.arms)}, not {request.robot!r}")
    if entry.host is not None and not request.host:
        raise ValueError(f"the {name} world needs --host ({entry.host})")
    return load_entry_point(entry.build)(request)


def world_choices() -> str:
    """What ``--world`` may be (the arm worlds), for the help: ``"mujoco (an arm in MuJoCo physics) | ur (…) | …"``."""
    return " | ".join(f"{name} ({entry.summary})" for name, entry in arm_worlds().items())


def arm_choices() -> str:
    """The arms of each world, for ``--robot``'s help: ``"ur5 or panda (--world mujoco), ur5 (ur), …"``."""
    parts = [f"{' or '.join(entry.arms)} ({name})" for name, entry in arm_worlds().items()]
    return ", ".join(parts)
