"""Type-checked, never run: the README's use of the public API (``import robocal as rc``).

``tests/test_typing.py`` runs mypy on this file with ``disallow_untyped_calls``: every public
function used here must carry type hints, and what it returns must be what the README says.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

import robocal as rc


def _usage(data_path: str, targets: npt.NDArray[np.float64]) -> None:
    names: list[str] = rc.robots()
    model: rc.Model = rc.robot(names[0])
    calib: rc.Model = rc.calibration_model("ur10")
    calib = rc.calibration_model(model, measure="pose")
    q = np.radians([[0, -90, 90, 0, 90, 0]])
    T: npt.NDArray[np.float64] = model.fk(q)
    frames: npt.NDArray[np.float64] = model.joint_frames(q)
    J: npt.NDArray[np.float64] = model.jacobian(q)
    J6: npt.NDArray[np.float64] = model.jacobian(q, rows="pose")
    Jq: npt.NDArray[np.float64] = model.joint_jacobian(q)
    free: tuple[str, ...] = model.free_names
    changed: rc.Model = model.with_free_values(model.free_values + 1e-4)
    rc.save_model(changed, "ur10_changed.yaml")
    same: bool = rc.load_model("ur10_changed.yaml") == changed

    data: rc.Measurements = rc.read_measurements(data_path, length_unit="mm")
    result: rc.CalibrationResult = rc.calibrate(calib, data, method="lm", tool_guess=[0, 0, 0.1])
    summary: str = result.summary()
    result.save("out/")
    stats = rc.validate(result, data)
    sigma: npt.NDArray[np.float64] = result.position_uncertainty(q)
    folds = rc.cross_validate(calib, data, folds=5)
    rc.write_measurements(data, "copy.csv")

    comp = rc.compensate_targets(result, targets, frame="measurement")
    q_cmd: npt.NDArray[np.float64] = comp.q
    built: rc.Model = rc.build_model([{"axis": [0, 0, 1], "point": [0, 0, 0]}])
    urdf: rc.Model = rc.model_from_urdf("robot.urdf", measure="position")
    step: type[rc.Step] = rc.Step
    joint: type[rc.Joint] = rc.Joint
    body: type[rc.Body] = rc.Body
    effects: type[rc.JointEffects] = rc.JointEffects
    error: type[Exception] = rc.ModelFileError
    version: str = rc.__version__
    R = rc.spatial.rotx(0.1)
    del calib, T, frames, J, J6, Jq, free, same, summary, stats, sigma, folds, q_cmd, built, urdf
    del step, joint, body, effects, error, version, R
