"""Issue 33: link masses from a URDF's ``<inertial>``, so joint compliance works from real
descriptions.

The bodies ``model_from_urdf`` attaches are checked independently of robocal: the gravity
torques they give (:func:`robocal.model.dynamics.gravity_torques`) equal Pinocchio's
``computeGeneralizedGravity`` on the whole URDF as Pinocchio parses it, at random
configurations, for a hand-written arm with every case (a mass on the base, fixed-joint chains
with turned frames, a turned inertial origin, a prismatic joint, a placeholder mass, a tool
after the tip, a sensor and a sliding finger off the chain) and for vendored public
descriptions.  Bad inertials are refused in one line naming the file and link; the model file
keeps the bodies; ``robocal calibrate --effects compliance`` works on the built model and
recovers a simulated robot's compliance."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from robocal.cli.app import app
from robocal.model.dynamics import gravity_torques
from robocal.model.files import load_model
from robocal.model.urdf.read import URDFError, build_from_urdf, urdf_link_masses

pin = pytest.importorskip("pinocchio")

DATA = Path(__file__).parent / "data"
_INERTIA = 'ixx="0.02" ixy="0.001" ixz="-0.002" iyy="0.03" iyz="0.003" izz="0.01"'


def _inertial(mass: str, xyz: str, rpy: str = "0 0 0") -> str:
    return (
        f'<inertial><origin xyz="{xyz}" rpy="{rpy}"/><mass value="{mass}"/><inertia {_INERTIA}/></inertial>'
    )


def _joint(name: str, kind: str, parent: str, child: str, xyz: str, rpy: str, axis: str = "0 0 1") -> str:
    limit = '<limit lower="-0.1" upper="0.2" effort="1" velocity="1"/>' if kind == "prismatic" else (
        '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
    )  # fmt: skip
    moving = f'<axis xyz="{axis}"/>{limit}' if kind != "fixed" else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}" rpy="{rpy}"/>{moving}</joint>'
    )


#: link -> its <inertial> (None: no inertial); the arm's 5 joints end at "tool" (--tip tool)
LINKS = {
    "world": None,
    "base": _inertial("4.0", "0 0 0.05"),  # before the first joint: no joint load
    "l1": _inertial("3.0", "0.01 0.02 0.1", "0.3 -0.2 0.1"),
    "l2": _inertial("2.5", "0.2 0.01 0.03", "0 0.4 0"),
    "l2b": _inertial("0.8", "0.05 -0.02 0.01"),  # fixed to l2 through a turned frame
    "l3": _inertial("1.5", "0.1 0 0.02", "0.1 0.2 0.3"),
    "l4": _inertial("0.6", "0 0.01 0.05"),  # moved by the prismatic joint
    "flange": _inertial("0.0001", "0 0 0"),  # a placeholder mass (Kinova's): kept
    "tool": _inertial("0.3", "0 0 0.05"),  # after the tip's last joint: loads it
    "camera": _inertial("0.2", "0.01 0 0"),  # off the chain, fixed to l3
    "finger": _inertial("0.05", "0 0.01 0.02"),  # off the chain, behind a sliding joint
    "light": None,  # massless
}
JOINTS = [
    _joint("mount", "fixed", "world", "base", "0.1 -0.2 0.05", "0 0 0.7"),
    _joint("j1", "revolute", "base", "l1", "0 0 0.3", "0 0 0.2"),
    _joint("j2", "revolute", "l1", "l2", "0.05 0 0.1", "1.5707963 0 0"),
    _joint("l2_fixed", "fixed", "l2", "l2b", "0.4 0 0", "0 0 0.3"),
    _joint("j3", "revolute", "l2b", "l3", "0.05 0 0", "0.2 0 0", axis="0 1 0"),
    _joint("j4", "prismatic", "l3", "l4", "0.3 0 0", "0 1.5707963 0"),
    _joint("j5", "revolute", "l4", "flange", "0 0 0.1", "0.4 0 0", axis="1 0 0"),
    _joint("tool_joint", "fixed", "flange", "tool", "0 0 0.12", "0 0 0"),
    _joint("camera_joint", "fixed", "l3", "camera", "0.02 0.05 0", "0 0 0"),
    _joint("light_joint", "fixed", "l3", "light", "0 0 0.1", "0 0 0"),
    _joint("finger_joint", "prismatic", "flange", "finger", "0 0.02 0.05", "0 0 0", axis="0 1 0"),
]


def _arm(tmp_path: Path, name: str = "arm.urdf", **replace: str) -> Path:
    """The hand-written arm; ``replace`` maps a text of it to another (to damage it)."""
    links = "".join(f'<link name="{n}">{i or ""}</link>' for n, i in LINKS.items())
    text = f'<?xml version="1.0"?>\n<robot name="arm_s17">{links}{"".join(JOINTS)}</robot>\n'
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _pinocchio_gravity(path: Path, joint_names: list[str], q: np.ndarray) -> np.ndarray:
    """Pinocchio's generalized gravity (z up, 9.81) of the whole URDF at ``q`` of the named
    joints (every other joint at its neutral value; ``<mimic>`` dropped), ``(n, dof)``."""
    import re

    pm = pin.buildModelFromXML(re.sub(r"<mimic[^>]*/>", "", path.read_text(encoding="utf-8")))
    data = pm.createData()
    ids = [pm.getJointId(n) for n in joint_names]
    out = []
    for row in q:
        qp = pin.neutral(pm)
        for j, v in zip(ids, row, strict=True):
            joint = pm.joints[j]
            qp[joint.idx_q : joint.idx_q + joint.nq] = v if joint.nq == 1 else (np.cos(v), np.sin(v))
        g = pin.computeGeneralizedGravity(pm, data, qp)
        out.append([g[pm.joints[j].idx_v] for j in ids])
    return np.array(out)


def _random_q(model, n: int, seed: int) -> np.ndarray:
    lo = np.array([(j.limits or (-3.0, 3.0))[0] for j in model.joints])
    hi = np.array([(j.limits or (-3.0, 3.0))[1] for j in model.joints])
    return np.random.default_rng(seed).uniform(lo, hi, (n, model.dof))


@pytest.mark.parametrize("measure", ["position", "pose"])
def test_hand_written_arm_gravity_equals_pinocchio(tmp_path, measure):
    path = _arm(tmp_path)
    model = build_from_urdf(path, measure, tip="tool").model
    masses = urdf_link_masses(path, model, tip="tool")
    carried = {"l1", "l2", "l2b", "l3", "l4", "flange", "tool", "camera", "finger"}
    assert {b.name for b in model.bodies} == carried and model.bodies == masses.bodies
    assert masses.on_base == ("base",) and masses.off_chain == ("finger",)
    assert masses.mass_kg == pytest.approx(3.0 + 2.5 + 0.8 + 1.5 + 0.6 + 0.0001 + 0.3 + 0.2 + 0.05)
    q = _random_q(model, 8, seed=1)
    expected = _pinocchio_gravity(path, list(model.joint_names), q)
    assert np.abs(expected).max() > 1.0  # the loads are real
    np.testing.assert_allclose(gravity_torques(model, q), expected, atol=1e-9)
    # the same model with one link's mass left out is seen (the comparison can fail)
    fewer = dataclasses.replace(model, bodies=tuple(b for b in model.bodies if b.name != "l3"))
    assert np.abs(gravity_torques(fewer, q) - expected).max() > 1e-3


@pytest.mark.parametrize(
    ("name", "tip"),
    [("urdf/ur5e.urdf", None), ("urdf/iiwa14.urdf", None), ("urdf/gen3_lite.urdf", "tool_frame"),
     ("urdf/xarm6.urdf", "link_tcp"), ("arm7.urdf", None)],
)  # fmt: skip
def test_public_descriptions_gravity_equals_pinocchio(name, tip):
    path = DATA / name
    model = build_from_urdf(path, "position", tip).model
    assert len(model.bodies) >= model.dof
    q = _random_q(model, 6, seed=2)
    expected = _pinocchio_gravity(path, list(model.joint_names), q)
    np.testing.assert_allclose(
        gravity_torques(model, q), expected, atol=1e-9 * max(1.0, np.abs(expected).max())
    )


def test_model_file_keeps_the_bodies_and_the_cli_says_how_many(tmp_path):
    path = _arm(tmp_path)
    out = tmp_path / "m.yaml"
    run = CliRunner().invoke(app, ["model", "build", str(path), "-o", str(out), "--tip", "tool"])
    assert run.exit_code == 0, run.output
    said = [line for line in run.output.splitlines() if line.startswith("link masses")]
    assert len(said) == 1 and " 9 " in said[0]  # the nine carried links (base left out)
    saved = load_model(out)
    built = build_from_urdf(path, "pose", tip="tool").model
    assert [(b.name, b.frame) for b in saved.bodies] == [(b.name, b.frame) for b in built.bodies]
    for s, b in zip(saved.bodies, built.bodies, strict=True):
        assert s.mass == b.mass and np.allclose(s.com, b.com, atol=1e-15)
        assert s.inertia is not None and np.allclose(s.inertia, b.inertia, atol=1e-15)
    q = _random_q(saved, 4, seed=3)
    np.testing.assert_allclose(
        gravity_torques(saved, q), _pinocchio_gravity(path, list(saved.joint_names), q), atol=1e-9
    )
    bare = CliRunner().invoke(
        app, ["model", "build", str(DATA / "ur10.urdf"), "-o", str(tmp_path / "b.yaml")]
    )
    assert bare.exit_code == 0 and "none read" in bare.output
    assert not load_model(tmp_path / "b.yaml").bodies


BAD = {
    "negative": ('<mass value="3.0"/>', '<mass value="-3.0"/>'),
    "nan": ('<mass value="3.0"/>', '<mass value="nan"/>'),
    "xyz": ('xyz="0.01 0.02 0.1"', 'xyz="0.01 0.02"'),
    "no mass": ('<mass value="3.0"/>', ""),
    "inertia": ('<mass value="3.0"/><inertia ixx="0.02"', '<mass value="3.0"/><inertia ixx="big"'),
}


@pytest.mark.parametrize("damage", sorted(BAD))
def test_bad_inertials_are_refused_in_one_line_naming_file_and_link(tmp_path, damage):
    path = _arm(tmp_path, "bad.urdf", **dict([BAD[damage]]))
    with pytest.raises(URDFError) as err:
        build_from_urdf(path, "position", tip="tool")
    message = str(err.value)
    assert "\n" not in message and str(path) in message and "'l1'" in message
    out = tmp_path / "m.yaml"
    run = CliRunner().invoke(app, ["model", "build", str(path), "-o", str(out), "--tip", "tool"])
    assert run.exit_code == 2 and run.output.startswith("error:") and run.output.count("error:") == 1
    assert "Traceback" not in run.output and "'l1'" in " ".join(run.output.split())
    assert not out.exists()


def test_what_loads_no_joint_may_be_unreadable(tmp_path):
    """A mass on the base, or a joint off the chain with unexpanded xacro and nothing heavy
    behind it, loads no joint: it does not stop the build; a mass behind such a joint does."""
    base = _arm(tmp_path, "base.urdf", **{'<mass value="4.0"/>': '<mass value="${m}"/>'})
    assert build_from_urdf(base, "position", tip="tool").model.bodies
    light = _arm(
        tmp_path, "light.urdf", **{'xyz="0 0 0.1" rpy="0 0 0"/></joint>': 'xyz="${x} 0 0.1"/></joint>'}
    )
    assert len(build_from_urdf(light, "position", tip="tool").model.bodies) == 9
    camera = _arm(tmp_path, "camera.urdf", **{'xyz="0.02 0.05 0"': 'xyz="${x} 0.05 0"'})
    with pytest.raises(URDFError, match=r"camera.*camera_joint"):
        build_from_urdf(camera, "position", tip="tool")


# --------------------------------------------------------- compliance through the CLI
TRUE = {"shoulder_lift_joint": 4e-5, "elbow_joint": 6e-5}  # rad/(N·m)


def _run(*args) -> object:
    return CliRunner().invoke(app, [str(a) for a in args])


def test_compliance_on_a_model_built_from_a_urdf(tmp_path):
    """The UR5e built from its description carries its masses: a robot that yields by the
    stated compliances under them is simulated, and ``calibrate --effects compliance`` of the
    built model recovers them within 4σ (it was refused: no link masses)."""
    built = tmp_path / "ur5e.yaml"
    assert (
        _run("model", "build", DATA / "urdf" / "ur5e.urdf", "-o", built, "--measure", "position").exit_code
        == 0
    )
    true = tmp_path / "ur5e_elastic.yaml"
    block = "joint_effects:\n" + "".join(
        f"  - {{joint: {j}, compliance: {c:.1e}}}\n" for j, c in TRUE.items()
    )
    true.write_text(built.read_text(encoding="utf-8").rstrip("\n") + "\n" + block, encoding="utf-8")
    data = tmp_path / "s.csv"
    made = _run(
        "simulate", true, "--kind", "point", "--n", "60", "--seed", "4", "--placements", "2", "-o", data
    )
    assert made.exit_code == 0, made.output
    fit = _run("calibrate", built, "--data", data, "--effects", "compliance", "--out", tmp_path / "cal")
    assert fit.exit_code == 0, fit.output
    doc = json.loads((tmp_path / "cal" / "constraints.json").read_text(encoding="utf-8"))
    fitted = {e["name"].removeprefix("compliance_"): e for e in doc["joint_effects"]}
    assert set(TRUE) <= set(fitted)
    for joint, e in fitted.items():
        assert abs(e["estimate_rad_per_Nm"] - TRUE.get(joint, 0.0)) < 4 * e["std_rad_per_Nm"], joint
    assert fitted["elbow_joint"]["std_rad_per_Nm"] < TRUE["elbow_joint"] / 4  # seen, not just allowed
    # without the URDF's masses the same calibration is refused, naming the model
    bare = tmp_path / "bare.yaml"
    bare.write_text(built.read_text(encoding="utf-8").split("\nbodies:")[0] + "\n", encoding="utf-8")
    assert not load_model(bare).bodies
    refused = _run("calibrate", bare, "--data", data, "--effects", "compliance", "--out", tmp_path / "no")
    assert refused.exit_code != 0 and "mass" in refused.output and "Traceback" not in refused.output
