"""The calibration probe: manual guidance plus a small, known excitation, to measure the person's arm.

Under manual guidance (MG, eq. 5.5) the robot adds nothing: the tool's motion is the plant's
response to the person's force alone, M a + D v = u_h. Where the person *wanted* the tool is
not recorded, and from such data alone the arm's stiffness cannot be told apart from the
intent: any stiffness explains the trial with some intent. The standard remedy in
physical human-robot interaction is a small perturbation the person does not plan for
(e.g. Perreault et al. 2004; Mugge et al. 2007): the tool is pushed a little, the arm pushes
back by −K·Δp − C·Δv, and because the push is known and independent of the person, the
arm's impedance can be read off the force's response (coassist.scenario.arm_identification).

The probe is a zero-mean multisine on each axis::

    r_x(k) = g(t) · a · Σ_j sin(2π f_j^x t + φ_j),    t = k·dt,
    φ_j ~ U[0, 2π) per trial and sine                    (drawn from the trial's seed)
    a   = rms · sqrt(2 / n)                              (so the sum's RMS is ``rms`` [N])

with different frequency sets on x and y (so that neither axis' push correlates with the
other's). The phases are new in every trial: a push with the same time course in every trial
would line up with the person's motion, which also starts with the plan in every trial, and
the two would correlate across the trials as they do within one (measured on a simulated arm
of known stiffness, 4 trials: 6 % too stiff with fixed phases, within the estimate's error with
drawn ones). The frequencies lie above the intent's band (a person's deliberate motion here lies below ~1 Hz) and
below the arm's reflexes' reach. g ramps from 0 to 1 over ``ramp_time`` so that the probe
never steps. :class:`ProbedGuidance` is MG with the probe added: u_r(k) = r(k).

At the default 2.5 N RMS per axis the push moves the tool by about 2 mm at 2 Hz on the
thesis' plant (M = 10 kg, D = 100 N·s/m), which a person barely feels; the logged robot
effort (``Trial.effort_r``) is the probe, which is what the identification reads (a real
arm's log carries it the same way).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from coassist._checks import check_real
from coassist.control.controllers import ControlStep, ManualGuidance
from coassist.interfaces import ZERO_EFFORT_FAULTS, TrialContext
from coassist.model.impedance import ImpedanceModel

__all__ = [
    "PROBE_BLOCK",
    "ProbeParameters",
    "ProbedGuidance",
    "probe_key",
    "probe_phases",
    "probe_signal",
    "probed_efforts",
    "probed_steps",
]


def _frequencies(values: object, name: str) -> tuple[float, ...]:
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        raise ValueError(f"{name} must be a list of frequencies [Hz], got {values!r}")
    freqs = tuple(check_real(f, name, 0.0, 20.0, open_lo=True) for f in values)
    if not freqs or list(freqs) != sorted(set(freqs)) or len(freqs) > 16:
        raise ValueError(f"{name} must be 1 to 16 distinct frequencies in increasing order, got {values!r}")
    return freqs


@dataclass(frozen=True)
class ProbeParameters:
    """The probe's multisine (module docstring).

    rms : [N] the push's RMS per axis (0 … 5 N: enough to measure an arm, never a shove).
    frequencies_x, frequencies_y : [Hz] the sines on each axis, distinct sets, each in (0, 20] Hz.
    ramp_time : [s] the fade-in at the start of a run (0: none).
    """

    rms: float = 2.5
    frequencies_x: tuple[float, ...] = (1.3, 1.9, 2.7, 3.7, 4.9)
    frequencies_y: tuple[float, ...] = (1.5, 2.2, 3.1, 4.3, 5.6)
    ramp_time: float = 0.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "rms", check_real(self.rms, "ProbeParameters.rms", 0.0, 5.0))
        fx = _frequencies(self.frequencies_x, "ProbeParameters.frequencies_x")
        fy = _frequencies(self.frequencies_y, "ProbeParameters.frequencies_y")
        if set(fx) & set(fy):
            raise ValueError(
                f"ProbeParameters: the axes must use distinct frequencies, both have {sorted(set(fx) & set(fy))}"
            )
        object.__setattr__(self, "frequencies_x", fx)
        object.__setattr__(self, "frequencies_y", fy)
        object.__setattr__(self, "ramp_time", check_real(self.ramp_time, "ProbeParameters.ramp_time", 0.0, 10.0))


#: Ticks of the probe :class:`ProbedGuidance` computes in one call (4 s at 125 Hz): one vectorised
#: :func:`probe_signal` instead of ten sines' worth of numpy calls every tick (issue 44: 21 CPU-s of a main job).
PROBE_BLOCK = 512

#: The stream of the trial's seed the phases are drawn from: coassist.scenario.seeds.ROBOT_STREAM
#: (the robot's own draws; tests/control/test_probe.py checks the two agree).
ROBOT_STREAM = 2


def probe_phases(params: ProbeParameters, seed: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The phases [rad] of the x and y sines for the trial of ``seed`` (module docstring); None:
    Schroeder's phases −π j (j − 1)/n (the same in every run: a probe outside any trial)."""
    if seed is None:
        return tuple(  # type: ignore[return-value]
            np.array([-math.pi * j * (j - 1) / len(f) for j in range(1, len(f) + 1)])
            for f in (params.frequencies_x, params.frequencies_y)
        )
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), ROBOT_STREAM]))
    return (
        rng.uniform(0.0, 2.0 * math.pi, len(params.frequencies_x)),
        rng.uniform(0.0, 2.0 * math.pi, len(params.frequencies_y)),
    )


def probe_signal(
    t: ArrayLike, params: ProbeParameters, n_dof: int = 2, phases: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """The probe r(t) [N] at times t [s] (module docstring): shape t.shape + (n_dof,). Axes beyond the
    second get no push (the probe measures the planar arm). ``phases``: :func:`probe_phases`'s (None:
    those of no trial)."""
    t = np.asarray(t, dtype=float)
    out = np.zeros(t.shape + (int(n_dof),))
    ramp = np.clip(t / params.ramp_time, 0.0, 1.0) if params.ramp_time > 0 else np.ones_like(t)
    phases = probe_phases(params, None) if phases is None else phases
    for axis, (freqs, phase) in enumerate(zip((params.frequencies_x, params.frequencies_y)[: int(n_dof)], phases)):
        amp = params.rms * math.sqrt(2.0 / len(freqs))
        total = np.zeros_like(t)
        for f, ph in zip(freqs, phase):
            total += np.sin(2.0 * math.pi * f * t + ph)
        out[..., axis] = amp * ramp * total
    return out


class ProbedGuidance:
    """MG with the calibration probe added (module docstring): u_r(k) = r(k·dt).

    The probe's clock is the number of ``step`` calls since :meth:`reset` (one per control tick).
    A tick MG refuses (a zero-effort fault: bad input) gets no push either.
    """

    name = "manual-probe"

    def __init__(self, model: ImpedanceModel, params: ProbeParameters | None = None) -> None:
        self.params = ProbeParameters() if params is None else params
        if not isinstance(self.params, ProbeParameters):
            raise ValueError(f"params must be ProbeParameters, got {type(self.params).__name__}")
        self.guidance = ManualGuidance(model)
        self.model = model
        self.horizon = self.guidance.horizon
        self.effort_limit = self.guidance.effort_limit
        self.n = int(model.n_dof)
        self.dt = float(model.dt)
        self.reset()

    def reset(self) -> None:
        """Start a run outside any trial: the probe's clock back to 0, the phases of no trial."""
        self.reset_for(None)

    def reset_for(self, context: TrialContext | None) -> None:
        """Start the trial of ``context``: the probe's clock back to 0, its phases from the trial's seed."""
        self._k = 0
        self._phases = probe_phases(self.params, None if context is None else context.seed)
        self._block = np.empty((0, self.n))  # r(k) for ticks _block_start … _block_start + PROBE_BLOCK − 1
        self._block_start = 0

    def _push(self, k: int) -> np.ndarray:
        """r(k·dt) (n,): :func:`probe_signal` of a whole block of ticks at once, the same values as one call per
        tick (each element's arithmetic is elementwise, in the same order), at a fraction of the calls."""
        i = k - self._block_start
        if not 0 <= i < len(self._block):
            self._block_start, i = k, 0
            self._block = probe_signal(np.arange(k, k + PROBE_BLOCK) * self.dt, self.params, self.n, self._phases)
        return self._block[i]

    def step(self, z: ArrayLike, ref_h: ArrayLike, ref_r: ArrayLike, wrench: ArrayLike) -> ControlStep:
        return self._pushed(self.guidance.step(z, ref_h, ref_r, wrench))

    def _pushed(self, out: ControlStep) -> ControlStep:
        """MG's step ``out`` of this tick with this tick's push added (none on a tick MG refused)."""
        k = self._tick()
        if out.fault & ZERO_EFFORT_FAULTS:
            return out
        return ControlStep(out.u_r + self._push(k), out.u_h_model, out.fault)

    def _tick(self) -> int:
        """This tick's number on the probe's clock (steps since the reset); the clock on by one."""
        k = self._k
        self._k += 1
        return k


def probe_key(controller: object) -> tuple | None:
    """What :class:`ProbedGuidance` controllers must share to be stepped together (:func:`probed_steps`): their MG's
    DOFs and input bounds (its law, zero effort, reads nothing else); None for any other controller."""
    if type(controller) is not ProbedGuidance:
        return None
    return (controller.n, controller.guidance.bounds)


def probed_steps(
    controllers: Sequence[ProbedGuidance], z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray
) -> list[ControlStep]:
    """Row b is ``controllers[b].step(z[b], ref_h[b], ref_r[b], wrench[b])`` bit for bit (each its own clock and
    phases), for calibration trials in lockstep (:func:`coassist.runtime.batched_loops.run_loops`): MG's guard once
    over the batch (:meth:`~coassist.control.controllers.ManualGuidance.step_batch` of the first's MG, a row it
    refuses redone by that row's own), then each row's push. The controllers share one :func:`probe_key`.
    z (B, 2n), ref_h and ref_r (B, rows, 2n), wrench (B, n)."""
    mg = [c.guidance for c in controllers]
    steps = mg[0].step_batch(z, ref_h, ref_r, wrench, alone=mg)
    return [c._pushed(s) for c, s in zip(controllers, steps)]


def probed_efforts(
    controllers: Sequence[ProbedGuidance], z: np.ndarray, ref_h: np.ndarray, ref_r: np.ndarray, wrench: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(u_r (B, n), clean (B,) bool) of :func:`probed_steps`' rows as the point-mass array path takes them
    (:meth:`~coassist.control.controllers.ManualGuidance.effort_batch`'s contract): where ``clean[b]``, ``u_r[b]`` is
    ``controllers[b].step(…).u_r`` bit for bit and that step carries no flag, its clock on; elsewhere the row was not
    stepped (its run leaves the array path and is run again)."""
    mg = [c.guidance for c in controllers]
    u, clean = mg[0].effort_batch(z, ref_h, ref_r, wrench, alone=mg)
    for b in np.flatnonzero(clean).tolist():
        c = controllers[b]
        u[b] = u[b] + c._push(c._tick())  # as step: MG's zero effort plus the push (0.0 + r, a −0.0 made +0.0)
    return u, clean
