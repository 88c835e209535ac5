"""A study's summary: per (pose set, device) statistics (``summary.json``) and their box plot
(``summary.png``), written together with one run id."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.outdir import write_together
from robocal.run_ids import figure_png, new_run_id
from robocal.safe_output import strict_json
from robocal.study.config import StudyConfig, StudyError

Array = NDArray[np.float64]


def _floats(rows: Sequence[Mapping[str, str]], column: str) -> Array:
    out = []
    for r in rows:
        try:
            v = float(r[column])
        except (KeyError, ValueError):
            continue
        if math.isfinite(v):
            out.append(v)
    return np.array(out)


def _summarise(config: StudyConfig, rows: Iterable[Mapping[str, str]]) -> dict[str, Any]:
    """Per (pose set, device): counts and statistics of the ok rows (mm)."""
    rows = list(rows)
    groups = []
    for s in config.pose_sets:
        for d in config.devices:
            mine = [r for r in rows if r["pose_set"] == s.name and r["device"] == d.name]
            ok = [r for r in mine if r["status"] == "ok"]
            entry: dict[str, Any] = {
                "pose_set": s.name,
                "device": d.name,
                "cases": len(mine),
                "ok": len(ok),
                "not_converged": sum(r["status"] == "not-converged" for r in mine),
                "failed": sum(r["status"] == "failed" for r in mine),
                "errors": sum(r["status"] == "error" for r in mine),
            }
            for col in ("true_rms_mm", "val_rms_mm", "rms_after_mm", "rms_before_mm"):
                v = _floats(ok, col)
                if len(v):
                    entry[col] = {
                        "mean": float(v.mean()),
                        "median": float(np.median(v)),
                        "p95": float(np.percentile(v, 95)),
                        "max": float(v.max()),
                    }
            groups.append(entry)
    robot = config.robot if config.robot is not None else f"built from {config.geometry}"
    return {"study": config.name, "robot": robot, "robots": config.robots, "groups": groups}


def read_study_summary(out: str | Path) -> dict[str, Any]:
    """A study's ``summary.json``; refuses a ``summary.png`` of another run beside it (a
    run killed between the two renames, or a file copied in by hand).

    Raises:
        StudyError: naming both files and their run ids, or ``summary.json`` when it is
            missing or not a summary.
    """
    import json

    from robocal.run_ids import read_run_id

    out = Path(out)
    path, png = out / "summary.json", out / "summary.png"
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise StudyError(f"{path}: cannot read the study summary ({err.__class__.__name__})") from None
    if not isinstance(summary, dict):
        raise StudyError(f"{path}: not a study summary")
    want = summary.get("run_id")
    got = read_run_id(png) if png.is_file() else want
    if got != want:
        raise StudyError(
            f"{path} is run {want or 'none'} but {png} is run {got or 'none'}: the two were not written "
            "together; run the study again (it resumes) to write both"
        )
    return summary


def _summary_png(config: StudyConfig, rows: Iterable[Mapping[str, str]], run_id: str) -> bytes:
    """Box plot of the held-out error against the true robot per (pose set, device), as PNG
    bytes (``run_id`` in its ``Description``, the ``run_id`` of ``summary.json``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(rows)
    labels, values = [], []
    for s in config.pose_sets:
        for d in config.devices:
            v = _floats(
                [
                    r
                    for r in rows
                    if r["pose_set"] == s.name and r["device"] == d.name and r["status"] == "ok"
                ],
                "true_rms_mm",
            )
            labels.append(f"{s.name}\n{d.name}\n({len(v)} robots)")
            values.append(v if len(v) else np.array([np.nan]))
    fig, ax = plt.subplots(figsize=(max(4.0, 1.6 * len(labels)), 4.0), dpi=100)
    ax.boxplot(values, showfliers=True)
    ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=8)
    ax.set_ylabel("held-out RMS error vs. the true robot (mm)")
    robot = Path(config.robot or config.geometry or "").stem
    ax.set_title(f"{config.name}: {config.robots} virtual robots ({robot})", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return figure_png(fig, run_id=run_id)


def write_summary(
    out: Path, config: StudyConfig, rows: Sequence[Mapping[str, str]], seconds: float, computed: int
) -> dict[str, Any]:
    """Write ``out/summary.json`` and ``out/summary.png`` of ``rows`` (both of this run or
    neither) and return the summary; ``seconds`` and ``computed`` give its throughput."""
    summary = _summarise(config, rows)
    summary["seconds"] = seconds
    summary["calibrations_per_second"] = computed / seconds if seconds > 0 else 0.0
    summary["run_id"] = new_run_id()
    write_together(  # the summary and its plot: both of this run or neither
        {
            out / "summary.json": (strict_json(summary, indent=2) + "\n").encode("utf-8"),
            out / "summary.png": _summary_png(config, rows, summary["run_id"]),
        }
    )
    return summary
