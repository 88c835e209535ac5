"""Accuracy on the real UR10 (series A): physical models, the learned residual and GP peers.

Data: ``../shared/data/ur10_laser_tracker/measurements_grid.csv`` (11,911 poses, Leica
laser tracker, T-Mac probe about 109 mm from the flange; see its README).  For each
training size (100, 300, 1,000 random rows) and seed (0-4) every model is calibrated on
the training rows only and validated on all the other rows (10,910-11,810 held-out
poses).  Models:

* plain DH            — the catalog's DH chain (``rc.robot("ur10")``), geometry only;
* complete            — seed 000's complete model (``rc.calibration_model``), geometry only;
* complete + compliance — plus joint compliance under gravity (catalog masses);
* robocal default     — what ``robocal calibrate ur10`` does: k-fold
  cross-validation on the training rows chooses among the above physics and the learned
  per-joint angle errors (``residual="auto"``);
* + GP (ARD, exact)   — peer: complete + compliance, then a Gaussian process on the
  position residual (base frame) with an ARD Matérn-3/2 kernel on (sin q, cos q) of all
  six joints, hyperparameters by marginal likelihood (scikit-learn);
* + GP (sparse, 300)  — the same with 300 inducing points (subset of regressors; the
  hyperparameters from a 300-pose subset): the form that scales to thousands of poses.

Per pose, the default is also compared with *physics alone*: the physics-only calibration
the default stores with it (``result.json``'s ``physics_only``, what a URDF export carries;
the default itself when CV chose no residual), on the same held-out poses: the share of
held-out poses the default predicts worse, the largest increase and the change at the 95th
percentile of the per-pose changes (``--tail`` prints only the default and this table, the
figures of docs/concepts/residual.md).  ``--cv-grid 8,16,24,32,48,64`` prints only the
cross-validation errors on the training rows per number of harmonics (the evidence for
the default's grid).

``--floor`` prints only what the default leaves when fitted on 8,000 rows: the share of its
residual on the other 3,911 rows (a diagnosis: they tune nothing) that each candidate
explanation explains out of sample (ridge, random and time-blocked folds: the tracker's
angle and range errors, a polynomial of the measured position, products of two joints'
harmonics, the probe's orientation to the beam, the move from the previous row), and how
the residuals of rows measured one after the other correlate.  Measured (issue 34): no
function of the configuration explains more than 2.2 % (none above zero with time-blocked
folds); the move from the previous row 11-12 % (18 parameters: backlash and a lag that
grows with the move; the previous pose is not an input of a calibration); consecutive rows
(7 s apart) correlate +0.32, rows 30 apart (4 min) +0.04: the rest is error that is shared
by measurements close in time, not a function of the pose.

``--days 14,15`` keeps only the rows measured on those days (training and held-out rows
alike): the splits on which the choice of harmonics was studied (issue 34, session 16: one
standard error kept 24 harmonics where 48 were lower at 100 poses; days 14-15 0.1163 ->
0.1084 mm, days 16-18 0.1378 -> 0.1334 mm with the lowest CV error).

``--pose`` adds the default path calibrated on pose data (the probe's measured
orientation, XYZ Euler degrees, in the identification) to show whether orientation
helps; ``--probe`` only prints which joints the physics' remaining error follows.
Times are the fit on this machine (BLAS single-threaded); the held-out columns
are means over the seeds.  Run: ``python benchmarks/bench_real_accuracy.py [--seeds 5]
[--sizes 100,300,1000] [--no-gp] [--pose] [--tail]`` (about 5 minutes with the GP peers);
``--transfer`` runs ``bench_transfer.py`` (calibrated on 14-17 July, re-registered on 18 July).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only add noise
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import robocal as rc

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
JOINTS = (
    "q1=shoulder_pan_joint,q2=shoulder_lift_joint,q3=elbow_joint,"
    "q4=wrist_1_joint,q5=wrist_2_joint,q6=wrist_3_joint"
)
POSITION = "x=measurement_x,y=measurement_y,z=measurement_z"
ROTATION = "rx=measurement_rx,ry=measurement_ry,rz=measurement_rz"
PROBE = [0.0, 0.0, 0.109]


DAYS: tuple[int, ...] = ()  # --days: only the rows measured on these days of July 2020 (all: empty)


def read(path: Path, pose: bool = False) -> rc.Measurements:
    columns = f"{JOINTS},{POSITION}" + (f",{ROTATION}" if pose else "")
    data = rc.read_measurements(
        path, length_unit="mm", decimal=",", sep=";", columns=columns,
        orientation="euler:XYZ:deg" if pose else "none",
    )  # fmt: skip
    if not DAYS:
        return data
    stamp = np.loadtxt(path, delimiter=";", skiprows=1, usecols=0, dtype=str)  # yyyymmddHHMMSS
    return data.subset(np.flatnonzero(np.isin([int(s[6:8]) for s in stamp], DAYS)))


def _features(q: np.ndarray) -> np.ndarray:
    return np.hstack([np.sin(q), np.cos(q)])


def gp_peer(result: rc.CalibrationResult, train: rc.Measurements, inducing: int | None):
    """A scikit-learn GP on the position residual of ``result``; returns predict(q) -> (n, 3)
    device-frame positions.  ``inducing``: subset-of-regressors with that many points."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    X = _features(train.q)
    r = (train.position - result.predict(train.q)[:, :3, 3]) * 1e3  # mm
    kernel = ConstantKernel(0.1, (1e-4, 10.0)) * Matern(
        np.ones(X.shape[1]), (1e-2, 1e3), nu=1.5
    ) + WhiteKernel(1e-3, (1e-6, 1.0))
    rng = np.random.default_rng(0)
    subset = (
        np.arange(len(X)) if inducing is None else rng.choice(len(X), min(inducing, len(X)), replace=False)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gp = GaussianProcessRegressor(kernel, n_restarts_optimizer=0).fit(X[subset], r[subset])
    if inducing is None:
        return lambda q: result.predict(q)[:, :3, 3] + gp.predict(_features(q)) * 1e-3
    k_signal, noise = gp.kernel_.k1, gp.kernel_.k2.noise_level
    Z = X[subset]
    Kmn = k_signal(Z, X)  # (m, n): memory O(m n), never n x n
    A = noise * k_signal(Z) + Kmn @ Kmn.T
    w = np.linalg.solve(A + 1e-9 * np.trace(A) / len(A) * np.eye(len(A)), Kmn @ r)
    return lambda q: result.predict(q)[:, :3, 3] + (k_signal(_features(q), Z) @ w) * 1e-3


def _stats(predicted: np.ndarray, test: rc.Measurements) -> tuple[float, float, float, float]:
    e = np.linalg.norm(predicted - test.position, axis=1)
    return float(e.mean()), float(np.sqrt(np.mean(e**2))), float(np.percentile(e, 95)), float(e.max())


def _against_physics(result: rc.CalibrationResult, test: rc.Measurements) -> tuple[float, ...]:
    """The default's held-out error per pose against its stored physics-only fit's: share of
    poses worse (%), the 95th percentile and the largest increase (m), both models' largest
    error (m)."""
    from robocal.compensate.export import kinematic_part

    physics = kinematic_part(result).calibrated if result.model.residual is not None else result
    e = np.linalg.norm(result.predict(test.q)[:, :3, 3] - test.position, axis=1)
    e_physics = np.linalg.norm(physics.predict(test.q)[:, :3, 3] - test.position, axis=1)
    change = e - e_physics
    worse = 100.0 * float(np.mean(change > 0.0))
    p95, largest = float(np.percentile(change, 95)), float(change.max())
    return worse, p95, largest, float(e.max()), float(e_physics.max())


TAIL: dict[int, list[tuple[float, ...]]] = {}  # training poses -> per seed: _against_physics
DEFAULT = "robocal default (CV: physics + learned angle errors)"


def run(
    sizes: list[int], seeds: int, gp: bool, pose: bool, only_default: bool = False
) -> dict[tuple[str, int], list[tuple]]:
    data = read(DATA)
    data_pose = read(DATA, pose=True) if pose else None
    dh, complete = rc.robot("ur10"), rc.calibration_model("ur10", "position")
    rows: dict[tuple[str, int], list[tuple]] = {}

    def add(name: str, n: int, predicted: np.ndarray, test: rc.Measurements, seconds: float) -> None:
        rows.setdefault((name, n), []).append((*_stats(predicted, test), seconds))

    for n in sizes:
        for seed in range(seeds):
            split = data.with_split(n, seed=seed)
            train, test = split.split_rows("train"), split.split_rows("test")
            fits = {
                "plain DH": (dh, {"residual": "none"}),
                "complete": (complete, {"residual": "none"}),
                "complete + compliance": (complete, {"residual": "none", "compliance": True}),
                DEFAULT: (complete, {"residual": "auto"}),
            }
            if only_default:
                fits = {DEFAULT: fits[DEFAULT]}
            results = {}
            for name, (model, options) in fits.items():
                t = time.perf_counter()
                result = rc.calibrate(model, train, tool_guess=PROBE, **options)
                seconds = time.perf_counter() - t
                results[name] = (result, seconds)
                add(name, n, result.predict(test.q)[:, :3, 3], test, seconds)
            TAIL.setdefault(n, []).append(_against_physics(results[DEFAULT][0], test))
            if gp and not only_default:
                physics, t_physics = results["complete + compliance"]
                peers = (("+ GP (ARD, exact)", None), ("+ GP (sparse, 300 inducing)", 300))
                for suffix, inducing in peers:
                    name = f"complete + compliance {suffix}"
                    if inducing is not None and n <= inducing:
                        continue
                    t = time.perf_counter()
                    predict = gp_peer(physics, train, inducing)
                    add(name, n, predict(test.q), test, t_physics + time.perf_counter() - t)
            if data_pose is not None and not only_default:
                split = data_pose.with_split(n, seed=seed)
                train, test = split.split_rows("train"), split.split_rows("test")
                t = time.perf_counter()
                result = rc.calibrate(
                    rc.calibration_model("ur10", "pose"), train, tool_guess=PROBE, residual="auto"
                )
                seconds = time.perf_counter() - t
                add(
                    "robocal default, pose data (orientation used)",
                    n,
                    result.predict(test.q)[:, :3, 3],
                    test,
                    seconds,
                )
            print(f"  {n} poses, seed {seed} done", flush=True)
    return rows


def probe(folds: int = 5) -> None:
    """Which joints the physics' remaining error follows: a nearest-neighbour regression of
    the residual of complete + compliance (fitted on all poses) on subsets of the joint
    angles, k-fold over all poses; mean error of each (mm)."""
    from sklearn.model_selection import KFold, cross_val_predict
    from sklearn.neighbors import KNeighborsRegressor

    data = read(DATA)
    result = rc.calibrate(rc.calibration_model("ur10", "position"), data, tool_guess=PROBE, compliance=True)
    r = data.position - result.predict(data.q)[:, :3, 3]
    mean = np.linalg.norm(r, axis=1).mean()
    print(f"complete + compliance on all {data.n} poses: residual mean {mean * 1e3:.3f} mm")
    for joints in ((0, 1, 2, 3, 4, 5), (1, 2, 3, 4, 5), (3, 4, 5), (1, 2), (0, 1, 2)):
        X = np.hstack([np.sin(data.q[:, joints]), np.cos(data.q[:, joints])])
        split = KFold(folds, shuffle=True, random_state=0)
        predicted = cross_val_predict(KNeighborsRegressor(5, weights="distance"), X, r, cv=split)
        e = np.linalg.norm(r - predicted, axis=1).mean()
        print(f"  5 nearest neighbours in joints {[j + 1 for j in joints]}: {e * 1e3:.3f} mm")


def cv_grid(sizes: list[int], seeds: int, grid: tuple[int, ...]) -> None:
    """The CV evidence behind the default's harmonics: for each training size and seed the
    default calibrated with ``residual_harmonics=grid``; per number of harmonics the mean
    5-fold CV error on the training rows (the lower of the physical variants'), averaged
    over the seeds, and how often each was chosen.  Held-out rows never enter."""
    data = read(DATA)
    model = rc.calibration_model("ur10", "position")
    print(f"| training poses | {' | '.join(f'H={h} CV mean mm' for h in grid)} | chosen (seeds) |")
    print("|---:|" + "---:|" * len(grid) + "---|")
    for n in sizes:
        cv_means, chosen = np.zeros((seeds, len(grid))), []
        for seed in range(seeds):
            train = data.with_split(n, seed=seed).split_rows("train")
            result = rc.calibrate(model, train, tool_guess=PROBE, residual="auto", residual_harmonics=grid)
            table = result.metadata["cv"]
            for i, h in enumerate(grid):
                cv_means[seed, i] = min(c["cv_mean_mm"] for c in table["candidates"] if c["harmonics"] == h)
            chosen.append(next(c["harmonics"] for c in table["candidates"] if c["name"] == table["chosen"]))
        counts = ", ".join(f"H={h}: {chosen.count(h)}" for h in sorted(set(chosen), key=lambda h: h or 0))
        print(f"| {n} | {' | '.join(f'{v:.4f}' for v in cv_means.mean(axis=0))} | {counts} |", flush=True)


def _ridge_r2(A: np.ndarray, r: np.ndarray, folds: list[np.ndarray]) -> float:
    """Out-of-sample share of the variance of the residual vectors ``r`` (n, 3) that a ridge
    fit of the vector design ``A`` (n, 3, k) plus a constant vector explains: held-out folds
    ``folds`` (index arrays), the best of a grid of penalties (a diagnosis, not a tuned model)."""
    A = np.concatenate([A, np.broadcast_to(np.eye(3), (len(A), 3, 3))], axis=2)
    A = A / (np.sqrt(np.mean(np.sum(A**2, axis=1), axis=0)) + 1e-12)  # columns on one scale
    k, sst = A.shape[2], float(np.sum((r - r.mean(axis=0)) ** 2))
    penalty = np.r_[np.ones(k - 3), np.zeros(3)] + 1e-12  # the constant is not shrunk
    best = -np.inf
    for alpha in (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0):
        sse = 0.0
        for held in folds:
            fit = np.ones(len(r), bool)
            fit[held] = False
            X = A[fit].reshape(-1, k)
            c = np.linalg.solve(X.T @ X + alpha * fit.sum() * np.diag(penalty), X.T @ r[fit].reshape(-1))
            sse += float(np.sum((np.einsum("nck,k->nc", A[held], c) - r[held]) ** 2))
        best = max(best, 1.0 - sse / sst)
    return best


def _harmonics(x: np.ndarray, H: int) -> np.ndarray:
    """(n, 2H): cos(h x), sin(h x) for h = 1..H."""
    return np.hstack([f(h * x)[:, None] for h in range(1, H + 1) for f in (np.cos, np.sin)])


def _polynomial(X: np.ndarray, degree: int) -> np.ndarray:
    """(n, m) monomials of the standardised columns of ``X`` up to ``degree`` (no constant)."""
    from itertools import combinations_with_replacement

    Z = (X - X.mean(axis=0)) / X.std(axis=0)
    terms = [c for d in range(1, degree + 1) for c in combinations_with_replacement(range(X.shape[1]), d)]
    return np.stack([np.prod(Z[:, list(t)], axis=1) for t in terms], axis=1)


def _each_component(F: np.ndarray) -> np.ndarray:
    """Scalar features (n, k) as a vector design (n, 3, 3k): each axis its own coefficients."""
    return np.einsum("ck,nf->nckf", np.eye(3), F).reshape(len(F), 3, 3 * F.shape[1])


def _floor_candidates(q, p, J, R, previous_q) -> dict[str, np.ndarray]:
    """Vector designs (n, 3, k) of the candidate explanations of the remaining error: joint
    angle errors ``J_j f(...)`` (J: (n, 3, 6) m/rad, device frame), the tracker's angle and
    range errors (p: (n, 3) m, device frame; the tracker at its origin), the beam's direction
    in the probe frame (R: (n, 3, 3) probe orientation), the direction of approach."""
    rng = np.linalg.norm(p, axis=1)
    az, el = np.arctan2(p[:, 1], p[:, 0]), np.arcsin(p[:, 2] / rng)
    e_r = p / rng[:, None]
    e_az = np.stack([-np.sin(az), np.cos(az), np.zeros(len(p))], axis=1)
    F = np.hstack([_harmonics(az, 4), _harmonics(el, 4), np.ones((len(p), 1))])
    tracker = np.concatenate(
        [e[:, :, None] * (w[:, None] * F)[:, None, :] for e, w in ((e_az, rng), (np.cross(e_r, e_az), rng))]
        + [e_r[:, :, None] * np.hstack([F, _polynomial(rng[:, None], 3)])[:, None, :]],
        axis=2,
    )
    beam = np.einsum("nji,nj->ni", R, -e_r)  # probe -> tracker, probe frame
    dq = q - previous_q

    def angle_errors(joints, features):
        return np.concatenate(
            [J[:, :, [j]] * f[:, None, :] for j, f in zip(joints, features, strict=True)], 2
        )

    def pair(a, b):
        P = (_harmonics(q[:, a], 3)[:, :, None] * _harmonics(q[:, b], 3)[:, None, :]).reshape(len(q), -1)
        return angle_errors((a, b), (P, P))

    approach = np.stack([np.sign(dq), np.tanh(dq / 0.05), dq], axis=2)  # (n, 6, 3)
    designs = {
        "control: per-joint angle errors again (H=8)": angle_errors(range(6), [_harmonics(x, 8) for x in q.T])
    }
    designs["tracker: angle-encoder errors (H=4 in azimuth, elevation) + range"] = tracker
    designs["tracker: cubic polynomial of the measured x, y, z"] = _each_component(_polynomial(p, 3))
    for a, b in ((0, 1), (1, 2), (2, 3), (1, 3)):
        designs[f"coupling: joints {a + 1}-{b + 1} errors, products of harmonics H=3"] = pair(a, b)
    designs["tool orientation: cubic polynomial of the beam in the probe frame"] = _each_component(
        _polynomial(beam, 3)
    )
    designs["approach: J_j (sign, tanh(dq/0.05), dq) of the move from the previous row"] = angle_errors(
        range(6), list(approach.transpose(1, 0, 2))
    )
    return designs


def floor(n_train: int = 8000) -> None:
    """What the default leaves on series A: the default fitted on ``n_train`` random rows,
    its residual on the other rows (a diagnosis only: held-out rows tune nothing) explained by
    each candidate (:func:`_floor_candidates`) out of sample, with random and with
    time-blocked folds (20 blocks in measuring order dealt to 5 folds), and how the residual
    of rows measured one after the other correlates."""
    data = read(DATA)
    stamp = np.loadtxt(DATA, delimiter=";", skiprows=1, usecols=0, dtype=str)
    seconds = np.array(
        [np.datetime64(f"{s[:4]}-{s[4:6]}-{s[6:8]}T{s[8:10]}:{s[10:12]}:{s[12:]}") for s in stamp]
    )
    seconds = (seconds - seconds.min()).astype(float)
    split = data.with_split(n_train, seed=0)
    result = rc.calibrate(
        rc.calibration_model("ur10", "position"), split.split_rows("train"), tool_guess=PROBE, residual="auto"
    )
    held = np.flatnonzero(split.split == "test")
    T = result.predict(data.q)
    r = (data.position - T[:, :3, 3]) * 1e3  # mm, device frame
    J = np.stack([(result.predict(data.q + d)[:, :3, 3] - result.predict(data.q - d)[:, :3, 3]) / 2e-6
                  for d in np.eye(6) * 1e-6], axis=2)  # fmt: skip
    previous = np.r_[data.q[:1], data.q[:-1]]
    print(f"default on {n_train} rows: held-out mean {np.linalg.norm(r[held], axis=1).mean():.4f} mm "
          f"({len(held)} rows, chosen: {result.metadata['cv']['chosen']})")  # fmt: skip
    random = np.array_split(np.random.default_rng(1).permutation(len(held)), 5)
    blocks = np.array_split(np.argsort(seconds[held]), 20)
    blocked = [np.concatenate(blocks[k::5]) for k in range(5)]
    designs = _floor_candidates(data.q[held], data.position[held], J[held], T[held, :3, :3], previous[held])
    print("| candidate | parameters | explained share, random folds | time-blocked folds |")
    print("|---|---:|---:|---:|")
    for name, A in designs.items():
        shares = f"{_ridge_r2(A, r[held], random):+.3f} | {_ridge_r2(A, r[held], blocked):+.3f}"
        print(f"| {name} | {A.shape[2]} | {shares} |", flush=True)
    c = r - r.mean(axis=0)
    print("| rows apart in measuring order | median seconds apart | correlation of the residual vectors |")
    print("|---:|---:|---:|")
    for lag in (1, 2, 5, 10, 30, 300, 3000):
        corr = np.mean(np.sum(c[lag:] * c[:-lag], axis=1)) / np.mean(np.sum(c**2, axis=1))
        print(f"| {lag} | {np.median(np.abs(np.diff(seconds[::lag]))):.0f} | {corr:+.3f} |")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--sizes", default="100,300,1000")
    parser.add_argument("--no-gp", action="store_true", help="leave out the scikit-learn GP peers")
    parser.add_argument("--pose", action="store_true", help="also calibrate with the measured orientations")
    parser.add_argument("--probe", action="store_true", help="only: which joints the remaining error follows")
    parser.add_argument("--tail", action="store_true", help="only the default and its per-pose change")
    parser.add_argument(
        "--floor", action="store_true", help="only: what explains the default's remaining error"
    )
    parser.add_argument("--cv-grid", default="", help="only: CV errors of these harmonics, e.g. 8,24,48")
    parser.add_argument(
        "--transfer",
        action="store_true",
        help="only: 14-17 July, re-registered on 18 July",
    )
    parser.add_argument(
        "--days",
        default="",
        help="only the rows of these days (14-18 July), training and held out, e.g. 14,15",
    )
    args = parser.parse_args(argv)
    global DAYS
    DAYS = tuple(int(d) for d in args.days.split(",") if d)
    if args.probe:
        probe()
        return
    if args.floor:
        floor()
        return
    if args.transfer:  # calibrate once, re-register later: its own module, this file's reader
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import bench_transfer

        bench_transfer.main(["--seeds", str(min(args.seeds, 3))])
        return
    sizes = [int(s) for s in args.sizes.split(",")]
    if args.cv_grid:
        cv_grid(sizes, args.seeds, tuple(int(h) for h in args.cv_grid.split(",")))
        return
    print(
        f"real UR10, series A; {args.seeds} seeds; {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}, "
        f"BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}"
    )
    rows = run(sizes, args.seeds, not args.no_gp, args.pose, args.tail)
    print("| model | training poses | held-out mean mm | RMS mm | p95 mm | max mm | fit s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        for (name, size), values in rows.items():
            if size != n:
                continue
            v = np.array(values)
            mean, rms, p95, worst, seconds = v.mean(axis=0)
            spread = v[:, 0].std()
            print(
                f"| {name} | {n} | {mean * 1e3:.3f} (± {spread * 1e3:.3f}) | {rms * 1e3:.3f} | "
                f"{p95 * 1e3:.3f} | {worst * 1e3:.3f} | {seconds:.2f} |"
            )
    print_tail(sizes)


def print_tail(sizes: list[int]) -> None:
    """The per-pose change of the default against physics alone (means over the seeds; the
    largest increase and both maxima: the worst seed's)."""
    print()
    print(
        "| training poses | held-out poses worse than physics alone % | p95 of the change mm | "
        "largest increase mm | max error default / physics alone mm (worst seed) | "
        "seeds with the default's max above physics alone's |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        v = np.array(TAIL.get(n, []))
        if not len(v):
            continue
        worse, p95, largest = v[:, 0].mean(), v[:, 1].mean(), v[:, 2].max()
        print(
            f"| {n} | {worse:.1f} (range {v[:, 0].min():.1f}-{v[:, 0].max():.1f}) | {p95 * 1e3:+.3f} | "
            f"{largest * 1e3:.3f} | {v[:, 3].max() * 1e3:.3f} / {v[:, 4].max() * 1e3:.3f} | "
            f"{int(np.sum(v[:, 3] > v[:, 4]))} of {len(v)} |"
        )


if __name__ == "__main__":
    main()
