"""The numpy path used while numba's cache is cold (robocal.model.kernel_mode,
robocal.identify.kernel_cache.choose_path): the same calibrations as the compiled kernels to
round-off, and a cold cache choosing it (and starting the warm-up) for the process."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import robocal as rc
from robocal.identify import fused, kernel_cache
from robocal.identify.kernels import numpy_path
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses
from robocal.model import chain_compiled, kernel_mode
from robocal.model.rank import sequential_test_numpy

pytest.importorskip("numba")


def _data(name: str, n: int, seed: int):
    model = rc.robot(name)
    device = LaserTracker(p_tool_target=np.array([0.05, 0.0, 0.109]), sigma=20e-6)
    true = draw_true_model(model, seed=seed)
    poses = random_poses(model, n, seed=seed + 1)
    return model, simulate(VirtualRobot(model, true, device), poses, seed=seed + 2)


@pytest.mark.parametrize(
    ("name", "options"),
    [("ur10", {}), ("ur10", {"compliance": True}), ("kr16", {})],
)
def test_numpy_path_calibrates_as_the_compiled_kernels(monkeypatch, name, options):
    model, data = _data(name, 60, 3)
    compiled = rc.calibrate(model, data, residual="none", **options)
    monkeypatch.delenv(kernel_mode.ENVIRONMENT, raising=False)
    kernel_mode.use_numpy_path(True)
    try:
        numpy = rc.calibrate(model, data, residual="none", **options)
    finally:
        kernel_mode.use_numpy_path(False)
    assert numpy.names == compiled.names
    assert [d.name for d in numpy.dropped] == [d.name for d in compiled.dropped]
    np.testing.assert_allclose(numpy.estimates, compiled.estimates, rtol=0, atol=1e-10)
    np.testing.assert_allclose(numpy.std, compiled.std, rtol=1e-8)
    np.testing.assert_allclose(numpy.residuals, compiled.residuals, rtol=0, atol=1e-10)
    assert numpy.condition_number == pytest.approx(compiled.condition_number, rel=1e-8)
    assert numpy.iterations == compiled.iterations


def test_a_cold_cache_chooses_the_numpy_path_and_starts_the_warm_up(monkeypatch):
    monkeypatch.delenv(kernel_mode.ENVIRONMENT, raising=False)
    started = []
    monkeypatch.setattr(kernel_cache, "warm_up", lambda: started.append(True))
    monkeypatch.setattr(kernel_cache, "kernels_to_compile", lambda: ["robocal.model.kernels.forward"])
    try:
        assert kernel_cache.choose_path()
        assert started == [True] and not kernel_mode.compiled_wanted()
        assert kernel_cache.stage_kernels() is numpy_path and kernel_cache.start_kernels() is numpy_path
        assert chain_compiled.load_kernels(None) is None  # the chain's numpy path
        assert chain_compiled.load_kernels(True) is not None  # asked for by name: still there
        model, data = _data("ur10", 30, 5)
        run_applies = []
        original = fused.applies
        monkeypatch.setattr(fused, "applies", lambda *args: run_applies.append(original(*args)) or False)
        rc.calibrate(model, data, residual="none")
        assert run_applies == [False]  # the compiled stages are not chosen
    finally:
        kernel_mode.use_numpy_path(False)
    assert kernel_mode.compiled_wanted()


def test_a_warm_cache_or_the_environment_keeps_the_choice(monkeypatch):
    started = []
    monkeypatch.setattr(kernel_cache, "warm_up", lambda: started.append(True))
    monkeypatch.delenv(kernel_mode.ENVIRONMENT, raising=False)
    monkeypatch.setattr(kernel_cache, "kernels_to_compile", list)  # all cached
    assert not kernel_cache.choose_path() and kernel_mode.compiled_wanted()
    monkeypatch.setattr(kernel_cache, "kernels_to_compile", lambda: ["x.y"])
    monkeypatch.setenv(kernel_mode.ENVIRONMENT, "compiled")  # the warm-up process itself
    assert not kernel_cache.choose_path() and kernel_mode.compiled_wanted()
    monkeypatch.setenv(kernel_mode.ENVIRONMENT, "numpy")
    assert not kernel_mode.compiled_wanted()
    assert started == []


def test_the_warm_up_script_and_its_lock(monkeypatch, tmp_path):
    compile(kernel_cache._WARM_UP, "<warm-up>", "exec")  # the script the warm-up process runs
    lock = tmp_path / "warm-up.lock"
    monkeypatch.setattr(kernel_cache, "warm_up_lock", lambda: lock)
    assert kernel_cache.wait_for_warm_up() is None  # none ran
    lock.write_text("41.5")
    assert kernel_cache.wait_for_warm_up() == pytest.approx(41.5)


# ---------------------------------------------------------------------- kernel by kernel
def _problem(seed, m=240, p=14):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, p)) * np.logspace(0, 2, p)
    J[:, 3] = J[:, 4] + 1e-3 * rng.normal(size=m) * np.linalg.norm(J[:, 4]) / m**0.5
    J[:, 7] *= 1e-4
    r = J @ rng.normal(scale=1e-4, size=p) + rng.normal(scale=1e-3, size=m)
    return r, J


@pytest.mark.parametrize("seed", range(3))
def test_stage_functions_match_the_compiled_kernels(seed):
    import robocal.identify.kernels.stage as compiled
    from robocal.identify.rules import Rules

    r, J = _problem(seed)
    rules = Rules()
    G, g, rr = J.T @ J, J.T @ r, float(r @ r)
    scale = np.full(J.shape[1], 0.5)
    for known in (False, True):
        counts, outs = [], []
        for kernels in (compiled, numpy_path):
            columns, sigmas = np.empty(J.shape[1], dtype=np.intp), np.empty(J.shape[1])
            count = kernels.screen(G, g, rr, len(r), scale, rules.screening(known), columns, sigmas)
            counts.append(count)
            outs.append((columns[:count], sigmas[:count]))
        assert counts[0] == counts[1] > 0
        np.testing.assert_array_equal(outs[0][0], outs[1][0])
        np.testing.assert_allclose(outs[0][1], outs[1][1], rtol=1e-9)
    row_s2 = np.where(np.arange(len(r)) % 6 < 3, 1.0, 4.0)
    for uniform in (True, False):
        a = compiled.covariance(J, row_s2, uniform, rules.covariance_singular)
        b = numpy_path.covariance(J, row_s2, uniform, rules.covariance_singular)
        assert a[4] and b[4]
        for x, y in zip(a[:3], b[:3], strict=True):
            np.testing.assert_allclose(y, x, rtol=1e-8, atol=1e-14)
        assert b[3] == pytest.approx(a[3], rel=1e-8)


@pytest.mark.parametrize("seed", range(4))
def test_rank_test_matches_the_compiled_kernel(seed):
    from robocal.model.rank_kernels import sequential_test

    rng = np.random.default_rng(seed)
    A = rng.normal(size=(60, 8)) @ rng.normal(size=(8, 12))  # rank 8 of 12
    A /= np.linalg.norm(A, axis=0)
    qr = scipy.linalg.lapack.dgeqrf(A)[0]
    want, got = sequential_test(qr, 1e-7), sequential_test_numpy(qr, 1e-7)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    np.testing.assert_allclose(got[2], want[2], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(got[3], want[3], atol=1e-10)
    assert got[4] == want[4]
    assert sequential_test_numpy(np.zeros((5, 3)), 1e-7)[4] is False


def test_start_values_match_the_compiled_kernel():
    import robocal.identify.kernels.start as compiled

    rng = np.random.default_rng(0)
    K, n = 2, 20
    T_flange = np.tile(np.eye(4), (K, n, 1, 1))
    T_flange[..., :3, :3] = rc.spatial.rotvec_to_matrix(rng.normal(0.0, 1.5, (K, n, 3)))
    T_flange[..., :3, 3] = rng.uniform(-1.0, 1.0, (K, n, 3))
    position = rng.uniform(-1.0, 1.0, (K, n, 3))
    outs = []
    for kernels in (compiled, numpy_path):
        frames, tools = np.tile(np.eye(4), (K, 1, 1)), np.tile(np.eye(4), (K, 1, 1))
        status = kernels.frames_and_tools(T_flange, position, np.zeros((1, 1, 3, 3)), False, frames, tools,
                                          True, True, 4)  # fmt: skip
        outs.append((status, frames, tools))
    assert outs[0][0] == outs[1][0] == numpy_path.OK
    np.testing.assert_allclose(outs[1][1], outs[0][1], atol=1e-10)
    np.testing.assert_allclose(outs[1][2], outs[0][2], atol=1e-10)
    collinear = np.zeros_like(position)
    collinear[1, :, 0] = np.linspace(0.0, 1.0, n)
    frames, tools = np.tile(np.eye(4), (K, 1, 1)), np.tile(np.eye(4), (K, 1, 1))
    T_fixed = np.tile(np.eye(4), (K, n, 1, 1))
    T_fixed[..., :3, 3] = collinear
    status = numpy_path.frames_and_tools(T_fixed, collinear, np.zeros((1, 1, 3, 3)), False, frames, tools,
                                         True, False, 1)  # fmt: skip
    assert status >= numpy_path.COLLINEAR
