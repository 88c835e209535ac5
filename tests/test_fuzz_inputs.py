"""Bad input: the corpus of broken files in tests/data/broken/, generated hostile files
(huge, endless, deeply nested), random bytes and mutations (hypothesis), and the numerical
guards of robocal.identify.guards.  Every case must end, fast, in the reader's own error
naming the file, and never in a traceback on the command line."""

from __future__ import annotations

import dataclasses
import os
import signal
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import robocal as rc
import robocal.measure.dataset.read as dataset_module
from robocal.cli import app
from robocal.cli.options import as_cli_text
from robocal.identify.guards import CalibrationGuardError, check_problem, check_solution
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.dataset.read import read_measurements
from robocal.measure.measurements import MeasurementFileError
from robocal.measure.poses import random_poses
from robocal.model.builder import load_geometry
from robocal.model.files import load_model
from robocal.model.geometry import GeometryError
from robocal.model.urdf.read import URDFError, model_from_urdf
from robocal.model.yaml_files import ModelFileError
from robocal.study import StudyError, load_study_config

BROKEN = Path(__file__).parent / "data" / "broken"
UR10_URDF = Path(__file__).parent / "data" / "ur10.urdf"
SECONDS = 180  # a hang guard: a hang fails the test instead of blocking the run (no speed limit)


@contextmanager
def time_limit(seconds: int = SECONDS):
    def expired(signum, frame):
        raise TimeoutError(f"took more than {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


# file -> the message the reader must give (after the file name)
CORPUS = {
    "csv_bad_quaternion.csv": "row 2, column 'qw': quaternion (qw, qx, qy, qz) has norm 2, not 1",
    "csv_bad_split.csv": "row 2, column 'set': 'validation' is not a train/test label",
    "csv_binary.csv": "cannot be read as UTF-8 text",
    "csv_comments_only.csv": "no header row",
    "csv_decimal_comma.csv": "row 3, column 'q1': '0,3' is not a number; it looks like a decimal comma",
    "csv_degrees.csv": "column 'q1': revolute joint values up to 20 rad (row 3): looks like degrees",
    "csv_duplicate_header.csv": "row 1, column 'x': column 'x' appears more than once in the header",
    "csv_duplicate_row.csv": "row 4: duplicates row 2",
    "csv_empty.csv": "no header row",
    "csv_empty_cell.csv": "row 3, column 'q4': empty cell",
    "csv_extra_joint.csv": "row 1, column 'q7': extra joint column 'q7'",
    "csv_header_only.csv": "row 1: no data rows after the header",
    "csv_incomplete_position.csv": "a position needs columns x, y, z; missing z",
    "csv_inf.csv": "row 3, column 'y': value '1e999' is not finite",
    "csv_millimetres.csv": "looks like mm: pass length_unit='mm'",
    "csv_missing_joint.csv": "row 1: missing joint column(s) q6 (wrist_3)",
    "csv_nan.csv": "row 3, column 'x': value 'nan' is not finite",
    "csv_negative_sigma.csv": "row 2, column 'sx': standard deviation '-1e-5' is negative",
    "csv_not_a_number.csv": "row 3, column 'q3': 'one' is not a number",
    "csv_not_utf8.csv": "cannot be read as UTF-8 text",
    "csv_nul_byte.csv": "row 3, column 'x': '\\x00' is not a number",
    "csv_outside_limits.csv": "row 2, column 'q3': joint elbow = 9.1 rad is outside the limits",
    "csv_ragged_row.csv": "row 3: has 8 cells but the header has 9",
    "csv_unterminated_quote.csv": "row 2: has 1 cells but the header has 9",
    "csv_utf16.csv": "cannot be read as UTF-8 text",
    "geometry_alias.yaml": "line 3, column 10: YAML aliases (*name) are not allowed",
    "geometry_wrong_type.yaml": "joints[0].position[2]: Field required",
    "geometry_no_as_number.yaml": "joints[0].position[2]: Input should be a valid number (got False)",
    "geometry_zero_axis.yaml": "joint 1: axis [0.0, 0.0, 0.0] has zero length",
    "model_alias_bomb.yaml": "line 3, column 8: YAML aliases (*name) are not allowed",
    "model_bad_motion.yaml": "chain[0].motion: Input should be 'Tx', 'Ty', 'Tz', 'Rx', 'Ry' or 'Rz'",
    "model_deep_nesting.yaml": "nested too deeply",
    "model_duplicate_param.yaml": "parameter name 't1' is used twice",
    "model_duplicate_key.yaml": "line 4, column 1: key 'name' appears twice (first on line 1)",
    "model_yes_as_number.yaml": "chain[1].value: Input should be a valid number (got True)",
    "model_empty.yaml": "a model file must be a mapping, got NoneType",
    "model_infinite_value.yaml": "chain[0].value: Input should be a finite number",
    "model_limits_without_joint.yaml": "chain[0]: Value error, 'limits' given for a step that is not a joint",
    "model_links_and_chain.yaml": "give either 'links' (with 'convention') or 'chain', not both",
    "model_not_a_mapping.yaml": "a model file must be a mapping, got list",
    "model_not_utf8.yaml": "not UTF-8 text (byte 9",
    "model_python_tag.yaml": "line 1, column 7: could not determine a constructor for the tag",
    "model_tab_indent.yaml": "line 3, column 1: found character '\\t' that cannot start any token",
    "model_too_many_steps.yaml": "about 1200 steps; a model file may have up to 1000",
    "model_unknown_field.yaml": "chain[0].colour: Extra inputs are not permitted",
    "model_wrong_type.yaml": "chain: Input should be a valid list (got 5)",
    "study_bad_quantity.yaml": "max_std: '0.5 parsec' is not a length",
    "study_negative_robots.yaml": "robots: Input should be greater than or equal to 1 (got -5)",
    "study_unknown_key.yaml": "robtos: Extra inputs are not permitted",
    "study_yes_as_count.yaml": "robots: Input should be a valid integer (got True)",
    "urdf_bad_joint_type.urdf": "line 14: joint 'shoulder_pan_joint': type 'teleport' is not one of",
    "urdf_billion_laughs.urdf": "DOCTYPE/ENTITY declarations are not allowed in a URDF",
    "urdf_duplicate_joint.urdf": "line 24: joint 'shoulder_lift_joint' is defined twice",
    "urdf_external_entity.urdf": "DOCTYPE/ENTITY declarations are not allowed in a URDF",
    "urdf_floating_joint.urdf": "joint 'shoulder_pan_joint': joint type JointModelFreeFlyer is not a 1-DOF",
    "urdf_inverted_limits.urdf": "line 17: joint 'shoulder_pan_joint': limit lower 6.2832 > upper -6.2832",
    "urdf_loop.urdf": "the joints form a loop through link 'shoulder_link'",
    "urdf_missing_child.urdf": "line 14: joint 'shoulder_pan_joint': child link 'nowhere' is not a <link>",
    "urdf_nan_origin.urdf": "line 16: origin xyz 'nan 0 0.1273' is not 3 finite numbers",
    "urdf_no_limits.urdf": "line 14: joint 'shoulder_pan_joint': a revolute joint needs <limit",
    "urdf_not_xml.urdf": "not well-formed XML: syntax error (line 1, column 1)",
    "urdf_only_fixed.urdf": "the robot has no movable joint",
    "urdf_text_axis.urdf": "line 16: axis xyz 'up' is not 3 finite numbers",
    "urdf_truncated.urdf": "not well-formed XML: unclosed token (line 25, column 5)",
    "urdf_undefined_entity.urdf": "not well-formed XML: undefined entity (line 5, column 1)",
    "urdf_utf16_doctype.urdf": "not a URDF (no <robot> element)",
    "urdf_zero_axis.urdf": "line 16: joint 'shoulder_pan_joint': the axis is zero",
}

ERRORS = (MeasurementFileError, ModelFileError, GeometryError, URDFError, StudyError)


def _read(path: Path):
    """The library reader of a corpus file (by its prefix)."""
    name = path.name
    if name.startswith("csv_"):
        return read_measurements(path, model=rc.robot("ur10"))
    if name.startswith("model_"):
        return load_model(path)
    if name.startswith("geometry_"):
        return load_geometry(path).build()
    if name.startswith("study_"):
        return load_study_config(path)
    return model_from_urdf(path)


def test_the_corpus_is_listed():
    assert sorted(p.name for p in BROKEN.iterdir() if p.name != "README.md") == sorted(CORPUS)


@pytest.mark.parametrize("name", sorted(CORPUS))
def test_broken_file_is_rejected_with_a_precise_message(name):
    path = BROKEN / name
    with time_limit(), pytest.raises(ERRORS) as caught:
        _read(path)
    message = str(caught.value)
    assert message.startswith(str(path)), message
    assert CORPUS[name] in message, message
    assert "\n" not in message


def _command(path: Path, tmp: Path) -> list[str]:
    name = path.name
    if name.startswith("csv_"):
        return ["calibrate", "ur10", "--data", str(path), "--out", str(tmp / "cal")]
    if name.startswith("model_"):
        return ["robots", "show", str(path)]
    if name.startswith("study_"):
        return ["study", str(path), "--out", str(tmp / "study"), "--workers", "0"]
    return ["model", "build", str(path), "-o", str(tmp / "model.yaml")]


@pytest.mark.parametrize("name", sorted(CORPUS))
def test_broken_file_on_the_command_line_is_one_error_line(name, tmp_path):
    path = BROKEN / name
    with time_limit():
        result = CliRunner().invoke(app, _command(path, tmp_path))
    assert result.exit_code == 2, (result.output, result.exception)
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert "Traceback" not in result.output
    expected = as_cli_text(CORPUS[name])  # the reader's keyword arguments as command-line options
    assert result.output.startswith(f"error: {path}") and expected in result.output, result.output
    assert not (tmp_path / "model.yaml").exists() and not (tmp_path / "cal").exists()


def test_data_check_lists_every_problem_without_a_traceback():
    for name in sorted(CORPUS):
        if not name.startswith("csv_"):
            continue
        with time_limit():
            result = CliRunner().invoke(app, ["data", "check", str(BROKEN / name), "ur10"])
        assert result.exit_code == 1, (name, result.output)
        assert "Traceback" not in result.output
        assert result.exception is None or isinstance(result.exception, SystemExit)


# ------------------------------------------------------------------ generated hostile files
def test_a_cell_beyond_the_csv_field_limit(tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text("q1,x,y,z\n" + "1" * 200_000 + ",1,2,3\n2,1,2,4\n")
    with (
        time_limit(),
        pytest.raises(MeasurementFileError, match=r"row 2: cannot be read as CSV: field larger"),
    ):
        read_measurements(path)


def test_a_number_of_five_thousand_digits_is_shortened_in_the_message(tmp_path):
    path = tmp_path / "digits.csv"
    path.write_text("q1,x,y,z\n" + "9" * 5000 + ",1,2,3\n2,1,2,4\n")
    with pytest.raises(MeasurementFileError) as caught:
        read_measurements(path)
    assert "(5000 characters) is not finite" in str(caught.value) and len(str(caught.value)) < 300


def test_a_header_of_200000_columns_is_summarised(tmp_path):
    path = tmp_path / "columns.csv"
    n = 200_000
    path.write_text(",".join(f"c{i}" for i in range(n)) + "\n" + ",".join("1" * n) + "\n")
    with time_limit(), pytest.raises(MeasurementFileError) as caught:
        read_measurements(path)
    assert "... (200000 columns)" in str(caught.value) and len(str(caught.value)) < 500


def test_files_over_the_size_limits_are_refused_before_reading(tmp_path, monkeypatch):
    monkeypatch.setattr(dataset_module, "MAX_FILE_BYTES", 1000)
    path = tmp_path / "big.csv"
    path.write_text("q1,x,y,z\n" + "1,2,3,4\n" * 500)
    with pytest.raises(MeasurementFileError, match="4009 bytes is more than the 1000"):
        read_measurements(path)
    big = tmp_path / "big.yaml"
    with open(big, "w") as fh:
        fh.write("name: big\nnotes: '")
        fh.write("x" * 5_000_001)
        fh.write("'\n")
    with time_limit(), pytest.raises(ModelFileError, match="too large for a model file"):
        load_model(big)


@pytest.mark.parametrize("reader", ["csv", "model", "geometry", "study", "urdf"])
def test_a_fifo_or_a_directory_is_not_read_forever(tmp_path, reader):
    fifo = tmp_path / f"pipe.{'urdf' if reader == 'urdf' else 'csv' if reader == 'csv' else 'yaml'}"
    os.mkfifo(fifo)
    functions = {
        "csv": read_measurements,
        "model": load_model,
        "geometry": load_geometry,
        "study": load_study_config,
        "urdf": model_from_urdf,
    }
    for target in (fifo, tmp_path):
        with time_limit(), pytest.raises(ERRORS, match="not a regular file"):
            functions[reader](target)


def test_a_urdf_with_a_thousand_joints_is_refused_before_pinocchio(tmp_path):
    """Pinocchio's work arrays grow faster than the square of the joints (8 GB for 500)."""
    joints = "".join(
        f'<link name="l{i + 1}"/><joint name="j{i}" type="revolute"><parent link="l{i}"/>'
        f'<child link="l{i + 1}"/><origin xyz="0.1 0 0"/><axis xyz="0 0 1"/>'
        f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        for i in range(1000)
    )
    path = tmp_path / "snake.urdf"
    path.write_text(f'<?xml version="1.0"?><robot name="snake"><link name="l0"/>{joints}</robot>')
    with (
        time_limit(),
        pytest.raises(URDFError, match="1000 movable joints; robocal reads URDFs of up to 200"),
    ):
        model_from_urdf(path)


def test_a_urdf_with_unaligned_axes_is_read(tmp_path):
    """Pinocchio wraps unaligned joints in its generic JointModel (an AttributeError before)."""
    path = tmp_path / "tilted.urdf"
    path.write_text(UR10_URDF.read_text().replace('<axis xyz="0 0 1"/>', '<axis xyz="0 -0.6 -0.8"/>', 1))
    model = model_from_urdf(path)
    assert model.dof == 6


# ------------------------------------------------------------------ random input (hypothesis)
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _tmpfile(data: bytes, suffix: str) -> Path:
    fd, name = tempfile.mkstemp(suffix=suffix)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
    return Path(name)


@FUZZ
@given(st.binary(max_size=2000))
def test_random_bytes_never_crash_the_readers(data):
    for suffix, read, errors in (
        (".csv", lambda p: read_measurements(p), (MeasurementFileError,)),
        (".yaml", load_model, (ModelFileError,)),
        (".yaml", load_study_config, (StudyError,)),
        (".yaml", load_geometry, (GeometryError,)),
    ):
        path = _tmpfile(data, suffix)
        try:
            with time_limit():
                read(path)
        except errors:
            pass
        finally:
            path.unlink()


CELL = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(alphabet="0123456789.,-+eE naifNAIF;\"'\t#", max_size=12),
)


@FUZZ
@given(
    header=st.lists(
        st.sampled_from(["q1", "q2", "q3", "x", "y", "z", "qw", "qx", "qy", "qz", "set", "sx", "zz"]),
        max_size=9,
    ),
    rows=st.lists(st.lists(CELL, max_size=10), max_size=8),
    sep=st.sampled_from([",", ";", "\t"]),
)
def test_random_tables_are_read_or_rejected(header, rows, sep):
    text = sep.join(header) + "\n" + "\n".join(sep.join(r) for r in rows) + "\n"
    path = _tmpfile(text.encode(), ".csv")
    try:
        with time_limit():
            data = read_measurements(path, dof=None)
        assert np.all(np.isfinite(data.q))
        if data.position is not None:
            assert np.all(np.isfinite(data.position))
    except MeasurementFileError as err:
        assert str(err).startswith(str(path))
    finally:
        path.unlink()


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_mutated_urdfs_are_read_or_rejected(data):
    text = UR10_URDF.read_text()
    cut = data.draw(st.integers(0, len(text) - 1))
    kind = data.draw(st.sampled_from(["delete", "insert", "number"]))
    if kind == "delete":
        text = text[:cut] + text[cut + data.draw(st.integers(1, 40)) :]
    elif kind == "insert":
        text = (
            text[:cut]
            + data.draw(st.sampled_from(["<", ">", '"', "&", "nan", "-1e400", "<joint>", "]]>"]))
            + text[cut:]
        )
    else:
        text = text.replace("0.612", data.draw(st.sampled_from(["nan", "x", "1 2", "", "1e999", "-0"])), 1)
    path = _tmpfile(text.encode(), ".urdf")
    try:
        with time_limit():
            model_from_urdf(path)
    except (URDFError, GeometryError) as err:
        assert str(path) in str(err)
    finally:
        path.unlink()


# ------------------------------------------------------------------ numerical guards
@pytest.fixture(scope="module")
def tracker_data():
    ur10 = rc.robot("ur10")
    q = random_poses(ur10, 40, seed=3)
    robot = VirtualRobot(
        ur10, draw_true_model(ur10, seed=3), LaserTracker(p_tool_target=np.array([0, 0, 0.1]))
    )
    return ur10, robot, q, simulate(robot, q, seed=3)


def test_guards_pass_good_data_and_a_good_fit(tracker_data):
    ur10, _, _, data = tracker_data
    assert check_problem(ur10, data, tool_guess=[0, 0, 0.1]) == []
    result = rc.calibrate(ur10, data, tool_guess=[0, 0, 0.1])
    assert check_solution(result) == []


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("same", r"all 40 poses have the same joint values"),
        (
            "few",
            r"3 distinct poses give 9 equations for the 23 parameters of 'ur10'.*at least 8 distinct poses",
        ),
        ("lock", r"rank-deficient data: these 40 distinct poses determine 21 of the 23 .*wrist_3 never move"),
        ("only1", r"determine 7 of the 23 .*shoulder_lift, elbow, wrist_1, wrist_2, wrist_3 never move"),
        ("frozen", r"the measured positions do not change over 40 poses"),
        ("nan", r"positions are NaN or inf in row\(s\) 5"),
    ],
)
def test_guards_stop_data_that_cannot_determine_the_model(tracker_data, change, message):
    ur10, robot, q, data = tracker_data
    if change == "same":
        data = simulate(robot, np.tile(q[:1], (40, 1)), seed=0)
    elif change == "few":
        data = simulate(robot, np.repeat(q[:3], 5, axis=0), seed=0)
    elif change == "lock":
        data = simulate(robot, np.c_[q[:, :5], np.zeros(40)], seed=0)
    elif change == "only1":
        data = simulate(robot, np.c_[q[:, :1], np.tile(q[0, 1:], (40, 1))], seed=0)
    elif change == "frozen":
        data = dataclasses.replace(data, position=np.tile(data.position[:1], (40, 1)))
    else:
        position = data.position.copy()
        position[4, 1] = np.nan
        data = dataclasses.replace(data, position=position)
    with pytest.raises(CalibrationGuardError, match=message):
        check_problem(ur10, data, tool_guess=[0, 0, 0.1])


def test_rank_deficient_data_may_be_allowed(tracker_data):
    ur10, robot, q, _ = tracker_data
    data = simulate(robot, np.c_[q[:, :5], np.zeros(40)], seed=0)
    warnings = check_problem(ur10, data, tool_guess=[0, 0, 0.1], allow_rank_deficient=True)
    assert any("wrist_3 do not move" in w for w in warnings) and any("rank-deficient" in w for w in warnings)


def test_guards_stop_a_fit_that_diverged_or_went_astray(tracker_data):
    ur10, _, _, data = tracker_data
    good = rc.calibrate(ur10, data, tool_guess=[0, 0, 0.1])
    with pytest.raises(CalibrationGuardError, match="the fit diverged: RMS error"):
        check_solution(dataclasses.replace(good, rms_after=2 * good.rms_before))
    with pytest.raises(CalibrationGuardError, match="did not converge"):
        check_solution(dataclasses.replace(good, success=False, message="too many"), require_convergence=True)
    assert (
        "did not converge" in check_solution(dataclasses.replace(good, success=False, message="too many"))[0]
    )
    estimates = good.estimates.copy()
    k = good.names.index("a2")
    estimates[k] += 0.2
    with pytest.raises(CalibrationGuardError, match=r"implausible parameter changes \(a2 \+200 mm"):
        check_solution(dataclasses.replace(good, estimates=estimates))
    std = good.std.copy()
    std[0] = np.inf
    with pytest.raises(CalibrationGuardError, match="is not finite: the fit is singular"):
        check_solution(dataclasses.replace(good, std=std))


def test_guard_on_data_of_another_robot(tracker_data):
    """UR10 measurements calibrated as a UR5: the guard sees what the fit did."""
    _, _, _, data = tracker_data
    ur5 = rc.robot("ur5")
    # rc.calibrate runs the guard itself: it stops instead of returning a bad model
    with pytest.raises(CalibrationGuardError, match="implausible parameter changes"):
        rc.calibrate(ur5, data, tool_guess=[0, 0, 0.1])
