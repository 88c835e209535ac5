"""Levenberg-Marquardt: the compiled iteration (robocal.identify.kernels.lm) against its numpy
reference (``tests/reference_lm.py``: ``levenberg_marquardt_batch_numpy``), in the same run.

The problem is ``bench_calibrate``'s: a 100-pose UR10 (27 unknowns, 300 weighted residuals),
captured where ``rc.calibrate`` calls the solver.  Rows (per call):

* one evaluation (residuals + Jacobian at a new point): what the solver cannot save;
* ``solvers.solve`` with the problem's cache emptied before each call (its three
  evaluations computed), and the solver alone: the same solve with the three evaluations
  replayed from memory (what the iteration costs besides them);
* ``rc.calibrate`` end to end;
* the batched engine of a study (:class:`robocal.identify.batch`, 50 robots at once);
* the first call of a new process (numba loading the kernels from its cache).

Minimum over rounds of the mean of a batch of calls, as CPU time of this thread
(``time.thread_time``, one BLAS thread); numpy and compiled rounds interleaved.  The two
iterations are checked to give the same solution, iterations and evaluations first.

Run: ``python benchmarks/bench_lm.py [--rounds 7] [--md docs/performance.md]`` (``--md`` writes the page's
``<!-- bench:lm -->`` block).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import timeit

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(1, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests.reference_lm
from tests.reference_lm import levenberg_marquardt_batch_numpy  # the numpy reference: the tests'

import readme_table
import robocal as rc
import robocal.identify.batch as batch_engine
import robocal.identify.pipeline as pipeline
from bench_calibrate import problem
from robocal.identify import solvers

FIRST_CALL = """
import time
import numpy as np
from robocal.identify.solvers import levenberg_marquardt
class P:
    t = np.linspace(0.0, 2.0, 40)
    y = 1.5 * np.exp(-0.7 * t) + 0.2
    def residual(self, x):
        return x[0] * np.exp(x[1] * self.t) + x[2] - self.y
    def jacobian(self, x):
        e = np.exp(x[1] * self.t)
        return np.column_stack([e, x[0] * self.t * e, np.ones_like(self.t)])
t0 = time.perf_counter()
levenberg_marquardt(P(), np.array([1.0, 0.0, 0.0]))
t1 = time.perf_counter()
levenberg_marquardt(P(), np.array([1.0, 0.0, 0.0]))
print(t1 - t0, time.perf_counter() - t1)
"""


class _Numpy:
    """Within: the numpy iteration in place of the compiled one (the solver, the engine)."""

    def __enter__(self):
        self.saved = solvers.levenberg_marquardt_batch, batch_engine.levenberg_marquardt_batch
        solvers.levenberg_marquardt_batch = levenberg_marquardt_batch_numpy
        batch_engine.levenberg_marquardt_batch = levenberg_marquardt_batch_numpy

    def __exit__(self, *exc):
        solvers.levenberg_marquardt_batch, batch_engine.levenberg_marquardt_batch = self.saved


def best(fns: dict, rounds: int, budget: float = 0.1) -> dict[str, float]:
    """CPU seconds per call of each function: the minimum over ``rounds`` (interleaved) of
    the mean of a batch of calls."""
    number = {}
    for name, fn in fns.items():
        fn()
        number[name] = max(1, int(budget / max(timeit.timeit(fn, number=1), 1e-7)))
    out = dict.fromkeys(fns, float("inf"))
    for _ in range(rounds):
        for name, fn in fns.items():
            t = time.thread_time()
            for _ in range(number[name]):
                fn()
            out[name] = min(out[name], (time.thread_time() - t) / number[name])
    return out


def captured_problem(model, data):
    """The problem, start values and options ``rc.calibrate`` hands the solver."""
    calls = []
    solve = pipeline.solve

    def spy(prob, x0, method="lm", **options):
        calls.append((prob, np.array(x0), method, options))
        return solve(prob, x0, method, **options)

    pipeline.solve = spy
    try:
        rc.calibrate(model, data)
    finally:
        pipeline.solve = solve
    return calls[0]


def levenberg_marquardt_numpy(problem, x0, **options):
    with _Numpy():
        return solvers.levenberg_marquardt(problem, x0, **options)


class _Replay:
    """A problem whose evaluations are those of one solve of ``prob`` from ``x0``, recorded:
    a solve from ``x0`` on it costs the solver's own work only."""

    def __init__(self, prob, x0, max_evaluations: int) -> None:
        self.points, self.r, self.J, self.i = [], [], [], 0

        self.prob, self.recording = prob, True
        prob._cache.clear()
        solvers.levenberg_marquardt(self, x0, max_iterations=max_evaluations)
        self.recording, self.checking = False, True
        for iteration in (solvers.levenberg_marquardt, levenberg_marquardt_numpy):
            iteration(self.rewound(), x0, max_iterations=max_evaluations)
        self.checking = False

    def rewound(self):
        self.i = 0
        return self

    def residual(self, x):
        if self.recording:
            self.points.append(np.array(x))
            self.r.append(self.prob.residual(x).copy())
            self.J.append(self.prob.jacobian(x).copy(order="K"))
            return self.r[-1]
        if self.checking:  # on the recorded path (checked once, untimed)
            np.testing.assert_allclose(x, self.points[self.i], rtol=1e-9, atol=1e-12)
        return self.r[self.i]

    def jacobian(self, x):
        if self.recording:
            return self.J[-1]
        self.i += 1
        return self.J[self.i - 1]


class _BatchReplay:
    """The first batched solve of ``calibrate_batch(model, datas)``, its evaluations recorded:
    ``run(iteration)`` repeats it with them replayed (the solver's own work only)."""

    def __init__(self, model, datas) -> None:
        calls = []

        def spy(evaluate, x0, **options):
            calls.append((evaluate, np.array(x0), options))
            return levenberg_marquardt_batch_numpy(evaluate, x0, **options)

        batch_engine.levenberg_marquardt_batch = spy
        try:
            batch_engine.calibrate_batch(model, datas)
        finally:
            batch_engine.levenberg_marquardt_batch = solvers.levenberg_marquardt_batch
        evaluate, self.x0, self.options = calls[0]
        self.tape = []

        def recorded(x, which):
            r, J = evaluate(x, which)
            self.tape.append((np.array(which), r, J))
            return r, J

        self.reference = levenberg_marquardt_batch_numpy(recorded, self.x0, **self.options)
        self.robots = len(self.x0)

    def run(self, iteration) -> None:
        tape = iter(self.tape)

        def replayed(x, which):
            expected, r, J = next(tape)
            assert len(which) == len(expected)
            return r, J

        iteration(replayed, self.x0, **self.options)


def check_same(prob, x0, method, options) -> None:
    prob._cache.clear()
    fast = solvers.solve(prob, x0, method, **options)
    with _Numpy():
        prob._cache.clear()
        ref = solvers.solve(prob, x0, method, **options)
    assert (fast.iterations, fast.evaluations, fast.success) == (ref.iterations, ref.evaluations, ref.success)
    np.testing.assert_allclose(fast.x, ref.x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fast.history, ref.history, rtol=1e-9)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--md", metavar="PAGE", help="write the performance page's bench:lm block")
    args = parser.parse_args()
    if args.md and (why := readme_table.check(args.md, "lm")):
        parser.error(why)
    load_start = readme_table.load()
    model, data = problem(100, 1)
    prob, x0, method, options = captured_problem(model, data)
    check_same(prob, x0, method, options)
    points = iter(x0 + 1e-9 * np.random.default_rng(0).normal(size=(100_000, len(x0))))

    def evaluation():
        x = next(points)
        prob._cache.clear()
        prob.residual(x)
        prob.jacobian(x)

    def cold():
        prob._cache.clear()
        return solvers.solve(prob, x0, method, **options)

    replay = _Replay(prob, x0, options["max_iterations"] * (len(x0) + 1))

    def alone():
        return solvers.solve(replay.rewound(), x0, method, **options)

    def numpy(fn):
        def run():
            with _Numpy():
                return fn()

        return run

    def calibrate():
        return rc.calibrate(model, data)

    rows = {
        "evaluation (r + J at a new point)": {"": evaluation},
        "solve, 3 evaluations": {"numpy": numpy(cold), "compiled": cold},
        "the solver alone (evaluations replayed)": {"numpy": numpy(alone), "compiled": alone},
        "rc.calibrate end to end": {"numpy": numpy(calibrate), "compiled": calibrate},
    }
    fleet, fleet_solve = fleet_fn(50)
    rows["batched engine, 50 robots (per robot)"] = {"numpy": numpy(fleet), "compiled": fleet}
    rows["batched solver alone, 50 robots (per robot)"] = {
        "numpy": lambda: fleet_solve.run(levenberg_marquardt_batch_numpy),
        "compiled": lambda: fleet_solve.run(solvers.levenberg_marquardt_batch),
    }
    title = f"LM on the 100-pose UR10 ({len(x0)} unknowns), CPU µs per call, min of {args.rounds} rounds"
    print(title)
    print(f"{'':46s} {'numpy':>9s} {'compiled':>9s} {'ratio':>6s}")
    table = []
    for name, fns in rows.items():
        t = best(fns, args.rounds)
        per = 50 if name.startswith("batched") else 1
        if "" in t:
            print(f"{name:46s} {t[''] * 1e6:9.1f}")
            table.append([name, "", f"{t[''] * 1e6:.1f}", ""])
        else:
            numpy_us, compiled_us = t["numpy"] * 1e6 / per, t["compiled"] * 1e6 / per
            ratio = t["numpy"] / t["compiled"]
            print(f"{name:46s} {numpy_us:9.1f} {compiled_us:9.1f} {ratio:5.2f}x")
            table.append([name, f"{numpy_us:.1f}", f"{compiled_us:.1f}", f"{ratio:.2f}×"])
    out = subprocess.run([sys.executable, "-c", FIRST_CALL], capture_output=True, text=True, check=True)
    first, second = (float(v) for v in out.stdout.split())
    first_line = (f"First call in a new process (kernels from numba's cache): {first * 1e3:.0f} ms "
                  f"(second {second * 1e6:.0f} µs).")  # fmt: skip
    print(first_line)
    if args.md:
        body = [
            f"`python benchmarks/bench_lm.py --rounds {args.rounds} --md docs/performance.md` — {title}:", "",
            *readme_table.markdown_table(["", "numpy", "compiled", "ratio"], table), "",
            first_line, "", readme_table.machine(load_start),
        ]  # fmt: skip
        readme_table.write_block(args.md, "lm", "\n".join(body))


def fleet_fn(robots: int):
    """The batched engine (a study's) on ``robots`` virtual UR10s of ``problem``'s kind, and
    its first solve, replayable."""
    model = problem(100, 1)[0]
    datas = [problem(100, seed)[1] for seed in range(1, robots + 1)]
    return (lambda: batch_engine.calibrate_batch(model, datas)), _BatchReplay(model, datas)


if __name__ == "__main__":
    main()
