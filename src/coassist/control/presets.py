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

Every world and command names its controller by kind: a simulated batch
(``TrialSpec.controller``, ``coassist collect``), ``coassist drive`` / ``ros2``
(``DriveConfig.controller``) and ``coassist play`` and its page (``PlayConfig.controllers``).
"""

from __future__ import annotations

import numpy as np

from coassist.config import CONTROL_PRESETS, ControlPreset
from coassist.control.arbitration import ArbitratedController, ArbitrationParameters
from coassist.control.controllers import AssistiveController, ImpedanceControl, ManualGuidance
from coassist.control.deceleration_damping import DampingParameters, DecelerationDamping
from coassist.control.game import cooperative_game
from coassist.control.probe import ProbedGuidance, ProbeParameters
from coassist.model.impedance import ImpedanceModel
from coassist.registry import UnknownNameError

__all__ = [
    "ARBITRATION",
    "CONTROLLER_KINDS",
    "DECELERATION_DAMPING",
    "FORMER_NAMES",
    "IMPEDANCE_STIFFNESS",
    "PROBE",
    "get_preset",
    "make_controller",
    "plant_model",
]

#: Controller kinds. "cooperative-arbitrated": the cooperative game with α set every tick
#: by the law :data:`ARBITRATION`.
CONTROLLER_KINDS = (
    "cooperative",
    "impedance",
    "manual",
    "cooperative-arbitrated",
    "cooperative-damped",
    "manual-probe",
)
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


def make_controller(kind: str, preset: ControlPreset):
    """A controller of ``kind`` (one of :data:`CONTROLLER_KINDS`) built from ``preset``."""
    model = plant_model(preset)
    if kind == "cooperative":
        return AssistiveController(cooperative_game(model, preset.game), effort_limit=preset.effort_limit)
    if kind == "cooperative-arbitrated":
        assistive = AssistiveController(cooperative_game(model, preset.game), effort_limit=preset.effort_limit)
        return ArbitratedController(assistive, ARBITRATION)
    if kind == "cooperative-damped":
        assistive = AssistiveController(cooperative_game(model, preset.game), effort_limit=preset.effort_limit)
        return DecelerationDamping(ArbitratedController(assistive, ARBITRATION), DECELERATION_DAMPING)
    if kind == "impedance":
        return ImpedanceControl(model, IMPEDANCE_STIFFNESS * np.eye(model.n_dof), effort_limit=preset.effort_limit)
    if kind == "manual":
        return ManualGuidance(model)
    if kind == "manual-probe":
        return ProbedGuidance(model, PROBE)
    raise ValueError(f"controller must be one of {CONTROLLER_KINDS}, got {kind!r}")
