"""Robot programs filtered through a calibration in their own language: byte identity,
the closed loop on a virtual robot, malformed input."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
import robocal.compensate.programs.config as program_config
import robocal.compensate.programs.krl as program_krl
import robocal.compensate.programs.rapid as program_rapid
import robocal.compensate.programs.values as program_values
from robocal import spatial
from robocal.cli import app
from robocal.compensate.compensation import nominal_model
from robocal.compensate.programs.filter_file import filter_program_file, filter_program_text
from robocal.compensate.programs.syntax import ProgramError
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate
from robocal.measure.ik import solve_ik

EXAMPLES = Path(__file__).parents[1] / "examples" / "programs"
runner = CliRunner()
PROBE = np.array([0.0, 0.0, 0.1])


def _unstamped(written: bytes) -> bytes:
    """A written KRL file without its ``;robocal run: ID`` line (the pair's run id), which
    must be there exactly once."""
    lines = written.splitlines(keepends=True)
    stamps = [ln for ln in lines if ln.startswith(b";robocal run: ")]
    assert len(stamps) == 1, stamps
    return b"".join(ln for ln in lines if ln not in stamps)


@pytest.mark.parametrize(
    ("program", "robot", "options"),
    [
        ("pick.script", "ur10", {}),
        ("pick.src", "kr16", {}),
        ("pick.mod", "irb120", {}),
        ("targets.csv", "ur10", {"length_unit": "mm"}),
    ],
)
def test_nominal_calibration_leaves_every_language_byte_identical(tmp_path, program, robot, options):
    out = tmp_path / program
    result = filter_program_file(EXAMPLES / program, rc.robot(robot), out, **options)
    if program.endswith(".src"):  # byte-identical but for the pair's run id line
        assert _unstamped(out.read_bytes()) == (EXAMPLES / program).read_bytes()
        assert _unstamped(out.with_suffix(".dat").read_bytes()) == (EXAMPLES / "pick.dat").read_bytes()
    else:
        assert out.read_bytes() == (EXAMPLES / program).read_bytes()
    assert len(result.targets) >= 3 and not result.changed.any()
    assert result.reachable.all(), result.problems


def test_unsupported_statements_are_listed_and_untouched():
    kinds = {}
    for program, robot in (("pick.script", "ur10"), ("pick.src", "kr16"), ("pick.mod", "irb120")):
        res = filter_program_file(EXAMPLES / program, rc.robot(robot))
        kinds[program] = [(Path(u.file).name, u.line) for u in res.unsupported]
    assert kinds == {
        "pick.script": [("pick.script", 15)],
        "pick.src": [("pick.src", 17), ("pick.src", 16)],
        "pick.mod": [("pick.mod", 17)],
    }


@pytest.fixture(scope="module")
def cell():
    """A UR10 with known errors, calibrated on simulated laser-tracker data, and its
    held-out error."""
    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=PROBE))
    data = simulate(robot, random_poses(nominal, 150, seed=1), seed=1)
    result = rc.calibrate(nominal, data.subset(np.arange(100)), tool_guess=PROBE)
    held_out = rc.validate(result, data.subset(np.arange(100, 150)))
    return nominal, robot, result, held_out


def _program(q_joint, T_pose, q_before_pose=None):
    """URScript: movej to each joint target, then for each pose a movej to the
    configuration it is approached from (the branch) and a movel to a named pose."""
    lines = [
        "def prog():",
        "  # generated for the closed-loop test",
        f"  set_tcp(p[0, 0, {PROBE[2]}, 0, 0, 0])",
    ]
    for k, q in enumerate(q_joint):
        lines.append(f"  movej([{', '.join(f'{v:.9f}' for v in q)}], a=1.4, v=1.05)  # J{k}")
    for k, T in enumerate(T_pose):
        if q_before_pose is not None:
            lines.append(f"  movej([{', '.join(f'{v:.9f}' for v in q_before_pose[k])}], a=1.4, v=1.05)")
        rv = spatial.matrix_to_rotvec(T[:3, :3])
        values = [*T[:3, 3], *rv]
        lines.append(f"  target_{k} = p[{', '.join(f'{v:.9f}' for v in values)}]")
        lines.append(f"  movel(target_{k}, a=0.5, v=0.1)")
    return "\n".join(lines) + "\nend\n"


def test_closed_loop_filtered_program_lands_on_its_targets(cell, tmp_path):
    """Targets in the robot base frame as the calibration located it in the cell; the
    program's tool is the tracker's probe, so the tracker sees where the targets land."""
    from robocal.compensate.programs.urscript import parse_urscript

    nominal, robot, result, held_out = cell
    T_probe = spatial.transl(*PROBE)
    q = random_poses(nominal, 40, seed=11)
    q = q[np.linalg.svd(nominal.joint_jacobian(q), compute_uv=False)[:, -1] > 0.05][:16]
    q_joint, q_pose = np.r_[q[:8], q[8:]], q[8:]
    T_pose = nominal.fk(q_pose) @ T_probe  # probe poses in the base frame
    goal_joint = (result.frame @ nominal.fk(q_joint) @ T_probe)[:, :3, 3]  # in the cell
    goal_pose = (result.frame @ T_pose)[:, :3, 3]
    path = tmp_path / "prog.script"
    path.write_text(_program(q[:8], T_pose, q_before_pose=q_pose))
    out = tmp_path / "filtered.script"
    res = filter_program_file(path, result, out, probe=PROBE)
    assert res.reachable.all() and res.branch_kept.all(), res.problems
    # what the controller is told, run on the true robot (the controller's IK: nominal model)
    targets, _, tool = parse_urscript(out.read_text(), 6, "filtered")
    targets = sorted(targets, key=lambda t: (t.kind, t.line))  # 8 movej, then the approach movej
    np.testing.assert_allclose(tool, T_probe)
    got_joint = np.array([[t.value for t in tg.tokens] for tg in targets if tg.kind == "joint"])
    got_pose = np.array([[t.value for t in tg.tokens] for tg in targets if tg.kind == "pose"])
    P_cmd = spatial.homogeneous(spatial.rotvec_to_matrix(got_pose[:, 3:]), got_pose[:, :3])
    controller = nominal  # the controller believes the nominal model
    q_ctrl = solve_ik(
        controller, P_cmd @ spatial.inverse(T_probe), kind="pose", q0=q_pose, restarts=0, tol=1e-11
    ).q

    def landed(qc):
        return robot.device.predict(robot.true.fk(qc)).position

    after = np.r_[
        np.linalg.norm(landed(got_joint) - goal_joint, axis=1),
        np.linalg.norm(landed(q_ctrl) - goal_pose, axis=1),
    ]
    before = np.r_[
        np.linalg.norm(landed(q_joint) - goal_joint, axis=1),
        np.linalg.norm(landed(q_pose) - goal_pose, axis=1),
    ]
    print(
        f"closed loop: before mean {before.mean() * 1e3:.3f} max {before.max() * 1e3:.3f} mm, after mean "
        f"{after.mean() * 1e3:.4f} max {after.max() * 1e3:.4f} mm; held-out RMS {held_out.rms * 1e3:.4f} "
        f"max {held_out.max * 1e3:.4f} mm"
    )
    assert after.max() <= held_out.max
    assert before.mean() >= 5 * after.mean()


def test_nominal_result_leaves_the_program_identical(cell, tmp_path):
    nominal, _, result, _ = cell
    nominal_result = dataclasses.replace(result, model=nominal_model(result))
    q = random_poses(nominal, 10, seed=4)
    text = _program(q[:4], nominal.fk(q[4:]))
    res = filter_program_text({"p.script": text}, "urscript", nominal_result)
    assert res.texts["p.script"] == text


@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        (
            "bad.script",
            "def p():\n  movel(p[0.1, 0.2, 0.3, 0, 0], a=1)\nend\n",
            r"bad\.script: line 2: a pose p\[\.\.\.\] needs 6",
        ),
        (
            "bad.mod",
            "MODULE M\n  CONST robtarget p1:=[[1,2,3],[1,0,0]];\nENDMODULE\n",
            r"bad\.mod: line 2: robtarget p1",
        ),
        ("bad.csv", "name,x,y,z\nA,1,2,zz\n", r"bad\.csv: line 2, column 'z'"),
        ("bad.src", "DEF bad()\nPTP {A1 0, A2 1\nEND\n", r"bad\.src: line 2"),
    ],
)
def test_malformed_programs_name_file_and_line_and_write_nothing(tmp_path, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    out = tmp_path / ("out" + path.suffix)
    with pytest.raises(ProgramError, match=message):
        filter_program_file(path, rc.robot("ur10"), out)
    assert not out.exists()
    res = runner.invoke(app, ["filter", str(_model_file(tmp_path)), str(path), "-o", str(out)])
    assert res.exit_code == 2 and not out.exists()


def _model_file(folder):
    path = folder / "ur10.yaml"
    if not path.exists():
        rc.save_model(rc.robot("ur10"), path)
    return path


def test_cli_filter_writes_the_corrected_program(cell, tmp_path):
    _, _, result, _ = cell
    folder = tmp_path / "cal"
    result.save(folder)
    out = tmp_path / "pick.script"
    res = runner.invoke(  # a probe far from the measured tool the calibration identified: refused
        app, ["filter", str(folder), str(EXAMPLES / "pick.script"), "--probe", "0,0,130mm", "-o", str(out)]
    )
    assert res.exit_code == 2 and "--probe" in res.output and not out.exists()
    assert "130.00" in res.output and "apart" in res.output  # both values named
    res = runner.invoke(
        app,
        [
            "filter",
            str(folder),
            str(EXAMPLES / "pick.script"),
            "-o",
            str(out),
        ],  # no --probe: the measured tool the calibration identified
    )
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "7 targets (urscript)" in text and "untouched" in text
    new, old = out.read_text().splitlines(), (EXAMPLES / "pick.script").read_text().splitlines()
    assert len(new) == len(old) and sum(a != b for a, b in zip(new, old, strict=True)) == 6


def _turn(q):
    """KUKA's turn T: bit j set when axis j + 1 is negative."""
    return sum(1 << j for j in range(6) if q[j] < 0)


def _status(q, model):
    """KUKA's status S (bits 0-2) of joint values ``q``."""
    from robocal.compensate.programs.config import _status

    return _status(model or rc.robot("kr16"), q)


def _cf(q, model):
    """ABB's cf1, cf4, cf6 (quadrants of axes 1, 4, 6) and cfx."""
    from robocal.compensate.programs.config import _cfx

    return ",".join(str(int(np.floor(np.degrees(q[j]) / 90))) for j in (0, 3, 5)) + f",{_cfx(model, q)}"


def _krl(q_joint, T_pose, q_before_pose, q_config=None, model=None):
    """A KRL .src and .dat: PTP to E6AXIS, then PTP to the approach axes and LIN to an E6POS."""
    src, dat = ["DEF prog( )", "; generated for the closed-loop test"], ["DEFDAT prog", "; targets"]
    for k, q in enumerate(np.r_[q_joint, q_before_pose]):
        axes = ",".join(f"A{j + 1} {np.degrees(v):.6f}" for j, v in enumerate(q))
        dat.append(f"DECL E6AXIS XJ{k}={{{axes},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}")
    for k in range(len(q_joint)):
        src.append(f"PTP XJ{k}")
    q_c = q_before_pose if q_config is None else q_config
    for k, T in enumerate(T_pose):
        a, b, c = np.degrees(spatial.zyx_angles(T[:3, :3]))
        x, y, z = T[:3, 3] * 1e3
        dat.append(
            f"DECL E6POS XP{k}={{X {x:.4f},Y {y:.4f},Z {z:.4f},A {a:.5f},B {b:.5f},C {c:.5f},"
            f"S {_status(q_c[k], model)},T {_turn(q_c[k])},E1 0.0}}"
        )
        src += [f"PTP XJ{len(q_joint) + k}", f"LIN XP{k} C_DIS"]
    return {"prog.src": "\n".join(src + ["END"]) + "\n", "prog.dat": "\n".join(dat + ["ENDDAT"]) + "\n"}


def _rapid(q_joint, T_pose, q_before_pose, q_config=None, model=None):
    lines = ["MODULE Prog", "    ! generated for the closed-loop test"]
    lines.append(
        f"    PERS tooldata probe:=[TRUE,[[0,0,{PROBE[2] * 1e3:.1f}],[1,0,0,0]],"
        "[0.1,[0,0,1],[1,0,0,0],0,0,0]];"
    )
    for k, q in enumerate(np.r_[q_joint, q_before_pose]):
        lines.append(
            f"    CONST jointtarget j{k}:=[[{','.join(f'{np.degrees(v):.6f}' for v in q)}],"
            "[9E9,9E9,9E9,9E9,9E9,9E9]];"
        )
    q_config = q_before_pose if q_config is None else q_config
    for k, T in enumerate(T_pose):
        qu = spatial.matrix_to_quaternion(T[:3, :3])
        lines.append(
            f"    CONST robtarget p{k}:=[[{','.join(f'{v * 1e3:.4f}' for v in T[:3, 3])}],"
            f"[{','.join(f'{v:.9f}' for v in qu)}],[{_cf(q_config[k], model or rc.robot('irb120'))}],"
            "[9E9,9E9,9E9,9E9,9E9,9E9]];"
        )
    lines.append("    PROC main()")
    lines += [f"        MoveAbsJ j{k}, v1000, fine, probe;" for k in range(len(q_joint))]
    for k in range(len(T_pose)):
        lines += [
            f"        MoveAbsJ j{len(q_joint) + k}, v1000, fine, probe;",
            f"        MoveL p{k}, v100, fine, probe;",
        ]
    return {"prog.mod": "\n".join(lines + ["    ENDPROC", "ENDMODULE"]) + "\n"}


@pytest.mark.parametrize(("language", "robot_name"), [("krl", "kr16"), ("rapid", "irb120")])
def test_closed_loop_krl_and_rapid(tmp_path, language, robot_name):

    nominal = rc.robot(robot_name)
    true = draw_true_model(nominal, length=1e-3, angle=np.radians(0.1), seed=5)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=PROBE))
    data = simulate(robot, random_poses(nominal, 150, seed=2), seed=2)
    result = rc.calibrate(nominal, data.subset(np.arange(100)), tool_guess=PROBE)
    held_out = rc.validate(result, data.subset(np.arange(100, 150)))
    T_probe = spatial.transl(*PROBE)
    q = random_poses(nominal, 60, seed=12)
    q = q[np.linalg.svd(nominal.joint_jacobian(q), compute_uv=False)[:, -1] > 0.05][:12]
    q_joint, q_pose = q[:6], q[6:]
    T_pose = nominal.fk(q_pose) @ T_probe
    texts = (_krl if language == "krl" else _rapid)(q_joint, T_pose, q_pose)
    tool = T_probe if language == "krl" else None
    res = filter_program_text(texts, language, result, tool=tool, probe=PROBE)
    assert res.reachable.all() and res.branch_kept.all() and not res.problems, res.problems
    assert not res.unsupported
    # read back what the controller gets, run it on the true robot
    units = program_values.UNITS[language]
    got = {}
    for label, text in res.texts.items():
        parse = program_krl.parse_krl if language == "krl" else program_rapid.parse_rapid
        parsed = parse(text, 6, label)[0]
        for t in parsed:
            got[t.name] = program_values.read_value(t, units, nominal.joint_types, False)
    n_j = len(q_joint)
    prefix_j, prefix_p = ("XJ", "XP") if language == "krl" else ("j", "p")
    got_joint = np.array([got[f"{prefix_j}{k}"] for k in range(n_j)])
    P_cmd = np.array([got[f"{prefix_p}{k}"] for k in range(len(q_pose))])
    q_ctrl = solve_ik(
        nominal, P_cmd @ spatial.inverse(T_probe), kind="pose", q0=q_pose, restarts=0, tol=1e-11
    ).q

    def landed(qc):
        return robot.device.predict(true.fk(qc)).position

    goal_joint = (result.frame @ nominal.fk(q_joint) @ T_probe)[:, :3, 3]
    goal_pose = (result.frame @ T_pose)[:, :3, 3]
    after = np.r_[
        np.linalg.norm(landed(got_joint) - goal_joint, axis=1),
        np.linalg.norm(landed(q_ctrl) - goal_pose, axis=1),
    ]
    before = np.r_[
        np.linalg.norm(landed(q_joint) - goal_joint, axis=1),
        np.linalg.norm(landed(q_pose) - goal_pose, axis=1),
    ]
    print(
        f"{language}: before mean {before.mean() * 1e3:.3f} mm, after mean {after.mean() * 1e3:.4f} max "
        f"{after.max() * 1e3:.4f} mm; held-out max {held_out.max * 1e3:.4f} mm"
    )
    assert after.max() <= held_out.max
    assert before.mean() >= 5 * after.mean()
    # and a nominal calibration leaves both byte-identical
    assert filter_program_text(texts, language, nominal, tool=tool).texts == texts


def test_krl_crlf_latin1_kept_and_angles_within_180(tmp_path):
    src = (
        (EXAMPLES / "pick.src")
        .read_bytes()
        .replace(b"\n", b"\r\n")
        .replace(b"; a small", "; Ä small".encode("latin-1"))
    )
    dat = (EXAMPLES / "pick.dat").read_bytes().replace(b"\n", b"\r\n")
    (tmp_path / "p.src").write_bytes(src)
    (tmp_path / "p.dat").write_bytes(dat)
    nominal = rc.robot("kr16")
    filter_program_file(tmp_path / "p.src", nominal, tmp_path / "out" / "p.src")
    assert _unstamped((tmp_path / "out" / "p.src").read_bytes()) == src
    assert _unstamped((tmp_path / "out" / "p.dat").read_bytes()) == dat
    moved = nominal.with_free_values(nominal.free_values + 1e-3)
    res = filter_program_file(tmp_path / "p.src", moved, tmp_path / "out2" / "p.src", nominal=nominal)
    assert res.changed.sum() == 7 and not res.problems
    new = (tmp_path / "out2" / "p.dat").read_bytes()
    assert new.count(b"\r\n") == dat.count(b"\r\n") + 1  # the run id line, CRLF too
    new_src = (tmp_path / "out2" / "p.src").read_bytes()
    assert new_src.count(b"\r\n") == src.count(b"\r\n") + 1 and "; Ä small".encode("latin-1") in new_src
    import re

    for name, value in re.findall(rb"\b([ABC]) (-?\d+\.\d+)", new + new_src):
        assert abs(float(value)) <= 180.0, (name, value)


def test_mutated_programs_raise_only_program_errors():
    """Seeded random damage to every example: a ProgramError (file and line) or a result."""
    import random

    rng = random.Random(0)
    cases = [
        ("pick.script", "urscript", "ur10"),
        ("pick.src", "krl", "kr16"),
        ("pick.mod", "rapid", "irb120"),
    ]
    cases.append(("targets.csv", "csv", "ur10"))
    models = {name: rc.robot(name) for name in ("ur10", "kr16", "irb120")}
    pieces = ["[", "]", "{", "}", ",", "p[", "1e400", "nan", "-", ".", "(", ")", ";", "\n", "9E9", "0,0,0,0"]
    for _ in range(40):
        name, language, robot = rng.choice(cases)
        text = (EXAMPLES / name).read_text()
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(text))
            if rng.random() < 0.4:
                text = text[:i] + text[i + rng.randint(1, 5) :]
            else:
                text = text[:i] + rng.choice(pieces) + text[i:]
        try:
            filter_program_text({name: text}, language, models[robot])
        except ProgramError as err:
            assert str(err).startswith(name) and "\n" not in str(err)


def test_unreachable_target_reported_with_line_and_strict_exit(cell, tmp_path):
    _, _, result, _ = cell
    folder = tmp_path / "cal"
    result.save(folder)
    path = tmp_path / "far.script"
    path.write_text("def far():\n  movel(p[5.0, 0.0, 0.3, 0.0, 3.14159, 0.0], a=0.5, v=0.1)\nend\n")
    args = ["filter", str(folder), str(path), "-o"]
    res = runner.invoke(app, [*args, str(tmp_path / "a.script")])
    assert res.exit_code == 1  # refused (issue 31): non-zero unless --partial
    assert "far.script: line 2: target line 2: not reachable" in " ".join(res.output.split())
    assert (tmp_path / "a.script").read_text() == path.read_text()  # left as written
    assert runner.invoke(app, [*args, str(tmp_path / "b.script"), "--partial"]).exit_code == 0
    assert runner.invoke(app, [*args, str(tmp_path / "c.script"), "--partial", "--strict"]).exit_code == 1


@pytest.mark.parametrize(
    ("option", "value", "hint"),
    [
        ("--probe", "0,0,109m", "109 m from the flange"),
        ("--tool", "0,0,109m,0,0,1.5rad", "109 m from the flange"),
        ("--probe", "0,0,109", "add the unit"),
        ("--tool", "0,0,109,0,0,1.5", "add the unit"),
    ],
)
def test_filter_refuses_a_tool_given_in_millimetres(cell, tmp_path, option, value, hint):
    """Every length option takes a unit (one spelling in every command): a bare 109 is
    refused, and so is a tool 109 m from the flange, in one line; nothing is written."""
    _, _, result, _ = cell
    folder = tmp_path / "cal"
    result.save(folder)
    out = tmp_path / "pick.script"
    args = ["filter", str(folder), str(EXAMPLES / "pick.script"), option, value, "-o", str(out)]
    res = runner.invoke(app, args)
    text = " ".join(res.output.split())
    assert res.exit_code == 2 and not out.exists()
    assert f"{option} '{value}':" in text and hint in text and "Traceback" not in text


@pytest.mark.parametrize("language", ["krl", "rapid"])
def test_written_configuration_chooses_the_branch(language):
    """The same Cartesian target in two configurations (A5/axis 4 and 6 flipped): each
    corrected in its own branch; the approach configuration is the other one."""

    robot = "kr16" if language == "krl" else "irb120"
    nominal = rc.robot(robot)
    moved = nominal.with_free_values(nominal.free_values + 5e-4)
    q_a = np.radians([10.0, -70.0, 80.0, 30.0, 40.0, 20.0] if language == "krl" else [10, 10, 10, 30, 40, 20])
    q_b = q_a + np.radians([0, 0, 0, -180, 0, -180])
    q_b[4] = -q_a[4]  # the wrist flip
    T_probe = spatial.transl(*PROBE)
    T = nominal.fk(q_a) @ T_probe
    np.testing.assert_allclose(nominal.fk(q_b) @ T_probe, T, atol=1e-9)  # the wrist flip: same pose
    # written in branch b (T / cf), approached from branch a
    texts = (_krl if language == "krl" else _rapid)(q_a[None], T[None], q_a[None], q_config=q_b[None])
    res = filter_program_text(texts, language, moved, nominal, tool=T_probe)
    assert not res.problems, res.problems
    pose = next(t for t in res.targets if t.kind == "pose")
    units = program_values.UNITS[language]
    label = pose.file
    parsed = (
        program_krl.parse_krl(res.texts[label], 6, label)[0]
        if language == "krl"
        else program_rapid.parse_rapid(res.texts[label], 6, label)[0]
    )
    pose = next(t for t in parsed if t.kind == "pose")
    P = program_values.read_value(pose, units, nominal.joint_types, False)
    # the controller solves it in branch b (where it was written): the real robot lands on T
    from robocal.measure.ik import solve_ik

    q_ctrl = solve_ik(
        nominal, P[None] @ spatial.inverse(T_probe), kind="pose", q0=q_b, restarts=0, tol=1e-12
    ).q[0]
    assert program_config.config_ok(pose, q_ctrl) and np.abs(q_ctrl - q_b).max() < 0.05
    assert np.linalg.norm((moved.fk(q_ctrl) @ T_probe)[:3, 3] - T[:3, 3]) < 1e-6  # the written resolution


@pytest.mark.parametrize("language", ["krl", "rapid"])
def test_written_status_or_cfx_not_reachable_is_reported_and_left_as_written(language):
    """A target written 'overhead' (KUKA S bit 0, ABB cfx digit 4) while T / cf1 pins
    axis 1 in front: no solution in that configuration; reported with file, line, name
    and the bit, left as written; a nominal calibration leaves it byte-identical."""

    robot = "kr16" if language == "krl" else "irb120"
    nominal = rc.robot(robot)
    moved = nominal.with_free_values(nominal.free_values + 5e-4)
    q_a = np.radians([10.0, -70.0, 80.0, 30.0, 40.0, 20.0] if language == "krl" else [10, 10, 10, 30, 40, 20])
    T_probe = spatial.transl(*PROBE)
    T = nominal.fk(q_a) @ T_probe
    texts = (_krl if language == "krl" else _rapid)(q_a[None], T[None], q_a[None])
    label = "prog.dat" if language == "krl" else "prog.mod"
    if language == "krl":
        s = program_config._status(nominal, q_a)
        texts[label] = texts[label].replace(f"S {s},", f"S 'B{s ^ 1:03b}',")  # KRL binary literal
        name, what = "XP0", "S bit 0 (overhead) 1 -> 0"
    else:
        c = program_config._cfx(nominal, q_a)
        texts[label] = texts[label].replace(f",{c}],[9E9", f",{c ^ 4}],[9E9")
        name, what = "p0", f"cfx {c ^ 4} -> {c}"
    line = next(k + 1 for k, s in enumerate(texts[label].splitlines()) if name + "=" in s or name + ":=" in s)
    res = filter_program_text(texts, language, moved, nominal, tool=T_probe)
    expected = f"{label}: line {line}: target {name}: reachable only in another configuration ({what}"
    assert any(p.startswith(expected) for p in res.problems), res.problems
    assert len(res.problems) == 1 and not res.ok
    pose = next(i for i, t in enumerate(res.targets) if t.kind == "pose")
    assert not res.changed[pose]
    assert res.changed.any()  # the joint targets are corrected
    assert filter_program_text(texts, language, nominal, tool=T_probe).texts == texts


def _frames_cell(language):
    """A nominal and a moved robot, a base / work object frame and targets written in it."""
    robot = "kr16" if language == "krl" else "irb120"
    nominal = rc.robot(robot)
    moved = nominal.with_free_values(nominal.free_values + 5e-4)
    W = spatial.homogeneous(spatial.rotz(np.radians(30.0)), [0.1, -0.2, 0.05])
    q = random_poses(nominal, 30, seed=4)
    q = q[np.linalg.svd(nominal.joint_jacobian(q), compute_uv=False)[:, -1] > 0.05][:4]
    T_probe = spatial.transl(*PROBE)
    T_pose = spatial.inverse(W) @ nominal.fk(q[2:]) @ T_probe
    return nominal, moved, W, T_probe, (_krl if language == "krl" else _rapid)(q[:2], T_pose, q[2:])


def test_krl_tool_and_base_read_from_config_dat(tmp_path):
    """$TOOL = TOOL_DATA[3] / $BASE = BASE_DATA[2] resolved from $config.dat (KUKA A, B, C
    = rotations about Z, Y, X in degrees) give what --tool/--base give."""
    nominal, moved, W, T_probe, texts = _frames_cell("krl")
    texts["prog.src"] = texts["prog.src"].replace(
        "; generated for the closed-loop test", "$BASE = BASE_DATA[2]\n$TOOL = TOOL_DATA[3]"
    )
    cfg = (
        "DEFDAT $CONFIG\n"
        f"TOOL_DATA[3]={{X 0.0,Y 0.0,Z {PROBE[2] * 1e3:.1f},A 0.0,B 0.0,C 0.0}}\n"
        "BASE_DATA[2]={X 100.0,Y -200.0,Z 50.0,A 30.0,B 0.0,C 0.0}\nENDDAT\n"
    )
    read = filter_program_text(texts, "krl", moved, nominal, config_dat=("$config.dat", cfg))
    given = filter_program_text(texts, "krl", moved, nominal, tool=T_probe, base=W)
    assert read.texts == given.texts and not read.problems and read.changed.all()
    assert filter_program_text(texts, "krl", moved, nominal).texts != read.texts  # the frames matter
    assert filter_program_text(texts, "krl", nominal, config_dat=("$config.dat", cfg)).texts == texts
    # from files: $config.dat next to the program; an index it lacks names file and line
    for name, text in texts.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "$config.dat").write_text(cfg)
    res = filter_program_file(tmp_path / "prog.src", moved, nominal=nominal)
    assert res.texts[str(tmp_path / "prog.dat")] == read.texts["prog.dat"]
    (tmp_path / "other.dat").write_text(cfg.replace("BASE_DATA[2]", "BASE_DATA[5]"))
    with pytest.raises(ProgramError, match=r"prog.src: line 2: BASE_DATA\[2\] is not in .*other.dat"):
        filter_program_file(tmp_path / "prog.src", moved, nominal=nominal, config_dat=tmp_path / "other.dat")


def test_rapid_tool_and_wobj_read_from_the_module():
    """Each Move's tooldata and \\WObj (uframe · oframe) declared in the module give what
    --tool/--base give; tool0/wobj0 are the flange and the base."""
    nominal, moved, W, T_probe, texts = _frames_cell("rapid")
    u = spatial.matrix_to_quaternion(spatial.rotz(np.radians(30.0)))
    text = texts["prog.mod"].replace(
        "    PROC main()",
        f'    PERS wobjdata table:=[FALSE,TRUE,"",[[100,-200,40],[{",".join(f"{v:.12f}" for v in u)}]],'
        "[[0,0,10],[1,0,0,0]]];\n"
        "    PERS tooldata other:=[TRUE,[[0,0,0],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\n    PROC main()",
    )
    text = text.replace("v100, fine, probe;", "v100, fine, probe \\WObj:=table;")
    read = filter_program_text({"prog.mod": text}, "rapid", moved, nominal)
    given = filter_program_text({"prog.mod": text}, "rapid", moved, nominal, tool=T_probe, base=W)
    assert read.texts == given.texts and not read.problems and read.changed.all()
    assert filter_program_text({"prog.mod": text}, "rapid", nominal).texts == {"prog.mod": text}
    unknown = filter_program_text(
        {"prog.mod": text.replace("\\WObj:=table", "\\WObj:=elsewhere")}, "rapid", moved, nominal
    )
    assert any("wobjdata elsewhere is declared outside the module" in p for p in unknown.problems)
    # a target moved to under two work objects: corrected for the first, the other reported
    twice = text.replace("    ENDPROC", "        MoveL p0, v100, fine, probe;\n    ENDPROC")
    res = filter_program_text({"prog.mod": twice}, "rapid", moved, nominal)
    line = next(k + 1 for k, s in enumerate(twice.splitlines()) if "p0:=" in s)
    last = len(twice.splitlines()) - 2
    assert (
        f"prog.mod: line {line}: target p0: moved to with another tool or base at prog.mod: line {last}"
        in (" ".join(res.problems))
    )


def test_cli_config_dat_and_strict_configuration_change(tmp_path):
    """--config-dat names the $config.dat (a missing one: one line, exit 2); a target
    reachable only in another configuration is a warning naming file, line and target,
    exit 1 with --strict."""

    nominal = rc.robot("kr16")
    moved = nominal.with_free_values(nominal.free_values + 5e-4)
    rc.save_model(moved, tmp_path / "moved.yaml")
    q_a = np.radians([10.0, -70.0, 80.0, 30.0, 40.0, 20.0])
    T = nominal.fk(q_a) @ spatial.transl(*PROBE)
    texts = _krl(q_a[None], T[None], q_a[None])
    s = program_config._status(nominal, q_a)
    texts["prog.dat"] = texts["prog.dat"].replace(f"S {s},", f"S {s ^ 1},")
    texts["prog.src"] = texts["prog.src"].replace(
        "; generated for the closed-loop test", "$TOOL = TOOL_DATA[1]"
    )
    for name, text in texts.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "cfg.dat").write_text(
        f"TOOL_DATA[1]={{X 0.0,Y 0.0,Z {PROBE[2] * 1e3:.1f},A 0.0,B 0.0,C 0.0}}\n"
    )
    args = ["filter", str(tmp_path / "moved.yaml"), str(tmp_path / "prog.src")]
    args += ["--nominal", "kr16", "-o", str(tmp_path / "out" / "prog.src")]
    res = runner.invoke(app, [*args, "--config-dat", str(tmp_path / "none.dat")])
    assert res.exit_code == 2 and "none.dat: no such $config.dat" in " ".join(res.output.split())
    res = runner.invoke(app, [*args, "--config-dat", str(tmp_path / "cfg.dat")])
    assert res.exit_code == 1, res.output  # refused (issue 31): non-zero unless --partial
    assert "prog.dat: line 5: target XP0: reachable only in another configuration (S bit 0" in " ".join(
        res.output.split()
    )
    res = runner.invoke(app, [*args, "--config-dat", str(tmp_path / "cfg.dat"), "--partial", "--force"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, [*args, "--config-dat", str(tmp_path / "cfg.dat"), "--strict", "--force"])
    assert res.exit_code == 1
