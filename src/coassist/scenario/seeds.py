"""The seed scheme of every trial: one integer seed, two independent streams.

A trial's seed s gives (numpy ``SeedSequence``; streams never overlap)::

    SeedSequence([s, 0])            the task: where the obstacle sits (:func:`task_rng`)
    SeedSequence([s, 1]).spawn(n)   the trial: the operator's intent, motor noise, the
                                    sensor (:func:`trial_rngs`, children in that order)

so the same seed draws the same task in every world (point mass, MuJoCo, the real arm,
the page), and the trial's own draws do not move the task. Spawned children are fixed by
their index: ``trial_rngs(s, 2)`` are the first two of ``trial_rngs(s, 3)``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["task_rng", "trial_rngs"]


def task_rng(seed: int) -> np.random.Generator:
    """The generator of the task of seed ``seed`` (its obstacle's place)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), 0]))


def trial_rngs(seed: int, n: int) -> tuple[np.random.Generator, ...]:
    """``n`` generators of the trial of seed ``seed``: intent, motor noise, sensor, in that order."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), 1]).spawn(int(n)))
