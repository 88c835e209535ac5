"""The report's content from an *evaluation* (ISO 9283 poses and paths, an ISO 9283 log,
compensation, timings) and the model choice: part of
:func:`robocal.evaluate.report.collect.collect_report`.

An evaluation is plain JSON-able data (``evaluation.json``, possibly from elsewhere): a
part of the wrong shape is a ``ValueError`` naming the part, never a traceback."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np

from robocal.evaluate.metrics import iso9283_pose_characteristics, path_accuracy
from robocal.evaluate.report.data import (
    CompensationData,
    IsoData,
    IsoLogData,
    LearnedCurve,
    ModelChoiceData,
    PathData,
    ResultFacts,
)

__all__ = ["compensation", "evaluation_part", "iso_data", "iso_log", "model_choice", "timings"]


@contextmanager
def evaluation_part(name: str) -> Iterator[None]:
    """Turns a malformed evaluation part into one clear ``ValueError``."""
    try:
        yield
    except (KeyError, TypeError, IndexError, AttributeError, ValueError) as err:
        raise ValueError(
            f"evaluation: {name!r} is not of the expected shape ({type(err).__name__}: {err})"
        ) from None


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else None


def _path(path: Mapping[str, Any]) -> PathData:
    c = np.asarray(path["commanded"], dtype=float)
    along = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))] * 1e3
    accuracy = {str(case): path_accuracy(c, attained) for case, attained in path["cases"].items()}
    return PathData(name=str(path["name"]), along_mm=along, accuracy=accuracy)


def iso_data(ev: Mapping[str, Any]) -> tuple[IsoData | None, str | None]:
    """ISO 9283 characteristics of the evaluation's poses and paths, or (None, why not)."""
    iso = ev.get("iso_poses") or {}
    with evaluation_part("iso_poses"):
        poses = {
            str(case): iso9283_pose_characteristics(iso["commanded"], attained, iso["labels"])
            for case, attained in (iso.get("cases") or {}).items()
        }
    with evaluation_part("paths"):
        paths = tuple(_path(p) for p in ev.get("paths") or [])
    if not poses and not paths:
        error = ev.get("iso_error")
        return None, None if not error else str(error)
    cube = iso.get("cube") or {}
    cycles = iso.get("cycles")
    plane = cube.get("plane")
    return (
        IsoData(
            poses=poses,
            cycles=int(cycles) if isinstance(cycles, int) else None,
            cube_side_m=_number(cube.get("side")),
            cube_plane=int(plane) if isinstance(plane, int) else None,
            paths=paths,
        ),
        None,
    )


def iso_log(ev: Mapping[str, Any]) -> IsoLogData | None:
    """The characteristics table of ``robocal iso9283 --json`` (``Iso9283Results.to_dict()``)."""
    iso = ev.get("iso9283")
    if not iso:
        return None
    with evaluation_part("iso9283"):
        rows = tuple(
            (
                str(c["number"]),
                f"{c['name']} ({c['symbols']})",
                str(c["clause"]),
                str(c["summary"]),
                str(c["cycles"]),
            )
            for c in iso.get("characteristics", [])
        )
        return IsoLogData(
            source=str(iso.get("source", "an unnamed log")),
            band_mm=_number(iso.get("limit_band_mm")),
            rows=rows,
        )


def compensation(ev: Mapping[str, Any]) -> Any | None:
    """The compensation's method and settings, as text."""
    comp = ev.get("compensation")
    if not comp:
        return None
    with evaluation_part("compensation"):
        items = [("method", str(comp.get("method", "not stated")))]
        for key, value in comp.items():
            if key == "method" or value is None:
                continue
            text = f"{value:.4g}" if isinstance(value, float) else str(value)
            items.append((str(key).replace("_", " "), text))
    return CompensationData(items=tuple(items))


def timings(ev: Mapping[str, Any]) -> tuple[tuple[str, float], ...]:
    """The steps' times (s) of the evaluation, those that are numbers."""
    with evaluation_part("timings_s"):
        raw = ev.get("timings_s") or {}
        return tuple((str(k), float(v)) for k, v in raw.items() if _number(v) is not None)


def model_choice(facts: ResultFacts) -> ModelChoiceData | None:
    """The cross-validation table and, when chosen, the learned joint angle errors."""
    table = facts.cv
    if table is None:
        return None
    learned = facts.model.residual
    curves: list[LearnedCurve] = []
    if learned is not None:
        for k, (name, j) in enumerate(zip(learned.joints, learned.joint_index, strict=True)):
            lo, hi = np.clip(facts.model.joint_limits[j], -math.pi, math.pi)
            q = np.zeros((400, facts.model.dof))
            q[:, j] = np.linspace(lo, hi, 400)
            curves.append(LearnedCurve(str(name), np.degrees(q[:, j]), learned.angle_errors(q)[:, k] * 1e6))
    return ModelChoiceData(
        candidates=tuple((c.name, c.cv_mean, c.cv_rms, c.fit_seconds) for c in table.candidates),
        chosen=table.chosen,
        folds=table.folds,
        curves=tuple(curves),
        harmonics=None if learned is None else int(learned.harmonics),
        noise_std_m=None if learned is None else float(learned.noise_std),
    )
