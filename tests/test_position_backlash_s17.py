"""Issue 33, session 17: backlash (and clearance) are not fitted on position rows, and asking
for them there is refused by name rather than quietly left out.

The study behind it (MUKCa's Kinova Gen3 lite and Panda recordings, docs/tutorials/
no-tracker.md): backlash on the ball-in-socket rows did not earn its place, so a point,
plane or distance file calibrated with ``--effects backlash`` used to exit 0 with a robot
that carried no backlash and no word about it.  Now: one ``error:`` line naming the option
and the kind, a non-zero exit and no folder; the kinds a position row does carry (compliance,
radial) and the tilt rows' own (test_tilt_mount.py) are unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.identify.constraints.fit import calibrate_constraints
from robocal.identify.constraints.position_effects import (
    POSITION_EFFECT_KINDS,
    SIGN_KINDS,
    check_sign_kinds,
)
from robocal.measure.constraints.data import read_constraints


def _run(args: list) -> object:
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def points(tmp_path_factory):
    """A UR10 (catalog masses) ball-in-socket file: position rows only."""
    path = tmp_path_factory.mktemp("sockets") / "points.csv"
    made = _run(["simulate", "ur10", "--kind", "point", "--n", "20", "--seed", "2", "-o", path])
    assert made.exit_code == 0, made.output
    return path


def test_sign_kinds_are_tilt_rows_only():
    assert not set(SIGN_KINDS) & set(POSITION_EFFECT_KINDS)
    for kinds in (("backlash",), ("compliance", "clearance"), ("clearance", "backlash", "compliance")):
        with pytest.raises(ValueError) as err:
            check_sign_kinds(kinds, tilt_rows=False)
        named = [k for k in SIGN_KINDS if k in kinds]
        assert all(k in str(err.value) for k in named) and "\n" not in str(err.value)
        check_sign_kinds(kinds, tilt_rows=True)  # tilt rows identify them: no refusal
    check_sign_kinds(("compliance", "radial"), tilt_rows=False)


@pytest.mark.parametrize(
    "effects", ["backlash", "compliance,backlash", "clearance", "clearance,backlash,compliance"]
)
def test_backlash_on_a_socket_file_is_refused_by_name(points, tmp_path, effects):
    out = tmp_path / "cal"
    refused = _run(["calibrate", "ur10", "--data", points, "--effects", effects, "--out", out])
    assert refused.exit_code != 0 and not out.exists()
    line = refused.output.strip()
    assert line.startswith("error:") and "\n" not in line and "Traceback" not in line
    assert "--effects" in line and all(k in line for k in SIGN_KINDS if k in effects.split(","))


def test_the_kinds_a_position_row_carries_still_run(points, tmp_path):
    """compliance (and identify, which asks for what each row can see) are not refused."""
    for effects in ("compliance", "identify"):
        out = tmp_path / effects
        ran = _run(["calibrate", "ur10", "--data", points, "--effects", effects, "--out", out])
        assert ran.exit_code == 0, ran.output
        assert (out / "model.yaml").exists() and "backlash_" not in (out / "constraints.json").read_text()


def test_the_api_refuses_backlash_on_position_rows(points):
    robot = rc.calibration_model("ur10")
    data = read_constraints(points, robot.dof)
    with pytest.raises(ValueError, match="backlash"):
        calibrate_constraints(robot, data, effects=("backlash",))
    assert np.isfinite(calibrate_constraints(robot, data, effects=("compliance",)).estimates).all()
