"""A person's paths learned from demonstrations (coassist.scenario.path_model), against hand-built paths."""

import numpy as np
import pytest

from coassist.scenario.path_model import (
    NEAREST_CANDIDATES,
    PathFrame,
    PathModel,
    PathModelSettings,
    fit_path_model,
)

# a straight plan along x, 1 m: a path's (s, d) is its (x, y)
NOMINAL = np.stack([np.linspace(0.0, 1.0, 501), np.zeros(501)], axis=1)
X = np.linspace(0.0, 1.0, 2001)


def _bump(centre, amplitude, width=0.12):
    """A smooth detour: y = A·exp(−((x − c)/w)⁴), on the straight plan (T, 2)."""
    return np.stack([X, amplitude * np.exp(-(((X - centre) / width) ** 4))], axis=1)


def test_the_frame_is_arc_length_and_offset():
    frame = PathFrame(NOMINAL)
    s, d = frame.project(np.array([[0.3, 0.05], [0.7, -0.02], [-0.1, 0.0]]))
    np.testing.assert_allclose(s, [0.3, 0.7, 0.0], atol=1e-12)
    np.testing.assert_allclose(d, [0.05, -0.02, 0.0], atol=1e-12)
    # on an arc of radius R (counter-clockwise: its left normal points to the centre) the offset is the
    # distance from the circle, positive inside (to the polyline's chord error)
    R, phi = 0.5, np.linspace(0.0, np.pi / 2, 2001)
    arc = PathFrame(np.stack([R * np.cos(phi), R * np.sin(phi)], axis=1))
    q = np.array([[0.0, 0.55], [0.4 * np.cos(0.4), 0.4 * np.sin(0.4)]])
    s, d = arc.project(q)
    chord = R * (np.pi / 2 / 2000) ** 2  # the polyline's sagitta and its vertex spacing bound the error
    np.testing.assert_allclose(d, [-0.05, 0.1], atol=10 * chord + 1e-6)
    np.testing.assert_allclose(s, [R * np.pi / 2, R * 0.4], atol=R * np.pi / 2 / 2000)


def test_demonstrations_are_kept_as_the_person_went():
    demos = [_bump(0.5, 0.08), _bump(0.52, -0.07), _bump(0.48, 0.09)]
    model = fit_path_model(NOMINAL, demos, noise=0.001)
    assert model.sides.tolist() == [1, -1, 1]
    got = model.demonstrations()
    for demo, path in zip(demos, got):
        # every point of the primitive's path lies on the demonstrated one: the bump spans ~10 basis
        # widths, which the basis resolves to a small fraction of its amplitude
        _, d = PathFrame(demo).project(path)
        assert np.max(np.abs(d)) < 0.002
        assert np.linalg.norm(path[0] - demo[0]) < 0.002 and np.linalg.norm(path[-1] - demo[-1]) < 0.002
    # the same demonstrations fit again give the same model, bit for bit
    again = fit_path_model(NOMINAL, demos, noise=0.001)
    assert again.weights.tobytes() == model.weights.tobytes()


def test_ways_have_laplaces_prior_and_a_plan_without_detours_has_one_way():
    model = fit_path_model(NOMINAL, [_bump(0.5, 0.08)] * 3 + [_bump(0.5, -0.08)], noise=0.001)
    assert model.ways() == pytest.approx({1: 4 / 6, -1: 2 / 6})
    straight = fit_path_model(NOMINAL, [_bump(0.5, 0.005), _bump(0.5, -0.01)], noise=0.001)
    assert straight.sides.tolist() == [0, 0] and straight.ways() == {0: 1.0}
    points, ways, prior = straight.curves((0.0,))
    assert ways.tolist() == [0, 0] and prior.sum() == pytest.approx(1.0)


def test_repeatability_is_what_the_others_mean_leaves_of_each_path():
    # r_j = ‖d_j − mean of the others of its way‖ / ‖d_j‖ (RMS over 5–95 % of the plan), median over j.
    # The same detour three times: 0. One detour and the same at c times its height: r = |1 − c| and |1 − c| / c,
    # the median of two their mean (0.5 and 1 at c = 0.5: 0.75). Two detours with nothing in common (apart
    # along the plan): ‖d_1 − d_2‖ = √2 ‖d_1‖, r = √2. A way taken once gives no figure, nor do paths that took
    # no detour (their offset is noise about the plan). Tolerance: the primitive's fit of these smooth bumps, a
    # few µm against RMS offsets of 18–36 mm (the test above bounds it by 2 mm for sharper ones)
    same = fit_path_model(NOMINAL, [_bump(0.5, 0.08)] * 3, noise=0.001)
    assert same.repeatability() == pytest.approx(0.0, abs=0.03)
    scaled = fit_path_model(NOMINAL, [_bump(0.5, 0.08), _bump(0.5, 0.04)], noise=0.001)
    assert scaled.repeatability() == pytest.approx(0.75, abs=0.03)
    apart = fit_path_model(NOMINAL, [_bump(0.3, 0.08), _bump(0.7, 0.08)], noise=0.001)
    assert apart.repeatability() == pytest.approx(np.sqrt(2.0), abs=0.03)
    # the others are of the same way: a left and a right detour say nothing of each other
    assert fit_path_model(NOMINAL, [_bump(0.5, 0.08), _bump(0.5, -0.08)], noise=0.001).repeatability() is None
    near = fit_path_model(NOMINAL, [_bump(0.3, 0.002), _bump(0.7, -0.002), _bump(0.5, 0.001)], noise=0.001)
    assert near.sides.tolist() == [0, 0, 0] and near.repeatability() is None
    mixed = fit_path_model(NOMINAL, [_bump(0.5, 0.08)] * 2 + [_bump(0.5, -0.08)] * 2, noise=0.001)
    assert mixed.repeatability() == pytest.approx(0.0, abs=0.03)


def test_a_way_nobody_took_is_the_mirror_of_the_other_and_shifts_move_along_the_plan():
    model = fit_path_model(NOMINAL, [_bump(0.5, 0.08), _bump(0.45, 0.1)], noise=0.001)
    points, ways, prior = model.curves((-0.02, 0.0, 0.02))
    assert ways.tolist() == [1] * 6 + [-1] * 6
    np.testing.assert_allclose(prior, np.r_[np.full(6, (3 / 4) / 6), np.full(6, (1 / 4) / 6)])
    # on a straight plan the mirror is y → −y, and a shift is a translation along x
    np.testing.assert_allclose(points[6:, :, 0], points[:6, :, 0], atol=1e-12)
    np.testing.assert_allclose(points[6:, :, 1], -points[:6, :, 1], atol=1e-12)
    demo = model.demonstrations()[0]
    np.testing.assert_allclose(points[0, :, 1], demo[:, 1], atol=1e-12)
    inner = (demo[:, 0] > 0.05) & (demo[:, 0] < 0.95)  # away from the ends, where the plan is clipped
    np.testing.assert_allclose(points[0, inner, 0], demo[inner, 0] - 0.02, atol=1e-9)
    np.testing.assert_allclose(points[2, inner, 0], demo[inner, 0] + 0.02, atol=1e-9)


@pytest.mark.parametrize(
    ("demos", "match"),
    [
        ([], "at least one"),
        ([np.full((10, 2), np.nan)], "demonstration 0 must be a finite"),
        ([np.zeros((10, 2))], "demonstration 0 does not move"),
        ([np.zeros((10, 3))], "demonstration 0 must be a finite"),
    ],
)
def test_bad_demonstrations_are_refused_in_one_line(demos, match):
    with pytest.raises(ValueError, match=match):
        fit_path_model(NOMINAL, demos, noise=0.001)


def test_a_model_out_of_range_is_refused_naming_the_field():
    good = fit_path_model(NOMINAL, [_bump(0.5, 0.08)], noise=0.001)
    with pytest.raises(ValueError, match="PathModel.noise"):
        PathModel(good.nominal, good.weights, good.sides, 1.0, good.settings)
    with pytest.raises(ValueError, match="PathModel.sides"):
        PathModel(good.nominal, good.weights, np.array([2]), 0.001, good.settings)
    with pytest.raises(ValueError, match="PathModel.weights"):
        PathModel(good.nominal, good.weights[:, :-1], good.sides, 0.001, good.settings)
    with pytest.raises(ValueError, match="PathModelSettings.n_basis"):
        PathModelSettings(n_basis=1)


def _brute_projection(frame: PathFrame, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every vertex against every point (the search PathFrame.project made before issue 44), then its formulas."""
    q = np.asarray(q, dtype=float).reshape(-1, 2)
    x, y = frame.points[:, 0], frame.points[:, 1]
    i = np.argmin((q[:, None, 0] - x[None, :]) ** 2 + (q[:, None, 1] - y[None, :]) ** 2, axis=1)
    rel = q - frame.points[i]
    s = np.clip(frame.arc[i] + np.sum(rel * frame.tangents[i], axis=1), 0.0, frame.length)
    return i, s, np.sum(rel * frame.normals[i], axis=1)


def _plan(n: int) -> np.ndarray:
    """A wavy plan of n vertices, 0.6 m long, unevenly spaced (as a task's polyline is)."""
    u = np.sort(np.random.default_rng(n).uniform(0.0, 1.0, n))
    u[0], u[-1] = 0.0, 1.0
    return np.stack([0.6 * u, 0.05 * np.sin(9.0 * u) + 0.02 * np.sin(31.0 * u)], axis=1)


@pytest.mark.parametrize("n_vertices", [2, NEAREST_CANDIDATES, NEAREST_CANDIDATES + 1, 1250])
def test_projection_is_every_vertex_searched_bit_for_bit(n_vertices):
    frame = PathFrame(_plan(n_vertices))
    rng = np.random.default_rng(3)
    q = np.concatenate(
        [
            rng.uniform([-0.1, -0.2], [0.7, 0.2], size=(3000, 2)),  # anywhere round the plan
            frame.points + rng.normal(scale=1e-7, size=frame.points.shape),  # next to a vertex
            frame.points,  # on a vertex: distance 0
            0.5 * (frame.points[1:] + frame.points[:-1]),  # halfway between two: (near) ties
            [[np.nan, 0.1], [0.2, np.inf], [1e200, 1e200]],  # what every vertex is compared with
        ]
    )
    with np.errstate(over="ignore", invalid="ignore"):  # the 1e200 point's squares overflow, as before
        i, s, d = _brute_projection(frame, q)
        np.testing.assert_array_equal(frame.nearest_vertex(q), i)
        got_s, got_d = frame.project(q)
    np.testing.assert_array_equal(got_s, s, strict=True)
    np.testing.assert_array_equal(got_d, d, strict=True)
    assert frame.project(np.empty((0, 2)))[0].shape == (0,)


def test_exact_ties_go_to_the_first_vertex_as_argmin_does():
    # a plan that comes back through its own vertices: the same point twice, far apart in arc length,
    # and points equidistant from two vertices; argmin takes the first
    pts = np.array(
        [[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.2, 0.1], [0.1, 0.0], [0.0, 0.1]] + [[0.3, 0.01 * k] for k in range(12)]
    )
    frame = PathFrame(pts)
    q = np.array([[0.1, 0.0], [0.15, 0.0], [0.1, 0.05], [0.05, 0.05], [0.3, 0.005], [0.3, 0.055]])
    i, s, d = _brute_projection(frame, q)
    assert i[0] == 1  # the first of the two vertices at (0.1, 0)
    np.testing.assert_array_equal(frame.nearest_vertex(q), i)
    got_s, got_d = frame.project(q)
    np.testing.assert_array_equal(got_s, s, strict=True)
    np.testing.assert_array_equal(got_d, d, strict=True)


def test_a_way_shown_once_or_twice_is_thin_and_counted_in_order():
    from coassist.scenario.path_model import FEW_PATHS, few_paths

    assert FEW_PATHS == 3
    assert few_paths(np.array([1, 1, 1, -1, 1, 1, 1, 1])) == {"right": 1}
    assert few_paths(np.array([-1, 1, 0, -1])) == {"left": 1, "right": 2}  # left first; no detour is no way
    assert list(few_paths(np.array([-1, 1, -1]))) == ["left", "right"]
    assert (
        few_paths(np.array([1, 1, 1, -1, -1, -1])) == few_paths(np.array([1, 1, 1])) == few_paths(np.array([0])) == {}
    )


def test_asked_ways_add_their_paths_but_not_to_the_prior():
    # three chosen left, one chosen right, two right asked for: the prior is the chosen trials' alone (Laplace over
    # four), the right way's hypotheses are its three paths, each a third of the way's prior
    demos = [_bump(0.5, 0.08)] * 3 + [_bump(0.5, -0.08), _bump(0.45, -0.07), _bump(0.55, -0.09)]
    asked = [False, False, False, False, True, True]
    model = fit_path_model(NOMINAL, demos, noise=0.001, asked=asked)
    assert model.asked.tolist() == asked
    assert model.ways() == pytest.approx({1: 4 / 6, -1: 2 / 6})
    chosen = fit_path_model(NOMINAL, demos, noise=0.001)
    assert chosen.asked.tolist() == [False] * 6 and chosen.ways() == pytest.approx({1: 4 / 8, -1: 4 / 8})
    shifts = (-0.01, 0.0, 0.01)
    _, ways, prior = model.curves(shifts)
    assert np.sum(ways == -1) == 3 * len(shifts)
    np.testing.assert_allclose(prior[ways == -1], 2 / 6 / (3 * len(shifts)), rtol=1e-12)
    assert prior.sum() == pytest.approx(1.0, abs=1e-12)
    # every path asked for: no preference known, even odds
    only_asked = fit_path_model(NOMINAL, demos[3:], noise=0.001, asked=[True] * 3)
    assert only_asked.ways() == pytest.approx({1: 0.5, -1: 0.5})
    for bad in ([True] * 5, [1, 0, 0, 0, 0, 0]):
        with pytest.raises(ValueError, match="asked"):
            fit_path_model(NOMINAL, demos, noise=0.001, asked=bad)
    with pytest.raises(ValueError, match="PathModel.asked"):
        PathModel(model.nominal, model.weights, model.sides, 0.001, model.settings, asked=np.array([1, 0, 0, 0, 0, 0]))
