"""Kinematics benchmark: robocal vs Robotics Toolbox for Python vs plain numpy.

Run from the repository root::

    python benchmarks/bench_kinematics.py [--n 10000] [--repeats 11] [--loop-n 2000] [--json PATH]

Everything is solved on the same seeded random configurations of the UR10 (uniform
within the joint limits, ±pi where a limit is unknown):

* forward kinematics, batched over configurations: robocal ``Model.fk``, RTB's
  C-accelerated ``ETS.eval`` and a plain-numpy standard-DH reference (4x4 matmuls);
* the identification Jacobian ``Model.jacobian`` (24 DH parameters, and 33 with a
  6-parameter base frame and a 3-parameter tool point), position and pose rows;
* the geometric joint Jacobian: robocal ``Model.joint_jacobian`` (batched) and RTB's
  ``DHRobot.jacob0`` / ``ETS.jacob0`` (one configuration per call, Python loop).

Results are cross-checked before anything is timed.  Every method is warmed up once,
then timed with time.perf_counter in ``--repeats`` interleaved rounds (each method once
per round, so bursts of concurrent load hit all methods alike) and the minimum is kept.
RTB's per-call Jacobians are timed over ``--loop-n`` configurations per round and
scaled per configuration.  BLAS is single-threaded unless OPENBLAS_NUM_THREADS,
OMP_NUM_THREADS or MKL_NUM_THREADS is set.  Ratios are time ratios ``t / t_ref``
(below 1 = faster than the reference).  RTB rows are skipped, with a note, when
roboticstoolbox cannot be imported.

Allocator state matters for the batched calls: their temporaries are megabytes, and
whether glibc hands out memory that is still mapped ("warm") or fresh pages that fault
in on first touch ("cold") changes the Jacobian's time by up to 2-3x.  With glibc's
default adaptive thresholds which one a program gets depends on what it allocated and
freed before, so this script fixes them (mallopt: mmap threshold 32 MiB, no automatic
trimming) and times every method twice per round: cold, right after ``malloc_trim(0)``
gave all free memory back to the OS (the cost in a fresh process, or whenever glibc
trims), then warm, reusing what the cold call left mapped (pure compute).  It reports
the minor page faults per call of both.  Ratios use the warm times.  Without glibc
only warm times are taken, with the platform's allocator as it is.
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util
import gc
import json
import math
import os
import platform
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

# Single-threaded BLAS unless the caller says otherwise (before numpy is imported).  The
# RTB and numpy-reference paths are single-threaded, and robocal's tall-skinny gemms
# (3n x 4 @ 4 x k) gain nothing from threads but, with other work on the cores, lose a
# lot waiting for them.  Run with OPENBLAS_NUM_THREADS=2 (etc.) to measure that case.
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
for _var in BLAS_THREAD_VARS:
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import robocal as rc  # noqa: E402
from robocal.model.conventions import frame6, model_from_steps, tool_point  # noqa: E402

try:
    import resource  # Unix only: minor page-fault counts
except ImportError:  # pragma: no cover - Windows
    resource = None

#: UR10 (CB3) standard DH table the benchmark expects: (theta offset, d, a, alpha), SI.
UR10_DH = np.array(
    [
        [0.0, 0.1273, 0.0, math.pi / 2],
        [0.0, 0.0, -0.612, 0.0],
        [0.0, 0.0, -0.5723, 0.0],
        [0.0, 0.163941, 0.0, math.pi / 2],
        [0.0, 0.1157, 0.0, -math.pi / 2],
        [0.0, 0.0922, 0.0, 0.0],
    ]
)

FK_TOL = 1e-12  # max abs difference of the 4x4 tool frames (m and unitless)
JAC_TOL = 1e-9  # max abs difference of the joint Jacobians


# ---------------------------------------------------------------------- helpers
@dataclass
class Row:
    group: str  # "FK" or "Jacobian"
    method: str
    seconds: float  # best warm time for `configs` configurations
    configs: int
    output: str  # shape of what one call returns
    seconds_cold: float | None = None  # best time right after malloc_trim(0)
    faults_warm: float | None = None  # median minor page faults per call
    faults_cold: float | None = None
    ratio_rtb: float | None = None  # t / t(RTB reference of the group), warm
    ratio_numpy: float | None = None  # t / t(plain-numpy FK reference), warm

    @property
    def us_per_config(self) -> float:
        return self.seconds / self.configs * 1e6

    @property
    def us_per_config_cold(self) -> float | None:
        return None if self.seconds_cold is None else self.seconds_cold / self.configs * 1e6


@dataclass
class Results:
    machine: dict
    settings: dict
    checks: dict = field(default_factory=dict)
    rows: list[Row] = field(default_factory=list)


@dataclass
class Bench:
    group: str  # "FK" or "Jacobian"
    method: str
    fn: Callable[[], object]
    configs: int  # configurations one call of fn covers
    shape: tuple[int, ...]  # shape one call returns (per call of the wrapped function for loops)


_M_TRIM_THRESHOLD = -1  # glibc mallopt parameters (malloc.h)
_M_MMAP_THRESHOLD = -3


def _glibc_allocator_control() -> Callable[[], object] | None:
    """Make glibc's allocator state explicit; return ``malloc_trim(0)``, or ``None``.

    By default glibc returns freed memory to the OS depending on adaptive thresholds
    (so whether a call reuses mapped memory or page-faults fresh memory depends on
    what the process did before).  Fixing the mmap threshold at its 32 MiB maximum
    and never trimming automatically makes freed memory stay mapped ("warm") until
    ``malloc_trim(0)`` gives it all back ("cold").  ``None`` when not on glibc.
    """
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim, mallopt = libc.malloc_trim, libc.mallopt
    except (OSError, AttributeError):  # not glibc (e.g. musl)
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    if not (mallopt(_M_MMAP_THRESHOLD, 32 << 20) and mallopt(_M_TRIM_THRESHOLD, 2**31 - 1)):
        return None
    return lambda: trim(0)


def _minor_faults() -> int:
    if resource is None:
        return 0
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


@dataclass
class Timing:
    warm: float  # best seconds per call
    cold: float | None
    faults_warm: float | None  # median minor page faults per call
    faults_cold: float | None


def best_times(benches: list[Bench], repeats: int) -> list[Timing]:
    """Minimum wall time (s) of each benchmark over ``repeats`` runs, warm and cold.

    Each benchmark is warmed up once (a batched call's result is checked against its
    expected shape).  The timed runs are interleaved in rounds (every benchmark once
    per round), so a burst of load from concurrent work hits all methods alike rather
    than all the repeats of one method; the garbage collector is off while timing.
    In each round a method is timed cold (right after ``malloc_trim(0)``), then warm
    (reusing the memory the cold call left mapped); see :func:`_glibc_allocator_control`.
    """
    trim = _glibc_allocator_control()
    for b in benches:
        out = b.fn()
        if out is not None:  # a batched call; per-call loops return None
            assert out.shape == b.shape, f"{b.method}: returned {out.shape}, expected {b.shape}"
    modes = ("cold", "warm") if trim is not None else ("warm",)
    times = {(i, mode): [] for i in range(len(benches)) for mode in modes}
    faults = {(i, mode): [] for i in range(len(benches)) for mode in modes}
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for _ in range(repeats):
            for i, b in enumerate(benches):
                for mode in modes:
                    if mode == "cold":
                        trim()
                    f0 = _minor_faults()
                    t0 = time.perf_counter()
                    b.fn()
                    t = time.perf_counter() - t0
                    faults[i, mode].append(_minor_faults() - f0)
                    times[i, mode].append(t)
    finally:
        if gc_was_enabled:
            gc.enable()
    has_faults = resource is not None
    return [
        Timing(
            warm=min(times[i, "warm"]),
            cold=min(times[i, "cold"]) if trim is not None else None,
            faults_warm=float(np.median(faults[i, "warm"])) if has_faults else None,
            faults_cold=(float(np.median(faults[i, "cold"])) if has_faults and trim is not None else None),
        )
        for i in range(len(benches))
    ]


def per_config_loop(fn: Callable[[np.ndarray], object], Q: np.ndarray) -> Callable[[], None]:
    """A callable that applies ``fn`` to each row of ``Q`` in a Python loop."""

    def run() -> None:
        for q in Q:
            fn(q)

    return run


def random_configurations(model: rc.Model, n: int, seed: int) -> np.ndarray:
    """``(n, dof)`` uniform within the joint limits (±pi where a limit is unknown)."""
    limits = model.joint_limits
    lo = np.where(np.isfinite(limits[:, 0]), limits[:, 0], -math.pi)
    hi = np.where(np.isfinite(limits[:, 1]), limits[:, 1], math.pi)
    return np.random.default_rng(seed).uniform(lo, hi, size=(n, model.dof))


def dh_table(model: rc.Model) -> np.ndarray:
    """The ``(dof, 4)`` standard-DH table (theta offset, d, a, alpha) of a model made of
    ``Rz(theta + q) Tz(d) Tx(a) Rx(alpha)`` revolute links, in chain order."""
    steps = model.steps
    if len(steps) != 4 * model.dof:
        raise ValueError(f"model {model.name!r} is not a plain standard-DH chain")
    rows = []
    for k in range(model.dof):
        link = steps[4 * k : 4 * k + 4]
        motions = tuple(s.motion for s in link)
        if motions != ("Rz", "Tz", "Tx", "Rx") or link[0].joint is None:
            raise ValueError(f"link {k + 1} of {model.name!r} is {motions}, not revolute standard DH")
        rows.append([s.value for s in link])
    return np.array(rows)


def numpy_dh_fk(table: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Plain-numpy reference: batched standard-DH forward kinematics, ``(n, 4, 4)``.

    One batched ``(n, 4, 4)`` link matrix per joint, chained with ``np.matmul``.
    """
    n = Q.shape[0]
    T = np.broadcast_to(np.eye(4), (n, 4, 4))
    for (offset, d, a, alpha), q in zip(table, Q.T, strict=True):
        theta = q + offset
        ct, st = np.cos(theta), np.sin(theta)
        ca, sa = math.cos(alpha), math.sin(alpha)
        A = np.zeros((n, 4, 4))
        A[:, 0, 0] = ct
        A[:, 0, 1] = -st * ca
        A[:, 0, 2] = st * sa
        A[:, 0, 3] = a * ct
        A[:, 1, 0] = st
        A[:, 1, 1] = ct * ca
        A[:, 1, 2] = -ct * sa
        A[:, 1, 3] = a * st
        A[:, 2, 1] = sa
        A[:, 2, 2] = ca
        A[:, 2, 3] = d
        A[:, 3, 3] = 1.0
        T = np.matmul(T, A)
    return T


def import_rtb():
    """``roboticstoolbox`` or ``None`` (with the reason) when it cannot be imported."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import roboticstoolbox as rtb
    except Exception as exc:  # ImportError, or a broken binary/numpy ABI
        return None, f"{type(exc).__name__}: {exc}"
    return rtb, ""


def rtb_robot_for(rtb, table: np.ndarray):
    """RTB's DH UR10 when its DH table is ours, else a ``DHRobot`` built from ``table``.

    Returns ``(robot, description)``.
    """
    try:
        ur10 = rtb.models.DH.UR10()
        theirs = np.array([[L.offset, L.d, L.a, L.alpha] for L in ur10.links], dtype=float)
        same = (
            theirs.shape == table.shape
            and np.allclose(theirs, table, rtol=0.0, atol=1e-12)
            and all(L.isrevolute and not L.isflip for L in ur10.links)
            and not ur10.mdh
            and np.allclose(ur10.base.A, np.eye(4), rtol=0.0, atol=0.0)
            and np.allclose(ur10.tool.A, np.eye(4), rtol=0.0, atol=0.0)
        )
    except Exception as exc:
        ur10, same = None, False
        print(f"  (could not inspect rtb.models.DH.UR10: {exc})")
    if same:
        return ur10, "roboticstoolbox.models.DH.UR10() (DH table identical to robocal's)"
    links = [
        rtb.RevoluteDH(d=float(d), a=float(a), alpha=float(alpha), offset=float(offset))
        for offset, d, a, alpha in table
    ]
    robot = rtb.DHRobot(links, name="UR10 (robocal table)")
    return robot, "rtb.DHRobot built from robocal's DH table (RTB's UR10 differs)"


def machine_info(np_version: str, rtb_version: str | None, rtb_c: bool | None) -> dict:
    cpu = platform.processor() or platform.machine()
    try:  # a nicer CPU name on Linux
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:  # not on every platform
        affinity = None
    return {
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "cpus_usable": affinity,
        "numpy": np_version,
        "blas_threads": ", ".join(f"{v}={os.environ.get(v)}" for v in BLAS_THREAD_VARS),
        "robocal": rc.__version__,
        "roboticstoolbox": rtb_version,
        "rtb_c_extension": rtb_c,
    }


# ---------------------------------------------------------------------- checks
def check_fk(name: str, T: np.ndarray, T_ref: np.ndarray, tol: float) -> float:
    err = float(np.max(np.abs(T - T_ref)))
    status = "ok" if err <= tol else "FAILED"
    print(f"  {name:<52s} max |diff| = {err:.2e}  (tol {tol:.0e})  {status}")
    assert err <= tol, f"{name}: max abs difference {err:.3e} > {tol:.0e}"
    return err


def finite_difference_jacobian(model: rc.Model, Q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central-difference pose Jacobian ``(6n, p)`` of ``model.fk`` wrt the free parameters."""
    x0 = model.free_values
    cols = []
    for k in range(len(x0)):
        dx = np.zeros_like(x0)
        dx[k] = h
        Tp = model.with_free_values(x0 + dx).fk(Q)
        Tm = model.with_free_values(x0 - dx).fk(Q)
        dpos = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
        # small rotation in the base frame: skew(w) ~ dR R^T
        S = (Tp[:, :3, :3] - Tm[:, :3, :3]) @ np.swapaxes(Tp[:, :3, :3] + Tm[:, :3, :3], 1, 2)
        S /= 4 * h
        dw = np.stack([S[:, 2, 1] - S[:, 1, 2], S[:, 0, 2] - S[:, 2, 0], S[:, 1, 0] - S[:, 0, 1]], axis=1) / 2
        cols.append(np.concatenate([dpos, dw], axis=1).reshape(-1))
    return np.stack(cols, axis=1)


# ---------------------------------------------------------------------- output
def fmt_ratio(r: float | None) -> str:
    if r is None:
        return "n/a"
    if r >= 100:
        return f"{r:.0f}"
    return f"{r:.2f}" if r >= 0.1 else f"{r:.2g}"


def fmt_rate(row: Row) -> str:
    rate = row.configs / row.seconds
    if rate >= 1e6:
        return f"{rate / 1e6:.2f} M/s"
    return f"{rate / 1e3:.1f} k/s"


def fmt_us(us: float | None) -> str:
    return "n/a" if us is None else f"{us:.3f}"


def fmt_faults(f: float | None) -> str:
    return "n/a" if f is None else f"{f:.0f}"


TABLE_HEAD = (
    "group",
    "method",
    "output per call",
    "µs/config",
    "configs/s",
    "× RTB ref",
    "× numpy ref",
    "µs/config cold",
    "faults/call warm",
    "faults/call cold",
)


def table_cells(r: Row) -> tuple[str, ...]:
    return (
        r.group,
        r.method,
        r.output,
        fmt_us(r.us_per_config),
        fmt_rate(r),
        fmt_ratio(r.ratio_rtb),
        fmt_ratio(r.ratio_numpy),
        fmt_us(r.us_per_config_cold),
        fmt_faults(r.faults_warm),
        fmt_faults(r.faults_cold),
    )


TABLE_NOTES = (
    "µs/config, configs/s and the ratios are warm (freed memory kept mapped by the allocator);",
    "'cold' is timed right after malloc_trim(0) (fresh pages, as in a new process); faults/call",
    "are median minor page faults per timed call (one batched call, or one loop of --loop-n).",
    "× RTB ref   = t / t_ref with t_ref = RTB ETS.eval (batched) for FK rows and",
    "              RTB DHRobot.jacob0 (per config) for Jacobian rows; below 1 = faster.",
    "× numpy ref = t / t(plain-numpy batched DH FK).",
)


def print_table(rows: list[Row]) -> None:
    body = [table_cells(r) for r in rows]
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(TABLE_HEAD)]

    def fmt(cells) -> str:
        return "  ".join(
            c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        )

    print(fmt(TABLE_HEAD))
    print("-" * len(fmt(TABLE_HEAD)))
    for b in body:
        print(fmt(b))
    print()
    for note in TABLE_NOTES:
        print("  " + note)


def markdown_table(rows: list[Row]) -> str:
    align = ["---"] * 3 + ["---:"] * (len(TABLE_HEAD) - 3)
    lines = ["| " + " | ".join(TABLE_HEAD) + " |", "|" + "|".join(align) + "|"]
    for r in rows:
        cells = list(table_cells(r))
        cells[2] = f"`{cells[2]}`"
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


# ---------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:  # noqa: C901 - one flat script: options, then a row per case
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=10_000, help="configurations (default 10000)")
    parser.add_argument(
        "--repeats", type=int, default=11, help="timed rounds, min taken (default 11, at least 7)"
    )
    parser.add_argument(
        "--loop-n",
        type=int,
        default=2000,
        help="configurations for RTB's per-call Jacobians (default 2000)",
    )
    parser.add_argument("--seed", type=int, default=20240601, help="random seed")
    parser.add_argument("--json", type=Path, default=None, metavar="PATH", help="write results as JSON")
    args = parser.parse_args(argv)
    if args.n < 1 or args.loop_n < 1:
        parser.error("--n and --loop-n must be positive")
    repeats = max(args.repeats, 7)
    loop_n = min(args.loop_n, args.n)

    rtb, rtb_error = import_rtb()
    m = rc.robot("ur10")
    m30 = model_from_steps("ur10_30", frame6("base"), list(m.steps), tool_point(0, 0, 0.1))
    Q = random_configurations(m, args.n, args.seed)
    table = dh_table(m)
    robot = ets = None
    rtb_desc = ""
    if rtb is not None:
        robot, rtb_desc = rtb_robot_for(rtb, table)
        ets = robot.ets()
    rtb_c = None if ets is None else getattr(ets, "_fknm", None) is not None

    info = machine_info(np.__version__, None if rtb is None else rtb.__version__, rtb_c)
    print("robocal kinematics benchmark")
    for key, value in info.items():
        print(f"  {key:<16s} {value}")
    print(
        f"  configurations   {args.n} (seed {args.seed}, uniform within joint limits), "
        f"{repeats} timed rounds (min), RTB per-call loops over {loop_n}"
    )
    if rtb is None:
        print(f"  roboticstoolbox not importable ({rtb_error}): RTB rows are skipped")
    else:
        print(f"  RTB robot        {rtb_desc}")
        print(f"  RTB ETS          {ets}")
        if not rtb_c:
            print("  WARNING: RTB's C extension is not active; ETS calls fall back to Python")
    print()

    results = Results(
        machine=info,
        settings={
            "n": args.n,
            "seed": args.seed,
            "repeats": repeats,
            "loop_n": loop_n,
            "robot": "ur10",
            "rtb_robot": rtb_desc or None,
            "params_ur10": len(m.free_names),
            "params_ur10_30": len(m30.free_names),
        },
    )

    # ------------------------------------------------------------------ checks
    print("correctness checks")
    assert np.allclose(table, UR10_DH, rtol=0.0, atol=1e-12), f"robocal's UR10 DH table differs:\n{table}"
    print(
        "  robocal UR10 DH table matches d1 .1273, a2 -.612, a3 -.5723, d4 .163941, "
        "d5 .1157, d6 .0922, alpha 90 0 0 90 -90 0 deg"
    )
    T_rc = m.fk(Q)
    T_np = numpy_dh_fk(table, Q)
    assert T_rc.shape == (args.n, 4, 4)
    checks = results.checks
    checks["fk_robocal_vs_numpy"] = check_fk("FK robocal vs numpy DH reference", T_rc, T_np, FK_TOL)
    if ets is not None:
        T_rtb = ets.eval(Q)
        checks["fk_robocal_vs_rtb_ets"] = check_fk("FK robocal vs RTB ETS.eval", T_rc, T_rtb, FK_TOL)
        checks["fk_numpy_vs_rtb_ets"] = check_fk("FK numpy reference vs RTB ETS.eval", T_np, T_rtb, FK_TOL)
    flange_to_tool = np.eye(4)
    flange_to_tool[2, 3] = 0.1
    checks["fk_ur10_30_vs_ur10"] = check_fk(
        "FK ur10_30 (zero base, tool z 0.1) vs ur10 · Tz(0.1)",
        m30.fk(Q),
        T_rc @ flange_to_tool,
        FK_TOL,
    )

    k = min(20, args.n)
    Jq = m.joint_jacobian(Q[:k])
    assert Jq.shape == (k, 6, m.dof)
    if robot is not None:
        J_dh = np.stack([robot.jacob0(q) for q in Q[:k]])
        J_ets = np.stack([ets.jacob0(q) for q in Q[:k]])
        checks["jacob_robocal_vs_rtb_jacob0"] = check_fk(
            f"joint Jacobian robocal vs RTB DHRobot.jacob0 ({k} configs)", Jq, J_dh, JAC_TOL
        )
        checks["jacob_robocal_vs_rtb_ets_jacob0"] = check_fk(
            f"joint Jacobian robocal vs RTB ETS.jacob0 ({k} configs)", Jq, J_ets, JAC_TOL
        )
    # the joint offsets theta_i enter exactly like q_i, so their identification columns
    # must be the joint Jacobian
    Jp = m.jacobian(Q[:k], rows="pose").reshape(k, 6, -1)
    theta_cols = [m.free_names.index(f"theta{j + 1}") for j in range(m.dof)]
    checks["jacob_theta_columns_vs_joint_jacobian"] = check_fk(
        f"identification Jacobian theta columns vs joint Jacobian ({k})",
        Jp[:, :, theta_cols],
        Jq,
        JAC_TOL,
    )
    kf = min(5, args.n)
    J30 = m30.jacobian(Q[:kf], rows="pose")
    checks["jacob_ur10_30_vs_central_differences"] = check_fk(
        f"identification Jacobian ur10_30 vs central differences ({kf})",
        J30,
        finite_difference_jacobian(m30, Q[:kf]),
        1e-7,
    )
    assert m.jacobian(Q[:2]).shape == (6, len(m.free_names)) == (6, 24)
    assert m30.jacobian(Q[:2], rows="pose").shape == (12, len(m30.free_names)) == (12, 33)
    print()

    # ------------------------------------------------------------------ timing
    n, p24, p33 = args.n, len(m.free_names), len(m30.free_names)
    rows = results.rows

    benches: list[Bench] = []

    def add(group: str, method: str, fn, configs: int, shape: tuple[int, ...]) -> int:
        benches.append(Bench(group, method, fn, configs, shape))
        return len(benches) - 1

    Qloop = Q[:loop_n]
    fk_np = add("FK", "numpy DH reference, batched matmul", lambda: numpy_dh_fk(table, Q), n, (n, 4, 4))
    fk_rtb = None
    if ets is not None:
        fk_rtb = add("FK", "RTB ETS.eval (C), batched", lambda: ets.eval(Q), n, (n, 4, 4))
    add("FK", "robocal Model.fk, batched", lambda: m.fk(Q), n, (n, 4, 4))
    add("FK", "robocal Model.fk, batched, 33-param model", lambda: m30.fk(Q), n, (n, 4, 4))

    jac_rtb = None
    if robot is not None:
        jac_rtb = add(
            "Jacobian",
            "RTB DHRobot.jacob0, per config (loop)",
            per_config_loop(robot.jacob0, Qloop),
            loop_n,
            (6, m.dof),
        )
        add(
            "Jacobian",
            "RTB ETS.jacob0 (C), per config (loop)",
            per_config_loop(ets.jacob0, Qloop),
            loop_n,
            (6, m.dof),
        )
    add(
        "Jacobian",
        "robocal joint_jacobian, batched",
        lambda: m.joint_jacobian(Q),
        n,
        (n, 6, m.dof),
    )
    add(
        "Jacobian",
        f"robocal jacobian position, {p24} params",
        lambda: m.jacobian(Q, rows="position"),
        n,
        (3 * n, p24),
    )
    add(
        "Jacobian",
        f"robocal jacobian pose, {p24} params",
        lambda: m.jacobian(Q, rows="pose"),
        n,
        (6 * n, p24),
    )
    add(
        "Jacobian",
        f"robocal jacobian position, {p33} params (base6+DH+tool3)",
        lambda: m30.jacobian(Q, rows="position"),
        n,
        (3 * n, p33),
    )
    add(
        "Jacobian",
        f"robocal jacobian pose, {p33} params (base6+DH+tool3)",
        lambda: m30.jacobian(Q, rows="pose"),
        n,
        (6 * n, p33),
    )

    print(f"timing: {len(benches)} methods, {repeats} interleaved rounds, min per method ...")
    t_start = time.perf_counter()
    timings = best_times(benches, repeats)
    print(f"  done in {time.perf_counter() - t_start:.1f} s")
    print()
    rows.extend(
        Row(
            b.group,
            b.method,
            t.warm,
            b.configs,
            str(b.shape),
            seconds_cold=t.cold,
            faults_warm=t.faults_warm,
            faults_cold=t.faults_cold,
        )
        for b, t in zip(benches, timings, strict=True)
    )
    for row in rows:
        row.ratio_numpy = row.us_per_config / rows[fk_np].us_per_config
        ref = fk_rtb if row.group == "FK" else jac_rtb
        if ref is not None:
            row.ratio_rtb = row.us_per_config / rows[ref].us_per_config

    print_table(rows)
    if rtb is None:
        print(f"  RTB rows skipped: roboticstoolbox not importable ({rtb_error})")
    print()
    print("Markdown:")
    print()
    print(
        f"UR10, {args.n} random configurations; {info['cpu']} ({info['cpu_count']} CPUs), "
        f"{info['platform']}, Python {info['python']}, numpy {info['numpy']}, "
        f"roboticstoolbox {info['roboticstoolbox'] or 'not installed'}; "
        f"BLAS threads {os.environ.get('OPENBLAS_NUM_THREADS')}; "
        f"min of {repeats} interleaved rounds."
    )
    print()
    print(markdown_table(rows))
    print()
    print(" ".join(" ".join(TABLE_NOTES).split()))  # the notes as one paragraph
    print()

    if args.json is not None:
        payload = asdict(results)
        for d, row in zip(payload["rows"], rows, strict=True):
            d["us_per_config"] = row.us_per_config
            d["us_per_config_cold"] = row.us_per_config_cold
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(payload, indent=2) + "\n", encoding="utf-8")
        print(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
