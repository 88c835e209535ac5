"""A calibration from constraints (ball in socket: no tracker) through the outputs: the HTML
report, URDF and UR kinematics exports, validate, compensate and filter.

One virtual UR10 (seeded errors) holds its tool ball in two sockets; it is calibrated on
one placement of the sockets through the command line and judged on another.
"""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from robocal.cli import app
from robocal.identify.constraints.fit import constraint_figures
from robocal.identify.constraints.result import load_constraint_calibration
from robocal.measure.constraints.data import read_constraints, write_constraints
from robocal.measure.constraints.sim import simulate_constraints
from robocal.measure.true_model import draw_true_model
from robocal.model.catalog import robot
from robocal.model.complete import calibration_model

runner = CliRunner()


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A constraint calibration folder, its calibration file and a held-out placement."""
    root = tmp_path_factory.mktemp("socket")
    true = draw_true_model(calibration_model(robot("ur10"), "position"), seed=3)
    for name, seed in (("socket.csv", 3), ("held.csv", 11)):
        data, _ = simulate_constraints(true, "point", 50, sigma=1e-5, count=2, seed=seed)
        write_constraints(data, root / name)
    out = root / "cal"
    res = runner.invoke(app, ["calibrate", "ur10", "--data", str(root / "socket.csv"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out, root / "socket.csv", root / "held.csv", true


def _copy(folder, tmp_path) -> Path:
    out = tmp_path / "cal"
    shutil.copytree(folder[0], out)
    return out


def _cells(html: str) -> str:
    """The page's text without plotly's script (what a reader sees in the tables)."""
    html = re.sub(r"<script.*?</script>", "", html, flags=re.S)
    return re.sub(r"<[^>]+>", " ", html)


def test_report_shows_the_kinds_figures_before_and_after(folder, tmp_path):
    out, train, held, _ = folder
    page_path = tmp_path / "r.html"
    res = runner.invoke(
        app, ["report", str(out), "--data", str(train), "--test-data", str(held), "-o", str(page_path)]
    )
    assert res.exit_code == 0, res.output
    html = page_path.read_text()
    text = _cells(html)
    cal = load_constraint_calibration(out)
    held_data = read_constraints(held, cal.model.dof)
    before = constraint_figures(cal.nominal, held_data).point_spread
    after = constraint_figures(cal.model, held_data).point_spread
    assert (after < before / 10).all()  # the calibration holds on another placement
    for b, a in zip(before, after, strict=True):  # the held-out rows: nominal and calibrated spread
        assert re.search(rf"RMS spread\s+{b * 1e3:.3f}\s+{a * 1e3:.3f}", text), (b, a)
    # what point data cannot see is named, and stays nominal
    for name in ("base_x", "base_y", "base_rx", "base_ry"):
        assert re.search(rf"{name}\s+redundant\s+nominal", text)
    assert "data-figure='constraint-bars-1'" in html and 'name="robocal-run"' in html
    # no device: no position-error sections of a tracker report
    sections = set(re.findall(r"<section id='([a-z0-9-]+)'", html))
    assert sections == {"summary", "figures", "identifiability", "scene", "provenance"}
    assert "position error mm" not in html  # no error histograms of a tracker report


def test_report_escapes_file_names_and_reads_the_recorded_file(folder, tmp_path):
    out, train, held, _ = folder
    hostile = tmp_path / "<img src=x onerror=alert(1)>.csv"
    shutil.copy(held, hostile)
    page_path = tmp_path / "r.html"
    # no --data: the calibration's own file as recorded (its SHA-256 checked)
    res = runner.invoke(app, ["report", str(out), "--test-data", str(hostile), "-o", str(page_path)])
    assert res.exit_code == 0, res.output
    html = page_path.read_text()
    assert "<img src=x" not in html and "&lt;img src=x" in html
    assert f"{train.name} (50 poses" in _cells(html)


def test_another_robots_file_is_refused_by_report_and_validate(folder, tmp_path):
    out, _, held, _ = folder
    seven = tmp_path / "seven.csv"  # a 7-joint robot's recording: q7 would be dropped unseen
    lines = held.read_text().splitlines()
    seven.write_text("\n".join([lines[0].replace("q6,", "q6,q7,")] + [_add_q7(r) for r in lines[1:]]))
    for command in (["report", str(out), "--test-data", str(seven), "-o", str(tmp_path / "r.html")],
                    ["validate", str(out), "--data", str(seven)]):  # fmt: skip
        res = runner.invoke(app, command)
        assert res.exit_code == 2 and "q7" in res.output and "Traceback" not in res.output, res.output
    assert not (tmp_path / "r.html").exists()


def _add_q7(row: str) -> str:
    cells = row.split(",")
    return ",".join([*cells[:6], "0.3", *cells[6:]])


def test_report_refuses_an_edited_model_and_notes_a_changed_file(folder, tmp_path):
    out = _copy(folder, tmp_path)
    doc = json.loads((out / "constraints.json").read_text())
    changed = tmp_path / "changed.csv"
    changed.write_text(Path(folder[1]).read_text() + "\n# one more line\n")
    (out / "constraints.json").write_text(json.dumps(doc | {"data": str(changed)}))
    page_path = tmp_path / "r.html"
    res = runner.invoke(app, ["report", str(out), "-o", str(page_path)])
    assert res.exit_code == 0 and "changed since the calibration" in res.output
    assert "socket.csv" not in _cells(page_path.read_text()).split("Provenance")[0]
    yaml_text = (out / "model.yaml").read_text()
    # an estimated length (a2 is held for the scale when no length was measured: issue 33)
    a3 = next(s for s in (out / "model.yaml").read_text().splitlines() if "param: a3," in s)
    (out / "model.yaml").write_text(yaml_text.replace(a3, a3.replace("value: 0.5", "value: 0.6")))
    res = runner.invoke(app, ["report", str(out), "-o", str(tmp_path / "r2.html")])
    assert res.exit_code == 2 and "a3" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "r2.html").exists()


@pytest.mark.parametrize(("kind", "headline"), [("plane", "RMS plane residual"), ("distance", "ball-bar")])
def test_report_of_plane_and_distance_calibrations(kind, headline, tmp_path):
    data = tmp_path / f"{kind}.csv"
    res = runner.invoke(app, ["simulate", "ur10", "--kind", kind, "--n", "40", "--count", "3", "--seed", "5",
                              "-o", str(data)])  # fmt: skip
    assert res.exit_code == 0, res.output
    out = tmp_path / "cal"
    assert runner.invoke(app, ["calibrate", "ur10", "--data", str(data), "--out", str(out)]).exit_code == 0
    res = runner.invoke(app, ["report", str(out), "-o", str(tmp_path / "r.html")])
    assert res.exit_code == 0, res.output
    text = _cells((tmp_path / "r.html").read_text())
    cal = load_constraint_calibration(out)
    figures = constraint_figures(cal.model, read_constraints(data, 6))
    values = figures.plane_rms if kind == "plane" else np.abs(figures.pair_error).max(keepdims=True)
    assert headline in text and all(f"{v * 1e3:.3f}" in text for v in values)
    assert re.search(r"base_x\s+(redundant|no effect)\s+nominal", text)  # the placement is not seen


@pytest.mark.parametrize(
    "damage",
    ["{not json", '{"kind": "tracker"}', '{"kind": "constraints", "names": ["a2"], "estimates": [1e9]}'],
)
def test_a_damaged_constraint_record_is_one_line_everywhere(folder, tmp_path, damage):
    out = _copy(folder, tmp_path)
    (out / "constraints.json").write_text(damage)
    targets = tmp_path / "t.csv"
    targets.write_text("name,x,y,z\nt1,0.5,0.2,0.6\n")
    for command in (
        ["report", str(out), "-o", str(tmp_path / "o.html")],
        ["export", "urdf", str(out), "-o", str(tmp_path / "o.urdf")],
        ["export", "ur-kinematics", str(out), "-o", str(tmp_path / "o.yaml")],
        ["compensate", str(out), "--targets", str(targets), "-o", str(tmp_path / "o.csv")],
    ):
        res = runner.invoke(app, command)
        lines = [line for line in res.output.splitlines() if line.startswith("error:")]
        assert res.exit_code == 2 and len(lines) == 1 and "constraints.json" in lines[0] + res.output, command
        assert "Traceback" not in res.output and not list(tmp_path.glob("o.*")), command


def _pin_frames(path: Path, frame: str, q: np.ndarray) -> np.ndarray:
    pin = pytest.importorskip("pinocchio")
    pm = pin.buildModelFromUrdf(str(path))
    data = pm.createData()
    out = []
    for qk in q:
        pin.framesForwardKinematics(pm, data, qk)
        out.append(data.oMf[pm.getFrameId(frame)].homogeneous.copy())
    return np.array(out)


def test_urdf_export_is_the_calibrated_chain_on_the_nominal_base(folder, tmp_path):
    out = folder[0]
    cal = load_constraint_calibration(out)
    urdf = tmp_path / "cal.urdf"
    res = runner.invoke(app, ["export", "urdf", str(out), "-o", str(urdf)])
    assert res.exit_code == 0, res.output
    q = np.random.default_rng(0).uniform(-3, 3, (40, 6))
    got = _pin_frames(urdf, "flange", q)
    np.testing.assert_allclose(got, cal.model.fk(q), atol=1e-9)  # closed loop: Pinocchio = the calibration
    assert np.abs(got[:, :3, 3] - cal.nominal.fk(q)[:, :3, 3]).max() > 1e-3  # and not the nominal robot
    comment = urdf.read_text().split("-->")[0]
    assert "base frame is nominal" in comment and "base_x" in comment
    catalog = calibration_model(robot("ur10"), "position")
    nominal = dict(zip(catalog.names, catalog.values, strict=True))
    calibrated = dict(zip(cal.model.names, cal.model.values, strict=True))
    for name in ("base_x", "base_y", "base_rx", "base_ry", "theta1"):  # left nominal, not invented
        assert name not in cal.names and calibrated[name] == nominal[name]
    res = runner.invoke(
        app, ["export", "urdf", str(out), "--device-link", "cell", "-o", str(tmp_path / "d.urdf")]
    )
    assert res.exit_code == 2 and "constraint calibration" in res.output
    assert not (tmp_path / "d.urdf").exists()


def test_ur_kinematics_export_is_the_calibrated_chain(folder, tmp_path):
    out = folder[0]
    model = load_constraint_calibration(out).model
    path = tmp_path / "kin.yaml"
    res = runner.invoke(app, ["export", "ur-kinematics", str(out), "-o", str(path)])
    assert res.exit_code == 0 and "base frame is nominal" in res.output, res.output
    from robocal.model.ur_kinematics import read_ur_kinematics, ur_kinematics

    q = np.random.default_rng(1).uniform(-3, 3, (30, 6))
    rest = ur_kinematics(model).T_flange_rest  # stated on stderr: the format cannot hold it
    assert np.abs(rest[:3, 3]).max() > 1e-5  # the ball offset the calibration found
    np.testing.assert_allclose(read_ur_kinematics(path).fk(q) @ rest, model.fk(q), atol=1e-9)


def test_validate_a_constraint_folder_on_a_held_out_placement(folder):
    out, _, held, _ = folder
    res = runner.invoke(app, ["validate", str(out), "--data", str(held)])
    assert res.exit_code == 0, res.output
    cal = load_constraint_calibration(out)
    spread = constraint_figures(cal.model, read_constraints(held, cal.model.dof)).point_spread
    before = constraint_figures(cal.nominal, read_constraints(held, cal.model.dof)).point_spread
    after_part, before_part = res.output.split("before calibration")
    for k, (s, b) in enumerate(zip(spread, before, strict=True)):
        assert f"point {k}: RMS spread {s * 1e3:.3f} mm" in after_part
        assert f"point {k}: RMS spread {b * 1e3:.3f} mm" in before_part


def test_compensate_corrects_relative_to_the_nominal_base_and_refuses_the_device_frame(folder, tmp_path):
    out = folder[0]
    cal = load_constraint_calibration(out)
    targets = tmp_path / "t.csv"
    targets.write_text("name,x,y,z\nt1,0.5,0.2,0.6\nt2,0.4,-0.3,0.5\n")
    res = runner.invoke(app, ["compensate", str(out), "--targets", str(targets), "--frame", "measurement",
                              "-o", str(tmp_path / "m.csv")])  # fmt: skip
    assert res.exit_code == 2 and "device frame" in res.output and not (tmp_path / "m.csv").exists()
    res = runner.invoke(
        app, ["compensate", str(out), "--targets", str(targets), "-o", str(tmp_path / "c.csv")]
    )
    assert res.exit_code == 0 and "base frame is nominal" in res.output, res.output
    rows = np.genfromtxt(tmp_path / "c.csv", delimiter=",", names=True)
    q = np.column_stack([rows[f"q{j}"] for j in range(1, 7)])
    qn = np.column_stack([rows[f"nominal_q{j}"] for j in range(1, 7)])
    target = np.array([[0.5, 0.2, 0.6], [0.4, -0.3, 0.5]])
    np.testing.assert_allclose(cal.model.fk(q)[:, :3, 3], target, atol=1e-6)  # the calibrated robot
    np.testing.assert_allclose(cal.nominal.fk(qn)[:, :3, 3], target, atol=1e-6)  # the controller's
    assert rows["predicted_error_before_mm"].min() > 0.1  # before: the nominal commands' error


def test_a_joint_program_needs_the_robot_the_calibration_started_from(folder, tmp_path):
    out = _copy(folder, tmp_path)
    program = tmp_path / "p.csv"
    program.write_text("q1,q2,q3,q4,q5,q6\n0.1,-1.2,1.5,0.3,1.1,0.0\n")
    res = runner.invoke(app, ["filter", str(out), str(program), "-o", str(tmp_path / "f.csv")])
    assert res.exit_code == 0, res.output
    corrected = np.genfromtxt(tmp_path / "f.csv", delimiter=",", names=True)
    cal = load_constraint_calibration(out)
    q = np.array([[corrected[f"q{j}"] for j in range(1, 7)]], dtype=float)
    q0 = np.array([[0.1, -1.2, 1.5, 0.3, 1.1, 0.0]])
    np.testing.assert_allclose(cal.model.fk(q)[:, :3, 3], cal.nominal.fk(q0)[:, :3, 3], atol=1e-6)
    doc = json.loads((out / "constraints.json").read_text())
    del doc["start"]  # a folder that does not record where it started
    (out / "constraints.json").write_text(json.dumps(doc))
    for command in (["filter", str(out), str(program)], ["compensate", str(out), "--program", str(program)]):
        res = runner.invoke(app, [*command, "-o", str(tmp_path / "g.csv")])
        assert res.exit_code == 2 and "--nominal" in res.output and not (tmp_path / "g.csv").exists()


PANDA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ball_in_socket"


def _placement_file(name: str, path: Path) -> None:
    """MUKCa's recordings of one placement (two sockets) as a constraint file."""
    holes = [np.loadtxt(PANDA / "panda_1" / name / f"hole_{h}.csv", delimiter=",") for h in (0, 1)]
    rows = [[*q, h] for h, qs in enumerate(holes) for q in qs]
    header = ",".join([f"q{j}" for j in range(1, 8)] + ["point"])
    path.write_text(
        header + "\n" + "\n".join(",".join(repr(float(v)) for v in r[:7]) + f",{r[7]}" for r in rows)
    )


@pytest.mark.skipif(not PANDA.is_dir(), reason="../shared/data/ball_in_socket is absent")
def test_real_panda_report_and_urdf_of_its_description(tmp_path):
    """The real Panda (MUKCa): calibrated on one placement through the command line, judged
    on another in the report, exported into its own URDF with the ball link: Pinocchio's
    ball centre is the calibrated model's."""
    from robocal.model.files import save_model
    from robocal.model.urdf.read import model_from_urdf

    urdf = PANDA / "urdf" / "panda.urdf"
    save_model(model_from_urdf(urdf, measure="position", tip="ball_link"), tmp_path / "panda.yaml")
    for name in ("front", "right"):
        _placement_file(name, tmp_path / f"{name}.csv")
    out = tmp_path / "cal"
    train = tmp_path / "front.csv"
    res = runner.invoke(app, ["calibrate", str(tmp_path / "panda.yaml"), "--data", str(train),
                              "--distance", "0,1=50mm", "--out", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["report", str(out), "--test-data", str(tmp_path / "right.csv"), "-o", str(tmp_path / "r.html")]
    )
    assert res.exit_code == 0, res.output
    cal = load_constraint_calibration(out)
    held = read_constraints(tmp_path / "right.csv", 7, distances=list(cal.distances))
    before, after = constraint_figures(cal.nominal, held), constraint_figures(cal.model, held)
    assert after.point_spread.max() < before.point_spread.min() / 5  # nominal: ~9 mm; calibrated: < 1 mm
    assert abs(after.point_distance_error[0]) < abs(before.point_distance_error[0])
    text = _cells((tmp_path / "r.html").read_text())
    assert re.search(rf"known distance 0: \|error\|\s+{abs(before.point_distance_error[0]) * 1e3:.3f}", text)
    res = runner.invoke(
        app,
        [
            "export",
            "urdf",
            str(out),
            "--urdf",
            str(urdf),
            "--tip",
            "ball_link",
            "-o",
            str(tmp_path / "p.urdf"),
        ],
    )
    assert res.exit_code == 0, res.output
    q = np.random.default_rng(0).uniform(-1.5, 1.5, (20, 7))
    q_pin = np.hstack([q, np.zeros((20, 2))])  # the fingers, off the chain
    np.testing.assert_allclose(
        _pin_frames(tmp_path / "p.urdf", "ball_link", q_pin), cal.model.fk(q), atol=1e-9
    )


def test_an_edit_of_a_parameter_the_fit_did_not_estimate_is_refused(folder, tmp_path):
    """The recorded SHA-256 of model.yaml catches what the estimates' check cannot: a socket
    calibration keeps the base nominal, and an edited base must not reach an export."""
    from robocal.identify.constraints.result import load_constraint_calibration

    out = _copy(folder, tmp_path)
    load_constraint_calibration(out)  # as written: accepted
    text = (out / "model.yaml").read_text()
    line = next(s for s in text.splitlines() if "param: base_z," in s or "param: base_x," in s)
    edited = line.split("value:")[0] + "value: 0.5}"
    (out / "model.yaml").write_text(text.replace(line, edited))
    with pytest.raises(ValueError, match=r"model\.yaml.*changed since the calibration"):
        load_constraint_calibration(out)
    res = runner.invoke(app, ["export", "urdf", str(out), "-o", str(tmp_path / "x.urdf")])
    assert res.exit_code == 2 and "changed since the calibration" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "x.urdf").exists()
