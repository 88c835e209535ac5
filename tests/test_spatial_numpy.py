"""robocal.spatial's numpy quaternions and Euler angles against scipy's Rotation (which
they replace to keep scipy.spatial out of the command line's start-up)."""

import itertools
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal import spatial

SEQUENCES = ["".join(p) for p in itertools.product("xyz", repeat=3) if p[0] != p[1] and p[1] != p[2]]
SEQUENCES += [s.upper() for s in SEQUENCES]


def rotations() -> np.ndarray:
    """Random rotations, the identity, half turns and every sequence's gimbal locks."""
    special = [np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])]
    for seq in SEQUENCES:
        for angles in ([0.3, 0.0, 0.2], [0.3, np.pi / 2, 0.2], [0.1, np.pi, -0.4], [1.0, -np.pi / 2, 2.0]):
            special.append(Rotation.from_euler(seq, angles).as_matrix())
    return np.concatenate([Rotation.random(500, random_state=1).as_matrix(), np.array(special)])


def test_quaternions_equal_scipy():
    R = rotations()
    expected = Rotation.from_matrix(R).as_quat(canonical=True)[:, [3, 0, 1, 2]]
    np.testing.assert_allclose(spatial.matrix_to_quaternion(R), expected, rtol=0, atol=1e-15)
    assert spatial.matrix_to_quaternion(R[0]).shape == (4,)


@pytest.mark.parametrize("seq", SEQUENCES)
def test_euler_angles_equal_scipy(seq):
    R = rotations()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = Rotation.from_matrix(R).as_euler(seq)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        angles = spatial.matrix_to_euler(R, seq)
    assert any("Gimbal lock" in str(w.message) for w in caught)  # as scipy, at the locked rows
    wrapped = (angles - expected + np.pi) % (2 * np.pi) - np.pi  # ±π are the same angle
    np.testing.assert_allclose(wrapped, 0.0, atol=1e-12)
    assert np.all(np.abs(angles) <= np.pi)


def test_non_rotations_still_go_to_scipy():
    almost = np.eye(3) + 1e-6  # scipy projects it onto the nearest rotation
    np.testing.assert_allclose(
        spatial.matrix_to_euler(almost, "xyz"), Rotation.from_matrix(almost).as_euler("xyz")
    )
    with pytest.raises(ValueError):
        spatial.matrix_to_euler(np.eye(3), "xyx1")
