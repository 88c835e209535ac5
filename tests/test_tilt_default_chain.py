"""The chain a catalog robot's tilt rows are calibrated in by default (issue 33): the
complete position model with the angles it leaves to the tool freed
(:func:`robocal.identify.constraints.tilt_rows.link_rotations_free`), chosen by what the
readings' Jacobian spans, not by the robot's name.  The thesis' Katana (whose position
model lacks its last joint's offset, a sensor on link 5 reads it) and a true UR10 with
errors in its last twist and offset (which its DH catalog chain cannot carry between its
parallel joints) both fit to the readings' noise through the default command; the same
tilt file alone and beside a tracker file gives the same joint effects."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli.app import app
from robocal.experiments.seed003_inclinometer import katana_robots
from robocal.experiments.seed003_tilt_rows import EFFECTS, thesis_tilt_file
from robocal.identify.constraints.fit import build_constraint_problem
from robocal.identify.constraints.tilt_rows import ALL_KINDS, link_rotations_free, tilt_chain, unclear_contact
from robocal.measure.constraints.data import read_constraints, write_constraints
from robocal.measure.constraints.mounts import mounts_at_home
from robocal.measure.constraints.sim import simulate_tilt_rows, simulate_tracker_rows
from robocal.measure.true_model import draw_true_model
from robocal.model.complete import calibration_model

COUNT = math.radians(0.001)  # the readings' σ (rad)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The thesis' tilt file (sensors level at home) and a tracker file of the same true Katana."""
    where = tmp_path_factory.mktemp("katana_default")
    tilt, tracker = where / "thesis_tilt.csv", where / "tracker.csv"
    thesis_tilt_file(tilt)
    write_constraints(simulate_tracker_rows(katana_robots().true, 60, sigma=1e-5, seed=6), tracker)
    return where, tilt, tracker


def _calibrate(args: list[str], out) -> dict:
    result = CliRunner().invoke(app, ["calibrate", *args, "-o", str(out)])
    assert result.exit_code == 0, result.output
    return json.loads((out / "constraints.json").read_text())


def _effects(doc: dict) -> dict[str, tuple[float, float]]:
    """``{name: (estimate, σ)}`` (SI) of the saved joint effects with a σ."""
    got = {}
    for e in doc["joint_effects"]:
        unit = "rad_per_Nm" if e["kind"] == "compliance" else "rad"
        if e[f"std_{unit}"]:
            got[e["name"]] = (float(e[f"estimate_{unit}"]), float(e[f"std_{unit}"]))
    return got


def _columns(model, data, frames):
    """The tilt rows' Jacobian at the start, columns of unit norm, and their names (zero
    columns, what the rows do not see, left out)."""
    problem = build_constraint_problem(model, data, None, None, ALL_KINDS, frames)
    J = np.asarray(problem.jacobian(problem.x0))
    norms = np.linalg.norm(J, axis=0)
    seen = norms > 1e-9 * norms.max()
    return J[:, seen] / norms[seen], [n for n, s in zip(problem.free_names, seen, strict=True) if s]


def _outside(A, names, B) -> list[str]:
    """The columns of ``A`` not in the span of ``B``'s."""
    U, s, _ = np.linalg.svd(B, full_matrices=False)
    U = U[:, s > 1e-8 * s[0]]
    return [n for n, a in zip(names, A.T, strict=True) if np.linalg.norm(a - U @ (U.T @ a)) > 1e-6]


def test_freed_complete_model_spans_the_catalog_chains_tilt_columns(files):
    """At the thesis' configurations the position model misses the catalog's joint-5 turn
    (``beta4`` / ``theta5``: the last joint's offset, held for the tool); with its link
    rotations freed it spans every column of the catalog chain and of itself before."""
    _, tilt, _ = files
    nominal = katana_robots().nominal
    data = read_constraints(tilt, nominal.dof, angle_unit="deg")
    data = data.select(~unclear_contact(nominal, data))
    position = calibration_model(nominal, "position")
    A, a_names = _columns(tilt_chain(nominal), data, nominal)
    P, p_names = _columns(position, data, nominal)
    F, _ = _columns(link_rotations_free(position), data, nominal)
    assert {"beta4", "theta5"} <= set(_outside(A, a_names, P))  # what the default lacked
    assert _outside(A, a_names, F) == [] and _outside(P, p_names, F) == []
    rank = np.linalg.matrix_rank
    assert rank(F, tol=1e-8) == rank(np.hstack([A, P]), tol=1e-8)


def test_default_command_fits_the_thesis_file_to_its_noise(files, tmp_path):
    """``robocal calibrate katana450 --data FILE`` (no --chain): the residual is the counts'
    noise (0.025° before) and the joint effects are the thesis' within 3σ
    (tests/test_tilt_thesis.py checks the tables through both chains)."""
    from robocal.experiments.seed003_inclinometer import THESIS_TABLE_5_2

    _, tilt, _ = files
    doc = _calibrate(["katana450", "--data", str(tilt), *EFFECTS], tmp_path / "out")
    assert doc["success"] and doc["rms_after_m"] < 1.3 * COUNT  # rad for tilt rows
    got = _effects(doc)
    for j, thesis in enumerate(THESIS_TABLE_5_2["backlash_deg"]):
        if f"backlash_q{j + 1}" in got:
            value, sigma = got[f"backlash_q{j + 1}"]
            assert abs(math.degrees(value) - thesis) <= 3 * math.degrees(sigma)


def test_same_tilt_file_alone_and_beside_a_tracker_file_agree(files, tmp_path):
    """The same tilt file calibrated alone and with a tracker file of the same robot
    (``--data tilt.csv --data tracker.csv``: the tracker's lengths and tool join the fit)
    gives the same joint effects within their σ, every one both fits identify."""
    _, tilt, tracker = files
    alone = _effects(_calibrate(["katana450", "--data", str(tilt), *EFFECTS], tmp_path / "alone"))
    both = _calibrate(["katana450", "--data", str(tilt), "--data", str(tracker), *EFFECTS], tmp_path / "both")
    mixed = _effects(both)
    assert both["success"] and len(alone) >= 10 and set(alone) == set(mixed)
    for name, (value, sigma) in alone.items():
        other, other_sigma = mixed[name]
        assert abs(value - other) <= max(sigma, other_sigma), (name, value, other, sigma)


def test_a_true_ur10_with_errors_the_position_model_holds_fits_to_its_noise(tmp_path):
    """A true UR10 whose last twist and offset (``alpha5``, ``theta6``: held by the
    position model, absent between the catalog's parallel joints) are off by up to 0.1°:
    the default chain fits its tilt file to the noise on every channel."""
    from tests.test_tilt_rows import _tilt_lines

    ur10 = rc.calibration_model("ur10")
    assert not {"alpha5", "theta6"} & set(ur10.free_names)  # the position model holds them
    drawn = draw_true_model(ur10, length="1mm", angle="0.1deg", seed=11)
    tilt = math.radians(0.1)
    true = drawn.with_values(
        {"alpha5": ur10.step("alpha5").value + tilt, "theta6": ur10.step("theta6").value - tilt}
    )
    path = tmp_path / "tilt.csv"
    plain = dataclasses.replace(true, joint_effects=())
    write_constraints(mounts_at_home(simulate_tilt_rows(plain, 30, seed=12), ur10), path)
    _calibrate(["ur10", "--data", str(path)], tmp_path / "out")
    run = CliRunner().invoke(app, ["validate", str(tmp_path / "out"), "--data", str(path)])
    assert run.exit_code == 0, run.output
    figures = _tilt_lines(run.output)
    assert len(figures) >= 10
    for after, before in figures.values():
        assert after < 0.0015 and after < before  # deg; σ 0.001°


def test_simulated_readings_take_the_effects_moments_about_the_robots_own_chain():
    """``simulate_tilt_rows(true, frames=own)``: the Katana's complete model (joint 5's frame
    0.147 m along its axis from the catalog's) with Table 5.2's effects reads as its catalog
    chain does, the same level sensors at the same configurations; without ``frames`` the
    effects' bending moments are taken about the moved frame and link 5 reads otherwise."""
    from robocal.measure.constraints.sim import level_mounts

    catalog = katana_robots().nominal
    assert catalog.joint_effects  # Table 5.2's joints
    complete = calibration_model(catalog, "position")
    assert complete.joint_effects

    def read(model, frames=None):
        data = simulate_tilt_rows(model, 40, sigma=1e-12, seed=3, mounts=level_mounts(model), frames=frames)
        return data.tilt_link, data.tilt  # the same seeded configurations and noise each time

    links, own = read(catalog)
    moved_links, moved = read(complete)
    fixed_links, fixed = read(complete, frames=catalog)
    assert np.array_equal(links, fixed_links) and np.array_equal(links, moved_links)
    np.testing.assert_allclose(fixed, own, atol=1e-12)
    assert np.abs(moved - own)[links == 4].max() > 1e-6  # rad: 0.0036° at most on link 5
