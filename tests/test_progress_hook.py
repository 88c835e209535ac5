"""The engine's progress hook (issue 36 item 1): ``rc.calibrate(..., progress=f)`` reports the
share of the fit done (after the physical fit, after each physical variant's cross-validation
of the learned residual), non-decreasing and ending at 1; the use case forwards it inside its
``calibrate`` stage, between that stage's start and the next stage's, which is what the GUI's
bar shows (no time-based estimate)."""

from __future__ import annotations

import itertools
import subprocess
import sys

import numpy as np
import pytest

import robocal as rc
from robocal.model.catalog import find_model
from robocal.workflow import STAGES, CalibrateRequest, FitOptions, calibrate_file


@pytest.fixture(scope="module")
def sim_csv(tmp_path_factory):
    where = tmp_path_factory.mktemp("progress")
    q = np.random.default_rng(0).uniform(-2.0, 2.0, (60, 6))
    np.savetxt(where / "poses.csv", q, delimiter=",", header="q1,q2,q3,q4,q5,q6", comments="")
    out = where / "sim60.csv"
    cmd = [sys.executable, "-m", "robocal.cli", "simulate", "ur10", "--poses", str(where / "poses.csv")]
    subprocess.run([*cmd, "-o", str(out), "--seed", "1"], check=True, capture_output=True)
    return out


def test_calibrate_reports_a_non_decreasing_share_that_ends_at_one(sim_csv):
    data = rc.read_measurements(sim_csv)
    model = rc.calibration_model("ur10", "position")
    seen: list[float] = []
    rc.calibrate(model, data, residual="auto", progress=seen.append)
    assert seen[-1] == 1.0
    assert all(b >= a for a, b in itertools.pairwise(seen))
    inside = [f for f in seen if 0.0 < f < 1.0]
    assert len(set(inside)) >= 3  # the physical fit, then each variant's fit and its folds
    plain: list[float] = []
    rc.calibrate(model, data, progress=plain.append)  # no residual: one fit, then done
    assert plain == [1.0]


def test_the_use_case_forwards_it_inside_the_calibrate_stage(sim_csv, tmp_path):
    starts = {key: start for key, _, start in STAGES}
    events: list[tuple[str, float]] = []
    request = CalibrateRequest(
        sim_csv, find_model("ur10"), tmp_path / "out", fit=FitOptions(residual="auto"), from_catalog=True,
        train_n=45, progress=lambda stage, fraction: events.append((stage, fraction)),
    )  # fmt: skip
    calibrate_file(request)
    fractions = [f for _, f in events]
    assert all(b >= a for a, b in itertools.pairwise(fractions))
    inside = [f for stage, f in events if stage == "calibrate"]
    assert inside[0] == starts["calibrate"] and inside[-1] == pytest.approx(starts["validate"])
    assert len(set(inside)) >= 4  # finer than the stage names alone
    assert [s for s, _ in events][-1] == "save"


@pytest.mark.parametrize("folds", [3, 6])
def test_the_cross_validation_reports_each_fold(sim_csv, folds):
    """Each physical variant reports its fit on all poses and then each of its ``folds`` folds
    (identify/residual/cv.py): the number of distinct shares inside the fit grows by one per
    fold and variant, so the page's bar moves per fold."""
    data = rc.read_measurements(sim_csv)
    model = rc.calibration_model("ur10", "position")
    seen: list[float] = []
    result = rc.calibrate(model, data, residual="auto", cv_folds=folds, progress=seen.append)
    table = result.diagnostics.cv_table()
    assert table is not None and table.folds == folds
    variants = len({c.physics for c in table.candidates})
    inside = sorted({f for f in seen if 0.0 < f < 1.0})
    # 0.2 after the physical fit, then per variant: its fit on all poses and its folds
    assert len(inside) >= 1 + variants * (1 + folds)
    assert all(b >= a for a, b in itertools.pairwise(seen))
