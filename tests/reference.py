"""Independent reference kinematics for the tests, written with plain numpy.

Nothing here uses robocal: the matrices are typed in from the textbook formulas so
that robocal's chain is compared against something it did not compute itself.
"""

from __future__ import annotations

import numpy as np


def Rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def Ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def Rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def Tr(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


ELEMENTARY = {
    "Rx": Rx,
    "Ry": Ry,
    "Rz": Rz,
    "Tx": lambda v: Tr(x=v),
    "Ty": lambda v: Tr(y=v),
    "Tz": lambda v: Tr(z=v),
}


def product(motions, values) -> np.ndarray:
    T = np.eye(4)
    for m, v in zip(motions, values, strict=True):
        T = T @ ELEMENTARY[m](v)
    return T


def dh_matrix(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """The closed-form standard DH matrix (seed 001 appendix, Paul 1981)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def mdh_matrix(alpha: float, a: float, theta: float, d: float) -> np.ndarray:
    """The closed-form modified DH matrix (Craig 2005, eq. 3.6)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_fk(table: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Standard-DH FK, one configuration; ``table`` rows are (theta_offset, d, a, alpha)."""
    T = np.eye(4)
    for (theta, d, a, alpha), qi in zip(table, q, strict=True):
        T = T @ dh_matrix(theta + qi, d, a, alpha)
    return T


def rotvec_of(R: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix (angle < pi), Rodrigues' inverse."""
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-12:
        return w / 2
    return w * angle / (2 * np.sin(angle))
