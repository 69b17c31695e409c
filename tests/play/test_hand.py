"""The browser hand: the spring-damper law, its force limit, and letting go."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coassist.play.hand import BrowserHand, SpringDamper
from coassist.runtime.world import HandOperator


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_spring_damper_is_hookes_law_minus_damping():
    arm = SpringDamper(stiffness=300.0, damping=20.0, force_limit=1e3)
    # hand-computed: 300·(0.05 − 0.01) − 20·0.1 = 10.0; 300·(−0.02 − 0) − 20·(−0.05) = −5.0
    assert arm.force((0.05, -0.02), 0.01, 0.0, 0.1, -0.05) == pytest.approx((10.0, -5.0), abs=1e-12)


def test_force_limit_scales_the_norm_and_keeps_the_direction():
    arm = SpringDamper(stiffness=400.0, damping=0.0, force_limit=40.0)
    fx, fy = arm.force((0.3, 0.4), 0.0, 0.0, 0.0, 0.0)  # unlimited: (120, 160), norm 200
    assert math.hypot(fx, fy) == pytest.approx(40.0)
    assert (fx, fy) == pytest.approx((24.0, 32.0))


@pytest.mark.parametrize(
    "field, value", [("stiffness", 0.0), ("damping", -1.0), ("force_limit", math.nan), ("stale_after", math.inf)]
)
def test_bad_arm_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"SpringDamper.{field}"):
        SpringDamper(**{field: value})


def test_hand_pulls_only_while_held_and_fresh_and_lets_go_on_release():
    clock = FakeClock()
    hand = BrowserHand(SpringDamper(stiffness=400.0, damping=40.0, stale_after=0.25), clock=clock)
    assert isinstance(hand, HandOperator)
    assert hand.force_xy(0.0, 0.0, 0.0, 0.0) == (0.0, 0.0)  # nothing received yet
    hand.set_pointer(0.02, 0.0, True, seq=7)
    assert hand.force_xy(0.0, 0.0, 0.0, 0.0) == pytest.approx((8.0, 0.0))
    assert hand.seq == 7 and hand.held
    w = hand.force(0.0, np.array([0.0, 0.0, 0.2, 0.0, 0.0, 0.0]), np.zeros(6))
    assert w.shape == (6,) and w[0] == pytest.approx(8.0) and np.all(w[2:] == 0.0)
    clock.t += 0.2  # still fresh
    assert hand.force_xy(0.0, 0.0, 0.0, 0.0)[0] == pytest.approx(8.0)
    clock.t += 0.1  # 0.3 s of silence: a hung tab lets go, the last force is not frozen
    assert hand.force_xy(0.0, 0.0, 0.0, 0.0) == (0.0, 0.0) and not hand.held
    hand.set_pointer(0.02, 0.0, True, seq=8)  # a heartbeat grabs again
    assert hand.force_xy(0.0, 0.0, 0.0, 0.0)[0] == pytest.approx(8.0)
    hand.release()  # the link closed
    assert hand.force_xy(0.0, 0.0, 0.0, 0.0) == (0.0, 0.0)
    hand.set_pointer(0.02, 0.0, False, seq=9)  # button up
    assert hand.force_xy(0.0, 0.0, 0.0, 0.0) == (0.0, 0.0)
