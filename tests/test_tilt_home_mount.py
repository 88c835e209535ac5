"""Inclinometer mounts stated at home (issue 33): the same sensors whatever chain is calibrated.

A ``home_r*_deg`` mount is the sensor's orientation in the base frame with every joint at
zero (0, 0, 0: level, x along the base's x); it is resolved against the calibrated chain's
nominal robot at home (:mod:`robocal.measure.constraints.mounts`).  The joint effects'
bending moments are taken about the robot's own chain's joint frame origins
(``loads_about``), so the catalog chain and the complete model of the Katana (joint 5's
frame 0.147 m further along its axis, joints 4-5 turned 180°) predict the same readings.
"""

import math

import numpy as np
import pytest

from robocal.identify.constraints.tilt_rows import ALL_KINDS, tilt_chain, tilt_rows, tilt_terms
from robocal.measure.constraints.data import ConstraintFileError, read_constraints, write_constraints
from robocal.measure.constraints.mounts import axis_shifts, mounts_at_home, mounts_in
from robocal.measure.constraints.sim import level_mounts, simulate_tilt_rows
from robocal.model.catalog import robot
from robocal.model.complete import calibration_model


@pytest.fixture(scope="module")
def katana():
    nominal = robot("katana450")
    return nominal, tilt_chain(nominal), calibration_model(nominal, "position")


def _effects(model) -> dict[str, float]:
    fields = (("clearance", "clearance_tilt"), ("backlash", "backlash"), ("compliance", "compliance"))
    return {f"{k}_{e.joint}": getattr(e, f) for e in model.joint_effects for k, f in fields}


def _predicted(chain, data, frames, effects):
    """The tilt rows' noise-free readings (rad) of ``chain`` at its nominal values."""
    data = mounts_in(data, chain)
    terms = tilt_terms(chain, chain, data, ALL_KINDS, frames)
    values = dict(zip(chain.names, chain.values.tolist(), strict=True))
    x = np.array([effects.get(n, 0.0) for n in terms.effects])
    r = tilt_rows(terms, data, values, np.zeros(len(terms.zeros)), x)[0]
    return r + data.tilt[data.tilted]


@pytest.fixture(scope="module")
def readings(katana):
    nominal, _, _ = katana
    data = simulate_tilt_rows(nominal, 12, sigma=1e-9, seed=3, mounts=level_mounts(nominal))
    return mounts_at_home(data, nominal)  # the catalog's level sensors, stated at home


def test_level_sensors_at_home_are_zeros_and_round_trip(readings, tmp_path):
    """Level at home in the catalog's frames is home angles 0, 0, 0; the file keeps them."""
    assert readings.tilt_home[readings.tilted].all()
    assert np.abs(readings.tilt_mount).max() < 1e-12
    path = tmp_path / "home.csv"
    write_constraints(readings, path)
    header = path.read_text().splitlines()[0].split(",")
    assert header[-3:] == ["home_rx_deg", "home_ry_deg", "home_rz_deg"] and "mount_rx_deg" not in header
    back = read_constraints(path, 5)
    assert back.tilt_home.all() and np.array_equal(back.tilt_mount, readings.tilt_mount)


def test_a_row_stating_both_mounts_is_refused_by_row(tmp_path):
    path = tmp_path / "both.csv"
    path.write_text(
        "q1,q2,q3,q4,q5,link,axis,tilt_deg,mount_rx_deg,mount_ry_deg,mount_rz_deg,home_rx_deg,home_ry_deg,home_rz_deg\n"
        "0,0.5,0,0,0,2,x,1.0,,,,0,0,0\n"
        "0,0.5,0,0,0,2,y,1.0,0,0,90,0,0,0\n"
    )
    with pytest.raises(ConstraintFileError, match=r"row 3"):
        read_constraints(path, 5)


def test_the_same_sensors_and_effects_in_the_catalog_chain_and_the_complete_model(katana, readings):
    """Home mounts resolved in each chain and the moments taken about the catalog's points:
    the complete model predicts the catalog's readings to round-off with Table 5.2's
    effects; the moments about its own (moved) points are another robot."""
    nominal, catalog, complete = katana
    effects = _effects(nominal)
    assert abs(axis_shifts(complete, nominal)[4] - 0.1473) < 1e-9  # joint 5's frame moved
    expected = _predicted(catalog, readings, None, effects)
    same = _predicted(complete, readings, nominal, effects)
    assert np.abs(same - expected).max() < 1e-12
    moved = _predicted(complete, readings, None, effects)
    assert np.abs(moved - expected).max() > math.radians(5e-4)


def test_joint_frame_angles_are_the_robot_own_chain_stated_at_home(katana, readings):
    """``mount_r*_deg`` angles (none: the joint frame) are the robot's own chain's: restated at
    home through it, the complete model reads them as the catalog does (in its own frames,
    turned 180° about joints 4 and 5, the same angles would read other sensors)."""
    nominal, catalog, complete = katana
    joint = mounts_in(readings, nominal)  # the catalog's joint-frame angles of the same sensors
    assert not joint.tilt_home.any()
    restated = mounts_at_home(joint, nominal)
    assert np.abs(restated.tilt_mount - readings.tilt_mount).max() < 1e-12
    effects = _effects(nominal)
    expected = _predicted(catalog, readings, None, effects)
    assert np.abs(_predicted(complete, restated, nominal, effects) - expected).max() < 1e-12
    misread = _predicted(complete, joint, nominal, effects)  # the angles taken in its frames
    assert np.abs(misread - expected).max() > math.radians(1.0)
