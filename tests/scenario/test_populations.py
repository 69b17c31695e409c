"""The named populations (scenario.populations): the thesis' unchanged, the drawn ones seeded, their
families disjoint and of different kinds, their arms and paths spread as documented."""

import dataclasses

import numpy as np
import pytest

from coassist.scenario.detours import FAMILIES, family_from_extra
from coassist.scenario.operator import AUTHOR, OperatorProfile, operator_profile
from coassist.scenario.populations import (
    POPULATION_FAMILIES,
    POPULATIONS,
    REPORT_ONLY_POPULATIONS,
    population_profile,
)


def test_the_thesis_population_is_operator_profile():
    for seed in (0, 3):
        for user in range(6):
            assert population_profile("thesis", user, seed) == operator_profile(user, seed)
    assert population_profile("thesis", 0) is AUTHOR
    assert all(population_profile("thesis", u).detour is None for u in range(6))
    # its record is what it was before families existed: the fields of the profile, no "detour"
    fields = {f.name for f in dataclasses.fields(OperatorProfile)} - {"detour"}
    assert set(AUTHOR.to_extra()) == fields


def test_the_held_out_families_are_of_another_kind_and_in_no_other_population():
    varied, held_out = POPULATION_FAMILIES["varied"], POPULATION_FAMILIES["held-out"]
    unseen = POPULATION_FAMILIES["unseen"]
    assert set(POPULATION_FAMILIES) == set(POPULATIONS) - {"thesis"}
    assert not set(varied) & set(held_out) and not set(unseen) & set(varied + held_out)
    assert {f.kind for f in varied} == {"shape"} and {f.kind for f in held_out} == {"segmented"}
    assert {f.kind for f in unseen} == {"reversing"}
    assert len(varied) >= 3 and len(held_out) >= 2 and len(unseen) >= 2
    assert FAMILIES["bump"] not in varied + held_out + unseen  # the thesis' family (and the fallback) in none
    assert REPORT_ONLY_POPULATIONS == ("held-out", "unseen")
    # what each population's people actually draw, over many users
    for name, families in POPULATION_FAMILIES.items():
        drawn = {type(population_profile(name, u, 5).detour) for u in range(30)}
        assert drawn == set(families)
        for u in range(12):
            assert type(population_profile(name, u).detour) is families[u % len(families)]


def test_drawn_populations_are_seeded_and_named():
    for name in ("varied", "held-out", "unseen"):
        assert population_profile(name, 3, 1) == population_profile(name, 3, 1)
        assert population_profile(name, 3, 1) != population_profile(name, 3, 2)
        assert population_profile(name, 0).name == f"{name}-user-0"
        assert population_profile(name, 0) != AUTHOR
    # a different stream from the thesis population's: not the same arm for the same (user, seed)
    assert population_profile("varied", 2).stiffness_min != operator_profile(2).stiffness_min
    assert population_profile("varied", 2).stiffness_min != population_profile("held-out", 2).stiffness_min
    assert population_profile("unseen", 2).stiffness_min != population_profile("held-out", 2).stiffness_min


@pytest.mark.parametrize("name", ["varied", "held-out", "unseen"])
def test_arms_and_paths_spread_over_the_documented_ranges(name):
    people = [population_profile(name, u, 7) for u in range(300)]

    def spread(values, lo, hi, reach):
        values = np.asarray(values)
        assert values.min() >= lo - 1e-12 and values.max() <= hi + 1e-12
        assert values.min() < lo + reach * (hi - lo) and values.max() > hi - reach * (hi - lo)  # the range is used

    spread([p.stiffness_min / AUTHOR.stiffness_min for p in people], 0.5, 2.0, 0.1)
    spread([p.damping / AUTHOR.damping for p in people], 0.5, 3.0, 0.1)
    spread([p.reaction_delay for p in people], 0.04, 0.16, 0.05)
    spread([p.left_preference for p in people], 0.1, 0.9, 0.05)
    spread([p.clearance for p in people], 0.005, 0.06, 0.05)
    spread([p.anticipation for p in people], 0.04, 0.2, 0.05)
    # log-uniform stiffness: as many softer than the author as stiffer (binomial, 300 draws: ±4 sd)
    softer = sum(p.stiffness_min < AUTHOR.stiffness_min for p in people)
    assert abs(softer - 150) < 4 * np.sqrt(300 * 0.25)


def test_a_profile_records_its_family_and_bad_names_are_refused():
    person = population_profile("held-out", 1)
    record = person.to_extra()
    assert record["detour"]["family"] == person.detour.name
    assert family_from_extra(record["detour"]) == person.detour
    with pytest.raises(ValueError, match="population must be one of"):
        population_profile("thesis2", 0)
    with pytest.raises(ValueError, match="user_index"):
        population_profile("varied", -1)
