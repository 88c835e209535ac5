"""Parameterisation singularities of seed 000 eqs. 1-10 found numerically."""

import math

import pytest

import robocal as rc
from robocal.model.conventions import dh, frame6, hayati, model_from_steps, tool_point, veitschegger
from robocal.model.singularity import check_model


def link(check, index):
    return next(lk for lk in check.links if lk.index == index)


@pytest.mark.parametrize("name", ["irb2400", "ur10", "puma560"])
def test_plain_dh_with_parallel_axes_is_flagged(name):
    """Seed 000 eq. 6: DH is singular for parallel revolute axes."""
    check = check_model(rc.robot(name))
    assert not check.ok
    assert link(check, 2).verdict == "singular" and link(check, 2).rank == 3
    assert check.identification_rank < check.identification_columns
    assert not next(c for c in check.continuity if c.joint == rc.robot(name).joint_names[2]).continuous


def test_frame6_is_singular_at_beta_90_degrees():
    """Seed 000 eqs. 1-2: Tx Ty Tz Rz Ry Rx loses rank at β = ±90°."""
    good = model_from_steps("f", frame6("tool", 0.1, 0, 0.1, 0.2, 0.4, 0.1))
    bad = model_from_steps("f", frame6("tool", 0.1, 0, 0.1, 0.2, math.pi / 2, 0.1))
    assert link(check_model(good), 0).verdict == "ok"
    tool = link(check_model(bad), 0)
    assert tool.verdict == "singular" and tool.needed == 6 and tool.rank == 5


def test_hayati_is_singular_for_perpendicular_axes():
    """Seed 000 eq. 8: Hayati fails when the distal z lies in the proximal x-y plane."""
    parallel = model_from_steps("h", hayati(1, a=0.4), hayati(2, a=0.3), tool_point(0.1, 0, 0))
    perpendicular = model_from_steps(
        "h", hayati(1, a=0.4, alpha=math.pi / 2), hayati(2, a=0.3), tool_point(0.1, 0, 0)
    )
    assert link(check_model(parallel, "position"), 1).verdict == "ok"
    assert link(check_model(perpendicular, "position"), 1).verdict == "singular"


def test_veitschegger_is_singular_for_perpendicular_intersecting_axes():
    """Seed 000 eq. 10: perpendicular z axes that intersect (a = 0, β = 90°) are singular.

    Its five parameters are one more than a line needs (not minimal), so with the origin
    on the proximal z axis alone (a = 0) the next axis can still be placed anywhere nearby.
    """

    def model(a, beta):
        steps = veitschegger(1, d=0.1, a=a, alpha=0.3, beta=beta)
        return model_from_steps("v", steps, dh(2, a=0.2), tool_point(0.1, 0, 0))

    assert link(check_model(model(0.3, 0.2), "position"), 1).verdict == "ok"
    assert link(check_model(model(0.0, 0.2), "position"), 1).verdict == "ok"
    assert link(check_model(model(0.0, math.pi / 2), "position"), 1).verdict == "singular"


def test_near_singular_links_are_reported():
    """A DH link between axes 0.1° apart is not singular yet, but nearly so."""
    model = model_from_steps(
        "n", dh(1, d=0.2, alpha=math.pi / 2), dh(2, a=0.5, alpha=math.radians(0.1)), dh(3, a=0.4)
    )
    assert link(check_model(model, "position"), 2).verdict == "near-singular"
