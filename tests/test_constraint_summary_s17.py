"""The constraint fit's "residual before -> after" is the measurements' own figure.

A stated distance between fixed points is held to 1 µm; its row, weighted and scaled back by
the points' σ, used to enter the figure: a Gen3 lite whose configurations spread by ~5 mm
around their socket printed "178 mm -> 1.0 mm".  The figure is now the RMS of the position
rows (m) alone, so before the fit it is the nominal model's spread per axis."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from robocal.identify.constraints.figures import pooled_spread
from robocal.identify.constraints.fit import calibrate_constraints, constraint_figures
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.urdf.read import model_from_urdf

MUKCA = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "mukca"


def _placement(folder: Path, distance_m: float) -> ConstraintSet:
    holes = [np.loadtxt(folder / f"hole_{h}.csv", delimiter=",") for h in (0, 1)]
    label = np.repeat([0, 1], [len(holes[0]), len(holes[1])])
    return ConstraintSet(np.vstack(holes), label, -np.ones(len(label), dtype=int),
                         point_pairs=[[0, 1]], point_length=[distance_m], sigma=1e-4)  # fmt: skip


@pytest.mark.parametrize("distance_m", [0.05, 0.06])  # 0.06: a stated distance 10 mm off
def test_residual_before_is_the_spread_not_the_weighted_distance(distance_m):
    model = model_from_urdf(MUKCA / "urdf" / "gen3lite.urdf", measure="position", tip="ball_link")
    data = _placement(MUKCA / "dinova_2" / "front", distance_m)
    result = calibrate_constraints(model, data)
    f = constraint_figures(model, data)  # the nominal model: each socket's RMS spread (3-D)
    per_axis = pooled_spread(f, data) / math.sqrt(3)
    # the fit starts each socket at the nominal model's centroid: the same figure per axis
    assert result.rms_before == pytest.approx(per_axis, rel=0.02)
    assert result.rms_after < result.rms_before
    assert "residual: " + f"{result.rms_before * 1e3:.3f} mm" in "\n".join(result.summary_lines())


def test_a_fit_without_any_length_says_the_scale_is_not_calibrated(tmp_path):
    """Fixed points alone cannot see the arm's size (scaled as a whole it fits them as well):
    the summary says so, and says nothing of it once a distance is stated."""
    from typer.testing import CliRunner

    from robocal.cli.app import app

    def run(*args):
        done = CliRunner().invoke(app, [str(a) for a in args])
        assert done.exit_code == 0, done.output
        return done.output

    data = tmp_path / "s.csv"
    run("simulate", "ur10", "--kind", "point", "--n", "40", "--count", "2", "--seed", "3", "-o", data)
    bare = run("calibrate", "ur10", "--data", data, "-o", tmp_path / "a")
    centres = np.array(json.loads((tmp_path / "s.csv.truth.json").read_text())["points_m"])
    stated = ["--distance", f"0,1={np.linalg.norm(centres[0] - centres[1]) * 1e3:.4f}mm"]
    with_length = run("calibrate", "ur10", "--data", data, *stated, "-o", tmp_path / "b")
    assert "scale is not calibrated" in " ".join(bare.split())
    assert "scale is not calibrated" not in " ".join(with_length.split())


def test_without_a_length_the_scale_rests_on_the_longest_link_not_the_tool(tmp_path):
    """Sockets alone: the length held for the scale is the longest link (a2), not the ball's
    offset on the flange, whose nominal error rescaled the whole arm (3.9 mm RMS on held-out
    tracker rows of the same true robot, worse than the nominal robot's 1.05 mm)."""
    from typer.testing import CliRunner

    from robocal.cli.app import app

    def run(*args):
        done = CliRunner().invoke(app, [str(a) for a in args])
        assert done.exit_code == 0, done.output
        return done.stdout

    common = ("--kind", "point", "--n", 40, "--count", 2, "--seed", 3, "--also-tracker", 30)
    run("simulate", "ur10", *common, "-o", tmp_path / "sock.csv")
    run("simulate", "ur10", *common, "--placements", 2, "-o", tmp_path / "held.csv")  # same truth
    summary = run("calibrate", "ur10", "--data", tmp_path / "sock.csv", "-o", tmp_path / "cal")
    saved = json.loads((tmp_path / "cal" / "constraints.json").read_text())
    unseen = {d["name"] for d in saved["not_identifiable"]}
    assert "a2" in unseen and "tool_z" not in unseen
    assert "rests on the nominal a2" in " ".join(summary.split())
    tracker = tmp_path / "held.tracker.csv"
    doc = json.loads(run("validate", tmp_path / "cal", "--data", tracker, "--refit-frame", "--json"))
    assert doc["rms_mm"] < 0.75 * doc["nominal"]["rms_mm"]  # better than the nominal robot (was 3.7x worse)


def test_compensating_with_a_calibration_that_measured_no_length_says_so(tmp_path):
    """The commands of such a calibration carry a nominal scale: robocal compensate says so."""
    from typer.testing import CliRunner

    from robocal.cli.app import app

    def run(*args):
        done = CliRunner().invoke(app, [str(a) for a in args])
        assert done.exit_code == 0, done.output
        return " ".join(done.stderr.split())

    data = tmp_path / "s.csv"
    run("simulate", "ur10", "--kind", "point", "--n", 40, "--count", 2, "--seed", 3, "-o", data)
    targets = tmp_path / "t.csv"
    targets.write_text("name,x,y,z\nA,0.5,0.3,0.6\n")
    centres = np.array(json.loads((tmp_path / "s.csv.truth.json").read_text())["points_m"])
    stated = f"0,1={np.linalg.norm(centres[0] - centres[1]) * 1e3:.4f}mm"
    said = {}
    for name, extra in (("bare", ()), ("stated", ("--distance", stated))):
        run("calibrate", "ur10", "--data", data, *extra, "-o", tmp_path / name)
        said[name] = "measured a length" in run("compensate", tmp_path / name, "--targets", targets,
                                                "-o", tmp_path / f"{name}.csv")  # fmt: skip
    assert said == {"bare": True, "stated": False}
