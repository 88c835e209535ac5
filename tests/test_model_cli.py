import subprocess
from pathlib import Path

from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from tests.browser import chromium

runner = CliRunner()
GEOMETRY = Path(__file__).resolve().parents[1] / "examples" / "geometry"


def test_model_build_writes_a_model_and_reports_the_count(tmp_path):
    out = tmp_path / "scara.yaml"
    result = runner.invoke(app, ["model", "build", str(GEOMETRY / "scara_rrpr.yaml"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "20 identified parameters" in result.output and "Hayati" in result.output
    model = rc.load_model(out)
    assert len(model.free_names) == 20
    result = runner.invoke(
        app, ["model", "build", str(GEOMETRY / "scara_rrpr.yaml"), "--measure", "position", "-o", str(out)]
    )
    assert result.exit_code == 2 and "already exists; use --force" in result.output
    assert len(rc.load_model(out).free_names) == 20  # the first model is untouched
    args = ["model", "build", str(GEOMETRY / "scara_rrpr.yaml"), "--measure", "position", "-o", str(out)]
    result = runner.invoke(app, [*args, "--force"])
    assert "17 identified parameters" in result.output


def test_model_build_from_urdf(tmp_path):
    out = tmp_path / "ur10.yaml"
    result = runner.invoke(
        app, ["model", "build", str(Path(__file__).parent / "data" / "ur10.urdf"), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert rc.load_model(out).dof == 6


def test_model_check_flags_plain_dh_and_passes_the_built_model(tmp_path):
    result = runner.invoke(app, ["model", "check", "irb2400"])
    assert result.exit_code == 1
    assert "singular" in result.output and "cannot describe every nearby axis line" in result.output
    out = tmp_path / "irb2400.yaml"
    runner.invoke(app, ["model", "build", str(GEOMETRY / "irb2400.yaml"), "-o", str(out)])
    result = runner.invoke(app, ["model", "check", str(out)])
    assert result.exit_code == 0, result.output
    assert "complete, minimal and continuous" in result.output


def test_model_show_writes_a_self_contained_page(tmp_path):
    out = tmp_path / "view.html"
    result = runner.invoke(app, ["model", "show", "katana450", "-o", str(out)])
    assert result.exit_code == 0, result.output
    page = out.read_text()
    assert "plotly" in page.lower() and "theta2" in page
    assert '<script src="http' not in page  # plotly.js is embedded, nothing fetched


def test_model_errors_are_one_line(tmp_path):
    result = runner.invoke(
        app, ["model", "build", str(tmp_path / "none.yaml"), "-o", str(tmp_path / "o.yaml")]
    )
    assert result.exit_code == 2 and "does not exist" in result.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: b\njoints:\n  - {type: revolute, position: [0, 0, 0], axis: [0, 0, 0]}\n")
    result = runner.invoke(app, ["model", "build", str(bad), "-o", str(tmp_path / "o.yaml")])
    assert result.exit_code == 2 and "joint 1: axis" in result.output


def test_model_view_renders_in_headless_chromium(tmp_path):
    """Runs where Chromium is installed (apt install chromium); CI machines skip it."""
    command = chromium(tmp_path / "profile", "--dump-dom")
    out = tmp_path / "view.html"
    runner.invoke(app, ["model", "show", "irb2400", "-o", str(out)])
    dom = subprocess.run([*command, out.as_uri()], capture_output=True, text=True, timeout=120)
    assert "main-svg" in dom.stdout  # plotly drew the figure
    assert "gl-container" in dom.stdout or "scene" in dom.stdout  # the 3D scene exists
