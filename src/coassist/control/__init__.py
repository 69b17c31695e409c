"""Control: prediction matrices, the human-robot games, baselines and the guarded controllers."""

from coassist.config import GameWeights
from coassist.control.controllers import (
    AssistiveController,
    Controller,
    ControlStep,
    ImpedanceControl,
    InputBounds,
    ManualGuidance,
    saturate,
)
from coassist.control.game import CooperativeGame, EquilibriumGains, NashGame, cooperative_game
from coassist.control.prediction import prediction_matrices
from coassist.interfaces import ZERO_EFFORT_FAULTS, Fault  # the flags live below control; re-exported

__all__ = [
    "ZERO_EFFORT_FAULTS",
    "AssistiveController",
    "ControlStep",
    "Controller",
    "CooperativeGame",
    "EquilibriumGains",
    "Fault",
    "GameWeights",
    "ImpedanceControl",
    "InputBounds",
    "ManualGuidance",
    "NashGame",
    "cooperative_game",
    "prediction_matrices",
    "saturate",
]
