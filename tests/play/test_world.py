"""The play world: the admittance plant against its closed form, the sensor, and the pacing."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from coassist.control.presets import get_preset, plant_model
from coassist.play.world import PlayWorld
from coassist.runtime.world import Command, World


class ConstantHand:
    def __init__(self, fx: float, fy: float) -> None:
        self.f = (fx, fy)

    def force_xy(self, x, y, vx, vy):
        return self.f


def test_constant_force_follows_the_closed_form_of_m_a_plus_d_v():
    # M a + D v = F from rest: v(t) = F/D (1 − e^{−t D/M}), x(t) = x0 + F/D (t − M/D (1 − e^{−t D/M}))
    model = plant_model(get_preset("thesis-application-dm"))
    M, D = float(model.M[0, 0]), float(model.D[0, 0])
    world = PlayWorld(model, ConstantHand(6.0, -3.0), (0.1, -0.5), paced=False)
    assert isinstance(world, World) and world.command_space == "effort"
    n = 250
    for _ in range(n):
        world.apply(Command(effort=np.array([2.0, 0.0])))
    t = n * world.dt
    e = math.exp(-t * D / M)
    for F, x0, x, v in ((8.0, 0.1, world.x, world.vx), (-3.0, -0.5, world.y, world.vy)):
        assert v == pytest.approx(F / D * (1 - e), rel=1e-9)
        assert x == pytest.approx(x0 + F / D * (t - M / D * (1 - e)), rel=1e-9, abs=1e-12)
    assert world.fh == (6.0, -3.0)


def test_the_sensor_reads_last_periods_hand_force_and_a_stop_holds():
    model = plant_model(get_preset("thesis-application-dm"))
    hand = ConstantHand(5.0, 0.0)
    world = PlayWorld(model, hand, (0.0, 0.0), paced=False)
    s0 = world.read()
    assert np.all(s0.wrench == 0.0)
    world.apply(Command(effort=np.zeros(2)))
    s1 = world.read()
    assert s1.wrench[0] == 5.0 and s1.wrench_seq == s0.wrench_seq + 1 and s1.t == pytest.approx(world.dt)
    world.apply(Command(effort=np.array([math.nan, 0.0])))  # garbage effort is never integrated
    assert math.isfinite(world.x)
    x = world.x
    world.apply(Command(effort=np.zeros(2), stop=True))
    world.apply(Command(effort=np.array([50.0, 0.0])))
    assert world.x == x and world.vx == 0.0


def test_pacing_holds_the_period_and_reports_overruns():
    model = plant_model(get_preset("thesis-application-dm"))
    world = PlayWorld(model, ConstantHand(0.0, 0.0), (0.0, 0.0))
    # the schedule starts at read(): timed from before it, so a slow moment between the two (CI under load:
    # 2.4 ms) is inside the measured span instead of shortening it below the 50 periods
    t0 = time.perf_counter()
    world.read()
    for _ in range(50):
        world.apply(Command(effort=np.zeros(2)))
    elapsed = time.perf_counter() - t0
    # 0.4 s of wall clock, not as fast as it can (deadlines are absolute: a late wake-up does not add up)
    assert 50 * world.dt - 0.002 <= elapsed <= 50 * world.dt + 0.05

    clock = [0.0]
    slept = []
    world = PlayWorld(model, ConstantHand(0.0, 0.0), (0.0, 0.0), clock=lambda: clock[0], sleep=slept.append)
    world.read()  # the schedule starts at t = 0
    clock[0] = 0.003
    world.apply(Command(effort=np.zeros(2)))
    assert world.last_overrun == 0.0 and slept[-1] == pytest.approx(0.005)
    clock[0] = 0.020  # period 2 ends 4 ms after its deadline (0.016)
    world.apply(Command(effort=np.zeros(2)))
    assert world.last_overrun == pytest.approx(0.004) and world.overruns == 1 and len(slept) == 1
    clock[0] = 0.040  # 16 ms late (> one period): the schedule re-anchors instead of racing
    world.apply(Command(effort=np.zeros(2)))
    assert world.overruns == 2
    clock[0] = 0.041
    world.apply(Command(effort=np.zeros(2)))
    assert world.last_overrun == 0.0 and slept[-1] == pytest.approx(0.007)


def test_the_play_world_integrates_the_simulators_plant_step():
    """The play world steps the one point-mass plant (coassist.model.plant): its state after a
    period is plant_step of the hand's and the robot's force, bit for bit; a model with a
    spring (K != 0) is refused, since the plant is free."""
    from coassist.model.impedance import ImpedanceModel
    from coassist.model.plant import PointMassPlant, plant_step

    model = plant_model(get_preset("thesis-application-dm"))
    world = PlayWorld(model, ConstantHand(6.0, -3.0), (0.1, -0.5), paced=False)
    plant = PointMassPlant.free(model)
    assert world.plant == plant
    x, y, vx, vy = 0.1, -0.5, 0.0, 0.0
    for k in range(50):
        effort = np.array([2.0 * np.sin(0.1 * k), -1.0])
        world.apply(Command(effort=effort))
        x, vx = plant_step(x, vx, 6.0 + float(effort[0]), plant.a_xv[0], plant.a_vv[0], plant.b_x[0], plant.b_v[0])
        y, vy = plant_step(y, vy, -3.0 + float(effort[1]), plant.a_xv[1], plant.a_vv[1], plant.b_x[1], plant.b_v[1])
        assert (world.x, world.y, world.vx, world.vy) == (x, y, vx, vy)
    spring = ImpedanceModel(model.M, model.D, np.eye(2) * 100.0, model.dt)
    with pytest.raises(ValueError, match="K != 0"):
        PlayWorld(spring, ConstantHand(0.0, 0.0), (0.0, 0.0), paced=False)
