"""The main job's seed plan: which trial seeds each collection of ``coassist reproduce`` uses.

A dataset of n trials collected with seed s uses the trial seeds s … s+n−1
(coassist.sim.collect). Each collection of the pipeline starts at the run's trial-seed base
(run seed × RUN_SEED_STRIDE: seed 0's is 0) plus its own offset; the offsets are far enough
apart that no two collections share a trial seed for any preset, and every offset is below
the stride, so runs with different seeds share none either (tests/experiments/test_reproduce.py
checks the thesis preset's sizes and three seeds).
"""

from __future__ import annotations

from coassist.scenario.populations import HELD_OUT

#: The trial seeds of run seed k are k·RUN_SEED_STRIDE … (k + 1)·RUN_SEED_STRIDE − 1.
RUN_SEED_STRIDE = 1_000_000


def trial_seed_base(seed: int) -> int:
    """The first trial seed of run seed ``seed`` (its collections' offsets are added to it)."""
    return int(seed) * RUN_SEED_STRIDE


#: D_k (iterative training, k = 0 … iterations): seed + ITERATION_SEED_STEP·(k+1).
ITERATION_SEED_STEP = 100_000
#: Transfer target i's training trials: seed + TRANSFER_SEED_OFFSET + TRANSFER_SEED_STEP·i;
#: its held-out test trials TRANSFER_TEST_SEED_OFFSET further on.
# (600_000: D_4 of a four-iteration run starts at 500_000, where the targets started before.)
TRANSFER_SEED_OFFSET, TRANSFER_SEED_STEP, TRANSFER_TEST_SEED_OFFSET = 600_000, 20_000, 10_000
#: The heavy load's own transfer dataset (application stage).
HEAVY_TRANSFER_SEED_OFFSET = 800_000
#: The application operators' calibration trials (the path-hypotheses source's person shapes).
CALIBRATION_SEED_OFFSET = 880_000
#: Application trials of object j: seed + APPLICATION_SEED_OFFSET + APPLICATION_SEED_STEP·j
#: (every controller meets the same trials: the same seeds).
APPLICATION_SEED_OFFSET, APPLICATION_SEED_STEP = 900_000, 1000


def iteration_seed(base: int, k: int) -> int:
    """First trial seed of D_k; ``base``: the run's :func:`trial_seed_base` (or any base)."""
    return base + ITERATION_SEED_STEP * (k + 1)


def transfer_seeds(base: int, i: int) -> tuple[int, int]:
    """First trial seeds of transfer target i's training and test datasets (``base``: as :func:`iteration_seed`'s)."""
    train = base + TRANSFER_SEED_OFFSET + TRANSFER_SEED_STEP * i
    return train, train + TRANSFER_TEST_SEED_OFFSET


def heavy_transfer_seed(base: int) -> int:
    """First trial seed of the heavy load's transfer dataset (``base``: as :func:`iteration_seed`'s)."""
    return base + HEAVY_TRANSFER_SEED_OFFSET


#: The held-out population's calibration and application trials have seeds of their own: on the thesis cells' seeds,
#: its trials were ones seen while the person model's lead check, its sign test and its filter's lock guard were
#: chosen (docs/person-model.md, *What the held-out cells were told*). Past the validation bases' trials (50000 and
#: 60000: calibrations from 930 000, application trials up to 961 999) and inside a run's block.
HELD_OUT_CALIBRATION_SEED_OFFSET = 975_000
HELD_OUT_APPLICATION_SEED_OFFSET = 985_000


def calibration_seed(base: int, population: str = "thesis") -> int:
    """First trial seed of ``population``'s application operators' calibration trials (``base``: as
    :func:`iteration_seed`'s; the held-out population's its own, :data:`HELD_OUT_CALIBRATION_SEED_OFFSET`)."""
    return base + (HELD_OUT_CALIBRATION_SEED_OFFSET if population == HELD_OUT else CALIBRATION_SEED_OFFSET)


def application_seed(base: int, j: int, population: str = "thesis") -> int:
    """First trial seed of ``population``'s application trials with object j (``base``: as :func:`iteration_seed`'s;
    the validation trials of docs/precision.md are bases 50000 and 60000, which no run seed's collections use; the
    held-out population's its own, :data:`HELD_OUT_APPLICATION_SEED_OFFSET`)."""
    offset = HELD_OUT_APPLICATION_SEED_OFFSET if population == HELD_OUT else APPLICATION_SEED_OFFSET
    return base + offset + APPLICATION_SEED_STEP * j
