"""Batched SE(3) and SO(3) helpers shared by every part of robocal.

Conventions
-----------
* Homogeneous transforms are arrays shaped ``(..., 4, 4)``; rotations ``(..., 3, 3)``.
  Every function accepts any number of leading batch dimensions.
* Units are SI: metres and radians.
* Quaternions are scalar-first ``(w, x, y, z)``, as in the measurement CSV files
  (``qw, qx, qy, qz``).  scipy uses scalar-last internally; the conversion happens here.
* Euler sequences follow scipy: upper case (``"ZXZ"``, ``"XYZ"``) are intrinsic
  (rotations about the moving axes, R = R1 R2 R3), lower case (``"xyz"``) extrinsic
  (about the fixed axes, R = R3 R2 R1).  Seed 003 describes tool orientation with
  intrinsic ZXZ angles (Phi, theta, Psi); seed 000 eq. (1) uses
  Rz(gamma) Ry(beta) Rx(alpha), which is extrinsic ``"xyz"`` = (alpha, beta, gamma).
* Orientation errors are rotation vectors in the reference (world) frame:
  ``log(R_actual @ R_referenceᵀ)``.  This is the convention of the identification
  Jacobian's orientation rows (see ``robocal.model.chain``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

__all__ = [
    "MOTIONS",
    "chain_product",
    "compose",
    "elementary",
    "euler_to_matrix",
    "fit_rigid_transform",
    "homogeneous",
    "inverse",
    "matrix_to_euler",
    "matrix_to_quaternion",
    "matrix_to_rotvec",
    "parse_vector",
    "pose_error",
    "quaternion_to_matrix",
    "rot",
    "rotvec_to_matrix",
    "rotx",
    "roty",
    "rotz",
    "skew",
    "transl",
    "zyx_angles",
]

#: The six elementary motions a kinematic chain is made of.
MOTIONS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")

Array = NDArray[np.float64]


def rot(axis: str | int, angle: ArrayLike) -> Array:
    """Rotation matrices about a principal axis.

    Args:
        axis: ``"x"``, ``"y"``, ``"z"`` or 0, 1, 2.
        angle: angles in rad, any shape ``S``.

    Returns:
        Array shaped ``S + (3, 3)``.
    """
    k = "xyz".index(axis) if isinstance(axis, str) else int(axis)
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((*a.shape, 3, 3))
    i, j = (k + 1) % 3, (k + 2) % 3
    R[..., k, k] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def rotx(angle: ArrayLike) -> Array:
    """Rotations about x, shape ``S + (3, 3)`` for angles (rad) shaped ``S``."""
    return rot(0, angle)


def roty(angle: ArrayLike) -> Array:
    """Rotations about y, shape ``S + (3, 3)`` for angles (rad) shaped ``S``."""
    return rot(1, angle)


def rotz(angle: ArrayLike) -> Array:
    """Rotations about z, shape ``S + (3, 3)`` for angles (rad) shaped ``S``."""
    return rot(2, angle)


def homogeneous(R: ArrayLike | None = None, p: ArrayLike | None = None) -> Array:
    """Assemble homogeneous transforms from rotations ``(..., 3, 3)`` and positions ``(..., 3)``.

    Either may be omitted (identity rotation or zero translation).  The batch shapes
    broadcast.
    """
    R = np.eye(3) if R is None else np.asarray(R, dtype=float)
    p = np.zeros(3) if p is None else np.asarray(p, dtype=float)
    batch = np.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    T = np.zeros((*batch, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def transl(x: ArrayLike = 0.0, y: ArrayLike = 0.0, z: ArrayLike = 0.0) -> Array:
    """Pure translations (m); the arguments broadcast to a batch shape ``S``: ``S + (4, 4)``."""
    x, y, z = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (x, y, z)))
    return homogeneous(p=np.stack([x, y, z], axis=-1))


def elementary(motion: str, value: ArrayLike) -> Array:
    """Elementary transforms ``Tx, Ty, Tz`` (value in m) or ``Rx, Ry, Rz`` (value in rad).

    Returns ``S + (4, 4)`` for values shaped ``S``.
    """
    if motion not in MOTIONS:
        raise ValueError(f"unknown elementary motion {motion!r}; expected one of {MOTIONS}")
    value = np.asarray(value, dtype=float)
    k = "xyz".index(motion[1])
    if motion[0] == "R":
        return homogeneous(R=rot(k, value))
    p = np.zeros((*value.shape, 3))
    p[..., k] = value
    return homogeneous(p=p)


def chain_product(motions: Sequence[str], values: ArrayLike) -> Array:
    """The 4x4 product of elementary transforms ``motions[0](values[0]) @ ...`` (identity
    when empty): the frame of a short chain of constant steps."""
    # on Python floats: numpy's per-step slicing cost ~4 µs a step for these few steps
    R = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]  # rows
    t = [0.0, 0.0, 0.0]
    for motion, value in zip(motions, np.asarray(values, dtype=float).tolist(), strict=True):
        if motion not in MOTIONS:
            raise ValueError(f"motion {motion!r} is not one of {MOTIONS}")
        k = "xyz".index(motion[1])
        if motion[0] == "T":
            t = [t[r] + R[r][k] * value for r in range(3)]
            continue
        i, j = (k + 1) % 3, (k + 2) % 3  # columns i, j of R turn about axis k
        c, s = math.cos(value), math.sin(value)
        for row in R:
            row[i], row[j] = c * row[i] + s * row[j], c * row[j] - s * row[i]
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def zyx_angles(R: ArrayLike) -> tuple[float, float, float]:
    """Intrinsic Z-Y-X angles ``(rz, ry, rx)`` (rad) with ``R = Rz(rz) Ry(ry) Rx(rx)``, in
    closed form (the same as ``matrix_to_euler(R, "ZYX")``, a fraction of its cost for
    one matrix; within 0.06° of gimbal lock, ``|ry| = 90°``, it is that function)."""
    R = np.asarray(R, dtype=float)
    cy = math.hypot(R[0, 0], R[1, 0])  # |cos ry|
    if cy > 1e-3:
        return math.atan2(R[1, 0], R[0, 0]), math.atan2(-R[2, 0], cy), math.atan2(R[2, 1], R[2, 2])
    # near gimbal lock the elements above all shrink with cos ry: scipy's algorithm
    # (Bernardes & Viollet 2022) keeps full accuracy there
    rz, ry, rx = matrix_to_euler(R, "ZYX")
    return float(rz), float(ry), float(rx)


def compose(*transforms: ArrayLike) -> Array:
    """Product ``T1 @ T2 @ ...`` of (batched, broadcasting) homogeneous transforms."""
    if not transforms:
        return np.eye(4)
    out = np.asarray(transforms[0], dtype=float)
    for T in transforms[1:]:
        out = out @ np.asarray(T, dtype=float)
    return out


def inverse(T: ArrayLike) -> Array:
    """Inverse of rigid transforms ``(..., 4, 4)`` using ``Rᵀ`` (no general matrix inverse)."""
    T = np.asarray(T, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return homogeneous(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def skew(v: ArrayLike) -> Array:
    """Skew-symmetric matrices ``[v]x`` shaped ``(..., 3, 3)`` for vectors ``(..., 3)``."""
    v = np.asarray(v, dtype=float)
    S = np.zeros((*v.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def _scipy_rotation() -> type[Rotation]:
    """scipy's ``Rotation``, imported on first use (``scipy.spatial`` would add about 0.15 s to the
    start of every ``robocal`` command)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def _as_rotation(R: ArrayLike) -> tuple[Rotation, tuple[int, ...]]:
    R = np.asarray(R, dtype=float)
    batch = R.shape[:-2]
    return _scipy_rotation().from_matrix(R.reshape(-1, 3, 3)), batch


def rotvec_to_matrix(rotvec: ArrayLike) -> Array:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` (axis * angle, rad)."""
    v = np.asarray(rotvec, dtype=float)
    return _scipy_rotation().from_rotvec(v.reshape(-1, 3)).as_matrix().reshape((*v.shape[:-1], 3, 3))


def matrix_to_rotvec(R: ArrayLike) -> Array:
    """Rotation vectors ``(..., 3)`` (rad) of rotation matrices ``(..., 3, 3)``.

    Closed form ``θ / (2 sin θ) · (R − Rᵀ)^∨`` with ``θ = atan2(sin θ, cos θ)`` (exact to
    first order at θ → 0), a few vector operations instead of scipy's per-call set-up:
    the IK and the pose residuals call it in their inner loops.  Beyond about 172°, where
    the antisymmetric part loses precision, scipy's quaternion route takes over.
    """
    R = np.asarray(R, dtype=float)
    if R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must be shaped (..., 3, 3), got {R.shape}")
    batch = R.shape[:-2]
    M = R.reshape(-1, 3, 3)
    v = np.stack([M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1]], axis=1)
    c = 0.5 * (M[:, 0, 0] + M[:, 1, 1] + M[:, 2, 2] - 1.0)  # cos θ
    s = 0.5 * np.linalg.norm(v, axis=1)  # sin θ
    theta = np.arctan2(s, c)
    tiny = s <= 1e-12
    factor = np.where(tiny, 1.0, theta / np.where(tiny, 1.0, s))  # θ / sin θ -> 1 at θ -> 0
    out = 0.5 * factor[:, None] * v
    near_pi = c < -0.99
    if near_pi.any():
        out[near_pi] = _scipy_rotation().from_matrix(M[near_pi]).as_rotvec()
    return out.reshape((*batch, 3))


def quaternion_to_matrix(quat: ArrayLike) -> Array:
    """Rotation matrices from scalar-first unit quaternions ``(..., 4)`` = (w, x, y, z).

    Quaternions are normalised; a zero quaternion raises ``ValueError``.
    """
    q = np.asarray(quat, dtype=float)
    flat = q.reshape(-1, 4)
    return _scipy_rotation().from_quat(flat[:, [1, 2, 3, 0]]).as_matrix().reshape((*q.shape[:-1], 3, 3))


def matrix_to_quaternion(R: ArrayLike) -> Array:
    """Scalar-first unit quaternions ``(..., 4)`` with ``w >= 0`` of rotation matrices."""
    R = np.asarray(R, dtype=float)
    M = R.reshape(-1, 3, 3)
    if not _is_rotation(M):  # scipy projects other matrices onto rotations (or refuses them)
        rotation, batch = _as_rotation(R)
        return rotation.as_quat(canonical=True)[:, [3, 0, 1, 2]].reshape((*batch, 4))
    return _canonical(_quaternions(M))[:, [3, 0, 1, 2]].reshape((*R.shape[:-2], 4))


# Quaternions and Euler angles of rotation matrices in numpy: the same results as scipy's
# Rotation (tests/test_spatial.py compares them), without importing scipy.spatial, which
# would cost the `robocal fk` command about a third of its start-up.
def _is_rotation(M: Array) -> bool:
    """Whether every ``(3, 3)`` matrix of ``M`` is a rotation to 1e-12."""
    gram = M @ np.swapaxes(M, -1, -2)
    return bool(np.all(np.abs(gram - np.eye(3)) <= 1e-12) and np.all(np.linalg.det(M) > 0))


def _quaternions(M: Array) -> Array:
    """Unit quaternions ``(N, 4)`` (x, y, z, w) of rotations ``(N, 3, 3)`` by Shepperd's method
    (J. Guidance and Control 1, 1978): built from the largest of 4w², 4x², 4y², 4z²."""
    trace = M[:, 0, 0] + M[:, 1, 1] + M[:, 2, 2]
    choice = np.argmax(np.stack([M[:, 0, 0], M[:, 1, 1], M[:, 2, 2], trace], axis=1), axis=1)
    q = np.empty((len(M), 4))
    w = choice == 3
    q[w] = np.stack(
        [M[w, 2, 1] - M[w, 1, 2], M[w, 0, 2] - M[w, 2, 0], M[w, 1, 0] - M[w, 0, 1], 1.0 + trace[w]], axis=1
    )
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        rows = choice == i
        q[rows, i] = 1.0 - trace[rows] + 2.0 * M[rows, i, i]
        q[rows, j] = M[rows, j, i] + M[rows, i, j]
        q[rows, k] = M[rows, k, i] + M[rows, i, k]
        q[rows, 3] = M[rows, k, j] - M[rows, j, k]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _canonical(q: Array) -> Array:
    """``q`` or ``−q`` (x, y, z, w): ``w > 0``, or the first non-zero of x, y, z positive."""
    flip = q[:, 3] < 0
    undecided = q[:, 3] == 0
    for i in range(3):
        flip |= undecided & (q[:, i] < 0)
        undecided &= q[:, i] == 0
    return np.where(flip[:, None], -q, q)


def _euler_from_quaternions(q: Array, seq: str) -> Array:
    """Euler angles ``(N, 3)`` of unit quaternions (x, y, z, w) for scipy's ``seq``, by the
    direct method of Bernardes and Viollet, "Quaternion to Euler angles conversion: a direct,
    general and computationally efficient method", PLoS ONE 17(11), 2022; at gimbal lock the
    third angle is zero (with a warning), as scipy does."""
    extrinsic = seq.islower()
    axes = ["xyz".index(c) for c in seq.lower()]
    i, j, k = axes if extrinsic else axes[::-1]
    symmetric = i == k
    if symmetric:
        k = 3 - i - j
    sign = (i - j) * (j - k) * (k - i) // 2  # +1 for a cyclic (i, j, k), −1 otherwise
    w = q[:, 3]
    if symmetric:
        a, b, c, d = w, q[:, i], q[:, j], q[:, k] * sign
    else:
        a, b, c, d = w - q[:, j], q[:, i] + q[:, k] * sign, q[:, j] + w, q[:, k] * sign - q[:, i]
    angles = np.zeros((len(q), 3))
    angles[:, 1] = 2.0 * np.arctan2(np.hypot(c, d), np.hypot(a, b))
    half_sum, half_diff = np.arctan2(b, a), np.arctan2(d, c)
    near_zero = np.abs(angles[:, 1]) <= 1e-7
    near_pi = np.abs(angles[:, 1] - np.pi) <= 1e-7
    regular = ~(near_zero | near_pi)
    if not regular.all():
        import warnings

        warnings.warn(
            "Gimbal lock detected. Setting third angle to zero since it is not possible to uniquely "
            "determine all angles.",
            UserWarning,
            stacklevel=3,
        )
    first, third = (0, 2) if extrinsic else (2, 0)
    angles[:, 0] = np.where(near_zero, 2.0 * half_sum, 2.0 * half_diff * (-1.0 if extrinsic else 1.0))
    angles[:, first] = np.where(regular, half_sum - half_diff, angles[:, first])
    angles[:, third] = np.where(regular, half_sum + half_diff, angles[:, third])
    if not symmetric:
        angles[:, third] *= sign
        angles[:, 1] -= np.pi / 2
    return (angles + np.pi) % (2.0 * np.pi) - np.pi


def euler_to_matrix(angles: ArrayLike, seq: str = "ZXZ") -> Array:
    """Rotation matrices from Euler angles ``(..., 3)`` (rad) in scipy's ``seq`` convention."""
    a = np.asarray(angles, dtype=float)
    return _scipy_rotation().from_euler(seq, a.reshape(-1, 3)).as_matrix().reshape((*a.shape[:-1], 3, 3))


def matrix_to_euler(R: ArrayLike, seq: str = "ZXZ") -> Array:
    """Euler angles ``(..., 3)`` (rad) of rotation matrices in scipy's ``seq`` convention.

    At gimbal lock the third angle is set to zero, with a warning (as scipy does).
    """
    R = np.asarray(R, dtype=float)
    M = R.reshape(-1, 3, 3)
    valid_seq = (
        isinstance(seq, str)
        and len(seq) == 3
        and (set(seq) <= set("xyz") or set(seq) <= set("XYZ"))
        and seq[0] != seq[1]
        and seq[1] != seq[2]
    )
    if not valid_seq or not _is_rotation(M):  # scipy's messages, or its projection onto rotations
        rotation, batch = _as_rotation(R)
        return rotation.as_euler(seq).reshape((*batch, 3))
    return _euler_from_quaternions(_quaternions(M), seq).reshape((*R.shape[:-2], 3))


def pose_error(T_actual: ArrayLike, T_reference: ArrayLike) -> Array:
    """Pose difference ``actual - reference`` shaped ``(..., 6)``.

    The first three components are the position error ``p_actual - p_reference`` (m),
    the last three the orientation error as a rotation vector in the reference's
    parent frame, ``log(R_actual R_referenceᵀ)`` (rad).  For small errors this is the
    small-angle vector whose first-order model is the identification Jacobian's
    orientation rows.
    """
    Ta = np.asarray(T_actual, dtype=float)
    Tr = np.asarray(T_reference, dtype=float)
    dp = Ta[..., :3, 3] - Tr[..., :3, 3]
    dR = Ta[..., :3, :3] @ np.swapaxes(Tr[..., :3, :3], -1, -2)
    return np.concatenate([dp, matrix_to_rotvec(dR)], axis=-1)


def fit_rigid_transform(P: ArrayLike, Q: ArrayLike, weights: ArrayLike | None = None) -> Array:
    """Least-squares rigid transform ``T_B_A`` mapping points ``P`` (frame A) onto ``Q`` (frame B).

    Minimises ``sum_k w_k |Q_k - (R P_k + t)|²`` over rotations R (det +1) and
    translations t, in closed form (Kabsch/Horn: SVD of the weighted cross-covariance
    of the centred point sets, with the sign correction that excludes reflections).
    Used to reconstruct a tool pose from measured markers and for the initial guess of
    a measuring device's frame.

    Args:
        P: ``(..., m, 3)`` points in frame A (m), ``m >= 3`` not all on one line.
        Q: ``(..., m, 3)`` the same points measured in frame B (m).  The batch shapes
            of ``P`` and ``Q`` broadcast (e.g. one marker layout ``(m, 3)`` against
            ``(n, m, 3)`` measurements).
        weights: optional ``(..., m)`` non-negative weights (e.g. ``1/sigma²``).

    Returns:
        ``(..., 4, 4)`` transforms ``T_B_A`` with ``Q ≈ R P + t``.

    Raises:
        ValueError: on mismatched shapes, fewer than 3 points, negative or all-zero
            weights, non-finite input, or (near-)collinear points, naming the batch index.
    """
    P = np.asarray(P, dtype=float)
    Q = np.asarray(Q, dtype=float)
    if P.ndim < 2 or Q.ndim < 2 or P.shape[-1] != 3 or Q.shape[-1] != 3 or P.shape[-2] != Q.shape[-2]:
        raise ValueError(f"point sets shaped {P.shape} and {Q.shape}; expected (..., m, 3) both")
    m = P.shape[-2]
    if m < 3:
        raise ValueError(f"a rigid fit needs at least 3 points, got {m}")
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(Q))):
        raise ValueError("point sets contain NaN or inf")
    batch = np.broadcast_shapes(P.shape[:-2], Q.shape[:-2])
    if weights is None and not batch:  # one unweighted fit (the calibration's start): plain matmuls
        p0, q0 = P.mean(axis=0), Q.mean(axis=0)
        H = (P - p0).T @ (Q - q0) / m
    else:
        H, p0, q0 = _weighted_cross_covariance(P, Q, weights, batch, m)
    U, s, Vt = np.linalg.svd(H)
    degenerate = s[..., 1] <= 1e-12 * np.maximum(s[..., 0], 1e-300)
    if np.any(degenerate):
        where = np.argwhere(np.atleast_1d(degenerate))[0]
        raise ValueError(
            f"points of fit {tuple(where.tolist()) if batch else ()} are (nearly) collinear; "
            "a rigid transform is not determined"
        )
    V = np.swapaxes(Vt, -1, -2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, -1, -2)))
    V[..., :, 2] *= d[..., None]
    R = V @ np.swapaxes(U, -1, -2)
    t = q0 - np.einsum("...ij,...j->...i", R, p0)
    return homogeneous(R, t)


def _weighted_cross_covariance(
    P: Array, Q: Array, weights: ArrayLike | None, batch: tuple[int, ...], m: int
) -> tuple[Array, Array, Array]:
    """``H = Σ w p qᵀ`` of the centred point sets ``(..., 3, 3)`` and the weighted
    centroids ``(..., 3)`` of ``P`` and ``Q`` (weights normalised to sum 1)."""
    if weights is None:
        w = np.ones((*batch, m))
    else:
        w = np.broadcast_to(np.asarray(weights, dtype=float), (*batch, m))
        if np.any(~np.isfinite(w)) or np.any(w < 0) or np.any(w.sum(axis=-1) <= 0):
            raise ValueError("weights must be finite, >= 0 and not all zero")
    wn = w / w.sum(axis=-1, keepdims=True)
    p0 = np.einsum("...k,...ki->...i", wn, np.broadcast_to(P, (*batch, m, 3)))
    q0 = np.einsum("...k,...ki->...i", wn, np.broadcast_to(Q, (*batch, m, 3)))
    Pc = P - p0[..., None, :]
    Qc = Q - q0[..., None, :]
    H = np.einsum("...k,...ki,...kj->...ij", wn, Pc, Qc)  # (..., 3, 3) = sum w p q^T
    return H, p0, q0


def parse_vector(text: str, count: int | tuple[int, ...] | None = None) -> NDArray[np.float64]:
    """The one parser of robocal for a vector typed as text (``"x,y,z"``, ``"0, -90, 90"``,
    ``"1 2 3"``; commas, semicolons and white space separate): a float array ``(n,)``.

    Args:
        text: the numbers as typed.
        count: the number of values required (or the allowed numbers), None for any.

    Raises:
        ValueError: a message without the option's name (the caller adds it): not numbers,
            the wrong count, or a value that is not finite.
    """
    parts = text.replace(",", " ").replace(";", " ").split()
    try:
        values = np.array([float(v) for v in parts], dtype=float)
    except ValueError:
        raise ValueError("the values must be numbers separated by commas or spaces") from None
    allowed = (count,) if isinstance(count, int) else count
    if allowed is not None and len(values) not in allowed:
        expected = " or ".join(str(n) for n in allowed)
        raise ValueError(f"expected {expected} numbers, got {len(values)} values")
    if not np.all(np.isfinite(values)):
        raise ValueError("the values must be finite numbers (no nan or inf)")
    return values
