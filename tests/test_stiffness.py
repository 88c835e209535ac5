"""Joint stiffness identified from poses (seed 003), and joint effects kept physical.

Every joint whose load the poses vary enough has its stiffness recovered within 3σ (Katana
450 with the thesis' Table 5.2 joints; a UR10 with invented ones); a joint the poses do not
load is reported as not identified, with the reason; no identified clearance, backlash or
compliance is below zero; seed 003's two-stage method with joint parameters off by ±25 %.
"""

import dataclasses
import math

import numpy as np
import pytest

import robocal as rc
from robocal import spatial
from robocal.experiments.seed003_setup import katana_setup
from robocal.identify.effects import EFFECT_SIGNIFICANCE, effect_verdict
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses
from robocal.model.dynamics import Payload
from robocal.model.files import STIFFNESS_SCALE
from robocal.model.joints import JointTilting
from robocal.model.steps import JointEffects

pytest.importorskip("pinocchio")

D = math.pi / 180
KGFM = STIFFNESS_SCALE["kgf*m/deg"]  # N·m/rad per kgf·m/deg
ATTR = {"clearance": "clearance_tilt", "backlash": "backlash", "compliance": "compliance"}
CMM = dict(frame="fixed", tool=None, measure="position")


def estimates(result) -> dict[str, tuple[float, float]]:
    rows = zip(result.names, result.estimates, result.std, strict=True)
    return {n: (float(v), float(s)) for n, v, s in rows}


def truth_of(model) -> dict[str, float]:
    return {f"{k}_{e.joint}": getattr(e, a) for e in model.joint_effects for k, a in ATTR.items()}


def assert_physical(result) -> None:
    """Every identified joint effect is at least 3σ above zero; the model carries no negative one."""
    for name, (v, s) in estimates(result).items():
        if name.startswith(tuple(f"{k}_" for k in ATTR)):
            assert v >= EFFECT_SIGNIFICANCE * s > 0, (name, v, s)
    for e in result.model.joint_effects:
        assert min(e.clearance_tilt, e.backlash, e.compliance) >= 0, e
    text = result.summary()
    assert "compliance -" not in text and "stiffness -" not in text


def assert_stiffness_within_3_sigma(result, true_model, joints) -> list[float]:
    """The true stiffness k = 1/c of each of ``joints`` lies in the estimate's 3σ interval
    [1/(ĉ + 3σ), 1/(ĉ − 3σ)] (skewed: the symmetric k̂ ± 3σ_c/ĉ² misses a true value 3.3σ_k
    below an estimate whose compliance is 2.6σ too high).  Returns the compliances' z."""
    est, truth = estimates(result), truth_of(true_model)
    z = []
    for joint in joints:
        c, s = est[f"compliance_{joint}"]
        k_true = 1 / truth[f"compliance_{joint}"] / KGFM
        low, high = 1 / (c + 3 * s) / KGFM, 1 / (c - 3 * s) / KGFM
        assert 3 * s < c and low < k_true < high, (joint, 1 / c / KGFM, low, high, k_true)
        z.append((c - truth[f"compliance_{joint}"]) / s)
    return z


def dropped(result) -> dict[str, object]:
    return {d.name: d for d in result.dropped}


# ------------------------------------------------------------------ the decision rule
def test_effect_verdict_rejects_negative_and_undetermined_values():
    assert effect_verdict("compliance_q2", 20e-6, 1e-6) is None
    below = effect_verdict("compliance_wrist_2", -10.9e-6, 93e-6)
    assert below.reason == "unphysical" and "-10.9 ± 93 µrad/(N·m)" in str(below)
    assert "not physical" in str(below)
    weak = effect_verdict("compliance_q5", 57.5e-6, 23e-6, peak_load=0.518)
    assert weak.reason == "undetermined" and "within 3σ of zero" in weak.detail and "0.518 N·m" in weak.detail
    assert effect_verdict("backlash_q2", 2.9 * D, 1.0 * D).reason == "undetermined"
    assert effect_verdict("backlash_q2", float("nan"), 1.0).reason == "undetermined"
    learned = effect_verdict(
        "compliance_wrist_1", 1.789e-3, 1.19e-3, confounder="the learned joint angle errors"
    )
    assert "with the learned joint angle errors gave 1.79e+03 ± 1.2e+03 µrad/(N·m)" in learned.detail
    assert "kept at its start value 0 µrad/(N·m)" in learned.detail


# ------------------------------------------------------------------ Katana 450 (seed 003)
@pytest.fixture(scope="module")
def katana():
    return katana_setup(n_test=300)


def katana_data(setup, q, seed, payload=None):
    robot = VirtualRobot(setup.nominal, setup.true, setup.device, JointTilting(payload=payload))
    return simulate(robot, q, seed=seed)


def katana_with_payload(setup, seeds) -> list[float]:
    """300 poses over the workspace with a 0.5 kg payload (the Katana's rated load) 0.15 m
    off the wrist axis, so that q5 carries up to 1.9 N·m: q2-q5 within 3σ, σ a few per cent
    (q2, q3) to a sixth (q5) of the value; q1, vertical, carries no torque."""
    payload = Payload(0.5, (0.15, 0.0, 0.05))
    z = []
    for seed in seeds:
        data = katana_data(setup, setup.test_q, seed, payload)
        result = rc.calibrate(setup.geometric, data, level=3, payload=payload, **CMM)
        z += assert_stiffness_within_3_sigma(result, setup.true, ["q2", "q3", "q4", "q5"])
        assert_physical(result)
        assert dropped(result)["compliance_q1"].reason == "no effect"
        est, truth = estimates(result), truth_of(setup.true)
        assert est["compliance_q2"][1] < 0.03 * truth["compliance_q2"]
        assert est["compliance_q5"][1] < 0.2 * truth["compliance_q5"]
    return z


def test_katana_stiffness_of_every_loaded_joint_within_3_sigma(katana):
    katana_with_payload(katana, [1])


@pytest.mark.slow
def test_katana_stiffness_sigma_is_calibrated(katana):
    """Over eight noise draws the compliances' errors are as large as their σ say."""
    z = katana_with_payload(katana, range(1, 9))
    assert 0.6 < np.sqrt(np.mean(np.square(z))) < 1.4 and abs(np.mean(z)) < 0.6


def test_katana_without_payload_reports_q5_stiffness_not_identified(katana):
    """Seed 003's set-up as the thesis has it: q5 carries at most 0.52 N·m, so its
    compliance (σ 23 µrad/N·m for a true 22) was shown as a stiffness of 31 ± 12 kgf·m/deg
    against a true 80; now it is reported as not identified, with the load."""
    data = katana_data(katana, katana.train_q, 1)
    result = rc.calibrate(katana.geometric, data, level=3, **CMM)
    assert_stiffness_within_3_sigma(result, katana.true, ["q2", "q3", "q4"])
    assert_physical(result)
    q5 = dropped(result)["compliance_q5"]
    assert q5.reason == "undetermined" and "load reaches 0.518 N·m" in q5.detail
    text = result.summary()
    assert "not identified:\n" in text and "compliance_q5: the fit gave" in text
    q5_line = next(line for line in text.splitlines() if "q5: clearance_tilt" in line)
    assert "compliance" not in q5_line and "stiffness" not in q5_line
    # the prediction keeps q5's backlash and clearance, which the poses do determine
    assert {"backlash_q5", "clearance_q5"} <= set(result.names)


def test_two_stage_method_with_joint_parameters_off_by_25_percent(katana):
    """Seed 003's two-stage method given Table 5.2 while the robot's joints differ by up to
    ±25 % (uniform, every clearance, backlash and stiffness): still several times better
    than the geometric calibration, but the error of the joint parameters remains (and the
    residuals say so); identifying the joint effects, starting from Table 5.2, recovers the
    robot's own (within 3σ) and the noise."""
    rng = np.random.default_rng(3)
    off = tuple(
        dataclasses.replace(e, **{a: getattr(e, a) * rng.uniform(0.75, 1.25) for a in ATTR.values()})
        for e in katana.nominal.joint_effects
    )
    setup = dataclasses.replace(katana, true=dataclasses.replace(katana.true, joint_effects=off))
    truth, given = truth_of(setup.true), truth_of(setup.nominal)
    ratio = [abs(truth[k] / given[k] - 1) for k in truth if given[k]]
    assert 0.2 < max(ratio) <= 0.25
    train, test = (katana_data(setup, q, seed) for q, seed in ((setup.train_q, 1), (setup.test_q, 2)))

    def held_out(result) -> float:
        return float(np.linalg.norm(result.predict(test.q)[:, :3, 3] - test.position, axis=1).mean())

    conventional = rc.calibrate(setup.geometric, train, level=2, **CMM)
    exact = dataclasses.replace(setup.nominal, joint_effects=setup.true.joint_effects)
    two_stage_exact = rc.calibrate(exact, train, effects="predict", **CMM)
    two_stage = rc.calibrate(setup.nominal, train, effects="predict", **CMM)
    identified = rc.calibrate(setup.nominal, train, level=3, **CMM)
    e = {k: held_out(r) for k, r in [("conv", conventional), ("exact", two_stage_exact), ("two", two_stage)]}
    e["identified"] = held_out(identified)
    assert e["two"] < 0.2 * e["conv"]  # measured: 0.08 against 0.50 mm
    assert e["exact"] < 0.02e-3 and e["identified"] < 0.02e-3  # the 0.01 mm CMM noise
    assert e["two"] > 3 * e["exact"]
    assert any("times the stated measurement noise" in w or "x the stated measurement noise" in w
               for w in two_stage.metadata["warnings"])  # fmt: skip
    assert two_stage.model.joint_effects == setup.nominal.joint_effects  # predicted, not changed
    assert_stiffness_within_3_sigma(identified, setup.true, ["q2", "q3", "q4"])
    assert_physical(identified)


# ------------------------------------------------------------------ UR10
UR10_COMPLIANCE = {  # rad/(N·m): invented, of the size the real UR10's shoulder and elbow show
    "shoulder_pan": 6e-6,
    "shoulder_lift": 7e-6,
    "elbow": 12e-6,
    "wrist_1": 40e-6,
    "wrist_2": 40e-6,
    "wrist_3": 40e-6,
}
TARGET = np.array([0.08, 0.0, 0.11])  # off the wrist_3 axis: its turn moves the target
TRACKER = spatial.homogeneous(spatial.rotvec_to_matrix([0.1, -0.05, 2.0]), [2.5, -1.0, 0.3])


def ur10_twin(effects, gravity, payload, seed, n=200):
    nominal = rc.calibration_model("ur10", "position")
    model = dataclasses.replace(nominal, joint_effects=effects)
    true = draw_true_model(model, length=0.5e-3, angle=0.05 * D, seed=3)
    device = LaserTracker(T_device_base=TRACKER, p_tool_target=TARGET, sigma=20e-6)
    robot = VirtualRobot(model, true, device, JointTilting(payload=payload, gravity=tuple(gravity)))
    data = simulate(robot, random_poses(model, n, seed=10 + seed), seed=20 + seed)
    return dataclasses.replace(model, joint_effects=()), true, data


def test_ur10_stiffness_of_every_joint_within_3_sigma():
    """A UR10 mounted 30° off the vertical (so the first joint carries torque) with its
    rated 10 kg payload off the wrist axes: the clearance, backlash and stiffness of all
    six joints identified together, each within 3σ."""
    effects = tuple(
        JointEffects(j, clearance_tilt=0.005 * D, backlash=0.01 * D, compliance=c)
        for j, c in UR10_COMPLIANCE.items()
    )
    gravity = 9.81 * np.array([math.sin(30 * D), 0.0, -math.cos(30 * D)])
    payload = Payload(10.0, (0.0, 0.08, 0.08))
    z = []
    for seed in (0, 1):
        geometric, true, data = ur10_twin(effects, gravity, payload, seed)
        result = rc.calibrate(geometric, data, tool_guess=TARGET, level=3, payload=payload, gravity=gravity)
        assert_stiffness_within_3_sigma(result, true, list(UR10_COMPLIANCE))
        assert_physical(result)
        est, truth = estimates(result), truth_of(true)
        others = [n for n in est if n.startswith(("clearance_", "backlash_"))]
        assert len(others) >= 11
        z += [(est[n][0] - truth[n]) / est[n][1] for n in others]
    # clearance and backlash: one of 24 at 3.2σ (the first joint's backlash, second draw)
    assert np.abs(z).max() < 3.5 and 0.5 < np.sqrt(np.mean(np.square(z))) < 1.5


def test_ur10_on_the_floor_reports_the_joints_gravity_does_not_load():
    """Floor-mounted, no payload: the vertical first joint and the last (its axis through
    the wrist's centre of mass) carry no gravity torque; wrist_2 at most 0.6 N·m — not
    identified (with the reason) or within 3σ; the others within 3σ."""
    effects = tuple(JointEffects(j, compliance=c) for j, c in UR10_COMPLIANCE.items())
    geometric, true, data = ur10_twin(effects, (0.0, 0.0, -9.81), None, 0)
    result = rc.calibrate(geometric, data, tool_guess=TARGET, level=3, effects=["compliance"])
    assert_stiffness_within_3_sigma(result, true, ["shoulder_lift", "elbow", "wrist_1"])
    assert_physical(result)
    why = dropped(result)
    assert why["compliance_shoulder_pan"].reason == why["compliance_wrist_3"].reason == "no effect"
    # wrist_2 (at most 0.6 N·m) sits at the edge of what 200 poses can tell: either held
    # as undetermined with the reason, or identified within 3σ of the truth (this draw:
    # 8.3 ± 2.7 µrad/N·m against 4, since the target sits on the flange's +x as built)
    wrist_2 = why.get("compliance_wrist_2")
    if wrist_2 is not None:
        assert wrist_2.reason == "undetermined" and "N·m at these poses" in wrist_2.detail
    else:
        assert_stiffness_within_3_sigma(result, true, ["wrist_2"])


def test_effects_that_are_zero_are_never_identified_below_zero():
    """Joints without backlash (the true values sit on the bound): over two noise draws
    none is identified — each is below zero or within 3σ of it, held at zero."""
    effects = tuple(JointEffects(j, compliance=c) for j, c in UR10_COMPLIANCE.items())
    gravity = 9.81 * np.array([math.sin(30 * D), 0.0, -math.cos(30 * D)])
    reasons = []
    for seed in range(2):
        geometric, _, data = ur10_twin(effects, gravity, None, seed, n=100)
        result = rc.calibrate(
            geometric, data, tool_guess=TARGET, level=3, gravity=gravity, effects=["backlash", "compliance"]
        )
        assert_physical(result)
        assert not any(n.startswith("backlash_") for n in result.names)
        why = dropped(result)
        reasons += [why[f"backlash_{j}"].reason for j in UR10_COMPLIANCE]
    assert set(reasons) == {"unphysical", "undetermined", "no effect"}  # wrist_3: no torque


def test_every_method_keeps_joint_effects_physical(katana):
    """Seed 001's bounded method and the pseudo-inverse apply the same rule (the Katana's
    compliances from its 118 poses)."""
    data = katana_data(katana, katana.train_q, 1)
    for method in ("bounded", "pinv"):
        result = rc.calibrate(katana.geometric, data, method, level=3, effects=["compliance"], **CMM)
        assert_physical(result)
        assert any(d.reason in ("unphysical", "undetermined") for d in result.dropped)
        if method == "bounded":
            assert len(result.metadata["at_bounds"]) < len(result.names)


def test_learned_residual_stage_holds_the_effects_it_confounds(monkeypatch):
    """With a learned residual the joint uncertainty of both can leave a compliance within
    3σ of zero (the real UR10's wrists: -136 ± 400 µrad/N·m): it is held at zero, the
    physics refitted, and the reason names the learned angle errors.  Here the joint
    uncertainty is inflated 50x for wrist_1 to force the case."""
    import robocal.identify.residual.stage as stage

    joint_uncertainty = stage._joint_uncertainty

    def inflated(result, q):
        result = joint_uncertainty(result, q)
        f = np.where(np.array(result.names) == "compliance_wrist_1", 50.0, 1.0)
        return dataclasses.replace(result, std=f * result.std, covariance=np.outer(f, f) * result.covariance)

    monkeypatch.setattr(stage, "_joint_uncertainty", inflated)
    effects = tuple(JointEffects(j, compliance=c) for j, c in UR10_COMPLIANCE.items())
    geometric, true, data = ur10_twin(effects, (0.0, 0.0, -9.81), None, 0, n=40)
    result = rc.calibrate(
        geometric,
        data,
        tool_guess=TARGET,
        compliance=True,
        residual="joint_fourier",
        residual_harmonics=1,
        cv_folds=2,
    )
    assert result.model.residual is not None
    held = dropped(result)["compliance_wrist_1"]
    assert held.reason == "undetermined" and "with the learned joint angle errors" in held.detail
    assert "compliance_wrist_1" not in result.names and "compliance_elbow" in result.names
    assert_physical(result)
    assert_stiffness_within_3_sigma(result, true, ["shoulder_lift", "elbow"])
