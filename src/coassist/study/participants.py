"""Simulated participants: the simulated operator population standing in for people (``--simulate``).

Participant number p is simulated by operator p of the plan's population (``study.population``,
default "thesis", where operator 0 is the thesis' author, so a study's participants are the new
users 1, 2, …; :func:`coassist.scenario.populations.population_profile`, population seed = the
plan's seed).
In a trial of seed s the operator wants what it wants in every world: its intent
(:func:`~coassist.scenario.operator.intent_trajectory`) and motor noise come from
:func:`coassist.scenario.seeds.trial_rngs` of s, the task from s as everywhere.

- On the page's world the operator's arm (eq. 4.1 with delay, adaptation and noise,
  :class:`~coassist.scenario.operator.OperatorArm`) is the hand (:class:`OperatorHand`);
  in a browser, Playwright moves the pointer along the same intent (:func:`hand_path`).
- On the MuJoCo UR5 it is ``coassist drive``'s own simulated operator.

The answers to the questionnaires are a rehearsal, not data: :func:`simulated_answers`
turns what the operator felt in the condition's trials (the mean hand force relative to its
force limit, f̄ = f_RMS / F_max ∈ [0, 1]) into ratings, plus seeded noise (σ = 8 TLX points,
0.5 Likert points)::

    TLX physical, effort = 100 f̄ + 10;  mental, temporal, frustration = 30 + 60 f̄;
    performance = 100 · min(1, σ_target / 0.02 m);  Likert = 1 + (points − 1)(1 − f̄)

so a condition that makes the operator push less is rated better, and the report's
questionnaire section has something to show before anyone is invited.
"""

from __future__ import annotations

import math

import numpy as np

from coassist.scenario.operator import OperatorArm, OperatorProfile, intent_trajectory, motor_noise
from coassist.scenario.populations import population_profile
from coassist.scenario.seeds import trial_rngs
from coassist.scenario.tasks import Task
from coassist.study.questionnaires import Form

__all__ = ["OperatorHand", "hand_path", "simulated_answers", "simulated_profile"]


def simulated_profile(number: int, population_seed: int, population: str = "thesis") -> OperatorProfile:
    """The simulated operator standing in for participant ``number`` (1, 2, …): user ``number`` of
    ``population`` (:func:`~coassist.scenario.populations.population_profile`)."""
    return population_profile(population, int(number), int(population_seed))


class OperatorHand:
    """The page world's hand (``force_xy``) driven by the simulated operator's arm, one call per period.

    task, seed : the trial's.  profile : the operator.  dt : the control period [s].  n : ticks to plan for.
    """

    def __init__(self, task: Task, seed: int, profile: OperatorProfile, dt: float, n: int) -> None:
        rng_intent, rng_motor = trial_rngs(seed, 2)
        self.intent = intent_trajectory(task, profile, rng_intent, n, dt)
        noise = motor_noise(profile, rng_motor, n, dt)
        self._arm = OperatorArm(profile, self.intent.positions, dt, noise)
        self.k = 0
        self.seq = -1
        self.held = True

    def force_xy(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """u_h(k) [N] (eq. 4.1), k the number of calls so far."""
        fx, fy = self._arm.force(self.k, x, y, vx, vy)
        self.k += 1
        return fx, fy

    def set_pointer(self, x: float, y: float, down: bool, seq: int) -> None:
        """A page's pointer is ignored: the simulated operator is the hand."""

    def release(self) -> None:
        pass


def hand_path(task: Task, seed: int, profile: OperatorProfile, dt: float, n: int) -> np.ndarray:
    """(n, 2) the simulated operator's intended hand positions [m] at t = k·dt: the path a browser's
    pointer follows for it (the spring-damper of the page then pulls the tool along)."""
    rng_intent, _ = trial_rngs(seed, 2)
    return intent_trajectory(task, profile, rng_intent, n, dt).positions


def simulated_answers(
    form: Form, f_rms: float, sigma: float | None, profile: OperatorProfile, rng: np.random.Generator
) -> list[int]:
    """The simulated operator's answers to ``form`` after a condition (module docstring): ``f_rms`` [N] the
    mean of its measured trials' f_RMS, ``sigma`` [m] their mean σ (None: never reached the target)."""
    fbar = min(1.0, max(0.0, f_rms / profile.force_limit))
    perf = 1.0 if sigma is None or not math.isfinite(sigma) else min(1.0, sigma / 0.02)
    tlx = {
        "mental": 30 + 60 * fbar,
        "temporal": 30 + 60 * fbar,
        "frustration": 30 + 60 * fbar,
        "physical": 100 * fbar + 10,
        "effort": 100 * fbar + 10,
        "performance": 100 * perf,
    }
    out = []
    for item in form.items:
        if item.scale == "tlx":
            mean, sd = tlx[item.key.removeprefix("tlx_")], 8.0
        else:
            mean, sd = item.lo + (item.hi - item.lo) * (1.0 - fbar), 0.5
        v = mean + sd * float(rng.standard_normal())
        v = item.lo + item.step * round((v - item.lo) / item.step)
        out.append(int(min(item.hi, max(item.lo, v))))
    return out
