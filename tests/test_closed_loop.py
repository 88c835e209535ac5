"""Closed loops with the DEFAULT calibration path (complete model, residual auto): a virtual
true robot executes what the controller does with robocal's output (nominal model -> joints
-> true FK) and lands within 3x the calibration's expected error."""

import numpy as np
import pytest

import robocal as rc
from robocal.compensate.compensation import compensate_targets
from robocal.compensate.safety import sigma_min
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

TOOL = np.array([0.0, 0.0, 0.1])


def _calibrated(name: str, n: int = 60):
    nominal = rc.robot(name)
    true = draw_true_model(nominal, length=0.5e-3, angle=np.radians(0.05), seed=4)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL))
    data = simulate(robot, random_poses(nominal, n, seed=2), seed=2)
    result = rc.calibrate(rc.calibration_model(name, "position"), data, residual="auto", tool_guess=TOOL)
    return robot, result


@pytest.mark.parametrize("name", ["ur10"])
def test_targets_and_joint_program_land_within_3x_expected_error(name):
    robot, result = _calibrated(name)
    q = random_poses(robot.nominal, 40, seed=9)
    q = q[sigma_min(robot.nominal, q, None, "pose") > 0.05][:12]
    # Cartesian targets in the cell (tracker) frame: where the true tool point should go
    goal = robot.device.predict(robot.T_base_tool(q)).position
    comp = compensate_targets(result, goal, frame="measurement", q0=q)
    assert comp.success, comp.refused
    # the controller commands comp.q; the true robot's tool point lands at
    landed = robot.device.predict(robot.T_base_tool(comp.q)).position
    error = np.linalg.norm(landed - goal, axis=1)
    expected = np.maximum(comp.expected_error_after, 2e-5)  # m; the tracker's noise floor
    assert np.all(error <= 3 * expected), (error, comp.expected_error_after)
    before = np.linalg.norm(robot.device.predict(robot.T_base_tool(comp.q_nominal)).position - goal, axis=1)
    assert error.mean() < before.mean() / 5


# ---------------------------------------------------------------- every output, several robots
# (issue 31 item 6) joint programs, paths and programs in each language through the default
# calibration path; the pass rule per target (:func:`_check_landed`): corrected -> within 3x the
# calibration's expected error on the virtual true robot; damped (near a singularity) -> every
# joint within its stated bound (min(bound, MAX_DAMPED)), no farther off than before or 3x expected;
# refused -> left as written and named.
_CALIBRATIONS: dict = {}
FLOOR = 2e-5  # m: the tracker's noise floor under the expected error


def _cal(name: str, n: int = 60):
    if name not in _CALIBRATIONS:
        _CALIBRATIONS[name] = _calibrated(name, n)
    return _CALIBRATIONS[name]


def _landed(robot, q):
    """Where the true robot's tool point goes at joints ``q`` (device frame, m)."""
    return robot.device.predict(robot.T_base_tool(np.atleast_2d(q))).position


def _check_landed(robot, result, comp, goal_device):
    """The pass rule above, per target; returns the true errors after (m)."""
    from robocal.compensate.safety import MAX_DAMPED

    after = np.linalg.norm(_landed(robot, comp.q) - goal_device, axis=1)
    before = np.linalg.norm(_landed(robot, comp.q_nominal) - goal_device, axis=1)
    expected = np.maximum(result.expected_position_error(comp.q), FLOOR)
    for i, status in enumerate(comp.status):
        dq = np.abs(comp.q[i] - comp.q_nominal[i])
        if status == "corrected":
            assert after[i] <= 3 * expected[i], (comp.names[i], after[i], expected[i])
        elif status == "damped":
            assert np.all(dq <= np.minimum(comp.joint_bound[i], MAX_DAMPED) + 1e-12), comp.names[i]
            assert after[i] <= max(before[i], 3 * expected[i]), (comp.names[i], after[i], before[i])
        else:
            assert np.array_equal(comp.q[i], comp.q_nominal[i]) and comp.reasons[i], comp.names[i]
    return after


def _special_configurations(model) -> dict[str, np.ndarray]:
    """Well-conditioned joints and joints near the wrist (joint 5 ~ 1e-4 rad), elbow (wrist
    centre on the lower arm's line) and shoulder (wrist centre on axis 1) boundaries, found on
    a grid from a well-conditioned configuration, and a 2π winding of the last joint."""
    from robocal.compensate.safety import _sides

    q_all = random_poses(model, 80, seed=21)
    sig = sigma_min(model, q_all, None, "pose")
    good = q_all[sig > 0.08][:6]
    q_ref = good[0].copy()
    out = {f"good{k}": q for k, q in enumerate(good)}
    wrist = q_ref.copy()
    wrist[4] = 1e-4
    out["wrist"] = wrist
    lim = model.joint_limits
    for label, joint, side in (("elbow", 2, 1), ("shoulder", 1, 0)):
        grid = np.repeat(q_ref[None], 721, axis=0)
        grid[:, joint] = np.linspace(max(lim[joint, 0], -np.pi), min(lim[joint, 1], np.pi), 721)
        out[label] = grid[np.argmin(np.abs(_sides(model, grid)[:, side]))]
    if q_ref[5] + 2 * np.pi <= lim[5, 1]:
        out["wound"] = q_ref + np.r_[np.zeros(5), 2 * np.pi]
    elif q_ref[5] - 2 * np.pi >= lim[5, 0]:
        out["wound"] = q_ref - np.r_[np.zeros(5), 2 * np.pi]
    return out


@pytest.mark.parametrize("name", ["ur10", "kr16", "irb2400"])
def test_joint_program_with_singular_and_wound_targets_lands(name):
    from robocal.compensate.compensation import filter_program, nominal_model

    robot, result = _cal(name)
    special = _special_configurations(robot.nominal)
    q = np.array(list(special.values()))
    comp = filter_program(result, q, names=list(special))
    goal = (result.frame @ nominal_model(result).fk(q))[:, :3, 3]  # where the program meant to go
    _check_landed(robot, result, comp, goal)
    status = dict(zip(comp.names, comp.status, strict=True))
    assert all(status[k] == "corrected" for k in special if k.startswith("good")), status
    assert status["wrist"] == "damped", status
    if "wound" in special:  # the winding is kept: corrected near the written value, not 2π away
        k = comp.names.index("wound")
        assert status["wound"] == "corrected" and abs(comp.q[k, 5] - q[k, 5]) < 0.01


@pytest.mark.parametrize("method", ["ik", "jacobian"])
def test_paths_land_within_3x_expected_error(method):
    from robocal.compensate.paths import compensate_cartesian_path, compensate_path

    robot, result = _cal("ur10")
    q_all = random_poses(robot.nominal, 40, seed=9)
    a, b = q_all[sigma_min(robot.nominal, q_all, None, "pose") > 0.08][:2]
    q_path = a + np.linspace(0, 0.25, 25)[:, None] * (b - a)  # a stretch away from singularities
    assert sigma_min(robot.nominal, q_path, None, "pose").min() > 0.05
    from robocal.compensate.compensation import nominal_model

    options = {"iterations": 3} if method == "jacobian" else {}
    comp = compensate_path(result, q_path, method=method, **options)
    goal = (result.frame @ nominal_model(result).fk(q_path))[:, :3, 3]
    _check_landed(robot, result, comp, goal)
    assert comp.status and comp.success and comp.smooth, comp.refused
    # a Cartesian path given in the cell frame
    goal = _landed(robot, q_path)  # where the true robot went: reachable, in the cell
    options |= {"frame": "measurement", "q0": q_path[0]}
    comp = compensate_cartesian_path(result, goal, method=method, **options)
    _check_landed(robot, result, comp, goal)
    assert comp.success, comp.refused


# measured (seed 4 errors, 40 poses): UR5's damped elbow-singular target lands 1.03 mm off where
# the nominal command lands 0.87 mm off: damping can make a target near a singularity worse
_WORSE = pytest.mark.xfail(strict=True, reason="UR5 elbow: damped correction 1.03 mm vs 0.87 mm before")


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=_WORSE) if n == "ur5" else n for n in rc.robots() if rc.robot(n).dof == 6]
)
def test_every_catalog_robot_joint_program_lands(name):
    from robocal.compensate.compensation import filter_program, nominal_model

    robot, result = _cal(name, 40)
    special = _special_configurations(robot.nominal)
    q = np.array(list(special.values()))
    comp = filter_program(result, q, names=list(special))
    goal = (result.frame @ nominal_model(result).fk(q))[:, :3, 3]
    after = _check_landed(robot, result, comp, goal)
    print(name, dict(zip(comp.names, comp.status, strict=True)), f"max after {after.max() * 1e3:.3f} mm")
