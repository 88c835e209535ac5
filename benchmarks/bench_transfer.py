"""Calibrate once, re-register later: series A's first four days -> its last day (issue 34).

The proxy of the issue's transfer check on the real UR10 (series A, 14-18 July 2020): the
default (``rc.calibrate(..., residual="auto")``, what ``robocal calibrate`` does, the tracker's
noise stated as ``--noise 0.03mm``) calibrated on 100 / 300 / 1,000 random rows of 14-17
July; on 18 July the robot is kept frozen and only the tracker frame is fitted
(:func:`robocal.identify.register.fit_frame`, what ``robocal register`` does) on 20 / 30 / 50
random rows of that day, and judged on the rest of the day (1,900+ rows it did not see).

Printed per training size and number of registration rows (means over the seeds): the
held-out mean, RMS, p95 and max error (mm), the expected RMS the registration states over
the measured RMS (the issue asks 0.8-1.25), the K-fold score's ratio on the registration rows
alone (``robocal register``'s own figure, all a user has), and two references on the same
rows: the source calibration's own frame (no re-registration: the tracker was moved between
days or not) and a fresh default calibration on the registration rows alone.

Run: ``python benchmarks/bench_transfer.py [--seeds 3] [--sizes 100,300,1000] [--rows 20,30,50]``
(about 2 minutes).  Also ``python benchmarks/bench_real_accuracy.py --transfer``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import warnings

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import robocal as rc
from robocal.identify.register import fit_frame, frozen_robot, score_registration

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_real_accuracy import DATA, PROBE, read  # the one reader of series A

NOISE_M = 0.03e-3  # the tracker's noise per axis, as the CLI's --noise 0.03mm
LAST_DAY = "18"


def _days() -> tuple[rc.Measurements, rc.Measurements]:
    """Series A's rows of 14-17 July and of 18 July, each with the tracker's noise stated."""
    data = read(DATA)
    stamp = np.loadtxt(DATA, delimiter=";", skiprows=1, usecols=0, dtype=str)  # yyyymmddHHMMSS
    last = np.array([s[6:8] == LAST_DAY for s in stamp])
    out = []
    for rows in (np.flatnonzero(~last), np.flatnonzero(last)):
        part = data.subset(rows)
        out.append(dataclasses.replace(part, sigma=np.full((part.n, 3), NOISE_M)))
    return out[0], out[1]


def _errors(predicted: np.ndarray, measured: np.ndarray) -> np.ndarray:
    return np.linalg.norm(predicted - measured, axis=1)


def transfer_rows(result: rc.CalibrationResult, last: rc.Measurements, m: int, seed: int) -> dict[str, float]:
    """One registration on ``m`` random rows of the last day, judged on the rest (m, ratios)."""
    order = np.random.default_rng(seed).permutation(last.n)
    few, rest = last.subset(order[:m]), last.subset(order[m:])
    robot = frozen_robot(result, few)
    fit = fit_frame(robot, few.position)
    held = frozen_robot(result, rest)
    e = _errors(fit.predict(held), rest.position)
    rms = float(np.sqrt(np.mean(e**2)))
    own = _errors(result.predict(rest.q)[:, :3, 3], rest.position)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fresh = rc.calibrate(rc.calibration_model("ur10", "position"), few, tool_guess=PROBE, residual="auto")
    fresh_e = _errors(fresh.predict(rest.q)[:, :3, 3], rest.position)
    return {
        "mean": float(e.mean()), "rms": rms, "p95": float(np.percentile(e, 95)), "max": float(e.max()),
        "ratio": float(np.sqrt(np.mean(fit.expected_ms(held)))) / rms,
        "kfold_ratio": float(score_registration(robot, few.position).ratio),
        "own_frame": float(own.mean()), "fresh": float(fresh_e.mean()),
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--sizes", default="100,300,1000")
    parser.add_argument("--rows", default="20,30,50", help="registration rows of the last day")
    args = parser.parse_args(argv)
    first, last = _days()
    print(f"series A: {first.n} rows of 14-17 July -> {last.n} rows of 18 July; {args.seeds} seeds; "
          f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")  # fmt: skip
    print("| calibrated on (14-17 July) | registered on (18 July) | held-out mean mm | RMS | p95 | max | "
          "expected / measured RMS | K-fold ratio (register's own) | no re-registration: mean | "
          "fresh default on the registration rows: mean |")  # fmt: skip
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in (int(s) for s in args.sizes.split(",")):
        rows: dict[int, list[dict[str, float]]] = {}
        for seed in range(args.seeds):
            train = first.subset(np.random.default_rng(seed).permutation(first.n)[:n])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = rc.calibrate(rc.calibration_model("ur10", "position"), train, tool_guess=PROBE,
                                      residual="auto")  # fmt: skip
            for m in (int(s) for s in args.rows.split(",")):
                rows.setdefault(m, []).append(transfer_rows(result, last, m, seed))
            print(f"  {n} poses, seed {seed} done", file=sys.stderr, flush=True)
        for m, runs in rows.items():
            v = {k: np.mean([r[k] for r in runs]) for k in runs[0]}
            mm = {k: v[k] * 1e3 for k in ("mean", "rms", "p95", "max", "own_frame", "fresh")}
            print(f"| {n} | {m} | {mm['mean']:.3f} | {mm['rms']:.3f} | {mm['p95']:.3f} | {mm['max']:.3f} | "
                  f"{v['ratio']:.2f} | {v['kfold_ratio']:.2f} | {mm['own_frame']:.3f} | {mm['fresh']:.3f} |",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
