"""Inclinometer readings as a row kind of the constraint fit (issue 33 item 1): the tilt
of a link's joint-frame axes, channel zeros and the joint effects (backlash, compliance)
as unknowns, alone or with tracker rows."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import robocal as rc
from robocal.identify.constraints.fit import (
    build_constraint_problem,
    calibrate_constraints,
    kind_identifiable,
)
from robocal.measure.constraints.data import (
    ConstraintFileError,
    constraint_kind,
    read_constraints,
    write_constraints,
)
from robocal.measure.constraints.data_set import merge_sets
from robocal.measure.constraints.sim import simulate_tilt_rows, simulate_tracker_rows
from robocal.measure.true_model import draw_true_model
from robocal.model.joints import effects_from_values

GAUGE = {"base_x", "base_y", "base_rx", "base_ry", "theta1", "d1"}  # with the device frame
COMPLIANCE = {"shoulder_lift": 2e-6, "elbow": 3e-6}  # rad/(N·m)


@pytest.fixture(scope="module")
def ur10():
    return rc.calibration_model("ur10")


@pytest.fixture(scope="module")
def true(ur10):
    robot = draw_true_model(ur10, length="1mm", angle="0.1deg", seed=7)
    effects = effects_from_values(robot, {("compliance", j): v for j, v in COMPLIANCE.items()}, start=())
    return dataclasses.replace(robot, joint_effects=tuple(effects))


def _truth(true) -> dict[str, float]:
    return dict(zip(true.names, true.values.tolist(), strict=True)) | {
        f"compliance_{j}": v for j, v in COMPLIANCE.items()
    }


def test_jacobian_matches_finite_differences(ur10, true):
    data = simulate_tilt_rows(true, 10, zeros={(2, 0): 0.01}, seed=1)
    problem = build_constraint_problem(ur10, data)
    x = problem.x0 + 1e-4 * np.random.default_rng(0).standard_normal(len(problem.x0))
    J = problem.jacobian(x)
    step = 1e-7
    numeric = np.column_stack([
        (problem.residual(x + step * e) - problem.residual(x - step * e)) / (2 * step)
        for e in np.eye(len(x))
    ])  # fmt: skip
    scale = np.abs(numeric).max()
    assert scale > 1.0  # the rows see something
    np.testing.assert_allclose(J, numeric, atol=1e-5 * scale)


def test_lengths_are_reported_not_seen(ur10, true):
    data = simulate_tilt_rows(true, 20, seed=2)
    kept, dropped = kind_identifiable(ur10, data)
    unseen = {d.name for d in dropped}
    lengths = {s.name for s in ur10.steps if s.free and not s.is_rotation}
    assert lengths <= unseen  # no length turns a link
    assert {"theta2", "alpha2", "theta3"} <= set(kept)  # the orientation of the links is seen
    assert "theta1" in unseen  # a turn about the vertical: no inclinometer sees it
    result = calibrate_constraints(ur10, data, known_noise=True)
    text = "\n".join(result.summary_lines())
    assert "not identifiable" in text and "a2" in text.split("not identifiable")[1]


def _z(result, truth: dict[str, float]) -> np.ndarray:
    """(estimate − truth)/σ of the robot's parameters and joint effects (effects not in the
    truth are zero); the channel zeros left out (zero here)."""
    rows = [k for k, n in enumerate(result.names) if not n.startswith("tilt_zero_")]
    est = result.estimates[rows]
    return (est - np.array([truth.get(result.names[k], 0.0) for k in rows])) / result.std[rows]


def test_recovers_orientation_and_compliance_at_the_cramer_rao_bound(ur10, true):
    truth = _truth(true)
    z = []
    for run in range(8):
        result = calibrate_constraints(ur10, simulate_tilt_rows(true, 30, seed=run), known_noise=True)
        assert result.success and "compliance_elbow" in result.names
        z.append(_z(result, truth))
    z_all = np.array(z)
    assert np.sqrt(np.mean(z_all**2)) <= 1.2 and np.abs(z_all).max() < 5.0


def test_mixed_tracker_and_tilt_rows_calibrate_together(ur10, true):
    truth = _truth(true)
    z = []
    for run in range(4):
        tilt = simulate_tilt_rows(true, 20, seed=run)
        tracker = simulate_tracker_rows(true, 30, sigma=2e-5, seed=100 + run)
        mixed = merge_sets(tracker, tilt)
        result = calibrate_constraints(ur10, mixed, known_noise=True)
        assert result.success and set(result.kinds) == {"tracker", "tilt"}
        assert {"a2", "compliance_elbow"} <= set(
            result.names
        )  # lengths from the tracker, effects from the tilts
        # the device frame and the base share a gauge (the tracker sees their product): the rest
        inner = {n: v for n, v in truth.items() if n not in GAUGE}
        z.append(_z(result, inner)[[n in inner for n in result.names if not n.startswith("tilt_zero_")]])
        alone = calibrate_constraints(ur10, tracker, known_noise=True)
        common = [n for n in alone.names if n in result.names and n.startswith(("alpha", "beta"))]
        sd_mixed = np.array([result.std[result.names.index(n)] for n in common])
        sd_alone = np.array([alone.std[alone.names.index(n)] for n in common])
        assert common and np.all(sd_mixed <= sd_alone * (1 + 1e-6))  # the tilts add information
    z_all = np.concatenate(z)
    assert np.sqrt(np.mean(z_all**2)) <= 1.3 and np.abs(z_all).max() < 5.0


def test_csv_round_trip_and_kind(tmp_path, ur10, true):
    data = simulate_tilt_rows(true, 5, seed=3)
    path = tmp_path / "tilt.csv"
    write_constraints(data, path)
    assert constraint_kind(path) == "tilt"
    back = read_constraints(path, ur10.dof)
    np.testing.assert_array_equal(back.tilt_link, data.tilt_link)
    np.testing.assert_array_equal(back.tilt_axis, data.tilt_axis)
    np.testing.assert_allclose(back.tilt, data.tilt, rtol=1e-12)
    text = path.read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join([text[0], text[1].rsplit(",", 2)[0] + ",z,1.0"]) + "\n")
    with pytest.raises(ConstraintFileError, match="row 2, column axis"):
        read_constraints(bad, ur10.dof)
    bad.write_text("\n".join([text[0], ",".join(["0"] * ur10.dof) + ",9,x,1.0"]) + "\n")
    with pytest.raises(ConstraintFileError, match="column link"):
        read_constraints(bad, ur10.dof)


def _tilt_lines(output: str) -> dict[str, list[float]]:
    """The validate output's tilt figures (deg): after the calibration, then before."""
    out: dict[str, list[float]] = {}
    for line in output.splitlines():
        if line.strip().startswith("tilt ") and "RMS residual" in line:
            name = line.split()[1].rstrip(":")
            out.setdefault(name, []).append(float(line.split("RMS residual")[1].split()[0]))
    return out


def test_cli_simulate_calibrate_validate_tilt(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli.app import app

    runner = CliRunner()
    data, out = tmp_path / "tilt.csv", tmp_path / "out"
    sim = runner.invoke(
        app, ["simulate", "ur10", "--kind", "tilt", "--n", "20", "-o", str(data), "--seed", "3"]
    )
    assert sim.exit_code == 0, sim.output
    cal = runner.invoke(app, ["calibrate", "ur10", "--data", str(data), "-o", str(out)])
    assert cal.exit_code == 0, cal.output
    assert "a2" in cal.output.split("not identifiable")[1]  # lengths: not seen
    val = runner.invoke(app, ["validate", str(out), "--data", str(data)])
    assert val.exit_code == 0, val.output
    figures = _tilt_lines(val.output)
    assert len(figures) >= 10  # both channels of the links' sensors
    for after, before in figures.values():
        assert after < 0.003 and after < before  # the noise is 0.001°: after near it, before above
    bad = tmp_path / "bad.csv"
    bad.write_text(data.read_text().replace(",x,", ",q,", 1))
    refused = runner.invoke(app, ["calibrate", "ur10", "--data", str(bad), "-o", str(tmp_path / "o2")])
    assert refused.exit_code != 0 and "column axis" in refused.output and "Traceback" not in refused.output
    assert not (tmp_path / "o2" / "model.yaml").exists()
