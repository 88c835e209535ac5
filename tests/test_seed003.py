"""Seed 003 reproduced (robocal reproduce seed003): the thesis' ordering and sizes,
within tolerances, on a quick run of the whole experiment."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from robocal.cli import app
from robocal.experiments.seed003 import THESIS
from robocal.experiments.seed003_setup import THESIS_GEOMETRIC_ERRORS, pose_errors
from robocal.experiments.seed003_trajectory import compensate_path

pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def reproduced(tmp_path_factory):
    out = tmp_path_factory.mktemp("seed003")
    result = CliRunner().invoke(app, ["reproduce", "seed003", "--quick", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return json.loads(result.output), out


def test_json_holds_the_held_out_errors_per_method(reproduced):
    numbers, _ = reproduced
    for key in ("before", "conventional", "tilt_aware", "simultaneous"):
        assert isinstance(numbers[key], float)
        assert numbers[key] == pytest.approx(numbers["held_out_average_dP"][key]["mean"], abs=1e-4)
    assert numbers["seconds"] > 0  # reported (its size: benchmarks, not a test on a shared machine)


def test_static_calibration_follows_the_thesis(reproduced):
    numbers, _ = reproduced
    before, conventional = numbers["before"], numbers["conventional"]
    tilt_aware, simultaneous = numbers["tilt_aware"], numbers["simultaneous"]
    # the thesis' ordering (Tables 4.5, 4.6): before > conventional > tilt-aware
    assert before > conventional > tilt_aware
    # sizes: before and conventional as in the thesis (±35 %) ...
    thesis_held = THESIS["held_out_average_dP"]
    assert before == pytest.approx(thesis_held["before"], rel=0.35)
    assert conventional == pytest.approx(thesis_held["conventional"], rel=0.35)
    calib = numbers["calibration_average_dP"]
    assert calib["before"]["mean"] == pytest.approx(1.21, rel=0.25)  # Table 4.5 average |ΔP|
    assert calib["conventional"]["mean"] == pytest.approx(0.33, rel=0.5)
    # ... the non-geometric methods well below the geometric one and at least as good as the thesis
    assert tilt_aware < THESIS["table_4_5"]["average"]["tilt_aware"][3]
    assert tilt_aware < 0.1 * conventional and simultaneous < 0.1 * conventional
    assert simultaneous < 0.03  # near the 0.01 mm noise
    # robocal's simultaneous method needs no measured joint parameters
    robust = numbers["robustness_joint_parameters_25pct"]
    assert robust["simultaneous"] < 0.5 * robust["tilt_aware"]


def test_tables_are_laid_out_like_the_thesis(reproduced):
    numbers, out = reproduced
    for where in ("calibration_poses", "held_out_poses"):
        table = numbers["tables"][where]
        assert {"before", "conventional", "tilt_aware", "simultaneous"} <= set(table)
        for summary in table.values():
            assert set(summary) == {"minimum", "maximum", "average"}
            assert all(len(v) == 7 for v in summary.values())
            assert np.all(np.array(summary["minimum"]) <= np.array(summary["average"]))
            assert np.all(np.array(summary["average"]) <= np.array(summary["maximum"]))
    assert len(numbers["held_out_first_10_dP"]["tilt_aware"]) == 10
    text = (out / "seed003.md").read_text()
    assert "|ΔP|" in text and "Agreement with the thesis" in text
    assert (out / "seed003_circle.png").stat().st_size > 10_000
    assert json.loads((out / "seed003.json").read_text())["before"] == numbers["before"]


def test_identified_joint_parameters_match_table_5_2(reproduced):
    params = reproduced[0]["joint_parameters"]
    for joint in ("q2", "q3", "q4", "q5"):
        for name in ("clearance_tilt_deg", "backlash_deg"):
            v = params[joint][name]
            assert abs(v["estimate"] - v["true"]) < 5 * v["sigma"] + 1e-3, (joint, name, v)
    assert params["q2"]["stiffness_kgfm_per_deg"]["true"] == pytest.approx(90)


def test_trajectory_follows_the_thesis(reproduced):
    tr = reproduced[0]["trajectory"]
    circle = tr["circle_average_dP"]
    thesis = THESIS["trajectory_average_dP"]
    assert circle["before"] > circle["geometric"] >= circle["stiffness"] - 0.01 > circle["tilting"]
    # the geometric-only level depends on which poorly identifiable parameters the
    # calibration leaves out (0.16-0.25 mm here); "agrees in size" with the thesis' 0.312
    assert thesis["geometric"] / 2.5 < circle["geometric"] < thesis["geometric"] * 1.5
    assert circle["tilting"] < thesis["tilting"] and circle["influence_tilting"] < thesis["tilting"]
    assert circle["before"] == pytest.approx(thesis["before"], rel=0.5)
    # the line was not calibrated on: the tilting model carries over, geometry alone does not
    line = tr["line_average_dP"]
    assert line["tilting"] < thesis["line_after"] < line["geometric"]
    assert tr["dynamic_load_change_Nm"] > 0  # the motion's inertial loads are in


def test_pose_errors_and_compensation_helpers():
    import robocal as rc

    model = rc.robot("katana450")
    q = np.radians([[10, 40, -30, 20, 5], [-50, 60, 30, -20, 90]])
    T = model.fk(q)
    moved = T.copy()
    moved[:, :3, 3] += [0.001, -0.002, 0.0]
    e = pose_errors(moved, T)
    np.testing.assert_allclose(e[:, :4], [[1, 2, 0, np.sqrt(5)]] * 2, atol=1e-9)
    np.testing.assert_allclose(e[:, 4:], 0, atol=1e-9)
    assert set(THESIS_GEOMETRIC_ERRORS) <= set(model.names)

    class Shifted:  # a "calibrated" robot whose tool sits 1 mm further along x
        def __init__(self):
            self.model = model

        def predict(self, q, frame=None, qd=None, qdd=None):
            T = model.fk(q)
            T[:, 0, 3] += 1e-3
            return T

    q_cmd = compensate_path(Shifted(), q, T[:, :3, 3])
    np.testing.assert_allclose(model.fk(q_cmd)[:, :3, 3], T[:, :3, 3] - [1e-3, 0, 0], atol=1e-9)
