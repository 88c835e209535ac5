"""Hostile inputs of issue 38 (items 5-7): terminals that cannot print UTF-8, targets and
frames far beyond any robot, ISO 9283 logs with overflowing or degenerate values, oversized
model, URDF and GUI inputs.  Each must end in one ``error:`` line naming the input (or a
faithful result), never a traceback, NaN in a result or a crash."""

from __future__ import annotations

import codecs
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from robocal.cli import app
from robocal.console import tolerate_terminal_encoding
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.ik import solve_ik
from robocal.measure.poses import random_poses
from robocal.model.catalog import robot
from robocal.model.files import save_model

runner = CliRunner()


def _errors(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.startswith("error:")]


def _one_error(result, *words: str) -> str:
    """The result is a refusal: exit 2, one error line holding ``words``, no traceback."""
    assert result.exit_code == 2, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    lines = _errors(result.stderr)
    assert len(lines) == 1 and "internal error" not in lines[0], result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


# ------------------------------------------------------------------ any terminal encoding
def _robocal(args: list[str], encoding: str, cwd: Path) -> subprocess.CompletedProcess[bytes]:
    env = os.environ | {"PYTHONIOENCODING": encoding, "COLUMNS": "100"}
    return subprocess.run(
        [sys.executable, "-m", "robocal.cli", *args], env=env, cwd=cwd, capture_output=True, timeout=300
    )


@pytest.mark.parametrize("encoding", ["ascii", "latin-1"])
def test_cli_prints_on_a_terminal_that_is_not_utf8(encoding, tmp_path):
    """`robots show` prints a dash and Greek letters: on an ASCII or latin-1 terminal they come
    out transliterated, the command succeeds and nothing is an internal error."""
    shown = _robocal(["robots", "show", "ur10"], encoding, tmp_path)
    assert shown.returncode == 0, shown.stderr
    text = shown.stdout.decode(encoding)  # every byte is of the terminal's encoding
    assert "ur10" in text and "UR10" in text
    assert b"internal error" not in shown.stderr
    missing = _robocal(["iso9283", "missing—σ.csv"], encoding, tmp_path)
    assert missing.returncode == 2
    errors = _errors(missing.stderr.decode(encoding))
    assert len(errors) == 1 and "missing-sigma.csv" in errors[0], missing.stderr


def test_transliteration_of_what_the_encoding_cannot_hold():
    text = "RMS 0.05 mm — σ 2 µm, 90°, ΔT ≤ 1 s, café, x² \udcff"
    ascii_ = text.encode("ascii", "robocal-ascii").decode("ascii")
    assert ascii_ == "RMS 0.05 mm - sigma 2 um, 90 deg, DeltaT <= 1 s, cafe, x2 \\xff"
    latin = text.encode("latin-1", "robocal-ascii").decode("latin-1")
    assert "µm" in latin and "°" in latin and "sigma" in latin and "café" in latin
    with pytest.raises(UnicodeDecodeError):  # an encoding handler only: decoding still fails loudly
        b"\xff".decode("utf-8", "robocal-ascii")
    assert codecs.lookup_error("robocal-ascii") is not None
    tolerate_terminal_encoding()  # harmless on streams that are not text files (pytest's capture)


# ------------------------------------------------------------------ far targets
def test_ik_refuses_targets_beyond_any_reach_and_names_them():
    ur10 = robot("ur10")
    for far in (1e200, 1e308, -1e7):
        with pytest.raises(ValueError, match=r"target 1 .*beyond any robot's reach"):
            solve_ik(ur10, np.array([[0.5, 0.2, 0.3], [far, 0.0, 0.0]]), kind="position")


def test_nearest_start_of_a_far_target_is_a_pool_configuration():
    """The k-d tree of starting configurations answers for targets whose squared distance
    overflows (it reports no neighbour at an infinite distance)."""
    from types import SimpleNamespace

    from robocal.measure.ik_starts import _seed_pool, nearest_pool

    ur10 = robot("ur10")
    T = np.tile(np.eye(4), (3, 1, 1))
    T[:, :3, 3] = [[1e200, 0, 0], [0, -1e300, 1e300], [0.4, 0.1, 0.5]]
    for kind in ("position", "pose"):
        problem = SimpleNamespace(model=ur10, T=T, kind=kind, w=0.5, k=2)
        q = nearest_pool(problem, 2000, np.arange(3), rank=1)
        assert q.shape == (3, ur10.dof) and np.all(np.isfinite(q))
        pool_q, pool_T = _seed_pool(ur10, 2000)
        assert all(any(np.array_equal(row, p) for p in pool_q) for row in q)
        # the far target along +x starts from a pool frame far out along +x
        assert pool_T[np.flatnonzero((pool_q == q[0]).all(axis=1))[0], 0, 3] > 0.5


def test_compensate_refuses_far_targets_and_writes_nothing(tmp_path):
    model = save_model(robot("ur10"), tmp_path / "ur10.yaml")
    for far in ("1e200", "1e308"):
        targets = tmp_path / f"far{far}.csv"
        targets.write_text(f"name,x,y,z\nnear,0.5,0.2,0.3\nfar,{far},0,0\n", encoding="utf-8")
        out = tmp_path / f"out{far}.csv"
        result = runner.invoke(app, ["compensate", str(model), "--targets", str(targets), "-o", str(out)])
        _one_error(result, targets.name, "reach")
        assert not out.exists()


# ------------------------------------------------------------------ report on a corrupted result
@pytest.fixture(scope="module")
def calibration(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("cal")
    ur10 = robot("ur10")
    q = random_poses(ur10, 30, seed=5)
    virtual = VirtualRobot(
        ur10, draw_true_model(ur10, seed=5), LaserTracker(p_tool_target=np.array([0, 0, 0.1]))
    )
    write_measurements(simulate(virtual, q, seed=5), root / "meas.csv")
    args = ["calibrate", "ur10", "--data", str(root / "meas.csv"), "--out", str(root / "cal")]
    result = runner.invoke(app, [*args, "--residual", "none"])
    assert result.exit_code == 0, result.output
    return root / "cal"


@pytest.mark.parametrize(
    ("row", "col", "value"), [(0, 3, 1e308), (0, 0, 1e308), (2, 2, 3.0), (1, 3, -1e12), (3, 3, 2.0)]
)
def test_report_refuses_a_device_frame_that_is_no_rigid_transform(calibration, tmp_path, row, col, value):
    import shutil

    cal = shutil.copytree(calibration, tmp_path / "cal")
    doc = json.loads((cal / "result.json").read_text(encoding="utf-8"))
    doc["frame"]["T_device_base"][row][col] = value
    (cal / "result.json").write_text(json.dumps(doc), encoding="utf-8")
    out = tmp_path / "report.html"
    result = runner.invoke(app, ["report", str(cal), "-o", str(out)])
    _one_error(result, "T_device_base")
    assert not out.exists()
    assert "Warning" not in result.stderr  # refused before any overflowing arithmetic


def test_report_of_the_intact_calibration_is_written(calibration, tmp_path):
    out = tmp_path / "report.html"
    result = runner.invoke(app, ["report", str(calibration), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.is_file()


# ------------------------------------------------------------------ ISO 9283 logs
HEADER = "time_s,test,cycle,target,x_mm,y_mm,z_mm,cmd_x_mm,cmd_y_mm,cmd_z_mm\n"


def _pose_log(cycles: int, samples: int = 1, times=None) -> str:
    """A pose test: ``cycles`` visits of P1 and P2, each of ``samples`` samples."""
    rows, t = [], 0.0
    for c in range(1, cycles + 1):
        for name, x in (("P1", 500.0), ("P2", 600.0)):
            for _ in range(samples):
                rows.append(f"{t if times is None else times},pose,{c},{name},{x + 0.01 * c},0,400,{x},0,400")
                t += 0.01
    return HEADER + "\n".join(rows) + "\n"


def _replace(text: str, row: int, column: str, value: str) -> str:
    lines = text.splitlines()
    cells = lines[row - 1].split(",")
    cells[HEADER.strip().split(",").index(column)] = value
    lines[row - 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("row", "column", "value"),
    [
        (3, "x_mm", "1e300"),
        (4, "cmd_z_mm", "-1e300"),
        (2, "y_mm", "1.7976931348623157e308"),
        (5, "cycle", "1e20"),
        (3, "time_s", "1e300"),
    ],
)
def test_iso9283_refuses_overflowing_values_by_row_and_column(tmp_path, row, column, value):
    log = tmp_path / "log.csv"
    log.write_text(_replace(_pose_log(3), row, column, value), encoding="utf-8")
    result = runner.invoke(app, ["iso9283", str(log)])
    _one_error(result, str(log), f"row {row}", f"column {column}")


@pytest.mark.parametrize("step", [0.0, 1e-300, 1e-9])
def test_iso9283_refuses_a_time_record_without_increasing_times(tmp_path, step):
    """All-zero (or sub-microsecond) time steps in runs of several samples: no speed or
    settling can be measured, and the fits of a time record degenerate (LAPACK errors)."""
    text = _pose_log(3, samples=5)
    lines = text.splitlines()
    for k in range(1, len(lines)):
        lines[k] = f"{k * step!r}," + lines[k].split(",", 1)[1]
    log = tmp_path / "log.csv"
    log.write_text("\n".join(lines) + "\n", encoding="utf-8")
    result = runner.invoke(app, ["iso9283", str(log), "--json"])
    _one_error(result, str(log), "row 3", "column time_s")
    assert "DLASCL" not in result.output and result.stdout == ""


def test_iso9283_time_records_10_ms_apart_are_read(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text(_pose_log(3, samples=5), encoding="utf-8")
    result = runner.invoke(app, ["iso9283", str(log), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["characteristics"][0]["measured"]


def test_iso9283_single_cycle_gives_no_nan(tmp_path):
    """One cycle per pose: AP is measured, RP says why it is not, no NaN anywhere."""
    log = tmp_path / "log.csv"
    log.write_text(_pose_log(1), encoding="utf-8")
    table = runner.invoke(app, ["iso9283", str(log)])
    assert table.exit_code == 0, table.output
    assert "nan" not in table.stdout.lower()
    data = json.loads(runner.invoke(app, ["iso9283", str(log), "--json"]).stdout)
    pose = data["characteristics"][0]
    assert pose["measured"] and "RP not measured" in pose["summary"]
    assert all(d["RP_mm"] is None and d["AP_mm"] > 0 for d in pose["details"])


# ------------------------------------------------------------------ GUI requests
@pytest.fixture(scope="module")
def gui(tmp_path_factory):
    pytest.importorskip("dash")
    from robocal.apps.gui.app import create_app

    app = create_app(tmp_path_factory.mktemp("gui"))
    return app, app.server.test_client()


def _callback(app, client, output: str, values: dict, trigger: str):
    """POST one Dash callback request: the callback whose output key holds ``output``, its
    inputs and states valued from ``values`` ((id, property) or id -> value, else None)."""
    key = next(k for k in app.callback_map if output in k)
    spec = app.callback_map[key]

    def item(d):
        return {"id": d["id"], "property": d["property"], "value": values.get((d["id"], d["property"]))}

    outputs = [
        {"id": o.split(".")[0], "property": o.split(".")[1].split("@")[0]}
        for o in key.strip(".").split("...")
    ]
    body = {
        "output": key,
        "outputs": outputs if len(outputs) > 1 else outputs[0],
        "inputs": [item(d) for d in spec["inputs"]],
        "state": [item(d) for d in spec["state"]],
        "changedPropIds": [trigger],
    }
    return client.post("/_dash-update-component", json=body)


def _no_traceback(caplog) -> None:
    assert not [r for r in caplog.records if r.exc_info], [r.getMessage() for r in caplog.records]
    assert "Traceback" not in caplog.text


@pytest.mark.parametrize(
    "body",
    [
        b"{not json",
        b"[1, 2, 3]",
        b"{}",
        b'{"output": "nope.children", "inputs": [], "changedPropIds": []}',
        b"null",
    ],
)
def test_gui_answers_malformed_callback_requests_with_400(gui, caplog, body):
    _, client = gui
    response = client.post("/_dash-update-component", data=body, content_type="application/json")
    assert response.status_code == 400
    assert response.get_json()["error"]
    _no_traceback(caplog)


def test_gui_answers_a_robot_outside_the_catalog_with_400(gui, caplog, tmp_path):
    import base64

    app, client = gui
    csv = b"q1,q2,q3,q4,q5,q6,x,y,z\n" + b"0,0,0,0,0,0,0.1,0.2,0.3\n" * 12
    uploaded = _callback(
        app,
        client,
        "csv-file.data",
        {  # the browser checks the size, then hands the file over in the csv-upload store
            ("csv-upload", "data"): {
                "contents": "data:text/csv;base64," + base64.b64encode(csv).decode(),
                "filename": "m.csv",
            },
        },
        "csv-upload.data",
    )
    assert uploaded.status_code == 200, uploaded.data
    token = uploaded.get_json()["response"]["csv-file"]["data"]
    options = {("opt-length", "value"): "m", ("opt-angle", "value"): "rad", ("opt-decimal", "value"): "."}
    options |= {("opt-orientation", "value"): "auto", ("opt-incomplete", "value"): "error"}
    options |= {("opt-limits", "value"): "error", ("csv-file", "data"): token}
    for robot_name in ("no-such-robot", "../ur10"):
        response = _callback(
            app, client, "csv-preview", options | {("cal-model", "value"): robot_name}, "cal-model.value"
        )
        assert response.status_code == 400, response.data
        assert "unknown robot" in response.get_json()["error"]
    good = _callback(
        app, client, "csv-preview", options | {("cal-model", "value"): "ur10"}, "cal-model.value"
    )
    assert good.status_code == 200, good.data
    _no_traceback(caplog)


def test_gui_refuses_an_upload_beyond_its_limit_before_reading_it(gui, caplog):
    from robocal.apps.gui.app import MAX_REQUEST_BYTES
    from robocal.apps.gui.jobs import MAX_UPLOAD_BYTES

    _, client = gui
    assert MAX_REQUEST_BYTES >= MAX_UPLOAD_BYTES * 4 // 3  # a file at the limit fits, in base64
    response = client.post(
        "/_dash-update-component", data=b" " * (MAX_REQUEST_BYTES + 1), content_type="application/json"
    )
    assert response.status_code == 413
    assert "limit" in response.get_json()["error"]
    _no_traceback(caplog)


# ------------------------------------------------------------------ sizes checked before parsing
def test_model_build_refuses_an_oversized_yaml_before_parsing_it(tmp_path, monkeypatch):
    """A YAML beyond the 5 MB limit is refused by its size: no YAML parser ever sees it."""
    import yaml

    from robocal.model.yaml_files import MAX_FILE_BYTES

    big = tmp_path / "big.yaml"
    row = "  - {name: j, type: revolute}\n"
    big.write_text("joints:\n" + row * (MAX_FILE_BYTES // len(row) + 10), encoding="utf-8")

    def parsed(*_args, **_kwargs):
        raise AssertionError("an oversized YAML reached the parser")

    for name in ("safe_load", "load", "parse", "compose"):
        monkeypatch.setattr(yaml, name, parsed)
    out = tmp_path / "model.yaml"
    result = runner.invoke(app, ["model", "build", str(big), "-o", str(out)])
    _one_error(result, "big.yaml", "too large")
    assert not out.exists()
