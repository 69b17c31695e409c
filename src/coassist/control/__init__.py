"""Control: prediction matrices, the human-robot games, baselines and the guarded controllers."""

from coassist.control.controllers import (
    ZERO_EFFORT_FAULTS,
    AssistiveController,
    Controller,
    ControlStep,
    Fault,
    ImpedanceControl,
    ManualGuidance,
    saturate,
)
from coassist.control.game import CooperativeGame, EquilibriumGains, NashGame, cooperative_game
from coassist.control.prediction import prediction_matrices

__all__ = [
    "ZERO_EFFORT_FAULTS",
    "AssistiveController",
    "ControlStep",
    "Controller",
    "CooperativeGame",
    "EquilibriumGains",
    "Fault",
    "ImpedanceControl",
    "ManualGuidance",
    "NashGame",
    "cooperative_game",
    "prediction_matrices",
    "saturate",
]
