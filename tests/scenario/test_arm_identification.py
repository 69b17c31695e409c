"""The person's arm from probe trials (coassist.scenario.arm_identification): a known arm is recovered."""

from dataclasses import replace

import numpy as np
import pytest

from coassist.control.presets import get_preset, make_controller
from coassist.scenario.arm_identification import ASSUMED_ARM, ArmEstimate, identify_arm
from coassist.scenario.objects import get_object
from coassist.scenario.operator import AUTHOR
from coassist.scenario.tasks import task_for_seed
from coassist.sim.trial_runner import run_trial

PRESET = get_preset("thesis-application-damped")
DT = 0.008


def _trials(profile, controller="manual-probe", n=10):
    ctrl = make_controller(controller, PRESET)
    return [
        run_trial(task_for_seed("linear", s, obstacle="large"), profile, get_object("handle"), ctrl, None, s)
        for s in range(n)
    ]


@pytest.mark.parametrize(("scale", "reflex"), [(0.5, 0.0), (2.0, 0.0), (1.0, 0.5)], ids=["soft", "stiff", "reflex"])
def test_a_known_arm_is_recovered(scale, reflex):
    # an arm of fixed stiffness K and damping C (no adaptation), half of K through an 80 ms reflex or none
    K, C = 700.0 * scale, 10.0 * scale
    arm = replace(AUTHOR, stiffness_min=K, stiffness_max=K, stiffness_gain=0.0, damping=C, reflex_share=reflex)
    est = identify_arm(_trials(arm))
    assert est.method == "probe-iv" and est.trials == 10
    # the estimate is informative (its jackknife error a fraction of K) and within three of its errors
    assert est.stiffness_se < 0.15 * K
    assert abs(est.stiffness - K) < 3.0 * est.stiffness_se, (est.stiffness, est.stiffness_se)
    # the effective damping: C less β·K·τ (the reflex) less K times the measurement's lag, which is one
    # tick, two where the 100 Hz sensor's sample is stale
    reflex_term = reflex * K * arm.reaction_delay
    lo, hi = C - reflex_term - 2 * K * DT, C - reflex_term - K * DT
    assert lo - 3 * est.damping_se < est.damping < hi + 3 * est.damping_se, (est.damping, est.damping_se, lo, hi)


def test_without_the_probe_the_arm_is_assumed_not_measured():
    assert identify_arm(_trials(AUTHOR, "manual", n=2)) is ASSUMED_ARM
    assert ASSUMED_ARM.method == "assumed" and ASSUMED_ARM.trials == 0


@pytest.mark.parametrize(
    ("field", "value"), [("stiffness", 50.0), ("stiffness", 1e300), ("damping", -500.0), ("method", "guess")]
)
def test_an_arm_out_of_a_persons_range_is_refused(field, value):
    with pytest.raises(ValueError, match=f"ArmEstimate.{field}"):
        ArmEstimate(**{field: value})
    assert np.isfinite(ArmEstimate().stiffness)


def test_an_arm_measured_in_fewer_than_three_trials_is_not_used():
    """Below three trials there is no jackknife error (it read "± 0" and passed every check: review, 2026-12-06), so
    the measured arm cannot be told from a bad one: the typical arm, and the note says why; three are judged."""
    from coassist.scenario.arm_identification import ARM_SE_MAX, measured_arm

    two = ArmEstimate(735.0, 4.2, 0.0, 0.0, samples=2000, trials=2, method="probe-iv")
    arm, note = measured_arm(two)
    assert arm == ASSUMED_ARM
    assert (
        note
        == "measured K = 735 N/m, C = 4.2 N·s/m from 2 trial(s): its error cannot be told below 3 (record 3 or more probe trials)"
    )
    three = replace(two, trials=3, stiffness_se=0.1 * 735.0, damping_se=1.0)
    assert measured_arm(three) == (three, "")
    wide = replace(three, stiffness_se=(ARM_SE_MAX + 0.01) * 735.0)
    assert measured_arm(wide)[0] == ASSUMED_ARM
