"""Named populations of simulated operators: who stands in for the people (issue 40).

A population is chosen by name beside its seed (``TrialSpec.population`` /
``population_seed``, ``coassist collect --population``, a study's simulated participants,
``coassist drive``'s simulated operator); :func:`population_profile` gives user i's profile.

- ``thesis``: :func:`coassist.scenario.operator.operator_profile`, unchanged: user 0 the
  thesis' author, users ≥ 1 drawn around them; every detour the symmetric bump. Every stage of
  the main job runs it.
- ``varied``: the in-family population to tune on. Families of the *shape* kind
  (:mod:`coassist.scenario.detours`: one smooth stroke out and one back, the progress one
  re-plan): :class:`~coassist.scenario.detours.Asymmetric`,
  :class:`~coassist.scenario.detours.Skewed`, :class:`~coassist.scenario.detours.Swing`.
- ``held-out``: families of another kind, kept out of everything tuned and used only to
  report: :class:`~coassist.scenario.detours.Corrective` (sub-movements in the path and the
  progress) and :class:`~coassist.scenario.detours.Hesitant` (the progress pauses at the
  onset). No family is in two populations (tests/scenario/test_populations.py).
- ``unseen``: families of a third kind, made after every choice of the person model and its
  evaluation had been made (2026-12-07), to report only (``coassist reproduce
  --held-out-population unseen``): :class:`~coassist.scenario.detours.Feint` (a lean the other
  way before going round) and :class:`~coassist.scenario.detours.Ringing` (a return that swings
  through the path several times). No setting was chosen while reading them.

In ``varied``, ``held-out`` and ``unseen`` every user (0 too) is drawn from a Generator seeded by
SeedSequence([population_seed, user_index, tag]) (tag 1 / 2 / 3: a stream of its own, apart from
the thesis population's [population_seed, user_index]); user i's family is the population's
family i mod (its number of families), so users 0…k−1 meet each family once. The name is
"<population>-user-<i>". Spreads (log-uniform where "×", else uniform):

- arm: stiffness (K_min, K_max and κ) × 0.5–2 the author's (K_max also ×/÷ 1.15, κ ×/÷ 1.3,
  log-normal), damping × 0.5–3, reaction delay 0.04–0.16 s, reflex share 0.3–0.7,
  adaptation time and the noise's correlation time as the thesis population's, force limit
  30–60 N; motor noise 1.25 × the author's ×/÷ 1.3 (log-normal): with the thesis population's
  noise the closed loop makes a median of 2–5 sub-movements against user-a's 9 (docs/realism.md);
- path: clearance 0.005–0.06 m, anticipation 0.04–0.2 m, shape jitter 0.1–0.3, left
  preference 0.1–0.9; pace ×/÷ 1.15 (log-normal), pace jitter 0.02–0.08, start delay 0.1–0.5 s;
- the families' own parameters: :data:`FAMILY_RANGES` (each family's jitter 0.1–0.2).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from coassist._checks import check_int
from coassist.scenario.detours import Asymmetric, Corrective, DetourFamily, Feint, Hesitant, Ringing, Skewed, Swing
from coassist.scenario.operator import AUTHOR, OperatorProfile, operator_profile

__all__ = [
    "FAMILY_RANGES",
    "HELD_OUT",
    "POPULATIONS",
    "POPULATION_FAMILIES",
    "REPORT_ONLY_POPULATIONS",
    "UNSEEN",
    "population_profile",
]

#: The population no setting is searched on, used only to report (docs/person-model.md, *What the held-out cells were
#: told*, names the choices made while seeing its operators).
HELD_OUT = "held-out"
#: A population of families made after every choice was made, to report only (module docstring).
UNSEEN = "unseen"
#: The populations by name, in the order the help lists them.
POPULATIONS = ("thesis", "varied", HELD_OUT, UNSEEN)
#: The populations no setting is chosen on: a report's held-out cells meet one of them.
REPORT_ONLY_POPULATIONS = (HELD_OUT, UNSEEN)

#: Each drawn population's families (the thesis population's is the bump alone).
POPULATION_FAMILIES: dict[str, tuple[type[DetourFamily], ...]] = {
    "varied": (Asymmetric, Skewed, Swing),
    "held-out": (Corrective, Hesitant),
    "unseen": (Feint, Ringing),
}

#: The stream tag of each drawn population (SeedSequence([population_seed, user, tag])).
_TAGS = {"varied": 1, "held-out": 2, "unseen": 3}

#: What each family's person parameters are drawn from (module docstring): text for the docs,
#: the draws themselves in :func:`_draw_family`.
FAMILY_RANGES = {
    "asymmetric": (
        "return_ratio ρ: |ln ρ| uniform on [ln 1.3, ln 2.5], either sign (0.4–0.77 or 1.3–2.5); overshoot 0–0.25"
    ),
    "skewed": "skew g 0.2–0.6, peak before or after the obstacle (½ each); overshoot 0–0.25",
    "swing": "overshoot o 0.15–0.4, settle_ratio μ 0.6–1.4",
    "corrective": (
        "2–3 strokes out, 2–3 back (weights 0.5–1.5, normalised), overlap 0.1–0.35, overshoot 0.1–0.35, "
        "return_ratio 0.7–1.6 (×), 3–6 progress dips of depth 0.4–0.8 and width 0.3–0.6 s"
    ),
    "hesitant": "depth 0.6–1 (1: a pause), duration 0.3–1 s, delay 0–0.2 s after the onset",
    "feint": "lean e 0.1–0.35 of the detour's amplitude, over 2λ anticipations, λ 0.5–1.5",
    "ringing": "overshoot o 0.1–0.3, decay r 0.3–0.6, 2–4 swings, each stroke after the first 0.5–1 anticipations",
}


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(math.log(lo), math.log(hi))))


def _draw_family(family: type[DetourFamily], rng: np.random.Generator) -> DetourFamily:
    """One person's parameters of ``family`` (:data:`FAMILY_RANGES`)."""
    jitter = float(rng.uniform(0.1, 0.2))
    if family is Asymmetric:
        magnitude = float(rng.uniform(math.log(1.3), math.log(2.5)))
        ratio = math.exp(magnitude if rng.random() < 0.5 else -magnitude)
        return Asymmetric(jitter=jitter, return_ratio=ratio, overshoot=float(rng.uniform(0.0, 0.25)))
    if family is Skewed:
        peak = -1 if rng.random() < 0.5 else 1
        return Skewed(
            jitter=jitter, skew=float(rng.uniform(0.2, 0.6)), peak=peak, overshoot=float(rng.uniform(0.0, 0.25))
        )
    if family is Swing:
        return Swing(jitter=jitter, overshoot=float(rng.uniform(0.15, 0.4)), settle_ratio=float(rng.uniform(0.6, 1.4)))
    if family is Corrective:
        n_out, n_back = (int(v) for v in rng.integers(2, 4, 2))
        return Corrective(
            jitter=jitter,
            out_weights=tuple(float(v) for v in rng.uniform(0.5, 1.5, n_out)),
            back_weights=tuple(float(v) for v in rng.uniform(0.5, 1.5, n_back)),
            overlap=float(rng.uniform(0.1, 0.35)),
            overshoot=float(rng.uniform(0.1, 0.35)),
            return_ratio=_log_uniform(rng, 0.7, 1.6),
            dips=int(rng.integers(3, 7)),
            dip_depth=float(rng.uniform(0.4, 0.8)),
            dip_width=float(rng.uniform(0.3, 0.6)),
        )
    if family is Hesitant:
        return Hesitant(
            jitter=jitter,
            depth=float(rng.uniform(0.6, 1.0)),
            duration=float(rng.uniform(0.3, 1.0)),
            delay=float(rng.uniform(0.0, 0.2)),
        )
    if family is Feint:
        return Feint(jitter=jitter, lean=float(rng.uniform(0.1, 0.35)), lean_ratio=float(rng.uniform(0.5, 1.5)))
    if family is Ringing:
        return Ringing(
            jitter=jitter,
            overshoot=float(rng.uniform(0.1, 0.3)),
            decay=float(rng.uniform(0.3, 0.6)),
            swings=int(rng.integers(2, 5)),
            swing_ratio=float(rng.uniform(0.5, 1.0)),
        )
    raise ValueError(f"no person draw for detour family {family.__name__}")


def _drawn(population: str) -> Callable[[int, int], OperatorProfile]:
    families = POPULATION_FAMILIES[population]

    def profile(user_index: int, population_seed: int) -> OperatorProfile:
        rng = np.random.default_rng(np.random.SeedSequence([population_seed, user_index, _TAGS[population]]))
        a = AUTHOR

        def lognormal(spread: float) -> float:
            return float(np.exp(rng.normal(0.0, np.log(spread))))

        stiff = _log_uniform(rng, 0.5, 2.0)
        return OperatorProfile(
            name=f"{population}-user-{user_index}",
            stiffness_min=a.stiffness_min * stiff,
            stiffness_max=a.stiffness_max * stiff * lognormal(1.15),
            stiffness_gain=a.stiffness_gain * stiff * lognormal(1.3),
            adaptation_time=a.adaptation_time * lognormal(1.4),
            damping=a.damping * _log_uniform(rng, 0.5, 3.0),
            reaction_delay=float(rng.uniform(0.04, 0.16)),
            reflex_share=float(rng.uniform(0.3, 0.7)),
            force_limit=float(rng.uniform(30.0, 60.0)),
            motor_noise=1.25 * a.motor_noise * lognormal(1.3),
            motor_noise_time=a.motor_noise_time * lognormal(1.3),
            clearance=float(rng.uniform(0.005, 0.06)),
            anticipation=float(rng.uniform(0.04, 0.20)),
            pace=a.pace * lognormal(1.15),
            pace_jitter=float(rng.uniform(0.02, 0.08)),
            shape_jitter=float(rng.uniform(0.1, 0.3)),
            start_delay=float(rng.uniform(0.1, 0.5)),
            left_preference=float(rng.uniform(0.1, 0.9)),
            detour=_draw_family(families[user_index % len(families)], rng),
        )

    return profile


def population_profile(population: str, user_index: int, population_seed: int = 0) -> OperatorProfile:
    """User ``user_index``'s profile in the population ``population`` (one of :data:`POPULATIONS`)
    of seed ``population_seed`` (module docstring); ``thesis``: :func:`operator_profile`, unchanged."""
    if population not in POPULATIONS:
        raise ValueError(f"population must be one of {POPULATIONS}, got {population!r}")
    user_index = check_int(user_index, "user_index", 0)
    population_seed = check_int(population_seed, "population_seed", 0)
    if population == "thesis":
        return operator_profile(user_index, population_seed)
    return _drawn(population)(int(user_index), int(population_seed))
