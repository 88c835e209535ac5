import json

import numpy as np
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.model.files import save_model

runner = CliRunner()


def test_robots_lists_the_catalog():
    result = runner.invoke(app, ["robots"])
    assert result.exit_code == 0, result.output
    for name in rc.robots():
        assert name in result.output


def test_robots_show_prints_mm_and_degrees():
    result = runner.invoke(app, ["robots", "show", "ur10"])
    assert result.exit_code == 0, result.output
    assert "163.941" in result.output and "-572.3" in result.output and "-90" in result.output
    assert "mass properties" in result.output


def test_fk_json_matches_the_model():
    result = runner.invoke(app, ["fk", "ur10", "--q", "10, -80, 70, 5, 90, -30", "--deg", "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    T = rc.robot("ur10").fk(np.radians([10, -80, 70, 5, 90, -30]))
    np.testing.assert_allclose(out["T"], T, atol=1e-15)
    assert out["outside_limits"] == []


def test_fk_table_and_model_file(tmp_path):
    path = save_model(rc.robot("katana450"), tmp_path / "k.yaml")
    result = runner.invoke(app, ["fk", str(path), "--q", "0 0 0 0 0"])
    assert result.exit_code == 0, result.output
    assert "x 384.0000" in result.output and "y -145.0000" in result.output


def test_fk_errors_are_one_line_messages():
    result = runner.invoke(app, ["fk", "ur10", "--q", "0, 1"])
    assert result.exit_code == 2
    assert "--q" in result.output and "expected 6 numbers, got 2" in result.output
    result = runner.invoke(app, ["fk", "ur11", "--q", "0"])
    assert result.exit_code == 2 and "unknown robot 'ur11'" in result.output
    result = runner.invoke(app, ["fk", "ur10", "--q", "a,b"])
    assert result.exit_code == 2 and "must be numbers" in result.output
    result = runner.invoke(app, ["fk", "missing.yaml", "--q", "0"])
    assert result.exit_code == 2 and "does not exist" in result.output
    assert "Traceback" not in result.output


def test_fk_warns_outside_limits():
    result = runner.invoke(app, ["fk", "katana450", "--q", "0, 150, 0, 0, 0", "--deg"])
    assert result.exit_code == 0
    assert "outside joint limits: q2" in result.output
