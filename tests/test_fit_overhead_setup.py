"""The fixed Python cost around the compiled fit (issue 35, the 100-pose calibration in
0.5 ms): the shortcuts taken where a calibration sets up and hands back its result give
what the general code gives.

* ``Model.with_free_values`` copies only the free steps and writes the copy's values from
  the model's: the same values as its steps, the fixed steps shared; ``Model.with_free``
  changes the model's free mask and names instead of working them out again: the same as
  its steps';
* a probe point's measured tool (Tx, Ty, Tz in any order, some not estimated) is taken in
  floats: the same numbers as ``J Σ Jᵀ`` of the general tool code, to the bit;
* the calibrated robot keeps the given model's free flags (level 1: every other parameter
  fixed in the fit, free again in the result), the steps the fit kept equal to the given
  model's;
* the robot and tool of a calibrated model, split once per model, are what
  :func:`~robocal.model.flange_tool.split_tool` gives, the tool read-only;
* the rank test's preference order, worked out once per robot and layout, is the one the
  problem's free parameters and roles give, and is left to be worked out again wherever
  the free parameters differ from the template's (a stated tool, joint effects, fixed ones);
* the diagnostics diagnose adds are those ``dataclasses.replace`` gives (an unknown field
  refused);
* the rank test's redundant parameters are the same :class:`Dropped` values as the
  dataclass builds.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

import robocal as rc
from robocal import spatial
from robocal.identify import diagnose as diagnose_module
from robocal.identify import measured_tool as mt
from robocal.identify import pipeline
from robocal.identify.options import CalibrationOptions
from robocal.identify.problem_setup import build_problem, without_measured_tool
from robocal.identify.stages import preference_columns
from robocal.measure.devices import LaserTracker
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.measure.true_model import draw_true_model
from robocal.model import rank
from robocal.model.flange_tool import split_tool
from robocal.model.rank import Dropped


@pytest.fixture(scope="module")
def ur10():
    """A UR10 and 60 simulated tracker poses of a perturbed one: (model, data)."""
    model = rc.calibration_model("ur10")
    true = draw_true_model(model, seed=11)
    frame = spatial.homogeneous(spatial.rotvec_to_matrix([0.2, 0.1, -0.8]), [1.8, 0.6, 0.2])
    device = LaserTracker(T_device_base=frame, p_tool_target=np.zeros(3), sigma=20e-6)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = np.random.default_rng(12).uniform(lim[:, 0], lim[:, 1], (60, model.dof))
    return model, simulate(VirtualRobot(model, true, device), q, seed=13)


def test_with_free_values_copies_the_free_steps_only(ur10):
    model, _ = ur10
    x = np.random.default_rng(1).normal(scale=0.01, size=len(model.free_names))
    moved = model.with_free_values(x)
    assert np.array_equal(moved.values, [s.value for s in moved.steps])
    assert np.array_equal(moved.free_values, x)
    assert not moved.values.flags.writeable
    for old, new in zip(model.steps, moved.steps, strict=True):
        assert (new is old) == (not old.free)
        assert (new.name, new.free, new.motion, new.role) == (old.name, old.free, old.motion, old.role)
    # the copy computes as a model built from its steps
    rebuilt = model.with_values(dict(zip(model.free_names, x.tolist(), strict=True)))
    q = np.zeros((1, model.dof))
    assert np.array_equal(moved.fk(q), rebuilt.fk(q))
    bad = x.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match=model.free_names[3]):
        model.with_free_values(bad)


@pytest.mark.parametrize("free", [False, True])
def test_with_free_keeps_mask_and_names_of_its_steps(ur10, free):
    model, _ = ur10
    rng = np.random.default_rng(2)
    current = model
    for _ in range(6):  # fix and free again, a few names at a time, in random order
        names = rng.choice(model.names, size=int(rng.integers(0, 6)), replace=False).tolist()
        current = current.with_free(names, free=free if rng.random() < 0.7 else not free)
        assert current.free_mask.tolist() == [s.free for s in current.steps]
        assert current.free_names == tuple(s.name for s in current.steps if s.free)
        assert not current.free_mask.flags.writeable
        assert np.array_equal(current.values, model.values)
    with pytest.raises(KeyError, match="no_such"):
        model.with_free(["no_such"])


def _general_tool(motions, values, cols, covariance):
    """The measured tool's point and covariance by the general code: ``J Σ Jᵀ`` over the
    estimated steps (a step not estimated adds nothing)."""
    p, J = mt._point_and_derivative(motions, values)
    estimated = [k for k, c in enumerate(cols) if c is not None]
    at = [c for c in cols if c is not None]
    Je = J[:, estimated]
    return p, Je @ covariance[np.ix_(at, at)] @ Je.T


@pytest.mark.parametrize("motions", list(itertools.permutations(["Tx", "Ty", "Tz"])))
def test_probe_point_equals_the_general_tool_code(motions):
    rng = np.random.default_rng(len(motions[0]) + ord(motions[0][1]))
    A = rng.normal(size=(8, 8))
    covariance = A @ A.T * 1e-8
    values = rng.normal(scale=0.1, size=3).tolist()
    for estimated in itertools.product([True, False], repeat=3):
        cols = [int(c) if e else None for e, c in zip(estimated, rng.permutation(8)[:3], strict=True)]
        point, cov = mt._probe_point(list(motions), values, cols, covariance)
        p, C = _general_tool(list(motions), values, cols, covariance)
        assert point == tuple(p.tolist())
        assert cov == tuple(tuple(row) for row in C.tolist())


def test_measured_tool_of_a_calibration_equals_the_general_code(ur10):
    model, data = ur10
    result = rc.calibrate(model, data, tool_guess=np.array([0.0, 0.0, 0.1]))
    tool = mt.measured_tool(result)
    steps = [s for s in result.model.steps if s.name.startswith("tcp_")]
    cols = [result.names.index(s.name) if s.name in result.names else None for s in steps]
    p, C = _general_tool([s.motion for s in steps], [s.value for s in steps], cols, result.covariance)
    assert tool.position_m == tuple(p.tolist())
    assert tool.covariance_m2 == tuple(tuple(row) for row in C.tolist())
    assert np.array_equal(tool.std_m, np.sqrt(np.diag(C)))


@pytest.mark.parametrize("level", [1, 2])
def test_calibrated_robot_keeps_the_given_free_flags(ur10, level):
    model, data = ur10
    result = rc.calibrate(model, data, level=level)
    robot = result.model.steps[: len(model.steps)]
    tool = result.model.steps[len(model.steps) :]
    assert [s.name for s in robot] == list(model.names)
    assert [s.free for s in robot] == [s.free for s in model.steps]
    assert tool and all(s.free for s in tool)
    # values: the calibrated measurement chain's, the device frame's steps left out
    chain = {s.name: s.value for s in result.measurement_chain.steps}
    assert [s.value for s in result.model.steps] == [chain[s.name] for s in result.model.steps]
    estimated = set(result.names)
    kept = [(s, g) for s, g in zip(robot, model.steps, strict=True) if s.name not in estimated]
    assert kept and all(s == g for s, g in kept)  # not fitted: the given model's steps as they were
    if level == 1:  # the fit held every non-joint parameter: all free in the result
        assert all(s.free for s in robot if s.joint is None and model.step(s.name).free)


def test_without_measured_tool_is_the_split_once_per_model(ur10):
    model, data = ur10
    calibrated = rc.calibrate(model, data).model
    for given in (model, calibrated, dataclasses.replace(calibrated, notes="a copy")):
        parts = split_tool(given)
        robot, tool = without_measured_tool(given)
        assert robot == parts.robot
        if parts.T_flange_tool is None:
            assert tool is None
        else:
            assert np.array_equal(tool, parts.T_flange_tool) and not tool.flags.writeable
        assert without_measured_tool(given)[0] is robot  # the same split, not worked out again


@pytest.mark.parametrize(
    ("keywords", "kept"),
    [({}, True), ({"tool": np.array([0.0, 0.0, 0.1])}, False), ({"level": 1}, True), ({"level": 3}, False)],
)
def test_preference_order_from_the_template(ur10, keywords, kept):
    model, data = ur10
    options = CalibrationOptions.from_keywords(None, **keywords)
    run = pipeline._check_inputs(model, data, "lm", options, None)
    problem = build_problem(run, None).problem
    assert (problem.preference is not None) == kept
    if kept:
        expected = preference_columns(problem.free_names, problem.chain.roles)
        assert np.array_equal(problem.preference, expected) and not problem.preference.flags.writeable
    assert problem.fix([problem.free_names[0]]).preference is None  # other unknowns: worked out again


def test_diagnostics_changed_as_dataclasses_replace(ur10):
    model, data = ur10
    before = rc.calibrate(model, data).diagnostics
    changes = {"outlier_poses": (3, 7), "fit_to_noise": before.fit_to_noise, "at_bounds": ("d1",)}
    changed = diagnose_module._with_changes(before, changes)
    expected = dataclasses.replace(before, **changes)
    assert changed == expected and hash(changed) == hash(expected) and repr(changed) == repr(expected)
    assert vars(before)["outlier_poses"] != (3, 7)  # the original is left as it was
    with pytest.raises(TypeError, match="no_such"):
        diagnose_module._with_changes(before, {"no_such": 1})


def test_redundant_parameters_are_dataclass_values(ur10):
    model, data = ur10
    result = rc.calibrate(model, data)
    redundant = [d for d in result.dropped if d.reason == "redundant"]
    assert redundant
    for d in redundant:
        built = Dropped(d.name, "redundant", d.absorbed_by, d.residual)
        assert d == built and hash(d) == hash(built) and repr(d) == repr(built)
        assert list(vars(d)) == list(vars(built))
    direct = rank._redundant("a", (("b", 0.5),), 0.25)
    assert direct == Dropped("a", "redundant", (("b", 0.5),), 0.25)


# ---------------------------------------------------------------------- session 15 (H18)
def test_fixed_step_copies_equal_a_fresh_copy(ur10):
    """A step fixed or freed is a checked copy with the flag asked (no cache: issue 32 keeps
    no identity-keyed caches of model parts)."""
    model, _ = ur10
    step = model.steps[3]
    assert step.free
    fixed = step._with_free(False)
    assert fixed == dataclasses.replace(step, free=False) and fixed is not step
    assert fixed._with_free(True) == step
    assert step._with_free(True) == step and fixed._with_free(False) == fixed


def test_fixing_the_same_steps_of_chains_sharing_a_mask(ur10):
    """Measurement chains of one template share its free mask: fixing the same steps of two
    of them gives each the flags its steps say, and a chain with other flags (same names)
    is not given the first one's."""
    model, data = ur10
    names = ["theta1", "d1", "a2"]
    first = model.with_values({"a2": 0.61})  # shares model's mask and names ("free" kept)
    a, b = model.fixed(names), first.fixed(names)
    for chain in (a, b):
        assert chain.free_mask.tolist() == [s.free for s in chain.steps]
        assert chain.free_names == tuple(s.name for s in chain.steps if s.free)
    assert a.step("a2").value != b.step("a2").value
    other = model.fixed(["alpha1"])  # another mask, same names: fixing theta1 etc. of it
    c = other.fixed(names)
    assert c.free_mask.tolist() == [s.free for s in c.steps]
    assert "alpha1" not in c.free_names and "alpha1" in a.free_names
    # a calibration fixes the same dropped steps twice: the same result both times
    r1 = rc.calibrate(model, data)
    r2 = rc.calibrate(model, data)
    assert r1.names == r2.names and np.array_equal(r1.estimates, r2.estimates)
    assert [s.free for s in r1.measurement_chain.steps] == [s.free for s in r2.measurement_chain.steps]


def test_measurement_chain_values_are_its_steps(ur10):
    model, data = ur10
    run = pipeline._check_inputs(model, data, "lm", CalibrationOptions.from_keywords(None), None)
    chain = build_problem(run, None).problem.chain
    assert np.array_equal(chain.values, [s.value for s in chain.steps])
    assert not chain.values.flags.writeable
    assert np.any(chain.values[:6] != 0)  # the device frame's start written in, not the template's zeros


def test_with_free_values_of_huge_finite_values(ur10):
    """Huge finite values are taken; a NaN or inf is refused by name, also next to +inf."""
    model, _ = ur10
    x = np.zeros(len(model.free_names))
    x[0] = 1e200
    assert model.with_free_values(x).values[model.free_mask][0] == 1e200
    x[5] = -np.inf
    with pytest.raises(ValueError, match=model.free_names[5]):
        model.with_free_values(x)
    x[0], x[5] = np.inf, -np.inf  # a sum of nan
    with pytest.raises(ValueError, match=model.free_names[0]):
        model.with_free_values(x)


def test_derived_copy_shares_only_what_is_asked(ur10):
    from robocal.model.chain_plan import derived_copy

    model, _ = ur10
    assert len(model.values) == len(model.names) and model.free_names  # worked out (cached) on the model
    copy = derived_copy(model, model.steps, ("names",), notes="changed")
    assert copy.notes == "changed" and copy.name == model.name and copy.steps is model.steps
    assert "names" in copy.__dict__ and "values" not in copy.__dict__ and "free_names" not in copy.__dict__
    assert copy == dataclasses.replace(model, notes="changed")


@pytest.mark.parametrize("frame", ["fit", "fixed"])
def test_calibrated_robot_flags_with_fixed_steps_and_any_device_frame(ur10, frame):
    """The robot's steps are found in the chain by the given model's first name, whatever
    the device frame adds before them (12 steps fitted, none for a fixed identity frame);
    steps the user fixed stay fixed, the others keep their flags, the tool's are free."""
    model, data = ur10
    given = model.fixed(["a2", "d4", "alpha3"])
    if frame == "fixed":  # the data in the robot's base frame: no device frame steps
        data = dataclasses.replace(data, position=rc.calibrate(model, data).robot.fk(data.q)[:, :3, 3])
    result = rc.calibrate(given, data, frame=frame)
    n_device = sum(s.role.value == "device" for s in result.measurement_chain.steps)
    assert n_device == (12 if frame == "fit" else 0)
    robot = result.model.steps[: len(given.steps)]
    assert [s.name for s in robot] == list(given.names)
    assert [s.free for s in robot] == [s.free for s in given.steps]
    assert all(s.free for s in result.model.steps[len(given.steps) :])
    for name in ("a2", "d4", "alpha3"):
        assert result.model.step(name) == given.step(name)  # not estimated: as given
