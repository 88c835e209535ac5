"""Issue 33: joint compliance on the position rows of a constraint fit (ball in socket).

A virtual robot whose joints yield to gravity (known compliances, its catalog link masses)
seats its ball in two sockets; the fit with ``effects=("compliance",)`` recovers the
compliances within their Cramér-Rao bound, predicts held-out rows with the deflections,
and refuses a model without link masses by name."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import robocal as rc
from robocal.identify.constraints.figures import deflections
from robocal.identify.constraints.fit import (
    build_constraint_problem,
    calibrate_constraints,
    constraint_figures,
)
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.measure.ik import solve_ik
from robocal.model.joints import effects_from_values

SIGMA = 2e-5  # m: the tool point's noise per axis
TRUE_COMPLIANCE = {"q2": 4e-5, "q3": 6e-5, "q4": 1e-4}  # rad/(N·m): up to 5 mrad under gravity


@pytest.fixture(scope="module")
def ur10():
    return rc.calibration_model("ur10")


def _elastic(model, compliance: dict[str, float]):
    names = model.joint_names
    values = {("compliance", names[int(k[1:]) - 1]): v for k, v in compliance.items()}
    return dataclasses.replace(model, joint_effects=effects_from_values(model, values, start=()))


def _seat(true, sockets: np.ndarray, q0: np.ndarray, rng) -> np.ndarray:
    """Joint values whose deflected tool point sits at its socket plus noise (IK, then the
    deflection at the new joint values taken off the target, a few rounds)."""
    target = sockets + rng.normal(0.0, SIGMA, sockets.shape)
    q = q0
    for _ in range(4):
        bend = true.fk(q, perturbations=deflections(true, q))[:, :3, 3] - true.fk(q)[:, :3, 3]
        q = solve_ik(true, target - bend, kind="position", q0=q, restarts=0, tol=1e-12).q
    return q


def _sockets_data(true, n: int, seed: int) -> ConstraintSet:
    """``n`` configurations per socket of two sockets 50 mm apart, spread over the workspace."""
    rng = np.random.default_rng(seed)
    q_mid = np.array([0.3, -1.2, 1.4, -1.6, -1.5, 0.2])
    centre = true.fk(q_mid[None])[0, :3, 3]
    sockets = np.array([centre, centre + [0.05, 0.0, 0.0]])
    label = np.repeat([0, 1], n)
    q0 = q_mid + rng.normal(0.0, [0.5, 0.3, 0.3, 0.6, 0.6, 0.8], (2 * n, 6))
    q = _seat(true, sockets[label], q0, rng)
    return ConstraintSet(q, label, -np.ones(2 * n, dtype=int), point_pairs=[[0, 1]], point_length=[0.05],
                         sigma=SIGMA)  # fmt: skip


def _fit(model, data):
    return calibrate_constraints(model, data, effects=("compliance",), known_noise=True, level=1)


def test_compliance_recovered_within_its_cramer_rao_bound(ur10):
    true = _elastic(ur10, TRUE_COMPLIANCE)
    names = {f"compliance_{ur10.joint_names[int(k[1:]) - 1]}": v for k, v in TRUE_COMPLIANCE.items()}
    z = []
    for seed in range(20):
        result = _fit(ur10, _sockets_data(true, 25, seed))
        assert result.success
        for name, value in names.items():
            k = result.names.index(name)  # identified, not dropped
            z.append((result.estimates[k] - value) / result.std[k])
    z = np.array(z)
    # the errors are the bound's size: neither biased nor beyond their sigma (60 draws, 3 per data set)
    assert np.sqrt(np.mean(z**2)) < 1.3
    assert abs(np.mean(z)) < 3 / np.sqrt(len(z)) + 0.3


def test_held_out_rows_are_predicted_with_the_deflections(ur10):
    true = _elastic(ur10, TRUE_COMPLIANCE)
    train, test = _sockets_data(true, 25, 10), _sockets_data(true, 25, 11)
    elastic = _fit(ur10, train)
    rigid = calibrate_constraints(ur10, train, known_noise=True, level=1)
    assert elastic.model.joint_effects  # the calibrated model carries its compliances
    spread = constraint_figures(elastic.model, test).point_spread
    assert np.all(spread < 3 * SIGMA)  # the noise's size: the deflections are explained
    assert np.all(constraint_figures(rigid.model, test).point_spread > spread)


def test_no_masses_no_compliance(ur10):
    bare = dataclasses.replace(ur10, bodies=())
    data = _sockets_data(_elastic(ur10, {}), 5, 3)
    with pytest.raises(ValueError, match="mass"):
        build_constraint_problem(bare, data, effects=("compliance",))
    with pytest.raises(ValueError, match="clearance"):
        build_constraint_problem(ur10, data, effects=("clearance",))


def test_sockets_and_tilt_rows_share_one_compliance(ur10):
    """A mixed fit: the tilt rows' compliance unknown is the socket rows' too (one name, one
    column), and the sockets' deflections sharpen it beyond the tilt rows' own."""
    from robocal.measure.constraints.data_set import merge_sets
    from robocal.measure.constraints.sim import level_mounts, simulate_tilt_rows

    true = _elastic(ur10, TRUE_COMPLIANCE)
    sockets = _sockets_data(true, 25, 21)
    tilts = simulate_tilt_rows(true, 15, links=(2, 3), seed=21, mounts=level_mounts(ur10, (2, 3)))
    mixed = merge_sets(sockets, tilts)
    kinds = ("compliance",)
    alone = calibrate_constraints(ur10, tilts, known_noise=True, level=1, tilt_kinds=kinds)
    both = calibrate_constraints(ur10, mixed, known_noise=True, level=1, tilt_kinds=kinds, effects=kinds)
    name = f"compliance_{ur10.joint_names[2]}"
    assert both.names.count(name) == 1
    k, j = both.names.index(name), alone.names.index(name)
    assert abs(both.estimates[k] - TRUE_COMPLIANCE["q3"]) < 4 * both.std[k]
    assert both.std[k] < alone.std[j]
    assert not any("tilt rows only" in note for note in both.notes)  # the sockets carry it too


def test_a_models_stated_compliance_is_held_and_predicts(ur10):
    """A model that states its compliances (and masses) is calibrated with them held: the
    socket rows are predicted with the deflections, the values kept, none fitted."""
    true = _elastic(ur10, TRUE_COMPLIANCE)
    train, test = _sockets_data(true, 25, 30), _sockets_data(true, 25, 31)
    result = calibrate_constraints(true, train, known_noise=True, level=1)
    assert not any(n.startswith("compliance_") for n in result.names)  # held, not fitted
    assert result.model.joint_effects == true.joint_effects
    assert np.all(constraint_figures(result.model, test).point_spread < 3 * SIGMA)
    rigid = calibrate_constraints(ur10, train, known_noise=True, level=1)
    assert result.rms_after < 0.5 * rigid.rms_after  # the deflections explain the rows
