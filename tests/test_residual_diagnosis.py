"""The learned residual's model family and what it is handed (issue 34 item 1)."""

from __future__ import annotations

import dataclasses

import numpy as np

import robocal as rc
from robocal.identify.problem_setup import without_measured_tool
from robocal.model.residual import JointAngleResidual


def test_a_model_with_a_learned_residual_keeps_it_through_the_tool_split() -> None:
    """The tool split is cached by the model's hash, which leaves the residual out: the same
    model with a residual split after the one without must keep its residual (the default
    fit's refit with the learned angle errors known reads it back)."""
    model = rc.calibration_model("ur10", "position")
    m = 2 * 2
    learned = JointAngleResidual(("elbow_joint",), (2,), 2, np.zeros(m), np.eye(m), 1e-5, (1e-4,), 0.1)
    with_residual = dataclasses.replace(model, residual=learned)
    assert without_measured_tool(model)[0].residual is None
    assert without_measured_tool(with_residual)[0].residual is learned
