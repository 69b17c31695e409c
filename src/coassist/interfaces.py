"""What the control loop shares with the intent predictor: fault flags, features, intent sources.

This module sits below ``control``, ``intent``, ``sim``, ``runtime`` and ``robot`` and
imports nothing of coassist, so none of them needs another to agree on these names
(docs/architecture.md, *Layers*; ``tests/test_layers.py`` enforces the order).

- :class:`Fault` — why a tick did not apply the plain control law; one int64 per tick
  in every logged trial (``Trial.fault``), flags combine.
- :data:`FEATURES` — the per-tick history features of the x-y predictor, thesis
  order (eq. 4.3–4.6).
- :class:`TrialContext`, :class:`IntentSource` — what a predictor may know at the start
  of a trial, and the per-tick interface the loop calls (window in, positions out).

History features, one row per tick, oldest first::

    FEATURES = (x, y, ẋ, ẏ, f_x, f_y, x_ref, y_ref)     [m, m, m/s, m/s, N, N, m, m]

x, y: measured tool position; ẋ, ẏ: its velocity; f: the hand wrench in use at that
tick (Trial.wrench); x_ref, y_ref: the planner's nominal reference (Trial.reference).
Row j of the window at tick k is exactly row k − history + 1 + j of the logged Trial,
so windows cut from logged trials are what the source sees online. Before ``history``
ticks have passed, the window is padded at the front with copies of tick 0's row.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from coassist._checks import is_real_number

__all__ = [
    "NETWORK_BACKENDS",
    "FEATURES",
    "Fault",
    "MOTION_LIMITED",
    "IntentSource",
    "PlausibilityLimits",
    "TRIAL_SLOTS",
    "TrialContext",
    "ZERO_EFFORT_FAULTS",
    "fault_names",
    "missing_members",
    "prediction_plausible",
]


class Fault(enum.IntFlag):
    """Why a tick did not apply the plain control law (flags combine; values are stored in trials).

    Controller guard (``control``): NONFINITE_* … INVALID_INPUT.
    Intent: PREDICTION_STALE, PREDICTION_FALLBACK, PREDICTOR_STALLED.
    Wrench pipeline (``runtime.wrench``): SENSOR_*, WRENCH_SPIKE.
    Safety layer (``runtime.safety``): the limits, DEADLINE_MISS, DECELERATING, STOPPED.
    Robot: ROBOT_PROTECTIVE_STOP, ROBOT_EMERGENCY_STOP (reported by the world).
    Arm tick (``runtime.tick``): STATE_MISMATCH.
    """

    NONE = 0
    NONFINITE_STATE = 1
    NONFINITE_REFERENCE = 2
    NONFINITE_WRENCH = 4
    SATURATED = 8  # the robot effort was scaled down to effort_limit
    NONFINITE_EFFORT = 16
    PREDICTION_STALE = 32  # the intent prediction in use was shifted, not fresh
    PREDICTION_FALLBACK = 64  # prediction too old or invalid: the nominal reference was used
    INTERNAL_ERROR = 128  # a stage raised; its safe output was used instead
    INVALID_INPUT = 256  # an input of the wrong shape or type (bool, str, complex), or implausibly large
    SENSOR_STALE = 512  # no new force/torque sample for longer than the pipeline allows
    SENSOR_SATURATED = 1024  # a sensor channel at its range limit: the reading is not the hand force
    WRENCH_SPIKE = 2048  # a physically implausible jump: the sample was rejected
    JOINT_VELOCITY_LIMIT = 4096  # the joint velocity command was scaled to its limit
    JOINT_ACCELERATION_LIMIT = 8192  # the change of the joint velocity command was limited
    TOOL_SPEED_LIMIT = 16384  # the tool's linear or angular speed was scaled to its limit
    WORKSPACE_LIMIT = 32768  # motion out of the workspace box was removed
    CONTACT_FORCE_LIMIT = 65536  # the hand wrench exceeded the contact threshold: protective stop
    SINGULARITY = 131072  # manipulability under its guard: motion scaled down
    DEADLINE_MISS = 262144  # the previous tick overran its period
    PREDICTOR_STALLED = 524288  # the intent worker is dead or has produced nothing for too long
    DECELERATING = 1 << 20  # the safety layer is ramping the command to zero
    STOPPED = 1 << 21  # the safety layer has stopped the robot (zero command until the run ends)
    ROBOT_PROTECTIVE_STOP = 1 << 22  # the robot controller reports a protective stop
    ROBOT_EMERGENCY_STOP = 1 << 23  # the robot controller reports an emergency stop
    STABILITY_DAMPING = (
        1 << 24
    )  # a large hand force turned, an oscillation: the robot is a damper (coassist.control.stability)
    STATE_MISMATCH = 1 << 25  # the joints' forward kinematics left the reported tool pose: one of them is wrong


#: (bit, name) of every single fault flag, built once: fault_names runs every tick.
_FAULT_BITS = tuple((int(f), f.name) for f in Fault if f and f.name)

#: The safety layer's interventions on the commanded motion: scaled or clipped to a limit, ramped down, stopped
MOTION_LIMITED = (
    Fault.JOINT_VELOCITY_LIMIT
    | Fault.JOINT_ACCELERATION_LIMIT
    | Fault.TOOL_SPEED_LIMIT
    | Fault.WORKSPACE_LIMIT
    | Fault.SINGULARITY
    | Fault.DECELERATING
    | Fault.STOPPED
)


def fault_names(value: int) -> list[str]:
    """The names of the flags set in ``value``, lowest bit first (nothing to look up on a clean tick)."""
    value = int(value)
    if not value:
        return []
    return [name for bit, name in _FAULT_BITS if value & bit == bit]


#: Faults after which the robot effort was forced to zero.
ZERO_EFFORT_FAULTS = (
    Fault.NONFINITE_STATE
    | Fault.NONFINITE_REFERENCE
    | Fault.NONFINITE_WRENCH
    | Fault.NONFINITE_EFFORT
    | Fault.INTERNAL_ERROR
    | Fault.INVALID_INPUT
)

#: The per-tick history features, in the thesis' order.
FEATURES = ("x", "y", "vx", "vy", "fx", "fy", "x_ref", "y_ref")
#: What evaluates a model-backed source's network in a simulated loop
#: (``coassist.intent.load_model_intent``): torch eager, ONNX Runtime (the ``onnx`` extra;
#: ``coassist.intent.onnx_network``), or "auto": ONNX Runtime where it is installed, else
#: torch. The two agree to float32 rounding.
NETWORK_BACKENDS = ("auto", "torch", "onnx")


@dataclass(frozen=True, eq=False)
class TrialContext:
    """What an intent source may know at the start of a trial.

    dt : tick [s]. horizon : rows the controller reads (≤ the source's horizon).
    start, target : (2,) [m]. reference : (n, 4) the planner's [x, y, ẋ, ẏ] on the tick
    grid (the nominal plan is public: it is shown on the monitor).
    task : the task kind. user, object : names.
    true_intent : (n, 2) the operator's desired positions — simulation only, for the
    oracle baseline: the episode fills it in only for a source whose ``reads_true_intent`` is
    True (coassist.scenario.reference_intents.OracleIntent); every other source gets None.
    path : (P, 2) the nominal path's polyline [m] in the plan's frame (public, like the
        reference), or None when the world has none.
    obstacles : the boxes the robot is told of, each ((x, y) centre, (width, depth) size) [m] in
        the plan's frame; empty when it is told of none (the person may still see some).
    seed : the trial's seed (TrialMeta.seed), the root of the robot's own random draws in the
        trial (the calibration probe's phases: coassist.control.probe); None: none given. An intent
        source is handed it modulo :data:`TRIAL_SLOTS` only (the tick's reset): enough to choose
        among calibration draws, not the seed the simulation's streams grow from (with it, and
        the user, a review rebuilt the simulated operator's intent bit for bit in a source that
        is told none).
    """

    dt: float
    horizon: int
    start: np.ndarray
    target: np.ndarray
    reference: np.ndarray
    task: str
    user: str
    object: str
    true_intent: np.ndarray | None = None
    path: np.ndarray | None = None
    obstacles: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = ()
    seed: int | None = None


#: An intent source sees the trial's seed modulo this (:class:`TrialContext`): every count of calibration draws up to
#: 8 divides it (lcm 1…8), so seed mod draws is the same either way.
TRIAL_SLOTS = 840


@runtime_checkable
class IntentSource(Protocol):
    """A predictor of the operator's desired positions (module docstring).

    Fallback: if ``predict`` raises, or returns anything other than a finite array of
    shape (≥ controller horizon, 2), the loop uses the nominal reference for that tick
    and sets ``Fault.PREDICTION_FALLBACK``.

    Attributes
    ----------
    history : samples of past features read per call (0: none; ``predict`` then
        receives an empty (0, 8) array).
    horizon : rows returned by ``predict``.
    model_id : id written to TrialMeta.model_id; None means the nominal reference is
        used (dataset D0, thesis eq. 4.7).
    """

    history: int
    horizon: int

    @property
    def model_id(self) -> str | None:  # read-only here, so a source may narrow it (None, or a str)
        ...

    def reset(self, context: TrialContext) -> None:
        """Called once before tick 0 of every trial (clear any carried state here)."""
        ...

    def predict(self, history: np.ndarray) -> np.ndarray:
        """(history, 8) features, oldest first → (horizon, 2) absolute positions [m] for k+1 … k+horizon.

        Called exactly once per tick, in tick order. The array is a read-only view
        valid only during the call: copy it to keep it.
        """
        ...


@dataclass(frozen=True)
class PlausibilityLimits:
    """What a predicted trajectory of the operator's hand may look like.

    max_distance : [m] the farthest any predicted position may lie from the tool's
        current position (the hand leads the tool by centimetres, a 0.4 s forecast at
        the operators' 0.4 m/s adds 0.16 m: 0.5 m leaves room and still catches a
        broken network's metres).
    max_speed : [m/s] the fastest motion between consecutive predicted rows (a hand
        guiding a load stays well under 1.5 m/s; 3 m/s is physically implausible here).
    """

    max_distance: float = 0.5
    max_speed: float = 3.0

    def __post_init__(self) -> None:
        for name in ("max_distance", "max_speed"):
            v = getattr(self, name)
            if not is_real_number(v) or not np.isfinite(v) or v <= 0:
                raise ValueError(f"PlausibilityLimits.{name} must be a finite number > 0, got {v!r}")
            object.__setattr__(self, name, float(v))


def prediction_plausible(
    positions: np.ndarray, pose: np.ndarray, dt: float, limits: PlausibilityLimits = PlausibilityLimits()
) -> bool:
    """True when a prediction may be used: finite, near the tool, and no faster than a hand.

    positions : (H, d) predicted positions for ticks k+1 … k+H [m].
    pose : (d,) the tool's position at tick k [m].  dt : tick [s].

    Plausible ⇔ all finite, max_i ‖p_i − pose‖_∞ ≤ max_distance and
    max_i ‖p_{i+1} − p_i‖_∞ / dt ≤ max_speed.  (The first row is not held to the speed
    bound against the pose: the hand leads the tool, the distance bound covers it.)
    """
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] < 1 or not np.isfinite(p).all():
        return False
    if float(np.max(np.abs(p - np.asarray(pose, dtype=np.float64)[: p.shape[1]]))) > limits.max_distance:
        return False
    if p.shape[0] > 1 and float(np.max(np.abs(np.diff(p, axis=0)))) > limits.max_speed * dt:
        return False
    return True


def missing_members(obj: object, protocol: type) -> list[str]:
    """The members of ``protocol`` (a Protocol class) that ``obj`` lacks (a world, an intent source), for the error that names them."""
    names = set()
    for klass in protocol.__mro__:
        if klass is object or klass is Protocol or klass.__module__ == "typing":
            continue
        names |= {n for n in getattr(klass, "__annotations__", {}) if not n.startswith("_")}
        names |= {n for n, v in vars(klass).items() if callable(v) and not n.startswith("_")}
    return sorted(n for n in names if not hasattr(obj, n))
