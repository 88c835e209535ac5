"""Issue 33: the prior toward the nominal geometry (MAP fit) of constraint calibrations, and
the real Panda's ball-in-socket recordings calibrated through the command line."""

from __future__ import annotations

import dataclasses
import json
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal.identify.constraints.figures import pooled_spread
from robocal.identify.constraints.fit import (
    build_constraint_problem,
    calibrate_constraints,
    constraint_figures,
)
from robocal.identify.constraints.model import NominalPrior
from robocal.identify.options import Pruning
from robocal.measure.constraints.data import write_constraints
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.measure.constraints.sim import simulate_constraints
from robocal.measure.true_model import draw_true_model

BASE = {"base_x", "base_y", "base_rx", "base_ry", "theta1", "d1"}  # the complete model's base frame
PANDA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ball_in_socket"
PLACEMENTS = ("front", "right", "back-high")
needs_panda = pytest.mark.skipif(not PANDA.is_dir(), reason="the ball-in-socket recordings are not here")


@pytest.fixture(scope="module")
def ur10():
    return rc.calibration_model("ur10")


@pytest.fixture(scope="module")
def sockets(ur10):
    """60 configurations at 2 sockets of a UR10 with drawn errors (0.1 mm noise), the truth."""
    true = draw_true_model(ur10, seed=4)
    data, truth = simulate_constraints(true, "point", 60, sigma=1e-4, count=2, seed=4)
    pairs = dict(
        point_pairs=[[0, 1]], point_length=[float(np.linalg.norm(truth.points[0] - truth.points[1]))]
    )
    return dataclasses.replace(data, **pairs), true


def _robot(result, model) -> dict[str, float]:
    return {n: v for n, v in zip(result.names, result.estimates, strict=True) if n in model.names}


# ---------------------------------------------------------------------- the prior rows
def test_prior_rows_have_an_exact_jacobian_and_spare_the_tool(ur10, sockets):
    data, _ = sockets
    problem = build_constraint_problem(ur10, data, prior=NominalPrior())
    tool = sum(n.startswith("tool_") for n in problem.chain.free_names)
    assert problem.n_prior_rows == len(problem.chain.free_names) - tool  # the ball's offset has none
    x = problem.x0 + np.random.default_rng(1).normal(scale=1e-4, size=len(problem.x0))
    J = problem.jacobian(x)
    numeric = np.empty_like(J)
    for k in range(len(x)):
        step = np.zeros(len(x))
        step[k] = 1e-7
        numeric[:, k] = (problem.residual(x + step) - problem.residual(x - step)) / 2e-7
    prior = slice(len(J) - problem.n_prior_rows, None)
    assert np.allclose(J[prior], numeric[prior], atol=1e-6)
    assert len(problem.measurement_residual(x)) == len(J) - problem.n_prior_rows


def test_prior_keeps_what_the_measurements_cannot_see_unidentified(ur10, sockets):
    data, _ = sockets
    plain = calibrate_constraints(ur10, data, known_noise=True)
    prior = calibrate_constraints(ur10, data, known_noise=True, prior=NominalPrior())
    unseen = {d.name for d in prior.dropped if d.reason in ("redundant", "no effect")}
    assert unseen >= BASE  # a prior does not make the base frame visible to fixed points
    assert unseen == {d.name for d in plain.dropped if d.reason in ("redundant", "no effect")}
    assert prior.prior == NominalPrior() and any("prior" in line for line in prior.summary_lines())


def test_prior_limits_are_least_squares_and_nominal(ur10, sockets):
    data, _ = sockets
    plain = _robot(calibrate_constraints(ur10, data, known_noise=True), ur10)
    loose = _robot(calibrate_constraints(ur10, data, known_noise=True, prior=NominalPrior(10.0, 10.0)), ur10)
    tight = calibrate_constraints(ur10, data, known_noise=True, prior=NominalPrior(1e-9, 1e-9))
    nominal = dict(zip(ur10.names, ur10.values, strict=True))
    assert max(abs(loose[n] - plain[n]) for n in plain) < 1e-7
    held = {n: v for n, v in _robot(tight, ur10).items() if not n.startswith("tool_")}
    assert held and max(abs(v - nominal[n]) for n, v in held.items()) < 1e-7
    assert tight.success


def test_prior_shrinks_toward_nominal_and_ignores_the_stated_noise(ur10, sockets):
    data, _ = sockets
    nominal = dict(zip(ur10.names, ur10.values, strict=True))
    plain = _robot(calibrate_constraints(ur10, data), ur10)
    prior = NominalPrior(0.2e-3, 2e-3)
    shrunk = _robot(calibrate_constraints(ur10, data, prior=prior), ur10)
    sigma = {s.name: prior.angle_std if s.is_rotation else prior.length_std for s in ur10.steps}
    kinematic = [n for n in plain if not n.startswith("tool_")]
    distance = [
        np.linalg.norm([(fit[n] - nominal[n]) / sigma[n] for n in kinematic]) for fit in (plain, shrunk)
    ]
    assert distance[1] < 0.9 * distance[0]  # MAP: nearer the nominal geometry in the prior's metric
    # the measurements are weighted by sigma-hat, not the stated sigma: a stated noise ten
    # times too large gives the same fit
    stated = _robot(calibrate_constraints(ur10, dataclasses.replace(data, sigma=1e-3), prior=prior), ur10)
    assert max(abs(stated[n] - shrunk[n]) for n in shrunk) < 1e-8


def test_prior_must_be_positive():
    with pytest.raises(ValueError, match="> 0"):
        NominalPrior(0.0, 1e-3)


# ---------------------------------------------------------------------- the real Panda
def _panda():
    from robocal.model.urdf.read import URDFError, model_from_urdf

    urdf = PANDA / "urdf" / "panda.urdf"
    try:
        return model_from_urdf(urdf, measure="position", tip="ball_link")
    except URDFError:  # the finger's <mimic>, off the chain to the ball
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "panda.urdf"
            path.write_text(re.sub(r"<mimic[^>]*/>", "", urdf.read_text()))
            return model_from_urdf(path, measure="position", tip="ball_link")


def _placement(name: str) -> ConstraintSet:
    q = [np.loadtxt(PANDA / "panda_1" / name / f"hole_{k}.csv", delimiter=",") for k in (0, 1)]
    label = np.repeat([0, 1], [len(q[0]), len(q[1])])
    return ConstraintSet(np.vstack(q), label, -np.ones(len(label), dtype=int), point_pairs=[[0, 1]],
                         point_length=[0.05], sigma=1e-4)  # fmt: skip


def _spread_mm(model, data: ConstraintSet) -> float:
    return pooled_spread(constraint_figures(model, data), data) * 1e3


@needs_panda
def test_panda_calibrated_through_the_cli_uses_the_prior(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli.app import app
    from robocal.model.files import load_model, save_model

    model = _panda()
    save_model(model, tmp_path / "panda.yaml")
    front = _placement("front")
    write_constraints(front, tmp_path / "front.csv")
    out = tmp_path / "cal"
    args = ["calibrate", str(tmp_path / "panda.yaml"), "--data", str(tmp_path / "front.csv")]
    run = CliRunner().invoke(app, [*args, "--distance", "0,1=50mm", "-o", str(out)])
    assert run.exit_code == 0, run.output
    doc = json.loads((out / "constraints.json").read_text())
    assert doc["prior"] == {"length_std_m": 0.3e-3, "angle_std_rad": 5e-3}
    calibrated = load_model(out / "model.yaml")
    same = calibrate_constraints(model, front, pruning=Pruning(), prior=NominalPrior())
    for held_out in ("right", "back-high"):
        data = _placement(held_out)
        nominal, cli = _spread_mm(model, data), _spread_mm(calibrated, data)
        assert nominal > 8.0  # the nominal URDF: 8-11 mm
        assert cli < 1.2  # bench_ball_in_socket.py: 0.47 and 1.05 mm
        assert cli == pytest.approx(_spread_mm(same.model, data), abs=1e-3)


@needs_panda
def test_panda_leave_one_placement_out_prefers_the_prior():
    """The CV that chose the CLI's default, and why 0.2 mm is out of reach on these data."""
    model, sets = _panda(), {name: _placement(name) for name in PLACEMENTS}
    held: dict[str, list[float]] = {"ls": [], "prior": []}
    for train in PLACEMENTS:
        for how, prior in (("ls", None), ("prior", NominalPrior())):
            result = calibrate_constraints(model, sets[train], pruning=Pruning(), prior=prior)
            assert _spread_mm(result.model, sets[train]) > 0.2  # the in-sample floor: 0.25-0.36 mm
            held[how] += [_spread_mm(result.model, sets[t]) for t in PLACEMENTS if t != train]
    assert np.mean(held["prior"]) < np.mean(held["ls"])  # 0.94 against 1.04 mm
    assert max(held["prior"]) < max(held["ls"])  # worst 1.31 against 1.67 mm


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q"]))
