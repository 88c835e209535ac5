"""Renderers of the calibration's own sections: summary, robot and model, model choice,
data, identifiability, parameters, residuals.  Each takes the
:class:`~robocal.evaluate.report.data.ReportData` and the page's figure collector and
returns ``(id, navigation label, html)``, or None when the section is left out."""

from __future__ import annotations

from typing import Any

from robocal.evaluate.report import figures as fg
from robocal.evaluate.report import markup as m
from robocal.evaluate.report.data import ReportData
from robocal.model.joints import effect_of

__all__ = ["SECTIONS"]

Section = tuple[str, str, str]


def _card(label: str, value_html: str, sub: str) -> str:
    return (
        f"<div class='card'><div class='label'>{m.e(label)}</div><div class='value'>{value_html}</div>"
        f"<div class='sub'>{m.e(sub)}</div></div>"
    )


def _before_after(before: float | None, after: float, digits: int = 3, cls: str = "after") -> str:
    """``before → after`` (m in, mm shown), coloured."""
    text = f"<span class='{cls}'>{m.f(after * 1e3, digits)} mm</span>"
    return text if before is None else f"<span class='before'>{m.f(before * 1e3)}</span> → {text}"


def _held_out_card(r: ReportData) -> str:
    v = r.validation
    if v is None:
        return ""
    if v.after is None:  # only the statistics stored in the result
        stored = dict(v.rows[0][1])
        value = f"<span class='after'>{m.f(stored.get('mean_mm'))} mm</span>"
        return _card("mean error on held-out poses", value, f"{stored['n']} held-out poses (stored)")
    sub = f"{v.after.n} held-out poses"
    if v.improvement is not None:
        imp = v.improvement
        sub += f"; {imp.percent:.1f} % smaller (95 % CI {imp.percent_low:.1f}–{imp.percent_high:.1f})"
    before = None if v.before is None else v.before.mean
    return _card("mean error on held-out poses", _before_after(before, v.after.mean), sub)


def _iso_cards(r: ReportData) -> str:
    if r.iso is None:
        return ""

    def cases(values: dict[str, float]) -> str:
        return " → ".join(
            f"<span class='{'before' if 'nominal' in c else 'comp'}'>{m.f(v * 1e3)}</span>"
            for c, v in values.items()
        )

    cards = ""
    if r.iso.poses:
        worst = {case: max(a.AP for a in ch.accuracy) for case, ch in r.iso.poses.items()}
        cards += _card("ISO 9283 AP, worst of P1–P5", cases(worst) + " mm", " → ".join(worst))
    if r.iso.paths:
        p0 = r.iso.paths[0]
        at = {case: pa.AT for case, pa in p0.accuracy.items()}
        cards += _card(f"ISO 9283 AT, {p0.name}", cases(at) + " mm", " → ".join(at))
    return cards


def _status(r: ReportData) -> str:
    """ "converged: <the solver's message>", the message's own "converged:" dropped."""
    facts = r.facts
    status = "converged" if facts.converged else "NOT CONVERGED"
    message = facts.message.strip()
    if message.lower().startswith(status.lower() + ":"):
        message = message[len(status) + 1 :].strip()
    return f"{status}: {message}" if message else status


def summary(r: ReportData, figs: m.Figures) -> Section:
    facts = r.facts
    n_effects = sum((e := effect_of(n)) is not None and e[0] == "compliance" for n in facts.names)
    cards = _held_out_card(r)
    cards += _card(
        "RMS error on calibration poses",
        _before_after(facts.rms_before_m, facts.rms_after_m, 4),
        f"{facts.n} poses, {facts.method}, {facts.iterations} "
        f"iteration{'' if facts.iterations == 1 else 's'}, {facts.seconds * 1e3:.0f} ms",
    )
    cards += _card(
        "identified parameters",
        f"{len(facts.names) - n_effects}" + (f" + {n_effects} compliances" if n_effects else ""),
        f"{len(facts.dropped)} not identified; condition number {m.g(facts.condition_number)}",
    )
    cards += _iso_cards(r)
    text = (
        f"{m.e(facts.model.name)}: {m.e(facts.measure)} measurements, method {m.e(facts.method)} "
        f"({m.e(_status(r))}). Before calibration = the nominal model with the device frame and tool "
        "fitted to the calibration data, the starting point of the identification."
    )
    return (
        "summary",
        "Summary",
        m.section("summary", "Summary", f"<div class='cards'>{cards}</div>" + m.note(text)),
    )


def robot_model(r: ReportData, figs: m.Figures) -> Section:
    from robocal.model.view import model_figure

    model = r.facts.model
    body = figs.html(
        model_figure(model, title=f"{model.name} at zero joint values (calibrated)"), "model", 560
    )
    info: list[list[str | int]] = [
        ["robot", model.title or model.name],
        ["joints", f"{model.dof} ({''.join('R' if t == 'revolute' else 'P' for t in model.joint_types)})"],
        ["steps (elementary transforms)", len(model.steps)],
        ["mass properties", "yes" if model.bodies else "no"],
    ]
    links = [
        n.strip().removesuffix(" calibrated") for n in model.notes.split(";") if n.strip().startswith("link")
    ]
    info_table = m.table(["", ""], info)
    if links:
        link_table = m.table(["link parameterisation (Motta 2005, seed 000)"], [[n] for n in links])
        body += f"<div class='grid2'><div>{info_table}</div><div>{link_table}</div></div>"
    else:
        body += info_table
    if model.source:
        body += m.note(f"source: {m.e(model.source)}")
    intro = (
        "The calibrated chain at zero joint values: every joint frame (x red, y green, z blue), the base and "
        "the measured tool point. Drag to rotate."
    )
    return "model", "Robot & model", m.section("model", "Robot and model", body, intro)


def model_choice(r: ReportData, figs: m.Figures) -> Section | None:
    from robocal.identify.residual.cv import SELECTION_SE

    mc = r.model_choice
    if mc is None:
        return None
    rows = [
        [
            name + (" (chosen)" if name == mc.chosen else ""),
            f"{mean * 1e3:.4f}",
            f"{rms * 1e3:.4f}",
            f"{sec * 1e3:.0f}",
        ]
        for name, mean, rms, sec in mc.candidates
    ]
    body = m.table(["candidate", "CV mean mm", "CV RMS mm", "fit ms"], rows)
    if mc.curves:
        body += figs.html(fg.learned_residual_figure(mc.curves), "residual", 380)
    if mc.harmonics is not None and mc.noise_std_m is not None:
        body += m.note(
            f"{mc.harmonics} harmonics per revolution; what remains: σ {mc.noise_std_m * 1e3:.4f} mm "
            "per axis (the evidence's estimate)."
        )
    intro = (
        f"{mc.folds}-fold cross-validation on the calibration poses compared the physical model "
        "(geometry, and geometry with joint compliance when the model has masses), alone and with learned "
        "per-joint angle errors (a Fourier series in the joint's own angle, fitted with the geometry under a "
        f"Gaussian-process prior). It chose <b>{m.e(mc.chosen)}</b>: the simplest candidate whose CV "
        f"error is within {SELECTION_SE:g} standard errors (over the poses) of the lowest. Held-out poses "
        "played no part in the choice."
    )
    return "model-choice", "Model choice", m.section("model-choice", "Model choice", body, intro)


def data(r: ReportData, figs: m.Figures) -> Section:
    cov = r.coverage
    if cov is None:
        body = m.note("No measurements were given to the report.")
    else:
        body = figs.html(fg.coverage_figure(cov), "coverage", 600)
        body += figs.html(fg.joint_coverage_figure(cov), "joint-coverage", 380)
        rows = []
        for s in cov.sets:
            extent = " × ".join(f"{v:.0f}" for v in s.extent_mm)
            sigma = "not stated" if s.median_sigma_mm is None else f"{s.median_sigma_mm:.4f}"
            rows.append([s.name, s.n, s.observes, extent, sigma, s.device or "not stated"])
        body += m.table(["set", "poses", "observed", "extent x × y × z mm", "median σ mm", "device"], rows)
    intro = (
        "Where the measured poses put the tool (computed with the calibrated model) and how much of each "
        "joint's range they use. Good coverage makes every parameter observable."
    )
    return "data", "Data", m.section("data", "Data: pose coverage", body, intro)


def identifiability(r: ReportData, figs: m.Figures) -> Section:
    ident, facts = r.identifiability, r.facts
    rows: list[list[Any]] = [
        ["condition number (column-scaled Jacobian)", m.g(facts.condition_number)],
        ["identified parameters", len(facts.names)],
        ["not identified", len(facts.dropped)],
    ]
    rows += [[label, m.g(value)] for label, value in ident.indices]
    body = m.table(["identifiability", "value"], rows)
    if ident.singular_values is None:
        body += m.note("Observability indices and singular values need the calibration measurements.")
    else:
        body += m.note(
            "O1–O5 from the Jacobian with columns scaled by the expected parameter errors (0.1 mm, 0.05°; "
            "Sun &amp; Hollerbach 2008): larger is better."
        )
        figure = figs.html(fg.singular_values_figure(ident.singular_values), "singular-values", 340)
        body = f"<div class='grid2'><div>{body}</div><div>{figure}</div></div>"
    body += m.table(
        ["parameter not identified", "reason", "absorbed by (coefficient) / detail"], ident.dropped
    )
    body += m.table(
        ["parameter", "parameter", "correlation"],
        [[a, b, f"{rho:+.3f}"] for a, b, rho in facts.correlations],
        caption="pairs correlated above 0.9",
    )
    intro = (
        "Which parameters these measurements can determine. A redundant parameter is absorbed by the ones "
        "listed (its column is their combination); a poorly identifiable one would move the tool by more "
        "than 0.5 mm at one σ and is left at its start value."
    )
    return "identifiability", "Identifiability", m.section("identifiability", "Identifiability", body, intro)


def parameters(r: ReportData, figs: m.Figures) -> Section:
    has_truth = any(p.true_delta is not None for p in r.parameters)
    header = ["parameter", "group", "unit", "start", "estimate", "Δ", "σ", "|Δ|/σ"] + (
        ["true Δ"] if has_truth else []
    )
    rows = []
    for p in r.parameters:
        digits = 4 if p.unit == "mm" else 5
        ratio = abs(p.delta) / p.std if p.std > 0 else None
        row = [p.name, p.group, p.unit, m.f(p.start, digits), m.f(p.estimate, digits)]
        row += [f"{p.delta:+.{digits}f}", m.f(p.std, digits), m.f(ratio, 1)]
        if has_truth:
            row.append("–" if p.true_delta is None else f"{p.true_delta:+.{digits}f}")
        rows.append(row)
    robot = [p for p in r.parameters if p.group == "robot"]
    body = figs.html(fg.parameters_figure(robot), "parameters", 420) if robot else ""
    body += m.table(header, rows) or m.note("No parameter was estimated.")
    if has_truth:
        body += m.note(
            "True Δ: the simulation's parameter errors. A parameter whose true error is absorbed by another "
            "(see Identifiability) is compared with a combination, not itself."
        )
    intro = (
        "Estimates with their change from the start values and one standard deviation σ from the residual "
        "scatter (σ̂²(JᵀWJ)⁻¹). Lengths in mm, angles in degrees; device-frame corrections and the tool point "
        "are identified with the robot."
    )
    return "parameters", "Parameters", m.section("parameters", "Identified parameters", body, intro)


def residuals(r: ReportData, figs: m.Figures) -> Section:
    from robocal.evaluate.report.sections_eval import STATS_HEADER, stats_rows

    res, facts = r.residuals, r.facts
    if res is None:
        body = m.note(
            f"RMS on the {facts.n} calibration poses: {m.f(facts.rms_before_m * 1e3, 4)} mm before, "
            f"{m.f(facts.rms_after_m * 1e3, 4)} mm after. Pass the calibration data for plots."
        )
    else:
        before = None if res.before is None else res.before.errors
        stats = [("before calibration", res.before), ("after calibration", res.after)]
        caption = f"position error on the {res.after.n} calibration poses"
        body = m.table(STATS_HEADER, stats_rows(stats), caption=caption)
        title = "residuals on the calibration poses"
        body += figs.html(
            fg.histogram_pair_figure(before, res.after.errors, title), "residual-histogram", 340
        )
        title = "residual per calibration pose"
        body += figs.html(fg.per_pose_figure(before, res.after.errors, title), "residual-per-pose", 340)
        title = "residual vectors at the calibration poses (robot base frame, exaggerated)"
        vectors = fg.error_vectors_figure(res.points_base_m, res.vectors_before_m, res.vectors_after_m, title)
        body += figs.html(vectors, "error-vectors", 560)
    intro = (
        "Predicted minus measured tool positions on the poses used for the calibration. Arrows are magnified "
        "by the factor in the legend; click 'error before calibration' to show the errors of the nominal "
        "model."
    )
    return "residuals", "Residuals", m.section("residuals", "Residuals before and after", body, intro)


#: the calibration's sections in page order (the evaluation's follow: sections_eval.SECTIONS)
SECTIONS = (summary, robot_model, model_choice, data, identifiability, parameters, residuals)
