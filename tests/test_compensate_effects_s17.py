"""Compensating a 5-axis Katana 450 program with the joint effects its catalog model states
(clearance tilt, backlash, compliance; seed 003 Table 5.2), and backlash near zero load.

The true robot is the katana model WITH its effects (the thesis' signs) executing the
written commands; the targets are the effect-free model's tool points at the program's q.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.compensate.compensation import filter_program
from robocal.model.files import save_model
from robocal.model.joints import joint_perturbations, load_moments

TOL = 1e-6  # m: the IK's reachability tolerance (compensate's default)
# the program of the report: points 1 and 3 have q2 below joint 2's lower limit (-30 deg)
REPRO = [[0.3, -0.6, -1.0, 0.2, 0.1], [0.5, 0.3, -1.2, -0.4, 0.3], [0.3, -1.409, -1.0, 0.2, 0.1]]
# ordinary points within the limits; Z: joint 2's gravity load +0.006 N*m (zero at q2 = 1.7334), where
# the IK chattered between the flanks and refused the point as not reachable
ORDINARY = {"A": [0.3, -0.3, -1.0, 0.2, 0.1], "B": [0.5, 0.3, -1.2, -0.4, 0.3]}
ZERO_LOAD = [0.3, 1.7340, -1.0, 0.2, 0.1]


@pytest.fixture(scope="module")
def katana(tmp_path_factory):
    folder = tmp_path_factory.mktemp("katana")
    save_model(rc.robot("katana450"), folder / "katana.yaml")
    return folder / "katana.yaml"


def _run(args):
    return CliRunner().invoke(app, [str(a) for a in args])


def _program(path, rows: dict[str, list[float]]):
    path.write_text(
        "name,q1,q2,q3,q4,q5\n" + "".join(f"{k},{','.join(map(str, v))}\n" for k, v in rows.items())
    )
    return path


def _commands(out) -> dict[str, np.ndarray]:
    rows = np.atleast_1d(np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8"))
    return {str(r["name"]): np.array([float(r[f"q{j}"]) for j in range(1, 6)]) for r in rows}


def _landed(q, flank_q2: float | None = None) -> np.ndarray:
    """Tool points (m) of the true robot at commands ``q``; ``flank_q2``: joint 2's backlash
    forced onto that flank (+1 or -1), as a joint with a small load may sit."""
    true = rc.robot("katana450")
    q = np.atleast_2d(q)
    d = joint_perturbations(true, q)
    if flank_q2 is not None:
        e = {x.joint: x for x in true.joint_effects}["q2"]
        d[:, 1, 2] = flank_q2 * e.backlash + e.compliance * load_moments(true, q)[:, 1, 2]
    return true.fk(q, d)[:, :3, 3]


def test_the_reported_program_names_its_out_of_limit_points_and_corrects_the_other(katana, tmp_path):
    """Points 1 and 3 were refused as 'joint 3 would move 7.32 deg' / 'joint 2 would move
    50.7 deg': the IK, clipped to the limits, started elsewhere.  They are refused naming
    q2, its value and its limits; point 2 lands; the 'before' column is the effects' error."""
    prog = tmp_path / "prog2.csv"
    prog.write_text("q1,q2,q3,q4,q5\n" + "".join(",".join(map(str, r)) + "\n" for r in REPRO))
    out = tmp_path / "out2.csv"
    done = _run(["compensate", katana, "--program", prog, "--kind", "position", "-o", out, "--json"])
    assert done.exit_code == 1  # refused by name, output as written
    doc = json.loads(done.stdout.splitlines()[0])
    rows = doc["targets"]
    assert [r["status"] for r in rows] == ["refused", "corrected", "refused"]
    for r in (rows[0], rows[2]):
        assert "q2" in r["reason"] and "limits" in r["reason"] and "-30" in r["reason"]
        assert r["q"] == r["nominal_q"]
    true_before = np.linalg.norm(_landed(REPRO) - rc.robot("katana450").fk(np.array(REPRO))[:, :3, 3], axis=1)
    before = np.array([r["predicted_error_before_mm"] for r in rows]) * 1e-3
    np.testing.assert_allclose(before[:2], true_before[:2], rtol=1e-6)  # known, not '-'
    q = _commands(out)["2"]
    target = rc.robot("katana450").fk(np.array([REPRO[1]]))[0, :3, 3]
    assert np.linalg.norm(_landed(q)[0] - target) < TOL
    assert np.abs(q - REPRO[1]).max() < math.radians(0.5)  # a small change near the program's q


def test_an_ordinary_program_and_its_zero_load_point_land_closed_loop(katana, tmp_path):
    """Every point corrected by a small joint change (exit 0); A and B land on the true robot
    within the IK tolerance; Z, where joint 2's load crosses zero, is corrected without
    chattering between flanks (it was 'not reachable'), lands within its reported flank
    spread on either flank, and is named in a warning."""
    rows = {**ORDINARY, "Z": ZERO_LOAD}
    out = tmp_path / "o.json"
    done = _run(["compensate", katana, "--program", _program(tmp_path / "p.csv", rows), "--kind", "position",
                 "-o", out])  # fmt: skip
    assert done.exit_code == 0, done.output
    doc = {r["name"]: r for r in json.loads(out.read_text())["targets"]}
    assert {r["status"] for r in doc.values()} == {"corrected"}
    targets = rc.robot("katana450").fk(np.array(list(rows.values())))[:, :3, 3]
    q = np.array([doc[k]["q"] for k in rows])
    assert np.abs(q - np.array(list(rows.values()))).max() < math.radians(1.0)
    landed = _landed(q)
    assert np.linalg.norm(landed[:2] - targets[:2], axis=1).max() < TOL
    assert doc["A"]["flank_spread_mm"] == 0 and doc["B"]["flank_spread_mm"] == 0
    spread = doc["Z"]["flank_spread_mm"] * 1e-3
    assert 1e-4 < spread < 2e-3
    flanks = [np.linalg.norm(_landed(q[2], s)[0] - targets[2]) for s in (-1.0, 1.0)]
    assert max(flanks) <= spread + TOL and max(flanks) > 10 * TOL  # the uncertainty is real
    assert "Z:" in done.stderr and "flank" in done.stderr


def test_the_flank_is_continuous_across_a_zero_load():
    """With a flank band the backlash term is a ramp through zero (no jump for Newton to
    chatter on); without one it is the thesis' sign."""
    m = rc.robot("katana450")
    q = np.array([ZERO_LOAD, [0.3, 1.7325, -1.0, 0.2, 0.1]])  # q2's load on either side of zero
    eta = load_moments(m, q)[:, 1, 2]
    assert eta[0] * eta[1] < 0 and np.abs(eta).max() < 0.02
    band = np.full((5, 2), 0.5)
    step = joint_perturbations(m, q)[:, 1, 2]
    ramp = joint_perturbations(m, q, flank_band=band)[:, 1, 2]
    assert abs(step[0] - step[1]) > 1.5 * m.joint_effects[1].backlash
    assert abs(ramp[0] - ramp[1]) < 0.1 * m.joint_effects[1].backlash


def test_filter_on_the_katana_model_uses_its_effects(katana, tmp_path):
    """``robocal filter`` on a model file stating joint effects: they were left out (0.000 mm
    'before', nothing changed, exit 0).  Now B's written joints move and the true robot lands
    on the effect-free tool point and axis; an out-of-limit point is refused by name."""
    prog = _program(tmp_path / "f.csv", {"B": ORDINARY["B"], "C": REPRO[0]})
    out = tmp_path / "f_out.csv"
    done = _run(["filter", katana, prog, "-o", out])
    assert done.exit_code == 1  # C: q2 outside its limits, left as written
    assert "line 3" in done.stderr and "q2" in done.stderr and "limits" in done.stderr
    q = _commands(out)
    np.testing.assert_array_equal(q["C"], REPRO[0])
    assert np.abs(q["B"] - ORDINARY["B"]).max() > 1e-4
    nominal = rc.robot("katana450").fk(np.array([ORDINARY["B"]]))[0]
    true = rc.robot("katana450")
    T = true.fk(q["B"][None], joint_perturbations(true, q["B"][None]))[0]
    assert np.linalg.norm(T[:3, 3] - nominal[:3, 3]) < 1e-5  # the CSV's written resolution (7 digits)
    assert np.degrees(np.arccos(np.clip(T[:3, 2] @ nominal[:3, 2], -1, 1))) < 1e-3


def test_the_api_refuses_out_of_limit_program_points_and_reports_the_spread():
    m = rc.robot("katana450")
    res = filter_program(m, np.array([REPRO[0], ORDINARY["A"], ZERO_LOAD]), kind="position")
    assert res.status == ("refused", "corrected", "corrected")
    assert "limits" in res.reasons[0] and res.flank_spread[2] > 1e-4 and res.flank_notes[2]
    assert res.notes and "q1" in res.notes[0]  # joint 1 (vertical) carries no load anywhere


@pytest.mark.parametrize("method", ["ik", "jacobian"])
def test_a_path_through_the_zero_load_is_corrected_without_a_jump(method):
    """Joint 2's load crosses zero mid-path: every sample corrected (the samples past zero
    were refused as not reachable, the correction stepping 0.58 deg between neighbours), the
    correction changing smoothly; a path sample outside the limits is refused by name."""
    from robocal.compensate.paths import compensate_path

    q = np.array([[0.3, q2, -1.0, 0.2, 0.1] for q2 in np.linspace(1.72, 1.745, 26)])
    res = compensate_path(rc.robot("katana450"), q, method=method, kind="position")
    assert set(res.status) == {"corrected"}
    assert res.correction_step.max() < math.radians(0.02)
    assert res.flank_spread.max() > 1e-4  # the samples near zero load are named
    beyond = compensate_path(rc.robot("katana450"), np.array(REPRO), method=method, kind="position")
    assert beyond.status[0] == "refused" and "limits" in beyond.reasons[0]
