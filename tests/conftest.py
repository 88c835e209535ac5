"""Test-suite settings.

Property-based tests (Hypothesis) are derandomized by default, so that the suite — and
CI — gives the same verdict on every run; ``HYPOTHESIS_PROFILE=explore python -m pytest``
draws fresh examples (more of them) to look for new failures.
"""

import os

import pytest
from hypothesis import settings

settings.register_profile("default", derandomize=True)
settings.register_profile("explore", derandomize=False, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

# the compiled kernels throughout, even when numba's cache is cold (a command would then take
# the numpy path and start a warm-up process: tests/test_cold_path.py tests that on purpose)
os.environ.setdefault("ROBOCAL_KERNELS", "compiled")


@pytest.fixture(scope="session")
def compliant_ur10():
    """A virtual UR10 whose shoulder and elbow give way under gravity, measured by a laser
    tracker at 40 poses, and its calibration with those two compliances:
    ``(model, robot, train, result)`` (the reports' tests share it)."""
    import numpy as np

    import robocal as rc
    from robocal.demo import GravityCompliance, complete_model
    from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

    model = complete_model("ur10")
    true = draw_true_model(model, length=1e-3, angle=np.radians(0.1), seed=4)
    robot = VirtualRobot(
        model,
        true,
        LaserTracker(p_tool_target=np.array([0, 0, 0.1])),
        GravityCompliance({"shoulder_lift": 4e-6, "elbow": 6e-6}),
    )
    train = simulate(robot, random_poses(model, 40, seed=1), seed=1)
    result = rc.calibrate(model, train, tool_guess=[0, 0, 0.1], compliance=["shoulder_lift", "elbow"])
    return model, robot, train, result
