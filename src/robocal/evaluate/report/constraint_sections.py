"""The page of a constraint calibration (:mod:`.constraint_collect`), one function per section.

No position-error tables: without a measuring device there are no measured positions to
compare with.  Each kind's own figures instead, before (the nominal robot) and after.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from robocal.evaluate.report import markup as m
from robocal.evaluate.report.constraint_collect import ConstraintReport, DataSetFigures, rms
from robocal.identify.constraints.fit import ConstraintFigures

__all__ = ["render_constraint_report", "write_constraint_report"]

Section = tuple[str, str, str] | None


def _mm(value: float | None, digits: int = 3) -> str:
    return m.f(None if value is None else value * 1e3, digits)


Row = tuple[str, float | None, float]


def _rows(before: ConstraintFigures | None, after: ConstraintFigures) -> list[Row]:
    """One row per figure: what, before and after (m; |error| for signed errors)."""
    out: list[Row] = []

    def add(what: str, attr: str) -> None:
        old = None if before is None else np.abs(getattr(before, attr))
        for k, v in enumerate(np.abs(getattr(after, attr))):
            out.append((what.format(k=k), None if old is None else float(old[k]), float(v)))

    add("point {k}: RMS spread", "point_spread")
    add("known distance {k}: |error|", "point_distance_error")
    add("plane {k}: RMS residual", "plane_rms")
    if len(after.pair_error):
        b = None if before is None else rms(before.pair_error)
        out.append(("ball-bar distances: RMS error", b, rms(after.pair_error)))
        b = None if before is None else float(np.abs(before.pair_error).max())
        out.append(("ball-bar distances: max |error|", b, float(np.abs(after.pair_error).max())))
    return out


def _headline(s: DataSetFigures) -> tuple[str, float | None, float]:
    """The set's main figure: the RMS spread over all points, else the plane or distance RMS."""
    for label, attr in (
        ("RMS spread around the fixed points", "point_spread"),
        ("RMS plane residual", "plane_rms"),
        ("RMS ball-bar distance error", "pair_error"),
    ):
        if len(getattr(s.after, attr)):
            before = None if s.before is None else rms(getattr(s.before, attr))
            return label, before, rms(getattr(s.after, attr))
    return "no figures", None, float("nan")


def _card(label: str, value_html: str, sub: str) -> str:
    return (
        f"<div class='card'><div class='label'>{m.e(label)}</div><div class='value'>{value_html}</div>"
        f"<div class='sub'>{m.e(sub)}</div></div>"
    )


def _before_after(before: float | None, after: float) -> str:
    text = f"<span class='after'>{_mm(after)} mm</span>"
    return text if before is None else f"<span class='before'>{_mm(before)}</span> → {text}"


def summary(r: ConstraintReport, figs: m.Figures) -> Section:
    cal = r.calibration
    cards = ""
    for s in reversed(r.sets):  # held-out first: the figure that matters
        label, before, after = _headline(s)
        cards += _card(f"{label} ({s.label})", _before_after(before, after), f"{s.n} poses of {s.source}")
        if len(s.after.point_distance_error) and len(s.after.point_spread):  # the sockets' stated distance
            old = None if s.before is None else rms(s.before.point_distance_error)
            cards += _card(f"known distance error, RMS ({s.label})",
                           _before_after(old, rms(s.after.point_distance_error)), f"{s.source}")  # fmt: skip
    if (t := r.tracker) is not None:  # a device measured positions: the error a user asks for first
        old = None if t.before is None else t.before.rms
        cards += _card("position error RMS (tracker file)", _before_after(old, t.after.rms),
                       f"{t.after.n} poses of {t.source}")  # fmt: skip
    cards += _card("fit residual (calibration data)", _before_after(cal.rms_before, cal.rms_after),
                   "converged" if cal.success else "the fit did NOT converge")  # fmt: skip
    held = f"{len(cal.unseen)} not identifiable, {len(cal.poorly_identified)} held at nominal"
    cards += _card("identified robot parameters", str(len(cal.robot_names)), held)
    text = (
        f"{m.e(cal.model.name)} calibrated from {m.e(', '.join(cal.kinds))} constraints "
        "(no measuring device). "
        "Before = the nominal robot, after = the calibrated one, each judged by the constraints alone: "
        "the spread of the tool point around each fixed point's centroid, the error of each known "
        "distance, the residual of each plane."
    )
    text += (
        " There are no position errors: no device measured positions."
        if r.tracker is None
        else " Position errors on a tracker file: see Tracker positions."
    )
    if cal.nominal is None:
        text += " This folder does not record the nominal robot: after only."
    body = f"<div class='cards'>{cards}</div>" + m.note(text)
    body += "".join(m.note(m.e(why)) for why in r.missing)
    return "summary", "Summary", m.section("summary", "Summary", body)


def _bar_figure(rows: list[Row], title: str) -> Any:
    import plotly.graph_objects as go

    names = [m.plot_text(row[0]) for row in rows]
    fig = go.Figure()
    if all(row[1] is not None for row in rows):
        before = [row[1] * 1e3 for row in rows if row[1] is not None]
        fig.add_trace(go.Bar(x=names, y=before, name="before (nominal)", marker_color=m.BEFORE))
    fig.add_trace(go.Bar(x=names, y=[row[2] * 1e3 for row in rows], name="after", marker_color=m.AFTER))
    fig.update_layout(barmode="group", title=m.plot_text(title), yaxis_title="mm", margin={"t": 60})
    return fig


def _radial_figure(s: DataSetFigures) -> Any:
    from robocal.evaluate.report.figures import histogram_pair_figure

    fig = histogram_pair_figure(
        s.radial_before, s.radial_after, f"distance of each pose from its point ({s.label})"
    )
    fig.update_xaxes(title_text="distance from the point's centroid mm")
    return fig


def kind_figures(r: ConstraintReport, figs: m.Figures) -> Section:
    if not r.sets:
        return None
    body = ""
    for i, s in enumerate(r.sets):
        rows = _rows(s.before, s.after)
        body += f"<h3>{m.e(s.label)}: {m.e(s.source)} ({s.n} poses, {m.e(', '.join(s.kinds))})</h3>"
        if rows:
            cells = [[what, _mm(b), _mm(a)] for what, b, a in rows]
            body += m.table(["figure", "before (nominal) mm", "after (calibrated) mm"], cells)
            body += figs.html(_bar_figure(rows, f"{s.label}: before and after"), f"constraint-bars-{i}", 380)
        body += _tilt_table(s)
        if len(s.radial_after):
            body += figs.html(_radial_figure(s), f"constraint-radial-{i}", 340)
    intro = (
        "Each kind's own figures (mm): a fixed point's RMS spread is the RMS distance of the tool points "
        "from their centroid; a known distance's error is the centroids' distance minus the stated one; "
        "a plane's residual is the RMS distance from the plane (the stated one, else the best fit)."
    )
    return "figures", "Constraint figures", m.section("figures", "Constraint figures", body, intro)


def tracker_positions(r: ConstraintReport, figs: m.Figures) -> Section:
    """The position errors on a tracker file, the nominal and the calibrated robot."""
    t = r.tracker
    if t is None:
        return None
    robots = [("nominal (before)", t.before), ("calibrated (after)", t.after)]
    cells = [
        [name, s.frame, str(s.n), _mm(s.mean, 4), _mm(s.rms, 4), _mm(s.p95, 4), _mm(s.max, 4)]
        for name, s in robots
        if s is not None
    ]
    body = m.table(["robot", "device frame", "poses", "mean mm", "RMS mm", "p95 mm", "max mm"], cells)
    frame = (
        "the device frame the calibration's tracker rows identified, used as it is"
        if t.after.frame == "calibrated"
        else f"a device frame fitted to this file, each row scored by a frame fitted on the others "
        f"({t.after.scoring}; the calibration has no device frame of its own)"
    )
    text = (
        f"{t.source}: the distance between each measured position and the robot's prediction (its tool "
        f"point, its joints' elastic deflections) in {frame}. A constraint calibration records no "
        "covariance of the robot's parameters: the error it expected here is not available."
    )
    if t.fitted_file:
        text += " This is a tracker file the calibration was fitted to: in-sample, it flatters it."
    body += m.note(m.e(text))
    return "tracker", "Tracker positions", m.section("tracker", "Position errors on a tracker file", body)


def _tilt_table(s: DataSetFigures) -> str:
    """Each inclinometer channel's RMS residual (deg) before and after, and what predicted
    the readings after (the calibration's joint effects and channel zeros)."""
    after = s.after
    if not len(after.tilt_channels):
        return ""
    was = {} if s.before is None else dict(zip(s.before.tilt_channels, s.before.tilt_rms, strict=True))
    cells = [
        [f"inclinometer {name}: RMS residual", m.f(_deg(was.get(name)), 5), m.f(_deg(v), 5)]
        for name, v in zip(after.tilt_channels, after.tilt_rms, strict=True)
    ]
    table = m.table(["figure", "before (nominal) deg", "after (calibrated) deg"], cells)
    return table + m.note(m.e(f"After: {after.tilt_basis}.")) if after.tilt_basis else table


def _deg(value: float | None) -> float | None:
    return None if value is None else float(np.degrees(value))


def _clean(value: float | None) -> float | None:
    """Rounding noise of a nominal value (1e-16 rad, -0) shown as 0."""
    return None if value is None else (0.0 if abs(value) < 1e-12 else value)


def _parameter_rows(r: ConstraintReport) -> list[list[str]]:
    cal = r.calibration
    nominal = None if cal.nominal is None else dict(zip(cal.nominal.names, cal.nominal.values, strict=True))
    steps = {s.name: s for s in cal.model.steps}
    rows = []
    for name, value, std in zip(cal.names, cal.estimates, cal.std, strict=True):
        if name not in steps:
            continue
        scale, unit = (1.0, "rad") if steps[name].is_rotation else (1e3, "mm")
        start = None if nominal is None else nominal[name]
        delta = None if start is None else (value - start) * scale
        rows.append([name, unit, m.g(_clean(None if start is None else start * scale), 6),
                     m.g(_clean(value * scale), 6), m.g(delta, 4), m.g(std * scale, 3)])  # fmt: skip
    return rows


def _effect_rows(r: ConstraintReport) -> list[list[str]]:
    """The joint effects a constraint calibration identified: a compliance in µrad/(N·m),
    a clearance or backlash in degrees."""
    from robocal.model.joints import COMPLIANCE_UNIT, effect_of

    rows = []
    for e in r.calibration.joint_effects:
        elastic = (effect_of(e.name) or ("",))[0] in ("compliance", "radial")
        unit, scale = COMPLIANCE_UNIT if elastic else ("deg", float(np.degrees(1.0)))
        rows.append([e.name, unit, m.g(e.value * scale, 5), m.g(e.std * scale, 3)])
    return rows


def identifiability(r: ConstraintReport, figs: m.Figures) -> Section:
    cal = r.calibration
    body = m.table(["parameter", "unit", "nominal", "estimate", "Δ", "σ"], _parameter_rows(r),
                   caption="identified robot parameters")  # fmt: skip
    reasons = dict(cal.dropped)
    unseen = [[n, reasons[n], "nominal (not identifiable)"] for n in cal.unseen]
    unseen += [[n, reasons[n], "nominal (σ too large)"] for n in cal.poorly_identified]
    if cal.joint_effects:  # identified beside the geometry (tilt rows, position rows' deflections)
        from robocal.identify.constraints.tilt_record import LOADS

        body += m.table(["joint effect", "unit", "estimate", "σ"], _effect_rows(r),
                        caption=f"identified joint effects (under {LOADS})")  # fmt: skip
    body += m.table(["parameter", "reason", "value used"], unseen, caption="not identified")
    body += m.note(m.e(cal.base_note() + "."))
    if r.tracker is None:
        body += m.note(
            "What this calibration does not give: the robot's absolute position accuracy in a measuring "
            "device's frame. Check it with a tracker file when you have one (robocal validate DIR --data "
            "FILE, or robocal report DIR --test-data FILE)."
        )
    return (
        "identifiability",
        "Identifiability",
        m.section("identifiability", "What the constraints can see", body),
    )


def scene(r: ConstraintReport, figs: m.Figures) -> Section:
    cal = r.calibration
    rows = [[f"point {k}", *(m.f(v * 1e3) for v in p)] for k, p in enumerate(cal.points)]
    body = m.table(
        ["fixed point", "x mm", "y mm", "z mm"], rows, caption="estimated in the (nominal) base frame"
    )
    body += m.table(
        ["stated distance", "mm"], [[f"point {a} – point {b}", m.f(d * 1e3)] for a, b, d in cal.distances]
    )
    planes = [[f"plane {k}", *(m.f(v, 5) for v in p[:3]), m.f(p[3] * 1e3)] for k, p in enumerate(cal.planes)]
    body += m.table(["plane", "nx", "ny", "nz", "offset mm"], planes)
    return ("scene", "Scene", m.section("scene", "Scene", body)) if body else None


def provenance(r: ConstraintReport, figs: m.Figures) -> Section:
    cal = r.calibration
    prior = cal.prior
    rows = [
        ["calibration file", str(cal.data_path) if cal.data_path else "–"],
        ["its SHA-256", cal.data_sha256 or "–"],
        ["measurements", ", ".join(cal.kinds)],
        ["fit", "MAP with a prior toward the nominal geometry" if prior else "least squares"],
        ["run id", cal.run_id or "–"],
        ["robocal", r.version],
    ]
    if prior:
        rows.insert(4, ["prior σ", f"lengths {_mm(prior.get('length_std_m'))} mm, "
                                   f"angles {m.g(prior.get('angle_std_rad'))} rad"])  # fmt: skip
    return "provenance", "Provenance", m.section("provenance", "Provenance", m.table(["", ""], rows))


SECTIONS = (summary, kind_figures, tracker_positions, identifiability, scene, provenance)


def render_constraint_report(r: ConstraintReport) -> str:
    """The report as one self-contained HTML page (plotly.js embedded once)."""
    figs = m.Figures()
    shown = [s for s in (render(r, figs) for render in SECTIONS) if s is not None]
    cal = r.calibration
    subtitle = (
        f"{m.e(cal.model.title or cal.model.name)} · {m.e(', '.join(cal.kinds))} constraints (no tracker)"
        + "".join(f" · {s.n} {m.e(s.label)} poses" for s in r.sets)
    )
    return m.page(
        r.title, subtitle, [(i, label) for i, label, _ in shown], "".join(h for _, _, h in shown), r.version
    )


def write_constraint_report(r: ConstraintReport, out_path: str | Path) -> Path:
    """Write the page of ``r`` to ``out_path`` atomically, stamped with the folder's run id
    (``<meta name="robocal-run">``, :mod:`robocal.outdir`)."""
    from robocal.outdir import atomic_write_text
    from robocal.run_ids import run_id_meta

    page = render_constraint_report(r)
    if r.calibration.run_id is not None:
        head = '<meta charset="utf-8">'
        page = page.replace(head, head + "\n" + run_id_meta(r.calibration.run_id), 1)
    return atomic_write_text(Path(out_path), page)
