"""The HTML report: self-contained, every section, from a result or a directory; it
renders in headless Chromium without console errors (where Chromium is installed)."""

import re
import subprocess

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.evaluate.report import before_validation, build_report, start_chain, write_report
from robocal.measure import random_poses, simulate
from tests.browser import chromium

runner = CliRunner()
SECTIONS = (
    "summary",
    "model",
    "data",
    "identifiability",
    "parameters",
    "residuals",
    "validation",
    "joint-effects",
    "provenance",
)


@pytest.fixture(scope="module")
def calibration(compliant_ur10):
    model, robot, train, result = compliant_ur10
    test = simulate(robot, random_poses(model, 60, seed=2), seed=2)
    return result, train, test


def _external_references(page: str) -> list[str]:
    """src/href attributes of tags that point off the page."""
    return re.findall(r"<(?:script|link|img|iframe)[^>]*(?:src|href)=[\"']?(?:https?:)?//[^\"' >]+", page)


def test_start_chain_reproduces_rms_before(calibration):
    result, train, _ = calibration
    stats = before_validation(result, train)
    assert stats.rms == pytest.approx(result.rms_before, rel=1e-9)
    assert start_chain(result).fk(train.q).shape == (train.n, 4, 4)


def test_report_has_every_section_and_no_external_resource(calibration, tmp_path):
    result, train, test = calibration
    path = write_report(result, tmp_path / "r.html", data=train, test_data=test, title="UR10 check")
    page = path.read_text(encoding="utf-8")
    for ident in SECTIONS:
        assert f"<section id='{ident}'>" in page, ident
    assert "<h1>UR10 check</h1>" in page
    assert not _external_references(page)
    assert page.count("<script src") == 0 and "<link" not in page
    assert len(re.findall(r"plotly\.js v\d", page)) == 1  # plotly.js embedded once
    figures = set(re.findall(r"data-figure='([a-z-]+)'", page))
    assert {
        "model",
        "coverage",
        "joint-coverage",
        "singular-values",
        "parameters",
        "residual-histogram",
        "residual-per-pose",
        "error-vectors",
        "validation-histogram",
        "joint-effects",
    } <= figures
    assert "The seeds' table" in page and "improvement" in page
    for d in result.dropped:
        assert d.name in page  # every dropped parameter is explained


def test_report_from_a_directory_and_the_command(calibration, tmp_path):
    result, train, test = calibration
    result.save(tmp_path)
    rc.write_measurements(train, tmp_path / "train.csv")
    rc.write_measurements(test, tmp_path / "test.csv")
    page = write_report(tmp_path, tmp_path / "a.html").read_text(encoding="utf-8")
    assert "<section id='validation'>" in page and f"{test.n} held-out poses" in page
    out = tmp_path / "b.html"
    res = runner.invoke(app, ["report", str(tmp_path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert out.is_file() and "wrote" in res.output
    res = runner.invoke(app, ["report", str(tmp_path), "-o", str(out)])
    assert res.exit_code == 2 and "--force" in res.output  # an existing report is kept
    res = runner.invoke(app, ["report", str(tmp_path / "nothing"), "-o", str(out), "--force"])
    assert res.exit_code == 2 and "holds no calibration result" in res.output


def test_report_of_a_bare_result_says_what_is_missing(calibration):
    result, _, _ = calibration
    page = build_report(result)
    assert "No measurements were given" in page and "No held-out measurements" in page
    assert "<section id='parameters'>" in page


def test_report_rejects_data_of_another_robot(calibration):
    result, train, _ = calibration
    wrong = rc.Measurements(q=train.q[:, :5], position=train.position)
    with pytest.raises(ValueError, match="5 joint columns"):
        build_report(result, data=wrong)


def test_report_renders_in_headless_chromium_without_console_errors(calibration, tmp_path):
    """Runs where Chromium is installed (apt install chromium); CI machines skip it."""
    result, train, test = calibration
    path = write_report(result, tmp_path / "r.html", data=train, test_data=test)
    flags = chromium(
        tmp_path / "profile",
        "--host-resolver-rules=MAP * ~NOTFOUND",  # any request off the page would fail and be logged
        "--enable-logging=stderr",
        "--v=0",
        "--window-size=1300,2000",
    )
    run = subprocess.run([*flags, "--dump-dom", path.as_uri()], capture_output=True, text=True, timeout=180)
    console = [line for line in run.stderr.splitlines() if ":CONSOLE" in line]
    errors = [line for line in console if re.search(r"Uncaught|Error|Failed|net::ERR|Refused", line)]
    assert not errors, errors
    page = path.read_text(encoding="utf-8")
    for name in set(re.findall(r"data-figure='([a-z-]+)'", page)):
        assert re.search(rf'id="fig-{name}"[^>]*class="[^"]*js-plotly-plot', run.stdout), name  # drawn
    assert run.stdout.count('class="main-svg"') >= 10


def test_report_lists_other_joint_effects_when_the_result_has_them(calibration):
    import dataclasses

    result = dataclasses.replace(calibration[0])
    estimates = {"elbow": {"backlash": (2.5e-4, 3e-5), "tilt_alpha": (1e-4, None)}}
    object.__setattr__(result, "effect_estimates", lambda: estimates)  # frozen: a stand-in on a copy
    page = build_report(result)
    assert "<section id='joint-effects'>" in page
    assert "backlash" in page and "0.00025" in page and "tilt_alpha" in page


def test_report_shows_the_iso9283_characteristics_of_a_log(calibration, tmp_path):
    from robocal.evaluate.iso9283.log import Iso9283Log, write_iso9283_log

    result = calibration[0]
    c = np.array([0.5, 0.0, 0.4])
    off = np.array([[1e-4, 0, 0], [1e-4, 2e-5, 0], [1e-4, 0, 2e-5]])
    log = Iso9283Log(
        source="<made>",
        conditions={"operator": "<b>x</b>"},
        time=np.arange(3.0),
        test=np.full(3, "pose"),
        cycle=np.arange(1, 4),
        target=np.full(3, "P1"),
        group=np.full(3, ""),
        position=c + off,
        commanded=np.tile(c, (3, 1)),
    )
    path = write_iso9283_log(log, tmp_path / "iso<1>.csv")
    result.save(tmp_path / "cal")
    out = tmp_path / "report.html"
    done = runner.invoke(app, ["report", str(tmp_path / "cal"), "-o", str(out), "--iso9283", str(path)])
    assert done.exit_code == 0, done.output
    page = out.read_text()
    assert "<section id='iso9283'>" in page and "iso&lt;1&gt;.csv" in page
    assert "pose accuracy and repeatability (AP, RP)" in page and "not measured" in page
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,test\n", encoding="utf-8")
    refused = runner.invoke(
        app, ["report", str(tmp_path / "cal"), "-o", str(tmp_path / "r2.html"), "--iso9283", str(bad)]
    )
    assert refused.exit_code == 2 and "missing column" in refused.output
    assert not (tmp_path / "r2.html").exists()
