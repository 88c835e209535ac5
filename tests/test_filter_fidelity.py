"""Program filters that change only targets (issue 38, item 3) and read bounded input
(item 5): comments and strings are not code, every motion is corrected or listed, a
``--nominal`` of another robot is refused, KRL pairs are read and written as pairs."""

import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
import robocal.compensate.programs.filter_file as programs
from robocal.cli import app
from robocal.compensate.compensation import filter_program
from robocal.compensate.programs.filter_file import filter_program_file, filter_program_text
from robocal.compensate.programs.krl import krl_run_id
from robocal.compensate.programs.syntax import ProgramError
from robocal.measure import draw_true_model

EXAMPLES = Path(__file__).parents[1] / "examples" / "programs"
runner = CliRunner()


def _moved(robot: str):
    """(nominal, a robot ~2 mm / 0.2° off it): every target the filter sees moves."""
    nominal = rc.robot(robot)
    return nominal, draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)


def _error_line(result) -> str:
    """The one ``error:`` line a refused command prints (exit 2, no traceback)."""
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, result.stderr
    return errors[0]


def _changed_lines(before: str, after: str) -> set[int]:
    a, b = before.splitlines(), after.splitlines()
    assert len(a) == len(b)
    return {k + 1 for k, (x, y) in enumerate(zip(a, b, strict=True)) if x != y}


# ---------------------------------------------------------------------- comments and strings
URSCRIPT = """def p():
  # old: movej([0.1, -1.2, 1.3, -1.4, -1.5, 0.6], a=1.4, v=1.05)
  textmsg("movel(p[0.5, 0.1, 0.4, 0, 3.14, 0])")
  movej([0.1, -1.2, 1.3, -1.4, -1.5, 0.6], a=1.4, v=1.05)  # then movel(p[0.5, 0.1, 0.4, 0, 3.14, 0])
  popup("target = p[0.5, 0.1, 0.4, 0, 3.14, 0]", "x = [1, 2]", blocking=True)
  # target = p[0.5, 0.1, 0.4, 0, 3.14, 0]
  movej([0.3, -1.0, 1.2, -1.6, -1.5, 0.2], a=1.4, v=1.05)
end
"""

KRL_SRC = """&ACCESS RVP
DEF c( )
; PTP {A1 10.0, A2 -80.0, A3 100.0, A4 10.0, A5 30.0, A6 10.0}
;DECL E6AXIS XOLD={A1 1.0,A2 -80.0,A3 90.0,A4 0.0,A5 40.0,A6 0.0}
MsgNotify("PTP {A1 10.0, A2 -80.0, A3 100.0, A4 10.0, A5 30.0, A6 10.0}")
PTP {A1 20.0, A2 -80.0, A3 100.0, A4 10.0, A5 30.0, A6 10.0} ; was {A1 21.0, A2 -80.0}
PTP XHOME ; {A1 1.0, A2 -80.0, A3 100.0, A4 10.0, A5 30.0, A6 10.0}
END
"""

# a robtarget (mm, quaternion, configuration, external axes) and a second one 13.75 mm lower
_RT = "[[374.76,143.05,513.75],[0.311829,-0.025779,0.937437,0.152675],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"
_RT2 = _RT.replace("513.75", "500")

RAPID = """MODULE C
    ! CONST robtarget pOld:=@RT;
    CONST jointtarget j1:=[[10,10,10,10,30,10],[9E9,9E9,9E9,9E9,9E9,9E9]];
    PROC main()
        TPWrite "MoveAbsJ [[20,10,10,10,30,10],[9E9,9E9,9E9,9E9,9E9,9E9]]";
        MoveAbsJ j1, v1000, fine, tool0; ! MoveAbsJ [[20,10,10,10,30,10],[9E9,9E9,9E9,9E9,9E9,9E9]]
    ENDPROC
ENDMODULE
""".replace("@RT", _RT)


@pytest.mark.parametrize(
    ("language", "robot", "text", "target_lines"),
    [("urscript", "ur10", URSCRIPT, {4, 7}), ("krl", "kr16", KRL_SRC, {6}), ("rapid", "irb120", RAPID, {3})],
)
def test_comments_and_strings_are_not_targets(language, robot, text, target_lines):
    """Motions and literals inside comments and strings are kept byte for byte; only the
    code's targets are read and rewritten."""
    nominal, real = _moved(robot)
    label = {"urscript": "c.script", "krl": "c.src", "rapid": "c.mod"}[language]
    result = filter_program_text({label: text}, language, real, nominal)
    assert {t.line for t in result.targets} == target_lines
    assert result.changed.all()
    assert _changed_lines(text, result.texts[label]) == target_lines
    if language == "urscript":  # the comment on a corrected line is kept too
        assert result.texts[label].splitlines()[3].endswith("# then movel(p[0.5, 0.1, 0.4, 0, 3.14, 0])")
    if language == "krl":
        assert result.texts[label].splitlines()[5].endswith("; was {A1 21.0, A2 -80.0}")
        assert [u.line for u in result.unsupported] == [7]  # XHOME: declared elsewhere, listed


def test_commented_frames_in_config_dat_are_not_read():
    """A ``TOOL_DATA[1]`` commented out in ``$config.dat`` is not the tool in force."""
    nominal, real = _moved("kr16")
    src = "DEF c( )\n$TOOL = TOOL_DATA[1]\nLIN {X 900.0, Y 100.0, Z 1200.0, A 0.0, B 90.0, C 0.0}\nEND\n"
    cfg = ";TOOL_DATA[1]={X 0.0,Y 0.0,Z 150.0,A 0.0,B 0.0,C 0.0}\n"
    with pytest.raises(ProgramError, match=r"TOOL_DATA\[1\] is not in"):
        filter_program_text({"c.src": src}, "krl", real, nominal, config_dat=("$config.dat", cfg))


# ---------------------------------------------------------------------- every target accounted for
RAPID_OTHERS = """MODULE M
    CONST robtarget p1:=@RT;
    CONST robtarget path{2}:=[@RT,@RT2];
    VAR robtarget pRun;
    PROC main()
        MoveL p1, v100, fine, tool0;
        MoveL path{1}, v100, fine, tool0;
        MoveL pElsewhere, v100, fine, tool0;
        MoveL Offs(p1,0,0,10), v100, fine, tool0;
        MoveL RelTool(p1,0,0,10), v100, fine, tool0;
        MoveLDO p1, v100, fine, tool0, do1, 1;
        pRun := CRobT();
        MoveL pRun, v100, fine, tool0;
        p1.trans.z := p1.trans.z + 10;
        MoveL p1, v100, fine, tool0;
    ENDPROC
ENDMODULE
""".replace("@RT2", _RT2).replace("@RT", _RT)

URSCRIPT_OTHERS = """def m():
  p1 = p[0.5, 0.1, 0.4, 0, 3.14, 0]
  movel(p1, a=0.5, v=0.1)
  movel(pose_trans(p1, p[0, 0, 0.05, 0, 0, 0]), a=0.5, v=0.1)
  movel(get_forward_kin(), a=0.5, v=0.1)
  p1 = pose_add(p1, p[0, 0, 0.01, 0, 0, 0])
  movel(p1, a=0.5, v=0.1)
end
"""


@pytest.mark.parametrize(
    ("language", "robot", "text", "listed"),
    [
        ("rapid", "irb120", RAPID_OTHERS, {3, 4, 7, 8, 9, 10, 11, 13, 14}),
        ("urscript", "ur10", URSCRIPT_OTHERS, {4, 5, 6}),
    ],
)
def test_every_target_is_corrected_or_listed_with_its_reason(language, robot, text, listed):
    """Arrays, names of other modules or set at run time, offsets, other motion instructions
    and run-time changes of a target are listed (line and reason); the rest is corrected."""
    nominal, real = _moved(robot)
    label = "m.mod" if language == "rapid" else "m.script"
    result = filter_program_text({label: text}, language, real, nominal)
    assert [t.line for t in result.targets] == [2] and result.changed.all()
    assert {u.line for u in result.unsupported} == listed
    assert all(u.reason for u in result.unsupported)
    assert _changed_lines(text, result.texts[label]) == {2}


def test_example_programs_account_for_every_motion_statement():
    """In the shipped examples, each motion statement holds a target read from the program
    or is listed as untouched."""
    motion = {
        "pick.script": re.compile(r"^\s*(movej|movel|movep|movec|servoj|servoc)\("),
        "pick.src": re.compile(r"^\s*(PTP|LIN|CIRC)\w*\b", re.I),
        "pick.mod": re.compile(r"^\s*Move\w*\b"),
    }
    for name, robot in (("pick.script", "ur10"), ("pick.src", "kr16"), ("pick.mod", "irb120")):
        result = filter_program_file(EXAMPLES / name, rc.robot(robot))
        text = (EXAMPLES / name).read_text(encoding="latin-1").splitlines()
        statements = {k + 1 for k, line in enumerate(text) if motion[name].match(line)}
        named = {t.name.upper() for t in result.targets}
        read = {t.line for t in result.targets if Path(t.file).name == name}
        to_names = {
            k
            for k in statements
            if any(re.search(rf"\b{re.escape(n)}\b", text[k - 1], re.I) for n in named if " " not in n)
        }
        untouched = {u.line for u in result.unsupported if Path(u.file).name == name}
        assert statements <= read | to_names | untouched, (name, statements - read - to_names - untouched)


# ---------------------------------------------------------------------- --nominal of another robot
def _model_file(folder: Path, model) -> Path:
    path = folder / f"{model.name}.yaml"
    rc.save_model(model, path)
    return path


@pytest.mark.parametrize("other", ["kr16", "ur5"])
def test_nominal_of_another_robot_is_refused(tmp_path, other):
    """A UR10 calibration with ``--nominal kr16`` (other joints) or ``ur5`` (same joints,
    another geometry): one error line naming the option's robot, exit 2, nothing written;
    the UR10's own nominal is accepted."""
    _, real = _moved("ur10")
    calibration = _model_file(tmp_path, real)
    out = tmp_path / "out.script"
    args = ["filter", str(calibration), str(EXAMPLES / "pick.script"), "-o", str(out)]
    line = _error_line(runner.invoke(app, [*args, "--nominal", other]))
    assert other in line and not out.exists()
    with pytest.raises(ProgramError, match=other):
        filter_program_text({"p.script": URSCRIPT}, "urscript", real, rc.robot(other))
    ok = runner.invoke(app, [*args, "--nominal", "ur10"])
    assert ok.exit_code == 0, ok.output
    assert out.exists()


def test_nominal_checked_against_a_calibration_result():
    """With a calibration result, the reference is its start model: the nominal it started
    from passes, a robot of other geometry does not."""
    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)
    robot = rc.measure.VirtualRobot(nominal, true, rc.measure.LaserTracker(p_tool_target=[0, 0, 0.1]))
    data = rc.measure.simulate(robot, rc.measure.random_poses(nominal, 60, seed=1), seed=1)
    result = rc.calibrate(nominal, data, tool_guess=[0, 0, 0.1])
    text = {"p.script": URSCRIPT}
    filtered = filter_program_text(text, "urscript", result, nominal)
    assert filtered.changed.all()
    with pytest.raises(ProgramError, match="ur5"):
        filter_program_text(text, "urscript", result, rc.robot("ur5"))


# ---------------------------------------------------------------------- KRL pairs
def _pair(folder: Path, *, bom: bool = False, defdat: str = "pick") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    prefix = b"\xef\xbb\xbf" if bom else b""
    src = (EXAMPLES / "pick.src").read_bytes()
    dat = (EXAMPLES / "pick.dat").read_bytes().replace(b"DEFDAT  pick", f"DEFDAT  {defdat}".encode())
    (folder / "pick.src").write_bytes(prefix + src)
    (folder / "pick.dat").write_bytes(prefix + dat)
    return folder / "pick.src"


def test_krl_output_of_another_kind_is_refused(tmp_path):
    """``-o other.dat`` for a ``.src``, and a ``.dat`` given while its ``.src`` is beside it,
    are refused; nothing is written."""
    nominal, real = _moved("kr16")
    program = _pair(tmp_path / "in")
    with pytest.raises(ProgramError, match="-o"):
        filter_program_file(program, real, tmp_path / "other.dat", nominal=nominal)
    with pytest.raises(ProgramError, match=r"pick\.src"):
        filter_program_file(program.with_suffix(".dat"), real, tmp_path / "pick.src", nominal=nominal)
    with pytest.raises(ProgramError, match=r"pick\.src"):
        filter_program_file(program.with_suffix(".dat"), real, tmp_path / "pick.dat", nominal=nominal)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_a_dat_alone_is_filtered_as_a_dat(tmp_path):
    nominal, real = _moved("kr16")
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "data.dat").write_bytes((EXAMPLES / "pick.dat").read_bytes())
    with pytest.raises(ProgramError, match="-o"):
        filter_program_file(folder / "data.dat", real, tmp_path / "data.src", nominal=nominal)
    result = filter_program_file(folder / "data.dat", real, tmp_path / "data.dat", nominal=nominal)
    assert result.changed.any() and not (tmp_path / "data.src").exists()
    assert "DEFDAT" in (tmp_path / "data.dat").read_text(encoding="latin-1")


def test_krl_pair_needs_force_for_both_files(tmp_path):
    """An unrelated ``.dat`` where the pair's ``.dat`` goes is not overwritten without
    ``--force``; with it both files are written as a pair."""
    nominal, real = _moved("kr16")
    calibration = _model_file(tmp_path, real)
    program = _pair(tmp_path / "in")
    out = tmp_path / "out" / "pick.src"
    out.parent.mkdir()
    out.with_suffix(".dat").write_text("DEFDAT pick\n; a user's own data list\nENDDAT\n")
    args = [
        "filter",
        str(calibration),
        str(program),
        "-o",
        str(out),
        "--nominal",
        str(_model_file(tmp_path, nominal)),
    ]
    line = _error_line(runner.invoke(app, args))
    assert "pick.dat" in line and "--force" in line
    assert not out.exists() and "a user's own" in out.with_suffix(".dat").read_text()
    ok = runner.invoke(app, [*args, "--force"])
    assert ok.exit_code == 0, ok.output
    src, dat = (p.read_text(encoding="latin-1") for p in (out, out.with_suffix(".dat")))
    assert krl_run_id(src) == krl_run_id(dat) is not None and "XAPPROACH" in dat


def test_src_without_dat_is_not_written_beside_a_stale_dat(tmp_path):
    """A ``.src`` that has no ``.dat`` is refused where another program's ``.dat`` lies (it
    would be read as the new ``.src``'s data list); ``--force`` writes the ``.src`` only,
    and the next read refuses the mixed pair."""
    nominal, real = _moved("kr16")
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "solo.src").write_text(
        "DEF solo( )\nPTP {A1 20.0, A2 -80.0, A3 100.0, A4 10.0, A5 30.0, A6 10.0}\nEND\n"
    )
    out = tmp_path / "out" / "solo.src"
    out.parent.mkdir()
    stale = "DEFDAT solo\nDECL E6AXIS XHOME={A1 0.0,A2 -90.0,A3 90.0,A4 0.0,A5 45.0,A6 0.0}\nENDDAT\n"
    out.with_suffix(".dat").write_text(stale)
    with pytest.raises(ProgramError, match=r"solo\.dat"):
        filter_program_file(folder / "solo.src", real, out, nominal=nominal, overwrite=False)
    assert not out.exists()
    filter_program_file(folder / "solo.src", real, out, nominal=nominal, overwrite=True)
    assert out.with_suffix(".dat").read_text() == stale
    with pytest.raises(ProgramError, match="not written together"):
        filter_program_file(out, real, tmp_path / "again.src", nominal=nominal)


def test_def_and_defdat_must_name_one_module(tmp_path):
    nominal, real = _moved("kr16")
    program = _pair(tmp_path / "in", defdat="other")
    with pytest.raises(ProgramError, match="DEFDAT other"):
        filter_program_file(program, real, tmp_path / "pick.src", nominal=nominal)
    assert not (tmp_path / "pick.src").exists()


def test_krl_byte_order_mark_stays_first(tmp_path):
    """A UTF-8 BOM stays the first bytes of both files; the run id line comes after the
    ``&`` header lines; everything else but the corrected numbers is kept."""
    nominal, real = _moved("kr16")
    program = _pair(tmp_path / "in", bom=True)
    out = tmp_path / "out" / "pick.src"
    result = filter_program_file(program, real, out, nominal=nominal)
    assert result.changed.any()
    for path in (out, out.with_suffix(".dat")):
        data = path.read_bytes()
        assert data.startswith(b"\xef\xbb\xbf&ACCESS RVP") and data.count(b"\xef\xbb\xbf") == 1
        lines = data[3:].decode().splitlines()
        assert lines[:2] == ["&ACCESS RVP", "&REL 1"] and lines[2].startswith(";robocal run: ")


# ---------------------------------------------------------------------- bounded input
def test_program_above_the_size_cap_is_refused_before_reading(tmp_path, monkeypatch):
    """The size is checked before the file is read: one error line naming the file."""
    monkeypatch.setattr(programs, "MAX_PROGRAM_BYTES", 1000)
    path = tmp_path / "big.script"
    path.write_text("def p():\n" + "  # comment\n" * 200 + "end\n")
    reads = []
    monkeypatch.setattr(Path, "read_bytes", lambda self: reads.append(self) or b"")
    with pytest.raises(ProgramError, match=r"big\.script"):
        filter_program_file(path, rc.robot("ur10"))
    assert reads == []
    line = _error_line(
        runner.invoke(
            app,
            [
                "filter",
                str(_model_file(tmp_path, rc.robot("ur10"))),
                str(path),
                "-o",
                str(tmp_path / "o.script"),
            ],
        )
    )
    assert "big.script" in line and not (tmp_path / "o.script").exists()


def test_long_program_lines_and_splices_are_exact():
    """Many targets on many lines (the linear-time line index and single splice): each
    target's line is its own, and only the target numbers change."""
    nominal, real = _moved("ur10")
    rng = np.random.default_rng(1)
    q = rng.uniform(-2.0, 2.0, (300, 6))
    lines = ["def long():"]
    for k, row in enumerate(q):
        lines.append(f"  # {k}: movej([{', '.join('9' for _ in row)}])")
        lines.append(f"  movej([{', '.join(f'{v:.6f}' for v in row)}], a=1.4, v=1.05)  # {k}")
    text = "\n".join([*lines, "end", ""])
    result = filter_program_text({"l.script": text}, "urscript", real, nominal)
    assert [t.line for t in result.targets] == [3 + 2 * k for k in range(300)]
    out = result.texts["l.script"].splitlines()
    assert out[1::2] == text.splitlines()[1::2]  # the comment lines, byte for byte
    got = np.array([[float(v) for v in re.findall(r"-?\d+\.\d+", ln.split("]")[0])] for ln in out[2:-1:2]])
    ok = result.reachable  # unreachable targets are left as written
    assert ok.sum() > 250
    expected = filter_program(real, q, nominal).q  # the same correction, from the joint values
    np.testing.assert_allclose(got[ok], expected[ok], atol=1e-5)  # corrections are ~1e-3 rad
    np.testing.assert_allclose(got[~ok], q[~ok], atol=6e-7)
    assert np.abs(got - q).max() > 1e-4


def test_unterminated_and_overlong_statements_are_listed_not_rescanned():
    """A RAPID Move without its ';', and URScript motions whose brackets close only at the
    end of the file, are listed (not corrected, not silently skipped); the file's real
    targets are still read."""
    rapid = "MODULE A\n" + "    MoveL p1, v100, fine, tool0\n" * 50 + "ENDMODULE\n"
    result = filter_program_text({"a.mod": rapid}, "rapid", rc.robot("irb120"))
    assert sorted(u.line for u in result.unsupported) == list(range(2, 52))
    nested = "  movej(p[\n" * 600 + "])" * 600
    text = f"def a():\n  movej([0.1, -1.2, 1.3, -1.4, -1.5, 0.6])\n{nested}\nend\n"
    result = filter_program_text({"a.script": text}, "urscript", rc.robot("ur10"))
    assert [t.line for t in result.targets] == [2]
    assert {u.line for u in result.unsupported} >= set(range(3, 3 + 500))
