"""The point-mass world: the thesis' robot as an ideal admittance, its trials' runner, batches.

See docs/architecture.md, *The simulated world*. Entry points: :func:`run_trial` (one trial from built parts),
:class:`TrialSpec` + :func:`run_spec` / :func:`run_trials` (by name, in parallel). The scenario it runs
(tasks, objects, operators, intent sources) is :mod:`coassist.scenario`; the controllers by kind are
:mod:`coassist.control.presets`.
"""

from coassist.sim.point_mass import PointMassWorld
from coassist.sim.trial_runner import TrialSpec, run_spec, run_trial, run_trials

__all__ = ["PointMassWorld", "TrialSpec", "run_spec", "run_trial", "run_trials"]
