"""MuJoCo worlds stepped in one model (coassist.robot.mujoco_world.MujocoArmGroup) against the same worlds alone.

The reference is each world stepping its own model: a grouped world must read, tick for tick, what its twin
alone reads, bit for bit (joints, velocities, the TCP's pose and twist, the sensor's samples and their count,
the TCP Jacobian), with a hand pushing on it, a member left out of a period held without moving the others,
and a joint limit (where MuJoCo's solver would couple the arms) refused; drive_lockstep then runs its drives
again apart and gives the same trials.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")

from coassist.robot import mujoco_world  # noqa: E402
from coassist.robot.drive import DriveConfig, drive, drive_lockstep  # noqa: E402
from coassist.robot.mujoco_world import ConstraintInGroup, MujocoArmGroup, MujocoUR5World  # noqa: E402
from coassist.runtime.world import Command  # noqa: E402


class SwayingHand:
    """A hand whose push follows the handle (so the group's state reaches it): a spring to a point, in x-y."""

    def __init__(self, anchor, stiffness: float) -> None:
        self.anchor = np.asarray(anchor, dtype=float)
        self.k = stiffness

    def force(self, t, pose, twist):
        w = np.zeros(6)
        w[:2] = self.k * (self.anchor - pose[:2]) - 5.0 * twist[:2]
        w[5] = 0.01 * np.sin(3.0 * t)
        return w


def _pair(seed: int, start, hand: bool, tool: str = "board") -> tuple[MujocoUR5World, MujocoUR5World]:
    """Two identical worlds: one to group, one to step alone."""

    def make():
        world = MujocoUR5World(tool, start=start, seed=seed)
        if hand:  # 2-3 cm from where the handle is: a push of a few newtons
            world.operator = SwayingHand(world.hand_pose()[0][:2] + (0.02, -0.015), 200.0)
        return world

    return make(), make()


def _read(world: MujocoUR5World) -> list[np.ndarray]:
    s = world.read()
    return [s.q, s.qd, s.tool_pose, s.tool_twist, s.wrench, s.sensor_rotation, np.array([s.wrench_seq, s.t])]


def _same(a: MujocoUR5World, b: MujocoUR5World) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(_read(a), _read(b))) and np.array_equal(
        a.tcp_jacobian(), b.tcp_jacobian()
    )


def _commands(k: int, i: int) -> np.ndarray:
    t = k * 0.008
    return 0.15 * np.sin(2.0 * np.pi * (0.3 + 0.1 * i) * t + np.arange(6) + i)


STARTS = ((-0.10, -0.615, 0.20), (0.05, -0.55, 0.22), (0.20, -0.60, 0.18))


def test_grouped_worlds_read_what_they_read_alone_tick_for_tick():
    pairs = [_pair(i, start, hand=i != 1) for i, start in enumerate(STARTS)]
    grouped, alone = [p[0] for p in pairs], [p[1] for p in pairs]
    before = [_read(w) for w in grouped]
    group = MujocoArmGroup(grouped)
    assert all(w._group is group for w in grouped)
    # adopted mid-life: what each world reads is what it read before
    assert all(all(np.array_equal(x, y) for x, y in zip(b, _read(w))) for b, w in zip(before, grouped))
    for k in range(150):
        for i, (g, a) in enumerate(zip(grouped, alone)):
            g.apply(Command(qd=_commands(k, i)))
            a.apply(Command(qd=_commands(k, i)))
        group.step()
        assert all(_same(g, a) for g, a in zip(grouped, alone)), k
    # the arms moved, and the hands pushed (the sensor saw it): the comparison was not of arms at rest
    assert min(abs(w.read().q - w.q_start).max() for w in grouped) > 0.01
    assert abs(grouped[0].read().wrench[0] - grouped[1].read().wrench[0]) > 0.5


def test_a_member_left_out_is_held_and_the_others_go_on_as_alone():
    pairs = [_pair(i, start, hand=True) for i, start in enumerate(STARTS)]
    grouped, alone = [p[0] for p in pairs], [p[1] for p in pairs]
    group = MujocoArmGroup(grouped)
    for k in range(120):
        for i, (g, a) in enumerate(zip(grouped, alone)):
            if i == 1 and k >= 40:  # run 1 ended at tick 40: it applies nothing more
                continue
            g.apply(Command(qd=_commands(k, i)))
            a.apply(Command(qd=_commands(k, i)))
        group.step()
        assert _same(grouped[0], alone[0]) and _same(grouped[2], alone[2]), k
    held = grouped[1].read()
    # held: its target zero and its hand let go, so it comes to rest (the servo's lag, a few ticks)
    assert np.abs(held.qd).max() < 1e-3 and not grouped[1]._hand_active


def test_worlds_built_otherwise_form_groups_of_their_own():
    a, b = _pair(0, STARTS[0], hand=False)
    c, d = _pair(1, STARTS[1], hand=False, tool="heavy")
    e = MujocoUR5World("board", seed=3, realtime=True)
    groups = MujocoArmGroup.form([a, c, e, b, d])
    assert sorted(len(g.worlds) for g in groups) == [2, 2] and e._group is None
    assert {w.tool for w in groups[0].worlds} != {w.tool for w in groups[1].worlds}
    with pytest.raises(ValueError, match="two or more fresh worlds built alike"):
        MujocoArmGroup([a, b])  # already grouped
    with pytest.raises(RuntimeError, match="reset on a world stepped in a MujocoArmGroup"):
        a.reset(a.q_start)


def test_a_joint_at_its_limit_is_refused():
    pairs = [_pair(i, start, hand=False) for i, start in enumerate(STARTS[:2])]
    grouped, alone = [p[0] for p in pairs], [p[1] for p in pairs]
    for w in (grouped[0], alone[0]):  # the base joint 0.02 rad inside its upper limit
        q = w.q_start.copy()
        q[0] = w.model.jnt_range[0, 1] - 0.02
        w.reset(q)
    group = MujocoArmGroup(grouped)
    with pytest.raises(ConstraintInGroup, match="constraint rows active"):
        for _ in range(100):
            for g, a in zip(grouped, alone):
                g.apply(Command(qd=np.array([1.0, 0, 0, 0, 0, 0])))
                a.apply(Command(qd=np.array([1.0, 0, 0, 0, 0, 0])))
            group.step()
    assert alone[0].data.nefc > 0  # alone, the arm reached its limit there too


def test_drive_lockstep_runs_its_drives_apart_after_a_constraint(monkeypatch):
    configs = [
        DriveConfig(world="mujoco", controller="cooperative", task=t, seed=s, user=u, intent="oracle", time_limit=0.6)
        for t, s, u in (("linear", 1, 0), ("curved", 2, 1))
    ]
    real_step = MujocoArmGroup.step
    calls = []

    def failing_step(self):
        calls.append(1)
        if len(calls) == 20:
            raise ConstraintInGroup("1 constraint rows active in a group of 2 MuJoCo arms (a joint at its limit)")
        real_step(self)

    monkeypatch.setattr(mujoco_world.MujocoArmGroup, "step", failing_step)
    trials = drive_lockstep(configs)
    assert len(calls) == 20  # the second run had no group
    for config, trial in zip(configs, trials):
        assert trial.equals(drive(config)), config
