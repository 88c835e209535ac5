"""Clearance identified by default from tilt rows (issue 33): the thesis' Katana set-up gives
Table 4.3's clearances through ``robocal calibrate`` with no ``--effects``; on a UR10 at
random configurations the clearances of the parallel joints, whose bending moment keeps its
side at every configuration (a fixed tilt the sensors' zeros and the geometry carry too),
are held by name with that reason while the geometry stays free (the pruning held
``alpha1`` before and left the readings at 9x their noise), and the clearances the rows do
see are identified at the Cramér–Rao bound."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.experiments.seed003_inclinometer import THESIS_TABLE_5_2
from robocal.experiments.seed003_tilt_rows import thesis_tilt_file, tilt_rows_tables
from robocal.identify.constraints.effect_groups import held_for
from robocal.identify.constraints.fit import build_constraint_problem, calibrate_constraints
from robocal.identify.constraints.tilt_rows import EFFECT_KINDS, PLAN_TRIES, fixed_tilt_joints
from robocal.identify.options import Pruning
from robocal.measure.constraints.sim import simulate_tilt_rows
from robocal.measure.true_model import draw_true_model
from robocal.model.joints import effects_from_values

SIGMA = np.radians(0.001)  # simulate_tilt_rows' default noise (rad)
PARALLEL = ("shoulder_lift", "elbow", "wrist_1")  # the UR10's horizontal parallel joints


@pytest.fixture(scope="module")
def ur10():
    return rc.calibration_model("ur10")


def _true(ur10, effects: dict[tuple[str, str], float]):
    robot = draw_true_model(ur10, length="1mm", angle="0.1deg", seed=7)
    return dataclasses.replace(robot, joint_effects=tuple(effects_from_values(robot, effects, start=())))


def _held(result) -> dict[str, str]:
    return {d.name: d.detail for d in result.dropped if d.reason == "poorly identifiable"}


def test_the_thesis_setup_gives_its_clearances_without_effects_option(tmp_path):
    """``robocal calibrate katana450 --data thesis.csv``: Table 4.3's five clearance tilts
    (and Table 4.4's backlashes) identified, each within 3σ and 0.002° of the thesis."""
    path, out = tmp_path / "thesis.csv", tmp_path / "out"
    thesis_tilt_file(path)
    result = CliRunner().invoke(app, ["calibrate", "katana450", "--data", str(path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    tables = tilt_rows_tables(out)
    for key in ("clearance_tilt_deg", "backlash_deg"):
        for row, thesis in zip(tables[key], THESIS_TABLE_5_2[key], strict=True):
            if row["one_fit"] is None:
                assert key == "backlash_deg" and row["joint"] == "q1", row  # a vertical axis: no torque
                continue
            estimate, sigma = row["one_fit"]
            assert abs(estimate - thesis) <= min(3 * sigma, 0.002), (key, row)
    identified = [r["joint"] for r in tables["clearance_tilt_deg"] if r["one_fit"]]
    assert identified == ["q1", "q2", "q3", "q4", "q5"]


def test_the_default_kinds_include_clearance():
    assert "clearance" in EFFECT_KINDS
    from robocal.workflow.constraints import ConstraintRequest

    fields = {f.name: f.default for f in dataclasses.fields(ConstraintRequest)}
    assert "clearance" in fields["tilt_kinds"]


def test_fixed_tilt_joints_are_the_parallel_joints_of_a_ur10_not_the_thesis_katana(ur10, tmp_path):
    """On a UR10 under gravity the bending moment of its parallel joints keeps its side at any
    configuration (the links' offsets along those axes); the thesis' designed Katana
    configurations put each joint's moment on both sides."""
    from robocal.experiments.seed003_inclinometer import katana_robots

    data = simulate_tilt_rows(ur10, 40, seed=11)
    fixed = fixed_tilt_joints(build_constraint_problem(ur10, data).tilt, data)
    assert set(PARALLEL) <= set(fixed) and "shoulder_pan" not in fixed  # joint 1's moment turns with the arm
    katana = katana_robots().nominal
    plan = simulate_tilt_rows(katana, 0, configurations=thesis_tilt_file(tmp_path / "thesis.csv"))
    assert fixed_tilt_joints(build_constraint_problem(katana, plan).tilt, plan) == ()


def test_random_ur10_holds_the_parallel_clearances_by_name_and_keeps_the_geometry(ur10):
    """No joint effects in the truth, 20 random configurations, the default kinds with the
    pruning: the three parallel clearances are held (each named, with what poses would
    separate it), ``alpha1`` is identified and the readings are fitted to their noise."""
    true = _true(ur10, {})
    data = simulate_tilt_rows(true, 20, seed=3)
    result = calibrate_constraints(ur10, data, known_noise=True, pruning=Pruning())
    held = _held(result)
    for joint in PARALLEL:
        name = f"clearance_{joint}"
        assert name in held and name not in result.names
        assert joint in held[name]  # the reason names the joint whose moment keeps its side
    assert "alpha1" in result.names and "alpha1" not in held
    assert "clearance_shoulder_pan" in result.names
    assert result.rms_after < 1.2 * SIGMA
    # the plan: one note names the joints; none of the robot's configurations turns their
    # moment over under its own weight (the links' offsets along the axes), so it says so
    plan = [n for n in result.notes if all(j in n for j in PARALLEL)]
    assert len(plan) == 1 and str(PLAN_TRIES) in plan[0]


def test_separable_clearances_at_the_cramer_rao_bound(ur10):
    """A UR10 with clearance at joints 1 and 5 and compliance at 2 and 3, 6 draws of 30 random
    configurations: every identified parameter's (estimate − truth)/σ has an RMS ≤ 1.2 and
    none beyond 5σ; both clearances identified."""
    effects = {("clearance", "shoulder_pan"): np.radians(0.02), ("clearance", "wrist_2"): np.radians(0.03),
               ("compliance", "shoulder_lift"): 2e-6, ("compliance", "elbow"): 3e-6}  # fmt: skip
    true = _true(ur10, effects)
    truth = dict(zip(true.names, true.values.tolist(), strict=True))
    truth |= {f"{k}_{j}": v for (k, j), v in effects.items()}
    z = []
    for run in range(6):
        result = calibrate_constraints(ur10, simulate_tilt_rows(true, 30, seed=run), known_noise=True,
                                       pruning=Pruning())  # fmt: skip
        assert result.success and {"clearance_shoulder_pan", "clearance_wrist_2"} <= set(result.names)
        rows = [k for k, n in enumerate(result.names) if not n.startswith("tilt_zero_")]
        est = result.estimates[rows]
        z.append((est - np.array([truth.get(result.names[k], 0.0) for k in rows])) / result.std[rows])
    z_all = np.concatenate(z)
    assert np.sqrt(np.mean(z_all**2)) <= 1.2 and np.abs(z_all).max() < 5.0


def test_a_true_fixed_tilt_clearance_is_held_not_invented(ur10):
    """A true clearance at the elbow (0.03°: its moment keeps its side) is carried by the
    geometry and the zeros: held by name, no clearance estimate, the readings fitted to their
    noise and the other joint effects within 4σ of the truth."""
    effects = {("clearance", "elbow"): np.radians(0.03), ("compliance", "shoulder_lift"): 2e-6}
    true = _true(ur10, effects)
    data = simulate_tilt_rows(true, 30, seed=21)
    result = calibrate_constraints(ur10, data, known_noise=True, pruning=Pruning())
    assert "clearance_elbow" in _held(result) and "clearance_elbow" not in result.names
    assert result.rms_after < 1.2 * SIGMA
    truth = {f"{k}_{j}": v for (k, j), v in effects.items()}
    for k, name in enumerate(result.names):
        if name.startswith(("clearance_", "backlash_", "compliance_")):
            assert abs(result.estimates[k] - truth.get(name, 0.0)) < 4 * result.std[k], name


def test_the_pruning_holds_the_effect_not_the_geometry_it_trades_with():
    """Two unknowns, a chain angle and a clearance, nearly the same column: the pruning's
    worst is the angle, and what is held is the clearance (named with the angle)."""
    names = ["alpha1", "clearance_elbow", "theta2"]
    J = np.array([[1.0, 1.0, 0.0], [1.0, 1.0 + 1e-4, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
    cov = np.linalg.inv(J.T @ J) * 1e-8
    scale = np.ones(3)
    held, records = held_for(names, 0, float(np.sqrt(cov[0, 0])), cov, scale, 1e-4)
    assert held == [1] and [d.name for d in records] == ["clearance_elbow"]
    assert "alpha1" in records[0].detail
    # a chain angle alone (no effect in its poor combination) is held itself
    held, records = held_for(["alpha1", "theta2"], 0, 1.0, np.diag([1.0, 1e-12]), np.ones(2), 1e-4)
    assert held == [0] and records[0].name == "alpha1"
