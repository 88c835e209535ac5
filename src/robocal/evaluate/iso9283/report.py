"""The fourteen ISO 9283 characteristics of a measurement log, as a table and a report.

:func:`evaluate_log` cuts an :class:`~robocal.evaluate.iso9283.log.Iso9283Log` into runs
(one approach to a pose, one traversal of a path), takes the attained pose of every
approach and hands the arrays to :mod:`robocal.evaluate.iso9283.characteristics` and
:mod:`robocal.evaluate.metrics`.  Every characteristic the log cannot support is listed as
"not measured" with the reason.  :func:`results_html` renders a small self-contained page.

Reading of the log (``docs/iso9283.md``):

* the *attained pose* of a run is the mean of its samples in the last ``tail_s`` seconds
  of its *dwell*, the final stretch in which the commanded pose no longer changes (a
  single-sample run: that sample);
* the "attained pose" signal of §7.4 is taken as the first sample of the dwell;
* the commanded path of a path test is the commanded positions of its first cycle,
  thinned to ``path_points`` and without its two end points.

The characteristics are computed in :mod:`robocal.evaluate.iso9283.eval_pose` (1-7, and the
options and row classes, re-exported here) and :mod:`robocal.evaluate.iso9283.eval_path` (8-14).
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.evaluate.iso9283.eval_path import (
    compliance,
    cornering,
    path,
    positioning,
    reorientation,
    velocity,
    weaving,
)
from robocal.evaluate.iso9283.eval_pose import (
    NAMES,
    Characteristic,
    EvaluationOptions,
    distance,
    drift,
    exchangeability,
    missing,
    multidirectional,
    pose_characteristic,
    pose_visits,
    stabilisation_rows,
)
from robocal.evaluate.iso9283.log import Iso9283Log
from robocal.safe_output import finite_or_none

__all__ = [
    "Characteristic",
    "EvaluationOptions",
    "Iso9283Results",
    "evaluate_log",
    "results_html",
    "results_text",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Iso9283Results:
    """The fourteen characteristics of one log."""

    source: str
    conditions: dict[str, str]
    band: float
    rows: tuple[Characteristic, ...]

    def to_dict(self) -> dict[str, Any]:
        """Plain data (mm, deg, s, %); a value that could not be computed is None."""
        return finite_or_none(
            {
                "source": self.source,
                "conditions": dict(self.conditions),
                "limit_band_mm": self.band * 1e3,
                "characteristics": [
                    {
                        "number": r.number,
                        "name": r.name,
                        "clause": r.clause,
                        "symbols": r.symbols,
                        "measured": r.measured,
                        "summary": r.summary,
                        "cycles": r.cycles,
                        "details": r.details,
                    }
                    for r in self.rows
                ],
            }
        )


# ------------------------------------------------------------------ all
def _band(log: Iso9283Log, opts: EvaluationOptions) -> float:
    if opts.band is not None:
        band = float(opts.band)
    elif "limit_band_mm" in log.conditions:
        try:
            band = float(log.conditions["limit_band_mm"]) * 1e-3
        except ValueError:
            raise ValueError(
                f"{log.source}: header limit_band_mm {log.conditions['limit_band_mm']!r} is not a number"
            ) from None
    else:
        band = 1e-4
    if not (math.isfinite(band) and band > 0):
        raise ValueError(f"{log.source}: the limit band must be > 0 mm, got {band * 1e3:g}")
    return band


def evaluate_log(log: Iso9283Log, options: EvaluationOptions | None = None) -> Iso9283Results:
    """The fourteen ISO 9283 characteristics of ``log`` (those it cannot support are
    listed as not measured, with the reason)."""
    opts = options or EvaluationOptions()
    band = _band(log, opts)

    def guarded(number: int, build: Callable[[], Any]) -> Any:
        """``build()``, or its rows as not measured when the log's data defeat it."""
        try:
            return build()
        except (ValueError, np.linalg.LinAlgError) as err:
            count = 2 if number == 4 else 1
            out = tuple(missing(*NAMES[number + k], f"the data do not allow it: {err}") for k in range(count))
            return out if count == 2 else out[0]

    pose = pose_visits(log, "pose", opts)
    stab, over = guarded(4, lambda: stabilisation_rows(log, pose, band))
    rows = (
        guarded(1, lambda: pose_characteristic(log, pose)),
        guarded(2, lambda: multidirectional(log, opts)),
        guarded(3, lambda: distance(log, opts)),
        stab,
        over,
        guarded(6, lambda: drift(log, opts)),
        guarded(7, lambda: exchangeability(log, opts)),
        guarded(8, lambda: path(log, opts)),
        guarded(9, lambda: reorientation(log, opts)),
        guarded(10, lambda: cornering(log, opts)),
        guarded(11, lambda: velocity(log, opts)),
        guarded(12, lambda: positioning(log, opts, band)),
        guarded(13, lambda: compliance(log)),
        guarded(14, lambda: weaving(log)),
    )
    return Iso9283Results(log.source, dict(log.conditions), band, rows)


# ------------------------------------------------------------------ output
def results_text(results: Iso9283Results) -> list[tuple[str, str, str, str, str]]:
    """Table rows ``(#, characteristic, clause, result, cycles)`` as plain text."""
    return [(str(r.number), f"{r.name} ({r.symbols})", r.clause, r.summary, r.cycles) for r in results.rows]


def _cell(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return "-" if not math.isfinite(v) else f"{v:.4g}"
    if isinstance(v, list):
        return ", ".join(_cell(x) for x in v)
    return str(v)


def results_html(results: Iso9283Results, title: str = "ISO 9283 characteristics") -> str:
    """A small self-contained HTML page: conditions, the table, the details of each row.
    Every string from the log is escaped."""
    e = html.escape
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>{e(title)}</title><style>body{{font-family:sans-serif;margin:2em}}"
        "table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #bbb;padding:.25em .6em;"
        "text-align:left;vertical-align:top}.no{color:#777}</style></head><body>",
        f"<h1>{e(title)}</h1><p>log: <code>{e(results.source)}</code>; limit band {results.band * 1e3:g} mm. "
        "Clauses of ISO 9283:1998; how robocal reads them: docs/iso9283.md.</p>",
    ]
    if results.conditions:
        parts.append("<h2>Test conditions</h2><table>")
        parts += [f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in results.conditions.items()]
        parts.append("</table>")
    parts.append(
        "<h2>Characteristics</h2><table><tr><th>#</th><th>characteristic</th><th>clause</th>"
        "<th>result</th><th>cycles</th></tr>"
    )
    for r in results.rows:
        cls = "" if r.measured else " class='no'"
        parts.append(
            f"<tr{cls}><td>{r.number}</td><td>{e(r.name)} ({e(r.symbols)})</td><td>{e(r.clause)}</td>"
            f"<td>{e(r.summary)}</td><td>{e(r.cycles)}</td></tr>"
        )
    parts.append("</table>")
    for r in results.rows:
        if not r.details:
            continue
        keys = list(dict.fromkeys(k for d in r.details for k in d))
        parts.append(
            f"<h3>{r.number}. {e(r.name)}</h3><table><tr>"
            + "".join(f"<th>{e(k)}</th>" for k in keys)
            + "</tr>"
        )
        for d in r.details:
            parts.append("<tr>" + "".join(f"<td>{e(_cell(d.get(k)))}</td>" for k in keys) + "</tr>")
        parts.append("</table>")
    parts.append("</body></html>")
    return "\n".join(parts)
