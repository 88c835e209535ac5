"""Speed and memory of the hybrid model (physics + learned joint angle errors) on the real UR10.

* fit: ``rc.calibrate(calibration_model("ur10"), train, residual="auto")`` on 1,000 random
  rows of series A (5-fold CV over 2 physical variants x 4 candidates, the final joint
  fit and the joint covariance), median of ``--repeats``; the physical fit alone
  (complete + compliance) measured in the same run as the reference;
* prediction: ``result.predict(q)`` for 10,000 poses, per pose, against the physical
  model's own ``predict`` in the same run;
* memory: the peak resident memory of a fresh process that reads the data and calibrates on
  10,000 training poses (physics alone, then the default hybrid path), against one that
  only reads the data.  The residual's design
  matrix is never held whole (its Gram matrix is accumulated over chunks of 2,048 poses,
  ``robocal.identify.residual``), so the residual adds O(m²) + one chunk; the physical
  fit's Jacobians are O(n p).

Run: ``python benchmarks/bench_residual.py [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import robocal as rc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_peers import _median_time
from bench_real_accuracy import DATA, PROBE, read


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    data = read(DATA)
    model = rc.calibration_model("ur10", "position")
    train = data.with_split(1000, seed=0).split_rows("train")
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}, "
        f"BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}"
    )
    t_phys, physics = _median_time(
        lambda: rc.calibrate(model, train, tool_guess=PROBE, compliance=True), args.repeats
    )
    t_hybrid, hybrid = _median_time(
        lambda: rc.calibrate(model, train, tool_guess=PROBE, residual="auto"), args.repeats
    )
    learned = hybrid.model.residual
    print(
        f"fit, 1,000 poses: physics (complete + compliance) {t_phys:.3f} s; "
        f"default hybrid path {t_hybrid:.2f} s "
        f"({t_hybrid / t_phys:.0f}x the physics; chosen: {hybrid.metadata['cv']['chosen']})"
    )
    q = data.q[:10000]
    hybrid.predict(q[:10])
    t_pred, _ = _median_time(lambda: hybrid.predict(q), args.repeats)
    t_pred_phys, _ = _median_time(lambda: physics.predict(q), args.repeats)
    print(
        f"prediction, 10,000 poses: hybrid {t_pred / len(q) * 1e6:.2f} µs/pose, physics "
        f"{t_pred_phys / len(q) * 1e6:.2f} µs/pose ({t_pred / t_pred_phys:.2f}x); residual size m = "
        f"{0 if learned is None else learned.size}"
    )
    for label, residual in (("data only", None), ("physical fit (complete + compliance)", "none"),
                            ("hybrid fit (default path)", "auto")):  # fmt: skip
        seconds, rss = _child_peak(residual)
        print(f"10,000 training poses, {label}: {seconds:.1f} s, peak resident memory {rss / 1e6:.0f} MB")


def _child(residual: str | None) -> None:
    """In a fresh process: read series A and (unless None) calibrate on 10,000 rows."""
    data = read(DATA)
    big = data.with_split(10000, seed=0).split_rows("train")
    t0 = time.perf_counter()
    if residual is not None:
        options = {"compliance": True} if residual == "none" else {}
        rc.calibrate(
            rc.calibration_model("ur10", "position"), big, tool_guess=PROBE, residual=residual, **options
        )
    print(time.perf_counter() - t0)


def _child_peak(residual: str | None) -> tuple[float, float]:
    """Seconds and peak resident memory (bytes) of :func:`_child` in its own process."""
    import subprocess

    code = (
        f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bench_residual as b; "
        f"b._child({residual!r}); import resource; print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    seconds, kb = out.stdout.split()[-2:]
    return float(seconds), float(kb) * 1e3


if __name__ == "__main__":
    main()
