"""The control tick (thesis Fig. 4.1), once, for every world.

Every period k the tick turns the world's :class:`~coassist.runtime.world.RobotState`
into a :class:`~coassist.runtime.world.Command`::

    sense ─► wrench pipeline ─► intent ─► controller ─► impedance model ─► twist ─► J⁺ (eq. 3.6) ─► safety ─► command
             (hand wrench)      (ŷ_ref,h)  (u_r, eq. 3.27–3.31)  (eq. 3.1–3.5)

1. **Wrench**: the raw sensor reading → the hand wrench w (6,) in the base frame
   (:mod:`coassist.runtime.wrench`: bias, payload, filter, deadband, stale/spike flags).
2. **Intent**: the feature row (x, y, ẋ, ẏ, f_x, f_y, x_ref, y_ref) goes to the intent
   stage (:mod:`coassist.runtime.intent`), which returns p̂(k+1 … k+H) or falls back
   to the nominal plan (eq. 4.7). The human reference is::

       ref_h[i] = [p̂(k+1+i) − x0,  (p̂(k+1+i) − p̂(k+i)) / dt]      i = 0 … H−1

   (the first row's velocity repeats the second's).
3. **Controller**: u_r = controller.step(z, ref_h, ref_r, w_d) on the d controlled DOFs
   (``TickConfig.dofs``, x-y by default), z = [Δx; v] relative to the start x0.
4. **Impedance model** (arm worlds): the admittance M a + D v = w_d + u_r (eq. 3.1, K = 0)
   is integrated exactly over the period (eq. 3.5) from its own virtual state z_a::

       z_a(k+1) = A_d z_a(k) + B_d (w_d(k) + u_r(k))

   and the controller reads z = z_a (the state its model predicts). The Cartesian twist
   command follows the virtual state and pulls the measured pose onto it::

       ẋ_cmd,i = v_a,i(k+1) + k_p (x0_i + Δx_a,i(k+1) − x_i)          controlled DOFs
       ẋ_cmd,j = k_hold (x0_j − x_j)                                  the other DOFs, held
       ω_cmd   = k_rot · log(R_des R_measᵀ)  (+ ω_a for controlled rotations)

   with orientation errors as rotation vectors, never Euler angles.
5. **Joint velocity** (eq. 3.6): q̇ = J⁺(q) ẋ_cmd with the damped least-squares
   pseudo-inverse of :mod:`coassist.robot.kinematics` (bounded near singularities).
6. **Safety** (:mod:`coassist.runtime.safety`): tool speed and workspace on the twist,
   then joint speed, acceleration, tool speed, workspace and manipulability on q̇;
   faults upstream (a stale or spiking sensor, a stalled predictor, a non-finite
   controller output, a missed deadline) decelerate; too many in a row, a contact force
   over its threshold or a robot stop latch STOPPED. When the layer changed the
   command, the admittance state is reset to what the robot was told to do (so it does
   not wind up and jump when the limit lets go).

``effort`` worlds (the 2-D point-mass world) render the impedance model physically:
steps 4–5 are theirs, the tick sends u_r, and the safety layer's effort stage applies
(``SafetyLayer.limit_effort``: contact force and robot stops latch STOPPED; above the
tool speed the effort may only brake). Every flag raised on the way is OR-ed into the tick's ``fault``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from coassist import spatial as _spatial
from coassist._checks import check_positive_scalar, is_integer
from coassist.interfaces import MOTION_LIMITED, TRIAL_SLOTS, Fault, TrialContext
from coassist.model.impedance import ImpedanceModel
from coassist.runtime.world import COMMAND_SPACES, Command, RobotState, finite_vector

__all__ = [
    "STATE_MISMATCH_ANGLE",
    "STATE_MISMATCH_POSITION",
    "UPSTREAM_BAD",
    "ControlTick",
    "Plan",
    "TickConfig",
    "TickOutput",
    "TickReferences",
    "human_reference",
]

#: Faults of the stages before the safety layer that make a tick "bad" for it.
UPSTREAM_BAD = (
    Fault.NONFINITE_STATE
    | Fault.NONFINITE_WRENCH
    | Fault.NONFINITE_EFFORT
    | Fault.INTERNAL_ERROR
    | Fault.INVALID_INPUT
    | Fault.SENSOR_STALE
    | Fault.SENSOR_SATURATED
    | Fault.WRENCH_SPIKE
    | Fault.PREDICTOR_STALLED
    | Fault.DEADLINE_MISS
    | Fault.STATE_MISMATCH
)
#: [m], [rad] How far the reported tool pose may move from the joints' forward kinematics, against where it was at the
#: run's first tick (in the tool's frame: a TCP offset is constant there), before the tick is STATE_MISMATCH: a joint
#: reading glitched by a finite amount (a second publisher, a wrong message) otherwise drives the arm to correct an
#: error it does not have. The tolerance leaves a real arm's calibration room to move the two apart over a task's few
#: decimetres (not measured on a real arm: no normal run of the simulated worlds flags a tick); 0.3 rad on a UR5's
#: base joint is some 15 cm.
STATE_MISMATCH_POSITION = 0.01
STATE_MISMATCH_ANGLE = 0.05
_MISMATCH_FROB2 = 8.0 * math.sin(STATE_MISMATCH_ANGLE / 2) ** 2  # ‖R₁ − R₂‖²_F of two rotations that far apart
#: The run's first ticks, within which the reference of the STATE_MISMATCH check (the reported pose in the FK's tool
#: frame) is taken again from two ticks that agree with each other where no tick agreed with the first tick's.
_ANCHOR_TICKS = 10


#: [m], [rad], [m/s], [rad/s] A pose or twist entry at or above this is no measurement of a tool (INVALID_INPUT).
_PLAUSIBLE = 1e3


def _plausible(x: np.ndarray) -> bool:
    """Whether every entry of the finite vector ``x`` lies within ±:data:`_PLAUSIBLE`."""
    # on plain floats: for six entries numpy's max and min cost five times the list (the same comparisons)
    entries = x.tolist()
    return max(entries) < _PLAUSIBLE and min(entries) > -_PLAUSIBLE


def _stop_reported(flag: object) -> bool:
    """A robot's stop flag as reported: a flag that is not one truth value (an array, an object whose truth raises)
    reads as a stop, the safe reading (an array raised in the tick and ended the run: a review, 2026-12-07)."""
    if flag is True or flag is False:
        return flag
    try:
        return bool(flag)
    except Exception:  # noqa: BLE001 - whatever it is, it is not "no stop"
        return True


def _offsets_apart(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    """Whether two offsets of the reported pose in the FK's tool frame (R row by row, then p) lie further apart than
    :data:`STATE_MISMATCH_POSITION` / :data:`STATE_MISMATCH_ANGLE`."""
    e = [u - v for u, v in zip(a, b, strict=True)]
    rot2 = sum(v * v for v in e[:9])  # two rotations θ apart differ by 2√2 sin(θ/2) in the Frobenius norm
    pos2 = e[9] * e[9] + e[10] * e[10] + e[11] * e[11]
    return pos2 > STATE_MISMATCH_POSITION**2 or rot2 > _MISMATCH_FROB2


#: Safety interventions after which the admittance state is reset to the command.
_RESET_ADMITTANCE = MOTION_LIMITED
_ROTATION = (3, 4, 5)
_DEADLINE_MISS = int(Fault.DEADLINE_MISS)


def human_reference(positions: np.ndarray, x0: np.ndarray, inv_dt: float, out: np.ndarray) -> None:
    """Write ref_h, the human reference of stage 2 (module docstring), from predicted positions.

    ``out[..., i, :] = [p̂(k+1+i) − x0 on x-y, …, (p̂(k+1+i) − p̂(k+i)) · inv_dt on x-y, …]``
    for i < m, the first row's velocity repeating the second's (0 when m = 1); the
    other DOFs' columns are left as they are.

    One tick or a batch of them alike: positions (..., m, 2) [m], x0 (..., 2) the start [m],
    inv_dt = 1/dt [1/s], out (..., ≥ m, 2d) [m, m/s] with d = out.shape[-1] // 2 (x-y first).
    The tick (:meth:`ControlTick.control_inputs`) and the point-mass array path
    (:mod:`coassist.sim.array_runner`) both build ref_h here, so their rows are equal bit for bit.
    """
    m = positions.shape[-2]
    d = out.shape[-1] // 2
    np.subtract(positions, x0[..., None, :], out=out[..., :m, :2])
    if m >= 2:
        np.subtract(positions[..., 1:, :], positions[..., :-1, :], out=out[..., 1:m, d : d + 2])
        out[..., 1:m, d : d + 2] *= inv_dt
        out[..., 0, d : d + 2] = out[..., 1, d : d + 2]
    else:
        out[..., 0, d : d + 2] = 0.0


#: How far a stage's period may differ from the tick's, relative: float rounding of one period
#: written two ways (1/125 against 0.008), never another rate.
_PERIOD_RTOL = 1e-9


def _check_period(dt: float, stage: Any, field: str, what: str) -> None:
    """Refuse a stage built for another period than the tick's (ValueError naming both).

    The safety layer's acceleration limit is a step of a·dt per call and the wrench pipeline's
    filter and staleness run on dt: a layer built for 32 ms in an 8 ms tick lets the joints
    accelerate 4× the limit, and nothing downstream could tell. A stage without ``dt`` has no
    period of its own to compare."""
    stage_dt = getattr(stage, "dt", None)
    if stage_dt is None:
        return
    try:
        ok = abs(float(stage_dt) - dt) <= _PERIOD_RTOL * dt
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(
            f"{field}.dt ({stage_dt!r} s, {what}'s period) must equal the tick's period, the controller's "
            f"model.dt ({dt!r} s): build {what} for the control period"
        )


@dataclass(frozen=True)
class TickConfig:
    """How the tick maps the admittance to a tool twist (arm worlds).

    dofs : indices of the pose [x, y, z, rx, ry, rz] the controller controls, in order
        (default (0, 1): the thesis' x-y plane). Must match the controller's DOFs.
    position_gain : [1/s] how hard the commanded twist pulls the measured TCP onto the
        admittance's virtual position; 10/s closes a 1 mm lag in about 0.1 s.
    hold_gain : [1/s] the stiff impedance holding the uncontrolled translations at the
        start pose (a 1 cm drift commands 5 cm/s back at 5/s).
    hold_rotation_gain : [1/s] the same for the orientation (rotation-vector error).
    dls_threshold : smallest singular value of J below which the pseudo-inverse is
        damped (eq. 3.6 stays bounded near singularities).
    dls_damping : the largest damping λ, reached at an exact singularity.
    """

    dofs: tuple[int, ...] = (0, 1)
    position_gain: float = 10.0
    hold_gain: float = 5.0
    hold_rotation_gain: float = 5.0
    dls_threshold: float = 0.05
    dls_damping: float = 0.05

    def __post_init__(self) -> None:
        dofs = tuple(self.dofs)
        if not dofs or len(set(dofs)) != len(dofs) or any(not is_integer(i) or not 0 <= i < 6 for i in dofs):
            raise ValueError(f"TickConfig.dofs must be distinct pose indices in 0..5, got {self.dofs!r}")
        if dofs[:2] != (0, 1):
            raise ValueError(
                f"TickConfig.dofs must start with x, y (0, 1): the intent predicts the x-y plane, got {dofs!r}"
            )
        object.__setattr__(self, "dofs", tuple(int(i) for i in dofs))
        for name in ("position_gain", "hold_gain", "hold_rotation_gain", "dls_threshold", "dls_damping"):
            object.__setattr__(self, name, check_positive_scalar(getattr(self, name), f"TickConfig.{name}"))


@dataclass(frozen=True, eq=False)
class Plan:
    """What the motion planner gives the loop for one run.

    reference : (n, 4) the nominal [x, y, ẋ, ẏ] on the tick grid [m, m/s], absolute, with
        at least ``horizon`` rows past the last tick the run may reach.
    start_pose : (6,) the TCP pose the run starts from (x0 of the controller's Δx frame;
        the uncontrolled DOFs are held here).
    """

    reference: np.ndarray
    start_pose: np.ndarray

    def __post_init__(self) -> None:
        ref = np.asarray(self.reference, dtype=float)
        if ref.ndim != 2 or ref.shape[1] != 4 or ref.shape[0] < 2 or not np.isfinite(ref).all():
            raise ValueError(f"Plan.reference must be a finite (n, 4) array with n >= 2, got shape {ref.shape}")
        start = np.asarray(self.start_pose, dtype=float)
        if start.shape != (6,) or not np.isfinite(start).all():
            raise ValueError(f"Plan.start_pose must be 6 finite numbers [m, rad], got {self.start_pose!r}")
        object.__setattr__(self, "reference", ref)
        object.__setattr__(self, "start_pose", start)


class TickOutput(NamedTuple):
    """One tick's command and log row (d = controlled DOFs, H = intent horizon).

    command : what the world is sent.  pose, velocity, wrench : (d,) measured pose and
    twist and the hand wrench used [m, m/s, N] (rotations as the world reports them, |rv| ≤ π;
    ``robot.drive`` makes the trial's columns continuous).  reference : (d,) nominal at k.
    prediction : (H, 2) positions in use (the nominal rows on fallback), or None when
    the source is the nominal plan.  u_r, u_h_model : (d,) [N].  fault : the tick's flags.
    """

    command: Command
    pose: np.ndarray
    velocity: np.ndarray
    wrench: np.ndarray
    reference: np.ndarray
    prediction: np.ndarray | None
    u_r: np.ndarray
    u_h_model: np.ndarray
    fault: Fault


class TickReferences(NamedTuple):
    """The grids a reset tick reads from (n plan rows, d controlled DOFs); read-only views.

    ref_ctrl : (n, 2d) the controller's reference [Δx; v], positions relative to x0 [m, m/s].
    ref_pos : (n, d) the nominal positions, absolute (the log's reference column) [m].
    ref_xy : (n, 2) the plan's x-y positions (the intent's nominal rows) [m].
    x0 : (d,) the start of the controlled DOFs [m, rad].
    """

    ref_ctrl: np.ndarray
    ref_pos: np.ndarray
    ref_xy: np.ndarray
    x0: np.ndarray


class ControlTick:
    """The tick (module docstring) for one controller, intent stage, wrench pipeline and safety layer.

    Parameters
    ----------
    controller : an AssistiveController, ImpedanceControl or ManualGuidance on the d
        controlled DOFs (``name``, ``model``, ``horizon``, ``step``).
    intent : a :class:`~coassist.runtime.intent.TickIntent` (WindowIntent or RealtimeIntent).
    wrench : a :class:`~coassist.runtime.wrench.WrenchPipeline`.
    safety : a :class:`~coassist.runtime.safety.SafetyLayer` (always on), built for the tick's
        period (``safety.dt`` = ``controller.model.dt``, as a wrench pipeline's ``dt``: ValueError
        otherwise, since a layer for a longer period would allow a larger acceleration).
    command_space : the world's, ``"joint_velocity"`` or ``"effort"``.
    kinematics : for joint-velocity worlds: ``forward_and_jacobian(q) -> (p, R, J)``
        (:class:`coassist.robot.kinematics.UR5Kinematics`).
    config : :class:`TickConfig`.
    """

    def __init__(
        self,
        controller: Any,
        intent: Any,
        wrench: Any,
        safety: Any,
        *,
        command_space: str,
        kinematics: Any = None,
        config: TickConfig | None = None,
    ) -> None:
        if command_space not in COMMAND_SPACES:
            raise ValueError(f"command_space must be one of {COMMAND_SPACES}, got {command_space!r}")
        self.config = config or TickConfig()
        model: ImpedanceModel = controller.model
        d = model.n_dof
        if d != len(self.config.dofs):
            raise ValueError(f"the controller has {d} DOFs but TickConfig.dofs names {len(self.config.dofs)}")
        if command_space == "joint_velocity" and kinematics is None:
            raise ValueError("a joint-velocity world needs kinematics (the Jacobian of eq. 3.6)")
        if int(intent.horizon) < int(controller.horizon):
            raise ValueError(f"intent horizon ({intent.horizon}) must be >= the controller's ({controller.horizon})")
        _check_period(float(model.dt), safety, "safety", "the safety layer")
        _check_period(float(model.dt), wrench, "wrench", "the wrench pipeline")
        self.controller, self.intent, self.wrench, self.safety = controller, intent, wrench, safety
        self.kinematics, self.command_space = kinematics, command_space
        # a redundant arm (n > 6) resolves eq. 3.6 itself (null-space posture, joint limits)
        self._redundant = getattr(kinematics, "redundant_joint_velocity", None)
        self.model, self.d, self.dt = model, d, float(model.dt)
        self._dofs = np.array(self.config.dofs)
        self._rot = [i for i in self.config.dofs if i in _ROTATION]
        self._ctrl_trans = [j for j, i in enumerate(self.config.dofs) if i < 3]
        self._ctrl_rot = [j for j, i in enumerate(self.config.dofs) if i >= 3]
        cfg = self.config
        self._rot_gain = np.array(
            [cfg.position_gain if i in self.config.dofs else cfg.hold_rotation_gain for i in _ROTATION]
        )
        self._Ad, self._Bd = np.ascontiguousarray(model.Ad), np.ascontiguousarray(model.Bd)
        self._tw = np.zeros(6)
        self.H = int(controller.horizon)
        self.Hs = int(intent.horizon)
        self._ref_h_buf = np.zeros((self.Hs, 2 * d))
        self._ref_h_view = self._ref_h_buf[: self.H]
        self._z = np.zeros(2 * d)
        self._decided: tuple[Fault, np.ndarray | None] | None = None  # control_inputs()'s flags and prediction

    # ------------------------------------------------------------------ per run
    def reset(self, plan: Plan, context: TrialContext, state: RobotState | None = None) -> None:
        """Start a run: the plan's grids, the intent, a zero admittance state, the safety layer, and
        the controller when it keeps state between ticks (an online-α arbitration).

        The safety layer's acceleration ramp starts from rest (q̇⁻ = 0), whatever ``state`` says: a
        velocity read before the run (before a person confirmed the limits, say) may be stale, and one
        read wrong would seed commands of a motion the arm is not making; braking from a motion is the
        direction a wrong start errs safely in. (Seeding it from a measured q̇ was tried and removed in
        review: an arm read coasting, then at rest by tick 0, was driven to 0.18 rad/s.)"""
        if not isinstance(plan, Plan):
            raise ValueError(f"plan must be a Plan, got {type(plan).__name__}")
        d = self.d
        start = plan.start_pose
        self._start = start.copy()
        self._x0 = start[self._dofs].copy()
        n = plan.reference.shape[0]
        ref_abs = np.zeros((n, 2 * d))  # the controller's reference [positions; velocities], absolute
        ref_abs[:, :d] = start[self._dofs]
        ref_abs[:, 0:2] = plan.reference[:, 0:2]
        ref_abs[:, d : d + 2] = plan.reference[:, 2:4]
        self._ref_pos = ref_abs[:, :d]  # the Trial's reference column
        self._ref_xy = plan.reference[:, 0:2]
        ref_ctrl = ref_abs.copy()
        ref_ctrl[:, :d] -= self._x0
        self._ref_ctrl = ref_ctrl
        # a controller with draws of its own (the calibration probe) is reset with the trial's context
        reset_for = getattr(self.controller, "reset_for", None)
        controller_reset = getattr(self.controller, "reset", None)
        if callable(reset_for):
            reset_for(context)
        elif callable(controller_reset):
            controller_reset()
        # the source sees the seed modulo TRIAL_SLOTS (TrialContext): the controller's draws grow from the whole seed
        seed = context.seed
        self.intent.reset(context if seed is None else replace(context, seed=int(seed) % TRIAL_SLOTS))
        self.wrench.reset()
        self.safety.reset()
        self._za = np.zeros(2 * d)
        self._R_start = _spatial.rotation_matrix(start[3:6])
        self._J = None
        self._inv_dt = 1.0 / self.dt
        self._last_pose = np.array(
            start, dtype=np.float64
        )  # held over a glitch of the state (step()); a buffer of its own
        self._last_twist = np.zeros(6)
        self._pose_read: np.ndarray | None = None  # this tick's measured pose, finite and plausible (sense())
        self._fk_offset: tuple[float, ...] | None = None  # the reported pose in the FK's tool frame (R row by row, p)
        self._fk_last: tuple[float, ...] | None = None  # that offset at the last tick
        self._fk_ticks = 0  # ticks compared so far
        self._fk_confirmed = False  # whether a later tick agreed with the reference

    def references(self) -> TickReferences:
        """This run's grids (:class:`TickReferences`), for a runner that does the tick's
        arithmetic for many runs at once (:mod:`coassist.sim.array_runner`)."""
        views = []
        for a in (self._ref_ctrl, self._ref_pos, self._ref_xy, self._x0):
            view = a.view()
            view.setflags(write=False)
            views.append(view)
        return TickReferences(*views)

    # ------------------------------------------------------------------ per tick
    def step(self, k: int, state: RobotState, upstream: Fault = Fault.NONE) -> TickOutput:
        """Tick k: the command for this period and the log row (module docstring)."""
        row = self.sense(k, state, upstream)
        return self.decide(None if row is None else self.predict(k, row))

    # step() in three parts, so a runner can batch the intent's network call over many
    # trials between sense() and decide() (coassist.runtime.batched_loops); step() is their
    # composition, so the per-trial and the batched loops run the same code.
    def sense(self, k: int, state: RobotState, upstream: Fault = Fault.NONE) -> tuple[float, ...] | None:
        """Stage 1 and the intent's feature row of tick k (8 floats, FEATURES order), or None
        when the intent is the nominal plan (nothing to predict). Then call :meth:`decide`."""
        dofs = self._dofs
        fault = upstream if type(upstream) is Fault else Fault(upstream)
        # 1. the hand wrench
        reading = self.wrench.update(state.wrench, state.sensor_rotation, state.wrench_seq, state.t)
        hand = reading.hand
        if reading.fault:  # (IntFlag arithmetic costs a microsecond; most ticks have no flag)
            fault |= reading.fault
        # a glitch (NaN, ±inf, None, a wrong shape) is flagged and the last good value held,
        # so the intent, the controller and the log never see it (the safety layer decelerates)
        pose = finite_vector(state.tool_pose, 6)
        twist = finite_vector(state.tool_twist, 6)
        # the measured pose as the arm stage reads it (finite and plausible; its twist is not its concern): read once
        self._pose_read = pose if pose is not None and _plausible(pose) else None
        if (pose is not None and self._pose_read is None) or (twist is not None and not _plausible(twist)):
            # finite but no measurement (1e200 in the pose's rotation overflowed its angle, and the tick raised)
            fault |= Fault.INVALID_INPUT
            pose = twist = None
        state_bad = pose is None or twist is None
        if pose is None:
            pose = self._last_pose
        else:
            np.copyto(self._last_pose, pose)  # held in the tick's own buffer: no per-tick allocation
        if twist is None:
            twist = self._last_twist
        else:
            np.copyto(self._last_twist, twist)
        if state_bad:
            fault |= Fault.NONFINITE_STATE
        x = pose[dofs]
        v = twist[dofs]
        w = hand[dofs]
        self._pending = (k, state, x, v, w, hand, fault, state_bad)
        self._decided = None  # control_inputs() of this tick has not run yet
        if self.intent.nominal:
            return None
        ref_pos = self._ref_pos
        return (x[0], x[1], v[0], v[1], w[0], w[1], ref_pos[k, 0], ref_pos[k, 1])

    def predict(self, k: int, row: tuple[float, ...]) -> tuple[np.ndarray | None, Fault]:
        """The intent stage's answer for tick k's feature row: (positions (≥H, 2) or None, flags)."""
        return self.intent.update(k, row, self._ref_xy[k + 1 : k + 1 + self.Hs])

    def decide(self, intent: tuple[np.ndarray | None, Fault] | None) -> TickOutput:
        """Stages 2–6 of the tick :meth:`sense` began, given the intent's (positions or None,
        flags) for its row (None for the nominal intent)."""
        return self.finish(self.controller.step(*self.control_inputs(intent)))

    # decide() in two parts around the controller, so a runner can serve many trials that
    # share one controller in one call (controller.step_batch, coassist.runtime.batched_loops).
    def control_inputs(self, intent: tuple[np.ndarray | None, Fault] | None) -> tuple[np.ndarray, ...]:
        """Stage 2 of the tick :meth:`sense` began: the controller's arguments (z (2d,), ref_h
        and ref_r (H, 2d), w (d,)) for the intent's answer; views of the tick's buffers, valid
        until its next tick. Then :meth:`finish` with the controller's step for them."""
        k, state, x, v, w, hand, fault, state_bad = self._pending
        d = self.d
        # 2. intent
        ref_r = self._ref_ctrl[k + 1 : k + 1 + self.H]
        prediction = None
        if intent is None:
            ref_h = ref_r  # eq. 4.7: the plan's own rows; nothing to predict
        else:
            pred, pf = intent
            if pf:
                fault |= pf
            if pred is not None:
                human_reference(pred, self._x0[:2], self._inv_dt, self._ref_h_buf)
                ref_h = self._ref_h_view
                prediction = pred
            else:
                ref_h = ref_r
                prediction = self._ref_xy[k + 1 : k + 1 + self.Hs]
        # 3. controller, on the measured state (effort worlds) or the admittance's (arm worlds)
        z = self._z
        if self.command_space == "effort":
            np.subtract(x, self._x0, out=z[:d])
            z[d:] = v
        else:
            z[:] = self._za
        self._decided = (fault, prediction)
        return z, ref_h, ref_r, w

    def finish(self, control: tuple[np.ndarray, np.ndarray, Fault]) -> TickOutput:
        """Stages 3–6 of the tick: the controller's (u_r, u_h_model, flags) for the arguments
        :meth:`control_inputs` gave → the command and the log row."""
        k, state, x, v, w, hand, _, state_bad = self._pending
        if self._decided is None:
            raise RuntimeError(f"ControlTick.finish() of tick {k} before its control_inputs()")
        fault, prediction = self._decided
        d = self.d
        u_r, u_h_model, cf = control
        if cf:
            fault |= cf
        if state_bad:  # as the controller does on a non-finite state: no effort from a held one
            u_r = np.zeros(d)
        elif not np.isfinite(u_r).all():  # a controller's NaN: no effort, a bad tick, never in the admittance or log
            u_r = np.zeros(d)
            fault |= Fault.NONFINITE_EFFORT
        if self.command_space == "effort":
            effort, sf, stop = self.safety.limit_effort(u_r, v, hand, fault, self._robot_stop(state))
            command = Command(effort=effort, stop=stop)
        else:
            command, sf = self._arm(state, u_r, w, hand, fault)
        if sf:
            fault |= sf
        return TickOutput(command, x, v, w, self._ref_pos[k], prediction, u_r, u_h_model, fault)

    # ------------------------------------------------------------------ stages
    def _robot_stop(self, state: RobotState) -> Fault:
        f = Fault.NONE
        if _stop_reported(state.protective_stop):
            f |= Fault.ROBOT_PROTECTIVE_STOP
        if _stop_reported(state.emergency_stop):
            f |= Fault.ROBOT_EMERGENCY_STOP
        return f

    def _arm(self, state: RobotState, u_r, w, hand, upstream: Fault) -> tuple[Command, Fault]:
        cfg, d, dofs = self.config, self.d, self.config.dofs
        f = Fault.NONE
        q = finite_vector(state.q, self.kinematics.n_joints)
        J = self._J
        R_meas = p_meas = None
        if finite_vector(state.qd, self.kinematics.n_joints) is None:  # (read after a stall: the layer's ramp start)
            f |= Fault.NONFINITE_STATE
        if q is not None:
            try:
                p_meas, R_meas, J = self.kinematics.forward_and_jacobian(q)
                self._J = J
            except Exception:
                f |= Fault.INTERNAL_ERROR
        else:
            f |= Fault.NONFINITE_STATE
        pose = self._pose_read  # as sense() read it (an implausible one flagged there, INVALID_INPUT)
        pose_ok = pose is not None
        if pose is None:
            pose = np.full(6, np.nan)  # the safety layer treats the tick as bad (decelerates)
        elif R_meas is not None and self._moved_apart(p_meas, R_meas, pose):
            f |= Fault.STATE_MISMATCH
        bad = (upstream | f) & UPSTREAM_BAD
        qd = np.zeros(self.kinematics.n_joints)
        sf = Fault.NONE
        if R_meas is not None and not bad and pose_ok:
            # 4. the admittance over one period (eq. 3.5), driven by the hand and the robot's effort
            za = self._Ad @ self._za + self._Bd @ (w + u_r)
            self._za = za
            start = self._start
            tw = self._tw
            # translations (from the kinematics, the same model as J): follow the admittance, hold the rest
            tw[0:3] = cfg.hold_gain * (start[0:3] - p_meas)
            for j in self._ctrl_trans:
                tw[dofs[j]] = za[d + j] + cfg.position_gain * (start[dofs[j]] + za[j] - p_meas[dofs[j]])
            # rotations: the error as a rotation vector, never Euler angles
            if self._rot:
                dr = np.zeros(3)
                for j in self._ctrl_rot:
                    dr[dofs[j] - 3] = za[j]
                R_des = _spatial.rotation_matrix(dr) @ self._R_start
            else:
                R_des = self._R_start
            tw[3:6] = self._rot_gain * _spatial.rotation_vector_unchecked(R_des @ R_meas.T)
            for j in self._ctrl_rot:
                tw[dofs[j]] += za[d + j]
            tw, sf = self.safety.limit_twist(tw, pose)
            # 5. eq. 3.6 with the damped least-squares pseudo-inverse
            if self._redundant is None:
                qd, _ = _spatial.dls_joint_velocity(J, tw, cfg.dls_threshold, cfg.dls_damping)
            else:
                qd = self._redundant(q, J, tw)
        Jc = J if J is not None else np.zeros((6, self.kinematics.n_joints))
        # after a stall the layer ramps from what the arm measures (it may have braked on its own)
        measured = state.qd if int(upstream) & _DEADLINE_MISS else None
        qd, lf, stop = self.safety.limit_joint_velocity(
            qd, Jc, pose, hand, upstream | f, self._robot_stop(state), measured=measured
        )
        sf |= lf | f
        twist_cmd = Jc @ qd
        if (sf & _RESET_ADMITTANCE) or bad:
            # bumpless: the admittance continues from what the robot was told to do
            x_meas = pose[self._dofs] if pose_ok else self._x0 + self._za[:d]
            self._za[:d] = x_meas - self._x0
            self._za[d:] = twist_cmd[self._dofs]
            if self._rot and R_meas is not None:  # rotations: the measured orientation's Δ from the start
                dr = _spatial.rotation_vector_unchecked(R_meas @ self._R_start.T)
                for j in self._ctrl_rot:
                    self._za[j] = dr[dofs[j] - 3]
        return Command(qd=qd, twist=twist_cmd, stop=stop), sf

    def _moved_apart(self, p_fk: np.ndarray, R_fk: np.ndarray, pose: np.ndarray) -> bool:
        """Whether the reported tool ``pose`` and the forward kinematics (``p_fk``, ``R_fk``) of the measured joints
        have moved apart by more than :data:`STATE_MISMATCH_POSITION` / :data:`STATE_MISMATCH_ANGLE` since the run's
        first tick (the offset of the reported pose in the FK's tool frame, held from then)."""
        # in Python floats: some 30 small numpy calls otherwise, 15 µs a tick
        x, y, z, a, b, c = pose.tolist()
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R_fk.tolist()
        px, py, pz = p_fk.tolist()
        (s00, s01, s02), (s10, s11, s12), (s20, s21, s22) = _spatial.rotation_matrix_of(a, b, c).tolist()
        dx, dy, dz = x - px, y - py, z - pz
        offset = (  # R_fkᵀ R_rep, row by row, then R_fkᵀ (p_rep − p_fk)
            r00 * s00 + r10 * s10 + r20 * s20,
            r00 * s01 + r10 * s11 + r20 * s21,
            r00 * s02 + r10 * s12 + r20 * s22,
            r01 * s00 + r11 * s10 + r21 * s20,
            r01 * s01 + r11 * s11 + r21 * s21,
            r01 * s02 + r11 * s12 + r21 * s22,
            r02 * s00 + r12 * s10 + r22 * s20,
            r02 * s01 + r12 * s11 + r22 * s21,
            r02 * s02 + r12 * s12 + r22 * s22,
            r00 * dx + r10 * dy + r20 * dz,
            r01 * dx + r11 * dy + r21 * dz,
            r02 * dx + r12 * dy + r22 * dz,
        )
        last, self._fk_last = self._fk_last, offset
        self._fk_ticks += 1
        if self._fk_offset is None:
            self._fk_offset = offset
            return False
        # Against the first tick's offset; and, until a tick has confirmed that reference (agreeing with it and with
        # the tick before), against the last tick's too: on a sound arm the offset does not move, so a jump between
        # two ticks means one of them is wrong. The first tick alone is no proof: one wrong joint reading there made
        # every correct tick after it the mismatch, and readings wrong every other tick passed unflagged while the
        # correct ones were flagged (the arm moved on its own, 39 mm in 2 s: a review, 2026-12-07). Now such a
        # flip-flop flags every tick (the safety layer stops the arm), and where the first tick's offset was the odd
        # one out, two ticks that agree with each other replace it.
        moved = _offsets_apart(offset, self._fk_offset)
        jumped = last is not None and _offsets_apart(offset, last)
        if not moved and not jumped:
            self._fk_confirmed = True
        elif moved and not jumped and not self._fk_confirmed and self._fk_ticks <= _ANCHOR_TICKS:
            self._fk_offset, self._fk_confirmed = offset, True
            return False
        return moved or (jumped and not self._fk_confirmed)
