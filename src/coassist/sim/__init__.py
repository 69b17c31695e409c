"""The simulated world: tasks and objects, the simulated operator, the closed loop, batches.

See docs/architecture.md, *The simulated world*. Entry points: :func:`run_trial` (one trial from built parts),
:class:`TrialSpec` + :func:`run_spec` / :func:`run_trials` (by name, in parallel).
"""

from coassist.interfaces import FEATURES, IntentSource, TrialContext
from coassist.sim.intent_source import NominalIntent, OracleIntent, load_intent_source
from coassist.sim.objects import OBJECTS, CarriedObject, ForceSensor, get_object
from coassist.sim.operator import (
    AUTHOR,
    Intent,
    OperatorArm,
    OperatorProfile,
    intent_trajectory,
    operator_profile,
)
from coassist.sim.tasks import TASK_KINDS, Box, MotionPlanner, NominalPath, Task, make_task, nominal_path
from coassist.sim.world import (
    CONTROLLER_KINDS,
    PRESETS,
    TrialSpec,
    get_preset,
    make_controller,
    run_spec,
    run_trial,
    run_trials,
)

__all__ = [
    "AUTHOR",
    "CONTROLLER_KINDS",
    "FEATURES",
    "OBJECTS",
    "PRESETS",
    "TASK_KINDS",
    "Box",
    "CarriedObject",
    "ForceSensor",
    "Intent",
    "IntentSource",
    "MotionPlanner",
    "NominalIntent",
    "NominalPath",
    "OperatorArm",
    "OperatorProfile",
    "OracleIntent",
    "Task",
    "TrialContext",
    "TrialSpec",
    "get_object",
    "get_preset",
    "intent_trajectory",
    "load_intent_source",
    "make_controller",
    "make_task",
    "nominal_path",
    "operator_profile",
    "run_spec",
    "run_trial",
    "run_trials",
]
