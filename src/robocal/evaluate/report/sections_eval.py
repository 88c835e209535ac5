"""Renderers of the sections that judge the calibration: held-out validation, ISO 9283,
joint effects, compensation and provenance (same contract as
:mod:`robocal.evaluate.report.sections`).

Joint stiffness is shown in one convention everywhere (the report and the CLI summary):
compliance in µrad/(N·m), stiffness in kN·m/rad (:data:`robocal.model.joints.COMPLIANCE_UNIT`,
:data:`robocal.model.joints.STIFFNESS_UNIT`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from robocal.evaluate.error_tables import ERROR_QUANTITIES, ErrorTable
from robocal.evaluate.report import figures as fg
from robocal.evaluate.report import markup as m
from robocal.evaluate.report.data import ReportData
from robocal.identify.validate import ValidationStats
from robocal.model.joints import COMPLIANCE_UNIT, STIFFNESS_UNIT

__all__ = ["SECTIONS", "STATS_HEADER", "effect_cells", "stats_rows"]

Section = tuple[str, str, str]
STATS_HEADER = ("model", "poses", "mean mm", "RMS mm", "p95 mm", "max mm", "|x| / |y| / |z| mean mm")
ANGLE_EFFECTS = ("clearance_tilt", "backlash")  # rad, shown in deg


def stats_rows(rows: Sequence[tuple[str, ValidationStats | Mapping[str, Any] | None]]) -> list[list[Any]]:
    """Table rows of error statistics (absent ones left out)."""
    out = []
    for name, s in rows:
        if s is None:
            continue
        d = s.to_dict() if isinstance(s, ValidationStats) else s
        axes = " / ".join(m.f(v) for v in d.get("axis_mean_abs_mm", [])) or "–"
        out.append([name, d["n"], m.f(d.get("mean_mm")), m.f(d.get("rms_mm")), m.f(d.get("p95_mm"))])
        out[-1] += [m.f(d.get("max_mm")), axes]
    return out


def seed_table_html(table: ErrorTable, caption: str) -> str:
    """The seeds' minimum / maximum / average table with the improvement and its CI."""
    cases = list(table.improvements)
    header = ["", "quantity", *table.cases] + [f"improvement ({c}) %" for c in cases]
    rows = []
    for stat, arr in (("minimum", table.minimum), ("maximum", table.maximum), ("average", table.average)):
        for i, q in enumerate(table.quantities):
            unit = " °" if q in ERROR_QUANTITIES[4:] else " mm"
            row: list[Any] = [stat if i == 0 else "", q + unit]
            row += [table.display(i, arr[i, j]) for j in range(len(table.cases))]
            for c in cases:
                imp = table.improvements[c].get(q)
                row.append(
                    f"{imp.percent:.1f} ({imp.percent_low:.1f} to {imp.percent_high:.1f})"
                    if stat == "average" and imp is not None
                    else ""
                )
            rows.append(row)
    return m.table(header, rows, "seed", caption)


def _expected_note(after: ValidationStats) -> str:
    if after.expected_rms is None or after.parameter_rms is None:  # set together
        return ""
    verdict = (
        "more than 1.5× the expectation: the robot or device changed, or the model misses errors the "
        "calibration poses did not show"
        if after.worse_than_expected
        else "as expected"
    )
    return m.note(
        f"The calibration expected an RMS error of {m.f(after.expected_rms * 1e3, 4)} mm on these poses "
        f"({m.f(after.parameter_rms * 1e3, 4)} mm from the uncertainty of its parameters, propagated through "
        "the Jacobian; the rest measurement noise and any error its residuals showed beyond it); measured "
        f"{m.f(after.rms * 1e3, 4)} mm: {verdict}."
    )


def validation(r: ReportData, figs: m.Figures) -> Section:
    v = r.validation
    if v is None:
        body = m.note("No held-out measurements were given.")
    elif v.after is None:
        body = m.table(STATS_HEADER, stats_rows(v.rows))
    else:
        caption = f"position error on {v.after.n} held-out poses (not used by the calibration)"
        body = m.table(STATS_HEADER, stats_rows(v.rows), caption=caption)
        body += _expected_note(v.after)
        before = None if v.before is None else v.before.errors
        hist = fg.histogram_pair_figure(before, v.after.errors, "errors on the held-out poses")
        body += figs.html(hist, "validation-histogram", 340)
        if v.seed_table is not None:
            body += "<h3>The seeds' table: minimum, maximum and average errors</h3>"
            body += seed_table_html(
                v.seed_table,
                "robot base frame; improvement of the average with its 95 % confidence interval (paired, "
                "delta method)",
            )
        if v.orientation_table is not None:
            caption = "predicted minus measured; ΔΦ Δθ ΔΨ as rotations about the base x, y, z axes"
            body += "<h3>With orientation</h3>" + seed_table_html(v.orientation_table, caption)
    intro = "The honest test: poses the calibration never saw, predicted with the calibrated device frame."
    return "validation", "Validation", m.section("validation", "Held-out validation", body, intro)


def _iso_pose_table(r: ReportData) -> str:
    iso = r.iso
    if iso is None or not iso.poses:
        return ""
    rows = []
    for case, ch in iso.poses.items():
        for row in ch.rows():
            first = case if row["pose"] == ch.labels[0] else ""
            signed = [f"{row[k]:+.3f}" for k in ("APx_mm", "APy_mm", "APz_mm")]
            rows.append([first, row["pose"], row["n"], m.f(row["AP_mm"]), *signed, m.f(row["RP_mm"])])
    caption = "pose accuracy AP and repeatability RP (mm) at P1–P5"
    if iso.cycles is not None:
        caption += f", {iso.cycles} cycles"
    if iso.cube_side_m is not None:
        caption += f"; cube side {iso.cube_side_m * 1e3:.0f} mm"
    if iso.cube_plane is not None:
        caption += f", diagonal plane {iso.cube_plane}"
    return m.table(["commands", "pose", "cycles", "AP", "APx", "APy", "APz", "RP"], rows, caption=caption)


def _finite_mean(values: np.ndarray) -> float:
    """The mean of the finite values (NaN where the attained path missed a normal plane)."""
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else math.nan


def _iso_path_table(r: ReportData) -> str:
    paths = () if r.iso is None else r.iso.paths
    rows = [
        [p.name, case, pa.n_cycles, m.f(pa.AT * 1e3), m.f(pa.RT * 1e3), m.f(_finite_mean(pa.at) * 1e3)]
        for p in paths
        for case, pa in p.accuracy.items()
    ]
    header = ["path", "commands", "cycles", "AT mm", "RT mm", "mean distance mm"]
    return m.table(header, rows, caption="path accuracy AT and repeatability RT (ISO 9283 §8.2–8.3)")


def _iso_log_html(r: ReportData) -> str:
    log = r.iso_log
    if log is None:
        return ""
    band = "" if log.band_mm is None else f" (limit band {m.g(log.band_mm)} mm)"
    head = "<h3>ISO 9283 characteristics of a measurement log</h3>" + m.note(
        f"From the measurement log {m.e(log.source)}{band}; clauses of ISO 9283:1998, read as "
        "docs/iso9283.md states."
    )
    table = m.table(["#", "characteristic", "clause", "result", "cycles (ISO)"], log.rows)
    return head + (table or m.note("The log gave no characteristics."))


def iso9283(r: ReportData, figs: m.Figures) -> Section | None:
    """ISO 9283 pose and path characteristics of the evaluation and those of a measurement
    log, in one section."""
    if r.iso is None and r.iso_log is None and r.iso_error is None:
        return None
    body = _iso_pose_table(r) + _iso_path_table(r)
    if r.iso is not None:
        body += m.note(
            "AP: distance from the commanded position to the barycentre of the attained positions; "
            "RP = l̄ + 3 S_l; AT: largest distance from the commanded path to the barycentre of the attained "
            "paths in the normal planes; RT = max(l̄ᵢ + 3 S_lᵢ). Attained positions: measured by the device, "
            "mapped into the robot base frame with the calibrated frame."
        )
    elif r.iso_error is not None:
        body += m.note(f"Not measured: {m.e(r.iso_error)}")
    body += _iso_log_html(r)
    intro = (
        "Pose and path characteristics of ISO 9283:1998 in the largest test cube of the workspace, with the "
        "nominal joint commands and with commands compensated by the calibrated model."
        if r.iso is not None
        else "Performance characteristics of ISO 9283:1998."
    )
    return "iso9283", "ISO 9283", m.section("iso9283", "ISO 9283 performance", body, intro)


def effect_cells(name: str, value: float, sigma: float | None) -> tuple[str, str, str]:
    """``(value, σ, unit)`` of a joint effect in the report's units (deg; µrad/(N·m) with
    the stiffness in kN·m/rad)."""
    if name in ANGLE_EFFECTS:
        k = math.degrees(1)
        return f"{value * k:.4f}", "–" if sigma is None else f"{sigma * k:.2g}", "deg"
    unit, k = COMPLIANCE_UNIT
    text = f"{value * k:.4g}"
    if value > 0:
        text += f" (stiffness {1.0 / value * STIFFNESS_UNIT[1]:.4g} {STIFFNESS_UNIT[0]})"
    return text, "–" if sigma is None else f"{sigma * k:.2g}", unit


def _compliance_table(r: ReportData) -> str:
    eff = r.effects
    if eff is None or not eff.compliance:
        return ""
    cu, ck = COMPLIANCE_UNIT
    su, sk = STIFFNESS_UNIT
    has_truth = any(c.true is not None for c in eff.compliance)
    rows = []
    for c in eff.compliance:
        stiffness = m.g(1.0 / c.compliance * sk, 4) if c.compliance > 0 else "not positive"
        row = [c.joint, f"{c.compliance * ck:.3f}", "–" if c.sigma is None else m.f(c.sigma * ck), stiffness]
        if has_truth:
            row.append("–" if c.true is None else f"{c.true * ck:.3f}")
        rows.append(row)
    header = ["joint", f"compliance {cu}", f"σ {cu}", f"stiffness {su}"] + (
        [f"true {cu}"] if has_truth else []
    )
    return m.table(header, rows, caption="joint compliance under gravity: δθ = −c τ(q)")


def joint_effects(r: ReportData, figs: m.Figures) -> Section | None:
    eff = r.effects
    if eff is None:
        return None
    body = _compliance_table(r)
    shown = {c.joint for c in eff.compliance}
    other = [
        (j, n, *effect_cells(n, v, s)) for j, n, v, s in eff.other if not (n == "compliance" and j in shown)
    ]
    body += m.table(
        ["joint", "effect parameter", "value", "σ", "unit"],
        other,
        caption="joint effects of the calibrated model (clearance tilt, backlash, compliance: "
        "robocal.model.joints); "
        "σ – where predicted, not identified",
    )
    body += m.table(
        ["joint effect", "not identified because"],
        eff.held,
        caption="joint effects below zero or within 3σ of it: kept at their start values",
    )
    if eff.displacement_m is not None:
        d = eff.displacement_m
        body += figs.html(fg.compliance_figure(d), "joint-effects", 320)
        body += m.note(
            f"The identified joint effects move the tool by {m.f(d.mean() * 1e3)} mm on average and up to "
            f"{m.f(d.max() * 1e3)} mm over these poses: errors a geometric model cannot represent."
        )
    intro = (
        "Non-geometric errors of the joints, identified with the geometry. Compliance under gravity: each "
        "joint gives way by δθ = −c τ(q), τ the torque holding the arm against gravity (Pinocchio, from the "
        "model's masses)."
    )
    return "joint-effects", "Joint effects", m.section("joint-effects", "Joint effects", body, intro)


def compensation(r: ReportData, figs: m.Figures) -> Section | None:
    paths = () if r.iso is None else r.iso.paths
    if r.compensation is None and not paths:
        return None
    body = "" if r.compensation is None else m.table(["compensation", ""], r.compensation.items)
    if paths:
        body += figs.html(fg.path_errors_figure(paths), "compensation-paths", 380)
    intro = (
        "Joint commands corrected so that the calibrated robot (with its joint effects) puts the tool on the "
        "target, compared with the nominal commands on the same targets."
    )
    return "compensation", "Compensation", m.section("compensation", "Compensation", body, intro)


def provenance(r: ReportData, figs: m.Figures) -> Section:
    facts = r.facts
    rows: list[list[Any]] = [
        ["robocal", r.version],
        ["written", r.written],
        ["method", facts.method],
        ["iterations", facts.iterations],
        ["calibration time", f"{facts.seconds * 1e3:.1f} ms"],
        ["residual σ", f"{m.f(facts.residual_std_m * 1e3, 4)} mm"],
    ]
    if facts.fit_to_noise is not None:
        rows.append(["residuals against the stated noise", facts.fit_to_noise])
    rows += [["warning", w] for w in facts.warnings]
    rows += [[label, value] for label, value in facts.inputs]
    rows += [[f"time: {step}", f"{sec:.2f} s"] for step, sec in r.timings_s]
    return "provenance", "Provenance", m.section("provenance", "Provenance", m.table(["", ""], rows))


#: the evaluation's sections in page order, after sections.SECTIONS
SECTIONS = (validation, iso9283, joint_effects, compensation, provenance)
