"""Calibration speed: robocal's analytic-Jacobian identification vs finite differences.

The same problem for both: a UR10 built from joint geometry (complete, minimal model),
errors of ±0.5 mm / ±0.05° on every parameter, a laser tracker at an unknown place
measuring a probe at an unknown tool offset with 20 µm noise, 100 random poses.

* robocal: ``rc.calibrate(model, data)`` end to end (start values, identifiable set,
  Levenberg-Marquardt on the analytic Jacobian, covariance).
* baselines: scipy ``least_squares`` (MINPACK ``lm``, same unknowns, same start
  values, tolerances 1e-12) with a 2-point finite-difference Jacobian, on residuals
  from three forward kinematics of the same chain: robocal's own kernel (a new model
  per evaluation — the strongest baseline), plain numpy (one batched 4x4 product per
  step, what a user writes by hand) and Robotics Toolbox's C ``ETS.eval`` (the ETS
  rebuilt per evaluation, RTB's documented way to change a model's constants).  Each
  is checked to reproduce robocal's FK to 1e-12 m.  Only the solve is timed for the
  baselines (start values and identifiable set are given to them free), which favours
  them.

FIGAROH, which pins its own dependencies, runs in its own environment on its own shipped
TIAGo data in ``benchmarks/bench_peers.py`` (robocal 4 ms against FIGAROH's 82 ms for
the same joint-offset calibration, docs/performance.md "Peers").

Run: ``python benchmarks/bench_calibrate.py [--repeats 7] [--poses 100] [--md docs/performance.md]`` (``--md``
writes the performance page's ``<!-- bench:calibrate -->`` block, with each stage's CPU time).
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import sys
import time
import timeit
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small problems: threads only add noise
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
import readme_table
import robocal as rc
from robocal.measure.devices import LaserTracker
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.measure.true_model import draw_true_model
from robocal.model.builder import load_geometry
from robocal.model.geometry import Tcp

ROOT = Path(__file__).resolve().parents[1]
#: CPU time of this thread: robocal and every baseline run on one thread (BLAS threads 1), so
#: on a machine shared with other work it measures the work, not the waiting (wall time
#: rose 3x under a load of 10 on 2 cores while CPU time stayed within 10 %)
CLOCK = time.thread_time
PROBE = (0.06, -0.04, 0.109)  # the reflector, off the flange axis (on it, two parameters are lost)


def problem(n_poses: int, seed: int):
    g = load_geometry(ROOT / "examples" / "geometry" / "ur10.yaml")
    model = g.__class__(**{**g.__dict__, "tcp": Tcp(PROBE)}).build("position").model
    true = draw_true_model(model, seed=seed)
    tracker = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.1, -0.2, 2.0]), [2.0, -1.0, 0.3])
    device = LaserTracker(T_device_base=tracker, p_tool_target=np.zeros(3), sigma=20e-6)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = np.random.default_rng(seed + 1).uniform(lim[:, 0], lim[:, 1], (n_poses, model.dof))
    return model, simulate(VirtualRobot(model, true, device), q, seed=seed + 2)


def numpy_fk(steps, values, q):
    """Tool positions ``(n, 3)`` of a chain of elementary transforms, written the way a
    user without a kinematics library would: one batched 4x4 product per step."""
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    j = 0
    for step, v in zip(steps, values, strict=True):
        k = "xyz".index(step.motion[1])
        angle = step.motion[0] == "R"
        if step.joint is not None:
            v = v + q[:, j]
            j += 1
        E = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy() if np.ndim(v) else np.eye(4)
        if angle:
            a, b = (k + 1) % 3, (k + 2) % 3
            c, s_ = np.cos(v), np.sin(v)
            E[..., a, a], E[..., a, b], E[..., b, a], E[..., b, b] = c, -s_, s_, c
        else:
            E[..., k, 3] = v
        T = T @ E
    return T[:, :3, 3]


def rtb_ets(steps, values):
    """The chain as a Robotics Toolbox ETS (joint offsets as constant rotations or
    translations about the joint's axis, in front of the joint), rebuilt per evaluation."""
    import roboticstoolbox as rtb

    elements = []
    for step, v in zip(steps, values, strict=True):
        make = getattr(rtb.ET, step.motion if step.motion[0] == "R" else "t" + step.motion[1])
        if step.joint is not None and v != 0.0:
            elements.append(make(float(v)))
        elements.append(make() if step.joint is not None else make(float(v)))
    return rtb.ETS(elements)


def baseline(result, data, fk: str = "robocal", solver: str = "lm"):
    """scipy least_squares with 2-point finite differences on the same unknowns and start
    values: ``solver`` ``"lm"`` (MINPACK, tolerances 1e-12, Jacobian scaling) or
    ``"trf"`` (scipy's defaults); the forward kinematics from ``fk``: robocal's kernel (a
    new model per evaluation), plain numpy, or Robotics Toolbox's C ``ETS.eval``.

    Returns the solve's CPU time (s, :data:`CLOCK`), the RMS residual (m), the number of residual
    evaluations and the time of one evaluation (s, the best of 20)."""
    chain = result.measurement_chain
    names = [n for n in result.names if n in chain.names]
    start = chain.with_values(dict(zip(names, result.nominal, strict=True))).with_free(None, False)
    start = start.with_free(names)
    steps, free = start.steps, start.free_mask
    values0 = start.values

    def positions(x):
        if fk == "robocal":
            return start.with_free_values(x).fk(data.q)[:, :3, 3]
        values = values0.copy()
        values[free] = x
        if fk == "numpy":
            return numpy_fk(steps, values, data.q)
        return rtb_ets(steps, values).eval(data.q)[:, :3, 3]

    calls = [0]

    def residual(x):
        calls[0] += 1
        return (positions(x) - data.position).ravel()

    x0 = start.free_values
    gap = float(np.abs(positions(x0) - start.fk(data.q)[:, :3, 3]).max())
    assert gap < 1e-12, f"the {fk} forward kinematics differs from robocal's by {gap:.3g} m"
    options = {"method": "lm", "x_scale": "jac", "ftol": 1e-12, "xtol": 1e-12, "gtol": 1e-12}
    calls[0] = 0
    t = CLOCK()
    res = least_squares(residual, x0, jac="2-point", **(options if solver == "lm" else {}))
    seconds = CLOCK() - t
    n_calls = calls[0]
    rms = float(np.sqrt(np.mean(np.sum(residual(res.x).reshape(-1, 3) ** 2, axis=1))))
    one = min(timeit.repeat(lambda: residual(res.x), number=1, repeat=20))
    return seconds, rms, n_calls, one


#: the stages of ``rc.calibrate`` (robocal/identify/pipeline.py; this calibration takes the
#: compiled stages of robocal/identify/fused.py), timed apart by :func:`stage_times`
STAGES = (
    ("pipeline", "_check_inputs"), ("pipeline", "build_problem"), ("fused", "rank_test"),
    ("pipeline", "_rank_guard"), ("fused", "fit"), ("pipeline", "_fused"), ("pipeline", "_hold_effects"),
    ("pipeline", "_assemble"), ("pipeline", "diagnose"), ("calibrate", "_with_tool_facts"),
)  # fmt: skip


def stage_times(model, data, calls: int = 300) -> tuple[dict[str, float], float]:
    """CPU time per call (s) of each stage of ``rc.calibrate`` (exclusive: ``_fused`` is what
    its two compiled stages and the rank guard leave) and of the whole call, over ``calls``
    calls.  The stages are wrapped for this measurement only (the wrappers cost ~1 µs each)."""
    from robocal.identify import fused, pipeline

    # the module, not the function robocal.identify re-exports under its name
    calibrate = importlib.import_module("robocal.identify.calibrate")
    modules = {"pipeline": pipeline, "fused": fused, "calibrate": calibrate}
    label = {stage: stage[1] if stage[0] == "pipeline" else ".".join(stage) for stage in STAGES}
    spent = dict.fromkeys(label.values(), 0.0)
    children: list[float] = []

    def timed(name, fn):
        def wrapper(*args, **kwargs):
            children.append(0.0)
            t = CLOCK()
            try:
                return fn(*args, **kwargs)
            finally:
                elapsed = CLOCK() - t
                spent[name] += elapsed - children.pop()
                if children:
                    children[-1] += elapsed

        return wrapper

    originals = {stage: getattr(modules[stage[0]], stage[1]) for stage in STAGES}
    try:
        for stage, fn in originals.items():
            setattr(modules[stage[0]], stage[1], timed(label[stage], fn))
        t = CLOCK()
        for _ in range(calls):
            rc.calibrate(model, data)
        total = (CLOCK() - t) / calls
    finally:
        for stage, fn in originals.items():
            setattr(modules[stage[0]], stage[1], fn)
    return {name: v / calls for name, v in spent.items()}, total


def measure(model, data, runs, repeats: int):
    """Interleaved rounds (the machine may be shared): each round times robocal 9 times and
    every baseline once.  Returns the median CPU time (s) of all robocal's calls and of their solves,
    the baselines' times per run, their (RMS, evaluations, one evaluation) and the last result."""
    ours, solves = [], []
    theirs: dict[tuple[str, str], list[float]] = {run: [] for run in runs}
    fd: dict[tuple[str, str], tuple[float, int, float]] = {}
    for _ in range(repeats):
        for _ in range(9):
            t = CLOCK()
            result = rc.calibrate(model, data)
            ours.append(CLOCK() - t)
            solves.append(result.diagnostics.solve_seconds)
        for run in runs:
            seconds, *fd[run] = baseline(result, data, fk=run[0], solver=run[1])
            theirs[run].append(seconds)
    MEASURED.update(calls=len(ours), quartiles=tuple(np.percentile(ours, [25, 75]).tolist()))
    # the median of every call (not the best one): what a user's calibration costs
    return float(np.median(ours)), float(np.median(solves)), theirs, fd, result


#: how :func:`measure` measured robocal's figure: the calls and their quartiles (s)
MEASURED: dict = {}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--md", metavar="PAGE", help="write the performance page's bench:calibrate block")
    args = parser.parse_args(argv)
    if args.md and (why := readme_table.check(args.md, "calibrate")):
        parser.error(why)
    load_start = readme_table.load()
    model, data = problem(args.poses, args.seed)
    print("robocal calibration benchmark")
    print(f"  platform  {platform.platform()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    print(
        f"  numpy {np.__version__}, robocal {rc.__version__}, "
        f"BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}"
    )
    result = rc.calibrate(model, data)  # warm-up
    print(
        f"  problem   UR10 (built, {len(model.free_names)} free robot parameters), {data.n} poses, "
        f"{len(result.names)} unknowns identified (robot + tracker frame + tool point)"
    )
    backends = [("robocal", "robocal's FK kernel, a new model per evaluation"), ("numpy", "plain numpy FK")]
    try:
        import roboticstoolbox  # noqa: F401

        backends.append(("rtb", "Robotics Toolbox `ETS.eval` (C), ETS rebuilt per evaluation"))
    except Exception as exc:  # an optional peer: report and go on
        print(f"  (Robotics Toolbox not available: {exc})")
    runs = [("robocal", "lm"), ("robocal", "trf")] + [(key, "lm") for key, _ in backends[1:]]
    t_ours, t_solve, theirs, fd, result = measure(model, data, runs, args.repeats)
    stages, t_loop = stage_times(model, data)
    rows = _rows(runs, dict(backends), t_ours, t_solve, theirs, fd, result)
    header = ["method", f"CPU time (median, {args.repeats} interleaved rounds)", "RMS residual", "ratio"]
    table = readme_table.markdown_table(header, rows)
    stage_table = readme_table.markdown_table(
        ["stage of `rc.calibrate` (identify/pipeline.py, fused.py, calibrate.py)", "CPU µs per call"],
        [[f"`{name}`", f"{v * 1e6:.0f}"] for name, v in stages.items()]
        + [["all (a tight loop of 300 calls, stages timed)", f"{t_loop * 1e6:.0f}"]],
    )
    t_numpy = float(np.median(theirs["numpy", "lm"]))
    q25, q75 = MEASURED["quartiles"]
    targets = (
        f"Targets: robocal end to end {t_ours * 1e3:.2f} ms, the median CPU time of "
        f"{MEASURED['calls']} calls "
        f"(quartiles {q25 * 1e3:.2f}-{q75 * 1e3:.2f} ms; load average {load_start} at the start, "
        f"{readme_table.load()} at the end) (issue 20: ≤ 0.7 ms; issue 35: ≤ 0.5 ms); "
        f"{t_numpy / t_ours:.1f}× scipy MINPACK LM with finite differences on plain numpy FK "
        f"(issue 20: ≥ 40×)."
    )
    print("", *table, "", *stage_table, "", targets, sep="\n")
    _where_the_limit_is(runs, theirs, fd, result, data, t_ours)
    if args.md:
        body = [
            f"`python benchmarks/bench_calibrate.py --repeats {args.repeats} --md docs/performance.md` "
            "— a UR10 "
            f"(complete model built from its joint geometry, probe off the flange axis), {data.n} poses, "
            f"{len(result.names)} unknowns (robot, tracker frame, probe point), 20 µm noise; CPU time, "
            "medians of interleaved rounds:",
            "", *table, "", *stage_table, "", targets, "",
            readme_table.machine(load_start),
        ]  # fmt: skip
        readme_table.write_block(args.md, "calibrate", "\n".join(body))
    return 0


def _rows(runs, labels, t_ours, t_solve, theirs, fd, result) -> list[list[str]]:
    solver_label = {"lm": "MINPACK LM", "trf": "defaults (TRF)"}
    rows = [
        ["robocal `rc.calibrate` (analytic Jacobian, own LM), end to end", f"{t_ours * 1e3:.2f} ms",
         f"{result.rms_after * 1e3:.4f} mm", "1"],
        ["robocal, the Levenberg-Marquardt solve inside it (wall time)", f"{t_solve * 1e3:.2f} ms", "", ""],
    ]  # fmt: skip
    for run in runs:
        t_fd = float(np.median(theirs[run]))
        rows.append([
            f"scipy `least_squares` {solver_label[run[1]]}, 2-point finite differences on {labels[run[0]]}, "
            "solve only", f"{t_fd * 1e3:.1f} ms", f"{fd[run][0] * 1e3:.4f} mm",
            f"{t_fd / t_ours:.1f}× end to end, {t_fd / t_solve:.1f}× solve to solve",
        ])  # fmt: skip
    return rows


def _where_the_limit_is(runs, theirs, fd, result, data, t_ours) -> None:
    """How far an analytic Jacobian can get against the fastest finite-difference baseline:
    its cost is its residual evaluations; robocal's solve needs ``passes`` fused passes."""
    solver_label = {"lm": "MINPACK LM", "trf": "defaults (TRF)"}
    fastest = min(runs[:2], key=lambda run: float(np.median(theirs[run])))
    t_fd = float(np.median(theirs[fastest]))
    _, calls, t_eval = fd[fastest]
    problem_chain = result.measurement_chain
    t_pass = min(
        timeit.repeat(
            lambda: problem_chain.evaluate(data.q, problem_chain.values, rows="position", jacobian=True),
            number=1,
            repeat=20,
        )
    )
    passes = result.diagnostics.evaluations
    print()
    print(f"Where the limit is (fastest baseline: {solver_label[fastest[1]]} on robocal's FK):")
    print(
        f"  baseline: {calls} residual evaluations x {t_eval * 1e6:.0f} µs = {calls * t_eval * 1e3:.1f} ms "
        f"of its {t_fd * 1e3:.1f} ms"
    )
    print(
        f"  robocal:  {passes} fused residual+Jacobian passes x {t_pass * 1e6:.0f} µs = "
        f"{passes * t_pass * 1e3:.2f} ms ({t_pass / t_eval:.1f} evaluations each)"
    )
    print(
        f"  with no other work at all robocal would be {t_fd / (passes * t_pass):.0f}x faster; "
        f"everything else (start values, rank test, screening, covariance, result) takes "
        f"{(t_ours - passes * t_pass) * 1e3:.2f} ms"
    )


if __name__ == "__main__":
    sys.exit(main())
