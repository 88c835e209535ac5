"""Forward kinematics and the joint Jacobian against Pinocchio, in the same run, as ratios.

For each robot (UR10 by default; ``--robots`` for others of the catalog), on the same seeded
random configurations within the joint limits:

* one configuration per call: robocal's direct entry points
  (``d = model.data()``, :class:`robocal.model.chain_compiled.ChainData`: ``d.fk(q, d.data)``,
  ``d.fk_jacobian(q, d.data)``, the outputs preallocated), ``Model.fk(q, data=d)`` and
  ``Model.joint_jacobian(q, data=d)`` (checked, into the caller's ``d``), ``Model.fk(q)`` and
  ``Model.joint_jacobian(q)`` (a new array per call), against Pinocchio's
  ``forwardKinematics`` + ``updateFramePlacement`` and
  ``computeFrameJacobian`` (LOCAL_WORLD_ALIGNED: the same ``[v; ω]`` in the base frame; it
  places the frame too);
* many configurations: ``Model.fk(Q)``, ``Model.joint_jacobian(Q)`` and the direct
  ``fk_many``, against Pinocchio called once per configuration (it has no batched call).

Pinocchio's model is robocal's (``robocal.model.dynamics.to_pinocchio``); every result is
checked against Pinocchio's before timing (frames to 1e-12, Jacobians to 1e-11).  Times
are CPU time of this thread (``time.thread_time``: on a shared machine wall time counts the
waiting too), the minimum over ``--rounds`` of the mean of a batch of calls, the methods
interleaved round by round; ratio = robocal / Pinocchio (below 1: faster).

Run: ``python benchmarks/bench_fk.py [--rounds 9] [--robots ur10 puma560] [--md docs/performance.md]``
(``--md`` writes the performance page's ``<!-- bench:fk -->`` block).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))
import readme_table
import robocal as rc
from robocal.model.dynamics import TOOL_FRAME, to_pinocchio

N_MANY = 1000
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def cpu_per_call(fns: list[Callable[[], object]], rounds: int, budget: float = 0.02) -> list[float]:
    """CPU seconds per call of each ``fn``: the minimum over ``rounds`` interleaved rounds of
    the mean over a batch sized to about ``budget`` seconds."""
    numbers = []
    for fn in fns:
        fn()
        t = time.thread_time()
        fn()
        numbers.append(max(1, int(budget / max(time.thread_time() - t, 1e-7))))
    best = [float("inf")] * len(fns)
    for _ in range(rounds):
        for i, (fn, number) in enumerate(zip(fns, numbers, strict=True)):
            t = time.thread_time()
            for _ in range(number):
                fn()
            best[i] = min(best[i], (time.thread_time() - t) / number)
    return best


def cases(name: str):
    """``(label, configurations per call, robocal call, Pinocchio call)`` for one robot, after
    checking every robocal result against Pinocchio's."""
    model = rc.robot(name)
    d = model.data()
    pm = to_pinocchio(model)
    pd = pm.createData()
    tool = pm.getFrameId(TOOL_FRAME)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    Q = np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (N_MANY, model.dof))
    q = Q[0].copy()
    fk, fkj, fk_many, data = d.fk, d.fk_jacobian, d.fk_many, d.data
    Ts, Js = np.empty((N_MANY, 4, 4)), np.empty((N_MANY, 6, model.dof))

    def pin_fk(q=q):
        pin.forwardKinematics(pm, pd, q)
        return pin.updateFramePlacement(pm, pd, tool)

    def pin_jacobian(q=q):
        return pin.computeFrameJacobian(pm, pd, q, tool, LWA)

    def pin_fk_many():
        for qk in Q:
            pin_fk(qk)

    def pin_jacobian_many():
        for qk in Q:
            pin_jacobian(qk)

    # the same results first
    T_pin = np.array([pin_fk(qk).homogeneous for qk in Q])
    J_pin = np.array([pin_jacobian(qk) for qk in Q])
    assert fk(q, data) and np.abs(d.T - T_pin[0]).max() < 1e-12
    assert fkj(q, data) and np.abs(d.J - J_pin[0]).max() < 1e-11
    assert np.abs(model.fk(q) - T_pin[0]).max() < 1e-12
    assert np.abs(model.joint_jacobian(q) - J_pin[0]).max() < 1e-11
    assert model.fk(q, data=d) is d.T and np.abs(d.T - T_pin[0]).max() < 1e-12
    assert model.joint_jacobian(q, data=d) is d.J and np.abs(d.J - J_pin[0]).max() < 1e-11
    assert fk_many(Q, data, Ts, Js, True)
    assert np.abs(Ts - T_pin).max() < 1e-12 and np.abs(Js - J_pin).max() < 1e-11
    assert np.abs(model.fk(Q) - T_pin).max() < 1e-12
    assert np.abs(model.joint_jacobian(Q) - J_pin).max() < 1e-11
    label = f"{name}:"
    return [
        (f"{label} FK, one configuration, direct `fk(q, data)`", 1, lambda: fk(q, data), pin_fk),
        (f"{label} FK, one configuration, `Model.fk(q, data=d)` (into d)", 1,
         lambda: model.fk(q, data=d), pin_fk),
        (f"{label} FK, one configuration, `Model.fk(q)` (new array)", 1, lambda: model.fk(q), pin_fk),
        (f"{label} FK + joint Jacobian, one configuration, direct `fk_jacobian(q, data)`", 1,
         lambda: fkj(q, data), pin_jacobian),
        (f"{label} joint Jacobian, one configuration, `Model.joint_jacobian(q, data=d)` (into d)", 1,
         lambda: model.joint_jacobian(q, data=d), pin_jacobian),
        (f"{label} joint Jacobian, one configuration, `Model.joint_jacobian(q)` (new array)", 1,
         lambda: model.joint_jacobian(q), pin_jacobian),
        (f"{label} FK, {N_MANY:,} configurations, `Model.fk(Q)`", N_MANY, lambda: model.fk(Q), pin_fk_many),
        (f"{label} FK, {N_MANY:,} configurations, direct `fk_many`", N_MANY,
         lambda: fk_many(Q, data, Ts, Js, False), pin_fk_many),
        (f"{label} joint Jacobian, {N_MANY:,} configurations, `Model.joint_jacobian(Q)`", N_MANY,
         lambda: model.joint_jacobian(Q), pin_jacobian_many),
        (f"{label} FK + joint Jacobian, {N_MANY:,} configurations, direct `fk_many`", N_MANY,
         lambda: fk_many(Q, data, Ts, Js, True), pin_jacobian_many),
    ]  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--robots", nargs="+", default=["ur10"], choices=rc.robots())
    parser.add_argument("--md", metavar="PAGE", help="write the table into this file's bench:fk block")
    args = parser.parse_args()
    if args.md and (why := readme_table.check(args.md, "fk")):
        parser.error(why)
    load_start = readme_table.load()
    all_cases = [c for name in args.robots for c in cases(name)]
    fns = [f for _, _, ours, theirs in all_cases for f in (ours, theirs)]
    times = cpu_per_call(fns, args.rounds)
    rows = []
    print(f"µs per configuration, CPU time, min of {args.rounds} rounds; ratio = robocal / Pinocchio")
    for k, (label, n, _, _) in enumerate(all_cases):
        ours, theirs = times[2 * k] / n * 1e6, times[2 * k + 1] / n * 1e6
        print(f"{label:<86} {ours:8.3f} {theirs:8.3f} {ours / theirs:6.2f}x")
        rows.append([label, f"{ours:.3f}", f"{theirs:.3f}", f"{ours / theirs:.2f}×"])
    if args.md:
        header = ["µs per configuration, CPU time", "robocal", "Pinocchio", "ratio"]
        cmd = f"python benchmarks/bench_fk.py --rounds {args.rounds}"
        if args.robots != ["ur10"]:
            cmd += " --robots " + " ".join(args.robots)
        body = [
            f"`{cmd} --md docs/performance.md` — robocal against Pinocchio {pin.__version__} in the same run "
            f"(CPU time of the thread, minimum over {args.rounds} interleaved rounds; ratio below 1: "
            "faster than Pinocchio; Pinocchio has no batched call, its many-configuration figures "
            "are one call per configuration):",
            "",
            *readme_table.markdown_table(header, rows),
            "",
            readme_table.machine(load_start, f"Pinocchio {pin.__version__}"),
        ]
        readme_table.write_block(args.md, "fk", "\n".join(body))


if __name__ == "__main__":
    main()
