"""The compiled start values (robocal.identify.kernels.start, numba, behind
robocal.identify.stages.initial_frames_and_tools) against the numpy implementation they
replaced, kept here as the reference: K = 1 and K > 1, position and pose data, every
fit_frame / fit_tool combination, given tools and frames, to 1e-12; and the same errors."""

import numpy as np
import pytest

import robocal as rc
from robocal.identify.stages import initial_frames_and_tools

pytest.importorskip("numba")

TOL = 1e-12


# ---------------------------------------------------------------------- the numpy reference
def _project_rotations(M):
    """The nearest rotations ``(..., 3, 3)`` to matrices ``M`` (SVD, det +1)."""
    U, _, Vt = np.linalg.svd(M)
    flip = np.linalg.det(U @ Vt) < 0
    U[flip, :, -1] *= -1
    return U @ Vt


def _rigid_fits(P, Q):
    """``(K, 4, 4)`` least-squares rigid transforms mapping ``P`` onto ``Q`` (``(K, n, 3)``)."""
    K, n = P.shape[:2]
    p0, q0 = P.mean(axis=1), Q.mean(axis=1)
    H = np.swapaxes(P - p0[:, None], 1, 2) @ (Q - q0[:, None]) / n
    U, s, Vt = np.linalg.svd(H)
    degenerate = s[:, 1] <= 1e-12 * np.maximum(s[:, 0], 1e-300)
    if np.any(degenerate):
        where = int(np.flatnonzero(degenerate)[0])
        raise ValueError(
            f"points of fit ({where},) are (nearly) collinear; a rigid transform is not determined"
        )
    V = np.swapaxes(Vt, 1, 2)
    Ut = np.swapaxes(U, 1, 2)
    V[:, :, 2] *= np.sign(np.linalg.det(V @ Ut))[:, None]
    T = np.zeros((K, 4, 4))
    T[:, :3, :3] = V @ Ut
    T[:, :3, 3] = q0 - (T[:, :3, :3] @ p0[..., None])[..., 0]
    T[:, 3, 3] = 1.0
    return T


def reference(
    T_flange,
    position,
    *,
    orientation=None,
    T_tool=None,
    T_frame=None,
    fit_frame=True,
    fit_tool=True,
    rounds=4,
):
    """initial_frames_and_tools as numpy computed it before the kernel (main at e55c00d)."""
    K, n = T_flange.shape[:2]
    T_tool = np.array(np.broadcast_to(np.eye(4) if T_tool is None else T_tool, (K, 4, 4)), dtype=float)
    T_frame = np.array(np.broadcast_to(np.eye(4) if T_frame is None else T_frame, (K, 4, 4)), dtype=float)
    R_f, p_f = T_flange[..., :3, :3], T_flange[..., :3, 3]
    R_fT = np.swapaxes(R_f, -1, -2)
    y = np.asarray(position, dtype=float)
    if fit_frame and not np.all(np.isfinite(y)):
        raise ValueError("point sets contain NaN or inf")
    for _ in range(rounds if (fit_frame and fit_tool) else 1):
        if fit_frame:
            p_base = (R_f @ T_tool[:, None, :3, 3:])[..., 0] + p_f
            T_frame = _rigid_fits(p_base, y)
        if fit_tool:
            R0, t0 = T_frame[:, :3, :3], T_frame[:, :3, 3]
            b = (y - t0[:, None, :]) @ R0 - p_f
            T_tool[:, :3, 3] = (R_fT @ b[..., None]).sum(axis=1)[..., 0] / n
            if orientation is not None:
                R = R0[:, None] @ R_f
                T_tool[:, :3, :3] = _project_rotations(np.einsum("anji,anjk->aik", R, orientation))
    return T_frame, T_tool


# ---------------------------------------------------------------------- data
def random_frames(rng, shape, spread=1.0):
    R = rc.spatial.rotvec_to_matrix(rng.normal(0.0, spread, (*shape, 3)))
    T = np.zeros((*shape, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = rng.uniform(-1.0, 1.0, (*shape, 3))
    T[..., 3, 3] = 1.0
    return T


def measurements(K, n, seed, noise=1e-4):
    """Flange frames ``(K, n, 4, 4)``, positions and orientations of random true device
    frames and tools, with noise (so the alternation has something left to do)."""
    rng = np.random.default_rng(seed)
    T_flange = random_frames(rng, (K, n), spread=1.5)
    F, X = random_frames(rng, (K,)), random_frames(rng, (K,), spread=0.3)
    X[:, :3, 3] *= 0.2
    T = F[:, None] @ T_flange @ X[:, None]
    position = T[..., :3, 3] + rng.normal(0.0, noise, (K, n, 3))
    orientation = T[..., :3, :3] @ rc.spatial.rotvec_to_matrix(rng.normal(0.0, noise, (K, n, 3)))
    return T_flange, position, orientation, F, X


def close(got, want):
    for a, b in zip(got, want, strict=True):
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=0, atol=TOL)


# ---------------------------------------------------------------------- agreement
@pytest.mark.parametrize("K", [1, 5])
@pytest.mark.parametrize("pose", [False, True], ids=["position", "pose"])
@pytest.mark.parametrize(
    "fit",
    [(True, True), (True, False), (False, True), (False, False)],
    ids=["frame+tool", "frame", "tool", "neither"],
)
def test_kernel_matches_numpy(K, pose, fit):
    fit_frame, fit_tool = fit
    T_flange, position, orientation, F, X = measurements(K, 37, seed=K + 10 * pose)
    rng = np.random.default_rng(3)
    starts = [
        {},
        {"T_tool": random_frames(rng, ())},  # one (4, 4) for all robots
        {"T_tool": X + 0.01, "T_frame": F},  # per robot (not even rigid: used as given)
        {"T_frame": random_frames(rng, (K,)), "rounds": 7},
        {"T_tool": X, "rounds": 1},
    ]
    for kw in starts:
        args = dict(orientation=orientation if pose else None, fit_frame=fit_frame, fit_tool=fit_tool, **kw)
        got = initial_frames_and_tools(T_flange, position, **args)
        close(got, reference(T_flange, position, **args))


def test_kernel_recovers_the_true_frame_and_tool():
    T_flange, position, orientation, F, X = measurements(3, 60, seed=1, noise=0.0)
    T_frame, T_tool = initial_frames_and_tools(T_flange, position, orientation=orientation, rounds=20)
    np.testing.assert_allclose(T_frame, F, atol=1e-9)
    np.testing.assert_allclose(T_tool, X, atol=1e-9)


def test_planar_points_and_inputs_of_other_layouts():
    """Points in a plane (rank-2 cross-covariance: the reflection is corrected), strided
    and float32 inputs, and the input arrays untouched."""
    T_flange, _, orientation, F, X = measurements(2, 30, seed=4)
    T_flange[..., 2, 3] = 0.1
    T_flange[..., :3, :3] = np.eye(3)
    position = (F[:, None] @ T_flange @ X[:, None])[..., :3, 3]
    assert np.linalg.matrix_rank(position[0] - position[0].mean(axis=0), tol=1e-9) == 2
    X_in = X.copy()
    args = dict(T_tool=X_in, orientation=orientation)
    close(initial_frames_and_tools(T_flange, position, **args), reference(T_flange, position, **args))
    np.testing.assert_array_equal(X_in, X)
    wide = np.zeros((2, 60, 4, 4))
    wide[:, ::2] = T_flange
    close(
        initial_frames_and_tools(wide[:, ::2], position.astype(np.float32)),
        reference(T_flange, position.astype(np.float32)),
    )


# ---------------------------------------------------------------------- errors
def test_errors_are_numpys():
    T_flange, position, orientation, _, _ = measurements(3, 20, seed=2)
    bad = position.copy()
    bad[1, 4, 2] = np.nan
    for kw in ({}, {"rounds": 0}, {"fit_tool": False}):
        with pytest.raises(ValueError, match=r"^point sets contain NaN or inf$"):
            initial_frames_and_tools(T_flange, bad, **kw)
    # without a frame fit non-finite points flow through, as they did
    close(initial_frames_and_tools(T_flange, bad, fit_frame=False), reference(T_flange, bad, fit_frame=False))
    line = position.copy()
    line[2] = np.linspace(0.0, 1.0, 20)[:, None] * [0.3, -0.2, 0.5]
    line[0, :, 1] = line[0, :, 0]  # robot 0 not collinear, only on a plane
    message = r"^points of fit \(2,\) are \(nearly\) collinear; a rigid transform is not determined$"
    for f in (initial_frames_and_tools, reference):
        with pytest.raises(ValueError, match=message):
            f(T_flange, line)
    with pytest.raises(np.linalg.LinAlgError, match="SVD did not converge"):
        initial_frames_and_tools(
            T_flange, position, orientation=np.where(position[..., None] > 0.5, np.inf, orientation)
        )
    nan_flange = T_flange.copy()
    nan_flange[0, 3, 0, 0] = np.nan
    with pytest.raises(np.linalg.LinAlgError, match="SVD did not converge"):
        initial_frames_and_tools(nan_flange, position)


# ---------------------------------------------------------------------- the 3x3 SVD by Jacobi
def _lapack_nearest(A):
    U, s, Vt = np.linalg.svd(A)
    if np.linalg.det(U @ Vt) < 0:
        U[:, -1] *= -1
    return U @ Vt, s


def test_jacobi_nearest_rotation_matches_lapack():
    """Random 3x3 matrices over ten decades, rank 2, nearly rotations, and equal smaller
    singular values: the same polar factor and singular values as LAPACK's SVD."""
    from robocal.identify.kernels.start import _nearest_rotation

    rng = np.random.default_rng(11)
    for trial in range(2000):
        A = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-5, 5)
        if trial % 4 == 1:
            A[:, 2] = 0.3 * A[:, 0] - A[:, 1]
        elif trial % 4 == 2:
            A = rc.spatial.rotvec_to_matrix(rng.normal(size=3)) * 100 + rng.normal(size=(3, 3)) * 1e-3
        elif trial % 4 == 3:
            Q1, Q2 = (rc.spatial.rotvec_to_matrix(rng.normal(size=3)) for _ in range(2))
            A = Q1 @ np.diag([3.0, 1.0, 1.0 + 1e-14]) @ Q2
        R = np.full((3, 3), np.nan)
        s0, s1 = _nearest_rotation(A, R)
        R_ref, s_ref = _lapack_nearest(A)
        np.testing.assert_allclose([s0, s1], s_ref[:2], rtol=1e-13, atol=0)
        np.testing.assert_allclose(R, R_ref, rtol=0, atol=1e-12)
    R = np.full((3, 3), np.nan)
    assert _nearest_rotation(np.outer([1.0, 2, 3], [0.5, 0, 1]), R)[1] <= 1e-12  # rank 1: not written
    assert np.isnan(R).all()
    assert _nearest_rotation(np.zeros((3, 3)), R) == (0.0, 0.0)


def test_far_device_and_degenerate_orientation_sums():
    """A device 30 m away (sums reassociated over large coordinates keep 1e-12), and
    orientation sums of rank below 2 (LAPACK decides the rotation, as numpy's did)."""
    T_flange, position, orientation, _, _ = measurements(2, 40, seed=6)
    far = position + np.array([30.0, -20.0, 5.0])
    close(initial_frames_and_tools(T_flange, far), reference(T_flange, far))
    args = dict(orientation=np.zeros_like(orientation), fit_frame=False)
    close(initial_frames_and_tools(T_flange, position, **args), reference(T_flange, position, **args))
    # rank 1: the rotation is not determined (LAPACK's choice); it is still a rotation
    rank1 = np.broadcast_to(np.diag([1.0, 0, 0]), orientation.shape)
    R = initial_frames_and_tools(T_flange, position, orientation=rank1)[1][:, :3, :3]
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


@pytest.mark.parametrize("spread, collinear", [(1e-10, False), (1e-15, True)])
def test_collinearity_threshold_is_numpys(spread, collinear):
    """Measured points on a line up to ``spread`` (relative): s1/s0 ≈ spread against the
    threshold 1e-12 of both implementations."""
    T_flange, _, _, _, _ = measurements(1, 30, seed=8)
    rng = np.random.default_rng(1)
    y = np.linspace(-1.0, 1.0, 30)[:, None] * [0.6, 0.0, 0.8] + spread * rng.normal(size=(30, 3))
    for f in (initial_frames_and_tools, reference):
        if collinear:
            with pytest.raises(ValueError, match="collinear"):
                f(T_flange, y[None], fit_tool=False)
        else:
            T_frame, _ = f(T_flange, y[None], fit_tool=False)
            assert np.isfinite(T_frame).all()


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # numpy's mean of nothing
def test_no_robots_and_no_poses_as_numpy():
    for K, n in ((0, 5), (2, 0)):
        T_flange, y = np.tile(np.eye(4), (K, n, 1, 1)), np.zeros((K, n, 3))
        tool_only = dict(orientation=np.zeros((K, n, 3, 3)), fit_frame=False)
        for kw in ({"fit_frame": False}, tool_only, {} if K == 0 else None):
            if kw is not None:
                close(initial_frames_and_tools(T_flange, y, **kw), reference(T_flange, y, **kw))
    with pytest.raises(np.linalg.LinAlgError, match="SVD did not converge"):  # the mean of no points
        initial_frames_and_tools(np.zeros((1, 0, 4, 4)), np.zeros((1, 0, 3)))


def test_shapes_are_checked_or_broadcast_as_numpy():
    T_flange, position, orientation, _, _ = measurements(3, 10, seed=9)
    one = position[:1]  # one robot's points for all three (broadcast, as numpy's fits did)
    close(initial_frames_and_tools(T_flange, one), reference(T_flange, one))
    for bad in (position[:, :9], position[..., :2]):
        with pytest.raises(ValueError):
            initial_frames_and_tools(T_flange, bad)
    with pytest.raises(ValueError):
        initial_frames_and_tools(T_flange, position, orientation=orientation[:, :9])
    with pytest.raises(ValueError, match=r"T_flange must have shape \(K, n, 4, 4\)"):
        initial_frames_and_tools(T_flange[..., :3, :], position)
