"""Parameter sets: validation messages name the field; thesis values are the thesis'."""

from dataclasses import replace

import numpy as np
import pytest

from coassist.config import (
    THESIS_APPLICATION,
    THESIS_EVALUATION,
    THESIS_WEIGHTS,
    ControlPreset,
    GameParameters,
    GameWeights,
    ImpedanceParameters,
)


def test_thesis_values():
    assert THESIS_EVALUATION.impedance.M == (10.0, 10.0) and THESIS_EVALUATION.impedance.D == (100.0, 100.0)
    evaluation, application = THESIS_EVALUATION.game, THESIS_APPLICATION.game
    assert evaluation.alpha == 0.8 and application.alpha == 0.9
    assert evaluation.weights is THESIS_WEIGHTS
    np.testing.assert_array_equal(evaluation.weights.R_r, [[5e-4, 0.0], [0.0, 5e-4]])
    np.testing.assert_array_equal(application.weights.R_r, [[1e-4, 0.0], [0.0, 1e-4]])
    np.testing.assert_array_equal(evaluation.weights.Q_hh, np.diag([1.0, 1.0, 1e-4, 1e-4]))
    for name in ("Q_hr", "Q_rh"):
        np.testing.assert_array_equal(getattr(evaluation.weights, name), np.zeros((4, 4)))
    # the application preset differs from the evaluation one in α and R_r only
    assert replace(application, alpha=0.8, weights=replace(application.weights, R_r=(5e-4, 5e-4))) == evaluation


def test_game_weights_equal_by_value_and_hash_alike():
    """A preset's game keys a memo of built games (coassist.control.game.cooperative_game):
    equal weights, however written, are equal and hash alike; other weights are not equal."""
    as_diagonals = GameWeights((1, 1, 1e-4, 1e-4), 0, 0, (1, 1, 1e-4, 1e-4), (5e-4, 5e-4), (5e-4, 5e-4))
    zero = np.zeros((4, 4))
    as_matrices = GameWeights(np.diag([1, 1, 1e-4, 1e-4]), -zero, zero, np.diag([1, 1, 1e-4, 1e-4]), 5e-4, 5e-4)
    assert as_diagonals == as_matrices == THESIS_WEIGHTS
    assert hash(as_diagonals) == hash(as_matrices)  # −0.0 in Q_hr: still the same hash
    assert GameParameters(as_matrices) == GameParameters() and hash(GameParameters(as_matrices)) == hash(
        GameParameters()
    )
    assert replace(THESIS_WEIGHTS, R_r=(1e-4, 5e-4)) != THESIS_WEIGHTS
    assert GameWeights(1.0, 0, 0, 1.0, 1.0, 1.0, n_dof=1) != GameWeights(1.0, 0, 0, 1.0, 1.0, 1.0, n_dof=2)
    assert THESIS_WEIGHTS != "weights"


@pytest.mark.parametrize(
    "build, field",
    [
        (lambda: ImpedanceParameters(M=(10, -1)), "impedance.M"),
        (lambda: ImpedanceParameters(D=(1, 2, 3)), "impedance.D must have 2 entries"),
        (lambda: ImpedanceParameters(dt=0), "impedance.dt"),
        (lambda: GameParameters(alpha=1.2), "game.alpha"),
        (lambda: GameParameters(alpha="abc"), "game.alpha must be a number"),
        (lambda: GameParameters(alpha=None), "game.alpha must be a number"),
        (lambda: GameParameters(alpha=1.0, input_weighting="alpha_scaled"), r"game.alpha must be in \(0, 1\)"),
        (lambda: GameParameters(input_weighting="x"), "game.input_weighting"),
        (lambda: GameParameters(GameWeights(1.0, 0, 0, 1.0, 1.0, 1.0, n_dof=7)), "game.weights must be on 1 to 6"),
        (lambda: GameParameters({"Q_hh": (1, 1)}), "game.weights must be a GameWeights, got dict"),
        (lambda: ControlPreset("x", effort_limit="a"), "effort_limit must be a number"),
        (lambda: replace(THESIS_WEIGHTS, Q_hh=(1, 1)), "Q_hh must be 4x4"),
        (lambda: replace(THESIS_WEIGHTS, Q_rh=(0, 0, -1, 0)), "Q_rh must be positive semidefinite"),
        (lambda: replace(THESIS_WEIGHTS, R_r=(0, 1)), "R_r must be positive definite"),
        (lambda: GameParameters(horizon=0), "game.horizon"),
        (lambda: GameParameters(control_horizon=80), "game.control_horizon"),
        (
            lambda: ControlPreset("x", impedance=ImpedanceParameters(M=(1,), D=(1,), K=(0,))),
            "impedance has 1 DOFs but game.weights has 2",
        ),
    ],
)
def test_validation_names_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()


def test_effort_limit_is_stored_as_a_number():
    assert ControlPreset("x", effort_limit="100").effort_limit == 100.0
