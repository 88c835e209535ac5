"""The model checks a calibration runs before it fits, timed as ratios (were wall-clock limits
in the tests: tests/test_no_timing.py forbids those).

* ``parameterisation_warnings`` of the UR10's catalog chain (DH, singular for its parallel
  axes), the check ``robocal calibrate --chain catalog`` and ``rc.calibrate`` run on every
  chain, against ``Model.fk`` of 1,000 configurations of the same robot in the same run.

Times are CPU time of this thread (``time.thread_time``: on a shared machine wall time counts
the waiting too), the minimum over ``--rounds`` of one call each, interleaved.

Run: ``python benchmarks/bench_checks.py [--rounds 9]``
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import robocal as rc
from robocal.model.singularity import parameterisation_warnings


def _cpu(call) -> float:
    start = time.thread_time()
    call()
    return time.thread_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=9)
    args = parser.parse_args()
    dh = rc.robot("ur10")
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (1000, dh.dof))
    checks, fks = [], []
    parameterisation_warnings(dh, "position")  # first use: imports and compiled kernels
    dh.fk(q)
    for _ in range(args.rounds):
        checks.append(_cpu(lambda: parameterisation_warnings(dh, "position")))
        fks.append(_cpu(lambda: dh.fk(q)))
    check, fk = min(checks), min(fks)
    print(f"parameterisation_warnings(ur10, position): {check * 1e3:.1f} ms CPU")
    print(f"ur10 Model.fk of 1000 configurations:      {fk * 1e3:.1f} ms CPU")
    print(f"ratio (check / fk of 1000):                {check / fk:.2f}")


if __name__ == "__main__":
    main()
