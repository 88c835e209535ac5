"""Measurement files: reading with units and renames, every rejection, check, CLI, the UR10 file."""

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal import spatial
from robocal.cli import app
from robocal.measure.dataset.read import check_measurements, read_measurements
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.measurements import MeasurementFileError, Measurements, MeasurementWarning
from robocal.model.chain import Model
from robocal.model.steps import Joint, Step

runner = CliRunner()

UR10_FILE = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
)
UR10_JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
]
UR10_COLUMNS = {
    **{f"q{j + 1}": name for j, name in enumerate(UR10_JOINTS)},
    **{axis: f"measurement_{axis}" for axis in ("x", "y", "z", "rx", "ry", "rz")},
    "temperature": "measurement_temperature",
}
UR10_OPTIONS = dict(length_unit="mm", decimal=",", sep=";", columns=UR10_COLUMNS)
needs_ur10 = pytest.mark.skipif(not UR10_FILE.is_file(), reason=f"{UR10_FILE} not present")


def write(tmp_path: Path, text: str, name: str = "m.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def arm() -> Model:
    """Two joints, revolute then prismatic, with limits (±90°, 0..0.5 m)."""
    return Model(
        "rp",
        (
            Step("Rz", "theta1", 0.0, joint=Joint("turn", (-math.pi / 2, math.pi / 2))),
            Step("Tx", "a1", 0.3),
            Step("Tz", "d2", 0.1, joint=Joint("lift", (0.0, 0.5))),
        ),
    )


GOOD = "q1,q2,x,y,z\n10,100,300,0,100\n-20,250,290,-50,250\n30,400,280,60,400\n"


def codes(problems):
    return [p.code for p in problems]


# ------------------------------------------------------------------ reading
def test_model_joint_types_take_their_units(tmp_path):
    data = read_measurements(write(tmp_path, GOOD), model=arm(), length_unit="mm", angle_unit="deg")
    np.testing.assert_allclose(data.q[:, 0], np.radians([10, -20, 30]))
    np.testing.assert_allclose(data.q[:, 1], [0.1, 0.25, 0.4])  # prismatic: mm -> m
    np.testing.assert_allclose(data.position[1], [0.29, -0.05, 0.25])
    assert data.observes == "position"


def test_semicolon_decimal_comma_metadata_and_renames(tmp_path):
    text = (
        "# device: laser tracker\n# frame: tracker\n"
        "A;B;px;py;pz\n0,5;-0,25;1000,5;2000;-3,25\n0,1;0,2;1;2;3000\n"
    )
    data = read_measurements(
        write(tmp_path, text),
        length_unit="mm",
        decimal=",",
        columns="q1=A,q2=B,x=px,y=py,z=pz",
    )
    np.testing.assert_allclose(data.q, [[0.5, -0.25], [0.1, 0.2]])
    np.testing.assert_allclose(data.position[0], [1.0005, 2.0, -0.00325])
    assert data.metadata["device"] == "laser tracker" and data.joint_names == ("A", "B")


def test_model_joint_names_serve_as_columns(tmp_path):
    path = write(tmp_path, "turn,lift\n0.1,0.2\n0.3,0.4\n")
    data = read_measurements(path, model=arm())
    np.testing.assert_allclose(data.q, [[0.1, 0.2], [0.3, 0.4]])
    assert data.observes == "joints"


def test_joint_only_poses_file_and_repeated_pose_is_a_warning(tmp_path):
    path = write(tmp_path, "q1,q2\n0.1,0.2\n0.3,0.4\n0.1,0.2\n")
    with pytest.warns(MeasurementWarning, match=r"row 4.*repeats the joint values of row 2"):
        data = read_measurements(path, model=arm())
    assert data.n == 3 and data.position is None


@pytest.mark.parametrize(
    ("columns", "orientation", "values", "seq"),
    [
        ("qw,qx,qy,qz", "auto", None, "quat"),
        ("rx,ry,rz", "auto", [0.1, -0.2, 0.3], "rotvec"),
        ("rx,ry,rz", "euler:XYZ", [0.1, -0.2, 0.3], "XYZ"),
        ("rx,ry,rz", "euler:zyx:deg", [10.0, -20.0, 30.0], "zyx"),
    ],
)
def test_orientation_conventions(tmp_path, columns, orientation, values, seq):
    R = spatial.euler_to_matrix([0.4, -0.3, 1.2], "XYZ")
    if seq == "quat":
        values = spatial.matrix_to_quaternion(R)
        expected = R
    elif seq == "rotvec":
        expected = spatial.rotvec_to_matrix(values)
    elif seq == "XYZ":
        expected = spatial.euler_to_matrix(values, "XYZ")
    else:
        expected = spatial.euler_to_matrix(np.radians(values), "zyx")
    row = ",".join(repr(float(v)) for v in values)
    path = write(tmp_path, f"q1,x,y,z,{columns}\n0.1,1,2,3,{row}\n")
    data = read_measurements(path, orientation=orientation)
    np.testing.assert_allclose(data.orientation[0], expected, atol=1e-12)
    assert data.observes == "pose"


def test_write_read_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    n = 7
    data = Measurements(
        q=rng.normal(size=(n, 3)),
        position=rng.normal(size=(n, 3)),
        orientation=spatial.rotvec_to_matrix(rng.normal(size=(n, 3))),
        sigma=np.abs(rng.normal(size=(n, 3))) * 1e-5,
        split=np.array(["train", "test"] * 3 + ["train"]),
        temperature=rng.normal(20, 1, n),
        joint_names=("a", "b", "c"),
        metadata={"device": "tracker"},
    )
    path = write_measurements(data, tmp_path / "out.csv")
    back = read_measurements(path)
    np.testing.assert_array_equal(back.q, data.q)
    np.testing.assert_array_equal(back.position, data.position)
    np.testing.assert_allclose(back.orientation, data.orientation, atol=1e-15)
    np.testing.assert_array_equal(back.sigma, data.sigma)
    np.testing.assert_array_equal(back.split, data.split)
    assert back.joint_names == ("a", "b", "c") and back.metadata["device"] == "tracker"


# ------------------------------------------------------------------ rejections
@pytest.mark.parametrize("bad", ["nan", "inf", "-Infinity"])
def test_nan_and_inf_are_rejected_with_row_and_column(tmp_path, bad):
    path = write(tmp_path, f"q1,q2,x,y,z\n0.1,0.2,1,2,3\n0.1,0.3,1,{bad},3\n")
    with pytest.raises(MeasurementFileError, match=rf"m.csv: row 3, column 'y': value '{bad}' is not finite"):
        read_measurements(path)


def test_non_numeric_and_empty_cells(tmp_path):
    path = write(tmp_path, "q1,q2,x,y,z\n0.1,abc,1,2,3\n0.1,0.3,1,,3\n0.2,0.3,1,2,3\n")
    with pytest.raises(MeasurementFileError, match=r"row 2, column 'q2': 'abc' is not a number") as err:
        read_measurements(path)
    assert codes(err.value.problems) == ["not-a-number", "empty"]
    assert err.value.problems[1].row == 3 and err.value.problems[1].column == "y"


def test_decimal_comma_gets_a_hint(tmp_path):
    path = write(tmp_path, "q1;x;y;z\n0,1;1;2;3\n")
    with pytest.raises(MeasurementFileError, match=r"row 2, column 'q1'.*decimal comma: pass decimal=','"):
        read_measurements(path)


def test_missing_joint_column_is_named(tmp_path):
    path = write(tmp_path, "q1,x,y,z\n0.1,0.3,0,0.1\n")
    with pytest.raises(
        MeasurementFileError, match=r"row 1: missing joint column\(s\) q2 \(lift\): model 'rp' has 2"
    ):
        read_measurements(path, model=arm())


def test_extra_joint_column_is_named(tmp_path):
    path = write(tmp_path, "q1,q2,q3,x,y,z\n0.1,0.2,0.3,0.3,0,0.1\n")
    with pytest.raises(
        MeasurementFileError, match=r"row 1, column 'q3': extra joint column 'q3': model 'rp'"
    ):
        read_measurements(path, model=arm())
    with pytest.raises(MeasurementFileError, match=r"extra joint column 'q3'"):
        read_measurements(path, dof=2)


def test_gap_in_joint_columns_without_model(tmp_path):
    path = write(tmp_path, "q1,q2,q4,x,y,z\n0.1,0.2,0.3,0.3,0,0.1\n")
    with pytest.raises(MeasurementFileError, match=r"extra joint column 'q4'.*q3 is missing"):
        read_measurements(path)


def test_rename_to_an_absent_column(tmp_path):
    path = write(tmp_path, GOOD)
    with pytest.raises(MeasurementFileError, match=r"column 'joint_a' \(given for 'q1' in columns=\) is not"):
        read_measurements(path, columns={"q1": "joint_a"})
    with pytest.raises(ValueError, match="'foo' is not a robocal column name"):
        read_measurements(path, columns={"foo": "q1"})


def test_out_of_limits_error_warn_ignore(tmp_path):
    text = "q1,q2,x,y,z\n10,100,300,0,100\n95,100,300,0,100\n10,600,300,0,120\n"
    path = write(tmp_path, text)
    opts = dict(model=arm(), length_unit="mm", angle_unit="deg")
    with pytest.raises(
        MeasurementFileError,
        match=r"row 3, column 'q1': joint turn = 95 deg is outside the limits \[-90, 90\] deg of model 'rp'",
    ) as err:
        read_measurements(path, **opts)
    assert [(p.row, p.column) for p in err.value.problems] == [(3, "q1"), (4, "q2")]
    assert "600 mm is outside the limits [0, 500] mm" in err.value.problems[1].message
    with pytest.warns(
        MeasurementWarning, match=r"(?s)2 warning\(s\).*row 3, column 'q1'.*row 4, column 'q2'"
    ):
        data = read_measurements(path, limits="warn", **opts)
    assert data.n == 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_measurements(path, limits="ignore", **opts).n == 3


def test_duplicate_rows_name_both(tmp_path):
    path = write(tmp_path, "q1,q2,x,y,z\n0.1,0.2,1,2,3\n0.3,0.2,1,2,3\n0.1,0.2,1,2,3\n")
    with pytest.raises(MeasurementFileError, match=r"row 4: duplicates row 2"):
        read_measurements(path)


def test_wrong_length_unit_is_detected_both_ways(tmp_path):
    mm = write(tmp_path, "q1,x,y,z\n0.1,1200,300,400\n0.2,1100,-200,500\n", "mm.csv")
    with pytest.raises(MeasurementFileError, match=r"column 'x/y/z'.*looks like mm: pass length_unit='mm'"):
        read_measurements(mm)
    assert read_measurements(mm, length_unit="mm").position[0, 0] == pytest.approx(1.2)
    metres = write(tmp_path, "q1,x,y,z\n0.1,1.2,0.3,0.4\n0.2,1.1,-0.2,0.5\n", "m.csv")
    with pytest.raises(MeasurementFileError, match=r"looks like m: pass length_unit='m'"):
        read_measurements(metres, length_unit="mm")


def test_joint_angles_in_degrees_read_as_radians(tmp_path):
    path = write(tmp_path, "q1,q2,x,y,z\n10,0.1,0.3,0,0.1\n170,0.2,0.3,0,0.2\n")
    with pytest.raises(
        MeasurementFileError, match=r"column 'q1'.*look(s)? like degrees: pass angle_unit='deg'"
    ):
        read_measurements(path)


def test_bad_split_label(tmp_path):
    path = write(tmp_path, "q1,x,y,z,set\n0.1,1,2,3,train\n0.2,1,2,3,Test\n0.3,1,2,3,validation\n")
    with pytest.raises(
        MeasurementFileError, match=r"row 4, column 'set': 'validation' is not a train/test label"
    ):
        read_measurements(path)


def test_ragged_row(tmp_path):
    path = write(tmp_path, "q1,q2,x,y,z\n0.1,0.2,1,2,3\n0.1,0.3,1,2\n0.1,0.4,1,2,3,4\n")
    with pytest.raises(MeasurementFileError, match=r"row 3: has 4 cells but the header has 5") as err:
        read_measurements(path)
    assert [(p.code, p.row) for p in err.value.problems] == [("ragged", 3), ("ragged", 4)]


def test_incomplete_groups_and_bad_quaternions(tmp_path):
    with pytest.raises(MeasurementFileError, match=r"a position needs columns x, y, z; missing z"):
        read_measurements(write(tmp_path, "q1,x,y\n0.1,1,2\n"))
    with pytest.raises(MeasurementFileError, match=r"row 2, column 'qw'.*norm 2, not 1"):
        read_measurements(write(tmp_path, "q1,x,y,z,qw,qx,qy,qz\n0.1,1,2,3,2,0,0,0\n"))
    with pytest.raises(MeasurementFileError, match=r"orientation='euler:XYZ' needs columns rx, ry, rz"):
        read_measurements(write(tmp_path, "q1,x,y,z\n0.1,1,2,3\n"), orientation="euler:XYZ")
    with pytest.raises(ValueError, match="Euler sequence 'XYx'"):
        read_measurements(write(tmp_path, GOOD), orientation="euler:XYx")


def test_no_rows_and_empty_file(tmp_path):
    with pytest.raises(MeasurementFileError, match=r"row 1: no data rows"):
        read_measurements(write(tmp_path, "q1,x,y,z\n"))
    with pytest.raises(MeasurementFileError, match=r"no header row"):
        read_measurements(write(tmp_path, "# only a comment\n"))


def test_check_collects_every_problem(tmp_path):
    text = (
        "q1,q2,x,y,z,set\n"
        "10,100,300,0,100,train\n"  # 2 ok
        "95,100,300,0,100,test\n"  # 3 outside limits
        "10,abc,300,0,100,test\n"  # 4 not a number
        "10,100,300,nan,100,test\n"  # 5 nan
        "10,100,300,0\n"  # 6 ragged
        "10,100,300,0,100,dev\n"  # 7 bad label
        "10,100,300,0,100,train\n"  # 8 duplicate of 2
    )
    problems = check_measurements(write(tmp_path, text), arm(), length_unit="mm", angle_unit="deg")
    found = {(p.code, p.row, p.column) for p in problems}
    assert found == {
        ("limits", 3, "q1"),
        ("not-a-number", 4, "q2"),
        ("not-finite", 5, "y"),
        ("ragged", 6, None),
        ("split", 7, "set"),
        ("duplicate", 8, None),
    }
    assert all(p.severity == "error" and p.file.endswith("m.csv") for p in problems)
    assert (
        check_measurements(write(tmp_path, GOOD, "ok.csv"), arm(), length_unit="mm", angle_unit="deg") == []
    )


# ------------------------------------------------------------------ CLI
def test_cli_data_check_reports_problems_and_exit_code(tmp_path):
    path = write(tmp_path, "q1,q2,x,y,z\n10,100,300,0,100\n95,100,300,0,100\n10,100,300,inf,100\n")
    result = runner.invoke(
        app, ["data", "check", str(path), str(rc.save_model(arm(), tmp_path / "rp.yaml")),
              "--length-unit", "mm", "--angle-unit", "deg"],
    )  # fmt: skip
    assert result.exit_code == 1, result.output
    assert "limits" in result.output and "not-finite" in result.output and "2 error(s)" in result.output
    # the reader's advice in command-line spelling
    comma = write(tmp_path, 'q1,q2,x,y,z\n10,100,300,0,100\n20,"1,5",300,0,100\n', "comma.csv")
    result = runner.invoke(app, ["data", "check", str(comma), "--length-unit", "mm"])
    text = " ".join(result.output.split())
    assert result.exit_code == 1 and "pass --angle-unit deg" in text and "pass --decimal" in text, text


def test_cli_data_check_summary_when_clean(tmp_path):
    path = write(tmp_path, "A;B;x;y;z\n10;100;300;0;100\n-20;250;290;-50;250\n")
    model_file = rc.save_model(arm(), tmp_path / "rp.yaml")
    result = runner.invoke(
        app, ["data", "check", str(path), str(model_file), "--length-unit", "mm",
              "--angle-unit", "deg", "--sep", ";", "--columns", "q1=A,q2=B"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "2 rows, clean" in result.output and "-20.000" in result.output and "250.000" in result.output


# ------------------------------------------------------------------ the real UR10 file
@needs_ur10
def test_ur10_file_reads_through_options_only():
    model = rc.robot("ur10")
    data = read_measurements(UR10_FILE, model=model, orientation="euler:XYZ:deg", **UR10_OPTIONS)
    assert data.n == 11911 and data.dof == 6 and data.observes == "pose"
    assert data.temperature.min() > 22.9 and data.temperature.max() < 23.7
    # the tracker sees the T-Mac 109 mm from the flange: a rigid fit of the nominal model's
    # probe positions to the measured ones leaves the arm's few-mm error, so units and
    # columns are right
    T = model.fk(data.q)
    p_base = T[:, :3, 3] + 0.109 * T[:, :3, 2]
    T_tracker_base = spatial.fit_rigid_transform(p_base, data.position)
    residual = data.position - (p_base @ T_tracker_base[:3, :3].T + T_tracker_base[:3, 3])
    rms = np.sqrt(np.mean(np.sum(residual**2, axis=1)))
    assert 1e-3 < rms < 5e-3
    assert 2.5 < np.linalg.norm(T_tracker_base[:3, 3]) < 4.0  # the tracker stands ~3 m away


@needs_ur10
def test_ur10_file_wrong_units_are_caught():
    model = rc.robot("ur10")
    problems = check_measurements(
        UR10_FILE, model, orientation="none", **{**UR10_OPTIONS, "length_unit": "m"}
    )
    assert codes(problems) == ["length-unit"]
    assert "looks like mm: pass length_unit='mm'" in problems[0].message
    # read as rotation vectors (the default for rx ry rz), the degrees are caught too
    problems = check_measurements(UR10_FILE, model, **UR10_OPTIONS)
    assert codes(problems) == ["angle-unit"] * 3
    assert [p.column for p in problems] == ["measurement_rx", "measurement_ry", "measurement_rz"]


def _polar(M):
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def fit_two_sided(R_meas, R_ref, iterations=30):
    """Constant rotations A, B with R_meas ≈ A R_ref B; returns A, B and the residual angles (deg).

    A is started from the rotation axes of the relative rotations (R_i R_0ᵀ turns about
    A·axis when R_ref_i R_ref_0ᵀ turns about axis), then refined by alternating polar fits.
    """
    rel_m = spatial.matrix_to_rotvec(R_meas @ np.swapaxes(R_meas[:1], 1, 2))
    rel_r = spatial.matrix_to_rotvec(R_ref @ np.swapaxes(R_ref[:1], 1, 2))
    A = spatial.fit_rigid_transform(rel_r, rel_m)[:3, :3]
    for _ in range(iterations):
        B = _polar(np.einsum("nji,njl->il", R_ref, A.T @ R_meas))  # sum R_refᵀ Aᵀ R_meas
        A = _polar(np.einsum("nij,nkj->ik", R_meas @ B.T, R_ref))  # sum R_meas Bᵀ R_refᵀ
    fitted = A @ R_ref @ B
    angles = np.degrees(np.linalg.norm(spatial.matrix_to_rotvec(R_meas @ np.swapaxes(fitted, 1, 2)), axis=1))
    return A, B, angles


@needs_ur10
def test_ur10_orientation_is_intrinsic_xyz_euler():
    """measurement_rx/ry/rz are intrinsic XYZ Euler angles (R = Rx Ry Rz), not extrinsic xyz.

    The measured T-Mac orientation must be the FK orientation turned by two constant
    rotations (tracker frame on the left, flange-to-T-Mac on the right).  Intrinsic XYZ
    fits all 11,911 rows to the arm's own orientation error (0.1° median); extrinsic xyz
    does not (degrees, and up to ~170° near ry = -90°).  The left rotation agrees with the
    tracker frame found from the positions alone.
    """
    model = rc.robot("ur10")
    data = {
        seq: read_measurements(UR10_FILE, model=model, orientation=f"euler:{seq}:deg", **UR10_OPTIONS)
        for seq in ("XYZ", "xyz")
    }
    R_fk = model.fk(data["XYZ"].q)[:, :3, :3]
    A, _, intrinsic = fit_two_sided(data["XYZ"].orientation, R_fk)
    _, _, extrinsic = fit_two_sided(data["xyz"].orientation, R_fk)
    assert np.median(intrinsic) < 0.15 and intrinsic.max() < 0.5
    assert np.median(extrinsic) > 1.0 and extrinsic.max() > 90
    T = model.fk(data["XYZ"].q)
    p_base = T[:, :3, 3] + 0.109 * T[:, :3, 2]
    R_tracker_base = spatial.fit_rigid_transform(p_base, data["XYZ"].position)[:3, :3]
    assert np.degrees(np.linalg.norm(spatial.matrix_to_rotvec(A @ R_tracker_base.T))) < 1.0


@needs_ur10
def test_ur10_goal_rpy_is_extrinsic_xyz_and_agrees_with_the_measurement():
    """Goal roll/pitch/yaw (rad) are ROS RPY, R = Rz(yaw) Ry(pitch) Rx(roll) (extrinsic xyz):
    they match the nominal FK up to the controller's base turned 180° about z and the tool
    90° about z; and the measured XYZ angles match them as they match the FK."""
    model = rc.robot("ur10")
    data = read_measurements(
        UR10_FILE,
        model=model,
        orientation="euler:XYZ:deg",
        extra=["Goal roll", "Goal pitch", "Goal yaw"],
        **UR10_OPTIONS,
    )
    rpy = np.stack([data.extra[k] for k in ("Goal roll", "Goal pitch", "Goal yaw")], axis=1)
    R_fk = model.fk(data.q)[:, :3, :3]
    R_goal = spatial.euler_to_matrix(rpy, "xyz")
    A, B, angles = fit_two_sided(R_goal, R_fk)
    assert np.median(angles) < 0.1 and angles.max() < 0.3
    np.testing.assert_allclose(A, spatial.rotz(np.pi), atol=0.01)
    np.testing.assert_allclose(B, spatial.rotz(np.pi / 2), atol=0.01)
    _, _, intrinsic = fit_two_sided(spatial.euler_to_matrix(rpy, "XYZ"), R_fk)
    assert np.median(intrinsic) > 0.5  # the other reading of the goal angles does not fit
    _, _, measured = fit_two_sided(data.orientation, R_goal)
    assert np.median(measured) < 0.15


def test_incomplete_rows_are_an_error_or_left_out(tmp_path):
    text = GOOD + "40,,270,70,450\n5,120,nan,0,120\n6,130,300\n-5,140,305,1,140\n"
    path = write(tmp_path, text)
    with pytest.raises(MeasurementFileError, match="leaves such rows out") as err:
        read_measurements(path, length_unit="mm", angle_unit="deg", model=arm())
    assert {p.code for p in err.value.problems} == {"empty", "not-finite", "ragged"}
    with pytest.warns(MeasurementWarning, match="row left out"):
        data = read_measurements(path, length_unit="mm", angle_unit="deg", model=arm(), incomplete="drop")
    assert data.n == 4 and data.metadata["rows_left_out"] == "3"
    np.testing.assert_allclose(np.degrees(data.q[:, 0]), [10, -20, 30, -5])
    np.testing.assert_allclose(data.position[-1], [0.305, 0.001, 0.14])
    everything_bad = write(tmp_path, "q1,q2,x,y,z\n1,,3,4,5\n", "bad.csv")
    with pytest.raises(MeasurementFileError, match="every data row"):
        read_measurements(everything_bad, model=arm(), incomplete="drop")
    with pytest.raises(ValueError, match="incomplete must be"):
        read_measurements(path, incomplete="skip")


def test_unused_columns_are_named(tmp_path):
    path = write(
        tmp_path,
        "id,q1,q2,x,y,z,note\n" + "".join(f"{k},{line},n\n" for k, line in enumerate(GOOD.splitlines()[1:])),
    )
    data = read_measurements(path, length_unit="mm", angle_unit="deg", model=arm())
    assert data.metadata["unused_columns"] == "id, note"
    result = runner.invoke(
        app,
        [
            "data",
            "check",
            str(path),
            str(_arm_file(tmp_path)),
            "--length-unit",
            "mm",
            "--angle-unit",
            "deg",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "not used: id, note" in result.output


def _arm_file(tmp_path):
    from robocal.model.files import save_model

    return save_model(arm(), tmp_path / "arm.yaml")
