"""Drive an arm (a UR5, a Franka Panda) with the assistive controller (or IMP / MG): MuJoCo physics or a real arm.

This is the environment of the runtime for arm worlds: it builds what is the arm's own
(the world, the simulated hand, the kinematics, the wrench pipeline for the tool's payload,
the safety limits and workspace) and hands the rest to the episode assembly every world
shares (:mod:`coassist.runtime.episode`: the task of the seed, the plan, the tick, the
termination, :func:`~coassist.runtime.loop.run_loop` and the :class:`~coassist.data.Trial`,
in the same format as the point-mass world plus the joint columns), so ``coassist train``,
``evaluate`` and ``show`` read it unchanged.

Worlds (:data:`coassist.robot.worlds.WORLDS`, one entry each; a world is an
:class:`~coassist.robot.worlds.ArmWorld`):

- a simulated one (``"mujoco"``: :class:`~coassist.robot.mujoco_world.MujocoUR5World`, or for
  ``robot="panda"`` :class:`~coassist.robot.mujoco_world.MujocoArmWorld`, the tasks moved into
  the arm's reach by :func:`move_tasks`) with the simulated operator lifted to 3-D
  (:class:`~coassist.scenario.hand.SimulatedHand`) or any
  :class:`~coassist.runtime.world.HandOperator` on its handle
  (:class:`~coassist.robot.worlds.HandWorld`); deterministic for a seed.
- a real arm (``"ur"``: :class:`~coassist.robot.ur_rtde_world.URRTDEWorld`; ``"franka"``,
  ``"ros2"``); the person at the handle is the operator. The task is laid out from wherever
  the TCP is when the run starts (coassist never moves a real arm to a start pose on its own).
  The ``"ur"`` world on ``coassist ur-sim`` (:class:`~coassist.robot.ur_sim_world.URSimWorld`)
  has a simulated handle: the simulated operator holds it, as in MuJoCo.

Controllers by kind (:data:`coassist.control.presets.CONTROLLERS`): ``cooperative`` (the
assistive controller, the cooperative game), ``cooperative-arbitrated``, ``cooperative-damped``,
``impedance`` (IMP, eq. 5.4), ``manual`` (MG, eq. 5.5) and ``manual-probe`` (MG plus the probe: the
calibration trials ``coassist calibrate`` fits).

What the robot is told: the nominal plan always; the task's obstacle in a simulated world; on any
world, the boxes of a lab's scene file instead (``DriveConfig.scene``,
:mod:`coassist.scenario.scene`), recorded in the trial (``meta.extra["scene"]``). Before the run,
``say`` is told in one line what the person will get (:func:`coassist.scenario.assistance.assistance_line`).
"""

from __future__ import annotations

import logging
import math
import re
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from coassist._checks import is_integer, is_real_number
from coassist.config import APPLICATION_PRESET, GameWeights, ImpedanceParameters
from coassist.control.presets import CONTROLLERS, get_preset, make_controller
from coassist.control.stability import StabilityGuard, StabilityGuardParameters
from coassist.data import Trial
from coassist.errors import CoassistError
from coassist.interfaces import FEATURES
from coassist.robot.worlds import WORLDS, ArmWorld, HandWorld, WorldRequest, arm_worlds, build_world, missing_members
from coassist.runtime.episode import EpisodeLabels, build_episode, episode_ticks, plan_grid
from coassist.runtime.intent import RealtimeIntent, WindowIntent
from coassist.runtime.loop import InterruptsHeld, RunInterrupted
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.safety_limits import SafetyLimits
from coassist.runtime.tick import TickConfig
from coassist.runtime.world import optional_member
from coassist.runtime.wrench import MEASURED_FROZEN_TIME, WrenchConfig, WrenchPipeline
from coassist.scenario.assistance import DEFAULT_INTENT, assistance_line, check_person, check_person_world
from coassist.scenario.hand import SimulatedHand
from coassist.scenario.intent_registry import INTENT_SOURCES, load_intent_source, needs_network, shared_intent_source
from coassist.scenario.objects import OBJECTS, get_object
from coassist.scenario.operator import OperatorArm, asked_to_go, intent_trajectory, motor_noise
from coassist.scenario.path_model import ASKED_WAY, check_way
from coassist.scenario.populations import POPULATIONS, population_profile
from coassist.scenario.scene import Scene, SceneError
from coassist.scenario.seeds import trial_rngs
from coassist.scenario.tasks import OBSTACLES, TASKS, Box, task_for_seed

logger = logging.getLogger(__name__)

__all__ = [
    "GUARDED_CONTROLLERS",
    "DriveConfig",
    "ZERO_READINGS",
    "SensorZeroError",
    "drive",
    "drive_lockstep",
    "move_tasks",
    "workspace_for",
    "zero_readings",
]

#: Where the real-time predictor runs (coassist.intent.realtime.BACKENDS).
PREDICTOR_BACKENDS = ("process", "onnx", "torch")
#: Height of the task plane above the base [m] in the MuJoCo world (the TCP at the handle).
TASK_HEIGHT = 0.20
#: Rotational inertia and damping of the 6-DOF admittance [kg·m², N·m·s/rad].
ROTATIONAL_INERTIA = 0.5
ROTATIONAL_DAMPING = 5.0


#: Longest run [s]. The loop's log is allocated up front for the whole run (≈ 1 kB a
#: tick with a 50-step prediction: 300 000 ticks, 0.3 GB, at 500 Hz); a trial is a
#: reach of seconds, so ten minutes is far beyond any and inf or 1e9 is a typo.
MAX_TIME_LIMIT = 600.0


@dataclass(frozen=True)
class DriveConfig:
    """One run on a UR5 (every field validated, errors name it as ``DriveConfig.<field>``).

    world : an arm world of :data:`coassist.robot.worlds.WORLDS` ("mujoco", "ur", "franka", "ros2":
        :func:`~coassist.robot.worlds.arm_worlds`).
    controller : a kind of :data:`coassist.control.presets.CONTROLLERS`: "cooperative",
        "cooperative-arbitrated" (α set every tick by coassist.control.presets.ARBITRATION),
        "cooperative-damped", "impedance", "manual" or "manual-probe" (a calibration trial).
    robot : the arm, one of the world's ``arms`` ("ur5" or "panda" in MuJoCo, "ur5" on "ur"
        and "ros2", "panda" or "fr3" on "franka"); None: the world's first.
    task : a task kind (linear, curved, sinusoidal, z).  object : handle, board or heavy.
    preset : a control preset (default :data:`coassist.config.APPLICATION_PRESET`, the main
        job's application preset, safe with a learned predictor in the loop).
    intent : a name of :data:`coassist.scenario.intent_registry.INTENT_SOURCES` ("oracle" in a
        simulated world only) or a folder (a person model, a model, a path-hypotheses calibration);
        default :data:`coassist.scenario.assistance.DEFAULT_INTENT`.
    user : simulated operator index (MuJoCo).  seed : task, operator and sensor seed.
    population, population_seed : who the simulated operator is
        (:func:`coassist.scenario.populations.population_profile`; "thesis": the main job's).
    person : the person at the handle, a pseudonymous id (letters, digits, ``-``, ``_``): the trial's
        user and whose calibration a person model uses; None: "operator" on a real arm, the simulated
        operator's name (``user-<user>``) in a simulated world.
    scene : the obstacles the robot is told of (a lab's scene file, :mod:`coassist.scenario.scene`), in
        the robot's base frame; None: the task's in a simulated world, none on a real arm.
    obstacle : the obstacle the operator goes around (coassist.scenario.tasks.OBSTACLES; "small"
        is the evaluation's box, "large" the application's).
    rate_hz : 125 (UR CB3) or 500 (e-Series); the MuJoCo world runs either.
    full_pose : control all 6 DOFs (orientation error as a rotation vector) instead of x-y.
    time_limit : [s], at most :data:`MAX_TIME_LIMIT`; None: 2 × the plan's duration + 10 s.
    limits : the safety layer's limits (the workspace box defaults to the task's); speeds
        beyond the arm's own (``ArmDescription.tool_speed_limit``, its joint speeds) and a
        contact force beyond :data:`MAX_CONTACT_FORCE` are refused.
    realtime_intent : run the predictor off the control thread (RealtimePredictor); the
        default is on for the real arm and off in MuJoCo, where a deterministic run is
        worth more than wall-clock realism. A simulated world then runs against the wall clock;
        an intent with no network (a named source, a person model) is computed in the tick all
        the same, so there it changes only that pace (the run's one-line statement says so).
    predictor_backend : where the real-time predictor runs: "process" (a worker process:
        the tick never waits for the GIL; the default, see benchmarks/bench_tick.py),
        "onnx" (ONNX Runtime in a worker thread) or "torch" (eager, worker thread); these two
        only with a model run off the control thread (else refused: they would change nothing).
    way : the way round the obstacle the person is asked to take in this run, +1 on the left of the plan, −1 on the
        right (a calibration that asks for a way shown too seldom, ``coassist calibrate``'s advice): recorded in the
        trial (``meta.extra["asked_way"]``) so that the person model counts its path but not as their preference; a
        simulated operator is made to go that way. 0: the person chooses.
    stability : the stability guard on an assistive controller (:data:`GUARDED_CONTROLLERS`, x-y only:
        not with ``full_pose``): once the hand force low-passed over 0.5 s passes 20 N while it turns (an
        oscillation, not a push held in one direction) the robot becomes a damper for the rest of the run
        (:mod:`coassist.control.stability`; a stiff person behind a long reflex delay can fall into a limit cycle
        with assistance that follows their force). None: off.
    """

    world: str = "mujoco"
    controller: str = "cooperative"
    task: str = "linear"
    object: str = "handle"
    preset: str = APPLICATION_PRESET
    intent: str = DEFAULT_INTENT
    user: int = 0
    seed: int = 0
    obstacle: str = "small"
    rate_hz: int = 125
    full_pose: bool = False
    time_limit: float | None = None
    limits: SafetyLimits = field(default_factory=SafetyLimits)
    realtime_intent: bool | None = None
    predictor_backend: str = "process"
    robot: str | None = None
    population: str = "thesis"
    population_seed: int = 0
    person: str | None = None
    scene: Scene | None = None
    stability: StabilityGuardParameters | None = StabilityGuardParameters()
    way: int = 0

    def __post_init__(self) -> None:
        def bad(name: str, what: str) -> ValueError:
            return ValueError(f"DriveConfig.{name} must be {what}, got {getattr(self, name)!r}")

        def one_of(name: str, choices: Any) -> None:
            # a list (unhashable) would make `in` on a dict raise TypeError instead of naming the field
            value = getattr(self, name)
            if not isinstance(value, str) or value not in choices:
                raise bad(name, f"one of {tuple(choices)}")

        arms = arm_worlds()
        one_of("world", arms)
        world = arms[self.world]
        if self.robot is None:
            object.__setattr__(self, "robot", world.arms[0])
        elif not isinstance(self.robot, str) or self.robot not in world.arms:
            raise bad("robot", f"one of {world.arms} with world {self.world!r}")
        one_of("controller", CONTROLLERS)
        one_of("task", TASKS)
        one_of("object", OBJECTS)
        if not isinstance(self.preset, str):
            raise bad("preset", "a control preset's name")
        try:
            get_preset(self.preset)
        except ValueError as exc:  # "preset 'x': no such control preset (choose from …; did you mean …)"
            raise ValueError(f"DriveConfig.{exc}") from None
        one_of("obstacle", OBSTACLES)
        if not isinstance(self.intent, str) or not self.intent.strip():
            raise bad(
                "intent", f"one of {', '.join(INTENT_SOURCES)} or a folder (a model, a path-hypotheses calibration)"
            )
        source = INTENT_SOURCES.get(self.intent)
        if source is not None and source.simulation_only and not world.simulated:
            raise bad("intent", f"a source a real arm can run, not {source.summary} (a simulation alone knows it)")
        one_of("population", POPULATIONS)
        for name in ("user", "seed", "population_seed"):
            v = getattr(self, name)
            if not is_integer(v) or v < 0:
                raise bad(name, "an int >= 0")
        if not is_integer(self.rate_hz) or self.rate_hz not in (125, 500):  # 125.0 would give dt and a rate of floats
            raise bad("rate_hz", "125 or 500 (an int)")
        # a string such as "no" is truthy: it would switch the field on
        if not isinstance(self.full_pose, bool):
            raise bad("full_pose", "True or False")
        if self.realtime_intent is not None and not isinstance(self.realtime_intent, bool):
            raise bad("realtime_intent", "True, False or None (the world's default)")
        if self.time_limit is not None and not (
            is_real_number(self.time_limit) and 0 < self.time_limit <= MAX_TIME_LIMIT
        ):
            raise bad("time_limit", f"a number of seconds in (0, {MAX_TIME_LIMIT:g}] or None")
        if not isinstance(self.limits, SafetyLimits):
            raise bad("limits", "a SafetyLimits")
        _check_limits_for_arm(self.limits, self.robot)
        one_of("predictor_backend", PREDICTOR_BACKENDS)
        # The backend is where a trained network runs off the control thread (_intent_stage): a named source, a
        # person model or a calibration is computed in the tick, and so is a model with realtime_intent off, so
        # another backend would change nothing. A string that is no such folder is tried as a model
        # (needs_network): its loader says what is wrong with it. (realtime_intent itself is not refused without
        # a network: it still paces a simulated world to the wall clock, the live view's use, docs/foxglove.md;
        # the run's one-line statement says so.)
        if self.predictor_backend != "process":
            realtime = self.realtime_intent if self.realtime_intent is not None else not world.simulated
            network = needs_network(self.intent)
            if not (network and realtime):
                why = (
                    "it has no network to run" if not network else "realtime_intent is off: the model runs in the tick"
                )
                raise bad("predictor_backend", f"'process' (the default) with intent {self.intent!r} ({why})")
        if self.person is not None and (not isinstance(self.person, str) or not _PERSON.fullmatch(self.person)):
            raise bad("person", "1-32 letters, digits, '-' or '_' (a pseudonymous id, e.g. P07)")
        if self.scene is not None and not isinstance(self.scene, Scene):
            raise bad("scene", "a Scene (coassist.scenario.scene.read_scene) or None")
        if self.stability is not None and not isinstance(self.stability, StabilityGuardParameters):
            raise bad("stability", "StabilityGuardParameters (coassist.control.stability) or None (off)")
        object.__setattr__(self, "way", check_way(self.way, "DriveConfig.way"))

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def who(self) -> str:
        """The person at the handle as the trial names them (``person``, or the world's default)."""
        if self.person is not None:
            return self.person
        if WORLDS[self.world].simulated:
            return population_profile(self.population, self.user, self.population_seed).name
        return "operator"


#: A person's id: what a folder may be named (as play's user). Matched with fullmatch: ``$`` would also
#: match before a trailing newline ("P07\n").
_PERSON = re.compile(r"[A-Za-z0-9_-]{1,32}")


#: [N] the largest contact force limit: the F/T sensor's range (FT300: 300 N per axis, the default
#: of runtime.wrench.WrenchConfig.force_range). Above it the protective stop could never trip.
MAX_CONTACT_FORCE = WrenchConfig.force_range


def _check_limits_for_arm(limits: SafetyLimits, robot: str | None) -> None:
    """Refuse limits that would switch a protection off: speeds beyond the arm's own hard
    limits (they limit nothing) and a contact force beyond what the sensor can measure."""
    from coassist.robot.arm_descriptions import get_arm

    arm = get_arm(robot or "ur5")
    if limits.tool_speed > arm.tool_speed_limit:
        raise ValueError(
            f"SafetyLimits.tool_speed must be at most {arm.tool_speed_limit:g} m/s, the {arm.name}'s own "
            f"tool speed limit, got {limits.tool_speed!r}"
        )
    vmax = np.asarray(arm.joint_velocity_limit, dtype=float)
    jv = limits.joint_velocity_array(vmax.size)  # raises naming the field when a per-joint tuple has another length
    if np.any(jv > vmax):
        shown = ", ".join(f"{v:.4g}" for v in vmax)
        raise ValueError(
            f"SafetyLimits.joint_velocity must be at most the {arm.name}'s own joint speeds ({shown}) "
            f"rad/s, got {limits.joint_velocity!r}"
        )
    if arm.joint_acceleration_limit is not None and limits.joint_acceleration > max(arm.joint_acceleration_limit):
        shown = ", ".join(f"{a:g}" for a in arm.joint_acceleration_limit)
        raise ValueError(
            f"SafetyLimits.joint_acceleration must be at most the {arm.name}'s own joint accelerations ({shown} "
            f"rad/s²; the layer holds every joint to the smallest), got {limits.joint_acceleration!r}"
        )
    if limits.contact_force > MAX_CONTACT_FORCE:
        raise ValueError(
            f"SafetyLimits.contact_force must be at most {MAX_CONTACT_FORCE:g} N, the force sensor's range "
            f"(above it the protective stop could never trip), got {limits.contact_force!r}"
        )


def arm_limits(limits: SafetyLimits, robot: str | None, world: str | None = None) -> SafetyLimits:
    """``limits`` with the joint acceleration bound at most the arm's smallest joint acceleration
    (:attr:`~coassist.robot.arm_descriptions.ArmDescription.joint_acceleration_limit`): the layer's one bound
    ‖q̇ − q̇⁻‖∞ ≤ a dt holds every joint to it (the default 8 rad/s² let a Panda's joint 2, 7.5 rad/s², take 7.84).
    Through franky (``world`` "franka") each joint's bound is also at most franky's own motion generator's
    (:data:`~coassist.robot.arm_descriptions.FRANKY_JOINT_ACCELERATION`: an FR3's joint 2, 10 rad/s² on the arm, is
    held to 7.5 by franky, which would smooth the layer's 8 there)."""
    from coassist.robot.arm_descriptions import FRANKY_JOINT_ACCELERATION, get_arm

    own = get_arm(robot or "ur5").joint_acceleration_limit
    if own is not None and world == "franka":
        own = tuple(min(a, b) for a, b in zip(own, FRANKY_JOINT_ACCELERATION))
    if own is None or limits.joint_acceleration <= min(own):
        return limits
    return replace(limits, joint_acceleration=float(min(own)))


#: The controller kinds the stability guard wraps (:attr:`DriveConfig.stability`): the assistive ones. Manual
#: guidance, impedance control and the calibration probe are the baselines and the lab's measurement.
GUARDED_CONTROLLERS = ("cooperative", "cooperative-arbitrated", "cooperative-damped")


def _controller(config: DriveConfig):
    """The preset's controller at the run's rate, on 2 (x-y) or 6 DOFs (coassist.control.presets.make_controller)."""
    preset = get_preset(config.preset)
    imp, game = preset.impedance, preset.game
    dt = config.dt
    ticks = lambda n: max(1, round(n * imp.dt / dt))  # noqa: E731 (the same look-ahead in seconds)
    gp = replace(
        game,
        horizon=max(2, ticks(game.horizon)),
        control_horizon=None if game.control_horizon is None else ticks(game.control_horizon),
    )
    M, D = imp.M, imp.D
    if config.full_pose:
        # z like x; rotations with their own inertia and damping; the game weighs them like positions.
        M = M + (M[0], ROTATIONAL_INERTIA, ROTATIONAL_INERTIA, ROTATIONAL_INERTIA)
        D = D + (D[0], ROTATIONAL_DAMPING, ROTATIONAL_DAMPING, ROTATIONAL_DAMPING)

        w = gp.weights

        def diagonal(name: str) -> tuple[float, ...]:
            matrix = getattr(w, name)
            d = np.diag(matrix)
            if not np.array_equal(matrix, np.diag(d)):  # the rotations copy x's weight: a diagonal's
                raise ValueError(f"full_pose needs the preset's game.weights.{name} diagonal, got {matrix.tolist()}")
            return tuple(float(v) for v in d)

        def six(q: tuple[float, ...]) -> tuple[float, ...]:
            return q[:2] + (q[0],) * 4 + q[2:] + (q[2],) * 4

        weights = GameWeights(
            *(np.array(six(diagonal(q))) for q in ("Q_hh", "Q_hr", "Q_rh", "Q_rr")),
            *(np.array(diagonal(r) + (diagonal(r)[0],) * 4) for r in ("R_h", "R_r")),
        )
        gp = replace(gp, weights=weights)
    impedance = ImpedanceParameters(M=M, D=D, K=(0.0,) * len(M), dt=dt)
    controller = make_controller(config.controller, replace(preset, impedance=impedance, game=gp))
    guard = stability_guard(config)
    if guard is not None:
        # a damper once a large hand force turns (an oscillation): the damper's c acts on the x-y velocity
        # (N·s/m), so not on the rotations of a full pose
        controller = StabilityGuard(controller, guard)
    return controller


def _lockstep_controller(config: DriveConfig, held: dict[tuple, Any]):
    """:func:`_controller` for a drive in lockstep: one object for the runs that would build equal ones
    (their preset, kind, rate, DOFs and guard) where it keeps no state between ticks (no ``reset``:
    MG, IMP, a fixed-α game), so :func:`~coassist.runtime.batched_loops.run_loops` steps them in one
    ``step_batch`` (row for row its ``step``, bit for bit); one of its own where it keeps state (the
    online-α arbitration, the stability guard)."""
    key = (config.preset, config.controller, config.dt, config.full_pose, stability_guard(config))
    controller = held.get(key)
    if controller is None:
        controller = _controller(config)
        if callable(getattr(controller, "reset", None)):
            return controller
        held[key] = controller
    return controller


def stability_guard(config: DriveConfig) -> StabilityGuardParameters | None:
    """The stability guard's parameters where the run's controller is wrapped in it (:attr:`DriveConfig.stability`:
    an assistive controller on x-y), else None."""
    if config.controller in GUARDED_CONTROLLERS and not config.full_pose:
        return config.stability
    return None


def workspace_for(
    reference: np.ndarray, start_pose: np.ndarray, margin: float = 0.25, z_margin: float = 0.15
) -> tuple[np.ndarray, np.ndarray]:
    """The default workspace box: the plan's x-y extent ± margin, the start height ± z_margin [m]."""
    lo = np.array([reference[:, 0].min() - margin, reference[:, 1].min() - margin, start_pose[2] - z_margin])
    hi = np.array([reference[:, 0].max() + margin, reference[:, 1].max() + margin, start_pose[2] + z_margin])
    return lo, hi


def drive(
    config: DriveConfig,
    *,
    operator: Any = None,
    world: Any = None,
    host: str | None = None,
    view: bool = False,
    confirm: Any = None,
    on_tick: Any = None,
    intent_source: Any = None,
    say: Any = None,
    live: Any = None,
    joint_names: Sequence[str] | None = None,
) -> Trial:
    """Run one trial on a UR5 (module docstring) and return it.

    operator : the MuJoCo world's hand; None: the simulated operator ``config.user``.
    world : a world built by the caller (tests inject faults this way); None: built here.
    host : the real arm's address (the worlds that need one: "ur", "franka").  view : MuJoCo's passive viewer.
    confirm : called with the text of the limits in force before a real arm moves; it
        must return True to go on (the CLI asks the person at the robot).
    intent_source : an IntentSource or RealtimePredictor to use instead of ``config.intent``.
    say : told in one line what the person will get (:func:`~coassist.scenario.assistance.assistance_line`),
        once the world is read and before ``confirm``.
    live : a :class:`~coassist.runtime.live.LiveFeed` (the live view, e.g. Foxglove) that watches the
        run; ``joint_names`` name its joint states (default: the UR's for a UR5, else joint_1 …).
    """
    run = _prepare(config, operator=operator, world=world, host=host, view=view, intent_source=intent_source)
    interrupted: RunInterrupted | None = None
    try:
        follow = optional_member(run.world, "follow_episode")
        if callable(follow):  # a world that publishes the run (ROS 2's monitor): its controller's α, its plan
            follow(run.episode)
        if say is not None:
            say(run.assistance)
        if confirm is not None and not confirm(run.limits.describe()):
            raise RuntimeError("not confirmed: the robot was not moved")
        if live is not None:
            if joint_names is None and config.robot == "ur5":
                from coassist.robot.ros2_world import UR_JOINT_NAMES  # (the names only: no rclpy)

                joint_names = UR_JOINT_NAMES
            on_tick = live.watch(run.episode, on_tick, joint_names=joint_names)
        try:
            log = run.episode.run(deadline=config.dt if run.world.realtime else None, on_tick=on_tick)
        except RunInterrupted as stop:  # Ctrl-C: the arm stopped, the ticks before it made a trial (below)
            interrupted, log = stop, stop.log
    except BaseException:
        run.close()
        raise
    with InterruptsHeld() as held:  # the run is over: a Ctrl-C from here on must not lose its trial
        try:
            run.close()
        except Exception as exc:  # the world's teardown on a dropped link (a broken pipe): the ticks are the trial
            logger.warning("drive: closing the world after the run raised %s: %s", type(exc).__name__, exc)
        trial = run.finish(log) if log.n or interrupted is None else None
    if interrupted is None and held.pending:
        interrupted = RunInterrupted(log, after_end=True)
    if interrupted is not None:
        interrupted.trial = trial
        raise interrupted
    assert trial is not None  # a run not interrupted is made a trial above, whatever its length
    return trial


def drive_lockstep(configs: Sequence[DriveConfig], *, together: bool = True) -> list[Trial]:
    """Simulated drives (a simulated world such as ``"mujoco"``, each its own) run in lockstep
    (:func:`coassist.runtime.batched_loops.run_loops`): one network call per tick for the runs
    with the same model in the loop, one controller call per tick for the runs of one controller
    kind (:func:`_lockstep_controller`). Each trial is its :func:`drive` to the float32 rounding
    of batched network calls (bit for bit with a named intent); in ``configs``' order.

    ``together``: the MuJoCo worlds built alike step in one model
    (:class:`~coassist.robot.mujoco_world.MujocoArmGroup`, the same states bit for bit); where a
    joint limit makes that impossible (:class:`~coassist.robot.mujoco_world.ConstraintInGroup`) the
    drives run again, each world its own."""
    from coassist.runtime.batched_loops import run_loops

    if together:
        from coassist.robot.mujoco_world import ConstraintInGroup, MujocoArmGroup

    for i, c in enumerate(configs):
        if not isinstance(c, DriveConfig) or not WORLDS[c.world].simulated or c.realtime_intent:
            simulated = ", ".join(name for name, entry in arm_worlds().items() if entry.simulated)
            raise ValueError(
                f"configs[{i}] must be a DriveConfig of a simulated world ({simulated}) without a real-time predictor"
            )
    sources: dict[tuple[str, int], Any] = {}
    controllers: dict[tuple, Any] = {}
    runs: list[_PreparedDrive] = []
    try:
        for c in configs:
            runs.append(_prepare(c, sources=sources, controllers=controllers))
        groups = MujocoArmGroup.form([r.world for r in runs if r.built_here]) if together else []

        def step_groups() -> None:
            for g in groups:
                g.step()

        try:
            logs = run_loops([r.episode.loop for r in runs], after_tick=step_groups if groups else None)
        except Exception as exc:
            if not (groups and isinstance(exc, ConstraintInGroup)):
                raise
            logger.warning("drive_lockstep: %s; the %d drives run again, each world its own", exc, len(configs))
            for r in runs:
                r.close()
            runs = []
            return drive_lockstep(configs, together=False)
    finally:
        for r in runs:
            r.close()
    return [r.finish(log) for r, log in zip(runs, logs)]


@dataclass
class _PreparedDrive:
    """A drive built and not yet run: its episode, and what :meth:`close` and :meth:`finish` need."""

    episode: Any
    world: ArmWorld
    limits: SafetyLimits
    wrench: WrenchPipeline
    built_here: bool
    intent_stage: Any
    assistance: str = ""

    def close(self) -> None:
        _release(self.world, self.built_here, self.intent_stage)

    def finish(self, log: Any) -> Trial:
        return self.episode.finish(log, {"sensor_bias": [float(v) for v in self.wrench.bias]})


def _check_scene(scene: Scene, start: np.ndarray, target: np.ndarray) -> None:
    """ValueError in one line, nothing moved, where a box of the lab's scene file holds the plan's start (where the
    tool stands) or its target: no person can take the tool there, and a source told of it leads the tool round a
    box that is not where the file says (most often the file is in another frame than the robot's base, or in mm)."""
    for i, b in enumerate(scene.boxes):
        center, size = b.center, b.size
        box = Box(center, size)
        for what, point in (("start (where the tool stands)", start), ("target", target)):
            if float(box.signed_distance(np.asarray(point, dtype=float))) <= 0.0:
                named = f"obstacle {i + 1}" + (f" ({b.name})" if b.name else "")
                raise SceneError(
                    f"scene {scene.source}: {named} (centre {center[0]:.3f}, {center[1]:.3f} m, size "
                    f"{size[0]:.3f} × {size[1]:.3f} m) holds the plan's {what} at {point[0]:.3f}, {point[1]:.3f} m: "
                    "a box there cannot be; give the obstacles in the robot's base frame, in metres"
                )


def _release(world: Any, built_here: bool, intent_stage: Any) -> None:
    """Close the world if the drive built it, and a real-time predictor's worker."""
    try:
        if built_here and world is not None:
            world.close()
    finally:
        if isinstance(intent_stage, RealtimeIntent):
            close = getattr(intent_stage.predictor, "close", None)
            if close is not None:
                close()


def _prepare(
    config: DriveConfig,
    *,
    operator: Any = None,
    world: Any = None,
    host: str | None = None,
    view: bool = False,
    intent_source: Any = None,
    sources: dict | None = None,
    controllers: dict | None = None,
) -> _PreparedDrive:
    """Build :func:`drive`'s episode (world, hand, kinematics, wrench, safety, tick) with the
    sensor zeroed; on failure, close what was built. ``sources``: a cache (intent, horizon) →
    loaded source that runs in lockstep share (those with a ``batcher``: stateless);
    ``controllers``: a cache of the controllers they share (:func:`_lockstep_controller`)."""
    if not isinstance(config, DriveConfig):
        raise ValueError(f"config must be a DriveConfig, got {type(config).__name__}")
    dt = config.dt
    controller = _controller(config) if controllers is None else _lockstep_controller(config, controllers)
    H = int(controller.horizon)
    task = task_for_seed(config.task, config.seed, obstacle=config.obstacle)  # the same draw in every world
    profile = population_profile(config.population, config.user, config.population_seed)
    profile = asked_to_go(profile, config.way)  # a simulated operator asked for a way goes that way
    obj = get_object(config.object)
    entry = WORLDS[config.world]
    simulated = entry.simulated
    n_max = episode_ticks(task, dt, config.time_limit)
    built_here = world is None
    intent_stage = None
    user = config.who
    try:
        intent_stage, model_id = _intent_stage(config, H, intent_source, sources)
        loaded = getattr(intent_stage, "source", None)
        check_person(loaded, user, config.intent)
        check_person_world(loaded, entry.origin, config.world, config.intent)
        ref_abs = plan_grid(task, dt, n_max, max(H, int(intent_stage.horizon)))
        rng_intent, rng_motor = trial_rngs(config.seed, 2)
        intent_traj = intent_trajectory(task, profile, rng_intent, ref_abs.shape[0], dt)
        intent_pos = intent_traj.positions
        target = np.array(task.target, dtype=float)
        start = (float(task.start[0]), float(task.start[1]), TASK_HEIGHT)
        robot = config.robot or entry.arms[0]  # DriveConfig sets it; `or` for the type checker
        moved: dict[str, Any] = {}  # the task's places in this run's frame, where it was moved
        if simulated and robot != "ur5":  # the tasks, laid out for the UR5, moved to this arm
            ref_abs, intent_pos, start = move_tasks(robot, ref_abs, intent_pos)
            shift = _task_shift(robot)
            target = target + shift
            # recorded where the run put them (the Panda's trial said the UR5's: its figure drew the box 0.6 m off
            # the path, and σ and the overshoot read NaN for a run that reached its target; a review, 2026-12-07)
            recorded = task.to_extra()
            moved = {
                "start": [float(v) for v in np.asarray(recorded["start"], dtype=float) + shift],
                "target": [float(v) for v in target],
                "obstacle": {
                    **recorded["obstacle"],
                    "center": [float(v) for v in np.asarray(recorded["obstacle"]["center"], dtype=float) + shift],
                },
            }
        limits = arm_limits(config.limits, robot, config.world)  # the layer's, and a simulated arm's ramp
        if world is None:
            # A real-time predictor runs against the wall clock: so must the simulated world it serves.
            world = build_world(
                config.world,
                WorldRequest(
                    robot,
                    config.object,
                    config.rate_hz,
                    config.seed,
                    start,
                    host,
                    view,
                    realtime=view or bool(config.realtime_intent),
                    joint_acceleration=limits.joint_acceleration,
                ),
            )
        if not isinstance(world, ArmWorld):
            raise ValueError(
                f"world must be an arm world (coassist.robot.worlds.ArmWorld); a {type(world).__name__} "
                f"lacks {', '.join(missing_members(world, ArmWorld))}"
            )
        world_dt = float(world.dt)
        if not math.isclose(world_dt, dt, rel_tol=1e-9):
            # the tick, the admittance and the safety layer's per-tick steps run on config.dt and the world paces on
            # its own: at 500 Hz under a 125 Hz config each period stepped the speed by a 125 Hz period's
            # acceleration (31 rad/s² for 8), and the trial's clock ran 4 times the robot's
            raise ValueError(
                f"the world runs at {1.0 / world_dt:g} Hz (dt {world_dt:g} s) and the drive at {config.rate_hz:g} Hz "
                f"(DriveConfig.rate_hz): build the world at the drive's rate, or give the drive the world's; "
                "nothing was moved"
            )
        state0 = world.read()
        if not np.isfinite(np.asarray(state0.tool_pose, dtype=float)).all():  # the plan is laid out from it
            raise ValueError(
                f"the robot reports a TCP pose that is not finite ({np.asarray(state0.tool_pose).tolist()}) before "
                "the run: nothing was moved; check the robot's state, then rerun"
            )
        # the sensor's zero: a real sensor from zero_samples readings of its stream that agree (one glitched sample
        # zeroed alone became a push the arm followed on its own); a simulated world's read repeats one sample
        # until it steps: that one. Read now, before a simulated handle is given its operator (who would push).
        zeroing = zero_readings(world, state0, 1 if simulated else ZERO_READINGS, dt)
        start_pose = np.asarray(state0.tool_pose, dtype=float).copy()
        hand: HandWorld | None = world if isinstance(world, HandWorld) else None  # a handle to hold
        # the simulated operator at a simulated handle: MuJoCo's, or coassist ur-sim's behind the ur world
        held = simulated or hand is not None
        # the robot is told the task's obstacle where the simulated operator, who goes round it, is at the
        # handle (a simulated world, or a simulated handle with no other hand given); a lab's scene otherwise
        told_task = simulated or (hand is not None and operator is None)
        if not held:
            # lay the task out from where the TCP is: shift the plan
            shift = start_pose[:2] - ref_abs[0, :2]
            ref_abs = ref_abs.copy()
            ref_abs[:, :2] += shift
            target = target + shift
        if config.scene is not None:
            _check_scene(config.scene, ref_abs[0, :2], target[:2])
        if operator is None and hand is not None:
            noise = motor_noise(profile, rng_motor, ref_abs.shape[0], dt)  # as long as the intent: stop() may step on
            arm = OperatorArm(profile, intent_pos, dt, noise)
            hand_pose, _ = hand.hand_pose()
            operator = SimulatedHand(
                arm, dt, hand_pose, full_pose=config.full_pose, offset=hand_pose[:2] - start_pose[:2]
            )
        if operator is not None and hand is not None:
            hand.operator = operator
        kin = world.kinematics()
        mass, com = world.tool_mass_and_com()
        # a noise-free simulated sensor (MuJoCo's without noise, a test's external F/T) repeats exactly
        # on a constant push: no frozen-sensor check there
        wrench = WrenchPipeline(
            WrenchConfig(
                tool_mass=mass,
                tool_com=tuple(com),
                max_frozen_time=None if world.noise_free_sensor else MEASURED_FROZEN_TIME,
            ),
            dt,
        )
        if limits.workspace_lower is None:
            lo, hi = workspace_for(ref_abs, start_pose)
            limits = replace(limits, workspace_lower=tuple(lo), workspace_upper=tuple(hi))
        dofs = (0, 1, 2, 3, 4, 5) if config.full_pose else (0, 1)
        guarded = stability_guard(config)
        episode = build_episode(
            world=world,
            controller=controller,
            intent=intent_stage,
            wrench=wrench,
            safety=SafetyLayer(limits, dt, int(world.n_joints)),
            task=task,
            plan=ref_abs,
            start_pose=start_pose,
            n_max=n_max,
            target=target,
            labels=EpisodeLabels(
                user=user if config.person is not None else (profile.name if held else "operator"),
                object=obj.name,
                seed=config.seed,
                origin=entry.origin,
                preset=config.preset,
                model_id=model_id,
            ),
            # the simulated operator's intent: the oracle's in any world (a test's simulated arm behind a
            # real-arm link), the Trial's intent column only where that operator held the handle
            true_intent=intent_pos,
            intent_end_time=intent_traj.end_time,
            log_intent=held,
            # the robot is told of the obstacle only where the simulated operator goes round it: a person at a
            # real arm sees no such box (the path-hypotheses source then is the present estimate alone)
            tell_obstacles=told_task,
            told_obstacles=None if config.scene is None else config.scene.told(),
            kinematics=kin,
            tick_config=TickConfig(dofs=dofs),
            extra={
                "world": config.world,
                # The admittance the tick integrates from wrench + u_r (the label 'hand_alone' removes u_r through it).
                "plant": {
                    name: [float(v) for v in np.diag(getattr(controller.model, name))] for name in ("M", "D", "K")
                },
                "robot": config.robot,
                "object": obj.to_extra(),
                "rate_hz": config.rate_hz,
                "full_pose": config.full_pose,
                "start_pose": [float(v) for v in start_pose],
                # the limits in force: the safety layer's, with the workspace box drawn round the plan
                "limits": limits.describe(),
                "dofs": list(dofs),
                **({} if config.scene is None else {"scene": config.scene.to_extra()}),
                # the simulated operator's way round the obstacle (+1 left): the report's per-side figures
                **({"intent_side": int(intent_traj.side)} if held else {}),
                **({ASKED_WAY: config.way} if config.way else {}),
                # whether the run's controller was wrapped in the stability guard, and with what (None: not)
                "stability_guard": None if guarded is None else asdict(guarded),
                **moved,
            },
        )
        assistance = assistance_line(
            config.controller,
            config.intent,
            loaded,
            user=user,
            # what build_episode told the source, read back rather than decided again (TrialContext.path, .obstacles)
            path=episode.context.path,
            obstacles=episode.context.obstacles,
            scene=None if config.scene is None else config.scene.source,
        )
        if guarded is not None:
            assistance += (
                f"; a damper if the hand force oscillates above {guarded.force_threshold:g} N (the stability guard)"
            )
        elif config.full_pose and config.controller in GUARDED_CONTROLLERS and config.stability is not None:
            # asked for (its default), but the guard watches x-y control alone: said, not dropped silently
            assistance += "; no stability guard (it watches x-y control, not the full pose)"
        if config.realtime_intent and intent_source is None and not needs_network(config.intent):
            # asked for a real-time predictor where there is none to run: say what it does instead
            assistance += (
                f"; realtime_intent runs no predictor ({config.intent} has no network, it is computed in the tick)"
                + (": it only paces the simulated world to the wall clock" if simulated else "")
            )
        # zero the sensor with the tool still and nobody touching it (the hand starts at rest), from the readings
        # taken before a simulated hand was given its operator
        wrench.zero(*zeroing)
    except BaseException:
        _release(world, built_here, intent_stage)
        raise
    return _PreparedDrive(episode, world, limits, wrench, built_here, intent_stage, assistance)


#: readings of a real arm's sensor :func:`drive` zeroes it from, before the run (the wrench pipeline's
#: ``zero_samples``: 0.2 s at 125 Hz); a simulated world's one
ZERO_READINGS = WrenchConfig().zero_samples
#: [N], [N·m] how far one reading of the zeroing may be from their median, per channel: a still sensor's
#: noise is well below (the deadband alone is 0.2 N), a hand resting on the tool or a glitched sample above.
ZERO_SPREAD_FORCE, ZERO_SPREAD_TORQUE = 5.0, 0.5


class SensorZeroError(CoassistError, ValueError):
    """The force sensor could not be zeroed: its readings with nobody touching the tool do not agree, or are
    not finite. Nothing was moved."""


def zero_readings(world: Any, state0: Any, n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(raw (n, 6), rotations (n, 3, 3)): ``state0``'s wrench and sensor rotation and n − 1 more read from
    ``world`` one period ``dt`` apart, for :meth:`~coassist.runtime.wrench.WrenchPipeline.zero`.

    Refused (:class:`SensorZeroError`, saying what to do) where a reading is not finite or one channel's
    readings spread more than :data:`ZERO_SPREAD_FORCE` / :data:`ZERO_SPREAD_TORQUE` from their median: zeroed
    on one glitched sample (a 60 N spike, below the sensor's range and the contact limit), the arm read the
    glitch as a push for the whole run and moved on its own at the tool-speed limit."""
    states = [state0]
    for _ in range(n - 1):
        time.sleep(dt)
        states.append(world.read())
    raw = np.array([np.asarray(s.wrench, dtype=float) for s in states])
    rotations = np.array([np.asarray(s.sensor_rotation, dtype=float) for s in states])
    if not (np.isfinite(raw).all() and np.isfinite(rotations).all()):
        bad = int(np.flatnonzero(~np.isfinite(raw).all(axis=1) | ~np.isfinite(rotations).all(axis=(1, 2)))[0])
        raise SensorZeroError(
            f"the force sensor cannot be zeroed: reading {bad + 1} of {n} is not finite (a sensor or driver fault); "
            "nothing was moved"
        )
    spread = np.abs(raw - np.median(raw, axis=0)).max(axis=0)
    limit = np.array([ZERO_SPREAD_FORCE] * 3 + [ZERO_SPREAD_TORQUE] * 3)
    if (spread > limit).any():
        i = int(np.argmax(spread / limit))
        unit = "N" if i < 3 else "N·m"
        raise SensorZeroError(
            f"the force sensor cannot be zeroed: its {n} readings over {(n - 1) * dt:.2f} s spread {spread[i]:.1f} "
            f"{unit} on {('fx', 'fy', 'fz', 'tx', 'ty', 'tz')[i]} (at most {limit[i]:g} {unit}): someone touching "
            "the tool, a cable pulling on it, or a glitched sample; let go of the tool and start again (nothing "
            "was moved)"
        )
    if (raw == raw[0]).all() and (rotations == rotations[0]).all():
        return raw[:1], rotations[:1]  # a world that repeats its sample (a simulator waiting for a command): that one
    return raw, rotations


def move_tasks(robot: str, ref_abs: np.ndarray, intent: np.ndarray):
    """The plan and the intent moved (x-y) from the UR5's task area to ``robot``'s
    (``ArmDescription.task_centre``), and the start TCP position (3,) at its task height [m]."""
    from coassist.robot.arms import get_arm

    shift = _task_shift(robot)
    ref_abs, intent = ref_abs.copy(), intent.copy()
    ref_abs[:, :2] += shift
    intent[:, :2] += shift
    return ref_abs, intent, (float(ref_abs[0, 0]), float(ref_abs[0, 1]), float(get_arm(robot).task_centre[2]))


def _task_shift(robot: str) -> np.ndarray:
    """(2,) [m] from the UR5's task centre to ``robot``'s (x-y)."""
    from coassist.robot.arms import get_arm

    ur5, arm = get_arm("ur5").task_centre, get_arm(robot).task_centre
    return np.array(arm[:2]) - np.array(ur5[:2])


def _check_model_rate(config: DriveConfig) -> None:
    """Refuse a model trained at another rate than the run's (its rows are a horizon of its own ticks: a 125 Hz
    model's 50 rows are 0.4 s, a 500 Hz controller asks 200), naming --intent and --rate, before anything is loaded."""
    from coassist.intent.model import DT_RTOL, ModelFileError, read_sidecar

    try:
        dt = float(read_sidecar(config.intent).get("dt") or config.dt)
    except (ModelFileError, OSError, TypeError, ValueError):
        return  # the loader below says what is wrong with the folder
    if not math.isclose(dt, config.dt, rel_tol=DT_RTOL):
        raise ValueError(
            f"--intent {config.intent}: the model was trained at {1 / dt:g} Hz (dt {dt:g} s), this run is at --rate "
            f"{config.rate_hz} (dt {config.dt:g} s): drive at --rate {round(1 / dt)}, or train a model on trials of "
            "this rate"
        )


def _intent_stage(config: DriveConfig, H: int, source: Any, sources: dict | None = None):
    realtime = config.realtime_intent if config.realtime_intent is not None else not WORLDS[config.world].simulated
    if source is not None:
        if hasattr(source, "tick"):
            return RealtimeIntent(source), getattr(source, "model_id", "realtime")
        return WindowIntent(source, H), source.model_id
    if not needs_network(config.intent):  # a named source or a calibration, computed in the tick: no network
        src = load_intent_source(config.intent, horizon=max(H, 2))
        return WindowIntent(src, H), src.model_id
    _check_model_rate(config)
    if realtime:
        from coassist.intent import RealtimeConfig, RealtimePredictor
        from coassist.intent.model import load_model

        model = load_model(config.intent, features=FEATURES)
        model.check_compatible(None, config.dt, what="the drive loop")
        digest = str(model.weights_sha256)[:12]  # the weights that were loaded and verified
        mid = f"{config.intent.rstrip('/').split('/')[-1]}@{digest}"
        predictor = RealtimePredictor(model, RealtimeConfig(threaded=True, backend=config.predictor_backend))
        return RealtimeIntent(predictor, model_id=mid), mid
    src = shared_intent_source(config.intent, max(H, 2), sources)
    return WindowIntent(src, H), src.model_id
