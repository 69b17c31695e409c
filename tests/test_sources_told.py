"""What each intent source is told: no source an arm may run is handed the simulated operator's intent."""

from dataclasses import replace

import numpy as np
import pytest

from coassist.interfaces import TRIAL_SLOTS
from coassist.runtime.episode import run_episode
from coassist.scenario.arm_identification import ASSUMED_ARM
from coassist.scenario.calibration_draws import MAX_DRAWS, draw_of
from coassist.scenario.intent_registry import INTENT_FOLDERS, INTENT_SOURCES, Told, load_intent_source
from coassist.scenario.path_hypotheses import PersonShape, write_calibration
from coassist.scenario.path_model import fit_path_model
from coassist.scenario.person_model import PersonFit, write_person_model
from coassist.sim.trial_runner import TrialSpec, spec_episode


def _folders(tmp_path):
    """A folder of each kind a person or an arm may run without a network (a model folder needs a trained
    network: tests/intent cover its loading; it never reads the context's intent)."""
    nominal = np.stack([np.linspace(0.0, 1.0, 101), np.zeros(101)], axis=1)
    x = np.linspace(0.0, 1.0, 400)
    demo = np.stack([x, 0.08 * np.exp(-(((x - 0.5) / 0.12) ** 4))], axis=1)
    paths = fit_path_model(nominal, [demo], noise=0.001)
    return {
        "person-model": str(write_person_model(tmp_path / "person", {"user-0": PersonFit(ASSUMED_ARM, paths)})),
        "path-hypotheses": str(write_calibration(tmp_path / "paths", {"user-0": PersonShape()})),
    }


def test_only_the_oracle_is_handed_the_simulated_operators_intent(tmp_path):
    specs = {name: name for name in INTENT_SOURCES}
    specs.update({f"folder:{k}": v for k, v in _folders(tmp_path).items()})
    assert set(specs) >= {"nominal", "present", "paths", "oracle", "folder:person-model"}
    for name, intent in specs.items():
        spec = TrialSpec(
            "linear", user=0, controller="cooperative-arbitrated", seed=900_017, intent=intent, obstacle="large"
        )
        source = load_intent_source(intent, horizon=50)
        seen = []
        reset = source.reset
        source.reset = lambda context, reset=reset, seen=seen: (seen.append(context), reset(context))[1]
        episode = spec_episode(spec, None, {(intent, 50, "auto"): source})
        episode.n_max = 30  # the context is handed over at the start: a few ticks show it
        run_episode(episode)
        simulation_only = INTENT_SOURCES[name].simulation_only if name in INTENT_SOURCES else False
        assert len(seen) == 1
        if simulation_only:
            assert seen[0].true_intent is not None, name
        else:
            assert seen[0].true_intent is None, f"{name} was handed the simulated operator's intent"
            assert getattr(source, "reads_true_intent", False) is False, name
        # nor the seed the simulation's streams grow from (with it and the user a review rebuilt the operator's
        # intent bit for bit): the seed modulo TRIAL_SLOTS, which picks a calibration draw as the seed does
        assert seen[0].seed == 900_017 % TRIAL_SLOTS == 377, name


def test_a_draw_picked_from_the_slot_is_the_seeds():
    for draws in range(1, MAX_DRAWS + 1):
        assert TRIAL_SLOTS % draws == 0
        for seed in (0, 17, 900_017, 2_985_123):
            assert draw_of(seed % TRIAL_SLOTS, draws) == draw_of(seed, draws)


def test_every_source_says_what_it_is_told():
    for name, entry in INTENT_SOURCES.items():
        assert isinstance(entry.told, Told) and entry.told.text(), name
    for name, kind in INTENT_FOLDERS.items():
        assert isinstance(kind.told, Told) and kind.told.text(), name
    assert INTENT_SOURCES["nominal"].told.text() == "the plan only"
    assert INTENT_SOURCES["paths"].told.scene and INTENT_SOURCES["paths"].told.family
    person = INTENT_FOLDERS["person-model"].told
    assert person.arm == "measured" and not person.scene and not person.family and not person.label
    assert person.text() == "arm measured; from the person's trials: paths round obstacles and the arm"
    # a calibration that fell back to the typical arm learnt only the paths from the person (a study's report said
    # "arm assumed; from the person's trials: paths round obstacles and the arm": a review, 2026-12-07)
    assumed = replace(person, arm="assumed").text()
    assert assumed == "arm assumed; from the person's trials: paths round obstacles"
    with pytest.raises(ValueError, match="Told.arm"):
        Told(arm="guessed")
