"""The decision rules of a calibration are defined once (robocal.identify.rules) and the
engines decide alike: the staged pipeline, the compiled fused stages and the batched engine
screen, prune and compute the covariance the same way on the test robots, and a changed
rule value changes every path the same way."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import robocal as rc
import robocal.identify.kernels.stage as stage_kernels
from robocal.identify import fused, rules
from robocal.identify.batch import calibrate_batch
from robocal.identify.options import Pruning
from robocal.identify.rules import NO_CANDIDATE, Rules
from robocal.identify.stages import (
    Covariance,
    poorly_identifiable,
    residual_variance,
    screen_unidentifiable,
    uncertainty,
)
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses

TOOL = np.array([0.05, 0.0, 0.109])
TIGHT = Pruning(max_std=1e-7, max_std_ratio=1.3)  # prunes several unknowns


def _data(name: str, n: int, seed: int, sigma: float = 20e-6, q=None):
    model = rc.robot(name)
    device = LaserTracker(p_tool_target=TOOL, sigma=sigma)
    poses = random_poses(model, n, seed=seed + 1) if q is None else q
    return model, simulate(
        VirtualRobot(model, draw_true_model(model, seed=seed), device), poses, seed=seed + 2
    )


def _fused_and_staged(model, data, **options):
    """rc.calibrate through the fused stages (checked to run) and through the staged ones."""
    calls = []
    original = fused.fit
    with pytest.MonkeyPatch.context() as m:
        m.setattr(fused, "fit", lambda *args: calls.append(1) or original(*args))
        compiled = rc.calibrate(model, data, tool_guess=TOOL, **options)
    assert calls, "the fused stages did not run"
    with pytest.MonkeyPatch.context() as m:
        m.setattr(fused, "applies", lambda *args: False)
        staged = rc.calibrate(model, data, tool_guess=TOOL, **options)
    return compiled, staged


def _decisions(result):
    return result.names, [(d.name, d.reason) for d in result.dropped]


def _assert_same(a, b):
    """Same identified set, same dropped unknowns, same covariance to 1e-10."""
    assert _decisions(a) == _decisions(b)
    np.testing.assert_allclose(a.estimates, b.estimates, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=1e-10, atol=1e-10 * np.max(b.std) ** 2)
    np.testing.assert_allclose(a.std, b.std, rtol=1e-10)


@pytest.mark.parametrize(("name", "n", "seed"), [("ur10", 40, 1), ("puma560", 50, 3), ("kr16", 60, 5)])
@pytest.mark.parametrize("pruning", [Pruning(), TIGHT], ids=["default", "tight"])
def test_staged_and_fused_paths_decide_alike(name, n, seed, pruning):
    model, data = _data(name, n, seed)
    compiled, staged = _fused_and_staged(model, data, pruning=pruning)
    _assert_same(compiled, staged)
    if pruning is TIGHT:
        assert sum(d.reason == "poorly identifiable" for d in compiled.dropped) >= 2


def test_batched_engine_decides_as_rc_calibrate():
    model = rc.robot("ur10")
    q = random_poses(model, 30, seed=2)
    data = [_data("ur10", 30, seed, q=q)[1] for seed in (4, 14)]
    # the two robots share their poses, so they are solved as one group: a robot's pruning
    # must not change its group-mate's columns (the batch read a view of the masks it pruned)
    for pruning in (Pruning(), TIGHT, Pruning(max_std=2e-6, max_std_ratio=2.0)):
        fits = calibrate_batch(model, data, tool_guess=TOOL, rules=Rules.of(pruning))
        for d, fit in zip(data, fits, strict=True):
            ref = rc.calibrate(model, d, tool_guess=TOOL, pruning=pruning)
            assert fit.names == ref.names
            assert [(x.name, x.reason) for x in fit.dropped] == [(x.name, x.reason) for x in ref.dropped]
            np.testing.assert_allclose(
                fit.covariance, ref.covariance, rtol=1e-10, atol=1e-10 * np.max(ref.std) ** 2
            )


@pytest.mark.parametrize(
    "changed",
    [
        {"max_std_ratio": 1.3, "max_std": 1e-7},  # pruning
        {"screen_margin": 0.4, "max_std": 1e-6},  # screening before the fit
        {"significance": 0.45},  # the χ² test of the stated noise: the variance factor
    ],
    ids=["pruning", "screening", "variance"],
)
def test_a_changed_rule_changes_every_path_alike(changed):
    model, data = _data("ur10", 40, 8)
    default_compiled, default_staged = _fused_and_staged(model, data)
    compiled, staged = _fused_and_staged(model, data, pruning=dataclasses.replace(Pruning(), **changed))
    _assert_same(default_compiled, default_staged)
    _assert_same(compiled, staged)
    if "significance" in changed:  # same decisions, another variance factor
        assert _decisions(compiled) == _decisions(default_compiled)
        assert not np.allclose(compiled.std, default_compiled.std, rtol=1e-3)
    else:
        assert len(compiled.dropped) > len(default_compiled.dropped)


def test_screening_margin_reaches_the_kernel():
    """The screening rule's margin is the Rules value: with a smaller margin, unknowns the
    default leaves to the pruning after the fit are screened before it."""
    model, data = _data("ur10", 40, 8)
    screened = {}
    for margin in (3.0, 0.4):
        result = rc.calibrate(
            model, data, tool_guess=TOOL, pruning=Pruning(max_std=1e-6, screen_margin=margin)
        )
        screened[margin] = result.diagnostics.evaluations
    assert screened[3.0] != screened[0.4]


def test_pruning_rule_is_one_function():
    """The Python stage and the kernels call the same compiled rule; its plain source is the
    definition (a worst unknown beyond both thresholds; never the last one)."""
    rng = np.random.default_rng(0)
    for _ in range(200):
        move = rng.lognormal(size=rng.integers(1, 9))
        max_std, ratio = float(rng.uniform(0, 2)), float(rng.uniform(1, 4))
        plain = rules.prune_candidate(move, max_std, ratio, 1.0)
        assert stage_kernels.prune_candidate(move, max_std, ratio, 1.0) == plain
        found = poorly_identifiable(move, np.ones_like(move), max_std, ratio)
        assert (found is None) == (plain == NO_CANDIDATE)
        if plain != NO_CANDIDATE:
            assert found[0] == plain == int(np.argmax(move))
            assert move[plain] > max(max_std, ratio * np.median(move))
        elif len(move) > 1:
            assert move.max() <= max(max_std, ratio * np.median(move))


def test_variance_rule_is_one_function():
    for chi2, dof, known in ((3.0, 2, True), (2000.0, 300, True), (290.0, 300, True), (290.0, 300, False)):
        low, high = Rules().chi2_bounds(np.array([float(dof)]))
        plain = rules.variance_factor(chi2, float(dof), known, float(low[0]), float(high[0]))
        assert residual_variance(chi2, dof, known) == plain
        assert stage_kernels.variance_factor(chi2, float(dof), known, float(low[0]), float(high[0])) == plain
    # a stricter test rejects a stated noise the default accepts
    assert residual_variance(270.0, 300, True) == 1.0
    assert residual_variance(270.0, 300, True, significance=0.4) == pytest.approx(0.9)


def test_uncertainty_is_a_named_record():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(60, 4))
    r = rng.normal(size=60)
    cov = uncertainty(r, J, 3)
    assert isinstance(cov, Covariance)
    np.testing.assert_allclose(cov.covariance, cov.variance * np.linalg.inv(J.T @ J), rtol=1e-10)
    np.testing.assert_allclose(cov.std, np.sqrt(np.diag(cov.covariance)), rtol=1e-12)
    assert cov.condition == pytest.approx(np.linalg.cond(J / np.linalg.norm(J, axis=0)), rel=1e-8)


def test_singular_thresholds_are_rules_fields():
    """The thresholds of a numerically singular normal matrix are Rules values handed to the
    kernels: a covariance threshold above every eigenvalue ratio sends a regular problem to
    the SVD path (same covariance and condition number), and a screening threshold that
    calls every block singular leaves every unknown to the fit."""
    rng = np.random.default_rng(3)
    J = rng.normal(size=(90, 5)) * np.array([1.0, 1e-3, 2.0, 1e-2, 1.0])
    r = rng.normal(size=90)
    regular = uncertainty(r, J, 3)
    svd = uncertainty(r, J, 3, rules=Rules(covariance_singular=1.0))
    np.testing.assert_allclose(svd.covariance, regular.covariance, rtol=1e-8, atol=1e-12)
    assert svd.condition == pytest.approx(regular.condition, rel=1e-10)
    # the screening: hopeless columns (σ far beyond the thresholds) screened by default ...
    scale = np.ones(5)
    strict = Rules(max_std=1e-9, max_std_ratio=1.0, screen_margin=1.0)
    assert screen_unidentifiable(r, J, scale, rules=strict)
    # ... and none when every block counts as singular
    assert screen_unidentifiable(r, J, scale, rules=dataclasses.replace(strict, screen_singular=1.0)) == []


def test_condition_number_is_one_function():
    """The compiled covariance reports rules.condition_number of its normal matrix, which is
    cond(J) of the unit-norm columns."""
    rng = np.random.default_rng(4)
    J = rng.normal(size=(60, 6)) * np.logspace(0, 3, 6)
    Jn = J / np.linalg.norm(J, axis=0)
    lam = np.linalg.eigvalsh(Jn.T @ Jn)
    assert rules.condition_number(lam) == pytest.approx(np.linalg.cond(Jn), rel=1e-9)
    *_, cond, ok = stage_kernels.normal_covariance(J.T @ J, 1.0, Rules().covariance_singular)
    assert ok and cond == pytest.approx(rules.condition_number(lam), rel=1e-9)
    assert rules.condition_number(np.array([0.0, 1.0])) == np.inf
    assert rules.condition_number(np.array([])) == np.inf


def test_build_problem_answers_a_frozen_start_and_leaves_the_run_unchanged():
    """Stage 3 is a function of the pass's inputs: it answers a frozen Start (problem,
    stated noise, size, joint effects) and writes nothing into Run but its warnings log."""
    from robocal.identify.options import CalibrationOptions
    from robocal.identify.pipeline import _check_inputs
    from robocal.identify.problem_setup import Run, Start, build_problem

    model, data = _data("ur10", 30, 6)
    sigma = np.full((data.n, 3), 20e-6)
    data = dataclasses.replace(data, sigma=sigma)
    run = _check_inputs(
        model, data, "lm", CalibrationOptions.from_keywords(None, tool_guess=TOOL, level=3), None
    )
    before = {f.name: getattr(run, f.name) for f in dataclasses.fields(Run) if f.name != "warnings"}
    start = build_problem(run, None)
    assert isinstance(start, Start) and start.known_noise and start.length > 0.1
    assert start.problem.n_effects == len(start.effect_names) == len(start.effect_kinds) > 0
    with pytest.raises(dataclasses.FrozenInstanceError):
        start.known_noise = False
    assert {f.name: getattr(run, f.name) for f in dataclasses.fields(Run) if f.name != "warnings"} == before
    assert {f.name for f in dataclasses.fields(Run)} >= {"data", "options"}
    assert not {"problem", "known_noise", "length", "effect_names"} & {
        f.name for f in dataclasses.fields(Run)
    }
