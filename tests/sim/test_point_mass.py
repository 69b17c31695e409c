"""The point-mass world's array twin: PointMassWorldBatch row for row against each PointMassWorld."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.runtime.world import Command
from coassist.sim.point_mass import PointMassWorld, PointMassWorldBatch
from coassist.sim.trial_runner import TrialSpec, spec_episode


def _worlds(specs: list[TrialSpec]) -> list[PointMassWorld]:
    return [spec_episode(spec).world for spec in specs]


def test_the_batch_advances_each_world_bit_for_bit():
    """Handle, board (yaw, off-centre grasp) and heavy object, three operators: under the same
    efforts, every period's pose, velocity, sensor reading and sample counter and the hand force
    equal each world's own apply bit for bit, while runs leave the batch."""
    specs = [
        TrialSpec(task=task, user=user, object=obj, seed=seed)
        for seed, (task, user, obj) in enumerate(
            [
                ("linear", 0, "handle"),
                ("curved", 1, "board"),
                ("sinusoidal", 2, "heavy"),
                ("z", 0, "board"),
                ("linear", 3, "handle"),
            ]
        )
    ]
    worlds = _worlds(specs)
    batch = PointMassWorldBatch(_worlds(specs))  # the same worlds, built again: the batch's own copies
    assert batch.dt == worlds[0].dt
    rng = np.random.default_rng(2)
    rows = np.arange(len(worlds))
    for k in range(400):
        if k == 250:
            rows = rows[[0, 1, 3]]  # two runs ended
        effort = rng.normal(0.0, 8.0, (rows.size, 2))
        fh = batch.apply(k, rows, effort)
        for j, i in enumerate(rows.tolist()):
            w = worlds[i]
            w.apply(Command(effort=effort[j]))
            state = w.read()
            assert fh[j].tolist() == list(w.hand_force()), (k, i)
            assert batch.position[i].tolist() == [w.x, w.y] and batch.velocity[i].tolist() == [w.vx, w.vy], (k, i)
            assert batch.wrench[i].tolist() == state.wrench[:2].tolist(), (k, i)
            assert batch.wrench_seq[i] == state.wrench_seq
    assert worlds[1]._th != 0.0  # the board yawed: its branch was exercised
    assert batch.wrench_seq[rows].min() > 300  # the 100 Hz sensor sampled at its own ticks (320 in 400 periods)


def test_only_fresh_point_mass_worlds_join_a_batch():
    world = _worlds([TrialSpec(task="linear", seed=0)])[0]
    assert PointMassWorldBatch.accepts(world)
    world.apply(Command(effort=np.zeros(2)))
    assert not PointMassWorldBatch.accepts(world)  # past tick 0
    with pytest.raises(ValueError, match="tick 0"):
        PointMassWorldBatch([world])
    stopped = _worlds([TrialSpec(task="linear", seed=1)])[0]
    stopped.stop()
    assert stopped.stopped and not PointMassWorldBatch.accepts(stopped)
    assert not PointMassWorldBatch.accepts(object())


def test_a_batchs_worlds_share_one_kind_of_arm_with_an_array_twin():
    from coassist.sim.person_twin import TwinArm, TwinArmBatch

    operator, twin, plain = _worlds([TrialSpec(task="linear", seed=s) for s in (0, 1, 2)])
    twin.arm = TwinArm(np.zeros((3, 2)), 500.0, 5.0)  # type: ignore[assignment]
    assert PointMassWorldBatch.accepts(twin)
    assert isinstance(PointMassWorldBatch([twin]).arms, TwinArmBatch)
    with pytest.raises(ValueError, match="one kind of arm, got OperatorArm, TwinArm"):
        PointMassWorldBatch([operator, twin])
    plain.arm = object()  # type: ignore[assignment]  # an arm with no array twin: the reference path's alone
    assert not PointMassWorldBatch.accepts(plain)
