"""Issue 31: invariants on every command robocal writes — the joint-change bound, damped
corrections near singularities, the configuration kept, refused targets left as written and
named (exit 1 unless --partial), the per-target table beside the output; --nominal gives
one configuration on every catalog robot; the issue's repros through the CLI."""

import csv
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.compensate.compensation import compensate_targets, filter_program
from robocal.compensate.result import table_path
from robocal.compensate.safety import (
    MAX_DAMPED,
    SINGULAR_SIGMA,
    configurations,
    same_configuration,
    sigma_min,
)
from robocal.measure import draw_true_model, random_poses

EXAMPLES = Path(__file__).parents[1] / "examples" / "programs"
runner = CliRunner()
TOOL = np.array([0.0, 0.0, 0.1])


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _write_program(path, names, q):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", *(f"q{j + 1}" for j in range(q.shape[1]))])
        for name, row in zip(names, q, strict=True):
            w.writerow([name, *(repr(float(v)) for v in row)])


@pytest.fixture(scope="module")
def ur10(tmp_path_factory):
    """A UR10 calibrated through the CLI's default path (complete model, residual auto) on
    simulated data (±0.5 mm, ±0.05°, tool 100 mm)."""
    folder = tmp_path_factory.mktemp("ur10")
    poses, data = folder / "poses.csv", folder / "data.csv"
    assert runner.invoke(app, ["poses", "ur10", "-o", str(poses), "--n", "60", "--seed", "1"]).exit_code == 0
    res = runner.invoke(
        app, ["simulate", "ur10", "--poses", str(poses), "-o", str(data), "--tool-offset", "0,0,100mm"]
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["calibrate", "ur10", "--data", str(data), "-o", str(folder / "cal"), "--tool", "0,0,100mm"]
    )
    assert res.exit_code == 0, res.output
    return folder


# ---------------------------------------------------------------- singular wrist (repro)
def test_singular_wrist_program_is_damped_not_thrown_around(ur10, tmp_path):
    """|q5| = 1e-4 rad: every joint moves at most 0.1 rad (the old filter turned wrist 1 and
    wrist 3 by ±1.5 rad and called it reachable); the table names them damped."""
    q = np.array(
        [[0.3, -1.2, 1.5, -0.5, s * 1e-4, 0.2] for s in (1, -1)] + [[0.3, -1.2, 1.5, -0.5, 0.5, 6.2]]
    )
    program, out = tmp_path / "p.csv", tmp_path / "o.csv"
    _write_program(program, ["s+", "s-", "wound"], q)
    res = runner.invoke(app, ["compensate", str(ur10 / "cal"), "--program", str(program), "-o", str(out)])
    assert res.exit_code == 0, res.output
    rows = _rows(out)
    q_new = np.array([[float(r[f"q{j}"]) for j in range(1, 7)] for r in rows])
    assert np.abs(q_new - q).max() <= MAX_DAMPED
    assert np.abs(q_new[2, 5] - 6.2) < 0.01  # the 2π winding of joint 6 is kept
    table = _rows(table_path(out))
    assert [r["status"] for r in table] == ["damped", "damped", "corrected"]
    assert all(float(r["sigma_min"]) < SINGULAR_SIGMA for r in table[:2])


def test_damped_correction_still_improves_and_is_bounded():
    nominal = rc.robot("ur10")
    real = draw_true_model(nominal, length=0.5e-3, angle=np.radians(0.05), seed=2)
    q = np.array([[0.3, -1.2, 1.5, -0.5, q5, 0.2] for q5 in (0.0, 1e-4, -1e-3, 0.01)])
    comp = filter_program(real, q, nominal)
    assert set(comp.status) == {"damped"}
    assert np.all(np.abs(comp.q - q) <= np.minimum(MAX_DAMPED, comp.joint_bound) + 1e-12)
    # damping gives up only the singular direction: the position error still falls
    assert np.all(comp.error_after < 0.5 * comp.error_before)


# ---------------------------------------------------------------- refusals
def test_refused_target_left_as_written_named_and_exit_1_unless_partial(ur10, tmp_path):
    targets = tmp_path / "t.csv"
    targets.write_text("name,x,y,z\nnear,-600,-400,500\n=far,9000,0,0\n")
    out = tmp_path / "o.csv"
    args = ["compensate", str(ur10 / "cal"), "--targets", str(targets), "--length-unit", "mm", "-o", str(out)]
    res = runner.invoke(app, args)
    assert res.exit_code == 1 and "far" in res.output
    rows = _rows(out)
    assert [r["status"] for r in rows] == ["corrected", "refused"]
    q = [float(rows[1][f"q{j}"]) for j in range(1, 7)]
    assert q == [float(rows[1][f"nominal_q{j}"]) for j in range(1, 7)]  # left as written
    table = table_path(out).read_text()
    assert "'=far" in table and "\n=far" not in table  # strings escaped for spreadsheets
    res = runner.invoke(app, [*args, "--partial", "--force"])
    assert res.exit_code == 0, res.output


def test_joint_change_beyond_the_bound_is_refused():
    """A "calibrated" model 3° off on joint 2 is no calibration: its corrections exceed the
    bound (at most 5°) ... unless the bound is derived from that same model, so compare to a
    nominal model the calibration did not start from."""
    nominal = rc.robot("kr16")
    real = nominal.with_free_values(nominal.free_values)  # same geometry ...
    names = list(real.names)
    wrong = real.with_values({names[names.index("theta2")]: np.radians(8.0)}) if "theta2" in names else None
    if wrong is None:
        pytest.skip("kr16 has no theta2 parameter")
    q = random_poses(nominal, 20, seed=3)
    q = q[sigma_min(nominal, q, None, "pose") > 0.05]
    comp = filter_program(wrong, q, nominal)
    assert comp.joint_bound.max() <= np.radians(5.0) + 1e-12
    ok = comp.accepted
    assert np.all(np.abs(comp.q[ok] - q[ok]) <= comp.joint_bound[ok] + 1e-12)
    assert np.array_equal(comp.q[~ok], q[~ok])  # refused: the programmed joints as written
    assert all(r for s, r in zip(comp.status, comp.reasons, strict=True) if s == "refused")


# ---------------------------------------------------------------- --nominal, one configuration
def _compensate_pick_targets(ur10, out, *options):
    """``robocal compensate`` of the example's targets (mm) with ``options``, into ``out``."""
    targets = ["--targets", str(EXAMPLES / "targets.csv"), "--length-unit", "mm"]
    return runner.invoke(app, ["compensate", str(ur10 / "cal"), *targets, *options, "-o", str(out)])


def _nominal_q(row: dict) -> np.ndarray:
    return np.array([float(row[f"nominal_q{j}"]) for j in range(1, 7)])


def test_nominal_ur10_keeps_the_pick_target_in_the_approach_configuration(ur10, tmp_path):
    out = tmp_path / "o.csv"
    res = _compensate_pick_targets(ur10, out, "--nominal", "ur10")
    assert res.exit_code == 0, res.output
    rows = {r["name"]: r for r in _rows(out)}
    q = {k: _nominal_q(r) for k, r in rows.items()}
    assert np.abs(q["pick"][3:] - q["approach"][3:]).max() < 0.05  # the wrist does not flip
    table = {r["name"]: r for r in _rows(table_path(out))}
    assert table["pick"]["configuration"] == table["approach"]["configuration"]
    for r in rows.values():
        assert float(r["predicted_angle_error_after_deg"]) < 1e-3


def test_q0_in_degrees_chooses_the_configuration_of_every_target(ur10, tmp_path):
    """The help's own --q0 (with its unit): every target is solved in q0's configuration,
    wrist side included whatever the winding; the repro's --nominal of another robot is refused."""
    out = tmp_path / "o.csv"
    res = _compensate_pick_targets(ur10, out, "--nominal", "ur10", "--q0", "0,-90,90,0,90,0deg")
    assert res.exit_code == 0, res.output
    nominal = rc.robot("ur10")
    q = np.array([_nominal_q(r) for r in _rows(out)])
    q0 = np.radians([0, -90, 90, 0, 90, 0])
    assert same_configuration(nominal, q, q0).all(), configurations(nominal, q)
    assert np.all(np.sin(q[:, 4]) > 0.5)  # the wrist on q0's side (q5 = 90 deg)
    res = _compensate_pick_targets(ur10, tmp_path / "k.csv", "--nominal", "kr16")
    assert res.exit_code == 2 and not (tmp_path / "k.csv").exists(), res.output


def test_same_configuration_reads_the_wrist_side_through_the_winding():
    nominal = rc.robot("ur10")
    q = np.array([0.3, -1.0, 1.2, 0.2, 1.5, 0.1])
    wound, flipped = q + [0, 0, 0, 0, 2 * np.pi, 0], q * [1, 1, 1, 1, -1, 1]
    assert same_configuration(nominal, np.array([wound]), q).all()
    assert not same_configuration(nominal, np.array([flipped, flipped + [0, 0, 0, 0, 2 * np.pi, 0]]), q).any()


@pytest.mark.parametrize("robot", [n for n in rc.robots() if rc.robot(n).dof >= 6])
def test_nominal_model_gives_one_configuration_on_every_catalog_robot(robot):
    """Targets near one configuration: the controller's model solves all of them in it,
    and the corrected commands stay within 0.05 rad of the true joints."""
    nominal = rc.robot(robot)
    real = draw_true_model(nominal, length=0.5e-3, angle=np.radians(0.05), seed=1)
    rng = np.random.default_rng(5)
    q_all = random_poses(nominal, 40, seed=11)
    q_ref = q_all[np.argmax(sigma_min(nominal, q_all, None, "pose"))]
    q_true = q_ref + rng.uniform(-0.15, 0.15, (6, nominal.dof))
    q_true = np.clip(q_true, nominal.joint_limits[:, 0], nominal.joint_limits[:, 1])
    comp = compensate_targets(real, real.fk(q_true), nominal, q0=q_ref)  # the branch: q0's
    assert comp.success, comp.refused
    assert len(set(comp.configuration)) == 1, comp.configuration
    assert set(configurations(nominal, comp.q)) == set(comp.configuration)
    assert np.abs(comp.q - q_true).max() < 0.05
    # without q0: still one configuration for the file (the PUMA's joint limits once split
    # these six targets over four configurations)
    free = compensate_targets(real, real.fk(q_true), nominal)
    assert free.success and len(set(free.configuration)) == 1, free.configuration


# ---------------------------------------------------------------- KR 16 filter (repro)
def test_kr16_default_model_filter_keeps_axes_and_predicts_millimetres(tmp_path):
    """`robocal filter CAL examples/programs/pick.src` (with the repro's --probe 0,0,0.1m or
    the probe stated at calibration by default) on a default KR 16 calibration: every axis changes by at most
    1°, the predicted error is at most 10 mm, nothing refused (exit 0)."""
    poses, data, cal = tmp_path / "p.csv", tmp_path / "d.csv", tmp_path / "cal"
    assert runner.invoke(app, ["poses", "kr16", "-o", str(poses), "--n", "60", "--seed", "2"]).exit_code == 0
    res = runner.invoke(
        app, ["simulate", "kr16", "--poses", str(poses), "-o", str(data), "--tool-offset", "0,0,100mm"]
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app, ["calibrate", "kr16", "--data", str(data), "-o", str(cal), "--tool", "0,0,100mm"]
    )
    assert res.exit_code == 0, res.output
    old = (EXAMPLES / "pick.src").read_text()
    # the probe: by default the tool stated at the calibration (issue 31 item 1); then the
    # repro's own --probe (with its unit) and the repro's wrong sign, which is refused
    for k, probe in enumerate(([], ["--probe", "0,0,0.1m"], ["--probe", "0,0,-0.1m"])):
        out = tmp_path / f"out{k}" / "pick.src"
        res = runner.invoke(app, ["filter", str(cal), str(EXAMPLES / "pick.src"), "-o", str(out), *probe])
        if k == 2:
            assert res.exit_code == 2 and not out.exists(), res.output
            continue
        assert res.exit_code == 0, res.output
        text = " ".join(res.output.split())
        before = float(text.split("predicted error ")[1].split(" mm")[0])
        assert 0 < before <= 10.0
        axes_old, axes_new = _axes(old), _axes(out.read_text())
        assert len(axes_old) == len(axes_new) > 0
        assert np.abs(np.array(axes_new) - np.array(axes_old)).max() <= 1.0


def _axes(text: str) -> list[list[float]]:
    import re

    out = []
    for m in re.finditer(r"\{A1 ([^}]*)\}", text):
        out.append([float(v) for v in re.findall(r"A\d\s+(-?[\d.]+)", "A1 " + m.group(1))[:6]])
    return out
