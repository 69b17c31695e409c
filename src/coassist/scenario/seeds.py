"""The seed scheme of every trial: one integer seed, two independent streams.

A trial's seed s gives (numpy ``SeedSequence``; streams never overlap)::

    SeedSequence([s, 0])            the task: where the obstacle sits (:func:`task_rng`)
    SeedSequence([s, 1]).spawn(n)   the trial: the operator's intent, motor noise, the
                                    sensor (:func:`trial_rngs`, children in that order)
    SeedSequence([s, 2])            the robot's own draws: the calibration probe's phases
                                    (:func:`robot_rng`; coassist.control.probe draws them
                                    below this layer, from TrialContext.seed)

so the same seed draws the same task in every world (point mass, MuJoCo, the real arm,
the page), and the trial's own draws do not move the task. Spawned children are fixed by
their index: ``trial_rngs(s, 2)`` are the first two of ``trial_rngs(s, 3)``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ROBOT_STREAM", "robot_rng", "task_rng", "trial_rngs"]

#: The stream of the robot's own draws (module docstring).
ROBOT_STREAM = 2


def task_rng(seed: int) -> np.random.Generator:
    """The generator of the task of seed ``seed`` (its obstacle's place)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), 0]))


def trial_rngs(seed: int, n: int) -> tuple[np.random.Generator, ...]:
    """``n`` generators of the trial of seed ``seed``: intent, motor noise, sensor, in that order."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), 1]).spawn(int(n)))


def robot_rng(seed: int) -> np.random.Generator:
    """The generator of the robot's own draws in the trial of seed ``seed`` (the probe's phases)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), ROBOT_STREAM]))
