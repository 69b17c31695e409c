"""The scenario every world runs: tasks and their plans, carried objects and the force sensor,
simulated operators (and their hand on an arm), intent sources, and the seed scheme.

See docs/architecture.md, *The scenario*. The point-mass world (:mod:`coassist.sim`), the arm
worlds (:mod:`coassist.robot`) and the page (:mod:`coassist.play`) all draw their trials from here.
"""

from coassist.scenario.constant_velocity import ConstantVelocityIntent
from coassist.scenario.intent_registry import INTENT_SOURCES, load_intent_source
from coassist.scenario.objects import OBJECTS, CarriedObject, ForceSensor, get_object
from coassist.scenario.operator import (
    AUTHOR,
    Intent,
    OperatorArm,
    OperatorProfile,
    intent_trajectory,
    operator_profile,
)
from coassist.scenario.populations import POPULATIONS, population_profile
from coassist.scenario.reference_intents import NominalIntent, OracleIntent
from coassist.scenario.seeds import task_rng, trial_rngs
from coassist.scenario.tasks import (
    OBSTACLES,
    TASK_KINDS,
    Box,
    MotionPlanner,
    NominalPath,
    Task,
    make_task,
    nominal_path,
    task_for_seed,
)

__all__ = [
    "AUTHOR",
    "INTENT_SOURCES",
    "OBJECTS",
    "OBSTACLES",
    "POPULATIONS",
    "TASK_KINDS",
    "Box",
    "CarriedObject",
    "ConstantVelocityIntent",
    "ForceSensor",
    "Intent",
    "MotionPlanner",
    "NominalIntent",
    "NominalPath",
    "OperatorArm",
    "OperatorProfile",
    "OracleIntent",
    "Task",
    "get_object",
    "intent_trajectory",
    "load_intent_source",
    "make_task",
    "nominal_path",
    "operator_profile",
    "population_profile",
    "task_for_seed",
    "task_rng",
    "trial_rngs",
]
