"""The controllers by kind, built from a control preset: the one controller vocabulary of every world.

A *control preset* (:data:`coassist.config.CONTROL_PRESETS`: impedance M, D at the control
period dt, the game's weights and horizon, the effort limit) and a *controller kind* give
one controller on the preset's free plant M a + D v = u (K = 0):

==========================  ==============================================================
kind                        controller (the thesis' name)
==========================  ==============================================================
``cooperative``             the assistive controller: the cooperative game (eq. 3.27–3.31)
``cooperative-arbitrated``  the same with α set every tick by :data:`ARBITRATION`
``cooperative-damped``      ``cooperative-arbitrated`` plus damping while the tool slows down
                            (:data:`DECELERATION_DAMPING`, :mod:`coassist.control.deceleration_damping`)
``impedance``               IMP, impedance control toward the plan (eq. 5.4)
``manual``                  MG, manual guidance, u_r = 0 (eq. 5.5)
``manual-probe``            MG plus the calibration probe, a small known push that measures the
                            person's arm (:data:`PROBE`, :mod:`coassist.control.probe`)
==========================  ==============================================================

Each kind is one entry of :data:`CONTROLLERS` (the function that builds it from the plant and
the preset, and a summary); a new kind is one function and one line there, and
:func:`make_controller` and every consumer of the kinds read the registry.

Every world and command names its controller by kind: a simulated batch
(``TrialSpec.controller``, ``coassist collect``), ``coassist drive`` / ``ros2``
(``DriveConfig.controller``) and ``coassist play`` and its page (``PlayConfig.controllers``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from coassist.config import CONTROL_PRESETS, ControlPreset
from coassist.control.arbitration import ArbitratedController, ArbitrationParameters
from coassist.control.controllers import AssistiveController, ImpedanceControl, ManualGuidance
from coassist.control.deceleration_damping import DampingParameters, DecelerationDamping
from coassist.control.game import cooperative_game
from coassist.control.probe import ProbedGuidance, ProbeParameters
from coassist.model.impedance import ImpedanceModel
from coassist.registry import Registry, UnknownNameError

__all__ = [
    "ARBITRATION",
    "CONTROLLERS",
    "CONTROLLER_KINDS",
    "ControllerEntry",
    "DECELERATION_DAMPING",
    "FORMER_NAMES",
    "IMPEDANCE_STIFFNESS",
    "INTENT_FREE_CONTROLLERS",
    "PROBE",
    "get_preset",
    "make_controller",
    "plant_model",
]

#: The names drive and play used before they took the kinds (old session files, muscle memory):
#: read in play's recorded sessions, and named in the command line's error for an old name.
FORMER_NAMES = {
    "assistive": "cooperative",
    "assistive-arbitrated": "cooperative-arbitrated",
    "imp": "impedance",
    "mg": "manual",
}
#: The arbitration law of "cooperative-arbitrated": α from the distance to where the robot's
#: plan ends (coassist.control.arbitration, law "target"). Chosen on validation seeds of the
#: application scenario (docs/assistance.md), against the hand-force law.
ARBITRATION = ArbitrationParameters(law="target", alpha_min=0.3, alpha_max=0.9, target_scale=0.05)
#: The extra damping of "cooperative-damped": 40 N·s/m at full gate (40 % of the plant's 100), the gate
#: fully open at 0.3 m/s² of deceleration (docs/precision.md: the lever's force and jerk cost).
DECELERATION_DAMPING = DampingParameters(gain=40.0, decel_ref=0.3, accel_time=0.02)
#: The probe of "manual-probe": 2.5 N RMS per axis at 1.3–5.6 Hz (coassist.control.probe), what
#: coassist.scenario.arm_identification reads the person's arm from.
PROBE = ProbeParameters()
#: Spring of the IMP baseline toward the nominal reference [N/m] (eq. 5.4). The thesis
#: does not give it (its K_i = 0 would make IMP equal MG); 200 N/m pulls back with
#: 10 N at a 5 cm deviation, about what the operators push with.
IMPEDANCE_STIFFNESS = 200.0


def get_preset(name: str) -> ControlPreset:
    """The control preset ``name``; ``ValueError`` "preset '<name>': no such control preset; did you mean …"."""
    try:
        return CONTROL_PRESETS.lookup(name)
    except UnknownNameError as exc:
        raise ValueError(f"preset {exc}") from None


def plant_model(preset: ControlPreset) -> ImpedanceModel:
    """The free plant M a + D v = u (K = 0) of a preset."""
    imp = preset.impedance
    return ImpedanceModel(np.diag(imp.M), np.diag(imp.D), np.zeros((imp.n_dof, imp.n_dof)), imp.dt)


@dataclass(frozen=True)
class ControllerEntry:
    """One controller kind of :data:`CONTROLLERS`.

    build : ``build(model, preset)`` → the controller, on the preset's free plant ``model``
        (:func:`plant_model`: M a + D v = u) with the preset's game, effort limit and rate.
    summary : what it is, a phrase (the thesis' name where it has one).
    """

    build: Callable[[ImpedanceModel, ControlPreset], Any]
    summary: str

    def __post_init__(self) -> None:
        if not callable(self.build):
            raise ValueError(
                f"ControllerEntry.build must be callable (model, preset) -> controller, got {self.build!r}"
            )
        if not isinstance(self.summary, str) or not self.summary:
            raise ValueError(f"ControllerEntry.summary must be a non-empty string, got {self.summary!r}")


def _cooperative(model: ImpedanceModel, preset: ControlPreset) -> AssistiveController:
    return AssistiveController(cooperative_game(model, preset.game), effort_limit=preset.effort_limit)


def _cooperative_arbitrated(model: ImpedanceModel, preset: ControlPreset) -> ArbitratedController:
    return ArbitratedController(_cooperative(model, preset), ARBITRATION)


def _cooperative_damped(model: ImpedanceModel, preset: ControlPreset) -> DecelerationDamping:
    return DecelerationDamping(_cooperative_arbitrated(model, preset), DECELERATION_DAMPING)


def _impedance(model: ImpedanceModel, preset: ControlPreset) -> ImpedanceControl:
    return ImpedanceControl(model, IMPEDANCE_STIFFNESS * np.eye(model.n_dof), effort_limit=preset.effort_limit)


def _manual(model: ImpedanceModel, preset: ControlPreset) -> ManualGuidance:
    return ManualGuidance(model)


def _manual_probe(model: ImpedanceModel, preset: ControlPreset) -> ProbedGuidance:
    return ProbedGuidance(model, PROBE)


#: The controller kinds (module docstring), in the order the help lists them; what
#: :func:`make_controller` builds and every world's controller option accepts.
CONTROLLERS: Registry[ControllerEntry] = Registry(
    "controller",
    {
        "cooperative": ControllerEntry(_cooperative, "the assistive controller: the cooperative game"),
        "impedance": ControllerEntry(_impedance, "IMP, impedance control toward the plan"),
        "manual": ControllerEntry(_manual, "MG, manual guidance"),
        "cooperative-arbitrated": ControllerEntry(
            _cooperative_arbitrated, "the cooperative game with α set every tick by the target law"
        ),
        "cooperative-damped": ControllerEntry(
            _cooperative_damped, "the arbitrated cooperative game, damped while the tool slows"
        ),
        "manual-probe": ControllerEntry(_manual_probe, "MG plus the calibration probe"),
    },
    entry_type=ControllerEntry,
)
#: Controllers that never read the intent (MG and its probe apply no effort toward any reference, IMP pulls toward
#: the nominal plan x_ref,r only): the person moves the same whatever the source; its rows are logged (and scored as
#: e_RMS) only. A controller registered later is taken to read it.
INTENT_FREE_CONTROLLERS = frozenset({"manual", "impedance", "manual-probe"})
#: The built-in kinds' names (a kind registered later is in :data:`CONTROLLERS`, not here).
#: "cooperative-arbitrated": the cooperative game with α set every tick by the law :data:`ARBITRATION`.
CONTROLLER_KINDS: tuple[str, ...] = tuple(CONTROLLERS)


def make_controller(kind: str, preset: ControlPreset):
    """A controller of ``kind`` (one of :data:`CONTROLLERS`) built from ``preset``."""
    model = plant_model(preset)
    if kind not in CONTROLLERS:
        raise ValueError(f"controller must be one of {tuple(CONTROLLERS)}, got {kind!r}")
    controller = CONTROLLERS[kind].build(model, preset)
    if not CONTROLLERS.is_declared(kind) and getattr(controller, "name", kind) != kind:
        # a registered kind's trials record (TrialMeta.controller) the kind its user named, not the class it builds
        # on: one built on ImpedanceControl read as IMP in every manifest
        controller.name = kind
    return controller
