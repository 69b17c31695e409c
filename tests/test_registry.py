"""coassist.registry: one lookup and one "did you mean" error for every kind of preset."""

import numpy as np
import pytest

from coassist.registry import Registry, UnknownNameError, load_entry_point, unknown_name_message


def test_lookup_and_mapping_behaviour():
    r = Registry("widget", {"alpha": 1, "beta": 2})
    assert r.lookup("beta") == 2 and r["alpha"] == 1
    assert list(r) == ["alpha", "beta"] and len(r) == 2
    assert "alpha" in r and "gamma" not in r
    assert r.get("gamma") is None  # Mapping.get: an unknown name is a KeyError underneath


def test_unknown_name_says_what_and_the_closest_name():
    r = Registry("widget", {"alpha": 1, "beta": 2})
    with pytest.raises(UnknownNameError) as info:
        r.lookup("alpah")
    assert str(info.value) == "'alpah': no such widget; did you mean 'alpha'? (choose from: alpha, beta)"
    assert isinstance(info.value, ValueError) and isinstance(info.value, KeyError)
    # nothing close: no hint
    assert (
        unknown_name_message("zzz", ["alpha", "beta"], "widget") == "'zzz': no such widget (choose from: alpha, beta)"
    )


def test_registry_is_read_only_and_validated():
    entries = {"a": 1}
    r = Registry("widget", entries)
    entries["b"] = 2  # a later change to the source dict does not leak in
    assert list(r) == ["a"]
    with pytest.raises(TypeError):
        r["c"] = 3  # type: ignore[index]
    with pytest.raises(ValueError, match="widget names must be non-empty strings"):
        Registry("widget", {"": 1})


def test_register_adds_after_the_declared_and_unregister_removes_only_what_was_added():
    r = Registry("widget", {"alpha": 1, "beta": 2}, entry_type=int)
    r.register("gamma", 3)
    assert list(r) == ["alpha", "beta", "gamma"] and r["gamma"] == 3 and len(r) == 3
    with pytest.raises(ValueError, match=r"^widget 'gamma' is already registered$"):
        r.register("gamma", 4)  # never replaced
    assert r["gamma"] == 3
    with pytest.raises(ValueError, match=r"^widget 'beta' is already registered$"):
        r.register("beta", 5)
    with pytest.raises(ValueError, match=r"^widget 'delta' must be a int, got str$"):
        r.register("delta", "4")
    with pytest.raises(ValueError, match="widget names must be non-empty strings"):
        r.register("", 4)
    with pytest.raises(ValueError, match="'alpha' is declared with the registry"):
        r.unregister("alpha")
    r.unregister("gamma")
    assert list(r) == ["alpha", "beta"] and "gamma" not in r
    with pytest.raises(UnknownNameError, match="no such widget"):
        r.unregister("gamma")
    with pytest.raises(ValueError, match=r"^widget 'x' must be a int, got float$"):
        Registry("widget", {"x": 1.0}, entry_type=int)  # the declared entries are checked too


def test_the_three_preset_kinds_are_registries_with_their_own_names():
    from coassist.config import CONTROL_PRESETS, DECIMETRE_SCALE, THESIS_EVALUATION
    from coassist.control.presets import get_preset
    from coassist.experiments.reproduce_config import REPRODUCE_PRESETS

    kinds = {CONTROL_PRESETS.what, REPRODUCE_PRESETS.what}
    try:
        from coassist.intent.presets import MODEL_PRESETS

        kinds.add(MODEL_PRESETS.what)
        assert isinstance(MODEL_PRESETS, Registry)
    except ImportError:  # torch missing
        pass
    assert {"control preset", "reproduce preset"} <= kinds
    # the decimetre preset is the SI one with every Q scaled by 10² (positions in dm)
    dm = CONTROL_PRESETS["thesis-evaluation-dm"]
    for name in ("Q_hh", "Q_rr"):
        expected = np.diag([DECIMETRE_SCALE**2 * q for q in (1.0, 1.0, 1e-4, 1e-4)])
        np.testing.assert_array_equal(getattr(dm.game.weights, name), expected)
    np.testing.assert_array_equal(dm.game.weights.R_r, THESIS_EVALUATION.game.weights.R_r)  # efforts unscaled
    with pytest.raises(
        ValueError, match=r"^preset 'thesis-eval': no such control preset; did you mean 'thesis-evaluation'\?"
    ):
        get_preset("thesis-eval")


def test_an_entry_point_names_a_module_attribute_imported_when_asked():
    from coassist.scenario.reference_intents import NominalIntent

    assert load_entry_point("coassist.scenario.reference_intents:NominalIntent") is NominalIntent
    for bad in ("coassist.scenario.reference_intents", ":NominalIntent", "coassist.scenario:", None):
        with pytest.raises(ValueError, match="an entry point is 'package.module:attribute'"):
            load_entry_point(bad)  # type: ignore[arg-type]
    with pytest.raises(
        ValueError, match=r"^entry point 'coassist.registry:Nothing': coassist.registry has no 'Nothing'$"
    ):
        load_entry_point("coassist.registry:Nothing")
    # the one form every registry checks its entries against
    from coassist.registry import is_entry_point

    assert is_entry_point("coassist.registry:Registry")
    assert not any(is_entry_point(v) for v in ("a:b:c", ":x", "x:", "x", None, 3))
    with pytest.raises(ImportError):  # the caller names the extra to install
        load_entry_point("coassist_no_such_module:thing")


def test_every_registry_refuses_an_entry_of_another_class_or_another_name():
    """Four registries took any entry ({"not": "a preset"}), which failed far away (an AttributeError in run_spec); a
    preset registered under another name than its own made trials record a name no registry knows (review,
    2026-12-06). Every registry of the project checks its entries' class, and a named entry's name."""
    from dataclasses import replace

    from coassist.config import CONTROL_PRESETS
    from coassist.control.presets import CONTROLLERS
    from coassist.experiments.reproduce_config import REPRODUCE_PRESETS
    from coassist.robot.worlds import WORLDS
    from coassist.scenario.intent_registry import INTENT_FOLDERS, INTENT_SOURCES
    from coassist.scenario.tasks import TASKS

    registries = [CONTROL_PRESETS, CONTROLLERS, REPRODUCE_PRESETS, WORLDS, INTENT_FOLDERS, INTENT_SOURCES, TASKS]
    try:
        from coassist.intent.presets import MODEL_PRESETS

        registries.append(MODEL_PRESETS)
    except ImportError:  # torch missing
        pass
    for registry in registries:
        assert registry.entry_type is not None, registry.what
        with pytest.raises(ValueError, match=rf"{registry.what} 'bogus' must be a "):
            registry.register("bogus", {"not": "an entry"})
        assert "bogus" not in registry
    preset = CONTROL_PRESETS["thesis-evaluation"]
    with pytest.raises(ValueError, match=r"control preset 'mine': its entry is named 'other'; register it under"):
        CONTROL_PRESETS.register("mine", replace(preset, name="other"))
    CONTROL_PRESETS.register("mine", replace(preset, name="mine"))
    CONTROL_PRESETS.unregister("mine")
    r = Registry("widget", {"a": 1})  # entries without a name of their own: any name
    r.register("b", 2)
