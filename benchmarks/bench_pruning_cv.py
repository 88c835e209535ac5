"""The pruning threshold ``max_std_ratio`` chosen by cross-validation on training poses only.

``rc.calibrate`` fixes a parameter whose σ (as tool displacement) exceeds both
``max_std`` and ``max_std_ratio`` times the median σ.  Its default was once picked by the
error on *held-out* data; this benchmark re-derives it the honest way: for each real data
set, k-fold cross-validation on the training poses alone (``rc.cross_validate``), for each
candidate ratio, and the ratio with the lowest CV error over the data sets is reported.

Data sets: the real UR10 (series A; 100 and 300 random training rows, seeds 0-2; the
complete model with compliance) and FIGAROH's TIAGo training day (37 postures, the
complete model built from its URDF).  Run: ``python benchmarks/bench_pruning_cv.py``
(about a minute).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import robocal as rc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_peers import TIP, TRAIN, URDF, _load
from bench_real_accuracy import DATA, PROBE, read

RATIOS = (3.0, 5.0, 7.0, 10.0, 30.0)


def cv_error(model: rc.Model, data: rc.Measurements, ratio: float, **options) -> float:
    """Mean held-out-fold RMS position error (m) of 5-fold CV on ``data``."""
    folds = rc.cross_validate(model, data, k=5, seed=0, max_std_ratio=ratio, **options)
    return float(np.mean([f.rms for f in folds]))


def main() -> None:
    from robocal.model.urdf.read import build_from_urdf

    cases: list[tuple[str, rc.Model, rc.Measurements, dict]] = []
    series_a = read(DATA)
    complete = rc.calibration_model("ur10", "position")
    for n in (100, 300):
        for seed in range(3):
            train = series_a.with_split(n, seed=seed).split_rows("train")
            cases.append((f"UR10 series A, {n} poses, seed {seed}", complete, train, {"compliance": True}))
    tiago = build_from_urdf(URDF, "position", TIP).model
    q, p = _load(TRAIN)
    cases.append(("TIAGo (FIGAROH), 37 postures", tiago, rc.Measurements(q=q, position=p), {}))
    print("| data (5-fold CV on the training poses) | " + " | ".join(f"{r:g}" for r in RATIOS) + " |")
    print("|---|" + "---:|" * len(RATIOS))
    relative = []
    for name, model, data, options in cases:
        errors = np.array([cv_error(model, data, r, tool_guess=PROBE if "UR10" in name else None, **options)
                           for r in RATIOS])  # fmt: skip
        relative.append(errors / errors.min())
        print(f"| {name} | " + " | ".join(f"{e * 1e3:.4f}" for e in errors) + " |")
    mean_relative = np.mean(relative, axis=0)
    print("| mean CV error / best of its row | " + " | ".join(f"{v:.4f}" for v in mean_relative) + " |")
    print(f"lowest mean relative CV error: max_std_ratio = {RATIOS[int(np.argmin(mean_relative))]:g}")


if __name__ == "__main__":
    main()
