"""The report's content, computed once: :func:`collect_report` turns a calibration result,
its measurements and an evaluation into a frozen :class:`ReportData`.

Every number the report shows is computed here (validation statistics, observability,
ISO 9283 characteristics, the seeds' tables, joint-effect displacements); the renderers
only format.  The result's own data is read through
:func:`~robocal.evaluate.report.facts.report_data_from_result` alone.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from robocal.evaluate.error_tables import PoseErrors, error_table, improvement, pose_errors
from robocal.evaluate.report.data import (
    ComplianceRow,
    CoverageData,
    EffectsData,
    IdentifiabilityData,
    ParameterRow,
    PoseSet,
    ReportData,
    ReportOptions,
    ResidualsData,
    ResultFacts,
    ValidationData,
)
from robocal.evaluate.report.facts import report_data_from_result, start_chain_of, start_validation
from robocal.evaluate.report.markup import AFTER, GEOMETRIC
from robocal.identify.effects import COMPLIANCE_PREFIX
from robocal.identify.result import CalibrationResult
from robocal.identify.validate import ValidationStats, validate
from robocal.measure.measurements import Measurements
from robocal.model.joints import effect_of
from robocal.model.steps import Role

__all__ = ["collect_report"]

Array = np.ndarray

#: why a parameter was not identified, as the report words it
DROP_REASONS = {
    "redundant": "redundant",
    "no effect": "no effect on the measurements",
    "poorly identifiable": "poorly identifiable",
    "unphysical": "outside its physical range (≥ 0)",
    "undetermined": "not told from zero by the data",
}
#: the observability indices' meanings, in the order of ``Observability.as_dict()``
INDEX_MEANINGS = (
    "D-optimal, geometric mean of σ / √n",
    "inverse condition number",
    "smallest singular value",
    "noise amplification σ²min/σmax",
    "A-optimal",
)


def _check_dof(facts: ResultFacts, data: Measurements | None, test_data: Measurements | None) -> None:
    for name, d in (("calibration data", data), ("held-out data", test_data)):
        if d is not None and d.dof != facts.model.dof:
            raise ValueError(
                f"{name} has {d.dof} joint columns but model {facts.model.name!r} "
                f"has {facts.model.dof} joints"
            )


#: m: a device frame farther from the base than this is a corrupted or hand-edited result
_FARTHEST_DEVICE = 1e6


def _check_result(result: CalibrationResult) -> None:
    """Refuse (ValueError naming the entry of result.json) a result whose device frame is no
    rigid transform or whose estimates are not finite: every number of the report would be
    NaN, inf or an overflow."""
    T = np.asarray(result.T_device_base, dtype=float)
    where = "result.json frame.T_device_base"
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{where}: the device frame must be a 4x4 matrix of finite numbers")
    R, t = T[:3, :3], T[:3, 3]
    rigid = np.max(np.abs(R)) <= 1 + 1e-6 and np.allclose(R.T @ R, np.eye(3), atol=1e-6)  # no overflow
    if not rigid or not np.allclose(T[3], [0, 0, 0, 1]):
        raise ValueError(f"{where}: the device frame is not a rigid transform (rotation and last row)")
    if np.max(np.abs(t)) > _FARTHEST_DEVICE:
        raise ValueError(f"{where}: the device lies {np.max(np.abs(t)):.3g} m from the base (at most 1e6 m)")
    bad = np.flatnonzero(~np.isfinite(np.asarray(result.estimates, dtype=float)))
    if bad.size:
        name = result.names[int(bad[0])]
        raise ValueError(f"result.json parameters: the estimate of {name!r} is not finite")


def _pose_set(facts: ResultFacts, name: str, data: Measurements, colour: str) -> PoseSet:
    model = facts.model
    revolute = np.array(model.joint_types) == "revolute"
    sigma = None if data.sigma is None else float(np.median(data.sigma)) * 1e3
    device = data.metadata.get("device") if isinstance(data.metadata, Mapping) else None
    positions = model.fk(data.q)[:, :3, 3] * 1e3
    return PoseSet(
        name=name,
        colour=colour,
        n=data.n,
        observes=str(data.observes),
        position_base_mm=positions,
        extent_mm=np.ptp(positions, axis=0),
        joint_display=np.where(revolute, np.degrees(data.q), data.q * 1e3),
        median_sigma_mm=sigma,
        device=None if device is None else str(device),
    )


def _cube_edges(center: Array, side: float) -> Array:
    from robocal.measure.cube import CUBE_CORNERS

    c = np.asarray(center, dtype=float) + side * (CUBE_CORNERS - 0.5)
    edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
    pts: list[Any] = []
    for a, b in edges:
        pts += [c[a], c[b], [np.nan] * 3]
    return np.array(pts)


def _coverage(
    facts: ResultFacts, data: Measurements | None, test_data: Measurements | None, ev: Mapping[str, Any]
) -> CoverageData | None:
    named = (("calibration poses", data, AFTER), ("held-out poses", test_data, GEOMETRIC))
    sets = tuple(_pose_set(facts, n, d, c) for n, d, c in named if d is not None)
    if not sets:
        return None
    model = facts.model
    revolute = np.array(model.joint_types) == "revolute"
    limits = np.where(revolute[:, None], np.degrees(model.joint_limits), model.joint_limits * 1e3)
    iso = ev.get("iso_poses") or {}
    cube = iso.get("cube")
    return CoverageData(
        sets=sets,
        joint_names=tuple(model.joint_names),
        limits_display=limits,
        cube_edges_mm=_cube_edges(cube["center"], float(cube["side"])) * 1e3 if cube else None,
        iso_points_mm=np.asarray(iso["commanded"], dtype=float) * 1e3 if iso else None,
        iso_labels=tuple(str(x) for x in iso.get("labels", ())),
        paths_mm=tuple(
            (str(p["name"]), np.asarray(p["commanded"], dtype=float) * 1e3) for p in ev.get("paths", [])
        ),
    )


def _observability(facts: ResultFacts, data: Measurements | None) -> tuple[dict[str, float], Array] | None:
    from robocal.identify.observability_indices import observability, scaled_jacobian, singular_values

    chain = facts.measurement_chain
    if data is None or chain is None or not chain.free_names or data.dof != facts.model.dof:
        return None
    rows: Literal["position", "pose"] = "pose" if facts.measure == "pose" else "position"
    idx = observability(chain, data.q, rows=rows, scale="tolerance").as_dict()
    Js, _, _ = scaled_jacobian(chain, data.q, rows=rows, scale="norm")
    return idx, singular_values(Js)


def _dropped_row(d: Any) -> tuple[str, str, str]:
    detail = ", ".join(f"{n} ({c:+.3g})" for n, c in d.absorbed_by) if d.absorbed_by else ""
    if d.sigma is not None:
        detail = f"σ {d.sigma * 1e3:.3g} mm as tool displacement; kept at its start value"
    detail = getattr(d, "detail", "") or detail
    return str(d.name), DROP_REASONS.get(d.reason, str(d.reason)), detail


def _identifiability(facts: ResultFacts, data: Measurements | None) -> IdentifiabilityData:
    obs = _observability(facts, data)
    indices: tuple[tuple[str, float], ...] = ()
    if obs is not None:
        indices = tuple(
            (f"{k} ({desc})", float(v)) for (k, v), desc in zip(obs[0].items(), INDEX_MEANINGS, strict=True)
        )
    return IdentifiabilityData(
        indices=indices,
        singular_values=None if obs is None else np.asarray(obs[1], dtype=float),
        dropped=tuple(_dropped_row(d) for d in facts.dropped),
    )


def _is_compliance(name: str) -> bool:
    """Whether an estimated parameter is an axial joint compliance (``compliance_q2``)."""
    effect = effect_of(name)
    return effect is not None and effect[0] == "compliance"


def _parameters(facts: ResultFacts, truth: Mapping[str, float]) -> tuple[ParameterRow, ...]:
    chain = facts.measurement_chain or facts.model
    rot = {s.name: s.is_rotation for s in chain.steps}
    groups = {Role.DEVICE: "device frame", Role.TOOL: "tool", Role.KINEMATIC: "robot"}
    rows = []
    for n, v0, v, s in zip(facts.names, facts.nominal, facts.estimates, facts.std, strict=True):
        if _is_compliance(n):  # in the joint-effects section
            continue
        is_rot = rot.get(n, False)
        k = math.degrees(1) if is_rot else 1e3
        group = groups[chain.roles.get(n, Role.KINEMATIC)]
        true = truth.get(n)
        rows.append(
            ParameterRow(
                name=n,
                group=group,
                unit="deg" if is_rot else "mm",
                start=float(v0) * k,
                estimate=float(v) * k,
                std=float(s) * k,
                true_delta=None if true is None else float(true) * k,
            )
        )
    return tuple(rows)


def _base_errors(facts: ResultFacts, stats: ValidationStats) -> PoseErrors:
    """Error vectors of ``stats`` rotated from the device frame into the robot base frame."""
    return PoseErrors(stats.error_vectors @ facts.T_device_base[:3, :3])


def _residuals(
    result: CalibrationResult, facts: ResultFacts, data: Measurements | None
) -> ResidualsData | None:
    if data is None or data.position is None:
        return None
    after = validate(result, data)
    before = start_validation(facts, data)
    R, t = facts.T_device_base[:3, :3], facts.T_device_base[:3, 3]
    return ResidualsData(
        before=before,
        after=after,
        points_base_m=data.position @ R - t @ R,
        vectors_before_m=None if before is None else _base_errors(facts, before).delta,
        vectors_after_m=_base_errors(facts, after).delta,
    )


def _orientation_table(facts: ResultFacts, result: CalibrationResult, data: Measurements) -> Any | None:
    """The seeds' table with orientation errors (x-y-z angles) for pose measurements."""
    from robocal import spatial

    chain = start_chain_of(facts)
    if chain is None or data.orientation is None or data.position is None:
        return None
    T_base_device = spatial.inverse(facts.T_device_base)
    measured = T_base_device @ spatial.homogeneous(data.orientation, data.position)
    cases = {
        "before calibration": pose_errors(T_base_device @ chain.fk(data.q), measured, "xyz"),
        "after calibration": pose_errors(T_base_device @ result.predict(data.q), measured, "xyz"),
    }
    return error_table(cases)


def _validation(
    result: CalibrationResult, facts: ResultFacts, test: Measurements | None, ev: Mapping[str, Any]
) -> ValidationData | None:
    if test is None or test.position is None:
        stored = facts.stored_validation
        return (
            None
            if stored is None
            else ValidationData(rows=(("after calibration (stored)", stored),), after=None)
        )
    after = validate(result, test)
    before = start_validation(facts, test)
    comparison = [c for c in ev.get("comparison") or [] if isinstance(c, Mapping) and "n" in c]
    rows = [(str(c["model"]), c) for c in comparison]
    if not rows:
        rows = [
            (name, s.to_dict())
            for name, s in (("before calibration", before), ("after calibration", after))
            if s
        ]
    seeds = None
    if before is not None:
        seeds = error_table(
            {
                "before calibration": _base_errors(facts, before),
                "after calibration": _base_errors(facts, after),
            }
        )
    return ValidationData(
        rows=tuple(rows),
        after=after,
        before=before,
        improvement=None if before is None else improvement(before.errors, after.errors),
        seed_table=seeds,
        orientation_table=_orientation_table(facts, result, test) if before is not None else None,
    )


def _effects(
    result: CalibrationResult, facts: ResultFacts, q: Array | None, truth: Mapping[str, Any]
) -> EffectsData | None:
    held = tuple(
        (d.name, d.detail or d.reason) for d in facts.dropped if d.reason in ("unphysical", "undetermined")
    )
    if not (facts.compliance or facts.effects or held):
        return None
    sigma = dict(zip(facts.names, facts.std, strict=True))
    true_c = truth.get("compliance_rad_per_Nm") or {}
    compliance = tuple(
        ComplianceRow(
            joint=joint,
            compliance=float(c),
            sigma=None if (s := sigma.get(COMPLIANCE_PREFIX + joint)) is None else float(s),
            true=None if not true_c else float(true_c.get(joint, 0.0)),
        )
        for joint, c in facts.compliance.items()
    )
    other = tuple(
        (joint, name, float(value), None if s is None else float(s))
        for joint, fields in facts.effects.items()
        for name, (value, s) in fields.items()
    )
    displacement = None
    pert = result.joint_perturbations(q) if q is not None else None
    if q is not None and pert is not None:
        model = facts.model
        displacement = np.linalg.norm(model.fk(q, pert)[:, :3, 3] - model.fk(q)[:, :3, 3], axis=1)
    return EffectsData(compliance=compliance, other=other, held=held, displacement_m=displacement)


def collect_report(
    result: CalibrationResult,
    *,
    data: Measurements | None = None,
    test_data: Measurements | None = None,
    evaluation: Mapping[str, Any] | None = None,
    options: ReportOptions | None = None,
) -> ReportData:
    """Everything the report shows, computed once.

    Args:
        result: the calibration.
        data: the calibration measurements (residuals, coverage, observability).
        test_data: held-out measurements (validation, the seeds' table).
        evaluation: ISO 9283 poses and paths, compensation, truth, timings, an ISO 9283
            log's characteristics (plain JSON-able data, see :mod:`robocal.evaluate.report`).
        options: the title and time stamp.

    Raises:
        ValueError: measurements of another robot, or an evaluation of the wrong shape.
    """
    from robocal._version import __version__
    from robocal.evaluate.report.collect_eval import (
        compensation,
        evaluation_part,
        iso_data,
        iso_log,
        model_choice,
        timings,
    )

    options = options or ReportOptions()
    _check_result(result)
    facts = report_data_from_result(result)
    _check_dof(facts, data, test_data)
    ev = dict(evaluation or {})
    truth = ev.get("truth") or {}
    q_effects = test_data.q if test_data is not None else (data.q if data is not None else None)
    iso, iso_error = iso_data(ev)
    with evaluation_part("iso_poses"):
        coverage = _coverage(facts, data, test_data, ev)
    return ReportData(
        title=options.title or f"Calibration report: {facts.model.name}",
        facts=facts,
        n_calibration=facts.n,
        n_held_out=None if test_data is None else test_data.n,
        coverage=coverage,
        identifiability=_identifiability(facts, data),
        parameters=_parameters(facts, truth.get("parameter_deltas") or {}),
        residuals=_residuals(result, facts, data),
        validation=_validation(result, facts, test_data, ev),
        iso=iso,
        iso_error=iso_error,
        iso_log=iso_log(ev),
        effects=_effects(result, facts, q_effects, truth),
        compensation=compensation(ev),
        model_choice=model_choice(facts),
        timings_s=timings(ev),
        written=options.written or _dt.datetime.now().isoformat(timespec="seconds"),
        version=__version__,
    )
