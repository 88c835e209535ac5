"""Bugs that mypy found (issue 32 item 6), each held by a test of the behaviour."""

from __future__ import annotations

import dataclasses

import numpy as np

from robocal import spatial
from robocal.evaluate.iso9283_log import Iso9283Log
from robocal.evaluate.iso9283_report import evaluate_log


def _reorientation_log(cycles: int = 3, samples: int = 40) -> Iso9283Log:
    """A reorientation test along a line, each cycle turning the tool about z (m, rad)."""
    s = np.linspace(0.0, 0.3, samples)
    commanded = np.column_stack([0.5 + s, np.zeros(samples), 0.4 + 0.0 * s])
    turn = spatial.rotvec_to_matrix(np.column_stack([0 * s, 0 * s, np.linspace(0.0, 1.0, samples)]))
    n = cycles * samples
    rng = np.random.default_rng(0)
    return Iso9283Log(
        source="built",
        conditions={},
        time=np.arange(n) * 0.01,
        test=np.full(n, "reorientation"),
        cycle=np.repeat(np.arange(1, cycles + 1), samples),
        target=np.full(n, "line"),
        group=np.full(n, ""),
        position=np.tile(commanded, (cycles, 1)) + rng.normal(0.0, 1e-5, (n, 3)),
        commanded=np.tile(commanded, (cycles, 1)),
        rotation=np.tile(turn, (cycles, 1, 1)),
        commanded_rotation=np.tile(turn, (cycles, 1, 1)),
    )


def _row(log: Iso9283Log, number: int):
    return next(r for r in evaluate_log(log).rows if r.number == number)


def test_reorientation_needs_commanded_orientations_too():
    """A log with measured but no commanded orientations (an Iso9283Log built in Python) was
    passed on as ``None`` commanded frames; clause 8.4 now says the orientations are missing."""
    full = _reorientation_log()
    assert _row(full, 9).measured  # the same log with both orientations is evaluated
    half = dataclasses.replace(full, commanded_rotation=None)
    row = _row(half, 9)
    assert not row.measured
    assert "orientation" in row.summary and "shape" not in row.summary, row.summary


def test_a_per_robot_pose_set_without_n_is_refused_by_name(tmp_path):
    """mypy: ``random_poses(model, spec.n)`` with ``n: int | None``.  A per-robot random pose
    set without ``n`` used to pass the study's checks and fail every robot's row with a
    TypeError (``int() argument ... not 'NoneType'``); it is now refused before any work."""
    from typer.testing import CliRunner

    from robocal.cli import app

    cfg = tmp_path / "study.yaml"
    cfg.write_text(
        "name: t\nrobot: ur5\nrobots: 1\n"
        "pose_sets:\n  - {name: a, per_robot: true}\ndevices:\n  - {name: d}\n"
    )
    out = tmp_path / "o"
    result = CliRunner().invoke(app, ["study", str(cfg), "--out", str(out), "--workers", "0"])
    assert result.exit_code == 2, result.output
    assert "pose_sets[0]" in result.output and "'n'" in result.output, result.output
    assert not (out / "results.csv").exists()
