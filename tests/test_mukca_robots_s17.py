"""Issue 33's check "recordings of other robots": MUKCa's KUKA iiwa 14 and Kinova Gen3 lite
(benchmarks/data/mukca/, vendored) through the CLI as a user runs it.

The URDFs come as MUKCa ships them (fixed joints with ``<axis xyz="0 0 0"/>``, meshes that are
not here); the iiwa calibrated on one placement must judge another placement far better than
its nominal URDF, with the figures the API gives; the Gen3 lite's fit must say what one
placement cannot identify and leave it at the nominal value, not invent it."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from robocal.cli.app import app
from robocal.identify.constraints.figures import pooled_spread
from robocal.identify.constraints.fit import constraint_figures
from robocal.measure.constraints.data import read_constraints
from robocal.model.files import load_model

ROOT = Path(__file__).resolve().parents[1]
MUKCA = ROOT / "benchmarks" / "data" / "mukca"
FIFTY_MM = [(0, 1, 0.05)]


def _run(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def _build(urdf: Path, out: Path):
    built = _run("model", "build", urdf, "--tip", "ball_link", "--measure", "position", "-o", out)
    assert built.exit_code == 0, built.output
    return load_model(out)


def _sockets(placement: Path, out: Path) -> Path:
    converted = _run("data", "sockets", placement, "-o", out)
    assert converted.exit_code == 0, converted.output
    return out


def _calibrated(tmp_path: Path, urdf: str, placement: str):
    """The nominal model built from ``urdf`` and the calibration folder of ``placement``'s
    sockets through the CLI (50 mm apart)."""
    nominal = _build(MUKCA / "urdf" / urdf, tmp_path / "nominal.yaml")
    data = _sockets(MUKCA / placement, tmp_path / "train.csv")
    cal = tmp_path / "cal"
    fit = _run("calibrate", tmp_path / "nominal.yaml", "--data", data, "--distance", "0,1=50mm", "-o", cal)
    assert fit.exit_code == 0, fit.output
    return nominal, cal


def _figures_mm(model, data) -> tuple[float, float]:
    """RMS spread of both sockets pooled and |distance - 50 mm| (the benchmark's figures)."""
    f = constraint_figures(model, data)
    return pooled_spread(f, data) * 1e3, abs(float(f.point_distance_error[0])) * 1e3


@pytest.mark.parametrize(("urdf", "dof"), [("iiwa14.urdf", 7), ("gen3lite.urdf", 6)])
def test_model_build_reads_mukcas_urdfs_as_they_come(tmp_path, urdf, dof):
    text = (MUKCA / "urdf" / urdf).read_text()
    assert re.search(r'type="fixed"', text) and 'xyz="0 0 0"/>' in text  # the case issue 33 names
    model = _build(MUKCA / "urdf" / urdf, tmp_path / "m.yaml")
    assert model.dof == dof
    # the chain ends at the ball: its nominal offset from the flange is carried (not zero)
    tip = model.fk(np.zeros((1, dof)))[0][:3, 3]
    assert np.all(np.isfinite(tip)) and np.linalg.norm(tip) > 0.3


def test_kuka_calibrated_on_one_placement_through_the_cli_judges_the_others(tmp_path):
    nominal, cal = _calibrated(tmp_path, "iiwa14.urdf", "kuka_14/front")
    calibrated = load_model(cal / "model.yaml")
    for name in ("left_back", "raised_left"):
        held = _sockets(MUKCA / "kuka_14" / name, tmp_path / f"{name}.csv")
        data = read_constraints(held, 7, distances=FIFTY_MM, sigma=1e-4)
        spread, distance = _figures_mm(calibrated, data)
        spread0, distance0 = _figures_mm(nominal, data)
        assert spread < 0.6 * spread0  # measured 0.145 / 0.466 mm against 0.86 / 0.85 nominal
        assert distance < distance0
        # validate prints the API's figures for the held-out placement, per socket
        shown = _run("validate", cal, "--data", held)
        assert shown.exit_code == 0, shown.output
        printed = [float(v) for v in re.findall(r"RMS spread ([0-9.]+) mm", shown.output)[:2]]
        per_socket = constraint_figures(calibrated, data).point_spread * 1e3
        assert printed == pytest.approx(per_socket, abs=6e-4)


def test_gen3_lite_fit_reports_what_one_placement_cannot_identify(tmp_path):
    nominal, cal = _calibrated(tmp_path, "gen3lite.urdf", "dinova_2/front")
    saved = json.loads((cal / "constraints.json").read_text())
    unseen = {d["name"] for d in saved["not_identifiable"]}
    # fixed points cannot see the base frame nor the first joint's zero and height
    assert {"base_x", "base_y", "base_rx", "base_ry", "theta1", "d1"} <= unseen
    assert not unseen & set(saved["names"])  # reported, not estimated
    calibrated = load_model(cal / "model.yaml")
    before = dict(zip(nominal.names, nominal.values, strict=True))
    after = dict(zip(calibrated.names, calibrated.values, strict=True))
    for name in unseen:  # left at the nominal value, not invented
        assert after[name] == pytest.approx(before[name], abs=1e-12)
    assert any(abs(after[n] - before[n]) > 1e-6 for n in saved["names"] if n in before)  # the rest moved


def test_validate_refuses_options_a_constraint_file_would_ignore_and_writes_json(tmp_path):
    _, cal = _calibrated(tmp_path, "iiwa14.urdf", "kuka_14/front")
    front = tmp_path / "train.csv"
    for extra in (["--refit-frame"], ["--length-unit", "mm"], ["--sep", ";"]):
        refused = _run("validate", cal, "--data", front, *extra)
        assert refused.exit_code != 0
        assert extra[0] in refused.output and "Traceback" not in refused.output
        assert not refused.output.lstrip().startswith("{")  # no JSON pretending to be the figures
    # --json: the same figures as one document (mm), the calibrated and the nominal robot's
    held = _sockets(MUKCA / "kuka_14" / "left_back", tmp_path / "left_back.csv")
    shown = _run("validate", cal, "--data", held, "--json")
    assert shown.exit_code == 0, shown.output
    doc = json.loads(shown.stdout)
    data = read_constraints(held, 7, distances=FIFTY_MM, sigma=1e-4)
    expected = constraint_figures(load_model(cal / "model.yaml"), data)
    assert doc["figures"]["point_spread_mm"] == pytest.approx(expected.point_spread * 1e3, rel=1e-9)
    assert doc["figures"]["point_distance_error_mm"] == pytest.approx(expected.point_distance_error * 1e3)
    assert doc["poses"] == data.n and min(doc["nominal_figures"]["point_spread_mm"]) > 0.5


def test_the_benchmark_series_keep_above_their_floor(monkeypatch):
    """The benchmark's two foreign robots (about 1 s): no held-out or pooled figure beats the
    placement's own in-sample fit, and the default beats the nominal URDF held out."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_ball_in_socket_robots as bench

    for name in ("kuka_14", "dinova_2"):
        series = bench.run_series(name)
        assert series.below == 0
        assert series.held["complete + prior"][:, 0].mean() < series.held["nominal"][:, 0].mean()


def test_data_sockets_prints_a_long_path_on_one_line(tmp_path):
    """The paths it names and the next command stay copyable (not broken at the console's width)."""
    import shutil

    deep = tmp_path / ("a_placement_folder_with_a_long_name_" * 3) / "front"
    shutil.copytree(MUKCA / "kuka_14" / "front", deep)
    out = deep.parent / "front.csv"
    converted = _run("data", "sockets", deep, "-o", out)
    assert converted.exit_code == 0, converted.output
    lines = converted.output.splitlines()
    assert any(line.endswith(str(deep / "hole_0.csv")) for line in lines), converted.output
    assert any(str(out) in line and "--distance" in line for line in lines), converted.output
