"""Reading a CSV without CLI knowledge (issue 36 item 4).

The reader's guess of the columns (UR RTDE ``actual_q_0..``, ROS ``shoulder_pan_joint``
..., ``q1..qN``, a device's ``measurement_x``); the roles turned into the reader's renames
with the mapping's own problems; the reader's option names reworded as the page's
controls; and in Chromium: a UR log read without typing a mapping, a comma-decimal file
read by choosing the decimal mark.
"""

from __future__ import annotations

import pytest

from robocal.apps.gui.columns_view import column_roles, gui_words, renames_from_roles
from robocal.measure.dataset.columns import guess_columns
from tests.test_gui import SERIES_A_COLUMNS, _open_calibration, _radio, browser, gui_url, page  # noqa: F401

UR_RTDE = ["timestamp", *[f"actual_q_{i}" for i in range(6)], *[f"actual_TCP_pose_{i}" for i in range(6)]]
SERIES_A_HEADER = (
    "Timestamp;Goal x;Goal y;Goal z;Goal roll;Goal pitch;Goal yaw;shoulder_pan_joint;shoulder_lift_joint;"
    "elbow_joint;wrist_1_joint;wrist_2_joint;wrist_3_joint;measurement_temperature;measurement_x;"
    "measurement_y;measurement_z;measurement_rx;measurement_ry;measurement_rz"
)
SERIES_A = SERIES_A_HEADER.split(";")


def test_the_reader_guesses_ur_ros_and_plain_joint_columns():
    rtde = guess_columns([*UR_RTDE, "tracker_x", "tracker_y", "tracker_z"])
    assert [rtde[f"q{j}"] for j in range(1, 7)] == [f"actual_q_{i}" for i in range(6)]
    assert (rtde["x"], rtde["z"]) == ("tracker_x", "tracker_z")
    assert guess_columns(UR_RTDE).get("x") is None  # the robot's own TCP pose is no measurement
    # the real UR10 file (ROS joint names, the tracker's measurement_*): the README's mapping
    assert ",".join(f"{k}={v}" for k, v in guess_columns(SERIES_A).items()) == SERIES_A_COLUMNS
    assert guess_columns(["q1", "q2", "x", "y", "z"]) == {}  # robocal's own names need nothing
    assert guess_columns(["field.position0", "field.position1"]) == {
        "q1": "field.position0",
        "q2": "field.position1",
    }
    assert guess_columns(["A1", "A2", "A3"]) == {"q1": "A1", "q2": "A2", "q3": "A3"}
    assert guess_columns(["Goal x", "Goal y", "Goal z", "elbow"]) == {}  # commanded, not measured


def test_roles_become_the_readers_renames_or_name_the_mapping():
    roles = column_roles(SERIES_A)
    assert roles[7:13] == [f"q{j}" for j in range(1, 7)] and roles[:7] == ["ignore"] * 7
    assert renames_from_roles(SERIES_A, roles) == SERIES_A_COLUMNS
    roles[9] = "ignore"  # elbow_joint left out: joint 3 has no column
    with pytest.raises(ValueError, match="column mapping: joint 3"):
        renames_from_roles(SERIES_A, roles)
    with pytest.raises(ValueError, match="column mapping: x is given to both"):
        renames_from_roles(["a", "b", "q1"], ["x", "x", "q1"])
    with pytest.raises(ValueError, match="column mapping: column 'x'"):
        renames_from_roles(["q1", "x"], ["q1", "ignore"])  # the reader would read it by its name
    assert renames_from_roles(["j", "x"], ["q1", "x"]) == "q1=j"


def test_reader_messages_name_the_page_controls():
    text = gui_words("row 2: '1,5' is not a number; it looks like a decimal comma: pass decimal=','")
    assert "decimal=" not in text and "decimal mark ','" in text
    text = gui_words("missing joint column(s) q1: rename with e.g. columns={'q1': '<file column>'}; header")
    assert "columns=" not in text and "column mapping" in text
    assert "lengths: mm" in gui_words("positions up to 2362 m: looks like mm: pass length_unit='mm'")


def test_a_ur_log_is_read_without_typing_a_mapping(page, tmp_path):  # noqa: F811
    log = tmp_path / "rtde_log.csv"
    rows = [
        "0.1 -1.2 1.3 -0.4 1.5 0.6 0.5 0.1 0.4 0.9 0.8 0.7",
        "0.2 -1.1 1.2 -0.5 1.4 0.7 0.6 0.2 0.5 1.0 0.9 0.8",
    ]
    header = " ".join([*[f"actual_q_{i}" for i in range(6)], *[f"actual_TCP_pose_{i}" for i in range(3)]])
    log.write_text(header + " measurement_x measurement_y measurement_z\n" + "\n".join(rows) + "\n")
    _open_calibration(page, log)
    summary = page.locator("#csv-summary")
    summary.wait_for(timeout=30_000)
    assert "2 rows, 6 joints, positions" in summary.inner_text()
    cli = page.locator("#columns-cli").inner_text()
    assert "q1=actual_q_0" in cli and "x=measurement_x" in cli
    # the first value of each column is shown beside its role
    assert "0.1" in page.locator("#column-table tbody tr").first.inner_text()


def test_a_comma_decimal_file_is_read_by_choosing_the_decimal_mark(page, tmp_path):  # noqa: F811
    data = tmp_path / "komma.csv"
    data.write_text("q1;q2;x;y;z\n0,1;0,2;1,5;0,25;0,75\n0,3;0,4;1,25;0,5;0,5\n", encoding="utf-8")
    _open_calibration(page, data)
    error = page.locator("#csv-error")
    error.wait_for(timeout=30_000)
    message = page.locator("#csv-preview").inner_text()
    assert "decimal mark" in message and "decimal=" not in message
    _radio(page, "opt-decimal", ",")
    summary = page.locator("#csv-summary")
    summary.wait_for(timeout=30_000)
    assert "2 rows, 2 joints, positions" in summary.inner_text()
    assert "1500.0000" in page.locator("#csv-preview table.preview").inner_text()  # 1,5 m in mm
