"""coassist.spatial's rotation vectors kept continuous, against scipy's rotations."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from coassist.spatial import continuous_rotation_vector, rotation_matrix, rotation_vector, unwrap_rotation_vectors


def test_a_rotation_through_pi_stays_continuous_and_is_the_same_rotation():
    # the tool pointing down (π about x) tilting on about x to π + 0.5: rotation_vector jumps to ≈ −π·x
    angles = np.linspace(math.pi - 0.3, math.pi + 0.5, 81)
    raw = np.array([rotation_vector(Rotation.from_rotvec([a, 0.0, 0.0]).as_matrix()) for a in angles])
    assert np.abs(np.diff(raw, axis=0)).max() > 6.0  # the jump this function exists for
    prev, out = raw[0], []
    for r in raw:
        prev = continuous_rotation_vector(r, prev)
        out.append(prev)
    out = np.array(out)
    np.testing.assert_allclose(out[:, 0], angles, atol=1e-9)  # the angle itself, past π
    np.testing.assert_allclose(out[:, 1:], 0.0, atol=1e-9)
    for r, a in zip(out, angles):  # every sample still describes the measured rotation
        np.testing.assert_allclose(rotation_matrix(r), Rotation.from_rotvec([a, 0.0, 0.0]).as_matrix(), atol=1e-9)


def test_continuous_rotation_vector_by_hand():
    # θ = 3 about z, previous at 3.5 about −z... i.e. the same axis flipped: k = round((−3.5 − 3)/2π) = −1
    r = continuous_rotation_vector([0.0, 0.0, 3.0], [0.0, 0.0, -3.5])
    np.testing.assert_allclose(r, [0.0, 0.0, 3.0 - 2 * math.pi])
    np.testing.assert_array_equal(continuous_rotation_vector([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]), 0.0)
    np.testing.assert_array_equal(continuous_rotation_vector([0.1, 0.2, 0.3], [np.nan, 0.0, 0.0]), [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match=r"rv must have shape \(3,\)"):
        continuous_rotation_vector([0.1, 0.2], [0.0, 0.0, 0.0])


def test_unwrap_rotation_vectors_matches_the_row_by_row_chain_and_skips_nan_rows():
    angles = np.linspace(math.pi - 0.2, math.pi + 0.4, 31)
    raw = np.array([rotation_vector(Rotation.from_rotvec([0.0, a, 0.0]).as_matrix()) for a in angles])
    raw[10] = np.nan  # a dropped sample: kept as it is, the chain goes on from the row before
    out = unwrap_rotation_vectors(raw, [0.0, math.pi - 0.2, 0.0])
    keep = np.arange(31) != 10
    np.testing.assert_allclose(out[keep, 1], angles[keep], atol=1e-9)
    assert np.isnan(out[10]).all()
    with pytest.raises(ValueError, match=r"rvs must have shape \(n, 3\)"):
        unwrap_rotation_vectors(np.zeros((4, 2)), [0.0, 0.0, 0.0])
