"""The controllers by kind, built from a control preset: the one controller vocabulary of every world.

A *control preset* (:data:`coassist.config.CONTROL_PRESETS`: impedance M, D at the control
period dt, the game's weights and horizon, the effort limit) and a *controller kind* give
one controller on the preset's free plant M a + D v = u (K = 0):

============================  ==========  ==============================================
kind                          short name  controller
============================  ==========  ==============================================
``cooperative``               assistive   the cooperative game (eq. 3.27–3.31)
``cooperative-arbitrated``    assistive-  the same with α set every tick by
                              arbitrated  :data:`ARBITRATION`
``impedance``                 imp         impedance control toward the plan (eq. 5.4)
``manual``                    mg          manual guidance, u_r = 0 (eq. 5.5)
============================  ==========  ==============================================

The kind is what a simulated batch names (``TrialSpec.controller``, ``coassist collect
--controller``); the short name is the thesis' label that ``coassist drive`` and ``coassist
play`` (and its page) offer a person. :func:`controller_kind` maps either to the kind, so
every world builds its controller through :func:`make_controller` from the same table.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from coassist.config import CONTROL_PRESETS, ControlPreset
from coassist.control.arbitration import ArbitratedController, ArbitrationParameters
from coassist.control.controllers import AssistiveController, ImpedanceControl, ManualGuidance
from coassist.control.game import cooperative_game
from coassist.model.impedance import ImpedanceModel
from coassist.registry import UnknownNameError

__all__ = [
    "ARBITRATION", "CONTROLLER_KINDS", "CONTROLLER_NAMES", "IMPEDANCE_STIFFNESS", "controller_kind", "get_preset",
    "make_controller", "plant_model",
]  # fmt: skip

#: Controller kinds. "cooperative-arbitrated": the cooperative game with α set every tick
#: by the law :data:`ARBITRATION`.
CONTROLLER_KINDS = ("cooperative", "impedance", "manual", "cooperative-arbitrated")
#: The short names a person picks from (``coassist drive`` / ``play``, the page) → the kind.
CONTROLLER_NAMES: Mapping[str, str] = MappingProxyType(
    {"assistive": "cooperative", "assistive-arbitrated": "cooperative-arbitrated", "imp": "impedance", "mg": "manual"}
)
#: The arbitration law of "cooperative-arbitrated": α from the distance to where the robot's
#: plan ends (coassist.control.arbitration, law "target"). Chosen on validation seeds of the
#: application scenario (docs/assistance.md), against the hand-force law.
ARBITRATION = ArbitrationParameters(law="target", alpha_min=0.3, alpha_max=0.9, target_scale=0.05)
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


def controller_kind(name: str) -> str:
    """The kind of a controller named by its kind or its short name (:data:`CONTROLLER_NAMES`)."""
    if name in CONTROLLER_KINDS:
        return name
    if isinstance(name, str) and name in CONTROLLER_NAMES:
        return CONTROLLER_NAMES[name]
    raise ValueError(f"controller must be one of {CONTROLLER_KINDS} or {tuple(CONTROLLER_NAMES)}, got {name!r}")


def plant_model(preset: ControlPreset) -> ImpedanceModel:
    """The free plant M a + D v = u (K = 0) of a preset."""
    imp = preset.impedance
    return ImpedanceModel(np.diag(imp.M), np.diag(imp.D), np.zeros((imp.n_dof, imp.n_dof)), imp.dt)


def make_controller(kind: str, preset: ControlPreset):
    """A controller of ``kind`` (a kind or short name, :func:`controller_kind`) built from ``preset``."""
    kind = controller_kind(kind)
    model = plant_model(preset)
    if kind == "cooperative":
        return AssistiveController(cooperative_game(model, preset.game), effort_limit=preset.effort_limit)
    if kind == "cooperative-arbitrated":
        assistive = AssistiveController(cooperative_game(model, preset.game), effort_limit=preset.effort_limit)
        return ArbitratedController(assistive, ARBITRATION)
    if kind == "impedance":
        return ImpedanceControl(model, IMPEDANCE_STIFFNESS * np.eye(model.n_dof), effort_limit=preset.effort_limit)
    return ManualGuidance(model)
