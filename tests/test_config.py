"""Parameter sets: validation messages name the field; thesis values are the thesis'."""

import pytest

from coassist.config import THESIS_APPLICATION, THESIS_EVALUATION, ControlPreset, GameParameters, ImpedanceParameters


def test_thesis_values():
    assert THESIS_EVALUATION.impedance.M == (10.0, 10.0) and THESIS_EVALUATION.impedance.D == (100.0, 100.0)
    assert THESIS_EVALUATION.game.alpha == 0.8 and THESIS_EVALUATION.game.R_r == (5e-4, 5e-4)
    assert THESIS_APPLICATION.game.alpha == 0.9 and THESIS_APPLICATION.game.R_r == (1e-4, 1e-4)
    assert THESIS_EVALUATION.game.Q_hh == (1.0, 1.0, 1e-4, 1e-4)


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
        (lambda: GameParameters(R_h=(), R_r=(), Q_hh=(), Q_hr=(), Q_rh=(), Q_rr=()), "game.R_h must have 1 to 6"),
        (lambda: ControlPreset("x", effort_limit="a"), "effort_limit must be a number"),
        (lambda: GameParameters(Q_hh=(1, 1)), "game.Q_hh must have 4 entries"),
        (lambda: GameParameters(R_r=(0, 1)), "game.R_r entries must be > 0"),
        (lambda: GameParameters(horizon=0), "game.horizon"),
        (lambda: GameParameters(control_horizon=80), "game.control_horizon"),
        (lambda: ControlPreset("x", impedance=ImpedanceParameters(M=(1,), D=(1,), K=(0,))), "impedance has 1 DOFs"),
    ],
)
def test_validation_names_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()


def test_effort_limit_is_stored_as_a_number():
    assert ControlPreset("x", effort_limit="100").effort_limit == 100.0
