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
  ``robocal.identify.residual.stage``), so the residual adds O(m²) + one chunk; the physical
  fit's Jacobians are O(n p).

The 10,000-pose fits (issue 20's target: the hybrid ≤ 30 s) report wall and CPU time of
the fit in the child (on a shared machine the wall time also counts waiting for a core).

Run: ``python benchmarks/bench_residual.py [--repeats 3] [--md docs/tutorials/ur10-real.md]`` (``--md``
writes the table into the UR10 tutorial's ``<!-- bench:residual -->`` block).
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
import readme_table
from bench_real_accuracy import DATA, PROBE, read


def _median_time(fn, repeats: int) -> tuple[float, float, object]:
    """Median CPU and wall seconds of ``fn()`` over ``repeats`` calls, and its last result."""
    cpu, wall, out = [], [], None
    for _ in range(repeats):
        c, w = time.process_time(), time.perf_counter()
        out = fn()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return float(np.median(cpu)), float(np.median(wall)), out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--md", metavar="PAGE", help="write the bench:residual block")
    args = parser.parse_args(argv)
    if args.md and (why := readme_table.check(args.md, "residual")):
        parser.error(why)
    load_start = readme_table.load()
    data = read(DATA)
    model = rc.calibration_model("ur10", "position")
    train = data.with_split(1000, seed=0).split_rows("train")
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}, "
        f"BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}"
    )
    t_phys, w_phys, physics = _median_time(
        lambda: rc.calibrate(model, train, tool_guess=PROBE, compliance=True), args.repeats
    )
    t_hybrid, w_hybrid, hybrid = _median_time(
        lambda: rc.calibrate(model, train, tool_guess=PROBE, residual="auto"), args.repeats
    )
    learned = hybrid.model.residual
    chosen = hybrid.metadata["cv"]["chosen"]
    print(
        f"fit, 1,000 poses (CPU): physics (complete + compliance) {t_phys:.3f} s; "
        f"default hybrid path {t_hybrid:.2f} s ({t_hybrid / t_phys:.0f}x the physics; chosen: {chosen})"
    )
    q = data.q[:10000]
    hybrid.predict(q[:10])
    t_pred, w_pred, _ = _median_time(lambda: hybrid.predict(q), args.repeats)
    t_pred_phys, w_pred_phys, _ = _median_time(lambda: physics.predict(q), args.repeats)
    size = 0 if learned is None else learned.size
    print(
        f"prediction, 10,000 poses (CPU): hybrid {t_pred / len(q) * 1e6:.2f} µs/pose, physics "
        f"{t_pred_phys / len(q) * 1e6:.2f} µs/pose ({t_pred / t_pred_phys:.2f}x); residual size m = {size}"
    )
    big: dict[str, tuple[float, float, float, str]] = {}
    for label, residual in (("data only", None), ("physics", "none"), ("hybrid", "auto")):
        big[label] = _child_peak(residual)
        wall, cpu, rss, chosen_big = big[label]
        print(
            f"10,000 training poses, {label}: {wall:.1f} s wall, {cpu:.1f} s CPU, peak resident memory "
            f"{rss / 1e6:.0f} MB{'; chosen: ' + chosen_big if chosen_big else ''}"
        )
    wall, cpu, rss, chosen_big = big["hybrid"]
    verdict = "met" if cpu <= 30 else "MISSED"  # CPU: on a shared machine the wall time waits for a core
    print(f"target (issue 20): hybrid fit on 10,000 poses <= 30 s: {verdict}")
    if args.md:
        pw, pc, prss, _ = big["physics"]
        rows = [
            ["fit, 1,000 poses, CPU (wall), median", f"{t_phys:.2f} s ({w_phys:.2f} s)",
             f"{t_hybrid:.2f} s ({w_hybrid:.2f} s)", f"{t_hybrid / t_phys:.0f}×", ""],
            ["fit, 10,000 poses, CPU (wall)", f"{pc:.1f} s ({pw:.1f} s)", f"{cpu:.1f} s ({wall:.1f} s)",
             f"{cpu / pc:.1f}×", f"≤ 30 s {verdict}"],
            ["peak resident memory, 10,000 poses (data alone "
             f"{big['data only'][2] / 1e6:.0f} MB)", f"{prss / 1e6:.0f} MB", f"{rss / 1e6:.0f} MB", "", ""],
            ["prediction, 10,000 poses, µs per pose, CPU (wall)",
             f"{t_pred_phys / len(q) * 1e6:.2f} ({w_pred_phys / len(q) * 1e6:.2f})",
             f"{t_pred / len(q) * 1e6:.2f} ({w_pred / len(q) * 1e6:.2f})",
             f"{t_pred / t_pred_phys:.1f}×", ""],
        ]  # fmt: skip
        header = ["real UR10 (series A)", "physics (complete + compliance)", "hybrid (`residual=\"auto\"`)",
                  "ratio", "target (issue 20)"]  # fmt: skip
        body = [
            f"`python benchmarks/bench_residual.py --repeats {args.repeats} "
            "--md docs/tutorials/ur10-real.md`; chosen by "
            f"cross-validation: {chosen} (1,000 poses), {chosen_big} (10,000 poses), m = {size} "
            "coefficients at 1,000 poses:",
            "",
            *readme_table.markdown_table(header, rows),
            "",
            readme_table.machine(load_start),
        ]
        readme_table.write_block(args.md, "residual", "\n".join(body))


def _child(residual: str | None) -> None:
    """In a fresh process: read series A and (unless None) calibrate on 10,000 rows; prints
    the wall and CPU seconds of the fit and the model chosen."""
    data = read(DATA)
    big = data.with_split(10000, seed=0).split_rows("train")
    t0, c0 = time.perf_counter(), time.process_time()
    chosen = "-"
    if residual is not None:
        options = {"compliance": True} if residual == "none" else {}
        result = rc.calibrate(
            rc.calibration_model("ur10", "position"), big, tool_guess=PROBE, residual=residual, **options
        )
        chosen = result.metadata.get("cv", {}).get("chosen", "-").replace(" ", "_")
    print(time.perf_counter() - t0, time.process_time() - c0, chosen)


def _child_peak(residual: str | None) -> tuple[float, float, float, str]:
    """Wall and CPU seconds, peak resident memory (bytes) of :func:`_child` in its own
    process, and the model it chose ("" for none)."""
    import subprocess

    code = (
        f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bench_residual as b; "
        f"b._child({residual!r}); import resource; print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    wall, cpu, chosen, kb = out.stdout.split()[-4:]
    return float(wall), float(cpu), float(kb) * 1e3, "" if chosen == "-" else chosen.replace("_", " ")


if __name__ == "__main__":
    main()
