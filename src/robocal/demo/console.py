"""What the demo shows: its progress over the steps, its closing numbers and the table it prints."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any


def summary_numbers(result, before, after, after_geo, ev, seconds, report_path) -> dict[str, Any]:
    from robocal.evaluate.error_tables import improvement
    from robocal.evaluate.metrics import iso9283_pose_characteristics, path_accuracy

    out: dict[str, Any] = {
        "robot": ev["robot"],
        "seconds": seconds,
        "report": None if report_path is None else str(report_path),
        "calibration_rms_mm": {"before": result.rms_before * 1e3, "after": result.rms_after * 1e3},
        "held_out": {
            "before": None if before is None else before.to_dict(),
            "geometric": after_geo.to_dict(),
            "after": after.to_dict(),
        },
        "condition_number": result.condition_number,
        "fit_to_noise": ev.get("fit_to_noise"),
        "identified": len(result.names),
        "dropped": len(result.dropped),
    }
    if before is not None:
        out["held_out_improvement"] = improvement(before.errors * 1e3, after.errors * 1e3).to_dict()
    iso = ev.get("iso_poses")
    if iso:
        out["iso9283"] = {}
        for case, attained in iso["cases"].items():
            ch = iso9283_pose_characteristics(iso["commanded"], attained, iso["labels"])
            out["iso9283"][case] = {
                "AP_max_mm": max(a.AP for a in ch.accuracy) * 1e3,
                "RP_max_mm": max(r.RP for r in ch.repeatability) * 1e3,
            }
        for path in ev.get("paths", []):
            for case, attained in path["cases"].items():
                pa = path_accuracy(path["commanded"], attained)
                out["iso9283"].setdefault(case, {})[f"AT {path['name']} mm"] = pa.AT * 1e3
        out["compensation"] = ev.get("compensation", {}).get("method")
    return out


def print_summary(numbers: Mapping[str, Any]) -> None:
    from rich.table import Table

    from robocal.console import console, safe
    from robocal.identify.noise_check import FitToNoise

    held = numbers["held_out"]
    table = Table(title=f"robocal demo — {numbers['robot']}: held-out poses", title_justify="left")
    for col in ("model", "mean mm", "RMS mm", "p95 mm", "max mm"):
        table.add_column(col, justify="left" if col == "model" else "right")
    rows = [
        ("before calibration (nominal)", held["before"]),
        ("geometric calibration", held["geometric"]),
        ("geometry + joint compliance", held["after"]),
    ]
    for name, s in rows:
        if s:
            table.add_row(
                name, f"{s['mean_mm']:.3f}", f"{s['rms_mm']:.3f}", f"{s['p95_mm']:.3f}", f"{s['max_mm']:.3f}"
            )
    console.print(table)
    for name, fit in (numbers.get("fit_to_noise") or {}).items():
        if fit:
            console.print(f"{name}: {FitToNoise.from_dict(fit).summary()}", highlight=False)
    imp = numbers.get("held_out_improvement")
    if imp:
        console.print(
            f"mean held-out error {imp['mean_before']:.3f} mm → {imp['mean_after']:.3f} mm: "
            f"{imp['percent']:.1f} % smaller (95 % CI "
            f"{imp['percent_low']:.1f} to {imp['percent_high']:.1f} %)",
            highlight=False,
        )
    iso = numbers.get("iso9283")
    if iso:
        cases = list(iso)
        t2 = Table(title="ISO 9283 in the test cube (robot base frame)", title_justify="left")
        t2.add_column("characteristic mm")
        for case in cases:
            t2.add_column(case.replace(" commands", ""), justify="right")
        keys = list(dict.fromkeys(k for case in cases for k in iso[case]))
        for k in keys:
            label = k.replace("_max_mm", " (worst of P1-P5)").replace(" mm", "")
            t2.add_row(label, *(f"{iso[c].get(k, float('nan')):.3f}" for c in cases))
        console.print(t2)
        console.print(f"compensation: {numbers.get('compensation')}", highlight=False)
    console.print(
        f"calibration RMS {numbers['calibration_rms_mm']['before']:.3f} mm → "
        f"{numbers['calibration_rms_mm']['after']:.4f} mm, condition "
        f"number {numbers['condition_number']:.3g}; "
        f"total {numbers['seconds']:.1f} s",
        highlight=False,
    )
    if numbers.get("report"):
        console.print(f"[bold]report:[/] {safe(numbers['report'])}", highlight=False, markup=True)


if TYPE_CHECKING:
    from rich.progress import Progress


class Steps:
    """Rich progress over the demo's steps, or silence."""

    def __init__(self, names: list[str], verbose: bool) -> None:
        self.names = names
        self.verbose = verbose
        self.timings: dict[str, float] = {}
        self._progress: Progress | None = None  # while the steps run with verbose output

    @contextlib.contextmanager
    def running(self) -> Iterator[Steps]:
        if not self.verbose:
            yield self
            return
        from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        from robocal.console import console
        from robocal.identify.kernel_cache import first_use

        with (
            first_use(console),
            Progress(
                SpinnerColumn(),
                TextColumn("[progress.description]{task.description}"),
                BarColumn(),
                TextColumn("{task.completed}/{task.total}"),
                TimeElapsedColumn(),
                console=console,
                transient=False,
            ) as progress,
        ):
            self._progress = progress
            self._task = progress.add_task("robocal demo", total=len(self.names))
            yield self
            progress.update(self._task, description="robocal demo: done")
        self._progress = None

    @contextlib.contextmanager
    def step(self, name: str) -> Iterator[None]:
        if self._progress is not None:
            self._progress.update(self._task, description=name)
        t = time.perf_counter()
        yield
        self.timings[name] = time.perf_counter() - t
        if self._progress is not None:
            self._progress.advance(self._task)
