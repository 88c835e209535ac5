"""The report's data object and its renderers: computed once into frozen sections, absent
data said in one sentence, stiffness in one unit, everything from data escaped, the style
sheet shipped as package data (also in an installed wheel), and the figure fixes (no
"converged: converged:", decade log ticks, the singular-value title above the plot,
3D labels inside their scene)."""

import dataclasses
import html
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal.evaluate.report import (
    ReportData,
    ReportOptions,
    build_report,
    collect_report,
    render_report,
    report_css,
    report_data_from_result,
)
from robocal.evaluate.report import figures as fg
from robocal.identify.result import CalibrationWarning
from robocal.measure import random_poses, simulate

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def twin(compliant_ur10):
    model, robot, train, result = compliant_ur10
    test = simulate(robot, random_poses(model, 30, seed=2), seed=2)
    geometric = rc.calibrate(model, train, tool_guess=[0, 0, 0.1])
    return result, geometric, train, test


def _visible(page: str) -> str:
    """The page's text as a reader sees it (no scripts, styles or tags; entities decoded)."""
    page = re.sub(r"<script.*?</script>", "", page, flags=re.S)
    page = re.sub(r"<style.*?</style>", "", page, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", " ", page))


def _section(page: str, ident: str) -> str:
    start = page.index(f"<section id='{ident}'>")
    return page[start : page.index("</section>", start)]


def test_the_report_is_computed_once_into_frozen_typed_sections(twin):
    result, _, train, test = twin
    options = ReportOptions(title="UR10 <check>", written="2026-01-02T03:04:05")
    report = collect_report(result, data=train, test_data=test, options=options)
    assert isinstance(report, ReportData)
    with pytest.raises(dataclasses.FrozenInstanceError):
        report.title = "another"  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        report.validation.after = None  # type: ignore[misc, union-attr]
    assert report.residuals.after.n == train.n and report.validation.after.n == test.n
    assert report.residuals.after.rms == pytest.approx(result.rms_after, rel=1e-9)
    assert report.residuals.before.rms == pytest.approx(result.rms_before, rel=1e-9)
    assert [s.n for s in report.coverage.sets] == [train.n, test.n]
    assert len(report.identifiability.singular_values) == len(result.measurement_chain.free_names)
    assert {p.name for p in report.parameters} == {n for n in result.names if not n.startswith("compliance_")}
    assert {c.joint for c in report.effects.compliance} == {"shoulder_lift", "elbow"}
    assert report.validation.improvement.percent > 90
    page = render_report(report)
    assert render_report(report) == page  # rendering only formats: the same data, the same page
    assert "<h1>UR10 &lt;check&gt;</h1>" in page and "2026-01-02T03:04:05" in page


def test_the_result_is_read_in_one_place(twin):
    result = twin[1]
    changed = result.replace(warnings=(CalibrationWarning("data", "w <1>"),), run_id="not a run id")
    facts = report_data_from_result(changed.with_records(data_file="/d/<x>.csv", train_n=40))
    assert facts.warnings == ("w <1>",) and ("data file", "/d/<x>.csv") in facts.inputs
    assert ("train n", "40") in facts.inputs and facts.run_id is None
    assert facts.rms_after_m == result.rms_after and facts.T_device_base.shape == (4, 4)
    assert facts.cv is None and facts.stored_validation is None and facts.compliance == {}


def test_a_section_without_data_says_so_in_one_sentence(twin):
    """No measurements: no empty tables, no NaN or None, one sentence where data is missing;
    a geometric calibration has no joint-effects section at all."""
    result, geometric, _, test = twin
    report = collect_report(geometric)
    assert report.coverage is None and report.residuals is None and report.validation is None
    assert report.effects is None and report.iso is None and report.model_choice is None
    assert report.identifiability.indices == () and report.identifiability.singular_values is None
    page = render_report(report)
    text = _visible(page)
    for sentence in (
        "No measurements were given to the report.",
        "Observability indices and singular values need the calibration measurements.",
        "No held-out measurements were given.",
        "Pass the calibration data for plots.",
    ):
        assert sentence in text
    assert not re.search(r"\b(nan|NaN|None|inf)\b", text)
    markup = re.sub(r"<script.*?</script>", "", page, flags=re.S)  # plotly.js holds such strings
    assert "<tbody></tbody>" not in markup and "<div></div>" not in markup
    assert "<section id='joint-effects'>" not in page and "<section id='iso9283'>" not in page
    # held-out statistics stored in the result, without the held-out data
    stored = geometric.with_validation(rc.validate(geometric, test).to_dict())
    page = build_report(stored)
    assert "after calibration (stored)" in _section(page, "validation")
    assert f"{test.n} held-out poses (stored)" in _section(page, "summary")
    # an ISO 9283 evaluation that could not be measured says why
    page = build_report(result, evaluation={"iso_error": "no cube <fits>"})
    assert "Not measured: no cube &lt;fits&gt;" in _section(page, "iso9283")


def test_an_evaluation_of_the_wrong_shape_is_one_clear_error(twin):
    with pytest.raises(ValueError, match=r"evaluation: 'paths' is not of the expected shape"):
        build_report(twin[1], evaluation={"paths": [{"name": "line"}]})
    with pytest.raises(ValueError, match=r"evaluation: 'iso_poses'"):
        build_report(twin[1], evaluation={"iso_poses": {"cases": {"nominal": [[0, 0, 0]]}}})


def test_stiffness_is_shown_in_one_unit_in_the_report_and_the_cli_summary(twin):
    """Compliance in µrad/(N·m), stiffness in kN·m/rad; the same number in both places."""
    result, _, train, _ = twin
    page = build_report(result, data=train)
    effects = _visible(_section(page, "joint-effects"))
    summary = result.summary()
    c = result.compliance["elbow"]
    for text in (effects, summary):
        assert "kN·m/rad" in text and "µrad/(N·m)" in text, text
        assert not re.search(r"kgf|µrad/N·m|N·m/deg|N\*m", text), text
        assert f"{1.0 / c / 1e3:.4g}" in text  # the elbow's stiffness in kN·m/rad
    assert f"{c * 1e6:.3f}" in effects


def test_everything_from_data_is_escaped(twin):
    result, _, train, test = twin
    bad = "<script>alert(1)</script>"
    model = dataclasses.replace(result.model, name=f"m{bad}", title=f"t{bad}")
    hostile = result.replace(
        model=model, message=f"done{bad}", warnings=(CalibrationWarning("data", f"w{bad}"),)
    ).with_records(data_file=f"f{bad}", source=f"s{bad}")
    c = np.array([[0.5, 0.0, 0.4], [0.6, 0.0, 0.4]])
    evaluation = {
        "paths": [{"name": f"p{bad}", "commanded": c, "cases": {f"case{bad}": np.stack([c, c + 1e-5])}}],
        "compensation": {"method": f"meth{bad}", f"key{bad}": f"v{bad}"},
        "comparison": [{"model": f"cmp{bad}", **rc.validate(result, test).to_dict()}],
        "timings_s": {f"step{bad}": 1.0},
        "iso9283": {
            "source": f"log{bad}",
            "characteristics": [
                {
                    "number": 1,
                    "name": f"n{bad}",
                    "symbols": "S",
                    "clause": "7",
                    "summary": f"r{bad}",
                    "cycles": 3,
                }
            ],
        },
    }
    page = build_report(hostile, data=train, test_data=test, evaluation=evaluation, title=f"T{bad}")
    assert bad not in page and "<script>alert" not in page
    outside_plots = re.sub(r"<script.*?</script>", "", page, flags=re.S)
    for prefix in ("m", "t", "w", "f", "s", "done", "T", "meth", "key", "v", "cmp", "step", "log", "n", "r"):
        assert prefix + html.escape(bad) in outside_plots, prefix
    assert "p&lt;script&gt;" in page  # the path's name inside plotly's JSON: shown, not interpreted


def test_the_style_sheet_is_package_data_and_in_every_page(twin):
    import robocal.evaluate.report as report_package

    css_file = Path(report_package.__file__).with_name("report.css")
    assert report_css() == css_file.read_text(encoding="utf-8") and ".card" in report_css()
    page = build_report(twin[1])
    assert f"<style>{report_css()}</style>" in page
    assert "robocal.evaluate.report" in (ROOT / "pyproject.toml").read_text(encoding="utf-8")


def test_an_installed_wheel_carries_the_style_sheet_and_template(tmp_path):
    """Build the wheel from a copy of the project (the repository stays clean), install it
    by unpacking, and write a page's style sheet with the installed robocal."""
    project = tmp_path / "project"
    project.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, project / name)
    shutil.copytree(ROOT / "src", project / "src", ignore=shutil.ignore_patterns("*.egg-info", "__pycache__"))
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", str(project), "-w", str(tmp_path / "dist")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if built.returncode != 0 and "No matching distribution" in built.stdout + built.stderr:
        pytest.skip("no build backend available to pip (offline without setuptools)")
    assert built.returncode == 0, built.stderr
    wheel = next((tmp_path / "dist").glob("robocal-*.whl"))
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        assert {"robocal/evaluate/report/report.css", "robocal/evaluate/report/page.html"} <= names
        z.extractall(tmp_path / "site")
    code = (
        "import robocal, robocal.evaluate.report as r; from robocal.evaluate.report import markup; "
        "print(robocal.__file__); print(len(r.report_css())); "
        "print('$sections' in markup._asset('page.html'))"
    )
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "site")}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0, run.stderr
    where, size, template = run.stdout.split()
    assert Path(where).is_relative_to(tmp_path / "site")  # the installed copy, not the checkout
    assert int(size) == len(report_css()) and template == "True"


# ------------------------------------------------------------------ what a reader saw before
def test_the_status_does_not_say_converged_twice(twin):
    result = twin[1]
    for success, message, shown in (
        (True, "converged: xtol reached", "(converged: xtol reached)"),
        (False, "NOT CONVERGED: 200 iterations", "(NOT CONVERGED: 200 iterations)"),
        (True, "", "(converged)"),
    ):
        page = build_report(dataclasses.replace(result, success=success, message=message))
        summary = _section(page, "summary")
        assert shown in summary and "converged: converged" not in summary.lower(), summary


def _log_axes(fig) -> list:
    layout = fig.to_plotly_json()["layout"]
    return [v for k, v in layout.items() if re.fullmatch(r"[xy]axis\d*", k) and v.get("type") == "log"]


def test_log_axes_show_decades_only_and_the_singular_value_title_sits_above_the_plot():
    sigma = np.logspace(0, -4, 12)
    errors = np.linspace(1e-5, 2e-3, 20)
    figures = [fg.singular_values_figure(sigma), fg.per_pose_figure(errors * 2, errors, "t")]
    from robocal.evaluate.metrics import path_accuracy
    from robocal.evaluate.report.data import PathData

    c = np.c_[np.linspace(0, 0.3, 30), np.zeros(30), np.full(30, 0.5)]
    accuracy = {"nominal commands": path_accuracy(c, np.stack([c + 1e-4, c + 2e-4]))}
    paths = [
        PathData("a", np.linspace(0, 300, 30), accuracy),
        PathData("b", np.linspace(0, 300, 30), accuracy),
    ]
    figures.append(fg.path_errors_figure(paths))
    for fig in figures:
        axes = _log_axes(fig)
        assert axes and all(a.get("dtick") == 1 for a in axes), axes
    layout = figures[0].to_plotly_json()["layout"]
    assert layout["title"]["yanchor"] == "top" and layout["margin"]["t"] >= 60


def _inside(fig, pad_fraction: float) -> None:
    """Every text label of ``fig``'s 3D traces lies inside the scene's axis ranges, at least
    ``pad_fraction`` of the range away from its ends (plotly clips labels at the edge)."""
    scene = fig.to_plotly_json()["layout"]["scene"]
    labelled = [t for t in fig.data if t.type == "scatter3d" and "text" in (t.mode or "")]
    assert labelled
    for trace in labelled:
        for axis in "xyz":
            lo, hi = scene[f"{axis}axis"]["range"]
            values = np.asarray(getattr(trace, axis), dtype=float)
            margin = pad_fraction * (hi - lo)
            assert np.all(values >= lo + margin) and np.all(values <= hi - margin), (trace.name, axis)


def test_3d_labels_stay_inside_their_scenes(twin):
    from robocal.model.view import model_figure

    result, _, train, test = twin
    _inside(model_figure(result.model), 0.05)
    report = collect_report(result, data=train, test_data=test)
    _inside(fg.coverage_figure(report.coverage), 0.02)
    # an ISO 9283 cube far from the measured poses: its edges and P1-P5 still inside the scene
    center, side = np.array([1.5, 1.5, 1.5]), 0.4
    commanded = center + side * np.array(
        [[0, 0, 0], [0.3, 0.3, 0.3], [-0.3, -0.3, -0.3], [0.3, -0.3, 0], [-0.3, 0.3, 0]]
    )
    iso = {
        "labels": ["P1", "P2", "P3", "P4", "P5"],
        "commanded": commanded,
        "cube": {"center": center, "side": side, "plane": 1},
        "cycles": 2,
        "cases": {"nominal commands": np.stack([commanded, commanded + 1e-4], axis=1)},
    }
    report = collect_report(result, data=train, evaluation={"iso_poses": iso})
    fig = fg.coverage_figure(report.coverage)
    _inside(fig, 0.02)
    scene = fig.to_plotly_json()["layout"]["scene"]
    edges = report.coverage.cube_edges_mm[np.isfinite(report.coverage.cube_edges_mm[:, 0])]
    for k, axis in enumerate("xyz"):
        lo, hi = scene[f"{axis}axis"]["range"]
        assert lo < edges[:, k].min() and edges[:, k].max() < hi
    assert set(report.iso.poses) == {"nominal commands"}
