"""Issue 33: joint compliance for socket, plane and distance files through the command line.

A true UR10 that yields to gravity (a model file: the catalog's UR10 with its link masses and
a ``joint_effects`` block) is simulated by ``robocal simulate --kind point|plane``; ``robocal
calibrate ur10 --effects compliance`` recovers the compliances within 4σ of the truth, the
folder keeps them (constraints.json, model.yaml), ``validate`` / the report predict a held-out
placement with the deflections at the noise, the exports say they cannot carry them, and a
robot without link masses is refused by name.  The default (no --effects) fits none."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal.model
import robocal.model.files
from robocal.cli import app
from robocal.identify.constraints.fit import constraint_figures
from robocal.identify.constraints.result import load_constraint_calibration
from robocal.measure.constraints.data import read_constraints
from robocal.model.joints import joint_perturbations

TRUE = {"shoulder_lift": 4e-5, "elbow": 6e-5, "wrist_1": 1e-4}  # rad/(N·m): mm at the tool
NOISE = 1e-5  # m: simulate's default tool-point noise per axis


def _run(args: list[str]):
    return CliRunner().invoke(app, [str(a) for a in args])


def _elastic_model_file(folder: Path) -> Path:
    """The documented way to state a true robot's compliance: the catalog file plus a block."""
    catalog = Path(robocal.model.__file__).parent / "robots" / "ur10.yaml"
    block = "joint_effects:\n" + "".join(
        f"  - {{joint: {j}, compliance: {c:.1e}}}\n" for j, c in TRUE.items()
    )
    path = folder / "ur10_elastic.yaml"
    path.write_text(catalog.read_text(encoding="utf-8").rstrip("\n") + "\n" + block, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def sockets(tmp_path_factory):
    """Two placements of two sockets recorded on the elastic true robot; calibrated with
    ``--effects compliance`` and without."""
    folder = tmp_path_factory.mktemp("sockets")
    true = _elastic_model_file(folder)
    data = folder / "s.csv"
    made = _run(
        ["simulate", true, "--kind", "point", "--n", "50", "--seed", "3", "--placements", "2", "-o", data]
    )
    assert made.exit_code == 0, made.output
    elastic = _run(
        ["calibrate", "ur10", "--data", data, "--effects", "compliance", "--out", folder / "elastic"]
    )
    assert elastic.exit_code == 0, elastic.output
    rigid = _run(["calibrate", "ur10", "--data", data, "--out", folder / "rigid"])
    assert rigid.exit_code == 0, rigid.output
    return folder


def _within_4_sigma(doc: dict) -> list[str]:
    """Each fitted compliance's name, checked against the truth (zero where none is stated)."""
    fitted = {e["name"]: e for e in doc["joint_effects"]}
    for name, e in fitted.items():
        truth = TRUE.get(name.removeprefix("compliance_"), 0.0)
        assert abs(e["estimate_rad_per_Nm"] - truth) < 4 * e["std_rad_per_Nm"], name
    return sorted(fitted)


def test_simulated_rows_carry_the_deflections(sockets):
    """The true robot's compliance reaches the simulated rows (the truth file states it):
    the elastic robot seats them at the noise, its rigid twin leaves mm."""
    import dataclasses

    from robocal.model.complete import calibration_model
    from robocal.model.files import load_model

    truth = json.loads((sockets / "s.csv.truth.json").read_text())
    stated = truth["true_joint_effects_rad_per_Nm"]
    assert stated == {f"compliance_{j}": c for j, c in TRUE.items()}
    true = calibration_model(load_model(sockets / "ur10_elastic.yaml"), "position")
    true = true.with_values(truth["true_parameters"])
    data = read_constraints(sockets / "s.csv", 6)
    assert np.all(constraint_figures(true, data).point_spread < 2 * NOISE)
    rigid = dataclasses.replace(true, joint_effects=())
    assert np.all(constraint_figures(rigid, data).point_spread > 20 * NOISE)


def test_compliance_recovered_saved_and_predicts_held_out(sockets):
    doc = json.loads((sockets / "elastic" / "constraints.json").read_text())
    assert {f"compliance_{j}" for j in TRUE} <= set(_within_4_sigma(doc))
    cal = load_constraint_calibration(sockets / "elastic")
    assert {e.name for e in cal.joint_effects} >= {f"compliance_{j}" for j in TRUE}
    saved = {e.joint: e.compliance for e in cal.model.joint_effects}  # model.yaml carries them
    for e in cal.joint_effects:
        assert saved[e.name.removeprefix("compliance_")] == pytest.approx(e.value, rel=1e-12)
    # the robot it started from has none: the "before" figures and the controller's model are rigid
    assert cal.nominal is not None and not any(e.compliance for e in cal.nominal.joint_effects)
    held_out = read_constraints(sockets / "s.placement2.csv", 6)
    after = constraint_figures(cal.model, held_out).point_spread
    assert np.all(after < 3 * NOISE)
    rigid = load_constraint_calibration(sockets / "rigid")
    assert not rigid.joint_effects and not rigid.model.joint_effects  # the default fits none
    assert np.all(constraint_figures(rigid.model, held_out).point_spread > 5 * after)
    checked = _run(["validate", sockets / "elastic", "--data", sockets / "s.placement2.csv"])
    assert checked.exit_code == 0, checked.output
    shown = [float(v) for v in checked.output.split("before calibration")[0].split() if _number(v)]
    assert shown and max(shown) < 3 * NOISE * 1e3  # validate prints the deflected figures (mm)


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def test_report_and_exports_read_the_compliance(sockets, tmp_path):
    page = tmp_path / "r.html"
    made = _run(["report", sockets / "elastic", "--test-data", sockets / "s.placement2.csv", "-o", page])
    assert made.exit_code == 0, made.output
    assert "compliance_elbow" in page.read_text(encoding="utf-8")
    from robocal.evaluate.report.constraint_collect import collect_constraint_report

    cal = load_constraint_calibration(sockets / "elastic")
    report = collect_constraint_report(cal, test_data=read_constraints(sockets / "s.placement2.csv", 6))
    held_out = report.sets[0]  # the page's held-out figures: with the deflections, at the noise
    assert np.all(held_out.after.point_spread < 3 * NOISE) and np.all(held_out.before.point_spread > 0.3e-3)
    for kind, out in (("urdf", tmp_path / "c.urdf"), ("ur-kinematics", tmp_path / "c.yaml")):
        ex = _run(["export", kind, sockets / "elastic", "-o", out])
        assert ex.exit_code == 0 and out.is_file(), ex.output
        assert "not carried: joint effects (compliance" in ex.output
        rigid = _run(["export", kind, sockets / "rigid", "-o", tmp_path / f"rigid_{out.name}"])
        assert "joint effects" not in rigid.output
    targets = tmp_path / "targets.csv"
    targets.write_text("name,x,y,z\nt1,0.5,0.2,0.6\nt2,-0.3,0.5,0.4\n")
    done = _run(["compensate", sockets / "elastic", "--targets", targets, "-o", tmp_path / "elastic.csv"])
    assert done.exit_code == 0, done.output
    model = load_constraint_calibration(sockets / "elastic").model  # its commands carry its deflections
    q = np.loadtxt(tmp_path / "elastic.csv", delimiter=",", skiprows=1, usecols=range(1, 7), ndmin=2)
    landed = model.fk(q, joint_perturbations(model, q))[:, :3, 3]
    assert np.abs(landed - [[0.5, 0.2, 0.6], [-0.3, 0.5, 0.4]]).max() < 1e-6
    assert np.abs(model.fk(q)[:, :3, 3] - landed).max() > 2e-5  # the deflection is there to correct


def test_commands_from_a_model_file_stating_compliance_land_on_the_elastic_robot(tmp_path):
    """Closed loop: a model file stating compliances and link masses; ``compensate`` and
    ``filter`` on it; the elastic robot it states executes the commands and lands on the
    targets (before, the bare model's commands left the deflection in: ~mm)."""
    true = robocal.model.files.load_model(_elastic_model_file(tmp_path))
    rng = np.random.default_rng(4)
    q_nominal = rng.uniform([-2, -2, 0.5, -2, 0.5, -2], [2, -0.5, 2, 0, 2.5, 2], (6, 6))
    q_nominal[0] = [0.0, -np.pi / 2, 0.0, -np.pi / 2, 0.0, 0.0]  # upright: the wrist at its singularity
    wanted = true.fk(q_nominal)[:, :3, 3]
    targets = tmp_path / "targets.csv"
    targets.write_text("name,x,y,z\n" + "".join(f"t{i},{x},{y},{z}\n" for i, (x, y, z) in enumerate(wanted)))
    out = tmp_path / "q.csv"
    done = _run(["compensate", tmp_path / "ur10_elastic.yaml", "--targets", targets, "-o", out])
    assert done.exit_code in (0, 1), done.output
    rows = np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8")
    q = np.array([[row[f"q{j}"] for j in range(1, 7)] for row in np.atleast_1d(rows)], dtype=float)
    reached = np.isfinite(q).all(axis=1)
    assert reached[1:].all()  # a refused target (the singular one) is named, not written wrong
    landed = true.fk(q[reached], joint_perturbations(true, q[reached]))[:, :3, 3]
    assert np.abs(landed - wanted[reached]).max() < 1e-6
    sagged = true.fk(q_nominal, joint_perturbations(true, q_nominal))[:, :3, 3]
    assert np.abs(sagged - wanted).max() > 1e-4  # uncompensated: the deflection


def test_no_link_masses_refused_by_name(tmp_path):
    data = tmp_path / "i.csv"
    assert (
        _run(["simulate", "irb120", "--kind", "point", "--n", "20", "--seed", "1", "-o", data]).exit_code == 0
    )
    out = tmp_path / "cal"
    refused = _run(["calibrate", "irb120", "--data", data, "--effects", "compliance", "--out", out])
    assert refused.exit_code != 0 and not out.exists()
    line = refused.output.strip()
    assert "\n" not in line and "--effects" in line and "mass" in line and "Traceback" not in line
    wrong = _run(["calibrate", "ur10", "--data", data, "--effects", "stiction", "--out", out])
    assert wrong.exit_code != 0 and "--effects" in wrong.output and not out.exists()


def test_radial_needs_position_rows(tmp_path):
    """Radial compliance is a position row's effect: tilt rows alone refuse it by name."""
    tilt = tmp_path / "t.csv"
    assert _run(["simulate", "ur10", "--kind", "tilt", "--n", "12", "--seed", "2", "-o", tilt]).exit_code == 0
    out = tmp_path / "cal"
    refused = _run(["calibrate", "ur10", "--data", tilt, "--effects", "compliance,radial", "--out", out])
    assert refused.exit_code != 0 and "--effects" in refused.output and "radial" in refused.output
    assert not out.exists()


@pytest.mark.parametrize("kind", ["point", "plane", "distance"])
def test_tracker_beside_each_kind_with_compliance(kind, tmp_path):
    """A socket, plane or ball-bar file and the same true robot's tracker rows (deflected
    too) in one fit; the held-out placement (sockets, planes) predicted at the noise."""
    true = _elastic_model_file(tmp_path)
    data = tmp_path / "p.csv"
    placements = "1" if kind == "distance" else "2"  # a ball-bar has no placement to move
    made = _run(["simulate", true, "--kind", kind, "--n", "60", "--count", "3", "--seed", "4",
                 "--also-tracker", "30", "--placements", placements, "-o", data])  # fmt: skip
    assert made.exit_code == 0, made.output
    out = tmp_path / "cal"
    fit = _run(["calibrate", "ur10", "--data", data, "--data", tmp_path / "p.tracker.csv", "--effects",
                "compliance", "--out", out])  # fmt: skip
    assert fit.exit_code == 0, fit.output
    doc = json.loads((out / "constraints.json").read_text())
    assert {f"compliance_{j}" for j in TRUE} <= set(_within_4_sigma(doc))
    assert doc["tracker_data"]  # both files in the one fit
    if kind != "distance":
        figures = constraint_figures(load_constraint_calibration(out).model,
                                     read_constraints(tmp_path / "p.placement2.csv", 6))  # fmt: skip
        assert np.all(np.concatenate([figures.point_spread, figures.plane_rms]) < 3 * NOISE)


def test_sockets_and_tilt_rows_share_the_compliance(sockets, tmp_path):
    """Tilt readings of the same true robot beside the socket file: one compliance per joint
    (saved once), within 4σ of the truth and sharper than from the sockets alone."""
    tilt = tmp_path / "tilt.csv"
    made = _run(
        ["simulate", sockets / "ur10_elastic.yaml", "--kind", "tilt", "--n", "20", "--seed", "3", "-o", tilt]
    )
    assert made.exit_code == 0, made.output
    out = tmp_path / "mixed"
    fit = _run(["calibrate", "ur10", "--data", sockets / "s.csv", "--data", tilt, "--effects", "compliance",
                "--out", out])  # fmt: skip
    assert fit.exit_code == 0, fit.output
    doc = json.loads((out / "constraints.json").read_text())
    names = [e["name"] for e in doc["joint_effects"]]
    assert len(names) == len(set(names)) and {f"compliance_{j}" for j in TRUE} <= set(_within_4_sigma(doc))
    alone = {
        e["name"]: e
        for e in json.loads((sockets / "elastic" / "constraints.json").read_text())["joint_effects"]
    }
    for e in doc["joint_effects"]:
        if e["name"] in alone:
            assert e["std_rad_per_Nm"] < alone[e["name"]]["std_rad_per_Nm"]


def test_a_model_files_stated_compliance_held_or_left_out(sockets, tmp_path):
    """A model file stating compliances and masses predicts the sockets with them, held (the
    default); ``--effects none`` leaves them out, as the tracker calibration's ``none`` does."""
    model = sockets / "ur10_elastic.yaml"
    runs = {}
    for name, extra in (("held", []), ("none", ["--effects", "none"])):
        done = _run(["calibrate", model, "--data", sockets / "s.csv", *extra, "--out", tmp_path / name])
        assert done.exit_code == 0, done.output
        runs[name] = load_constraint_calibration(tmp_path / name)
    held = {e.joint: e.compliance for e in runs["held"].model.joint_effects}
    assert held == TRUE and not runs["held"].joint_effects  # carried, not fitted
    assert not runs["none"].model.joint_effects
    test = read_constraints(sockets / "s.placement2.csv", 6)
    spread = {k: constraint_figures(c.model, test).point_spread for k, c in runs.items()}
    assert np.all(spread["held"] < spread["none"])


def test_a_model_file_stating_compliance_without_masses_is_refused_by_compensate(tmp_path):
    text = _elastic_model_file(tmp_path).read_text(encoding="utf-8")
    start = text.index("bodies:")
    end = text.index("\n", text.rindex("  - {name:", start))
    bare = tmp_path / "no_masses.yaml"
    bare.write_text(text[:start] + text[end + 1 :], encoding="utf-8")
    targets = tmp_path / "t.csv"
    targets.write_text("name,x,y,z\nt1,0.5,0.2,0.6\n")
    out = tmp_path / "q.csv"
    refused = _run(["compensate", bare, "--targets", targets, "-o", out])
    line = refused.output.strip()
    assert refused.exit_code != 0 and not out.exists()
    assert "\n" not in line and "no_masses.yaml" in line and "mass" in line and "Traceback" not in line
